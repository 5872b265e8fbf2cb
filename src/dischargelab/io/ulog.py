"""PX4 ULog files: ``battery_status`` of every instance, arming and landing state.

Read with pyulog (the ``logs`` extra). Fields of ``battery_status`` used
(PX4 uORB message, SI units): ``timestamp`` [us], ``voltage_v`` [V],
``current_a`` [A, discharge positive; -1 = not measured], ``discharged_mah``
[mAh, a counter that need not start at 0], ``remaining`` [0-1],
``temperature`` [degC; 0 or NaN = not measured], ``cell_count``,
``voltage_cell_v[0..N]`` [V], ``capacity`` [mAh; 0 = not set] and, where the
PX4 version logs them, ``internal_resistance_estimate`` [ohm] and
``ocv_estimate`` [V].

Flights come from ``vehicle_status.arming_state`` (2 = armed) or
``actuator_armed.armed``; take-off and landing from
``vehicle_land_detected.landed``. The state in a topic's first record is
taken to hold from the log start (PX4 logs from arming by default).
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError, require
from .flightlog_base import (
    BatterySeries,
    FlightLog,
    _first_line,
    build_flight_log,
    drop_rows,
    drop_unmeasured_temperature,
    quiet,
)

BATTERY_TOPIC = "battery_status"

#: canonical column -> battery_status field.
BATTERY_FIELDS = {
    "voltage_V": "voltage_v",
    "current_A": "current_a",
    "temperature_C": "temperature",
    "log_discharged_mAh": "discharged_mah",
    "log_remaining_frac": "remaining",
    "log_resistance_ohm": "internal_resistance_estimate",
    "log_voltage_rest_V": "ocv_estimate",
}

STATE_TOPICS = ("vehicle_status", "actuator_armed", "vehicle_land_detected")

#: PX4 ``vehicle_status.arming_state`` value meaning armed.
ARMING_STATE_ARMED = 2

#: Field names that look like a voltage or a current (for the "other topic" hint).
_LOOKS_ELECTRIC = re.compile(r"volt|vbat|current|curr_|amper", re.IGNORECASE)

#: What pyulog raises on a corrupt, truncated or foreign file.
_ULOG_ERRORS = (OSError, ValueError, IndexError, KeyError, TypeError, OverflowError,
                struct.error, UnicodeDecodeError, EOFError, MemoryError)


def _load(pyulog, path: Path, topics):
    name = path.name
    try:
        with quiet("pyulog") as captured:
            ulog = pyulog.ULog(str(path), list(topics) if topics else None, True)
    except pyulog.core.ULogException as exc:
        raise DataError(f"{name}: not a readable ULog file ({_first_line(exc)}); the file is "
                        "truncated or corrupt at its start, or not a PX4 log") from None
    except _ULOG_ERRORS as exc:
        raise DataError(f"{name}: the ULog file is corrupt or truncated and cannot be read "
                        f"({type(exc).__name__}); copy the log from the vehicle again") from None
    return ulog, captured.getvalue()


def read_ulog(path, *, topic: str | None = None, fields: dict | None = None) -> FlightLog:
    """Read the battery data of a PX4 ULog file.

    Parameters
    ----------
    path : path-like
        ``.ulg`` file.
    topic : str, optional
        Topic with the battery data (default ``battery_status``).
    fields : dict, optional
        Canonical name -> field of ``topic`` (default :data:`BATTERY_FIELDS`).

    Returns
    -------
    FlightLog

    Raises
    ------
    DataError
        Unreadable file; no battery topic (the message names the topics and
        fields that look like voltage or current and how to use them).
    """
    pyulog = require("pyulog", "logs")
    path = Path(path)
    topic = topic or BATTERY_TOPIC
    ulog, printed = _load(pyulog, path, (topic,) + STATE_TOPICS)
    notes = []
    if ulog.file_corruption or "corrupt" in printed.lower():
        notes.append("the ULog reader found corrupt data; records in the damaged part are "
                     "missing")
    start = int(ulog.start_timestamp)
    datasets = sorted((d for d in ulog.data_list if d.name == topic), key=lambda d: d.multi_id)
    if not datasets and not ulog.message_formats:
        raise DataError(f"{path.name}: the ULog file ends before its message definitions (cut "
                        "or corrupt); copy the log from the vehicle again")
    if not datasets:
        raise DataError(_no_topic_message(pyulog, path, ulog, topic))
    mapping = dict(fields) if fields else BATTERY_FIELDS
    batteries = [_battery(d, mapping, topic, custom=fields is not None) for d in datasets]
    events = _events(ulog, start)
    if not events:
        notes.append("no arming or landing state in the log (vehicle_status, actuator_armed, "
                     "vehicle_land_detected): flights found from the current")
    log = build_flight_log(path, "ulog", batteries, start_s=start * 1e-6, events=events,
                           notes=notes)
    return log


def _seconds(timestamps: np.ndarray) -> np.ndarray:
    """ULog timestamps [us since boot] -> seconds since boot."""
    return timestamps.astype(np.int64) * 1e-6


def _battery(dataset, mapping: dict, topic: str, *, custom: bool) -> BatterySeries:
    data = dataset.data
    label = f"{topic}[{dataset.multi_id}]"
    missing = [f for key, f in mapping.items() if key in ("voltage_V", "current_A")
               and f not in data]
    if missing:
        available = ", ".join(sorted(k for k in data if k != "timestamp"))
        raise DataError(f"{label} has no field {', '.join(missing)}; its fields are "
                        f"{available}")
    frame = pd.DataFrame({"time_s": _seconds(data["timestamp"])})
    for key, name in mapping.items():
        if name in data:
            frame[key] = data[name].astype(float)
    series = BatterySeries(index=int(dataset.multi_id), label=label, frame=frame)
    if custom:
        series.notes.append(f"battery data from {topic} fields "
                            + ", ".join(f"{k} = {v}" for k, v in mapping.items())
                            + " (taken as V, A, degC)")
        return series
    _add_cells(series, data)
    series.frame = drop_rows(series.frame, series.frame["current_A"].to_numpy() == -1.0,
                             "current_not_measured", series.dropped)
    drop_unmeasured_temperature(series, "temperature")
    _check_cells(series)
    capacity = data.get("capacity")
    if capacity is not None and capacity.size and float(np.nanmax(capacity)) > 0:
        series.capacity_mAh = float(np.nanmax(capacity))
    return series



def _add_cells(series: BatterySeries, data: dict) -> None:
    """Cell count, and the first ``cell_count`` voltage_cell_v slots as cellK_V."""
    counts = data.get("cell_count")
    if counts is None or not counts.size or int(np.max(counts)) <= 0:
        return
    cells = int(np.max(counts))
    series.cells = cells
    slots = sorted((k for k in data if k.startswith("voltage_cell_v[")),
                   key=lambda k: int(k[len("voltage_cell_v["):-1]))
    if not slots:
        return
    if cells > len(slots):
        series.notes.append(f"cell_count is {cells} but the log has only {len(slots)} "
                            "voltage_cell_v slots: per-cell voltages not kept")
        return
    for k in range(cells):
        series.frame[f"cell{k + 1}_V"] = data[slots[k]].astype(float)


def _check_cells(series: BatterySeries) -> None:
    """Keep per-cell voltages only when they look measured."""
    columns = series.cell_columns
    if not columns or not series.rows:
        return
    block = series.frame[columns].to_numpy(dtype=float)
    reason = None
    if not np.any(np.isfinite(block) & (block > 0)):
        reason = "per-cell voltages not measured (voltage_cell_v is 0 or NaN)"
    elif np.all(np.nanmax(block, axis=1) - np.nanmin(block, axis=1) < 1e-4):
        reason = ("per-cell voltages in the log are all equal in every record (derived from "
                  "the pack voltage, not measured): not kept")
    if reason:
        series.frame = series.frame.drop(columns=columns)
        series.notes.append(reason)


def _events(ulog, start: int) -> list[dict]:
    """Armed/disarmed and take-off/landed events from the state topics."""
    by_name = {d.name: d for d in ulog.data_list if d.multi_id == 0}
    events: list[dict] = []
    status = by_name.get("vehicle_status")
    armed = by_name.get("actuator_armed")
    if status is not None and "arming_state" in status.data:
        events += _transitions(status.data, status.data["arming_state"] == ARMING_STATE_ARMED,
                               "armed", "disarmed", start)
    elif armed is not None and "armed" in armed.data:
        events += _transitions(armed.data, armed.data["armed"] != 0, "armed", "disarmed", start)
    land = by_name.get("vehicle_land_detected")
    if land is not None and "landed" in land.data:
        events += _transitions(land.data, land.data["landed"] == 0, "takeoff", "landed", start)
    return events


def _transitions(data: dict, state: np.ndarray, on: str, off: str, start: int) -> list[dict]:
    t = _seconds(data["timestamp"])
    state = np.asarray(state, dtype=bool)
    if not state.size:
        return []
    order = np.argsort(t, kind="stable")
    t, state = t[order], state[order]
    events = [{"time_s": min(float(t[0]), start * 1e-6), "event": on if state[0] else off}]
    for k in np.flatnonzero(state[1:] != state[:-1]) + 1:
        events.append({"time_s": float(t[k]), "event": on if state[k] else off})
    return events


def _no_topic_message(pyulog, path: Path, ulog, topic: str) -> str:
    """The one-line error for a ULog without the battery topic, naming candidates."""
    candidates = {}
    for name, fmt in ulog.message_formats.items():
        hits = [f[2] for f in fmt.fields if _LOOKS_ELECTRIC.search(f[2])
                and not f[2].startswith("_padding")]
        if hits:
            candidates[name] = hits
    logged = set()
    if candidates:
        full, _ = _load(pyulog, path, tuple(candidates))
        logged = {d.name for d in full.data_list}
    found = [f"{name}.{field}" for name in sorted(candidates) if name in logged
             for field in candidates[name]][:8]
    text = f"{path.name} has no {topic} topic"
    if not found:
        return text + " and no logged field that looks like a voltage or a current"
    example = found[0].split(".")
    return (text + f"; fields that look like voltage or current: {', '.join(found)}; read them "
            f"with topic='{example[0]}', fields={{'voltage_V': '<field>', 'current_A': "
            f"'<field>'}} (CLI: --topic {example[0]} --fields voltage_V=<field>,"
            f"current_A=<field>)")


__all__ = ["read_ulog", "BATTERY_TOPIC", "BATTERY_FIELDS"]
