"""LabVIEW measurement files (``.lvm`` text).

An ``.lvm`` file starts with ``LabVIEW Measurement``, then header blocks of
``key<TAB>value`` lines, each ending with ``***End_of_Header***``. The data
follow a line starting with ``X_Value`` that names the channels (often just
``Untitled``, ``Untitled 1``...); a file may hold several segments, each with
its own header block. The clock time of the data is the first segment's ``Date``
and ``Time`` (the file header's when it has none). Reference: National
Instruments, "Specification for the LabVIEW Measurement File (.lvm)".

Channel names such as ``Untitled 1`` say nothing, so the meaning of the columns
comes from ``--columns``. When a ``Description`` line lists the columns (``time,
Current, Voltage, Power, Battery Temp, and Chamber Temp``) and their number
matches the data, those names are used instead, and the metadata says so.

A description may leave out a channel or two (the ARTS-Lab Samsung 30Q cycling
files name six columns for seven: the hoop strain is missing). Then every way of
placing the listed names over the columns in order is checked against what the
names mean (:func:`align_described_names`): time never runs backwards, a voltage
is positive, a power is voltage times current, a temperature lies between -60
and 150 degC and is not a column of values within 1 of zero. The one placement
that passes is used; when several pass, only the names they agree on are.
"""

from __future__ import annotations

import re
from itertools import combinations

import numpy as np
import pandas as pd

from ..errors import DataError
from .columns import SourceTable, name_score, split_name_unit
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
    segment: dict[str, str] = {}
    x_value_at = None
    ends = 0
    for k, line in enumerate(lines):
        if line.startswith("X_Value"):
            x_value_at = k
            break
        key, _, value = line.partition("\t")
        key = key.strip()
        if key == END_OF_HEADER:
            ends += 1
        elif key and ends == 0 and key not in header:
            header[key] = value.strip()
        elif key in ("Date", "Time") and ends == 1 and key not in segment:
            segment[key] = value.split("\t")[0].strip()
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
    kept: dict[str, str] = {k: header[k] for k in ("Date", "Time", "Operator", "Description",
                                                   "Separator", "Decimal_Separator")
                            if k in header}
    if segment.get("Date") and segment.get("Time"):
        # the segment's own date and time are those of its first sample; the file
        # header's are when logging began, and a test rig writing one file per cycle
        # repeats them in every file of a run
        kept.update(Date=segment["Date"], Time=segment["Time"])
    meta = {"format": "lvm", "lvm_header": kept}
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
    ncols = table.data.shape[1]
    if described and len(described) == ncols:
        table.names = described
        table.names_inferred = f"the LabVIEW Description line ({header['Description']!r})"
    elif described:
        names, why = align_described_names(described, table.data, table.names)
        if names is None:
            table.meta["notes"].append(
                f"the Description line lists {len(described)} columns but the data have "
                f"{ncols}; not used ({why})")
        else:
            table.names = names
            table.names_inferred = (f"the LabVIEW Description line ({header['Description']!r}), "
                                    f"which lists {len(described)} of {ncols} columns: {why}")
    return table


#: Most channels a Description line may leave out for its names still to be placed.
MAX_UNNAMED_CHANNELS = 2


def _quantity(name: str) -> str | None:
    base, unit, _ = split_name_unit(name)
    if "power" in base:
        return "power"
    scores = {key: name_score(base, key, unit) for key in
              ("time_s", "voltage_V", "current_A", "temperature_C", "ambient_temperature_C")}
    best = max(scores, key=lambda k: scores[k])
    return best if scores[best] else None


def _plausible(quantity: str, values: np.ndarray, placed: dict[str, np.ndarray]) -> bool:
    """Whether a column's values can be the quantity its name says (units as in the file)."""
    finite = values[np.isfinite(values)]
    if finite.size < 0.5 * values.size or finite.size < 2:
        return False
    if quantity == "time_s":
        return bool(np.mean(np.diff(finite) >= 0) >= 0.99)
    if quantity == "voltage_V":
        return bool(0 < np.median(finite) <= 1000)
    if quantity in ("temperature_C", "ambient_temperature_C"):
        return bool(np.all((finite > -60) & (finite < 150)) and np.max(np.abs(finite)) >= 1.0)
    if quantity == "power":
        v, i = placed.get("voltage_V"), placed.get("current_A")
        if v is None or i is None:
            return True
        ok = np.isfinite(values) & np.isfinite(v) & np.isfinite(i)
        if ok.sum() < 2:
            return False
        gap = np.median(np.abs(np.abs(values[ok]) - np.abs(v[ok] * i[ok])))
        return bool(gap <= 0.05 * np.median(np.abs(values[ok])) + 1e-6)
    return True


def align_described_names(described: list[str], data: pd.DataFrame,
                          channel_names: list[str] | None = None
                          ) -> tuple[list[str] | None, str]:
    """Place the names of a Description line that lists fewer names than the data have columns.

    Every placement that keeps the names in order and leaves one or two columns
    unnamed is checked with what each recognised name means (time, voltage,
    current, power = voltage x current, temperatures; see the module docstring).

    Parameters
    ----------
    described : list of str
        Names from the Description line, in order.
    data : pandas.DataFrame
        The data columns (0..n-1).
    channel_names : list of str, optional
        The channel names of the ``X_Value`` line; unnamed columns keep theirs.

    Returns
    -------
    names : list of str or None
        One name per column (unnamed columns keep their channel name), or None
        when no placement passes or too many columns are missing.
    why : str
        What was decided, for the notes.
    """
    ncols = data.shape[1]
    missing = ncols - len(described)
    if missing < 1 or missing > MAX_UNNAMED_CHANNELS:
        return None, f"{missing} columns unnamed; at most {MAX_UNNAMED_CHANNELS} are placed"
    numeric = [pd.to_numeric(data.iloc[:, k], errors="coerce").to_numpy(dtype=float)
               for k in range(ncols)]
    quantities = [_quantity(n) for n in described]
    passing = []
    for unnamed in combinations(range(ncols), missing):
        positions = [k for k in range(ncols) if k not in unnamed]
        placed = {q: numeric[k] for q, k in zip(quantities, positions)
                  if q in ("voltage_V", "current_A")}
        if all(q is None or _plausible(q, numeric[k], placed)
               for q, k in zip(quantities, positions)):
            passing.append(positions)
    if not passing:
        return None, "no placement of the listed names fits the data"
    fallback = list(channel_names or [])[:ncols]
    fallback += [f"column {k}" for k in range(len(fallback), ncols)]
    names = list(fallback)
    agreed = []
    for j, name in enumerate(described):
        spots = {positions[j] for positions in passing}
        if len(spots) == 1:
            k = spots.pop()
            names[k] = name
            agreed.append(f"{name!r} = column {k}")
    if not agreed:
        return None, "several placements of the listed names fit the data equally"
    unnamed_cols = [k for k in range(ncols) if names[k] == fallback[k]]
    why = ("names placed where the data fit them (" + ", ".join(agreed) + "); column"
           + ("s " if len(unnamed_cols) > 1 else " ")
           + ", ".join(str(k) for k in unnamed_cols) + " left unnamed")
    if len(passing) > 1:
        why += f"; {len(passing)} placements fit, only the names they agree on are used"
    return names, why


__all__ = ["is_lvm", "read_lvm", "description_names", "align_described_names", "MAGIC"]
