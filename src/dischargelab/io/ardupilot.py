"""ArduPilot DataFlash logs, binary ``.bin`` and text ``.log``, read with pymavlink.

Battery messages (field meanings from ArduPilot's log documentation):

* ``BAT`` (ArduPilot 3.6 and later; ``BAT2`` for the second battery in 3.6-3.x):
  ``TimeUS`` [us], ``Instance``/``Inst``, ``Volt`` [V], ``VoltR`` [V, estimated
  resting voltage], ``Curr`` [A], ``CurrTot`` [mAh], ``EnrgTot`` [Wh], ``Temp``
  [degC], ``Res`` [ohm], ``RemPct`` [%] where logged;
* ``CURR`` (older logs): ``Volt`` [centivolts when stored as an integer],
  ``Curr`` [centiamperes when stored as an integer], ``CurrTot`` [mAh]. Old
  ``CURR`` has no time field: its time is that of the last ``GPS`` record
  before it (``Week``, ``TimeMS``), so GPS is read in the same pass;
* ``BCL``: ``Instance``, ``V1``... cell voltages [mV; 0 or 65535 = no cell].

Arming comes from ``EV`` (10 armed, 11 disarmed, 16/28 take-off, 18 landed)
or ``ARM`` (``ArmState``); capacities from the ``BATT_CAPACITY``,
``BATT2_CAPACITY``... parameters [mAh].

Speed: pymavlink indexes the file once and then jumps straight to the
requested message types, so only the few battery, GPS and event messages are
decoded (see ``benchmarks/flightlog_read_speed.py``).
"""

from __future__ import annotations

import math
import struct
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError, require
from .flightlog_base import (
    DATAFLASH_HEAD,
    BatterySeries,
    FlightLog,
    build_flight_log,
    drop_unmeasured_temperature,
    quiet,
    quiet_native,
)

#: Event ids of the ``EV`` message (ArduPilot ``LogEvent``).
EVENT_IDS = {10: "armed", 11: "disarmed", 16: "takeoff", 28: "takeoff", 18: "landed"}

#: canonical column -> BAT field.
BAT_FIELDS = {"voltage_V": "Volt", "current_A": "Curr", "temperature_C": "Temp",
              "log_voltage_rest_V": "VoltR", "log_discharged_mAh": "CurrTot",
              "log_energy_Wh": "EnrgTot", "log_resistance_ohm": "Res"}

#: Format characters that pymavlink returns unscaled as integers.
_INTEGER_FORMATS = set("bBhHiIqQ")

#: Seconds in a GPS week.
WEEK_S = 604800.0

#: What pymavlink raises on a corrupt, truncated or foreign file.
_DATAFLASH_ERRORS = (ValueError, IndexError, KeyError, TypeError, AttributeError, OverflowError,
                     struct.error, UnicodeDecodeError, EOFError, OSError, AssertionError,
                     ZeroDivisionError)


class _Collector:
    """Rows per battery instance while the messages stream past."""

    def __init__(self):
        self.rows: dict[int, list[tuple]] = defaultdict(list)
        self.cells: dict[int, list[tuple]] = defaultdict(list)
        self.columns: dict[int, tuple[str, ...]] = {}
        self.labels: dict[int, str] = {}
        self.events: list[dict] = []
        self.no_time: dict[int, int] = defaultdict(int)
        self.gps_time: float | None = None
        self.first_time: float | None = None
        self.params: dict[str, float] = {}
        self.sources: set[str] = set()

    def seen(self, t: float) -> None:
        if self.first_time is None or t < self.first_time:
            self.first_time = t


def _instance(msg, default: int) -> int:
    for name in ("Instance", "Inst", "I"):
        if name in msg.fmt.colhash:
            value = getattr(msg, name)
            return int(value) if value is not None else default
    return default


def _own_time(msg) -> float | None:
    columns = msg.fmt.colhash
    if "TimeUS" in columns:
        return msg.TimeUS * 1e-6
    if "TimeMS" in columns and msg.get_type() != "GPS":
        return msg.TimeMS * 1e-3
    return None


def _gps_time(msg) -> float | None:
    """Time of a GPS record [s]: ``TimeUS``, else GPS week and milliseconds of the week."""
    columns = msg.fmt.colhash
    if "TimeUS" in columns:
        return msg.TimeUS * 1e-6
    week = next((getattr(msg, c) for c in ("Week", "GWk") if c in columns), None)
    ms = next((getattr(msg, c) for c in ("TimeMS", "GMS") if c in columns), None)
    if week is None or ms is None or (week == 0 and ms == 0):  # no fix yet
        return None
    return week * WEEK_S + ms * 1e-3


def _scale(msg, field: str, integer_scale: float) -> float:
    value = getattr(msg, field)
    if value is None:
        return math.nan
    i = msg.fmt.colhash[field]
    return float(value) * (integer_scale if msg.fmt.format[i] in _INTEGER_FORMATS else 1.0)


def read_dataflash(path, *, topic: str | None = None, fields: dict | None = None) -> FlightLog:
    """Read the battery data of an ArduPilot DataFlash log (binary or text).

    Parameters
    ----------
    path : path-like
        ``.bin`` or text ``.log`` file.
    topic : str, optional
        Message with the battery data instead of ``BAT``/``BAT2``/``CURR``.
    fields : dict, optional
        With ``topic``: canonical name -> field name (values taken as V, A...);
        default ``Volt`` and ``Curr``.

    Returns
    -------
    FlightLog

    Raises
    ------
    DataError
        Unreadable file, or no battery message.
    """
    require("pymavlink", "logs")
    from pymavlink import DFReader

    path = Path(path)
    with open(path, "rb") as fh:
        binary = fh.read(len(DATAFLASH_HEAD)) == DATAFLASH_HEAD
    kind = "ardupilot-bin" if binary else "ardupilot-text"
    if topic and not fields:
        fields = {"voltage_V": "Volt", "current_A": "Curr"}
    battery_types = [topic] if topic else ["BAT", "BAT2", "CURR"]
    types = battery_types + ["BCL", "GPS", "EV", "ARM", "PARM"]
    collector = _Collector()
    try:
        with quiet("pymavlink"), quiet_native():
            if binary:
                reader = DFReader.DFReader_binary(str(path))
            else:
                reader = DFReader.DFReader_text(str(path))
            defined = len(getattr(reader, "formats", {})) > 1  # more than the built-in FMT
            try:
                _stream(reader, types, collector, topic, fields)
            finally:
                _close(reader)
    except DataError as exc:
        raise DataError(f"{path.name}: {exc}") from None
    except Exception as exc:
        # pymavlink reports a corrupt format table with a bare Exception ("Unsupported format
        # char"); any other kind that is not in the list is a bug and goes on
        if not isinstance(exc, _DATAFLASH_ERRORS) and type(exc) is not Exception:
            raise
        raise DataError(f"{path.name}: the DataFlash log is corrupt or truncated and cannot be "
                        f"read ({type(exc).__name__}); copy the log from the vehicle again or "
                        "check that it is an ArduPilot log") from None
    if not defined:
        raise DataError(f"{path.name}: no message definitions (FMT) in the file: it is corrupt, "
                        "cut at its start, or not an ArduPilot DataFlash log")
    if not collector.rows:
        known = ", ".join(battery_types)
        raise DataError(f"{path.name}: no battery messages ({known}) in the log; is the battery "
                        "monitor enabled (BATT_MONITOR)? For another message use topic= and "
                        "fields= (CLI: --topic NAME --fields voltage_V=F,current_A=F)")
    return _assemble(path, kind, collector)


def _close(reader) -> None:
    close = getattr(reader, "close", None)  # older pymavlink readers have no close()
    if close is not None:
        close()
    else:
        reader.filehandle.close()


def _stream(reader, types, collector: _Collector, topic, fields) -> None:
    wanted = set(types)
    while True:
        msg = reader.recv_match(type=types)
        if msg is None:
            return
        name = msg.get_type()
        if name not in wanted:  # pymavlink adds MODE, MSG... to any type filter
            continue
        if name == "GPS":
            t = _gps_time(msg)
            if t is not None:
                collector.gps_time = t
                collector.seen(t)
            continue
        if name == "PARM":
            collector.params[str(msg.Name)] = float(msg.Value)
            continue
        t = _own_time(msg)
        if t is None:
            t = collector.gps_time
        if name == topic:
            _battery_row(msg, name, t, collector, topic, fields)
        elif name in ("EV", "ARM"):
            _event(msg, name, t, collector)
        elif name == "BCL":
            if t is not None:
                _cells(msg, t, collector)
        else:
            _battery_row(msg, name, t, collector, topic, fields)


def _event(msg, name: str, t, collector: _Collector) -> None:
    if name == "EV":
        event = EVENT_IDS.get(int(msg.Id))
    else:
        event = "armed" if int(msg.ArmState) else "disarmed"
    if event is not None:
        collector.events.append({"time_s": t, "event": event})


def _cells(msg, t: float, collector: _Collector) -> None:
    volts = []
    k = 1
    while f"V{k}" in msg.fmt.colhash:
        raw = getattr(msg, f"V{k}")
        volts.append(math.nan if raw in (None, 0, 0xFFFF) else raw * 1e-3)
        k += 1
    collector.cells[_instance(msg, 0)].append((t, *volts))


def _battery_row(msg, name: str, t, collector: _Collector, topic, fields) -> None:
    if name == "BAT2":
        instance = _instance(msg, 1)
    else:
        instance = _instance(msg, 0)
    if t is None:
        collector.no_time[instance] += 1
        return
    collector.seen(t)
    if topic is not None:
        columns = tuple(fields)
        row = tuple(float(getattr(msg, fields[c])) if fields[c] in msg.fmt.colhash else math.nan
                    for c in columns)
        collector.sources.add(f"{name} ({', '.join(f'{k} = {v}' for k, v in fields.items())})")
    elif name == "CURR":
        columns = ("voltage_V", "current_A", "log_discharged_mAh")
        row = (_scale(msg, "Volt", 0.01), _scale(msg, "Curr", 0.01),
               float(msg.CurrTot) if "CurrTot" in msg.fmt.colhash else math.nan)
        collector.sources.add("CURR")
    else:
        columns = tuple(k for k, f in BAT_FIELDS.items() if f in msg.fmt.colhash)
        row = tuple(_value(msg, BAT_FIELDS[c]) for c in columns)
        if "RemPct" in msg.fmt.colhash:
            columns += ("log_remaining_frac",)
            row += (_value(msg, "RemPct") / 100.0,)
        collector.sources.add(name)
    previous = collector.columns.setdefault(instance, columns)
    if previous != columns:
        raise DataError(f"battery instance {instance} is logged in two different message layouts "
                        f"({', '.join(previous)} and {', '.join(columns)}); choose one with "
                        "topic=")
    collector.labels.setdefault(instance, f"{name}[{instance}]")
    collector.rows[instance].append((t, *row))


def _value(msg, field: str) -> float:
    value = getattr(msg, field)
    return math.nan if value is None else float(value)


def _assemble(path: Path, kind: str, collector: _Collector) -> FlightLog:
    batteries = []
    for instance in sorted(collector.rows):
        columns = ("time_s",) + collector.columns[instance]
        frame = pd.DataFrame(np.array(collector.rows[instance], dtype=float), columns=columns)
        series = BatterySeries(index=instance, label=collector.labels[instance], frame=frame)
        if collector.no_time[instance]:
            series.dropped["no_time"] = collector.no_time[instance]
        if series.label.startswith("CURR"):
            series.notes.append("old CURR message: time from the last GPS record before each "
                                "record (CURR has no time field)")
        drop_unmeasured_temperature(series, "Temp")
        _merge_cells(series, collector.cells.get(instance, []))
        capacity = collector.params.get("BATT_CAPACITY" if instance == 0
                                        else f"BATT{instance + 1}_CAPACITY")
        if capacity and capacity > 0:
            series.capacity_mAh = float(capacity)
        batteries.append(series)
    notes = [f"battery data from {', '.join(sorted(collector.sources))}"]
    events = [e for e in collector.events if e["time_s"] is not None]
    undated = len(collector.events) - len(events)
    start = collector.first_time
    if undated:
        # events before the first GPS record happened at the log start (the GPS clock's zero)
        events = [{"time_s": start, "event": e["event"]} for e in collector.events
                  if e["time_s"] is None] + events
    return build_flight_log(path, kind, batteries, start_s=start, events=events, notes=notes)



def _merge_cells(series: BatterySeries, rows: list[tuple]) -> None:
    """Attach BCL cell voltages to the battery records (nearest BCL within 1 s)."""
    if not rows:
        return
    width = max(len(r) for r in rows)
    cells = pd.DataFrame([r + (math.nan,) * (width - len(r)) for r in rows],
                         columns=["time_s"] + [f"cell{k}_V" for k in range(1, width)])
    present = [c for c in cells.columns[1:] if np.isfinite(cells[c].to_numpy()).any()]
    if not present:
        return
    cells = cells[["time_s"] + present].sort_values("time_s")
    merged = pd.merge_asof(series.frame.reset_index().sort_values("time_s"), cells, on="time_s",
                           direction="nearest", tolerance=1.0)
    series.frame = merged.sort_values("index").drop(columns="index").reset_index(drop=True)
    series.cells = len(present)
    series.notes.append(f"cell voltages from BCL ({len(present)} cells), matched to the nearest "
                        "BCL record within 1 s")


__all__ = ["read_dataflash", "EVENT_IDS", "BAT_FIELDS"]
