"""LabVIEW measurement files (``.lvm`` text).

An ``.lvm`` file starts with ``LabVIEW Measurement``, then header blocks of
``key<TAB>value`` lines, each ending with ``***End_of_Header***``. The data
follow a line starting with ``X_Value`` that names the channels (often just
``Untitled``, ``Untitled 1``...); a file may hold several segments, each with
its own header block. Reference: National Instruments, "Specification for the
LabVIEW Measurement File (.lvm)".

Channel names such as ``Untitled 1`` say nothing, so the meaning of the columns
comes from ``--columns``. When a ``Description`` line lists the columns (``time,
Current, Voltage, Power, Battery Temp, and Chamber Temp``) and their number
matches the data, those names are used instead, and the metadata says so.
"""

from __future__ import annotations

import re

from ..errors import DataError
from .columns import SourceTable
from .text import content_lines, is_number, parse_delimited

MAGIC = "LabVIEW Measurement"
END_OF_HEADER = "***End_of_Header***"


def is_lvm(first_line: str) -> bool:
    """True when the first line marks a LabVIEW measurement file."""
    return first_line.strip().lstrip("\ufeff").startswith(MAGIC)


def description_names(description: str) -> list[str] | None:
    """Column names listed in an LVM ``Description`` value, or None.

    ``"Clolumns are: time, Current, Voltage, Power, Battery Temp, and Chamber Temp"``
    gives ``["time", "Current", "Voltage", "Power", "Battery Temp", "Chamber Temp"]``.
    """
    if ":" not in description:
        return None
    listing = description.split(":", 1)[1]
    parts = re.split(r",\s*(?:and\s+)?|\s+and\s+", listing)
    names = [p.strip().rstrip(".").strip() for p in parts if p.strip()]
    return names if len(names) >= 2 else None


def read_lvm(text: str, path_name: str, *, delimiter=None) -> SourceTable:
    """Parse an ``.lvm`` text file into a :class:`SourceTable`.

    Raises
    ------
    DataError
        No ``X_Value`` line (not a complete LVM file) or no data rows.
    """
    lines, numbers = content_lines(text)
    header: dict[str, str] = {}
    x_value_at = None
    for k, line in enumerate(lines):
        if line.startswith("X_Value"):
            x_value_at = k
            break
        key, _, value = line.partition("\t")
        key = key.strip()
        if key and key != END_OF_HEADER and key not in header:
            header[key] = value.strip()
    if x_value_at is None:
        raise DataError(f"{path_name}: LabVIEW file without an 'X_Value' line before the data; "
                        "save it with the X column or export it as CSV")
    separator = header.get("Separator", "Tab").lower()
    if delimiter is None:
        delimiter = {"tab": "\t", "comma": ","}.get(separator, "\t")
    decimal_separator = header.get("Decimal_Separator", ".")

    # Later segments repeat header blocks: keep only rows whose first field is a number.
    body, body_numbers, skipped = [], [], 0
    for line, number in zip(lines[x_value_at + 1:], numbers[x_value_at + 1:]):
        first = line.split(delimiter, 1)[0]
        if is_number(first):
            body.append(line)
            body_numbers.append(number)
        else:
            skipped += 1
    if not body:
        raise DataError(f"{path_name}: LabVIEW file has a header but no data rows")
    meta = {
        "format": "lvm",
        "lvm_header": {k: header[k] for k in ("Date", "Time", "Operator", "Description",
                                               "Separator", "Decimal_Separator") if k in header},
    }
    if skipped:
        meta["lvm_skipped_header_lines"] = skipped
    lvm_names = [n.strip() for n in lines[x_value_at].split(delimiter)]
    table = parse_delimited([lines[x_value_at]] + body,
                            [numbers[x_value_at]] + body_numbers, path_name,
                            delimiter=delimiter, header=True, meta=meta)
    if decimal_separator == "," and table.meta.get("decimal") != "comma":
        table.meta.setdefault("notes", []).append("the LVM header says decimal comma")
    table.meta["lvm_channel_names"] = lvm_names
    described = description_names(header.get("Description", ""))
    if described and len(described) == table.data.shape[1]:
        table.names = described
        table.names_inferred = f"the LabVIEW Description line ({header['Description']!r})"
    elif described:
        table.meta["notes"].append(
            f"the Description line lists {len(described)} columns but the data have "
            f"{table.data.shape[1]}; not used")
    return table


__all__ = ["is_lvm", "read_lvm", "description_names", "MAGIC"]
