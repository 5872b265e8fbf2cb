"""Read real discharge files into canonical columns.

One entry point, :func:`read_discharge`, for every supported source:

* delimited text: CSV, TSV, semicolon or whitespace separated, with or
  without header, byte-order mark, CRLF, comment lines (:mod:`.text`);
* LabVIEW measurement files ``.lvm`` (:mod:`.lvm`);
* DJI ground-station app logs with ``Battery updated`` records, and the CSV
  derived from them (:mod:`.dji`);
* dischargelab's own logger files (first line ``# dischargelab-log v1``,
  :mod:`.logfile`);
* flight logs: ArduPilot DataFlash, PX4 ULog, Betaflight/INAV blackbox, MAVLink
  telemetry logs and in-flight logger CSV with per-cell columns
  (:mod:`.flightlog`; one flight of one battery is returned);
* battery testers' files: Neware ``.nda``/``.ndax``, BioLogic ``.mpr``, Arbin
  ``.res``/CSV/``.xlsx``, Maccor text exports (:mod:`.cyclers`; one step is
  returned, with the tester's ``cycle_index`` and ``step_index``).

Every reader returns ``(DataFrame, meta)``; the frame has ``time_s`` (0 at load
start), ``voltage_V``, ``current_A`` (discharge positive) and, when present,
``temperature_C`` plus reader extras (``soc_pct``, ``flight_mode``...).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError
from .columns import (
    CANONICAL_COLUMNS,
    COLUMN_KEYS,
    CanonicalTable,
    map_columns,
    parse_columns,
    parse_units,
    validate_columns,
    validate_units,
)
from .cyclers import (
    detect_tester,
    discharge_numbers,
    fit_steps,
    tester_reader,
)
from .dji import BATTERY_MARK, flight_breaks, is_dji_raw, mode_events, read_dji_raw
from .flightlog import detect_flight_log, read_flight_discharge
from .lvm import is_lvm, read_lvm
from .prepare import check_current_option, check_segment_option, describe, prepare
from .text import load_text, read_delimited

#: First line of a dischargelab logger file.
LOG_MAGIC = "# dischargelab-log v1"

#: Accepted values of ``fmt``.
FORMATS = ("auto", "text", "lvm", "dji-raw", "dischargelab-log")


def detect_format(text: str) -> str:
    """Name of the format of a file's text (one of :data:`FORMATS` except ``"auto"``)."""
    stripped = text.lstrip("\ufeff \t\r\n")
    first = stripped[:stripped.find("\n")] if "\n" in stripped else stripped
    if first.strip().startswith(LOG_MAGIC):
        return "dischargelab-log"
    if is_lvm(first):
        return "lvm"
    if BATTERY_MARK in stripped or is_dji_raw(first):
        return "dji-raw"
    return "text"


def read_discharge(path, *, columns=None, current_A=None, sign="auto", units=None,
                   segment="auto", delimiter=None, header="auto", fmt="auto",
                   rest_sample="auto", flight=None, battery=None):
    """Read one discharge from a file.

    Parameters
    ----------
    path : str or path-like
        Data file.
    columns : dict or str, optional
        Which source column holds which quantity: ``{"time_s": 0, "current_A": 1,
        "voltage_V": 2, "temperature_C": 4}`` (0-based numbers or header names),
        or the ``--columns`` text ``"time_s=0,current_A=1,voltage_V=2"``. Columns
        not given are found by header name; a headerless two-column file is read
        as (time_s, voltage_V).
    current_A : float, optional
        Constant discharge current [A] (``--current``), for files without a
        current column; if the file has one, it is used only to find the
        discharge and the given value replaces it (noted in ``meta["notes"]``).
    sign : {"auto", "positive", "negative"}
        Sign of the discharge current in the file (``--sign``). ``"auto"``
        detects it from the voltage trend under load.
    units : dict or str, optional
        Source units, e.g. ``{"voltage_V": "mV", "time_s": "h"}`` or
        ``"voltage_V=mV,time_s=h"`` (``--units``); otherwise read from header
        names such as ``"Voltage (mV)"`` or ``"current_mA"``, else V, A, s, degC.
    segment : "auto", "none" or int
        ``"auto"``: the longest discharge segment; ``"none"``: every valid row;
        ``N``: the N-th segment counting from 1 (``--segment``). Tester files
        (Neware, BioLogic, Arbin, Maccor): ``N`` is step N of the file (a discharge
        step, ``--step N``; ``meta["steps"]`` lists them), ``"auto"`` the first full
        discharge (from a charge to the lower voltage limit).
    delimiter : str, optional
        ``","``, ``"\\t"``, ``";"``, ``"|"`` or ``"whitespace"``; detected when None.
    header : {"auto", True, False}
        Whether the first line is a header; detected by default.
    fmt : {"auto", "text", "lvm", "dji-raw", "dischargelab-log"}
        File format; detected from the content by default.
    rest_sample : {"auto", "none"}
        Keep the rest sample before the load step in ``meta["rest_sample"]``.
    flight : int, optional
        Flight logs (ArduPilot, PX4 ULog, blackbox, MAVLink .tlog, in-flight CSV; found
        from the content): the flight to keep, counting from 1 (``--flight``);
        default the longest (:mod:`.flightlog`).
    battery : int, optional
        Flight logs: the battery instance (``--battery``); default the first
        with samples, the others named in ``meta["notes"]``.

    Returns
    -------
    frame : pandas.DataFrame
        ``time_s`` [s] from 0 at load start, ``voltage_V`` [V], ``current_A`` [A]
        (discharge positive), optional ``temperature_C`` [degC] and extras.
    meta : dict
        ``source``, ``format``, ``sign_convention`` ("discharge positive" or
        "discharge negative (flipped)"), ``sign_source``, ``current_source``
        ("column" or "given"), ``dropped`` (rows by reason), ``summary`` (one
        sentence), ``rest_sample`` (``{"voltage_V", "time_s", "current_A",
        "line", "rule"}`` or None; time relative to load start), ``segments``
        (every discharge segment found), ``segment`` (number kept), for tester
        files ``steps`` (every step: number, cycle, step, kind, times, charge) and
        ``step`` (the one kept),
        ``time_offset_s`` (file time of load start), ``column_map``, ``units``,
        ``notes`` (everything inferred), plus reader keys (``events``...).

    Raises
    ------
    DataError
        One line saying what is wrong and which option fixes it.
    """
    check_segment_option(segment)
    read = discharge_reader(path, columns=columns, current_A=current_A, sign=sign,
                            units=units, delimiter=delimiter, header=header, fmt=fmt,
                            rest_sample=rest_sample, flight=flight, battery=battery)
    return read(segment=segment)


#: What :func:`read_discharges` takes from a tester file when no step is named.
CHOICES = ("fit", "all")


def read_discharges(path, *, steps=None, choose: str = "fit", segment="auto", **options
                    ) -> list[tuple[pd.DataFrame, dict]]:
    """The discharges of a file a command works on: several for a tester file.

    Parameters
    ----------
    path : str or path-like
    steps : sequence of int, optional
        Tester files: the steps to read (``--step``; numbers as in ``meta["steps"]``).
    choose : {"fit", "all"}
        Tester files without ``steps`` or ``segment``: ``"fit"`` the discharge steps
        worth fitting (:func:`dischargelab.io.cyclers.fit_steps`), ``"all"`` every
        discharge step. Each meta says why in ``chosen_by``.
    segment, **options
        As :func:`read_discharge`; other files give one discharge.

    Returns
    -------
    list of (frame, meta)

    Raises
    ------
    DataError
        As :func:`read_discharge`; ``steps`` for a file that is not a tester file.
    """
    if choose not in CHOICES:
        raise DataError(f"choose must be one of {', '.join(CHOICES)}; got {choose!r}")
    segment = check_segment_option(segment)
    if _tester_kind(path, options.get("fmt", "auto"), options.get("columns")) is None:
        if steps is not None:
            raise DataError(f"{Path(path).name} is not a battery tester file: steps apply to "
                            "Neware, BioLogic, Arbin and Maccor files; choose a discharge with "
                            "segment=N (--segment N)")
        return [read_discharge(path, segment=segment, **options)]
    read = discharge_reader(path, **options)
    tester = read.tester
    if steps is None and segment != "auto":
        return [read(segment=segment)]
    if steps is not None:
        numbers = [check_segment_option(n) for n in steps]
        why = "named by step"
    elif choose == "fit":
        numbers, why = fit_steps(tester.steps)
    else:
        numbers, why = discharge_numbers(tester.steps), "every discharge step"
    if not numbers:
        return [read(segment="auto")]
    out = []
    for number in numbers:
        frame, meta = read(segment=number)
        meta["chosen_by"] = why
        out.append((frame, meta))
    return out


def discharge_label(meta: dict) -> str:
    """A short label of a read discharge: the file's stem, and the step of a tester file
    (``"maccor_001 step 7"``)."""
    label = Path(str(meta.get("source") or meta.get("name") or "data")).stem
    step = meta.get("step")
    return f"{label} step {step['number']}" if isinstance(step, dict) else label


def discharge_reader(path, *, columns=None, current_A=None, sign="auto", units=None,
                     delimiter=None, header="auto", fmt="auto", rest_sample="auto",
                     flight=None, battery=None) -> Callable[..., tuple[pd.DataFrame, dict]]:
    """Parse a file once; ``read(segment="auto")`` then gives any of its discharges.

    The arguments are :func:`read_discharge`'s (without ``segment``), and
    ``read(segment=...)`` returns what ``read_discharge(path, ..., segment=...)``
    would, without parsing the text again (the logbook reads every segment and the
    whole file). A flight log is parsed at each call, as :func:`read_discharge` does.

    Raises
    ------
    DataError
        As :func:`read_discharge`, for the file and the options.
    """
    path = Path(path)
    name = path.name
    if fmt not in FORMATS:
        raise DataError(f"format must be one of {', '.join(FORMATS)}; got {fmt!r}")
    if isinstance(columns, str):
        columns = parse_columns(columns)
    elif columns is not None:
        columns = validate_columns(dict(columns))
    if isinstance(units, str):
        units = parse_units(units)
    elif units is not None:
        units = validate_units(dict(units))
    given = check_current_option(current_A)

    flight_log = detect_flight_log(path) if fmt == "auto" else None
    if flight_log is not None:
        return functools.partial(read_flight_discharge, path, flight=flight, battery=battery,
                                 current_A=given, sign=sign, rest_sample=rest_sample)
    tester = _tester_kind(path, fmt, columns)
    if tester is not None:
        if flight is not None or battery is not None:
            raise DataError(f"{name} is a battery tester file: --flight and --battery apply to "
                            "flight logs; choose a step with --step N")
        if units:
            raise DataError(f"{name} is a battery tester file: its units come from the file; "
                            "leave --units out")
        return tester_reader(path, kind=tester, current_A=given, sign=sign,
                             rest_sample=rest_sample)
    if flight is not None or battery is not None:
        raise DataError(f"{name} is not a flight log (ArduPilot, PX4 ULog, blackbox, telemetry "
                        ".tlog, in-flight logger CSV): --flight and --battery apply only to "
                        "those; use --segment N to choose a discharge")
    text, encoding = load_text(path)
    kind = detect_format(text) if fmt == "auto" else fmt
    if kind == "dischargelab-log":
        table, logged_current = _read_logfile(path)
        if given is None and logged_current is not None:
            given = logged_current
            table.meta["notes"].append(f"constant current {given:g} A from the log header")
    elif kind == "dji-raw":
        table = read_dji_raw(text, name)
        ignored = [opt for opt, val in (("--columns", columns), ("--units", units)) if val]
        if ignored:
            table.meta["notes"].append(f"{' and '.join(ignored)} ignored: DJI logs have fixed "
                                       "fields")
    else:
        if kind == "lvm":
            source = read_lvm(text, name, delimiter=delimiter)
        else:
            source = read_delimited(text, name, delimiter=delimiter, header=header,
                                    meta={"format": "text"})
            if source.names and "flight_mode_last_event" in source.names:
                source.meta["format"] = "dji-derived-csv"
        table = map_columns(source, name, columns=columns, units=units)
        if table.meta.get("format") == "dji-derived-csv" and "flight_mode" in table.frame:
            table.breaks_s = flight_breaks(mode_events(table.frame["time_s"],
                                                       table.frame["flight_mode"]))
    table.meta.setdefault("format", kind)
    table.meta["source"] = str(path)
    table.meta["encoding"] = encoding["encoding"] + (" with BOM" if encoding.get("bom") else "")
    # prepare() copies the rows and the metadata it changes, so the table serves every call
    return functools.partial(prepare, table, name, current_A=given, sign=sign,
                             rest_sample=rest_sample)


def _tester_kind(path, fmt: str, columns) -> str | None:
    """What :func:`dischargelab.io.cyclers.detect_tester` says, unless the format or the
    columns are given (a table read as the user maps it) or the path is a flight log."""
    if fmt != "auto" or columns is not None or detect_flight_log(path) is not None:
        return None
    return detect_tester(path)


def _read_logfile(path: Path) -> tuple[CanonicalTable, float | None]:
    try:
        from .logfile import read_log
    except ImportError:
        raise DataError(f"{path.name} is a dischargelab log file, but this installation has no "
                        "reader for it (dischargelab.io.logfile)") from None
    frame, meta = read_log(path)
    meta = dict(meta)
    meta["format"] = "dischargelab-log"
    meta.setdefault("notes", [])
    meta["reader_dropped"] = meta.pop("dropped", {})
    logged_current = None
    if meta.pop("current_source", None) == "given" and "current_A" in frame:
        logged_current = float(frame.pop("current_A").iloc[0]) if len(frame) else None
    meta.pop("sign_convention", None)
    meta["column_map"] = {c: c for c in frame.columns if c in COLUMN_KEYS}
    meta["units"] = {c: "canonical" for c in frame.columns if c in COLUMN_KEYS}
    meta["explicit_units"] = [c for c in frame.columns if c in COLUMN_KEYS]
    frame = frame.reset_index(drop=True)
    if "line" in frame:
        lines = frame.pop("line").to_numpy()
    else:
        lines = np.arange(1, len(frame) + 1)
        meta["notes"].append("line numbers in messages count data rows of the log, not file lines")
    return CanonicalTable(frame=frame, line_numbers=lines, meta=meta), logged_current


__all__ = ["read_discharge", "read_discharges", "discharge_label", "discharge_reader", "describe",
           "parse_columns", "parse_units", "detect_format", "FORMATS", "CANONICAL_COLUMNS",
           "COLUMN_KEYS", "LOG_MAGIC"]
