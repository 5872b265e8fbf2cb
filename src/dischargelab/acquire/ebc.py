"""ZKETECH EBC-A series battery tester (electronic load + charger) over USB-serial.

Protocol as described by public reverse-engineering notes (cited in
``docs/electronic-loads.md``; no vendor document exists). Facts all sources
agree on:

* Every frame is ``0xFA | payload | checksum | 0xF8``; the checksum is the XOR
  of the payload bytes. Host -> device frames are 10 bytes (7-byte payload),
  device -> host frames are 19 bytes (16-byte payload).
* Numbers are sent in two bytes in base 240 (``value = hi*240 + lo``), so no
  payload byte reaches 0xF0 and the markers 0xF8/0xFA never occur inside a
  payload (the checksum byte can, which is why frames are split by length).
* Host commands: first payload byte is the command, then three base-240
  parameters. CC discharge ``0x01``: current in 10 mA, cutoff voltage in 10 mV,
  time limit in minutes (0 = none). Stop ``0x02``, connect ``0x05``, disconnect
  ``0x06``, adjust a running CC discharge ``0x07``.
* The device streams status frames on its own once connected. Byte 1 is
  ``state*10 + mode`` (mode 0 = CC discharge, 1 = CP discharge, 2.. = charge;
  state 0 = idle, 1 = running, 2 = finished by its own cutoff); then measured
  current, voltage [mV] and capacity [mAh], an unused field, the three set
  values echoed in command units, and a model code. Right after connecting,
  some frames carry the firmware version instead of the set values (states
  10 and 11).
* The device sends no explicit acknowledgement: a command is confirmed by the
  next status frames changing state.

Where sources disagree the driver is configurable and says so:

* Parity: 9600 baud, 8 data bits, 1 stop bit; even parity in two sources
  (default here), odd in one (``parity="O"``).
* Unit of the measured current: 1 mA in one source, 10 mA in another. By
  default the driver compares the reported current with the set current echoed
  in the same frame and picks the unit that matches (``current_unit_A=None``).
* A checksum that would be >= 0xF0 is sent reduced modulo 240 by one public
  implementation; frames with that variant are accepted too.

References
----------
.. [1] Kazhuu, "ebc-battery-tester", FRAMES.md (EBC-A20 frame reference).
.. [2] pop.fsck.pl, "ZKETECH EBC-A20 Battery Tester" (control interface).
.. [3] sigrok wiki, "ZKETECH EBD-USB" (same framing on the EBD-USB load).
.. [4] JOGAsoft, "EBC-controller" (ebcc.conf command table, models).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from enum import IntEnum
from functools import reduce

from ..errors import DataError, DischargelabError

SOF = 0xFA
EOF = 0xF8
HOST_FRAME_BYTES = 10
DEVICE_FRAME_BYTES = 19
BASE = 240
MAX_FIELD = BASE * BASE - 1

BAUDRATE = 9600
DEFAULT_PARITY = "E"

#: Resolution of set currents [A] and voltages [V] in commands.
SET_CURRENT_STEP_A = 0.01
SET_VOLTAGE_STEP_V = 0.01

#: Candidate units of the measured current field [A per count].
CURRENT_UNITS_A = (0.001, 0.01)

#: Model codes (last payload byte of every status frame). 0x05, 0x06 and 0x09
#: agree across sources; 0x0A for the A40L is from one source only.
MODELS = {0x05: "EBC-A05", 0x06: "EBC-A10H", 0x09: "EBC-A20", 0x0A: "EBC-A40L"}

#: Largest discharge current of each model [A] (vendor ratings quoted in [2], [4]).
MAX_DISCHARGE_A = {"EBC-A05": 5.0, "EBC-A10H": 10.0, "EBC-A20": 20.0, "EBC-A40L": 40.0}


class Command(IntEnum):
    """First payload byte of host -> device frames."""

    CC_DISCHARGE = 0x01
    STOP = 0x02
    CONNECT = 0x05
    DISCONNECT = 0x06
    CC_ADJUST = 0x07
    CC_RESUME = 0x08
    KEEPALIVE = 0x0A      # sent once a minute by the vendor software ("timer sync")
    CP_DISCHARGE = 0x11


MODE_NAMES = {0: "cc-discharge", 1: "cp-discharge"}
STATE_NAMES = {0: "idle", 1: "active", 2: "finished", 10: "idle", 11: "active"}


class EbcFrameError(DataError):
    """A frame from or for the EBC is malformed (length, markers, checksum, range)."""


class LoadControlError(DischargelabError):
    """The load did not confirm a command (start or stop) in time."""


# --------------------------------------------------------------------------- pure encoding

def encode_field(value: int) -> tuple[int, int]:
    """Split an integer 0..57599 into base-240 (high, low) bytes."""
    value = int(value)
    if not 0 <= value <= MAX_FIELD:
        raise EbcFrameError(f"value {value} does not fit a base-240 field (0..{MAX_FIELD})")
    return divmod(value, BASE)


def decode_field(high: int, low: int) -> int:
    """Inverse of :func:`encode_field`; bytes above 239 are invalid."""
    if not (0 <= high < BASE and 0 <= low < BASE):
        raise EbcFrameError(f"bytes {high:#04x} {low:#04x} are not a base-240 field")
    return high * BASE + low


def xor_checksum(payload: bytes) -> int:
    """XOR of all payload bytes (markers and checksum excluded)."""
    return reduce(lambda acc, b: acc ^ b, payload, 0)


def checksum_matches(payload: bytes, received: int) -> bool:
    """True for the plain XOR, or for the modulo-240 variant when the XOR is >= 0xF0."""
    expected = xor_checksum(payload)
    return received == expected or (expected >= BASE and received == expected % BASE)


def build_frame(payload: bytes) -> bytes:
    """``SOF | payload | XOR | EOF``."""
    payload = bytes(payload)
    return bytes([SOF]) + payload + bytes([xor_checksum(payload), EOF])


def split_frame(frame: bytes, length: int) -> bytes:
    """Check markers, length, byte range and checksum; return the payload."""
    frame = bytes(frame)
    if len(frame) != length:
        raise EbcFrameError(f"frame has {len(frame)} bytes, expected {length}")
    if frame[0] != SOF or frame[-1] != EOF:
        raise EbcFrameError("frame does not start with 0xFA and end with 0xF8")
    payload = frame[1:-2]
    if max(payload) >= BASE:
        raise EbcFrameError("payload byte above 0xEF")
    if not checksum_matches(payload, frame[-2]):
        raise EbcFrameError(f"checksum {frame[-2]:#04x} != XOR {xor_checksum(payload):#04x}")
    return payload


def encode_command(code: int, a: int = 0, b: int = 0, c: int = 0) -> bytes:
    """10-byte host frame: command byte and three base-240 parameters."""
    if not 0 <= int(code) < BASE:
        raise EbcFrameError(f"command byte {code:#04x} out of range")
    payload = bytes([int(code), *encode_field(a), *encode_field(b), *encode_field(c)])
    return build_frame(payload)


def decode_command(frame: bytes) -> tuple[int, int, int, int]:
    """Inverse of :func:`encode_command`: ``(code, a, b, c)``."""
    p = split_frame(frame, HOST_FRAME_BYTES)
    return p[0], decode_field(p[1], p[2]), decode_field(p[3], p[4]), decode_field(p[5], p[6])


def _to_steps(value: float, step: float, what: str, low: float, high: float) -> int:
    if not (low <= value <= high):
        raise DataError(f"{what} must be between {low:g} and {high:g}, got {value:g}")
    return int(round(value / step))


def cc_discharge_frame(current_A: float, cutoff_V: float, time_limit_min: int = 0,
                       command: int = Command.CC_DISCHARGE) -> bytes:
    """Start (``0x01``) or adjust (``0x07``) a constant-current discharge.

    Parameters
    ----------
    current_A : float
        Discharge current [A], 0.01..40 (sent in 10 mA steps).
    cutoff_V : float
        The load's own cutoff voltage [V], 0.01..300 (sent in 10 mV steps).
    time_limit_min : int
        Time limit [min], 0 = none.
    """
    current = _to_steps(current_A, SET_CURRENT_STEP_A, "discharge current [A]", 0.01, 40.0)
    cutoff = _to_steps(cutoff_V, SET_VOLTAGE_STEP_V, "cutoff voltage [V]", 0.01, 300.0)
    if not 0 <= int(time_limit_min) <= 9999:
        raise DataError(f"time limit must be 0..9999 min, got {time_limit_min}")
    return encode_command(command, current, cutoff, int(time_limit_min))


def stop_frame() -> bytes:
    """Stop whatever runs (discharge or charge)."""
    return encode_command(Command.STOP)


def connect_frame() -> bytes:
    """Put the device under PC control; it starts streaming status frames."""
    return encode_command(Command.CONNECT)


def disconnect_frame() -> bytes:
    """Release PC control."""
    return encode_command(Command.DISCONNECT)


def keepalive_frame(minute: int) -> bytes:
    """The once-a-minute frame the vendor software sends while running (minute counter)."""
    return encode_command(Command.KEEPALIVE, int(minute))


@dataclass(frozen=True)
class Status:
    """One device -> host status frame, fields raw as sent.

    Attributes
    ----------
    code : int
        ``state*10 + mode`` (see :data:`MODE_NAMES`, :data:`STATE_NAMES`).
    current_raw : int
        Measured current in device counts (unit 1 or 10 mA, see module notes).
    voltage_mV : int
        Measured voltage [mV].
    capacity_mAh : int
        Charge moved since the start [mAh].
    unknown : int
        Bytes 7-8; always 0 in the frames described so far.
    setting1, setting2, setting3 : int
        Set values echoed in command units (CC discharge: current [10 mA],
        cutoff [10 mV], time limit [min]); in firmware reports ``setting1`` is
        the firmware version (302 = "3.0.2").
    model_code : int
        Model (see :data:`MODELS`).
    """

    code: int
    current_raw: int
    voltage_mV: int
    capacity_mAh: int
    unknown: int = 0
    setting1: int = 0
    setting2: int = 0
    setting3: int = 0
    model_code: int = 0x09

    @property
    def mode(self) -> int:
        return self.code % 10

    @property
    def state_code(self) -> int:
        return self.code // 10

    @property
    def mode_name(self) -> str:
        return MODE_NAMES.get(self.mode, "charge" if 2 <= self.mode <= 7 else f"mode {self.mode}")

    @property
    def state(self) -> str:
        return STATE_NAMES.get(self.state_code, f"state {self.state_code}")

    @property
    def is_firmware_report(self) -> bool:
        return self.state_code >= 10

    @property
    def is_active(self) -> bool:
        return self.state == "active"

    @property
    def is_finished(self) -> bool:
        return self.state == "finished"

    @property
    def model(self) -> str:
        return MODELS.get(self.model_code, f"unknown model {self.model_code:#04x}")

    @property
    def voltage_V(self) -> float:
        return self.voltage_mV / 1000.0

    @property
    def set_current_A(self) -> float | None:
        """Set discharge current [A] (CC discharge frames only)."""
        if self.mode != 0 or self.is_firmware_report:
            return None
        return self.setting1 * SET_CURRENT_STEP_A

    @property
    def cutoff_V(self) -> float | None:
        """Set cutoff voltage [V] (discharge frames only)."""
        if self.mode not in (0, 1) or self.is_firmware_report:
            return None
        return self.setting2 * SET_VOLTAGE_STEP_V

    @property
    def firmware_version(self) -> str | None:
        if not self.is_firmware_report:
            return None
        v = self.setting1
        return f"{v // 100}.{v // 10 % 10}.{v % 10}"


def encode_status(status: Status) -> bytes:
    """19-byte device frame for ``status`` (used by the virtual load)."""
    payload = bytes([status.code, *encode_field(status.current_raw),
                     *encode_field(status.voltage_mV), *encode_field(status.capacity_mAh),
                     *encode_field(status.unknown), *encode_field(status.setting1),
                     *encode_field(status.setting2), *encode_field(status.setting3),
                     status.model_code])
    return build_frame(payload)


def decode_status(frame: bytes) -> Status:
    """Parse a 19-byte status frame; raises :class:`EbcFrameError` if it is corrupt."""
    p = split_frame(frame, DEVICE_FRAME_BYTES)
    f = [decode_field(p[i], p[i + 1]) for i in range(1, 15, 2)]
    return Status(p[0], *f, model_code=p[15])


class FrameSplitter:
    """Cut a byte stream into fixed-length frames, resynchronising on garbage.

    A candidate starts at 0xFA and must end with 0xF8 ``length`` bytes later and
    have no payload byte >= 0xF0; otherwise the 0xFA is dropped and the search
    goes on. Checksums are checked by the decoder, not here.
    """

    def __init__(self, length: int = DEVICE_FRAME_BYTES):
        self.length = length
        self._buffer = bytearray()
        self.skipped_bytes = 0
        self.resyncs = 0

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer.extend(data)
        frames = []
        buf = self._buffer
        while True:
            start = buf.find(SOF)
            if start < 0:
                self.skipped_bytes += len(buf)
                buf.clear()
                break
            if start:
                self.skipped_bytes += start
                del buf[:start]
            if len(buf) < self.length:
                break
            candidate = bytes(buf[:self.length])
            if candidate[-1] == EOF and max(candidate[1:-2]) < BASE:
                frames.append(candidate)
                del buf[:self.length]
            else:
                self.resyncs += 1
                self.skipped_bytes += 1
                del buf[:1]
        return frames


def choose_current_unit(status: Status, set_current_A: float | None = None,
                        tolerance: float = 0.3) -> float | None:
    """Pick the unit of the measured current [A/count] from a running CC frame.

    Compares ``current_raw * unit`` with the set current (from the frame, or
    given) and returns the unit within ``tolerance`` (relative), or None when
    the frame cannot tell (idle, zero current, no set value).
    """
    target = set_current_A if set_current_A is not None else status.set_current_A
    if not status.is_active or not target or status.current_raw <= 0:
        return None
    errors = {u: abs(status.current_raw * u - target) / target for u in CURRENT_UNITS_A}
    unit = min(errors, key=errors.get)
    return unit if errors[unit] <= tolerance else None


# --------------------------------------------------------------------------- the source

def _open_serial_port(port: str, *, baudrate: int, parity: str, timeout_s: float):
    """Open the USB-serial port through the transport module (the only pyserial user)."""
    from .transport import open_serial

    return open_serial(port, baudrate=baudrate, parity=parity, timeout_s=timeout_s)


class EbcSource:
    """A ZKETECH EBC-A load running a constant-current discharge, as a SampleSource.

    Connects, starts a CC discharge at ``current_A`` with the load's own cutoff
    ``cutoff_V`` and turns every status frame into a :class:`Sample`. The host
    also watches ``safety_cutoff_V`` (default: the load cutoff) and stops the
    load itself when the voltage reaches it, so a wrong setting in the load
    cannot over-discharge the pack. :meth:`stop_load` sends Stop and waits for a
    status frame that shows the load no longer running (resending up to
    ``stop_attempts`` times), otherwise it raises :class:`LoadControlError`.

    Parameters
    ----------
    port : str
        Serial device (``/dev/ttyUSB0``, ``COM5``, a pty path).
    current_A : float
        Discharge current [A].
    cutoff_V : float
        Cutoff voltage the load enforces itself [V] (pack voltage).
    time_limit_min : int
        The load's time limit [min], 0 = none.
    safety_cutoff_V : float, optional
        Voltage [V] at which the host stops the load; default ``cutoff_V``.
    calibration : Calibration, optional
        Applied to the load's voltage reading (e.g. checked against a multimeter).
    current_unit_A : float, optional
        Unit of the measured current field [A]; None = detect from the set current.
    parity : {"E", "O", "N"}
        Serial parity (sources disagree; even by default).
    start : bool
        Start the discharge on open (False: monitor only).
    serial_port : object, optional
        An already open port object (``read``, ``write``, ``close``,
        ``reset_input_buffer``); bypasses opening ``port``.
    """

    name = "ebc"
    #: The electronic load is the load: the host starts and stops it.
    controls_load = True

    def __init__(self, port: str, *, current_A: float, cutoff_V: float, time_limit_min: int = 0,
                 safety_cutoff_V: float | None = None, calibration=None,
                 current_unit_A: float | None = None, parity: str = DEFAULT_PARITY,
                 baudrate: int = BAUDRATE, start: bool = True, connect_timeout_s: float = 5.0,
                 command_timeout_s: float = 3.0, stop_attempts: int = 3,
                 keepalive_interval_s: float | None = 60.0, serial_port=None,
                 clock=time.monotonic):
        if current_unit_A is not None and current_unit_A not in CURRENT_UNITS_A:
            raise DataError(f"current_unit_A must be one of {CURRENT_UNITS_A}, got "
                            f"{current_unit_A}")
        if parity not in ("E", "O", "N"):
            raise DataError(f"parity must be E, O or N, got {parity!r}")
        # validate the numbers before touching the port
        cc_discharge_frame(current_A, cutoff_V, time_limit_min)
        if calibration is not None and not 0.8 <= calibration.gain <= 1.25:
            raise DataError(f"calibration gain {calibration.gain:g} is a divider's Ke; the EBC "
                            "load reports volts, so its correction must be close to 1 "
                            "(calibrate the load against a multimeter, or drop --calibration/--ke)")
        self.port = port
        self.current_A = float(current_A)
        self.cutoff_V = float(cutoff_V)
        self.time_limit_min = int(time_limit_min)
        self.safety_cutoff_V = float(cutoff_V if safety_cutoff_V is None else safety_cutoff_V)
        self.calibration = calibration
        self.current_unit_A = current_unit_A
        self.parity = parity
        self.baudrate = int(baudrate)
        self.connect_timeout_s = float(connect_timeout_s)
        self.command_timeout_s = float(command_timeout_s)
        self.stop_attempts = int(stop_attempts)
        self.keepalive_interval_s = keepalive_interval_s
        self._clock = clock
        self._serial = serial_port
        self._owns_port = serial_port is None
        self._splitter = FrameSplitter()
        self._t0: float | None = None
        self._last_keepalive = 0.0
        self._keepalive_minute = 0
        self._unit_votes: list[float] = []
        self.last_status: Status | None = None
        self.capacity_mAh: int | None = None      # the load's own count since the start
        self._frame_interval_s: float | None = None
        self._last_frame_time: float | None = None
        self.running = False
        self.ended_by: str | None = None
        self.commands_sent: list[bytes] = []
        self.stats = {"frames_ok": 0, "frames_corrupt": 0, "frames_lost": 0, "reconnects": 0,
                      "bytes_skipped": 0, "stop_commands": 0}
        self.info = {"source": "ebc", "port": port, "baudrate": self.baudrate, "parity": parity,
                     "set_current_A": self.current_A, "load_cutoff_V": self.cutoff_V,
                     "safety_cutoff_V": self.safety_cutoff_V,
                     "time_limit_min": self.time_limit_min,
                     "current_unit_A": current_unit_A, "protocol": "ZKETECH EBC-A (public notes)"}
        if calibration is not None:
            self.info["calibration"] = {"gain": calibration.gain,
                                        "offset_V": calibration.offset_V}
        self._open()
        try:
            self._connect()
            if start:
                self.start_discharge()
        except BaseException:
            self._close_port()
            raise

    # -- link ---------------------------------------------------------------------
    def _open(self):
        if self._serial is None:
            self._serial = _open_serial_port(self.port, baudrate=self.baudrate,
                                             parity=self.parity, timeout_s=0.05)
            self._owns_port = True

    def _close_port(self):
        if self._serial is not None and self._owns_port:
            try:
                self._serial.close()
            except OSError:
                pass
        self._serial = None if self._owns_port else self._serial

    def _send(self, frame: bytes) -> None:
        from .pipeline import SourceDisconnected

        try:
            self._serial.write(frame)
            flush = getattr(self._serial, "flush", None)
            if flush:
                flush()
        except (OSError, ValueError, TypeError, AttributeError) as exc:
            # pyserial raises TypeError/AttributeError when the port vanished under it
            raise SourceDisconnected(f"{self.port}: write failed ({exc})") from exc
        self.commands_sent.append(frame)

    def _read_statuses(self, timeout_s: float) -> list[Status]:
        """Read for up to ``timeout_s`` (returning early once frames arrived)."""
        from .pipeline import SourceDisconnected

        deadline = self._clock() + max(timeout_s, 0.0)
        statuses: list[Status] = []
        while True:
            try:
                waiting = getattr(self._serial, "in_waiting", 0) or 1
                data = self._serial.read(max(waiting, 1))
            except (OSError, ValueError, TypeError, AttributeError) as exc:
                raise SourceDisconnected(f"{self.port}: read failed ({exc})") from exc
            skipped = self._splitter.skipped_bytes
            for frame in self._splitter.feed(data):
                try:
                    statuses.append(decode_status(frame))
                    self.stats["frames_ok"] += 1
                except EbcFrameError:
                    self.stats["frames_corrupt"] += 1
            self.stats["bytes_skipped"] += self._splitter.skipped_bytes - skipped
            if statuses or self._clock() >= deadline:
                return statuses

    def _connect(self) -> None:
        deadline = self._clock() + self.connect_timeout_s
        while self._clock() < deadline:
            self._send(connect_frame())
            statuses = self._read_statuses(min(1.0, max(deadline - self._clock(), 0.0)))
            if statuses:
                self._note(statuses)
                return
        raise LoadControlError(f"{self.port}: no status frames from the EBC load within "
                               f"{self.connect_timeout_s:g} s; check the cable, the port and "
                               f"the serial parity (now {self.parity}; public notes disagree "
                               "between even and odd)")

    def _note(self, statuses: list[Status]) -> None:
        status = statuses[-1]
        self.last_status = status
        self.info["model"] = status.model
        fw = next((s.firmware_version for s in statuses if s.is_firmware_report), None)
        if fw:
            self.info["firmware"] = fw
        limit = MAX_DISCHARGE_A.get(status.model)
        if limit is not None and self.current_A > limit:
            raise DataError(f"{status.model} discharges at most {limit:g} A; "
                            f"{self.current_A:g} A requested")

    def _wait_for(self, predicate, timeout_s: float) -> list[Status] | None:
        """Read until a status satisfies ``predicate``; returns all statuses read, or None."""
        deadline = self._clock() + timeout_s
        seen: list[Status] = []
        while self._clock() < deadline:
            statuses = self._read_statuses(min(0.5, max(deadline - self._clock(), 0.0)))
            seen.extend(statuses)
            if statuses:
                self.last_status = statuses[-1]
            if any(predicate(s) for s in statuses):
                return seen
        return None

    # -- control --------------------------------------------------------------------
    def start_discharge(self) -> None:
        """Send the CC discharge command and wait until the load reports it running."""
        frame = cc_discharge_frame(self.current_A, self.cutoff_V, self.time_limit_min)
        want = int(round(self.current_A / SET_CURRENT_STEP_A))
        for _ in range(self.stop_attempts):
            self._send(frame)
            seen = self._wait_for(
                lambda s: s.mode == 0 and s.is_active
                and (s.is_firmware_report or s.setting1 == want),
                self.command_timeout_s)
            if seen:
                self._note(seen)
                self.running = True
                self.ended_by = None
                self._t0 = self._clock()
                self._last_frame_time = self._t0
                self._last_keepalive = self._t0
                self.info["start_time"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
                return
        last = self.last_status
        if last is not None and last.voltage_V <= self.cutoff_V:
            raise LoadControlError(
                f"the load did not start: battery at {last.voltage_V:.3f} V is at or below the "
                f"cutoff {self.cutoff_V:g} V; is the pack connected and charged?")
        raise LoadControlError(f"the EBC load did not start the discharge after "
                               f"{self.stop_attempts} attempts; stop it on its front panel")

    def stop_load(self) -> None:
        """Send Stop and wait until a status frame shows the load no longer running."""
        self.stats["stop_commands"] += 1
        for _ in range(self.stop_attempts):
            self._send(stop_frame())
            seen = self._wait_for(lambda s: not s.is_active, self.command_timeout_s)
            if seen:
                self.last_status = seen[-1]
                self.running = False
                if self.ended_by is None:
                    self.ended_by = "host stop"
                return
        raise LoadControlError(f"the EBC load did not confirm Stop after {self.stop_attempts} "
                               "attempts: switch it off on its front panel NOW")

    # -- SampleSource ---------------------------------------------------------------
    def _current_A(self, status: Status) -> float | None:
        if self.current_unit_A is None:
            unit = choose_current_unit(status, self.current_A if status.mode == 0 else None)
            if unit is not None:
                self._unit_votes.append(unit)
                if self._unit_votes.count(unit) >= 3:
                    self.current_unit_A = unit
                    self.info["current_unit_A"] = unit
        unit = self.current_unit_A or (self._unit_votes[-1] if self._unit_votes else None)
        if unit is None:
            return 0.0 if status.current_raw == 0 else None
        value = status.current_raw * unit
        return value if status.mode in (0, 1) else -value   # charge current is negative

    def _sample(self, status: Status, now: float):
        from .pipeline import Sample

        voltage = status.voltage_V
        if self.calibration is not None:
            voltage = self.calibration.apply(voltage)
        t0 = self._t0 if self._t0 is not None else now
        return Sample(time_s=now - t0, voltage_V=voltage, current_A=self._current_A(status),
                      temperature_C=None, seq=None)

    def _receipt_times(self, count: int, now: float) -> list[float]:
        """Times of ``count`` frames read together.

        The frames carry no time stamp. When the host read late, several frames
        arrive at once although the load sent them at its steady rate; they are
        spread back from ``now`` at the frame interval seen on single-frame reads,
        never before the previous sample.
        """
        if count == 0:
            return []
        interval = self._frame_interval_s
        if count == 1 and self._last_frame_time is not None:
            gap = now - self._last_frame_time
            if 0 < gap < 5.0:
                interval = gap if interval is None else 0.8 * interval + 0.2 * gap
                self._frame_interval_s = interval
        floor = self._last_frame_time if self._last_frame_time is not None else -math.inf
        if interval is None:
            times = [now] * count
        else:
            times = [max(now - (count - 1 - i) * interval, floor) for i in range(count)]
        self._last_frame_time = now
        return times

    def read(self, timeout_s: float) -> list:
        """Samples from the status frames received within ``timeout_s``."""
        statuses = self._read_statuses(timeout_s)
        now = self._clock()
        samples = []
        for status, stamp in zip(statuses, self._receipt_times(len(statuses), now)):
            self.last_status = status
            self.capacity_mAh = status.capacity_mAh
            if self.running and status.is_finished:
                self.running = False
                self.ended_by = "load cutoff"
                self.info["ended_by"] = self.ended_by
            samples.append(self._sample(status, stamp))
        if self.running and samples and samples[-1].voltage_V <= self.safety_cutoff_V:
            self.ended_by = "host cutoff"
            self.info["ended_by"] = self.ended_by
            self.stop_load()
        if (self.running and self.keepalive_interval_s
                and now - self._last_keepalive >= self.keepalive_interval_s):
            self._keepalive_minute += 1
            self._last_keepalive = now
            self._send(keepalive_frame(self._keepalive_minute))
        return samples

    @property
    def finished(self) -> bool:
        """True once the discharge has ended (load cutoff, host cutoff or stop)."""
        return self.ended_by is not None and not self.running

    def reconnect(self) -> None:
        """Reopen the port and resume monitoring (the load keeps running on its own)."""
        self._close_port()
        self._splitter = FrameSplitter()
        self._open()
        self._connect()
        self.stats["reconnects"] += 1

    def close(self) -> None:
        """Stop a running discharge (best effort), release PC control, close the port."""
        if self._serial is None:
            return
        try:
            if self.running:
                self.stop_load()
            self._send(disconnect_frame())
        except DischargelabError:
            pass
        finally:
            self._close_port()
            self._serial = None


def ebc_status_summary(status: Status, current_unit_A: float | None = None) -> dict:
    """Human-readable fields of a status frame (for logs and the CLI)."""
    out = {"model": status.model, "mode": status.mode_name, "state": status.state,
           "voltage_V": status.voltage_V, "capacity_mAh": status.capacity_mAh}
    if current_unit_A:
        out["current_A"] = status.current_raw * current_unit_A
    if status.set_current_A is not None:
        out["set_current_A"] = status.set_current_A
    if status.cutoff_V is not None:
        out["cutoff_V"] = status.cutoff_V
    if status.firmware_version:
        out["firmware"] = status.firmware_version
    return out


__all__ = [
    "SOF", "EOF", "HOST_FRAME_BYTES", "DEVICE_FRAME_BYTES", "BAUDRATE", "DEFAULT_PARITY",
    "MODELS", "MAX_DISCHARGE_A", "CURRENT_UNITS_A", "Command", "Status", "EbcFrameError",
    "LoadControlError", "FrameSplitter", "EbcSource", "encode_field", "decode_field",
    "xor_checksum", "checksum_matches", "build_frame", "split_frame", "encode_command",
    "decode_command", "cc_discharge_frame", "stop_frame", "connect_frame", "disconnect_frame",
    "keepalive_frame", "encode_status", "decode_status", "choose_current_unit",
    "ebc_status_summary",
]
