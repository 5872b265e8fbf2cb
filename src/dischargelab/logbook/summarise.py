"""The pure task of the logbook: one source file -> a small summary of its events.

:func:`summarise_source` reads a file with the readers (:mod:`dischargelab.io`) and
returns a :class:`SourceSummary`: the file's SHA-256, the reader's notes and one small
dict per event (numbers and a compact charge-voltage curve, never the samples). It never
touches the database and keeps no state, so it can run on any worker.

* A **long log** -- a tester's file with step numbers, or any log whose charges move at
  least 5 % of what its discharges move (a BMS log, a cell's whole life, a day of
  flights with the charger) -- is split into discharges, charges, rests and gaps by
  :func:`dischargelab.logbook.events.split_log`, one event each.
* Any other file gives one event per discharge or flight (the readers' segments), with
  the rests on either side read from the whole file.

Every discharge, flight and charge carries ``details`` (stored as JSON): the rest
readings before and after it (voltage, what is left to relax, idle current,
temperature), the charge counted between them and how well the samples count it, the
resistance's method, per-cell figures, its rows in the file read whole and, for a
charge, what it moved and whether it ended in a constant-voltage taper.

Per event (sign convention: discharge current positive; pack values):

* ``kind`` (:data:`dischargelab.logbook.events.KINDS`), ``start_time`` (ISO 8601,
  when the file records a clock time), ``cycle`` (from a file name such as
  ``DischargeCycle010.txt``, when the file holds one event);
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
from .estimates import step_resistance
from .events import (
    CURVE_POINTS,
    LogArrays,
    after_sample,
    compact_curve,
    event_details,
    is_long_log,
    knee_ratio,
    load_figures,
    log_events,
    rest_of,
    rest_sample,
    split_log,
)

#: zlib level of the kept raw file (6: about a third of a text log's size).
RAW_ZLIB_LEVEL = 6

#: Reader formats that are flights.
FLIGHT_FORMATS = ("ardupilot-bin", "ardupilot-text", "ulog", "blackbox", "inflight-csv",
                  "flightlog-csv", "mavlink-tlog", "dji-raw", "dji-derived-csv")

#: Reader options a summary may be given (the rest are the logbook's own).
READER_OPTIONS = ("columns", "current_A", "sign", "units", "delimiter", "header", "fmt",
                  "battery")

#: A cycle number in a file name (``DischargeCycle042``); at most five digits, so a date
#: (``cycle_20240501``) is not read as one.
_CYCLE = re.compile(r"cycle[\s_\-]*0*(\d{1,5})(?!\d)", re.IGNORECASE)


#: A date and time in a file name (``2020_01_21_20_55``, ``20200121-205530``,
#: ``2020-01-21T20.55``): year, month, day, hour, minute, optional seconds. A date alone
#: (``2020-01-21``) is read at midnight.
_NAME_CLOCK = re.compile(r"(?<!\d)(20\d\d|19\d\d)[-_.]?(\d\d)[-_.]?(\d\d)"
                         r"(?:[T_\- ]?(\d\d)[-_.:h]?(\d\d)(?:[-_.:m]?(\d\d))?)?(?!\d)")


def name_clock(name) -> datetime | None:
    """The date and time a file name carries (loggers and ground-station apps name their
    files by when they started), or None; the last such stamp in the name counts."""
    found = None
    for match in _NAME_CLOCK.finditer(Path(str(name)).stem):
        parts = [int(g) if g else 0 for g in match.groups()]
        try:
            found = datetime(*parts)
        except ValueError:
            continue
    return found


#: Said once per file whose events are dated by its name.
NAME_CLOCK_NOTE = "clock time from the file name (the file records no date)"


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
    try:
        whole, whole_meta = read(segment="none")
    except DataError:
        whole, whole_meta = None, None
    events = None
    if whole is not None and str(whole_meta.get("format")) not in FLIGHT_FORMATS \
            and len(whole) >= 2:
        events = _long_log_events(whole, whole_meta, name)
    if events is not None:
        fmt = str(whole_meta.get("format", "unknown"))
        notes = list(whole_meta.get("notes", []))
    else:
        first_frame, first_meta = read()
        segments = first_meta.get("segments") or []
        reads = [(first_frame, first_meta)]
        if len(segments) > 1:
            reads = [read(segment=s["number"]) for s in segments]
        fmt = str(first_meta.get("format", "unknown"))
        cycle = None
        match = _CYCLE.search(Path(name).stem)
        if match and len(reads) == 1:
            cycle = int(match.group(1))
        events = []
        for index, (frame, meta) in enumerate(reads):
            event = summarise_event(frame, meta, whole, whole_meta, name=name)
            event["index"] = index
            event["kind"] = "flight" if fmt in FLIGHT_FORMATS else "discharge"
            event["cycle"] = meta.get("cycle", cycle)  # a tester's step knows its cycle
            events.append(event)
        notes = list(dict.fromkeys(n for _, meta in reads for n in meta.get("notes", [])))
    if any(e.get("start_time") for e in events) and name_clock(name) is not None \
            and _start_time(dict(whole_meta or {}, time_offset_s=0.0)) is None:
        notes.append(NAME_CLOCK_NOTE)
    return SourceSummary(sha256=sha256_bytes(data), file_name=name, size_bytes=len(data),
                         format=fmt, notes=notes, events=events, options=options,
                         raw_zlib=zlib.compress(data, RAW_ZLIB_LEVEL) if keep_raw else b"")


def _long_log_events(whole, whole_meta: dict, name: str | None = None) -> list[dict] | None:
    """The events of a long log (a tester's steps, or charges among the discharges), or
    None when the file is read by its discharge segments."""
    t = whole["time_s"].to_numpy(dtype=float)
    i = whole["current_A"].to_numpy(dtype=float)
    steps = whole["step_index"].to_numpy() if "step_index" in whole else None
    cycles = whole["cycle_index"].to_numpy() if "cycle_index" in whole else None
    table = whole_meta.get("steps") if steps is not None else None
    kinds = None if not table else {(int(s["cycle"]), int(s["step"])): s["kind"] for s in table}
    spans = split_log(t, i, step_index=steps, cycle_index=cycles, step_kinds=kinds)
    if not is_long_log(spans, t, i, steps):
        return None
    offset = float(whole_meta.get("time_offset_s") or 0.0)

    def start_time_of(time_s: float) -> str | None:
        return _start_time(dict(whole_meta, time_offset_s=offset + time_s), name)

    return log_events(whole, spans, start_time_of=start_time_of, cells=whole_meta.get("cells"))


def _start_time(meta: dict, name: str | None = None) -> str | None:
    """Clock time of the load start (ISO 8601), when the file records one, else from the
    date and time in the file's name (:func:`name_clock`) when ``name`` is given."""
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
    elif name is not None:
        stamp = name_clock(name)
    if stamp is None:
        return None
    return (stamp + timedelta(seconds=offset)).isoformat(timespec="seconds")


def summarise_event(frame, meta: dict, whole=None, whole_meta: dict | None = None,
                    name: str | None = None) -> dict:
    """The numbers of one discharge or flight (see the module docstring).

    Parameters
    ----------
    frame, meta : DataFrame, dict
        One segment as :func:`dischargelab.io.read_discharge` returns it.
    whole, whole_meta : DataFrame, dict, optional
        The same file read with ``segment="none"`` (every row), for the rests on either
        side of the load (and what they read, in ``details``).
    name : str, optional
        The file's name: its date and time date the event when the file records none.
    """
    log = LogArrays.from_frame(frame)
    around = _rests_around(meta, whole, whole_meta)
    rest = meta.get("rest_sample") or None
    after = None
    details: dict = {}
    if around is not None:
        whole_log, a, b, before, after_rest = around
        if rest is None and before is not None:
            rest = rest_sample(whole_log, before)
            rest["time_s"] -= whole_log.time_s[a]
        after = after_sample(whole_log, after_rest, b)
        details = dict(event_details(whole_log, a, b, before, after_rest), rows=[a, b])
    ambient = frame["ambient_temperature_C"].to_numpy(dtype=float) \
        if "ambient_temperature_C" in frame else None
    event = load_figures(log, rest=rest, after=after, ambient_C=ambient)
    details["resistance_method"] = event.pop("resistance_method")
    event.update(start_time=_start_time(meta, name), cells=meta.get("cells") or _gauge_cells(whole),
                 segment=meta.get("segment"), details=details)
    return event


#: A rest beside a flight reads the pack's state when it covers at least this long [s]
#: (from its first sample to the load, or from the load to its last sample): a flight's
#: moments at zero throttle are not rests.
MIN_READING_S = 5.0

def _gauge_cells(whole) -> int | None:
    """Cells in series from a smart battery's own state of charge, when the log has one
    (:func:`dischargelab.flight.samples.cells_from_gauge`)."""
    from ..flight.samples import cells_from_gauge

    if whole is None or "soc_pct" not in whole:
        return None
    return cells_from_gauge(whole["voltage_V"], whole["current_A"], whole["soc_pct"])


#: Rows of a rest beside a flight draw at most this share of the load level (98th
#: percentile of the current) above the log's quietest current.
REST_SHARE = 0.05


def _rests_around(meta: dict, whole, whole_meta: dict | None):
    """``(whole log, first row, stop row, rest before, rest after)`` of a segment in the whole
    file read with ``segment="none"``, or None. A rest is the rows below the reader's load
    threshold next to the load, up to a gap, another load or a pack swap; it reads the pack
    at its last quiet row (see :data:`REST_SHARE`)."""
    from ..io.segment import SOC_JUMP_PCT, voltage_jumps_up
    from .events import gap_limit

    if whole is None or whole_meta is None or len(whole) < 2:
        return None
    log = LogArrays.from_frame(whole)
    t = log.time_s + float(whole_meta.get("time_offset_s") or 0.0)
    start = float(meta.get("time_offset_s") or 0.0)
    segments = meta.get("segments") or []
    seg = next((s for s in segments if s.get("number") == meta.get("segment")), None)
    if seg is None:
        return None
    end = start + float(seg["duration_s"])
    a = int(np.searchsorted(t, start - 1e-6, side="left"))
    b = int(np.searchsorted(t, end + 1e-6, side="right"))
    if b - a < 2:
        return None
    level = float(np.percentile(np.abs(log.current_A), 98))
    threshold = meta.get("load_threshold_A")
    if threshold is None:
        threshold = 0.2 * level
    # a rest is quiet: at most REST_SHARE of the load level above the quietest current (a
    # flight controller's draw on the ground, not a spooled-up motor)
    low = np.abs(log.current_A) < threshold
    quiet = np.abs(log.current_A) < min(threshold, float(np.min(np.abs(log.current_A)))
                                         + REST_SHARE * level)
    # a flight read from arming holds its time on the ground: its rests are outside the load
    while a < b - 2 and low[a]:
        a += 1
    while b > a + 2 and low[b - 1]:
        b -= 1
    gap = gap_limit(t)
    swapped = np.r_[False, voltage_jumps_up(log.voltage_V, log.current_A, threshold)]
    soc = whole["soc_pct"].to_numpy(dtype=float) if "soc_pct" in whole else None

    def joined(k: int) -> bool:
        """Rows k-1 and k belong to one stretch (no gap, no pack swap)."""
        if t[k] - t[k - 1] > gap or swapped[k]:
            return False
        return soc is None or not (soc[k] - soc[k - 1] >= SOC_JUMP_PCT)

    # the rests: the rows below the load threshold next to the load; each reads the pack
    # at its last quiet row (a motor spooling up before take-off is counted, not rested on)
    lo = a
    while lo > 0 and low[lo - 1] and joined(lo):
        lo -= 1
    hi = b
    while hi < t.size and low[hi] and joined(hi):
        hi += 1
    before = after = None
    calm = np.flatnonzero(quiet[lo:a]) + lo
    if calm.size and t[a] - t[lo] >= MIN_READING_S:
        load_row = lo - 1 if lo > 0 and not low[lo - 1] and joined(lo) else None
        before = rest_of(log, lo, int(calm[-1]) + 1, load_row=load_row,
                         direction=0 if load_row is None else
                         1 if log.current_A[load_row] > 0 else -1)
    calm = np.flatnonzero(quiet[b:hi]) + b
    if calm.size and b < t.size and joined(b) and t[calm[-1]] - t[b - 1] >= MIN_READING_S:
        after = rest_of(log, b, int(calm[-1]) + 1, load_row=b - 1, direction=1)
    return log, a, b, before, after


__all__ = ["SourceSummary", "summarise_source", "summarise_event", "sha256_file",
           "sha256_bytes", "step_resistance", "knee_ratio", "compact_curve",
           "check_reader_options", "READER_OPTIONS", "FLIGHT_FORMATS", "CURVE_POINTS"]
