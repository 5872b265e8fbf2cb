"""Flight logs with battery data: shared types, format detection, flights, cleaning.

Four families of logs are read, each by its own module behind the ``logs``
extra (``pip install 'dischargelab[logs]'``):

* ArduPilot DataFlash, binary ``.bin`` and text ``.log`` (:mod:`.ardupilot`);
* PX4 ULog (:mod:`.ulog`);
* Betaflight / INAV blackbox (:mod:`.blackbox`);
* in-flight logger CSV with per-cell columns, such as INA3221 monitors
  (:mod:`.inflight_csv`, needs no extra);
* MAVLink telemetry logs ``.tlog`` saved by a ground station (:mod:`.tlog`).


Every reader returns a :class:`~.flightlog_base.FlightLog` (the shared types, cleaning
and flight finding live in :mod:`.flightlog_base`, which no reader imports back).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError
from .flightlog_base import (  # the shared types, re-exported for callers
    BLACKBOX_MAGIC,
    DATAFLASH_HEAD,
    DROP_REASONS,
    EXPORT_MAGIC,
    FLIGHT_LOG_FORMATS,
    LOG_COLUMNS,
    MAX_PAUSE_S,
    MIN_ON_A,
    OFF_RATIO,
    ON_FRACTION,
    ULOG_MAGIC,
    BatterySeries,
    FlightLog,
    FlightSpan,
    _first_line,
    build_flight_log,
    choose_battery,
    choose_span,
    current_intervals,
)

# --------------------------------------------------------------------------- detection

def detect_flight_log(path) -> str | None:
    """Format of a flight log from its first bytes, or None for anything else.

    ULog starts with ``ULog`` 0x01 0x12 0x35, binary DataFlash with 0xA3 0x95,
    text DataFlash has lines starting ``FMT,`` near the top, blackbox starts
    with ``H Product:Blackbox flight data recorder``, a telemetry log with records of
    a UNIX time in microseconds and a MAVLink frame; in-flight logger CSV is
    recognised by its values (a pack column equal to the sum of the cell
    columns next to it), never by the file name.

    Returns
    -------
    str or None
        One of :data:`FLIGHT_LOG_FORMATS`, or None (missing file, folder, other data).
    """
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536)
    except OSError:
        return None
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if head.startswith(DATAFLASH_HEAD):
        return "ardupilot-bin"
    if head.startswith(BLACKBOX_MAGIC):
        return "blackbox"
    from .tlog import is_tlog

    if is_tlog(head):
        return "mavlink-tlog"
    if b"\x00" in head[:4096]:
        return None
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff")
    if text.startswith(EXPORT_MAGIC):
        return "flightlog-csv"
    lines = text.splitlines()
    if any(line.startswith("FMT,") for line in lines[:200]):
        return "ardupilot-text"
    from .inflight_csv import looks_like_inflight_csv

    if looks_like_inflight_csv(lines[:-1] if len(head) == 65536 else lines):
        return "inflight-csv"
    return None


# --------------------------------------------------------------------------- reading

def read_flight_log(path, *, battery: int | None = None, flight: int | None = None,
                    topic: str | None = None, fields: dict | None = None) -> FlightLog:
    """Read the battery data of a flight log.

    Parameters
    ----------
    path : str or path-like
        ArduPilot ``.bin``/``.log``, PX4 ``.ulg``, blackbox ``.bbl``/``.bfl``,
        MAVLink telemetry ``.tlog`` or in-flight logger CSV; the format is found
        from the content.
    battery : int, optional
        Keep only this battery instance (PX4 ``multi_id``, ArduPilot instance).
    flight : int, optional
        Keep only this flight (1-based).
    topic : str, optional
        ULog topic or DataFlash message holding the battery data when it is
        not the standard one (``battery_status``; ``BAT``/``CURR``).
    fields : dict, optional
        With ``topic``: canonical name -> field, e.g. ``{"voltage_V":
        "bus_voltage", "current_A": "bus_current"}``; the fields must be in
        V and A. ``voltage_V`` and ``current_A`` are required.

    Returns
    -------
    FlightLog

    Raises
    ------
    DataError
        Not a flight log, corrupt or truncated beyond use, no battery data,
        or no such battery/flight; one line saying how to fix it.
    MissingExtraError
        The reader's optional dependency is not installed.
    """
    path = Path(path)
    if not path.exists():
        raise DataError(f"file not found: {path}")
    if path.is_dir():
        raise DataError(f"{path} is a folder; give a flight-log file")
    kind = detect_flight_log(path)
    if kind is None:
        raise DataError(f"{path.name} is not a flight log this version reads (ArduPilot .bin/.log, "
                        "PX4 .ulg, Betaflight/INAV blackbox, MAVLink telemetry .tlog, in-flight "
                        "logger CSV with per-cell columns); a bench discharge, a tester's file or "
                        "a DJI app log is read as a discharge (dl.read, as `dischargelab fit` "
                        "and `logbook add` do)")
    if (topic is not None or fields is not None) and kind not in ("ulog", "ardupilot-bin",
                                                                 "ardupilot-text"):
        raise DataError(f"{path.name}: topic= and fields= apply to ULog and DataFlash logs only "
                        f"(this is {kind})")
    if fields is not None:
        fields = _check_fields(fields)
    log = _READERS[kind](path, topic=topic, fields=fields)
    if battery is not None:
        series = choose_battery(log, battery)[0]
        log = replace(log, batteries=[series])
    if flight is not None:
        log = log.flight(flight)
    return log


def _read_ardupilot(path, *, topic, fields):
    from .ardupilot import read_dataflash
    return read_dataflash(path, topic=topic, fields=fields)


def _read_ulog(path, *, topic, fields):
    from .ulog import read_ulog
    return read_ulog(path, topic=topic, fields=fields)


def _read_blackbox(path, *, topic, fields):
    from .blackbox import read_blackbox
    return read_blackbox(path)


def _read_tlog(path, *, topic, fields):
    from .tlog import read_tlog
    return read_tlog(path)


def _read_inflight(path, *, topic, fields):
    from .inflight_csv import read_inflight_csv
    return read_inflight_csv(path)


def _read_export(path, *, topic, fields):
    """A CSV written by :func:`convert_flight_log`: flights from its ``flight`` column."""
    with open(path, encoding="utf-8") as fh:
        first = fh.readline()
    try:
        info = json.loads(first[len(EXPORT_MAGIC):])
        frame = pd.read_csv(path, comment="#")
    except (json.JSONDecodeError, ValueError, pd.errors.ParserError) as exc:
        raise DataError(f"{Path(path).name}: damaged flight-log export ({_first_line(exc)}); "
                        "convert the flight log again") from None
    missing = [c for c in ("time_s", "voltage_V", "current_A", "flight") if c not in frame]
    if missing or not isinstance(info, dict):
        raise DataError(f"{Path(path).name}: damaged flight-log export (no "
                        f"{', '.join(missing) or 'header'}); convert the flight log again")
    flight = pd.to_numeric(frame.pop("flight"), errors="coerce").fillna(0).to_numpy()
    t = pd.to_numeric(frame["time_s"], errors="coerce").to_numpy(dtype=float)
    spans = [(float(np.nanmin(t[flight == n])), float(np.nanmax(t[flight == n])))
             for n in sorted(set(flight[flight > 0].tolist()))]
    series = BatterySeries(index=int(info.get("battery") or 0),
                           label=str(info.get("label") or "battery"), frame=frame,
                           cells=info.get("cells"), capacity_mAh=info.get("capacity_mAh"))
    notes = [f"flight-log export of {info.get('source')} ({info.get('format')}); flights from "
             "its flight column"]
    return build_flight_log(path, "flightlog-csv", [series], start_s=0.0, spans=spans,
                            found_by="flight column", notes=notes)


_READERS = {"ardupilot-bin": _read_ardupilot, "ardupilot-text": _read_ardupilot,
            "ulog": _read_ulog, "blackbox": _read_blackbox, "inflight-csv": _read_inflight,
            "flightlog-csv": _read_export, "mavlink-tlog": _read_tlog}


def _check_fields(fields) -> dict:
    if isinstance(fields, str):
        pairs = [p.partition("=") for p in fields.split(",") if p.strip()]
        if any(not sep for _, sep, _ in pairs):
            raise DataError(f"fields expects NAME=FIELD pairs, e.g. voltage_V=bus_voltage,"
                            f"current_A=bus_current; got {fields!r}")
        fields = {k.strip(): v.strip() for k, _, v in pairs}
    fields = dict(fields)
    allowed = ("time_s", "voltage_V", "current_A", "temperature_C") + LOG_COLUMNS
    unknown = [k for k in fields if k not in allowed]
    if unknown:
        raise DataError(f"fields: unknown name(s) {', '.join(unknown)}; use "
                        f"{', '.join(allowed)}")
    missing = [k for k in ("voltage_V", "current_A") if k not in fields]
    if missing:
        raise DataError(f"fields must name the log fields for {' and '.join(missing)}, e.g. "
                        "{'voltage_V': 'bus_voltage', 'current_A': 'bus_current'}")
    return fields



def read_flight_discharge(path, *, flight=None, battery=None, current_A=None, sign="auto",
                          segment="auto", rest_sample="auto", log: FlightLog | None = None
                          ) -> tuple[pd.DataFrame, dict]:
    """One flight of one battery as :func:`dischargelab.io.read_discharge` returns it.

    ``flight`` None takes the longest flight (``segment`` N, when given, picks
    flight N; ``segment="none"`` keeps every sample); ``battery`` None the
    first battery with samples. The frame goes through the same checks as
    every other reader (:func:`dischargelab.io.prepare.prepare`); the sign is
    known (discharge positive) unless ``sign`` says otherwise. The idle sample
    just before the flight, when there is one within :data:`MAX_PAUSE_S`,
    becomes ``meta["rest_sample"]``. ``log``: the log of ``path`` already read by
    :func:`read_flight_log` (several flights of one log read once; it is not changed).
    """
    from .columns import CanonicalTable
    from .prepare import check_segment_option, prepare, summary_sentence

    segment = check_segment_option(segment)
    if log is None:
        log = read_flight_log(path)
    series, notes = choose_battery(log, battery)
    if flight is None and isinstance(segment, int):
        flight = segment
    frame = series.frame
    t = frame["time_s"].to_numpy(dtype=float)
    number = frame["flight"].to_numpy()
    span = None
    if flight is not None:
        span = choose_span(log, flight)
    elif segment != "none" and log.spans:
        span = max(log.spans, key=lambda s: s.duration_s)
        if len(log.spans) > 1:
            notes.append(f"flight {span.number} of {len(log.spans)} kept (the longest); choose "
                         f"another with flight=N (--flight N)")
    if span is None:
        keep = np.ones(t.size, dtype=bool)
        if segment != "none":
            notes.append("no flight found (no arm/disarm, take-off/landing or sustained "
                         "current): every sample kept")
    else:
        keep = number == span.number
    positions = np.flatnonzero(keep)
    if positions.size < 2:
        raise DataError(f"{Path(log.source).name}: {series.label} has {positions.size} sample(s) "
                        f"in flight {span.number if span else ''}; choose another battery or "
                        f"flight")
    first, last = int(positions[0]), int(positions[-1])
    reader_dropped = {k: v for k, v in series.dropped.items() if v}
    idle = number == 0
    reader_dropped["rest"] = int(np.sum(~keep[:first] & idle[:first]))
    reader_dropped["relaxation"] = int(np.sum(~keep[last + 1:] & idle[last + 1:]))
    reader_dropped["other_segments"] = int(np.sum(~keep & ~idle))
    kept = frame.iloc[positions].reset_index(drop=True)
    meta = {"format": log.format, "source": str(path), "reader_dropped": reader_dropped,
            "notes": list(log.notes) + notes + list(series.notes),
            "explicit_units": ["time_s", "voltage_V", "current_A"],
            "column_map": {c: c for c in ("time_s", "voltage_V", "current_A",
                                          "temperature_C") if c in kept},
            "units": dict.fromkeys(("time_s", "voltage_V", "current_A"), "canonical (flight log)")}
    table = CanonicalTable(frame=kept, line_numbers=positions + 1, meta=meta)
    given_sign = "positive" if sign == "auto" else sign
    out, meta = prepare(table, Path(path).name, current_A=current_A, sign=given_sign,
                        segment="none", rest_sample="none")
    if sign == "auto":
        meta["sign_source"] = "flight log (discharge positive by the reader)"
    meta.update({
        "battery": series.index, "battery_label": series.describe(), "cells": series.cells,
        "capacity_mAh": series.capacity_mAh, "current_offset_A": series.current_offset_A,
        "flight": span.number if span else None, "flights": [s.to_dict() for s in log.spans],
        "segment": span.number if span else None,
        "segments": [_segment_dict(s, frame) for s in log.spans],
        "events": log.events, "flight_log_summary": log.summary(),
    })
    if log.start_time:
        meta["start_time"] = log.start_time
    meta["rest_sample"] = (_rest_before(frame, first, meta["time_offset_s"])
                           if rest_sample == "auto" and span is not None else None)
    meta["summary"] = summary_sentence(meta)
    if len(log.spans) > 1 and span is not None:
        meta["summary"] = meta["summary"].replace(f"segment {span.number} of", "flight "
                                                  f"{span.number} of")
    if series.current_offset_A is not None:
        meta["summary"] += f"; current offset {series.current_offset_A:.3g} A (not subtracted)"
    return out, meta


def _segment_dict(span: FlightSpan, frame: pd.DataFrame) -> dict:
    inside = np.flatnonzero(frame["flight"].to_numpy() == span.number)
    t = frame["time_s"].to_numpy(dtype=float)[inside]
    i = frame["current_A"].to_numpy(dtype=float)[inside]
    charge = float(np.sum(0.5 * (i[1:] + i[:-1]) * np.diff(t)) / 3600.0) if t.size > 1 else 0.0
    return {"number": span.number,
            "first_line": int(inside[0]) + 1 if inside.size else 0,
            "last_line": int(inside[-1]) + 1 if inside.size else 0,
            "start_time_s": span.start_s, "duration_s": span.duration_s,
            "rows": int(inside.size), "mean_current_A": float(i.mean()) if i.size else 0.0,
            "charge_Ah": charge, "ended_by": span.found_by}


def _rest_before(frame: pd.DataFrame, first: int, offset_s: float) -> dict | None:
    """The idle sample just before the flight, as a rest sample, or None."""
    if first == 0:
        return None
    k = first - 1
    t = frame["time_s"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    threshold = max(MIN_ON_A, ON_FRACTION * float(np.percentile(i, 99))) * OFF_RATIO
    if frame["flight"].iloc[k] != 0 or t[first] - t[k] > MAX_PAUSE_S or i[k] > threshold:
        return None
    row = {"voltage_V": float(frame["voltage_V"].iloc[k]), "time_s": float(t[k] - offset_s),
           "current_A": float(i[k]), "line": k + 1,
           "rule": "last idle sample before the flight"}
    if "temperature_C" in frame and np.isfinite(frame["temperature_C"].iloc[k]):
        row["temperature_C"] = float(frame["temperature_C"].iloc[k])
    return row


# --------------------------------------------------------------------------- export

#: Columns of the canonical CSV, in this order (those present).
EXPORT_FIRST = ("time_s", "voltage_V", "current_A", "temperature_C")


def convert_flight_log(path, out, *, flight: int | None = None, battery: int | None = None,
                       force: bool = False, topic: str | None = None,
                       fields: dict | None = None) -> dict:
    """Write one battery of a flight log as a canonical CSV file.

    Columns: ``time_s, voltage_V, current_A`` [s, V, A discharge positive],
    ``temperature_C`` and ``cell1_V``... when measured, the log's own columns,
    ``session`` for a file of several joined recordings, and ``flight`` (0
    outside any flight). Two ``#`` comment lines at the top
    name the source (JSON) and summarise it; :func:`read_flight_log` and
    :func:`dischargelab.io.read_discharge` read the file back with its
    flights. The file is written atomically
    (:func:`dischargelab.atomic.write_text`): a crash never leaves a
    half-written file.

    Parameters
    ----------
    path : path-like
        Flight log.
    out : path-like
        CSV file to write.
    flight : int, optional
        Only this flight (1-based); default every sample.
    battery : int, optional
        Battery instance; default the first with samples.
    force : bool
        Overwrite an existing ``out`` (never the input).
    topic, fields : optional
        Where the battery data is when not in the standard topic (see
        :func:`read_flight_log`).

    Returns
    -------
    dict
        ``output``, ``rows``, ``battery``, ``flight``, ``flights``,
        ``charge_mAh``, ``summary``, ``notes``.

    Raises
    ------
    dischargelab.atomic.OutputExistsError
        ``out`` exists and ``force`` is false.
    dischargelab.atomic.OutputIsInputError
        ``out`` is the input file.
    DataError
        The log cannot be read, or has no such battery or flight.
    """
    from ..atomic import check_outputs, write_text

    path, out = Path(path), Path(out)
    check_outputs(out, inputs=[path], force=force)
    log = read_flight_log(path, topic=topic, fields=fields)
    series, notes = choose_battery(log, battery)
    part = log.flight(flight) if flight is not None else log
    series = next(b for b in part.batteries if b.index == series.index)
    if series.rows == 0:
        raise DataError(f"{path.name}: battery {series.index} has no samples in flight {flight}")
    frame = series.frame
    columns = [c for c in EXPORT_FIRST if c in frame] + series.cell_columns + \
        [c for c in LOG_COLUMNS if c in frame] + [c for c in ("session", "flight") if c in frame]
    info = {"source": path.name, "format": log.format, "battery": series.index,
            "label": series.label, "cells": series.cells, "capacity_mAh": series.capacity_mAh,
            "flight": flight}
    header = (EXPORT_MAGIC + json.dumps(info) + "\n# " + part.summary().replace("\n", " ")
              + "\n")
    body = _rounded(frame[columns]).to_csv(index=False, lineterminator="\n")
    write_text(out, header + body)
    return {"output": str(out), "source": str(path), "format": log.format,
            "battery": series.index, "battery_label": series.describe(), "flight": flight,
            "flights": len(log.spans), "rows": series.rows, "columns": columns,
            "charge_mAh": series.charge_mAh(), "current_offset_A": series.current_offset_A,
            "summary": part.summary(), "notes": notes + list(series.notes)}


def _rounded(frame: pd.DataFrame) -> pd.DataFrame:
    digits = {"time_s": 6, "voltage_V": 5, "current_A": 5, "temperature_C": 3}
    out = frame.copy()
    for column in out.columns:
        if out[column].dtype.kind == "f":
            out[column] = out[column].round(digits.get(column, 6))
    return out


__all__ = ["FlightLog", "BatterySeries", "FlightSpan", "detect_flight_log", "read_flight_log",
           "convert_flight_log", "build_flight_log", "current_intervals", "FLIGHT_LOG_FORMATS",
           "LOG_COLUMNS", "DROP_REASONS"]

