"""Flight logs with battery data: shared types, format detection, flights, cleaning.

Four families of logs are read, each by its own module behind the ``logs``
extra (``pip install 'dischargelab[logs]'``):

* ArduPilot DataFlash, binary ``.bin`` and text ``.log`` (:mod:`.ardupilot`);
* PX4 ULog (:mod:`.ulog`);
* Betaflight / INAV blackbox (:mod:`.blackbox`);
* in-flight logger CSV with per-cell columns, such as INA3221 monitors
  (:mod:`.inflight_csv`, needs no extra).

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
import json
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
                      "flightlog-csv")

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
        """Charge drawn [mAh]: trapezoidal integral of ``current_A`` over ``time_s``."""
        if self.rows < 2:
            return 0.0
        t = self.frame["time_s"].to_numpy(dtype=float)
        i = self.frame["current_A"].to_numpy(dtype=float)
        return float(np.sum(0.5 * (i[1:] + i[:-1]) * np.diff(t)) / 3.6)

    def counter_mAh(self) -> float | None:
        """Charge by the log's own counter [mAh] (last minus first), or None."""
        if "log_discharged_mAh" not in self.frame:
            return None
        values = self.frame["log_discharged_mAh"].to_numpy(dtype=float)
        values = values[np.isfinite(values)]
        return float(values[-1] - values[0]) if values.size >= 2 else None

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
               "dropped": {k: v for k, v in self.dropped.items() if v}, "notes": list(self.notes)}
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
    """

    source: str
    format: str
    batteries: list[BatterySeries]
    spans: list[FlightSpan] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    flight_number: int | None = None

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
    return text + ". "


# --------------------------------------------------------------------------- detection

def detect_flight_log(path) -> str | None:
    """Format of a flight log from its first bytes, or None for anything else.

    ULog starts with ``ULog`` 0x01 0x12 0x35, binary DataFlash with 0xA3 0x95,
    text DataFlash has lines starting ``FMT,`` near the top, blackbox starts
    with ``H Product:Blackbox flight data recorder``; in-flight logger CSV is
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
        ArduPilot ``.bin``/``.log``, PX4 ``.ulg``, blackbox ``.bbl``/``.bfl``
        or in-flight logger CSV; the format is found from the content.
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
                        "PX4 .ulg, Betaflight/INAV blackbox, in-flight logger CSV with per-cell "
                        "columns); for other data use read_discharge")
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


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


_READERS = {"ardupilot-bin": _read_ardupilot, "ardupilot-text": _read_ardupilot,
            "ulog": _read_ulog, "blackbox": _read_blackbox, "inflight-csv": _read_inflight,
            "flightlog-csv": _read_export}


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
                                 notes=list(series.notes), dropped=dict(series.dropped)))
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

def read_flight_discharge(path, *, flight=None, battery=None, current_A=None, sign="auto",
                          segment="auto", rest_sample="auto") -> tuple[pd.DataFrame, dict]:
    """One flight of one battery as :func:`dischargelab.io.read_discharge` returns it.

    ``flight`` None takes the longest flight (``segment`` N, when given, picks
    flight N; ``segment="none"`` keeps every sample); ``battery`` None the
    first battery with samples. The frame goes through the same checks as
    every other reader (:func:`dischargelab.io.prepare.prepare`); the sign is
    known (discharge positive) unless ``sign`` says otherwise. The idle sample
    just before the flight, when there is one within :data:`MAX_PAUSE_S`,
    becomes ``meta["rest_sample"]``.
    """
    from .columns import CanonicalTable
    from .prepare import check_segment_option, prepare, summary_sentence

    segment = check_segment_option(segment)
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
    and ``flight`` (0 outside any flight). Two ``#`` comment lines at the top
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
        [c for c in LOG_COLUMNS if c in frame] + ["flight"]
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


def drop_unmeasured_temperature(series: BatterySeries, field: str) -> None:
    """Drop ``temperature_C`` when every record is 0 or NaN (not measured), with a note."""
    if "temperature_C" not in series.frame:
        return
    values = series.frame["temperature_C"].to_numpy(dtype=float)
    if not np.any(np.isfinite(values) & (values != 0.0)):
        series.frame = series.frame.drop(columns="temperature_C")
        series.notes.append(f"battery temperature not measured ({field} is 0 or NaN in every "
                            "record)")
