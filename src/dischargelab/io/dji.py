"""DJI ground-station logs: battery records and flight events of a flight app.

The raw log is Android ``logcat`` text, one event per line, prefixed by the
local time ``HH:MM:SS.mmm``. Battery records look like::

    20:56:12.556 I/ExceptionLogger : Battery updated: Battery{exists=true,
        currentVoltage=25730, currentCurrent=800, remainPowerPercent=98,
        smartBattery=true, temperature=17.950012}.

with the pack voltage in mV and the current in mA (positive while
discharging in these logs; the sign is checked like any other file). The app
writes a record when the state of charge changes by 1 % (about every 12 s in
flight), so landed periods usually have few or no records.

Flight events kept: ``onFlightMode change: A -> B`` (mode B from then on),
``TAKEOFF_POSITION_UPDATED as landed`` (mode ``LANDED``) and
``onSerialNumberChanged = S`` (the aircraft the app talks to). The clock has no
date: a time earlier than the previous line by more than 12 h is taken as a
midnight rollover.

One discharge segment per flight (:func:`flight_breaks`). A flight starts at a
take-off mode (``*_TAKEOFF``) while on the ground and ends at a landing
(``as landed`` or the ``LANDED`` mode); when a landing mode (``AUTO_LANDING``)
is followed by a mission mode (``GPS_WAYPOINT``) without a logged touchdown,
the aircraft landed and took off again between two records. A different
serial number is another aircraft, hence another pack. Pack swaps on the
ground show as a state-of-charge jump (:mod:`dischargelab.io.segment`). Gaps in
the records are not flight ends: the app writes nothing while it reconnects,
even in flight, and nothing while landed. A take-off mode reported while
airborne (after the app reconnects in flight) is not a new flight.

The derived CSV files (``time_s, voltage_V, current_A, soc_pct, temperature_C,
smartBattery, flight_mode_last_event``) are plain delimited text and read by
:mod:`dischargelab.io.text`; ``flight_mode_last_event`` becomes ``flight_mode``.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from ..errors import DataError
from .columns import CanonicalTable

BATTERY_MARK = "Battery updated: Battery{"

_STAMP = r"^(\d{1,2}):(\d{2}):(\d{2}(?:\.\d+)?)\s"
_EVENT = re.compile(
    _STAMP + r".*?(?:Battery updated: Battery\{(?P<battery>[^}]*)\}"
    r"|onFlightMode change: (?P<old>\S+) -> (?P<new>[A-Za-z_]+)"
    r"|(?P<landed>TAKEOFF_POSITION_UPDATED as landed)"
    r"|onSerialNumberChanged = (?P<serial>\S+))",
    re.MULTILINE,
)
_LOGCAT_LINE = re.compile(r"^\d{2}:\d{2}:\d{2}\.\d{3} [VDIWEF]/")

#: Flight modes that start a flight (when on the ground); a segment ends before them.
TAKEOFF_MODES = ("AUTO_TAKEOFF", "ASSISTED_TAKEOFF", "TAKEOFF")
#: Flight modes of a landing in progress; touchdown follows.
LANDING_MODES = ("AUTO_LANDING", "ATTI_LANDING", "CONFIRM_LANDING")
#: Autonomous mission modes: entered after a landing mode, a new flight has begun.
MISSION_MODES = ("GPS_WAYPOINT", "GPS_HOT_POINT", "GPS_FOLLOW_ME")


def flight_breaks(events) -> list[float]:
    """Times at which one flight ends or another begins, from flight events in time order.

    Parameters
    ----------
    events : iterable of dict
        ``{"time_s", "event", "mode"}`` with ``event`` one of ``"flight_mode"``,
        ``"landed"`` or ``"serial"`` (then ``"serial"`` holds the number).

    Returns
    -------
    list of float
        Break times [s]: take-offs from the ground, landings, a mission mode
        after a landing mode (touchdown and take-off between two records), and
        a change of aircraft serial number.
    """
    breaks = []
    airborne: bool | None = None      # unknown at the start of a log
    landing = False
    serial = None
    for event in events:
        t, kind, mode = event["time_s"], event["event"], str(event.get("mode", "")).upper()
        if kind == "serial":
            if serial is not None and event["serial"] != serial:
                breaks.append(t)
            serial = event["serial"]
        elif kind == "landed" or mode == "LANDED":
            if airborne is not False:
                breaks.append(t)
            airborne, landing = False, False
        elif mode in TAKEOFF_MODES:
            if not airborne:
                breaks.append(t)
            airborne, landing = True, False
        elif mode in LANDING_MODES:
            airborne, landing = True, True
        elif mode in MISSION_MODES:
            if landing:
                breaks.append(t)
            airborne, landing = True, False
    return breaks


def mode_events(time_s, modes) -> list[dict]:
    """Flight events from a per-record flight-mode column (a mode change is an event)."""
    events = []
    previous = None
    for t, mode in zip(np.asarray(time_s, dtype=float), modes):
        mode = str(mode)
        if mode != previous:
            events.append({"time_s": float(t), "event": "flight_mode", "mode": mode})
            previous = mode
    return events


def is_dji_raw(text_head: str) -> bool:
    """True when text (the first part of a file) looks like a DJI app log with battery records."""
    return BATTERY_MARK in text_head or bool(_LOGCAT_LINE.match(text_head.lstrip("\ufeff")))


def _fields(body: str) -> dict[str, str]:
    out = {}
    for part in body.split(","):
        key, sep, value = part.partition("=")
        if sep:
            out[key.strip()] = value.strip()
    return out


def _float(text: str | None) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return np.nan


def read_dji_raw(text: str, path_name: str) -> CanonicalTable:
    """Battery records of a DJI app log as canonical columns.

    Returns
    -------
    CanonicalTable
        ``time_s`` (seconds since the first battery record), ``voltage_V``,
        ``current_A`` (as logged; positive while discharging), ``temperature_C``,
        ``soc_pct`` and ``flight_mode`` (last flight event before the record);
        ``meta["events"]`` lists flight events (a change of serial number is
        in ``meta["notes"]``); ``breaks_s`` holds the flight boundaries
        (:func:`flight_breaks`).

    Raises
    ------
    DataError
        No battery records, or a record without voltage or current.
    """
    rows = []
    events = []
    serials: list[dict] = []
    mode = "UNKNOWN"
    day_offset = 0.0
    previous = None
    line_number, scanned_to = 1, 0
    ignored = 0
    for match in _EVENT.finditer(text):
        clock = int(match.group(1)) * 3600 + int(match.group(2)) * 60 + float(match.group(3))
        if previous is not None and clock + day_offset < previous - 12 * 3600:
            day_offset += 86400.0
        t = clock + day_offset
        previous = t
        line_number += text.count("\n", scanned_to, match.start())
        scanned_to = match.start()
        if match.group("battery") is not None:
            fields = _fields(match.group("battery"))
            if fields.get("exists", "true") != "true":
                ignored += 1
                continue
            try:
                voltage_mV = float(fields["currentVoltage"])
                current_mA = float(fields["currentCurrent"])
            except (KeyError, ValueError):
                raise DataError(f"{path_name} line {line_number}: battery record without a "
                                "readable currentVoltage/currentCurrent") from None
            smart = fields.get("smartBattery", "true") == "true"
            temperature = _float(fields.get("temperature"))
            if not smart and temperature == 0.0:
                temperature = np.nan  # not reported by a pack without smart-battery data
            soc = _float(fields.get("remainPowerPercent"))
            rows.append((t, voltage_mV * 1e-3, current_mA * 1e-3, temperature, soc, mode,
                         line_number))
        elif match.group("new") is not None:
            mode = match.group("new")
            events.append({"clock_s": t, "event": "flight_mode", "mode": mode,
                           "line": line_number})
        elif match.group("serial") is not None:
            serial = match.group("serial")
            if not serials or serials[-1]["serial"] != serial:
                serials.append({"clock_s": t, "event": "serial", "serial": serial,
                                "line": line_number})
        else:
            mode = "LANDED"
            events.append({"clock_s": t, "event": "landed", "mode": mode, "line": line_number})
    if not rows:
        raise DataError(f"{path_name}: no '{BATTERY_MARK}...}}' battery records found; "
                        "is this a DJI app log?")
    data = np.array([r[:5] for r in rows], dtype=float)
    t0 = data[0, 0]
    frame = pd.DataFrame({
        "time_s": data[:, 0] - t0,
        "voltage_V": data[:, 1],
        "current_A": data[:, 2],
        "temperature_C": data[:, 3],
        "soc_pct": data[:, 4],
        "flight_mode": np.array([r[5] for r in rows], dtype=object),
    })
    for event in events + serials:
        event["time_s"] = round(event.pop("clock_s") - t0, 3)
    breaks = flight_breaks(sorted(events + serials, key=lambda e: (e["time_s"], e["line"])))
    hours, rem = divmod(t0 % 86400.0, 3600.0)
    meta = {
        "format": "dji-raw",
        "clock_start": f"{int(hours):02d}:{int(rem // 60):02d}:{rem % 60:06.3f}",
        "events": events,
        "units": {"time_s": "s (log clock)", "voltage_V": "mV (log)", "current_A": "mA (log)",
                  "temperature_C": "degC (log)", "soc_pct": "% (log)"},
        "column_map": {"time_s": "log time HH:MM:SS.mmm", "voltage_V": "currentVoltage",
                       "current_A": "currentCurrent", "temperature_C": "temperature",
                       "soc_pct": "remainPowerPercent", "flight_mode": "last flight event"},
        "notes": [],
        "explicit_units": ["time_s", "voltage_V", "current_A"],
    }
    if day_offset:
        meta["notes"].append("the log passes midnight; times after it were shifted by 24 h")
    if ignored:
        meta["notes"].append(f"{ignored} battery record(s) with exists=false ignored")
    for before, after in zip(serials, serials[1:]):
        meta["notes"].append(f"line {after['line']}: the aircraft serial number changes from "
                             f"{before['serial']} to {after['serial']} (another aircraft and "
                             "pack: the flight ends there)")
    return CanonicalTable(frame=frame, line_numbers=np.array([r[6] for r in rows]), meta=meta,
                          breaks_s=breaks)


__all__ = ["is_dji_raw", "read_dji_raw", "flight_breaks", "mode_events", "BATTERY_MARK",
           "TAKEOFF_MODES", "LANDING_MODES", "MISSION_MODES"]
