"""Betaflight / INAV / Cleanflight blackbox logs, read with orangebox.

A blackbox file holds one log per arming, so every log in the file is one
flight. Fields used (Betaflight 4.x units): ``time`` [us since the flight
controller started], ``vbatLatest`` [0.01 V], ``amperageLatest`` [0.01 A,
discharge positive] and ``rcCommand[3]`` (throttle command, 1000 = idle).
Header values used: ``vbatref`` [0.01 V, pack voltage at arming] and
``vbatcellvoltage`` [0.01 V: min, warning, max per cell].

Sensor spikes: a pack under load never reads above its resting voltage. The
resting value of each flight is the larger of ``vbatref`` and the 95th
percentile of the first second; frames more than :data:`SPIKE_MARGIN_V` above
it are dropped as spikes (counted and noted). Frames before the throttle first
leaves idle are "before take-off" and give the current at motor idle.

Speed: orangebox decodes every frame in Python, about 20 000 frames (80 s of
250 Hz logging, 0.6 MB) per second on one core.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError, require
from .flightlog_base import BatterySeries, FlightLog, build_flight_log, drop_rows, quiet

#: Frames this far [V] above the resting value are sensor spikes.
SPIKE_MARGIN_V = 0.05
#: The resting value is taken from this first part of each flight [s].
REST_WINDOW_S = 1.0
#: Throttle command above idle + this share of its range means take-off.
TAKEOFF_THROTTLE_FRACTION = 0.05

#: What orangebox raises on a corrupt, truncated or foreign file.
_BLACKBOX_ERRORS = (ValueError, IndexError, KeyError, TypeError, AttributeError, RuntimeError,
                    OverflowError, struct.error, UnicodeDecodeError, EOFError, OSError,
                    StopIteration, ZeroDivisionError)


def read_blackbox(path) -> FlightLog:
    """Read the battery data of every log (flight) in a blackbox file.

    Returns
    -------
    FlightLog
        One battery (index 0); one flight per log in the file, found by "log index".

    Raises
    ------
    DataError
        Unreadable file, or no voltage and current fields.
    """
    orangebox = require("orangebox", "logs")
    path = Path(path)
    try:
        with quiet("orangebox"):
            parser = orangebox.Parser.load(str(path))
            count = parser.reader.log_count
    except _BLACKBOX_ERRORS + (orangebox.errors.InvalidHeaderException,) as exc:
        raise DataError(f"{path.name}: the blackbox file is corrupt or truncated in its header "
                        f"and cannot be read ({type(exc).__name__}); copy it from the flight "
                        "controller again") from None
    if count < 1:
        raise DataError(f"{path.name}: no blackbox log in the file")
    parts, spans, notes, events = [], [], [], []
    headers = {}
    clock_shift = 0.0
    spikes = 0
    for index in range(1, count + 1):
        part, headers_i, note = _read_log(orangebox, parser, index, path.name)
        if note:
            notes.append(note)
        if part is None:
            continue
        headers = headers or headers_i
        t = part["time_s"].to_numpy()
        if spans and t[0] + clock_shift <= spans[-1][1]:
            clock_shift = spans[-1][1] - t[0] + 1.0
            notes.append(f"log {index}: the flight controller clock restarted; its times follow "
                         "the previous log")
        part["time_s"] = t + clock_shift
        part, spiked = _drop_spikes(part, headers_i, index, notes)
        spikes += spiked
        spans.append((float(part["time_s"].iloc[0]), float(part["time_s"].iloc[-1])))
        takeoff = _takeoff(part)
        if takeoff is not None:
            events.append({"time_s": takeoff, "event": "takeoff"})
        parts.append(part)
    if not parts:
        raise DataError(f"{path.name}: none of the {count} blackbox logs has battery frames "
                        f"({'; '.join(notes)})")
    frame = pd.concat(parts, ignore_index=True)
    dropped = {"voltage_spike": spikes} if spikes else {}
    series = BatterySeries(index=0, label="vbat", frame=frame.drop(columns="throttle"),
                           dropped=dropped, cells=_cells(headers, notes))
    notes.insert(0, f"{count} log(s) in the file, one flight each; firmware "
                    f"{headers.get('Firmware revision', 'unknown')}")
    start = spans[0][0] if spans else 0.0
    return build_flight_log(path, "blackbox", [series], start_s=start, events=events,
                            spans=spans, found_by="log index", notes=notes)


def _read_log(orangebox, parser, index: int, name: str):
    """Frames of log ``index``: (DataFrame or None, headers, note or None)."""
    try:
        with quiet("orangebox"):
            parser.set_log_index(index)
            fields = parser.field_names
            headers = parser.headers
    except _BLACKBOX_ERRORS + (orangebox.errors.InvalidHeaderException,) as exc:
        return None, {}, f"log {index}: unreadable header ({type(exc).__name__}), skipped"
    if not fields or "time" not in fields:
        return None, headers, (f"log {index}: no frame definitions in its header (the header "
                               "is corrupt or cut), skipped")
    if "vbatLatest" not in fields or "amperageLatest" not in fields:
        missing = [f for f in ("vbatLatest", "amperageLatest") if f not in fields]
        return None, headers, (f"log {index}: no {' or '.join(missing)} field (battery voltage "
                               "or current sensor not logged), skipped")
    wanted = [fields.index(f) for f in ("time", "vbatLatest", "amperageLatest")]
    throttle = fields.index("rcCommand[3]") if "rcCommand[3]" in fields else None
    rows = []
    note = None
    try:
        with quiet("orangebox"):
            for frame in parser.frames():
                data = frame.data
                rows.append((data[wanted[0]], data[wanted[1]], data[wanted[2]],
                             data[throttle] if throttle is not None else np.nan))
    except _BLACKBOX_ERRORS as exc:
        note = (f"log {index}: decoding stopped after {len(rows)} frames "
                f"({type(exc).__name__}); the file is truncated or corrupt there")
    if len(rows) < 2:
        return None, headers, note or f"log {index}: no frames, skipped"
    values = np.array([[_number(x) for x in r] for r in rows], dtype=float)
    time_us = _unwrap_us(values[:, 0])
    part = pd.DataFrame({"time_s": time_us * 1e-6, "voltage_V": values[:, 1] * 0.01,
                         "current_A": values[:, 2] * 0.01, "throttle": values[:, 3]})
    return part, headers, note


def _number(value) -> float:
    return float(value) if isinstance(value, (int, float)) else np.nan


def _unwrap_us(t: np.ndarray) -> np.ndarray:
    """Undo 32-bit microsecond counter wrap-arounds."""
    steps = np.diff(t)
    wraps = np.concatenate(([0.0], np.cumsum(np.where(steps < -2.0 ** 31, 2.0 ** 32, 0.0))))
    return t + wraps


def _drop_spikes(part: pd.DataFrame, headers: dict, index: int, notes: list
                 ) -> tuple[pd.DataFrame, int]:
    t = part["time_s"].to_numpy()
    v = part["voltage_V"].to_numpy()
    first = v[(t - t[0] <= REST_WINDOW_S) & (v > 0)]
    reference = _header_number(headers, "vbatref")
    rest = max([x for x in (reference * 0.01 if reference else None,
                            float(np.percentile(first, 95)) if first.size else None)
                if x is not None], default=None)
    if rest is None:
        return part, 0
    bad = v > rest + SPIKE_MARGIN_V
    counts: dict[str, int] = {}
    part = drop_rows(part, bad, "voltage_spike", counts)
    if counts:
        notes.append(f"log {index}: {counts['voltage_spike']} frame(s) above the resting "
                     f"{rest:.2f} V + {SPIKE_MARGIN_V} V dropped as sensor spikes (max "
                     f"{v[bad].max():.2f} V)")
    return part, counts.get("voltage_spike", 0)


def _header_number(headers: dict, key: str) -> float | None:
    value = headers.get(key)
    return float(value) if isinstance(value, (int, float)) else None


def _takeoff(part: pd.DataFrame) -> float | None:
    """Time [s] of the first frame with the throttle command above idle, or None."""
    throttle = part["throttle"].to_numpy()
    if not np.isfinite(throttle).any():
        return None
    low, high = np.nanmin(throttle), np.nanmax(throttle)
    above = np.flatnonzero(throttle > low + TAKEOFF_THROTTLE_FRACTION * max(high - low, 1.0))
    return float(part["time_s"].iloc[above[0]]) if above.size else None


def _cells(headers: dict, notes: list) -> int | None:
    """Cells in series by Betaflight's own rule: vbatref / max cell voltage + 1 (integer)."""
    reference = _header_number(headers, "vbatref")
    limits = headers.get("vbatcellvoltage")
    if not reference or not isinstance(limits, list) or len(limits) < 3 or not limits[2]:
        return None
    cells = int(reference // float(limits[2])) + 1
    notes.append(f"{cells} cells from vbatref {reference * 0.01:.2f} V and the maximum cell "
                 f"voltage {float(limits[2]) * 0.01:.2f} V (the flight controller's rule)")
    return cells


__all__ = ["read_blackbox"]
