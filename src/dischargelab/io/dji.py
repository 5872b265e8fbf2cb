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

Flight events kept: ``onFlightMode change: A -> B`` (mode B from then on) and
``TAKEOFF_POSITION_UPDATED as landed`` (mode ``LANDED``). Take-offs
(``*_TAKEOFF`` modes) and landings also end a discharge segment, so a file with
several flights yields one segment per flight. The clock has no date: a time
earlier than the previous line by more than 12 h is taken as a midnight rollover.

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
    r"|(?P<landed>TAKEOFF_POSITION_UPDATED as landed))",
    re.MULTILINE,
)
_LOGCAT_LINE = re.compile(r"^\d{2}:\d{2}:\d{2}\.\d{3} [VDIWEF]/")

#: Flight modes that start a flight; a segment ends before them.
TAKEOFF_MODES = ("AUTO_TAKEOFF", "ASSISTED_TAKEOFF", "TAKEOFF")


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
        ``meta["events"]`` lists flight events; ``breaks_s`` holds take-off and
        landing times.

    Raises
    ------
    DataError
        No battery records, or a record without voltage or current.
    """
    rows = []
    events = []
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
    for event in events:
        event["time_s"] = round(event.pop("clock_s") - t0, 3)
    breaks = [e["time_s"] for e in events
              if e["event"] == "landed" or e["mode"] in TAKEOFF_MODES]
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
    return CanonicalTable(frame=frame, line_numbers=np.array([r[6] for r in rows]), meta=meta,
                          breaks_s=breaks)


__all__ = ["is_dji_raw", "read_dji_raw", "BATTERY_MARK", "TAKEOFF_MODES"]
