"""The pure task of the logbook: one source file -> a small summary of its events.

:func:`summarise_source` reads a file with the readers (:mod:`dischargelab.io`),
splits it into its discharges or flights (the readers' segments) and returns a
:class:`SourceSummary`: the file's SHA-256, the reader's notes and one small dict
per event (numbers and a compact charge-voltage curve, never the samples). It never
touches the database and keeps no state, so it can run on any worker.

Per event (sign convention: discharge current positive; pack values):

* ``start_time`` (ISO 8601, when the file records a clock time), ``cycle`` (from
  a file name such as ``DischargeCycle010.txt``, when the file holds one event);
* ``discharged_Ah`` and ``discharged_Wh`` (trapezoid of I and V*I over time),
  ``duration_s``, mean and peak current;
* rest voltage before the load and, when the file goes on idle after it, the rest
  voltage after it and how long after the load it was read;
* minimum and end voltage and the end current;
* ``resistance_ohm``: the pack's resistance from its load steps (see
  :func:`step_resistance`), with a 95 % interval;
* temperatures (start, peak, ambient) and the per-cell voltage spread where the
  source logs cell voltages;
* ``reaches_knee``: the discharge ends on the steep end of its voltage curve
  (see :func:`knee_ratio`), i.e. at its cutoff;
* ``curve``: voltage and current at :data:`CURVE_POINTS` evenly spaced charges
  (what the health computation compares partial discharges against).
"""

from __future__ import annotations

import functools
import hashlib
import re
import tempfile
import zlib
from dataclasses import asdict, dataclass, field
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

from ..errors import DataError

#: zlib level of the kept raw file (6: about a third of a text log's size).
RAW_ZLIB_LEVEL = 6

#: Points of the compact charge-voltage curve kept per event.
CURVE_POINTS = 101

#: Load steps used for the resistance: at most this far apart [s] (so the open-circuit
#: voltage has not moved and the slow polarisation has not built up).
STEP_MAX_DT_S = 2.0

#: A load step counts when the current changes by at least this share of the event's
#: mean current (and :data:`STEP_MIN_A`).
STEP_MIN_FRACTION = 0.2

#: ... and by at least this much [A].
STEP_MIN_A = 0.2

#: The end of a discharge is at its knee when the voltage falls this many times faster
#: over the last :data:`KNEE_SPAN` of its charge than over the middle (20-80 %) of it.
KNEE_RATIO = 4.0

#: Share of the charge over which the end slope is measured.
KNEE_SPAN = 0.03

#: Reader formats that are flights.
FLIGHT_FORMATS = ("ardupilot-bin", "ardupilot-text", "ulog", "blackbox", "inflight-csv",
                  "flightlog-csv", "mavlink-tlog", "dji-raw", "dji-derived-csv")

#: Reader options a summary may be given (the rest are the logbook's own).
READER_OPTIONS = ("columns", "current_A", "sign", "units", "delimiter", "header", "fmt",
                  "battery")

#: A cycle number in a file name (``DischargeCycle042``); at most five digits, so a date
#: (``cycle_20240501``) is not read as one.
_CYCLE = re.compile(r"cycle[\s_\-]*0*(\d{1,5})(?!\d)", re.IGNORECASE)


@dataclass
class SourceSummary:
    """What one source file holds, small enough to send between processes.

    Attributes
    ----------
    sha256 : str
        SHA-256 of the file's bytes (hex).
    file_name : str
    size_bytes : int
    format : str
        Reader format (``lvm``, ``ulog``, ``dji-raw``...).
    notes : list of str
        The reader's notes (what it inferred), once per file.
    events : list of dict
        One per discharge or flight, in file order (keys in the module docstring).
    options : dict
        Reader options used.
    raw_zlib : bytes
        The file's bytes, zlib-compressed (what the logbook keeps to recompute any
        figure; compressed here, on the worker, so the client only writes it); empty
        when the logbook records only the file's path.
    """

    sha256: str
    file_name: str
    size_bytes: int
    format: str
    notes: list[str] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    options: dict = field(default_factory=dict)
    raw_zlib: bytes = b""

    def to_dict(self) -> dict:
        out = asdict(self)
        out.pop("raw_zlib")
        return out


def sha256_bytes(data: bytes) -> str:
    """SHA-256 of bytes (hex)."""
    return hashlib.sha256(data).hexdigest()


def sha256_file(path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file's bytes (hex), read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while True:
            block = fh.read(chunk)
            if not block:
                break
            digest.update(block)
    return digest.hexdigest()


def check_reader_options(options: dict | None) -> dict:
    """The reader options, checked by name (values are checked by the readers)."""
    options = dict(options or {})
    unknown = sorted(set(options) - set(READER_OPTIONS))
    if unknown:
        raise DataError(f"unknown reader option(s) {', '.join(unknown)}; use "
                        f"{', '.join(READER_OPTIONS)}")
    return {k: v for k, v in options.items() if v is not None}


def summarise_source(source, options: dict | None = None, keep_raw: bool = True
                     ) -> SourceSummary:
    """Read one file and summarise every discharge or flight in it.

    Parameters
    ----------
    source : path-like or (str, bytes)
        A file, or a file name and its bytes (an upload).
    options : dict, optional
        Reader options (:data:`READER_OPTIONS`, as :func:`dischargelab.io.read_discharge`).
    keep_raw : bool
        Also return the file's bytes compressed (``raw_zlib``), for the logbook to keep.

    Returns
    -------
    SourceSummary

    Raises
    ------
    DataError
        The file cannot be read or holds no discharge (one line, from the reader).
    """
    options = check_reader_options(options)
    if isinstance(source, tuple):
        name, data = source
        name = safe_file_name(name)
        with tempfile.TemporaryDirectory(prefix="dischargelab-") as folder:
            path = Path(folder) / name
            path.write_bytes(data)
            return _summarise_path(path, name, data, options, keep_raw)
    path = Path(source)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    data = path.read_bytes()
    return _summarise_path(path, path.name, data, options, keep_raw)


#: Longest file name kept for a file given as bytes [UTF-8 bytes] (file systems allow 255).
MAX_NAME_BYTES = 120


def safe_file_name(name) -> str:
    """A file name given with a file's bytes, safe to write in a folder of our own: the
    last path part, control characters replaced, at most :data:`MAX_NAME_BYTES` (the
    suffix kept, as the readers look at it), and ``upload`` for none, ``.`` or ``..``."""
    text = str(name).replace("\\", "/").rsplit("/", 1)[-1]
    text = re.sub(r"[\x00-\x1f\x7f]", "_", text).strip()
    if text in ("", ".", ".."):
        return "upload"
    stem, dot, suffix = text.rpartition(".")
    if not dot or len(suffix.encode()) > 16:
        stem, suffix = text, ""
    room = MAX_NAME_BYTES - len(suffix.encode()) - (1 if suffix else 0)
    stem = stem.encode()[:room].decode("utf-8", "ignore") or "upload"
    return f"{stem}.{suffix}" if suffix else stem


def _reader(path: Path, options: dict):
    """``read(segment=...)`` of one file, parsed once for all its discharges or flights."""
    from ..io import check_current_option, discharge_reader
    from ..io.flightlog import detect_flight_log, read_flight_discharge, read_flight_log

    if detect_flight_log(path) is None:
        return discharge_reader(path, **options)
    return functools.partial(read_flight_discharge, path, log=read_flight_log(path),
                             battery=options.get("battery"),
                             current_A=check_current_option(options.get("current_A")),
                             sign=options.get("sign") or "auto")


def _summarise_path(path: Path, name: str, data: bytes, options: dict,
                    keep_raw: bool = True) -> SourceSummary:
    read = _reader(path, options)
    first_frame, first_meta = read()
    segments = first_meta.get("segments") or []
    reads = [(first_frame, first_meta)]
    if len(segments) > 1:
        reads = [read(segment=s["number"]) for s in segments]
    try:
        whole, whole_meta = read(segment="none")
    except DataError:
        whole, whole_meta = None, None
    fmt = str(first_meta.get("format", "unknown"))
    cycle = None
    match = _CYCLE.search(Path(name).stem)
    if match and len(reads) == 1:
        cycle = int(match.group(1))
    events = []
    for index, (frame, meta) in enumerate(reads):
        event = summarise_event(frame, meta, whole, whole_meta)
        event["index"] = index
        event["kind"] = "flight" if fmt in FLIGHT_FORMATS else "discharge"
        event["cycle"] = meta.get("cycle", cycle)  # a tester's step knows its cycle
        events.append(event)
    notes = list(dict.fromkeys(n for _, meta in reads for n in meta.get("notes", [])))
    return SourceSummary(sha256=sha256_bytes(data), file_name=name, size_bytes=len(data),
                         format=fmt, notes=notes, events=events, options=options,
                         raw_zlib=zlib.compress(data, RAW_ZLIB_LEVEL) if keep_raw else b"")


def _start_time(meta: dict) -> str | None:
    """Clock time of the load start (ISO 8601), when the file records one."""
    offset = float(meta.get("time_offset_s") or 0.0)
    header = meta.get("lvm_header") or {}
    stamp = None
    if header.get("Date") and header.get("Time"):
        clock = str(header["Time"])
        clock = clock[:clock.index(".") + 7] if "." in clock else clock
        try:
            stamp = datetime.strptime(f"{header['Date']} {clock}", "%Y/%m/%d %H:%M:%S.%f")
        except ValueError:
            try:
                stamp = datetime.strptime(f"{header['Date']} {clock}", "%Y/%m/%d %H:%M:%S")
            except ValueError:
                stamp = None
    elif meta.get("start_time"):
        try:
            stamp = datetime.fromisoformat(str(meta["start_time"]))
        except ValueError:
            stamp = None
    if stamp is None:
        return None
    return (stamp + timedelta(seconds=offset)).isoformat(timespec="seconds")


def _finite(x) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


def summarise_event(frame, meta: dict, whole=None, whole_meta: dict | None = None) -> dict:
    """The numbers of one discharge or flight (see the module docstring).

    Parameters
    ----------
    frame, meta : DataFrame, dict
        One segment as :func:`dischargelab.io.read_discharge` returns it.
    whole, whole_meta : DataFrame, dict, optional
        The same file read with ``segment="none"`` (every row), for the rest after the load.
    """
    t = frame["time_s"].to_numpy(dtype=float)
    v = frame["voltage_V"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    dt = np.diff(t)
    charge = np.concatenate(([0.0], np.cumsum(0.5 * (i[1:] + i[:-1]) * dt))) / 3600.0
    energy = float(np.sum(0.5 * (i[1:] * v[1:] + i[:-1] * v[:-1]) * dt)) / 3600.0
    tail = slice(max(0, t.size - 3), t.size)
    rest = meta.get("rest_sample") or None
    after = _rest_after(meta, whole, whole_meta)
    resistance = step_resistance(t, v, i, rest=rest, after=after)
    event: dict = {
        "start_time": _start_time(meta),
        "duration_s": float(t[-1] - t[0]),
        "discharged_Ah": float(charge[-1]),
        "discharged_Wh": energy,
        "mean_current_A": float(charge[-1] * 3600.0 / (t[-1] - t[0])) if t[-1] > t[0]
        else float(np.mean(i)),
        "max_current_A": float(np.max(i)),
        "rest_voltage_V": None if rest is None else float(rest["voltage_V"]),
        "rest_after_V": None if after is None else after["voltage_V"],
        "rest_after_s": None if after is None else after["relaxed_s"],
        "min_voltage_V": float(np.min(v)),
        "end_voltage_V": float(np.median(v[tail])),
        "end_current_A": float(np.mean(i[tail])),
        "resistance_ohm": resistance[0],
        "resistance_interval95": resistance[1],
        "reaches_knee": bool(knee_ratio(charge, v) >= KNEE_RATIO),
        "cells": meta.get("cells"),
        "samples": int(t.size),
        "segment": meta.get("segment"),
    }
    event.update(_temperatures(frame, rest))
    event["cell_spread_V"] = _cell_spread(frame)
    event["curve"] = compact_curve(charge, v, i)
    return event


def compact_curve(charge_Ah, voltage_V, current_A, points: int = CURVE_POINTS) -> dict:
    """Voltage and current at ``points`` evenly spaced charges from 0 to the end [Ah, V, A]."""
    q = np.maximum.accumulate(np.asarray(charge_Ah, dtype=float))
    grid = np.linspace(0.0, q[-1], points)
    keep = np.concatenate(([True], np.diff(q) > 0))
    qv, vv, iv = q[keep], np.asarray(voltage_V, float)[keep], np.asarray(current_A, float)[keep]
    return {"charge_Ah": np.round(grid, 6).tolist(),
            "voltage_V": np.round(np.interp(grid, qv, vv), 5).tolist(),
            "current_A": np.round(np.interp(grid, qv, iv), 5).tolist()}


def knee_ratio(charge_Ah, voltage_V) -> float:
    """How many times faster the voltage falls at the end of a discharge than in its middle.

    End slope: voltage drop over the last :data:`KNEE_SPAN` of the charge; middle
    slope: over 20-80 % of it (both per Ah). A discharge to its cutoff ends on the
    steep end of the voltage curve (ratios of 10 and more); one stopped on the
    plateau gives about 1. Returns 0 for fewer than 10 samples or no charge.
    """
    q = np.maximum.accumulate(np.asarray(charge_Ah, dtype=float))
    v = np.asarray(voltage_V, dtype=float)
    total = q[-1] if q.size else 0.0
    if q.size < 10 or total <= 0:
        return 0.0
    at = lambda frac: float(np.interp(frac * total, q, v))  # noqa: E731
    middle = (at(0.2) - at(0.8)) / (0.6 * total)
    end = (at(1.0 - KNEE_SPAN) - float(np.median(v[-3:]))) / (KNEE_SPAN * total)
    if middle <= 0:
        return float("inf") if end > 0 else 0.0
    return float(end / middle)


def _noise(x: np.ndarray) -> float:
    """Sample noise from second differences (robust: MAD), same units as ``x``."""
    if x.size < 5:
        return 0.0
    d2 = np.diff(x, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def step_resistance(time_s, voltage_V, current_A, rest: dict | None = None,
                    after: dict | None = None) -> tuple[float | None, list | None]:
    """Pack resistance from the load steps of one event [ohm], with its 95 % interval.

    Every change of current between two samples at most :data:`STEP_MAX_DT_S`
    apart, by at least :data:`STEP_MIN_FRACTION` of the mean current, gives
    ``R = -dV/dI``; so do the step from the rest sample before the load to the
    first loaded sample and the step from the last loaded sample to the rest after
    it. The resistance is the median of these (the DC resistance over about a
    second, series resistance plus the fastest polarisation; cf. the pulse
    resistance of the FreedomCAR Battery Test Manual's hybrid pulse power test, with
    a shorter pulse).

    95 % interval: from the sample noise of voltage and current (second differences),
    widened to the spread of the steps when there are three or more (standard error
    of the median, 1.2533 sd/sqrt(n), sd from the MAD).

    Returns
    -------
    (resistance_ohm, [low, high]) or (None, None) when no step qualifies.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_V, dtype=float)
    i = np.asarray(current_A, dtype=float)
    if t.size < 2:
        return None, None
    level = max(STEP_MIN_A, STEP_MIN_FRACTION * abs(float(np.mean(i))))
    di, dv, dt = np.diff(i), np.diff(v), np.diff(t)
    sel = (np.abs(di) >= level) & (dt <= STEP_MAX_DT_S)
    values = list(-dv[sel] / di[sel])
    steps = list(np.abs(di[sel]))
    if rest is not None and rest.get("voltage_V") is not None:
        gap = t[0] - float(rest.get("time_s", t[0]))
        d_i = i[0] - float(rest.get("current_A") or 0.0)
        if abs(d_i) >= level and gap <= STEP_MAX_DT_S:
            values.append((float(rest["voltage_V"]) - v[0]) / d_i)
            steps.append(abs(d_i))
    if after is not None and after.get("first_current_A") is not None:
        d_i = i[-1] - after["first_current_A"]
        if abs(d_i) >= level and after["first_gap_s"] <= STEP_MAX_DT_S:
            values.append((after["first_voltage_V"] - v[-1]) / d_i)
            steps.append(abs(d_i))
    arr = np.array([x for x in values if np.isfinite(x) and x > 0])
    if arr.size == 0:
        return None, None
    r = float(np.median(arr))
    sv, si = _noise(v), _noise(i)
    d_i = float(np.median(steps))
    half = 1.96 * np.sqrt(2.0 * sv ** 2 + 2.0 * (r * si) ** 2) / d_i / np.sqrt(arr.size)
    if arr.size >= 3:
        sd = 1.4826 * float(np.median(np.abs(arr - r)))
        half = max(half, 1.96 * 1.2533 * sd / np.sqrt(arr.size))
    return r, [max(0.0, r - half), r + half]


def _rest_after(meta: dict, whole, whole_meta: dict | None) -> dict | None:
    """The idle samples after the load, from the whole file read with ``segment="none"``."""
    if whole is None or whole_meta is None or len(whole) < 2:
        return None
    offset = float(meta.get("time_offset_s") or 0.0)
    whole_offset = float(whole_meta.get("time_offset_s") or 0.0)
    t = whole["time_s"].to_numpy(dtype=float) + whole_offset
    i = whole["current_A"].to_numpy(dtype=float)
    v = whole["voltage_V"].to_numpy(dtype=float)
    threshold = meta.get("load_threshold_A")
    if threshold is None:
        threshold = 0.2 * float(np.percentile(np.abs(i), 98))
    segments = meta.get("segments") or []
    number = meta.get("segment")
    seg = next((s for s in segments if s.get("number") == number), None)
    end = offset + (float(seg["duration_s"]) if seg else 0.0)
    if seg is None:
        return None
    k = int(np.searchsorted(t, end + 1e-9, side="right"))
    idle = np.abs(i[k:]) < threshold
    if idle.size == 0 or not idle[0]:
        return None
    stop = idle.size if idle.all() else int(np.argmin(idle))
    rows = np.arange(k, k + stop)
    last = rows[-3:] if rows.size >= 3 else rows
    return {"voltage_V": float(np.median(v[last])),
            "relaxed_s": float(t[rows[-1]] - end),
            "first_voltage_V": float(v[rows[0]]), "first_current_A": float(i[rows[0]]),
            "first_gap_s": float(t[rows[0]] - end)}


def _temperatures(frame, rest: dict | None) -> dict:
    out: dict = {"temperature_start_C": None, "temperature_max_C": None, "ambient_C": None}
    if "temperature_C" in frame:
        temp = frame["temperature_C"].to_numpy(dtype=float)
        temp = temp[np.isfinite(temp)]
        if temp.size:
            start = rest.get("temperature_C") if rest else None
            out["temperature_start_C"] = _finite(start if start is not None else temp[0])
            out["temperature_max_C"] = float(np.max(temp))
    if "ambient_temperature_C" in frame:
        amb = frame["ambient_temperature_C"].to_numpy(dtype=float)
        amb = amb[np.isfinite(amb)]
        if amb.size:
            out["ambient_C"] = float(np.median(amb))
    return out


def _cell_spread(frame) -> float | None:
    """Largest minus smallest cell voltage [V], median over the last 10 % of the samples."""
    cells = [c for c in frame.columns if re.fullmatch(r"cell\d+_V", str(c))]
    if len(cells) < 2:
        return None
    values = frame[cells].to_numpy(dtype=float)
    values = values[np.all(np.isfinite(values), axis=1)]
    if values.size == 0:
        return None
    spread = values.max(axis=1) - values.min(axis=1)
    return float(np.median(spread[-max(1, spread.size // 10):]))


__all__ = ["SourceSummary", "summarise_source", "summarise_event", "sha256_file",
           "sha256_bytes", "step_resistance", "knee_ratio", "compact_curve",
           "check_reader_options", "READER_OPTIONS", "FLIGHT_FORMATS", "CURVE_POINTS"]
