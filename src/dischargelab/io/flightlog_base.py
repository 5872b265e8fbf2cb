"""What every flight-log reader shares: the battery-series and flight types, cleaning,
flight finding and the assembly of a :class:`FlightLog`.

The readers (:mod:`.ardupilot`, :mod:`.ulog`, :mod:`.blackbox`, :mod:`.inflight_csv`)
build on this module and :mod:`.flightlog` (format detection and dispatch) calls
them; this module imports no reader.

Every reader returns a :class:`FlightLog`: one :class:`BatterySeries` per
battery instance, in canonical columns and units (the glossary of
:mod:`dischargelab.io.columns`):

========================  ==================================================
``time_s``                time since the log start [s]
``voltage_V``             pack voltage [V]
``current_A``             pack current [A], discharge positive
``temperature_C``         battery temperature [degC] (only when measured)
``cell1_V`` ...           measured cell voltages [V] (only when measured)
``log_discharged_mAh``    the log's own consumed-charge counter [mAh]
``log_remaining_frac``    the log's own state-of-charge estimate [0-1]
``log_resistance_ohm``    the log's own internal-resistance estimate [ohm]
``log_voltage_rest_V``    the log's own resting-voltage estimate [V]
``log_energy_Wh``         the log's own consumed-energy counter [Wh]
``session``               recording session (1, 2, ...) of a file holding several
                          joined recordings (telemetry logs); charge is never
                          counted across two sessions
``flight``                flight number (1, 2, ...), 0 outside any flight
========================  ==================================================

Flights come from arm/disarm events where the log has them, else from
take-off/landing events, else from the current: a flight is sustained current
above a threshold (hysteresis, pauses shorter than :data:`MAX_PAUSE_S` do not
split it, gaps in the logging do not split it, flights shorter than
:data:`MIN_FLIGHT_S` are ignored). Blackbox files hold one log per flight.

Records that are not a battery reading (NaN, 0 V while the logger powers down,
PX4's ``current_a = -1`` meaning "not measured", an unplug artefact at the end,
sensor spikes) are dropped, counted by reason and noted, never refused. The
current measured while the vehicle is disarmed or before take-off is reported
as the current-sensor offset; it is not subtracted.
"""


from __future__ import annotations

import bisect
import contextlib
import io
import logging
import os
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError
from .segment import runs

#: Names returned by :func:`detect_flight_log`.
FLIGHT_LOG_FORMATS = ("ardupilot-bin", "ardupilot-text", "ulog", "blackbox", "inflight-csv",
                      "flightlog-csv", "mavlink-tlog")

#: ULog file magic (8 bytes with the version byte following).
ULOG_MAGIC = b"ULog\x01\x12\x35"
#: First two bytes of every binary DataFlash message.
DATAFLASH_HEAD = b"\xa3\x95"
#: First header line of a Betaflight / INAV / Cleanflight blackbox log.
BLACKBOX_MAGIC = b"H Product:Blackbox flight data recorder"
#: First characters of a CSV written by :func:`convert_flight_log`.
EXPORT_MAGIC = "# dischargelab flight-log export: "

#: Log-own columns a reader may add (see the module docstring).
LOG_COLUMNS = ("log_discharged_mAh", "log_remaining_frac", "log_resistance_ohm",
               "log_voltage_rest_V", "log_energy_Wh")

#: A current above this share of the 99th-percentile current starts a flight ...
ON_FRACTION = 0.10
#: ... and at least this many amperes.
MIN_ON_A = 1.0
#: A flight ends when the current falls below this share of the start threshold.
OFF_RATIO = 0.5
#: Runs of current shorter than this [s] do not start a flight (spin-up blips, spikes).
MIN_BURST_S = 1.0
#: Pauses in the current shorter than this [s] do not split a flight.
MAX_PAUSE_S = 10.0
#: Flights found from the current shorter than this [s] are ignored.
MIN_FLIGHT_S = 5.0
#: Fewest idle samples for a current offset.
MIN_IDLE_SAMPLES = 3
#: Below this a "voltage" is not a battery reading [V].
MIN_BATTERY_V = 0.5
#: An end record whose voltage falls by more than this share without more current is an unplug.
UNPLUG_DROP_FRACTION = 0.01
#: At most this many records at the end are checked for unplug artefacts.
UNPLUG_MAX_RECORDS = 3

#: Why records were dropped (keys of ``BatterySeries.dropped``).
DROP_REASONS = {
    "nan": "empty or NaN time, voltage or current",
    "zero_voltage": f"voltage below {MIN_BATTERY_V} V (logger powering down or battery "
                    "not connected)",
    "current_not_measured": "current_a = -1 (PX4: current not measured)",
    "voltage_spike": "voltage above the resting value (sensor spike)",
    "unplug": "unplug artefact at the end (voltage falls with no more current)",
    "time_not_increasing": "time not after the previous record",
    "no_time": "no time for the record (no GPS time before it)",
    "malformed": "malformed line",
    "unknown_value": "voltage or current the sender marks unknown (MAVLink UINT16_MAX, -1)",
}


# --------------------------------------------------------------------------- types

@dataclass
class FlightSpan:
    """One flight: from ``start_s`` to ``end_s`` [s, log time], found by ``found_by``."""

    number: int
    start_s: float
    end_s: float
    found_by: str

    @property
    def duration_s(self) -> float:
        """Duration [s]."""
        return self.end_s - self.start_s

    def to_dict(self) -> dict:
        return {"number": self.number, "start_s": self.start_s, "end_s": self.end_s,
                "duration_s": self.duration_s, "found_by": self.found_by}


@dataclass
class BatterySeries:
    """The samples of one battery instance of a flight log.

    Attributes
    ----------
    index : int
        Battery instance number in the log (PX4 ``multi_id``, ArduPilot
        ``Instance``; 0 when the log has one battery).
    label : str
        Where the samples come from, e.g. ``"battery_status[1]"`` or ``"BAT[0]"``.
    frame : pandas.DataFrame
        Canonical columns (see :mod:`dischargelab.io.flightlog`).
    cells : int or None
        Cells in series, when the log says.
    capacity_mAh : float or None
        Capacity configured in the log [mAh], when the log says.
    notes : list of str
        Everything inferred or dropped, one sentence each.
    dropped : dict
        Records dropped, by reason (keys of :data:`DROP_REASONS`).
    masked : dict
        Samples of one column set to NaN while the record is kept, by column (e.g. a
        glitching cell channel: ``{"cell3_V": 75}``).
    current_offset_A : float or None
        Median current [A] while disarmed or before take-off (not subtracted).
    idle_samples : int
        Samples the offset was taken from.
    """

    index: int
    label: str
    frame: pd.DataFrame
    cells: int | None = None
    capacity_mAh: float | None = None
    notes: list[str] = field(default_factory=list)
    dropped: dict[str, int] = field(default_factory=dict)
    masked: dict[str, int] = field(default_factory=dict)
    current_offset_A: float | None = None
    idle_samples: int = 0

    @property
    def rows(self) -> int:
        """Number of samples."""
        return len(self.frame)

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample [s]."""
        if self.rows < 2:
            return 0.0
        t = self.frame["time_s"].to_numpy()
        return float(t[-1] - t[0])

    @property
    def cell_columns(self) -> list[str]:
        """Names of the per-cell voltage columns, in cell order."""
        return [c for c in self.frame.columns if c.startswith("cell") and c.endswith("_V")]

    def charge_mAh(self) -> float:
        """Charge drawn [mAh]: trapezoidal integral of ``current_A`` over ``time_s``
        (never across the join of two recording sessions, see ``session``)."""
        if self.rows < 2:
            return 0.0
        t = self.frame["time_s"].to_numpy(dtype=float)
        i = self.frame["current_A"].to_numpy(dtype=float)
        steps = 0.5 * (i[1:] + i[:-1]) * np.diff(t)
        return float(np.sum(steps[self._same_session()]) / 3.6)

    def counter_mAh(self) -> float | None:
        """Charge by the log's own counter [mAh] (last minus first, summed over the
        recording sessions), or None."""
        if "log_discharged_mAh" not in self.frame:
            return None
        values = self.frame["log_discharged_mAh"].to_numpy(dtype=float)
        known = np.isfinite(values)
        if known.sum() < 2:
            return None
        sessions = (self.frame["session"].to_numpy()[known] if "session" in self.frame
                    else np.zeros(int(known.sum()), dtype=int))
        values = values[known]
        return float(sum(values[sessions == s][-1] - values[sessions == s][0]
                         for s in np.unique(sessions)))

    def _same_session(self) -> np.ndarray:
        """For each step between two samples: True when both are in one recording session."""
        if "session" not in self.frame:
            return np.ones(max(self.rows - 1, 0), dtype=bool)
        session = self.frame["session"].to_numpy()
        return session[1:] == session[:-1]

    def describe(self) -> str:
        """A few words: label, cells, capacity."""
        parts = [self.label]
        if self.cells:
            parts.append(f"{self.cells}S")
        if self.capacity_mAh:
            parts.append(f"{self.capacity_mAh:g} mAh")
        return " ".join(parts)

    def to_dict(self) -> dict:
        """Description without the samples (for JSON)."""
        frame = self.frame
        out = {"index": self.index, "label": self.label, "cells": self.cells,
               "capacity_mAh": self.capacity_mAh, "rows": self.rows,
               "duration_s": self.duration_s, "columns": list(frame.columns),
               "charge_mAh": self.charge_mAh(), "log_counter_mAh": self.counter_mAh(),
               "current_offset_A": self.current_offset_A, "idle_samples": self.idle_samples,
               "dropped": {k: v for k, v in self.dropped.items() if v},
               "masked": {k: v for k, v in self.masked.items() if v}, "notes": list(self.notes)}
        if self.rows:
            v = frame["voltage_V"].to_numpy(dtype=float)
            i = frame["current_A"].to_numpy(dtype=float)
            out.update({"voltage_V": {"first": float(v[0]), "last": float(v[-1]),
                                      "min": float(v.min()), "max": float(v.max())},
                        "current_A": {"min": float(i.min()), "mean": float(i.mean()),
                                      "max": float(i.max())}})
        return out


@dataclass
class FlightLog:
    """Battery data of one flight-log file.

    Attributes
    ----------
    source : str
        The file read.
    format : str
        One of :data:`FLIGHT_LOG_FORMATS`.
    batteries : list of BatterySeries
        One per battery instance, in instance order.
    spans : list of FlightSpan
        The flights, numbered from 1.
    events : list of dict
        Arm, disarm, take-off and landing events: ``{"time_s", "event"}``.
    notes : list of str
        Notes about the whole file.
    flight_number : int or None
        Set on the parts returned by :meth:`flights`.
    skipped : dict
        Messages of the file skipped before any battery record was made, by reason
        (e.g. ``{"corrupt_messages": 3}`` for a telemetry log).
    start_time : str or None
        Clock time (ISO 8601, UTC) of ``time_s = 0`` when the log records one on a
        clock that runs through the whole file (a telemetry log of one recording).
    """

    source: str
    format: str
    batteries: list[BatterySeries]
    spans: list[FlightSpan] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    flight_number: int | None = None
    skipped: dict[str, int] = field(default_factory=dict)
    start_time: str | None = None

    def battery(self, index: int | None = None) -> BatterySeries:
        """The battery with instance ``index``, or the first one with samples (None).

        Raises
        ------
        DataError
            No such battery, or no battery has samples.
        """
        return choose_battery(self, index)[0]

    def flight(self, number: int) -> FlightLog:
        """The part of the log in flight ``number`` (1-based)."""
        span = choose_span(self, number)
        return _restrict(self, span)

    def flights(self) -> list[FlightLog]:
        """The log split into its flights (samples outside every flight left out)."""
        return [_restrict(self, span) for span in self.spans]

    def to_pandas(self) -> pd.DataFrame:
        """All battery samples, with ``battery`` and ``flight`` columns."""
        parts = []
        for series in self.batteries:
            if series.rows:
                frame = series.frame.copy()
                frame.insert(0, "battery", series.index)
                parts.append(frame)
        if not parts:
            return pd.DataFrame(columns=["battery", "time_s", "voltage_V", "current_A", "flight"])
        return pd.concat(parts, ignore_index=True)

    def summary(self) -> str:
        """One paragraph: format, batteries, flights, charge, offsets, drops."""
        name = Path(self.source).name
        text = [f"{name} ({self.format})"]
        if self.flight_number is not None:
            text.append(f", flight {self.flight_number}")
        text.append(f": {len(self.batteries)} "
                    f"batter{'y' if len(self.batteries) == 1 else 'ies'}")
        if self.spans:
            how = sorted({s.found_by for s in self.spans})
            text.append(f", {len(self.spans)} flight{'s' if len(self.spans) != 1 else ''} "
                        f"(from {' and '.join(how)}: "
                        + ", ".join(f"{s.duration_s:.1f} s" for s in self.spans) + ")")
        else:
            text.append(", no flight found")
        text.append(". ")
        for series in self.batteries:
            text.append(_battery_sentence(series, whole=self.flight_number is None))
        return "".join(text).strip()

    def to_dict(self) -> dict:
        """Everything but the samples (for JSON)."""
        return {"source": self.source, "format": self.format,
                "flight_number": self.flight_number,
                "flights": [s.to_dict() for s in self.spans],
                "batteries": [b.to_dict() for b in self.batteries],
                "events": list(self.events), "notes": list(self.notes),
                "skipped": dict(self.skipped), "start_time": self.start_time,
                "summary": self.summary()}


def _battery_sentence(series: BatterySeries, whole: bool = True) -> str:
    if not series.rows:
        return f"{series.describe()}: no usable samples. "
    text = (f"{series.describe()}: {series.rows} samples over {series.duration_s:.1f} s, "
            f"{series.charge_mAh():.1f} mAh by the current")
    counter = series.counter_mAh()
    if counter is not None:
        text += f" ({counter:.1f} mAh by the log's counter)"
    if series.current_offset_A is not None:
        text += (f"; current offset {series.current_offset_A:.3g} A (median of "
                 f"{series.idle_samples} idle samples, not subtracted)")
    else:
        text += "; current offset unknown (no samples while disarmed or before take-off)"
    dropped = {k: v for k, v in series.dropped.items() if v}
    if dropped:
        text += ("; dropped " if whole else "; dropped in the whole log ") + ", ".join(
            f"{v} {k.replace('_', ' ')}" for k, v in dropped.items())
    if masked_text(series):
        text += "; " + masked_text(series)
    return text + ". "


def masked_text(series: BatterySeries) -> str:
    """``"masked 75 samples of cell3_V (kept the records)"`` or ``""``."""
    masked = {k: v for k, v in series.masked.items() if v}
    if not masked:
        return ""
    return "masked " + ", ".join(f"{v} sample(s) of {k}" for k, v in masked.items()) + \
        " (glitches; the records, their pack voltage and current kept)"



def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def choose_battery(log: FlightLog, index: int | None) -> tuple[BatterySeries, list[str]]:
    """The battery ``index`` (or the first with samples) and notes about the others."""
    if index is not None:
        for series in log.batteries:
            if series.index == index:
                if series.rows < 2:
                    raise DataError(f"{Path(log.source).name}: battery {index} has no usable "
                                    f"samples ({_drop_text(series)})")
                return series, []
        known = ", ".join(f"{b.index} ({b.describe()})" for b in log.batteries)
        raise DataError(f"{Path(log.source).name} has no battery {index}; batteries: {known}")
    usable = [b for b in log.batteries if b.rows >= 2]
    if not usable:
        reasons = "; ".join(f"{b.label}: {_drop_text(b)}" for b in log.batteries)
        raise DataError(f"{Path(log.source).name}: no battery has usable samples ({reasons})")
    chosen = usable[0]
    notes = [f"the log also holds {b.describe()}; choose it with battery={b.index} "
             f"(--battery {b.index})" for b in log.batteries if b is not chosen and b.rows >= 2]
    return chosen, notes


def _drop_text(series: BatterySeries) -> str:
    dropped = {k: v for k, v in series.dropped.items() if v}
    if not dropped:
        return "no records"
    return "dropped " + ", ".join(f"{v} records: {DROP_REASONS.get(k, k)}"
                                  for k, v in dropped.items())


def choose_span(log: FlightLog, number: int) -> FlightSpan:
    """Flight ``number`` (1-based) of ``log``."""
    if isinstance(number, bool) or not isinstance(number, (int, np.integer)) or number < 1:
        raise DataError(f"flight must be a flight number counting from 1; got {number!r}")
    for span in log.spans:
        if span.number == number:
            return span
    name = Path(log.source).name
    if not log.spans:
        raise DataError(f"{name}: no flight found, so there is no flight {number}; "
                        "leave --flight out to use every sample")
    raise DataError(f"{name} has {len(log.spans)} flight(s); --flight must be 1 to "
                    f"{len(log.spans)}, got {number}")


def _restrict(log: FlightLog, span: FlightSpan) -> FlightLog:
    batteries = []
    for series in log.batteries:
        keep = series.frame["flight"].to_numpy() == span.number
        batteries.append(replace(series, frame=series.frame[keep].reset_index(drop=True),
                                 notes=list(series.notes), dropped=dict(series.dropped),
                                 masked=dict(series.masked)))
    events = [e for e in log.events if span.start_s <= e["time_s"] <= span.end_s]
    return replace(log, batteries=batteries, spans=[span], events=events,
                   notes=list(log.notes), flight_number=span.number)


# --------------------------------------------------------------------------- assembly


def drop_rows(frame: pd.DataFrame, bad: np.ndarray, reason: str,
              dropped: dict) -> pd.DataFrame:
    """Remove the rows where ``bad`` is True, counting them under ``reason``."""
    bad = np.asarray(bad, dtype=bool)
    count = int(bad.sum())
    if count:
        dropped[reason] = dropped.get(reason, 0) + count
        frame = frame[~bad].reset_index(drop=True)
    return frame


def clean_series(series: BatterySeries) -> BatterySeries:
    """Drop records that are not battery readings (NaN, ~0 V, time backwards, unplug).

    Per-column NaN in optional columns (temperature, cells, log columns) keeps
    the record; a column that is NaN everywhere is removed.
    """
    frame = series.frame.reset_index(drop=True)
    dropped = series.dropped
    required = ["time_s", "voltage_V", "current_A"]
    values = frame[required].to_numpy(dtype=float)
    frame = drop_rows(frame, ~np.isfinite(values).all(axis=1), "nan", dropped)
    frame = drop_rows(frame, frame["voltage_V"].to_numpy(dtype=float) < MIN_BATTERY_V,
                      "zero_voltage", dropped)
    frame = _drop_time_not_increasing(frame, dropped)
    frame = _drop_unplug(frame, dropped)
    empty = [c for c in frame.columns if c not in required and c != "flight"
             and frame[c].dtype.kind == "f" and not np.isfinite(frame[c].to_numpy()).any()]
    frame = frame.drop(columns=empty)
    series.frame = frame
    negative = frame["current_A"].to_numpy(dtype=float) < 0
    if negative.any():
        series.notes.append(f"{int(negative.sum())} sample(s) with negative current (min "
                            f"{frame['current_A'].min():.3g} A) kept as measured")
    for reason, count in dropped.items():
        if count:
            series.notes.append(f"dropped {count} record(s): {DROP_REASONS.get(reason, reason)}")
    return series


def _drop_time_not_increasing(frame: pd.DataFrame, dropped: dict) -> pd.DataFrame:
    """Keep the longest run of records whose time increases; drop the fewest others.

    A single corrupt time (a spike far ahead, a step back) costs one record,
    not every record after it.
    """
    t = frame["time_s"].to_numpy(dtype=float)
    if t.size < 2 or np.all(np.diff(t) > 0):
        return frame
    keep = np.zeros(t.size, dtype=bool)
    keep[_longest_increasing(t)] = True
    return drop_rows(frame, ~keep, "time_not_increasing", dropped)


def _longest_increasing(values: np.ndarray) -> np.ndarray:
    """Indices of a longest strictly increasing subsequence (patience sorting, O(n log n))."""
    tails: list[float] = []  # smallest tail value of an increasing run of each length
    tail_index: list[int] = []
    parent = np.full(values.size, -1, dtype=np.int64)
    for k, value in enumerate(values.tolist()):
        length = bisect.bisect_left(tails, value)
        if length == len(tails):
            tails.append(value)
            tail_index.append(k)
        else:
            tails[length] = value
            tail_index[length] = k
        parent[k] = tail_index[length - 1] if length else -1
    out = []
    k = tail_index[-1] if tail_index else -1
    while k >= 0:
        out.append(k)
        k = int(parent[k])
    return np.array(out[::-1], dtype=np.int64)


def _drop_unplug(frame: pd.DataFrame, dropped: dict) -> pd.DataFrame:
    v = frame["voltage_V"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    n = v.size
    bad = np.zeros(n, dtype=bool)
    k = n - 1
    while k >= 1 and n - k <= UNPLUG_MAX_RECORDS:
        falls = v[k] < v[k - 1] * (1.0 - UNPLUG_DROP_FRACTION)
        if falls and i[k] <= max(i[k - 1], 0.0) and i[k] <= 0.0:
            bad[k] = True
            k -= 1
        else:
            break
    return drop_rows(frame, bad, "unplug", dropped)


def build_flight_log(source, fmt: str, batteries: list[BatterySeries], *, start_s: float,
                     events: list[dict] | None = None, spans: list[tuple] | None = None,
                     found_by: str = "log index", notes: list[str] | None = None) -> FlightLog:
    """Clean the batteries, put time on the log clock, find flights and offsets.

    Parameters
    ----------
    source : path-like
        The file read.
    fmt : str
        One of :data:`FLIGHT_LOG_FORMATS`.
    batteries : list of BatterySeries
        ``time_s`` still on the log's own clock [s].
    start_s : float
        Log start on that clock [s]; becomes ``time_s = 0``.
    events : list of dict, optional
        ``{"time_s": log clock [s], "event": "armed" | "disarmed" | "takeoff" | "landed"}``.
    spans : list of (start_s, end_s), optional
        Flights given by the format (blackbox logs), on the log clock.
    found_by : str
        How ``spans`` were found.
    notes : list of str, optional
        Notes about the whole file.

    Raises
    ------
    DataError
        No battery has a usable sample.
    """
    events = sorted(({"time_s": float(e["time_s"]) - start_s, "event": e["event"]}
                     for e in (events or [])), key=lambda e: e["time_s"])
    for series in batteries:
        series.frame = series.frame.assign(time_s=series.frame["time_s"] - start_s)
        clean_series(series)
    name = Path(source).name
    usable = [b for b in batteries if b.rows >= 2]
    if not usable:
        reasons = "; ".join(f"{b.label}: {_drop_text(b)}" for b in batteries) or "none found"
        raise DataError(f"{name}: no usable battery samples ({reasons})")
    t_first = min(float(b.frame["time_s"].iloc[0]) for b in usable)
    t_last = max(float(b.frame["time_s"].iloc[-1]) for b in usable)
    if spans is not None:
        intervals = [(a - start_s, b - start_s) for a, b in spans]
    else:
        intervals, found_by = _event_intervals(events, t_first, t_last)
        if not intervals and found_by is None:
            first = usable[0].frame
            intervals = current_intervals(first["time_s"].to_numpy(dtype=float),
                                          first["current_A"].to_numpy(dtype=float))
            found_by = "current"
    flight_spans = _number_spans(intervals, usable, found_by)
    takeoffs = [e["time_s"] for e in events if e["event"] == "takeoff"]
    for series in batteries:
        _assign_flights(series, flight_spans)
        _offset(series, flight_spans, takeoffs, found_by)
    return FlightLog(source=str(source), format=fmt, batteries=batteries, spans=flight_spans,
                     events=events, notes=list(notes or []))


def _event_intervals(events: list[dict], t_first: float, t_last: float
                     ) -> tuple[list[tuple[float, float]], str | None]:
    """Armed intervals, else in-air intervals; (intervals, how) or ([], None)."""
    for on, off, how in (("armed", "disarmed", "arm/disarm"),
                         ("takeoff", "landed", "take-off/landing")):
        relevant = [e for e in events if e["event"] in (on, off)]
        if not relevant:
            continue
        intervals: list[tuple[float, float]] = []
        state, start = None, None
        for e in relevant:
            if e["event"] == on and state is not True:
                state, start = True, e["time_s"]
            elif e["event"] == off:
                if state is True:
                    intervals.append((start, e["time_s"]))
                elif state is None and e["time_s"] > t_first:  # the log starts armed
                    intervals.append((t_first, e["time_s"]))
                state = False
        if state is True:
            intervals.append((start, t_last))
        return intervals, how
    return [], None


def current_intervals(time_s: np.ndarray, current_A: np.ndarray) -> list[tuple[float, float]]:
    """Flights from the current alone: sustained current with hysteresis.

    A sample switches "on" above ``max(MIN_ON_A, ON_FRACTION * p99(current))``
    and "off" below ``OFF_RATIO`` times that. Runs shorter than
    :data:`MIN_BURST_S` are ignored (spin-up blips, spikes; inside a flight they
    are covered by the runs around them); runs separated by pauses shorter than
    :data:`MAX_PAUSE_S` are one flight; flights shorter than :data:`MIN_FLIGHT_S`
    are ignored. Gaps in the samples never split a flight.

    Returns
    -------
    list of (start_s, end_s)
        First and last "on" sample of each flight.
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    if t.size < 2:
        return []
    on_A = max(MIN_ON_A, ON_FRACTION * float(np.percentile(i, 99)))
    level = np.where(i > on_A, 1.0, np.where(i < OFF_RATIO * on_A, 0.0, np.nan))
    state = pd.Series(level).ffill().fillna(0.0).to_numpy() > 0.5
    merged: list[list[float]] = []
    for a, b in runs(state):
        start, end = t[a], t[b - 1]
        if end - start < MIN_BURST_S:
            continue
        if merged and start - merged[-1][1] < MAX_PAUSE_S:
            merged[-1][1] = end
        else:
            merged.append([start, end])
    return [(a, b) for a, b in merged if b - a >= MIN_FLIGHT_S]


def _number_spans(intervals, usable: list[BatterySeries], found_by: str | None
                  ) -> list[FlightSpan]:
    spans = []
    for start, end in intervals:
        inside = max(int(np.sum((b.frame["time_s"] >= start) & (b.frame["time_s"] <= end)))
                     for b in usable)
        if inside >= 2 and end > start:
            spans.append(FlightSpan(len(spans) + 1, float(start), float(end),
                                    found_by or "current"))
    return spans


def _assign_flights(series: BatterySeries, spans: list[FlightSpan]) -> None:
    t = series.frame["time_s"].to_numpy(dtype=float)
    number = np.zeros(t.size, dtype=int)
    for span in spans:
        number[(t >= span.start_s) & (t <= span.end_s)] = span.number
    series.frame = series.frame.assign(flight=number)


def _offset(series: BatterySeries, spans: list[FlightSpan], takeoffs: list[float],
            found_by: str | None) -> None:
    if not series.rows:
        return
    t = series.frame["time_s"].to_numpy(dtype=float)
    idle = series.frame["flight"].to_numpy() == 0
    for span in spans:
        first = [x for x in takeoffs if span.start_s <= x <= span.end_s]
        if first:
            idle |= (t >= span.start_s) & (t < min(first))
    count = int(idle.sum())
    if count >= MIN_IDLE_SAMPLES:
        value = float(np.median(series.frame["current_A"].to_numpy(dtype=float)[idle]))
        series.current_offset_A = value
        series.idle_samples = count
        where = {"log index": "before take-off", "current": "outside the flights (idle)",
                 "flight column": "outside the flights (idle)"}.get(
            found_by, "while disarmed or before take-off")
        series.notes.append(f"current offset {value:.3g} A: median of {count} samples {where} "
                            f"(reported, not subtracted)")
    else:
        series.notes.append("current offset unknown: fewer than "
                            f"{MIN_IDLE_SAMPLES} samples while disarmed or before take-off")


# --------------------------------------------------------------------------- library quirks

@contextlib.contextmanager
def quiet(*logger_names: str):
    """Keep a parsing library's prints and log warnings off the user's terminal.

    Yields the captured text (stdout and stderr together) as a StringIO.
    """
    captured = io.StringIO()
    loggers = [logging.getLogger(n) for n in logger_names]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        with contextlib.redirect_stdout(captured), contextlib.redirect_stderr(captured):
            yield captured
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def _flush_c_streams() -> None:
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no C library handle on this platform
        pass


@contextlib.contextmanager
def quiet_native():
    """Also silence compiled extensions that print with C stdio (file descriptors 1 and 2).

    The C buffers are flushed before the descriptors are restored, so nothing
    the extension printed surfaces later.
    """
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(AttributeError, ValueError, OSError):
            stream.flush()
    _flush_c_streams()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no usable descriptors (embedded interpreter): nothing to silence
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        _flush_c_streams()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved + [devnull]:
            os.close(fd)


# --------------------------------------------------------------------------- read_discharge

def drop_unmeasured_temperature(series: BatterySeries, field: str) -> None:
    """Drop ``temperature_C`` when every record is 0 or NaN (not measured), with a note."""
    if "temperature_C" not in series.frame:
        return
    values = series.frame["temperature_C"].to_numpy(dtype=float)
    if not np.any(np.isfinite(values) & (values != 0.0)):
        series.frame = series.frame.drop(columns="temperature_C")
        series.notes.append(f"battery temperature not measured ({field} is 0 or NaN in every "
                            "record)")
