"""MAVLink telemetry logs (``.tlog``): what a ground station saved, read with pymavlink.

Mission Planner and QGroundControl write every MAVLink message they receive,
each preceded by its arrival time: a 64-bit big-endian UNIX time in
microseconds. The frames are MAVLink 1 (marker 0xFE) or MAVLink 2 (0xFD);
pymavlink's MAVLink 2 parser decodes both and checks each checksum.

Battery data (field meanings and "unknown" values from the MAVLink common
message set):

* ``BATTERY_STATUS`` (per battery ``id``): ``voltages[]`` [mV; UINT16_MAX =
  unknown; cell voltages, or the pack voltage in ``voltages[0]`` with the others
  unknown; above 65.534 V, ``voltages[0]`` is UINT16_MAX - 1 and ``voltages[1]``
  holds the rest], ``voltages_ext[]`` [mV, 0 = unused], ``current_battery``
  [cA; -1 = unknown], ``current_consumed`` [mAh; -1 = unknown],
  ``energy_consumed`` [hJ; -1 = unknown], ``temperature`` [cdegC; INT16_MAX =
  unknown], ``battery_remaining`` [%; -1 = unknown];
* ``SYS_STATUS`` (used when no ``BATTERY_STATUS`` has both voltage and current):
  ``voltage_battery`` [mV; UINT16_MAX = unknown], ``current_battery`` [cA; -1 =
  unknown], ``battery_remaining`` [%; -1 = unknown];
* ``HEARTBEAT`` of the vehicle (not a ground station, autopilot not
  ``MAV_AUTOPILOT_INVALID``): ``base_mode`` bit 128 (``MAV_MODE_FLAG_SAFETY_ARMED``)
  gives the flights; without it they come from the current;
* ``PARAM_VALUE``: the configured capacity (``BATT_CAPACITY``, ``BAT1_CAPACITY``)
  [mAh] and cell count (``BAT1_N_CELLS``) when the ground station fetched them.

A file may hold several recordings joined together. A new **session** starts
where the arrival time steps back (and stays back), where no message arrived for more than
:data:`SESSION_GAP_S`, or where the consumed-charge counter restarts. Sessions
in time order and less than an hour apart keep their clock; otherwise they are
laid end to end, :data:`SESSION_SPACER_S` apart, so time never steps back. Flights never span
two sessions, and charge is never counted across the join.

Corrupt messages (bad checksum, broken framing, an arrival time that jumps
while the next records carry on from before it) are skipped and counted;
unknown values are missing values.

References
----------
MAVLink common message set, https://mavlink.io/en/messages/common.html
(``BATTERY_STATUS``, ``SYS_STATUS``, ``HEARTBEAT``, ``MAV_MODE_FLAG``);
MAVLink serialisation (frame layout), https://mavlink.io/en/guide/serialization.html
"""

from __future__ import annotations

import math
import struct
from collections import defaultdict
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError, require
from .flightlog_base import (
    BatterySeries,
    FlightLog,
    build_flight_log,
    drop_rows,
    drop_unmeasured_temperature,
)

#: Frame start markers: MAVLink 1 and MAVLink 2.
MARKER_V1, MARKER_V2 = 0xFE, 0xFD
#: Message ids read (the others are skipped by their length, not decoded).
HEARTBEAT, SYS_STATUS, PARAM_VALUE, BATTERY_STATUS = 0, 1, 22, 147
WANTED = frozenset((HEARTBEAT, SYS_STATUS, PARAM_VALUE, BATTERY_STATUS))
#: MAVLink "unknown" values.
UINT16_UNKNOWN, INT16_UNKNOWN, SIGNED_UNKNOWN = 65535, 32767, -1
#: ``voltages[0]`` when the pack voltage overflows into ``voltages[1]``.
UINT16_OVERFLOW = 65534
#: ``base_mode`` flag of an armed vehicle.
ARMED_FLAG = 128
#: ``HEARTBEAT.type`` of a ground station and ``autopilot`` of a non-autopilot.
MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID = 6, 8
#: Arrival times outside these UNIX times [s] are corrupt (2000-01-01, 2100-01-01).
EARLIEST_S, LATEST_S = 946684800.0, 4102444800.0
#: No message for longer than this [s]: the recording stopped, a new session starts.
SESSION_GAP_S = 120.0
#: Arrival times of messages from two links may step back by this much [s] (a reordered
#: message, not a new recording; its record is dropped as out of time order).
JITTER_S = 0.5
#: Records looked at after a jump of the arrival time to tell a corrupt time from a new session.
LOOK_AHEAD = 6
#: Arrival times further apart than this [s] are checked against the records after them.
STEP_S = JITTER_S
#: Sessions that do not follow each other in time, or pause longer than
#: :data:`KEEP_CLOCK_GAP_S` [s], are laid this far apart [s].
SESSION_SPACER_S = 60.0
KEEP_CLOCK_GAP_S = 3600.0
#: The same sender, message and sequence number again within this time [s] is a duplicate.
DUPLICATE_S = 2.0
#: A consumed-charge counter falling by more than this [mAh] has restarted.
COUNTER_RESTART_MAH = 1.0
#: Cell voltages are read as cells only inside this range [mV].
CELL_MV = (1000, 5000)
#: Parameters naming the capacity [mAh] and the cell count, by battery instance (0-based).
CAPACITY_PARAMS = ("BATT{n}_CAPACITY", "BAT{m}_CAPACITY")
CELLS_PARAMS = ("BAT{m}_N_CELLS",)


def is_tlog(head: bytes) -> bool:
    """True when ``head`` (the first bytes of a file) starts like a telemetry log.

    Three consecutive records must each hold a UNIX time in microseconds
    between 2000 and 2100 followed by a MAVLink frame marker, the next record
    starting where the frame's length says (two records when the file is that short).
    """
    pos, found = 0, 0
    while found < 3:
        frame = _frame_at(head, pos)
        if frame is None:
            return found >= 2 and pos >= len(head) - 8
        found += 1
        pos = frame[0]
    return True


def _frame_at(data: bytes, pos: int):
    """``(end, marker)`` of the record at ``pos`` when it looks valid, else None."""
    if pos + 16 > len(data):
        return None
    t = int.from_bytes(data[pos:pos + 8], "big") * 1e-6
    marker = data[pos + 8]
    if not EARLIEST_S <= t <= LATEST_S or marker not in (MARKER_V1, MARKER_V2):
        return None
    length = data[pos + 9]
    if marker == MARKER_V1:
        size = length + 8
    else:
        size = length + 12 + (13 if data[pos + 10] & 1 else 0)
    end = pos + 8 + size
    return (end, marker) if end <= len(data) else None


@dataclass
class _Scan:
    """What the scan of a file found."""

    times: list[float] = field(default_factory=list)        # every good record
    messages: list[tuple[int, float, object]] = field(default_factory=list)  # (record, t, msg)
    corrupt: int = 0          # bad checksum of a decoded message, or a broken frame
    skipped_bytes: int = 0    # bytes skipped to find the next frame
    truncated: bool = False   # the last record is cut short
    spikes: int = 0           # records with a corrupt arrival time


def _scan(data: bytes, mavlink) -> _Scan:
    """Walk the records; decode the wanted messages; count what is corrupt."""
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    scan = _Scan()
    n, pos = len(data), 0
    resyncing = False
    while pos + 8 < n:
        found = _frame_at(data, pos)
        # a frame is trusted when the next record starts where its length says (or at EOF)
        if found is not None and (found[0] >= n - 8 or _frame_at(data, found[0]) is not None
                                  or found[0] + 16 > n):
            end, marker = found
            if resyncing:
                scan.corrupt += 1
                resyncing = False
            t = int.from_bytes(data[pos:pos + 8], "big") * 1e-6
            msgid = data[pos + 13] if marker == MARKER_V1 else (
                data[pos + 15] | data[pos + 16] << 8 | data[pos + 17] << 16)
            record = len(scan.times)
            scan.times.append(t)
            if msgid in WANTED:
                try:
                    msg = parser.decode(bytearray(data[pos + 8:end]))
                except (mavlink.MAVError, struct.error, ValueError, IndexError, TypeError,
                        UnicodeDecodeError):  # bad checksum, length or payload
                    scan.corrupt += 1
                    msg = None
                if msg is not None:
                    scan.messages.append((record, t, msg))
            pos = end
            continue
        if pos + 16 > n or (found is None and _looks_truncated(data, pos)):
            scan.truncated = True
            break
        resyncing = True
        scan.skipped_bytes += 1
        pos += 1
    if resyncing:
        scan.corrupt += 1
    return scan


def _looks_truncated(data: bytes, pos: int) -> bool:
    """A last record whose header is valid but whose frame runs past the end of the file."""
    if pos + 10 > len(data):
        return True
    t = int.from_bytes(data[pos:pos + 8], "big") * 1e-6
    return (EARLIEST_S <= t <= LATEST_S and data[pos + 8] in (MARKER_V1, MARKER_V2)
            and pos + 8 + data[pos + 9] + 8 > len(data))


# --------------------------------------------------------------------------- sessions

def _spikes(times: np.ndarray) -> np.ndarray:
    """Records whose arrival time is corrupt: a step back (more than :data:`JITTER_S`) or
    ahead (more than :data:`STEP_S`) after which most of the next :data:`LOOK_AHEAD`
    records carry on from the time before it. A jump that lasts is a pause or a new
    session, not a spike."""
    bad = np.zeros(times.size, dtype=bool)
    if times.size == 0:
        return bad
    last = float(times[0])
    for k in range(1, times.size):
        t = float(times[k])
        if last - JITTER_S <= t <= last + STEP_S:
            last = t
            continue
        ahead = times[k + 1:k + 1 + LOOK_AHEAD]
        until = last + SESSION_GAP_S if t < last else min(t, last + SESSION_GAP_S) - JITTER_S
        carry_on = np.sum((ahead >= last - JITTER_S) & (ahead <= until))
        if ahead.size and carry_on > ahead.size / 2:
            bad[k] = True
        else:
            last = t
    return bad


def _session_of_records(times: np.ndarray) -> np.ndarray:
    """Session number (1, 2, ...) of every record from its arrival time alone: a new one
    where the time goes back by more than :data:`JITTER_S` or pauses over
    :data:`SESSION_GAP_S`."""
    if times.size == 0:
        return np.zeros(0, dtype=int)
    step = np.diff(times)
    new = (step < -JITTER_S) | (step > SESSION_GAP_S)
    return np.concatenate(([1], 1 + np.cumsum(new)))


#: How :func:`_layout` says the sessions kept their clock.
OWN_CLOCK = "on the recording's own clock"


def _layout(times: np.ndarray, session: np.ndarray) -> tuple[np.ndarray, str]:
    """Log-clock time [s] from 0 for every record, and how the sessions were laid out."""
    numbers = np.unique(session)
    starts = np.array([times[session == s].min() for s in numbers])
    ends = np.array([times[session == s].max() for s in numbers])
    if numbers.size == 1 or (np.all(starts[1:] > ends[:-1])
                             and np.all(starts[1:] - ends[:-1] <= KEEP_CLOCK_GAP_S)):
        return times - starts[0], OWN_CLOCK
    out = np.empty_like(times)
    offset = 0.0
    for s, a, b in zip(numbers, starts, ends):
        inside = session == s
        out[inside] = times[inside] - a + offset
        offset += (b - a) + SESSION_SPACER_S
    return out, (f"laid end to end {SESSION_SPACER_S:g} s apart (their clocks overlap, go "
                 f"back or pause over {KEEP_CLOCK_GAP_S / 3600:g} h)")


# --------------------------------------------------------------------------- reading

def read_tlog(path) -> FlightLog:
    """Read the battery data of a MAVLink telemetry log.

    Parameters
    ----------
    path : path-like
        ``.tlog`` file as saved by Mission Planner or QGroundControl.

    Returns
    -------
    FlightLog
        One battery series per ``BATTERY_STATUS`` id (or one from ``SYS_STATUS``),
        with a ``session`` column (see the module docstring).

    Raises
    ------
    DataError
        Not a telemetry log, or no battery voltage and current in it (one line).
    """
    require("pymavlink", "logs")
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    path = Path(path)
    data = path.read_bytes()
    scan = _scan(data, mavlink)
    if not scan.times:
        raise DataError(f"{path.name}: no MAVLink message found; it is not a telemetry log "
                        "(.tlog) or is corrupt from its start")
    times = np.asarray(scan.times)
    spikes = _spikes(times)
    good = ~spikes
    session = np.zeros(times.size, dtype=int)
    session[good] = _session_of_records(times[good])
    messages = [(r, t, m) for r, t, m in scan.messages if good[r]]
    collected = _collect(messages, session)
    collected.split_counter_restarts(session)
    clock = np.full(times.size, np.nan)
    clock[good], layout = _layout(times[good], session[good])
    start_time = None
    if layout == OWN_CLOCK:   # time_s = 0 is the first good record's arrival time
        start_time = datetime.fromtimestamp(float(times[good][0]), tz=UTC).replace(
            tzinfo=None).isoformat(timespec="seconds")
    batteries = collected.batteries(path.name, clock, session)
    notes = _notes(scan, int(spikes.sum()), session, layout, collected)
    events = collected.events(clock, session)
    log = build_flight_log(path, "mavlink-tlog", batteries, start_s=0.0, events=events,
                           notes=notes)
    log.skipped = {"corrupt_messages": scan.corrupt + int(spikes.sum()),
                   "truncated_messages": int(scan.truncated)}
    log.start_time = start_time
    return log


class _Collected:
    """The decoded battery, heartbeat and parameter messages, by system."""

    def __init__(self):
        self.battery: dict[tuple[int, int], list] = defaultdict(list)   # (sys, id) -> rows
        self.system: dict[int, list] = defaultdict(list)                # sys -> rows
        self.heartbeats: dict[int, list] = defaultdict(list)            # sys -> (rec, armed)
        self.params: dict[str, float] = {}
        self.counts: dict[str, int] = defaultdict(int)
        self.unknown: dict[tuple, int] = defaultdict(int)
        self.restarts = 0
        self.duplicates = 0
        self.source: dict[tuple, str] = {}

    def split_counter_restarts(self, session: np.ndarray) -> None:
        """Start a new session where a battery's consumed-charge counter restarts."""
        cuts = set()
        for rows in self.battery.values():
            last: dict[int, float] = {}
            for record, *values in rows:
                consumed = values[3]
                s = session[record]
                if math.isfinite(consumed):
                    if s in last and consumed < last[s] - COUNTER_RESTART_MAH:
                        cuts.add(record)
                    last[s] = consumed
        self.restarts = len(cuts)
        if not cuts:
            return
        bump = np.zeros(session.size, dtype=int)
        bump[sorted(cuts)] = 1
        valid = session > 0
        session[valid] += np.cumsum(bump)[valid]
        # renumber consecutively
        _, session[valid] = np.unique(session[valid], return_inverse=True)
        session[valid] += 1

    def batteries(self, name: str, clock: np.ndarray, session: np.ndarray
                  ) -> list[BatterySeries]:
        chosen = _choose_sources(self)
        if not chosen:
            raise DataError(_no_battery_text(name, self))
        systems = sorted({key[0] for key in chosen})
        out = []
        for k, key in enumerate(chosen):
            sysid, bid = key
            rows = self.battery[key] if bid >= 0 else self.system[sysid]
            if len(systems) == 1:
                index, label = max(bid, 0), self.source[key]
            else:
                index, label = k, f"{self.source[key]} of system {sysid}"
            series = _series(rows, index, label, clock, session)
            _unknown_notes(series, self.unknown, key)
            capacity, cells = self._configured(bid)
            if capacity:
                series.capacity_mAh = capacity
            if cells and not series.cells:
                series.cells = cells
            out.append(series)
        return out

    def _configured(self, bid: int) -> tuple[float | None, int | None]:
        """Capacity [mAh] and cells of battery ``bid`` from the parameters, when fetched."""
        n = max(bid, 0)
        capacity_names = [f"BATT{n + 1}_CAPACITY" if n else "BATT_CAPACITY",
                          f"BAT{n + 1}_CAPACITY"] + (["BAT_CAPACITY"] if n == 0 else [])
        cells_names = [f"BAT{n + 1}_N_CELLS"] + (["BAT_N_CELLS"] if n == 0 else [])
        capacity = next((self.params[k] for k in capacity_names
                         if self.params.get(k, 0) > 0), None)
        cells = next((int(self.params[k]) for k in cells_names
                      if self.params.get(k, 0) > 0), None)
        return capacity, cells

    def events(self, clock: np.ndarray, session: np.ndarray) -> list[dict]:
        """Armed and disarmed events of the vehicle; an armed session ends disarmed."""
        vehicles = {k[0] for k in _choose_sources(self)}
        beats = sorted((rec, armed) for s in vehicles for rec, armed in self.heartbeats[s]
                       if session[rec] > 0)
        events: list[dict] = []
        state, current, last_time = False, None, 0.0
        for rec, armed in beats:
            if session[rec] != current:
                if state:
                    events.append({"time_s": last_time, "event": "disarmed"})
                state, current = False, session[rec]
            t = float(clock[rec])
            if armed != state:
                events.append({"time_s": t, "event": "armed" if armed else "disarmed"})
                state = armed
            last_time = t
        if state:
            events.append({"time_s": last_time, "event": "disarmed"})
        return events


def _collect(messages, session: np.ndarray) -> _Collected:
    out = _Collected()
    last: dict[tuple, tuple[int, float]] = {}
    for record, t, msg in messages:
        kind = msg.get_type()
        sysid = msg.get_srcSystem()
        sender = (sysid, msg.get_srcComponent(), kind)
        seq = msg.get_seq()
        previous = last.get(sender)
        last[sender] = (seq, t)
        if previous is not None and previous[0] == seq and 0 <= t - previous[1] < DUPLICATE_S:
            out.duplicates += 1  # one message received over two links
            continue
        out.counts[kind] += 1
        if kind == "HEARTBEAT":
            if msg.type != MAV_TYPE_GCS and msg.autopilot != MAV_AUTOPILOT_INVALID:
                out.heartbeats[sysid].append((record, bool(msg.base_mode & ARMED_FLAG)))
        elif kind == "PARAM_VALUE":
            param = msg.param_id
            if isinstance(param, bytes):
                param = param.decode("ascii", "replace")
            out.params[str(param).rstrip("\x00")] = float(msg.param_value)
        elif kind == "BATTERY_STATUS":
            key = (sysid, int(msg.id))
            out.source.setdefault(key, f"BATTERY_STATUS[{int(msg.id)}]")
            out.battery[key].append((record, *_battery_values(msg, out.unknown, key)))
        elif kind == "SYS_STATUS":
            key = (sysid, -1)
            out.source.setdefault(key, "SYS_STATUS")
            out.system[sysid].append((record, *_system_values(msg, out.unknown, key)))
    return out


def _known(value, unknown, counter: dict, key: tuple, what: str, scale: float) -> float:
    if value is None or value == unknown:
        counter[key + (what,)] += 1
        return math.nan
    return float(value) * scale


def _battery_values(msg, counter, key) -> tuple:
    """(voltage V, current A, cells [V...], consumed mAh, energy Wh, temperature C, remaining)."""
    raw = [int(v) for v in msg.voltages]
    ext = [int(v) for v in getattr(msg, "voltages_ext", []) or [] if v]
    valid = [v for v in raw if v != UINT16_UNKNOWN]
    cells: list[float] = []
    if not valid:
        counter[key + ("voltage",)] += 1
        voltage = math.nan
    elif raw[0] == UINT16_OVERFLOW:
        voltage = (raw[0] + (raw[1] if raw[1] != UINT16_UNKNOWN else 0)) * 1e-3
    elif len(valid) + len(ext) >= 2 and all(CELL_MV[0] <= v <= CELL_MV[1] for v in valid + ext):
        cells = [v * 1e-3 for v in valid + ext]
        voltage = sum(cells)
    else:
        voltage = raw[0] * 1e-3 if raw[0] != UINT16_UNKNOWN else math.nan
    current = _known(msg.current_battery, SIGNED_UNKNOWN, counter, key, "current", 0.01)
    consumed = float(msg.current_consumed) if msg.current_consumed != SIGNED_UNKNOWN \
        else math.nan
    energy = msg.energy_consumed * 100.0 / 3600.0 if msg.energy_consumed != SIGNED_UNKNOWN \
        else math.nan
    temperature = msg.temperature * 0.01 if msg.temperature != INT16_UNKNOWN else math.nan
    remaining = msg.battery_remaining / 100.0 if msg.battery_remaining != SIGNED_UNKNOWN \
        else math.nan
    return voltage, current, cells, consumed, energy, temperature, remaining


def _system_values(msg, counter, key) -> tuple:
    voltage = _known(msg.voltage_battery, UINT16_UNKNOWN, counter, key, "voltage", 1e-3)
    current = _known(msg.current_battery, SIGNED_UNKNOWN, counter, key, "current", 0.01)
    remaining = msg.battery_remaining / 100.0 if msg.battery_remaining != SIGNED_UNKNOWN \
        else math.nan
    return voltage, current, [], math.nan, math.nan, math.nan, remaining


def _usable(rows) -> int:
    """Records with both a known voltage and a known current."""
    return sum(1 for r in rows if math.isfinite(r[1]) and math.isfinite(r[2]))


def _choose_sources(collected: _Collected) -> list[tuple[int, int]]:
    """BATTERY_STATUS ids with voltage and current; else SYS_STATUS, per system."""
    chosen = []
    systems = sorted({k[0] for k in collected.battery} | set(collected.system))
    for sysid in systems:
        ids = [k for k in sorted(collected.battery) if k[0] == sysid
               and _usable(collected.battery[k]) >= 2]
        if ids:
            chosen.extend(ids)
        elif _usable(collected.system.get(sysid, [])) >= 2:
            chosen.append((sysid, -1))
    return chosen


def _no_battery_text(name: str, collected: _Collected) -> str:
    parts = []
    for kind, rows in (("BATTERY_STATUS", [r for v in collected.battery.values() for r in v]),
                       ("SYS_STATUS", [r for v in collected.system.values() for r in v])):
        if not rows:
            parts.append(f"no {kind}")
            continue
        currents = sum(1 for r in rows if math.isfinite(r[2]))
        volts = [r[1] for r in rows if math.isfinite(r[1])]
        text = f"{kind}: current unknown (-1) in {len(rows) - currents} of {len(rows)} records"
        if volts:
            text += (f", voltage {min(volts):.2f} V" if max(volts) - min(volts) < 0.01
                     else f", voltage {min(volts):.2f}-{max(volts):.2f} V")
        parts.append(text)
    return (f"{name}: no battery data in this telemetry log ({'; '.join(parts)}): the vehicle "
            "sent no battery current; set up its current sensor (e.g. BATT_MONITOR) and record "
            "again")


def _series(rows, index: int, label: str, clock: np.ndarray, session: np.ndarray
            ) -> BatterySeries:
    records = np.array([r[0] for r in rows], dtype=int)
    width = max((len(r[3]) for r in rows), default=0)
    table = {
        "time_s": clock[records],
        "voltage_V": np.array([r[1] for r in rows], dtype=float),
        "current_A": np.array([r[2] for r in rows], dtype=float),
        "temperature_C": np.array([r[6] for r in rows], dtype=float),
    }
    for k in range(width):
        table[f"cell{k + 1}_V"] = np.array([r[3][k] if k < len(r[3]) else math.nan
                                            for r in rows], dtype=float)
    table["log_discharged_mAh"] = np.array([r[4] for r in rows], dtype=float)
    table["log_energy_Wh"] = np.array([r[5] for r in rows], dtype=float)
    table["log_remaining_frac"] = np.array([r[7] for r in rows], dtype=float)
    table["session"] = session[records]
    frame = pd.DataFrame(table)
    frame = frame[frame["session"] > 0].reset_index(drop=True)
    series = BatterySeries(index=index, label=label, frame=frame,
                           cells=width if width >= 2 else None)
    unknown = ~np.isfinite(frame[["voltage_V", "current_A"]].to_numpy()).all(axis=1)
    series.frame = drop_rows(frame, unknown, "unknown_value", series.dropped)
    drop_unmeasured_temperature(series, "temperature")
    return series


def _unknown_notes(series: BatterySeries, unknown: dict, key: tuple) -> None:
    for what in ("voltage", "current"):
        count = unknown.get(key + (what,), 0)
        if count:
            series.notes.append(f"{count} record(s) with the {what} unknown "
                                f"({'UINT16_MAX' if what == 'voltage' else '-1'}, MAVLink's "
                                "'not known') read as missing")


def _notes(scan: _Scan, spikes: int, session: np.ndarray, layout: str,
           collected: _Collected) -> list[str]:
    notes = []
    sessions = int(session.max()) if session.size else 0
    counted = ", ".join(f"{collected.counts[k]} {k}" for k in
                        ("BATTERY_STATUS", "SYS_STATUS", "HEARTBEAT") if collected.counts[k])
    notes.append(f"{len(scan.times)} MAVLink messages ({counted})")
    corrupt = scan.corrupt + spikes
    if corrupt:
        notes.append(f"skipped {corrupt} corrupt message(s) (bad checksum, broken framing or "
                     f"a corrupt arrival time; {scan.skipped_bytes} byte(s) skipped to find "
                     "the next message)")
    if collected.duplicates:
        notes.append(f"skipped {collected.duplicates} duplicate message(s) (received twice, "
                     "same sender and sequence number)")
    if scan.truncated:
        notes.append("the last message is cut short (the recording was interrupted)")
    if sessions > 1:
        why = []
        if collected.restarts:
            why.append(f"{collected.restarts} consumed-charge counter restart(s)")
        notes.append(f"{sessions} recording sessions joined in this file (time going back, "
                     f"pauses over {SESSION_GAP_S:g} s"
                     + (", " + ", ".join(why) if why else "") + f"), {layout}; flights and "
                     "charge never span two sessions")
    if not any(collected.heartbeats.values()):
        notes.append("no vehicle HEARTBEAT: flights found from the current")
    return notes


__all__ = ["read_tlog", "is_tlog", "SESSION_GAP_S", "SESSION_SPACER_S"]
