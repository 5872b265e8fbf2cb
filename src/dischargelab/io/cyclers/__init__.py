"""Battery testers' own files: Neware, BioLogic, Arbin, Maccor and other exports.

=================================  ================================  ====================
file                               read with                          extra
=================================  ================================  ====================
Neware ``.nda`` / ``.ndax``        NewareNDA (:mod:`.neware`)         ``cyclers``
BioLogic EC-Lab ``.mpr``           galvani (:mod:`.biologic`)         ``cyclers``
Arbin ``.res`` (MS Access)         Debian's mdbtools (:mod:`.arbin`)  ``apt-get install
                                                                      mdbtools``
Arbin ``.xlsx`` export             openpyxl (:mod:`.exports`)         ``cyclers``
Arbin CSV, Maccor text, others     our reader (:mod:`.exports`)       none
=================================  ================================  ====================

The format is found from the content. Each file becomes a
:class:`~.steps.TesterFile`: canonical columns (``time_s`` test time,
``voltage_V``, ``current_A`` discharge positive, ``temperature_C`` where
recorded) plus the tester's ``cycle_index`` and ``step_index`` (integers as the
tester numbered them), and its **steps** (charge, rest, discharge; see
:func:`~.steps.step_table`). :func:`tester_reader` gives what
:func:`dischargelab.io.read_discharge` returns for any step: ``segment=N`` is
step N of the file (a discharge step), ``"auto"`` the first full discharge,
``"none"`` every record.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import DataError
from ..columns import CanonicalTable
from .steps import (
    STEP_KINDS,
    TesterFile,
    TesterRecords,
    describe_step,
    discharge_numbers,
    finish,
    fit_steps,
    full_discharges,
)

#: Formats :func:`detect_tester` names (``*-text`` and ``*-xlsx`` also come as
#: ``tester-text`` / ``tester-xlsx`` for exports of other testers).
TESTER_FORMATS = ("neware-nda", "neware-ndax", "biologic-mpr", "arbin-res", "arbin-text",
                  "arbin-xlsx", "maccor-text", "basytec-text", "ec-lab-text", "novonix-text",
                  "pec-text", "tester-text", "tester-xlsx")

#: Columns a step read keeps besides the canonical ones.
STEP_COLUMNS = ("cycle_index", "step_index")

_NEWARE_MAGIC = b"NEWARE"
_BIOLOGIC_MAGIC = b"BIO-LOGIC MODULAR FILE"
#: Members of an ``.ndax`` zip archive.
_NDAX_MEMBERS = ("data.ndc", "VersionInfo.xml", "NdaxConfig.xml")


def detect_tester(path) -> str | None:
    """The kind of tester file from its content, or None for any other file.

    ``"neware"`` (``.nda`` starts ``NEWARE``, ``.ndax`` is a zip holding
    ``data.ndc``), ``"biologic"`` (``BIO-LOGIC MODULAR FILE``), ``"arbin-res"``
    (an MS Access database), ``"xlsx"`` (a workbook with a tester table) or
    ``"text"`` (a header with time, voltage, current and a cycle or step column
    within the first lines).
    """
    import zipfile

    from .arbin import is_access
    from .exports import decode_text, is_tester_table, is_xlsx, table_lines, text_header

    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536)
    except OSError:
        return None
    if head.startswith(_NEWARE_MAGIC):
        return "neware"
    if head.startswith(_BIOLOGIC_MAGIC):
        return "biologic"
    if is_access(head):
        return "arbin-res"
    if head.startswith(b"PK"):
        try:
            with zipfile.ZipFile(path) as archive:
                names = archive.namelist()
        except (zipfile.BadZipFile, OSError):
            return None
        if any(n in names for n in _NDAX_MEMBERS):
            return "neware"
        if is_xlsx(head, path) and _xlsx_has_tester_table(path, is_tester_table):
            return "xlsx"
        return None
    if b"\x00" in head[:4096]:
        return None
    text = decode_text(head)
    lines = table_lines(text)
    return "text" if text_header(lines[:-1] if len(head) == 65536 else lines) else None


def _xlsx_has_tester_table(path: Path, is_tester_table) -> bool:
    """The first rows of a sheet name a tester table (read without loading the data)."""
    import zipfile

    try:
        import openpyxl
        from openpyxl.utils.exceptions import InvalidFileException
    except ImportError:
        return True   # reading it says which extra is missing
    try:
        book = openpyxl.load_workbook(path, read_only=True, data_only=True)
    except (InvalidFileException, zipfile.BadZipFile, KeyError, ValueError, OSError):
        return False   # a damaged workbook is not read as a tester file
    try:
        for sheet in book.worksheets:
            for row in sheet.iter_rows(min_row=1, max_row=20, values_only=True):
                if is_tester_table(["" if v is None else str(v) for v in row]):
                    return True
        return False
    finally:
        book.close()


def read_tester(path, kind: str | None = None, sign: str = "auto") -> TesterFile:
    """Read a tester file into records and steps.

    Parameters
    ----------
    path : path-like
    kind : str, optional
        What :func:`detect_tester` says (found from the content when None).
    sign : {"auto", "positive", "negative"}
        Sign of the discharge current in the file; ``"auto"`` reads it from the file.

    Raises
    ------
    DataError
        Not a tester file, or one the reader cannot read (one line naming the reader
        and its version).
    MissingExtraError
        The reader's library (extra ``cyclers``) or mdbtools is not installed.
    """
    path = Path(path)
    kind = kind or detect_tester(path)
    if kind == "neware":
        from .neware import read_neware
        raw = read_neware(path)
    elif kind == "biologic":
        from .biologic import read_biologic
        raw = read_biologic(path)
    elif kind == "arbin-res":
        from .arbin import read_arbin_res
        raw = read_arbin_res(path)
    elif kind == "xlsx":
        from .exports import read_xlsx_export
        raw = read_xlsx_export(path)
    elif kind == "text":
        from .exports import read_text_export
        raw = read_text_export(path)
    else:
        from ..text import OLE2_MAGIC, excel97_message

        with open(path, "rb") as fh:
            if fh.read(len(OLE2_MAGIC)) == OLE2_MAGIC:
                raise DataError(excel97_message(path.name))
        raise DataError(f"{path.name} is not a battery tester file this version reads (Neware "
                        ".nda/.ndax, BioLogic .mpr, Arbin .res/.csv/.xlsx, or a text export "
                        "whose header names time, voltage, current and a step or cycle)")
    tester = finish(raw, path.name, sign)
    tester.meta["source"] = str(path)
    return tester


def tester_reader(path, *, kind: str | None = None, current_A=None, sign: str = "auto",
                  rest_sample: str = "auto"):
    """Parse a tester file once; ``read(segment="auto")`` gives any of its steps.

    ``read(segment=...)`` returns ``(frame, meta)`` as
    :func:`dischargelab.io.read_discharge` does: ``"auto"`` the first full
    discharge (else the longest discharge step), ``N`` step N (a discharge),
    ``"none"`` every record. ``read.tester`` is the :class:`TesterFile`.
    """
    tester = read_tester(path, kind=kind, sign=sign)
    read = functools.partial(read_step, tester, current_A=current_A, rest_sample=rest_sample)
    read.tester = tester  # type: ignore[attr-defined]
    return read


def read_step(tester: TesterFile, segment="auto", *, current_A=None, rest_sample="auto"
              ) -> tuple[pd.DataFrame, dict]:
    """One step (or every record) of a read tester file, as ``read_discharge`` returns it."""
    from ..prepare import check_segment_option, prepare, summary_sentence

    segment = check_segment_option(segment)
    name = Path(tester.meta["source"]).name
    numbers = discharge_numbers(tester.steps)
    if segment == "none":
        a, b, step = 0, len(tester.frame), None
    else:
        if not numbers:
            kinds = sorted({s["kind"] for s in tester.steps})
            raise DataError(f"{name}: no discharge step in the file (its steps are "
                            f"{' and '.join(kinds)})")
        number = default_step(tester.steps) if segment == "auto" else segment
        if not 1 <= number <= len(tester.steps):
            raise DataError(f"{name} has {len(tester.steps)} steps; step (segment) {number} "
                            f"does not exist; its discharge steps are {_numbers(numbers)}")
        step = tester.step(number)
        if step["number"] not in numbers:
            what = "is not a discharge" if step["kind"] != "discharge" else \
                f"has {step['rows']} record(s), too few for a discharge"
            raise DataError(f"{name}: {describe_step(step)} {what}; its discharge steps are "
                            f"{_numbers(numbers)} (segment='none' gives every step with its "
                            "cycle_index and step_index)")
        a, b = tester.bounds[number - 1]
    columns = [c for c in ("time_s", "voltage_V", "current_A", "temperature_C")
               if c in tester.frame] + list(STEP_COLUMNS)
    meta = {k: v for k, v in tester.meta.items()
            if k not in ("sign_source", "sign_convention")}
    meta.update({"explicit_units": ["time_s", "voltage_V", "current_A"],
                 "cell_voltage_known": True,
                 "notes": list(tester.meta.get("notes", []))})
    meta.setdefault("column_map", {})
    table = CanonicalTable(frame=tester.frame.iloc[a:b][columns].reset_index(drop=True),
                           line_numbers=tester.records[a:b], meta=meta)
    out, meta = prepare(table, name, current_A=current_A, sign="positive", segment="none",
                        rest_sample="none", discharge_only=step is not None)
    meta["sign_source"] = tester.meta["sign_source"]
    meta["sign_convention"] = tester.meta["sign_convention"]
    meta["steps"] = tester.steps
    meta["segments"] = [_segment(tester.step(n)) for n in numbers]
    meta["segment"] = None if step is None else step["number"]
    meta["step"] = step
    if step is not None:
        meta["starts_full"] = bool(step.get("after_charge"))
        meta["cycle"] = step["cycle"]
        rest = _rest_before(tester, step, meta["time_offset_s"]) \
            if rest_sample == "auto" else None
        meta["rest_sample"] = rest
    meta["summary"] = _summary(meta, summary_sentence(meta), step, len(numbers))
    return out, meta


def used_steps_note(metas: list[dict]) -> list[str]:
    """One line per tester file among ``metas``: which steps were used, why, and which
    discharge steps were left (to validate on)."""
    by_source: dict[str, list[dict]] = {}
    for meta in metas:
        if isinstance(meta.get("step"), dict):
            by_source.setdefault(str(meta.get("source")), []).append(meta)
    lines = []
    for source, parts in by_source.items():
        used = [m["step"]["number"] for m in parts]
        left = [n for n in discharge_numbers(parts[0]["steps"]) if n not in used]
        why = parts[0].get("chosen_by") or "named by step"
        text = (f"{Path(source).name}: steps {_numbers(used)} used ({why})"
                if len(used) > 1 else f"{Path(source).name}: step {used[0]} used ({why})")
        if left:
            text += f"; its other discharge steps: {_numbers(left)}"
        lines.append(text)
    return lines


def default_step(steps: list[dict]) -> int:
    """The step ``segment="auto"`` reads: the first full discharge, else the longest."""
    full = full_discharges(steps)
    if full:
        return full[0]["number"]
    numbers = discharge_numbers(steps)
    return max((s for s in steps if s["number"] in numbers),
               key=lambda s: s["duration_s"])["number"]


def _numbers(numbers: list[int]) -> str:
    if len(numbers) > 12:
        return ", ".join(map(str, numbers[:10])) + f", ... ({len(numbers)} in all)"
    return ", ".join(map(str, numbers))


def _segment(step: dict) -> dict:
    """A discharge step in the shape of ``meta["segments"]`` entries."""
    return {"number": step["number"], "first_line": step["first_record"],
            "last_line": step["last_record"], "start_time_s": step["start_s"],
            "duration_s": step["duration_s"], "rows": step["rows"],
            "mean_current_A": step["mean_current_A"], "charge_Ah": step["charge_Ah"],
            "ended_by": "end of step" + (" at the lower voltage limit" if step.get("to_limit")
                                         else ""),
            "cycle": step["cycle"], "step": step["step"]}


def _rest_before(tester: TesterFile, step: dict, offset_s: float) -> dict | None:
    """The last record of the rest step just before ``step``, as its rest sample."""
    number = step["number"]
    if number < 2 or tester.step(number - 1)["kind"] != "rest":
        return None
    k = tester.bounds[number - 2][1] - 1
    row = tester.frame.iloc[k]
    rest = {"voltage_V": float(row["voltage_V"]), "time_s": float(row["time_s"]) - offset_s,
            "current_A": float(row["current_A"]), "line": int(tester.records[k]),
            "rule": "last record of the rest step before the discharge"}
    if "temperature_C" in tester.frame and np.isfinite(row["temperature_C"]):
        rest["temperature_C"] = float(row["temperature_C"])
    return rest


def _summary(meta: dict, sentence: str, step: dict | None, discharges: int) -> str:
    sentence = sentence.split("; segment ")[0]
    if step is None:
        return f"{sentence}; {len(meta['steps'])} steps ({discharges} discharges), every record"
    return (f"{describe_step(step)}; one of {discharges} discharge step(s); {sentence}"
            + ("" if step.get("after_charge") else "; it does not start after a charge"))


__all__ = ["detect_tester", "read_tester", "tester_reader", "read_step", "default_step",
           "used_steps_note",
           "fit_steps", "full_discharges", "discharge_numbers", "describe_step", "TesterFile",
           "TesterRecords", "STEP_KINDS", "TESTER_FORMATS"]
