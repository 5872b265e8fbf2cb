"""A virtual dischargelab logger on a pseudo-terminal, driven by the battery model.

It speaks the firmware's exact bytes (:mod:`dischargelab.acquire.protocol`) and
answers the host commands like the sketch, so the host side runs unchanged over
real pyserial. What it measures is a simulated discharge:

* pack voltage from :meth:`dischargelab.model.Battery.voltage` at the load
  current, with the discharged charge integrated by
  :func:`dischargelab.model.charge_from_current`;
* the front end: divider + follower gain ``1/Ke`` (paper 3.1, eq. 7), Gaussian
  noise at the ADC pin, 10-bit truncating ADC with a 5 V reference, clipping;
* optional current sensor (ACS712 model) and NTC thermistor with a lumped
  thermal model (temperature rise ``I^2 R_pack R_th`` with time constant ``tau``);
* faults: dropped bytes, bit-flipped frames, a disconnect (the pty closes and
  comes back later as a freshly reset board, or the board stops answering for
  a while);
* link pacing: at ``baudrate`` the bytes leave no faster than a real UART
  (10 bits per byte); samples that do not fit in the board's buffers are
  dropped like the firmware drops them (the sample counter still advances);
* time compression: ``speed`` battery seconds per wall second.

The load: without ``relay`` the load is wired straight to the pack and starts
when the host first sends START (as if the operator closed the load switch when
starting the logger). With ``relay`` it follows SET_LOAD (off at power-up).

The port is a symlink (``port``) to the current pty slave, so it survives a
simulated unplug/replug. ``record`` writes every frame the device produced, with
what happened to it, for checking the host against the truth.
"""

from __future__ import annotations

import csv
import math
import os
import select
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..model import Battery, charge_from_current, load_battery
from . import protocol as proto
from .pseudo_terminal import close_fds, open_raw_pty
from .sensors import (
    ADC_REFERENCE_V,
    CURRENT_CHANNEL,
    CURRENT_SENSORS,
    TEMPERATURE_CHANNEL,
    VOLTAGE_CHANNEL,
    CurrentSensor,
    Thermistor,
    volts_to_adc,
)

FIRMWARE_NAME = "dischargelab-logger"
FIRMWARE_VERSION = "1.0.0"

#: Bytes the firmware can hold before it must drop a sample: the 64-byte
#: HardwareSerial transmit buffer plus its 8-entry sample ring.
TX_BUFFER_BYTES = 64
SAMPLE_RING_ENTRIES = 8

RECORD_COLUMNS = ("index", "seq", "wall_time", "device_time_s", "voltage_V", "current_A",
                  "charge_Ah", "temperature_C", "codes", "status")


@dataclass(frozen=True)
class SentFrame:
    """One sample the device produced and what became of it.

    ``status``: "sent", "corrupted" (bits flipped), "bytes-dropped",
    "overflow" (not sent: link too slow), "silent" (disconnected), "unread"
    (the pty buffer was full: nobody reading).
    """

    index: int
    seq: int
    wall_time: float
    device_time_s: float
    voltage_V: float
    current_A: float
    charge_Ah: float
    temperature_C: float
    codes: tuple[int, ...]
    status: str


def _check_link(link: Path) -> None:
    """The port symlink may replace only a stale symlink, never a file or a folder."""
    if link.is_symlink() or not link.exists():
        return
    raise DataError(f"cannot create the port link {link}: a file or folder of that name exists "
                    "(the link would replace it); choose another link path")


class VirtualDevice:
    """A simulated Arduino logger on a pseudo-terminal.

    Parameters
    ----------
    battery : str, path or Battery
        Preset name or battery file (:func:`dischargelab.model.load_battery`).
    cells_series : int, optional
        Override the pack's series cell count.
    current_A : float, optional
        Load current [A], discharge positive; default 1C (the pack capacity in A).
    rate_Hz : float
        Sample rate at power-up [Hz] (the host normally sets it).
    speed : float
        Battery seconds per wall-clock second (time compression).
    divider_gain : float
        Ke of the simulated front end: pin voltage = pack voltage / Ke.
    noise_mV : float
        RMS noise at the ADC pin [mV].
    drop_bytes : float
        Probability that each byte of a SAMPLE frame is lost.
    corrupt : float
        Probability that a SAMPLE frame gets 1-3 bits flipped.
    disconnect_after_s, disconnect_for_s : float
        Wall seconds after the first START until a disconnect, and its length.
    disconnect_mode : {"close", "silent"}
        "close": the pty vanishes and comes back as a freshly reset board;
        "silent": the board stops answering, then carries on.
    baudrate : int, optional
        Pace the output like a UART at this baud rate; None = as fast as the pty goes.
    seed : int
        Seed of the noise and fault generator.
    link : path, optional
        Where to create the port symlink (default: in a new temporary directory).
    record : path, optional
        CSV file of every produced frame (:data:`RECORD_COLUMNS`).
    keep_history : bool
        Also keep the frames in :attr:`history` (memory grows with the run).
    relay : bool
        Model a load relay switched by SET_LOAD (off at power-up).
    current_sensor : str or CurrentSensor
    thermistor : Thermistor
    ambient_C : float
    thermal_resistance_K_per_W, thermal_time_constant_s : float
        Lumped thermal model of the pack.
    """

    def __init__(self, battery="zippy-1100-2s", *, cells_series: int | None = None,
                 current_A: float | None = None, rate_Hz: float = 1.0, speed: float = 1.0,
                 divider_gain: float = 4.38, noise_mV: float = 2.0, drop_bytes: float = 0.0,
                 corrupt: float = 0.0, disconnect_after_s: float | None = None,
                 disconnect_for_s: float = 2.0, disconnect_mode: str = "close",
                 baudrate: int | None = None, seed: int = 0, link=None, record=None,
                 keep_history: bool = False, relay: bool = False,
                 current_sensor: str | CurrentSensor = "acs712-20a",
                 thermistor: Thermistor | None = None, ambient_C: float = 25.0,
                 thermal_resistance_K_per_W: float = 5.0, thermal_time_constant_s: float = 600.0):
        bat = load_battery(battery) if not isinstance(battery, Battery) else battery
        if cells_series is not None:
            bat = bat.with_pack(cells_series=int(cells_series))
        self.battery = bat
        self.current_A = float(bat.capacity_Ah if current_A is None else current_A)
        checks = {"speed": speed > 0, "divider_gain": divider_gain > 0, "noise_mV": noise_mV >= 0,
                  "drop_bytes": 0 <= drop_bytes < 1, "corrupt": 0 <= corrupt <= 1,
                  "current_A": self.current_A >= 0, "rate_Hz": rate_Hz > 0}
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise DataError(f"virtual device: invalid {', '.join(bad)} (speed, gain, rate > 0; "
                            "probabilities in [0, 1); noise and current >= 0)")
        if disconnect_mode not in ("close", "silent"):
            raise DataError(f"disconnect mode must be 'close' or 'silent', got {disconnect_mode!r}")
        self.speed = float(speed)
        self.divider_gain = float(divider_gain)
        self.noise_V = float(noise_mV) / 1000.0
        self.drop_bytes = float(drop_bytes)
        self.corrupt = float(corrupt)
        self.disconnect_after_s = disconnect_after_s
        self.disconnect_for_s = float(disconnect_for_s)
        self.disconnect_mode = disconnect_mode
        self.baudrate = None if not baudrate else int(baudrate)
        self.relay = bool(relay)
        self.current_sensor = (CURRENT_SENSORS[current_sensor] if isinstance(current_sensor, str)
                               else current_sensor)
        self.thermistor = thermistor or Thermistor()
        self.ambient_C = float(ambient_C)
        self.thermal_resistance = float(thermal_resistance_K_per_W)
        self.thermal_tau_s = float(thermal_time_constant_s)
        self.rng = np.random.default_rng(seed)
        self.power_on_period_us = proto.quantize_period_us(round(1e6 / rate_Hz))
        self.keep_history = keep_history
        self.history: list[SentFrame] = []
        self._record_path = None if record is None else Path(record)
        self._record_file = None
        self._record_writer = None
        self._tmpdir = None
        if link is None:
            self._tmpdir = tempfile.mkdtemp(prefix="dischargelab-vdev-")
            link = Path(self._tmpdir) / "ttyDLAB0"
        _check_link(Path(link))
        self.port = str(link)
        # counters
        self.counts = {"produced": 0, "sent": 0, "corrupted": 0, "bytes-dropped": 0,
                       "overflow": 0, "silent": 0, "unread": 0}
        self.commands: list[tuple[str, int | None]] = []
        self.disconnects = 0
        # events for tests
        self.started = threading.Event()         # first START
        self.disconnected = threading.Event()
        self.reconnected = threading.Event()
        self.load_switched_off = threading.Event()
        # battery state
        self.charge_Ah = 0.0
        self.temperature_C = self.ambient_C
        self.battery_time_s = 0.0
        self._discharging = False
        self._relay_on = False
        self._last_wall: float | None = None
        self._first_start_wall: float | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master = self._slave = None
        self._reboot()

    # ------------------------------------------------------------------ public
    def start(self) -> str:
        """Open the pty and start answering; returns the port path."""
        if self._record_path is not None:
            self._record_file = open(self._record_path, "w", newline="", encoding="utf-8")
            self._record_writer = csv.writer(self._record_file)
            self._record_writer.writerow(RECORD_COLUMNS)
        self._open_pty()
        self._thread = threading.Thread(target=self._run, name="dischargelab-vdev", daemon=True)
        self._thread.start()
        return self.port

    def stop(self) -> None:
        """Stop the device, close the pty, flush the record."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(10)
        self._close_pty()
        if self._record_file is not None:
            self._record_file.close()
            self._record_file = None
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)

    def __enter__(self) -> VirtualDevice:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def load_on(self) -> bool:
        return self._relay_on if self.relay else self._discharging

    def summary(self) -> dict:
        """What the device did: frames by fate, disconnects, battery time and charge.

        Returns
        -------
        dict
            ``port``, ``battery``, ``cells_series``, ``current_A``, ``speed``,
            ``frames`` (produced, sent, corrupted, bytes-dropped, overflow, silent,
            unread), ``disconnects``, ``battery_time_s``, ``charge_Ah``,
            ``commands`` (number received).
        """
        return {"port": self.port, "battery": self.battery.name,
                "cells_series": self.battery.cells_series, "current_A": self.current_A,
                "speed": self.speed, "frames": dict(self.counts),
                "disconnects": self.disconnects, "battery_time_s": self.battery_time_s,
                "charge_Ah": self.charge_Ah, "commands": len(self.commands)}

    def truth(self) -> dict:
        """The model that drives the device (for comparing a fit with the truth)."""
        return {"battery": self.battery.to_dict(), "current_A": self.current_A,
                "divider_gain": self.divider_gain, "noise_mV": self.noise_V * 1000,
                "speed": self.speed}

    # ------------------------------------------------------------------ pty
    def _open_pty(self) -> None:
        self._master, self._slave, target = open_raw_pty()
        tmp = f"{self.port}.{os.getpid()}.tmp"
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        os.symlink(target, tmp)
        os.replace(tmp, self.port)
        self._parser = proto.FrameParser()
        self._line_free_at = 0.0

    def _close_pty(self) -> None:
        try:
            os.unlink(self.port)
        except OSError:
            pass
        close_fds(self._master, self._slave)
        self._master = self._slave = None

    # ------------------------------------------------------------------ firmware state
    def _reboot(self) -> None:
        """Power-on state of the firmware (also after a simulated unplug)."""
        self.streaming = False
        self.mask = 1 << VOLTAGE_CHANNEL
        self.period_us = self.power_on_period_us
        self._relay_on = False
        self._k = 0
        self._start_wall = 0.0

    # ------------------------------------------------------------------ battery
    def _advance(self, wall: float) -> None:
        """Move the battery state to wall time ``wall``."""
        if self._last_wall is None:
            self._last_wall = wall
            return
        dt = (wall - self._last_wall) * self.speed
        if dt <= 0:
            return
        i = self.current_A if self.load_on else 0.0
        t0 = self.battery_time_s
        t_charge = self.charge_Ah
        self.charge_Ah = float(charge_from_current(np.array([t0, t0 + dt]), np.array([i, i]),
                                                   self.charge_Ah)[-1])
        # current x overpotential of the model (any family), at the charge before the step
        drop = float(self.battery.voltage(0.0, t_charge) - self.battery.voltage(i, t_charge))
        heat_W = i * drop if math.isfinite(drop) else 0.0
        target = self.ambient_C + heat_W * self.thermal_resistance
        self.temperature_C = target + (self.temperature_C - target) * math.exp(
            -dt / self.thermal_tau_s)
        self.battery_time_s = t0 + dt
        self._last_wall = wall

    def pack_voltage_V(self) -> float:
        """Present true pack voltage [V] (0 once the model has collapsed)."""
        i = self.current_A if self.load_on else 0.0
        v = float(self.battery.voltage(i, self.charge_Ah))
        return v if math.isfinite(v) and v > 0 else 0.0

    def _codes(self, mask: int) -> tuple[tuple[int, ...], float, float]:
        v = self.pack_voltage_V()
        i = self.current_A if self.load_on else 0.0
        pins = []
        for ch in proto.channels_of_mask(mask):
            if ch == VOLTAGE_CHANNEL:
                pin = v / self.divider_gain
            elif ch == CURRENT_CHANNEL:
                pin = float(self.current_sensor.pin_voltage(i))
            elif ch == TEMPERATURE_CHANNEL:
                pin = float(self.thermistor.pin_voltage(self.temperature_C))
            else:
                pin = ADC_REFERENCE_V / 2
            pins.append(pin)
        pins = np.asarray(pins) + self.rng.normal(0.0, self.noise_V, len(pins)) \
            if self.noise_V > 0 else np.asarray(pins)
        return tuple(int(c) for c in volts_to_adc(pins)), v, i

    # ------------------------------------------------------------------ main loop
    def _run(self) -> None:
        disconnect_at = None
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if (disconnect_at is None and self.disconnect_after_s is not None
                        and self.started.is_set() and not self.disconnected.is_set()):
                    disconnect_at = self._first_start_wall + self.disconnect_after_s
                if disconnect_at is not None and now >= disconnect_at \
                        and not self.disconnected.is_set():
                    self._disconnect()
                    continue
                timeout = 0.05
                if self.streaming:
                    due = self._start_wall + self._k * self.period_us / 1e6 / self.speed
                    timeout = min(timeout, max(0.0, due - now))
                try:
                    readable, _, _ = select.select([self._master], [], [], timeout)
                except (OSError, ValueError):
                    readable = []
                if readable:
                    self._receive()
                self._produce(time.monotonic())
        finally:
            self._stop.set()

    def _receive(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        for frame in self._parser.feed(data):
            if isinstance(frame, proto.CommandFrame):
                self._command(frame)

    def _command(self, frame: proto.CommandFrame) -> None:
        now = time.monotonic()
        kind = proto.MessageType(frame.command)
        arg = int.from_bytes(frame.payload, "little") if frame.payload else None
        self.commands.append((kind.name, arg))
        status, value = proto.AckStatus.OK, 0
        if kind == proto.MessageType.IDENTIFY:
            self._write(proto.encode_info(self.identity()), now)
            return
        if kind == proto.MessageType.SET_PERIOD:
            try:
                self.period_us = value = proto.quantize_period_us(arg)
            except ValueError:
                status, value = proto.AckStatus.BAD_ARGUMENT, self.period_us
        elif kind == proto.MessageType.SET_CHANNELS:
            if 0 < arg < (1 << proto.MAX_CHANNELS):
                self.mask = value = arg
            else:
                status, value = proto.AckStatus.BAD_ARGUMENT, self.mask
        elif kind == proto.MessageType.START:
            self._advance(now)
            if not self.started.is_set():
                self._first_start_wall = now
                self._discharging = True
                self.started.set()
            self.streaming = True
            self._k = 0
            self._start_wall = now
        elif kind == proto.MessageType.STOP:
            self.streaming = False
        elif kind == proto.MessageType.SET_LOAD:
            self._advance(now)
            self._relay_on = bool(arg)
            value = int(self._relay_on)
            if not arg:
                self.load_switched_off.set()
        self._write(proto.encode_ack(kind, status, value), now)

    def identity(self) -> dict:
        """The INFO fields (the firmware sends the same keys; ``time_scale`` only here)."""
        return {"fw": FIRMWARE_NAME, "fw_version": FIRMWARE_VERSION,
                "proto": proto.PROTOCOL_VERSION, "board": "virtual", "adc_bits": 10,
                "vref_mV": int(ADC_REFERENCE_V * 1000), "channels": proto.MAX_CHANNELS,
                "period_us": self.period_us, "mask": self.mask, "streaming": int(self.streaming),
                "load": int(self._relay_on), "time_scale": f"{self.speed:g}"}

    def _produce(self, now: float) -> None:
        while self.streaming:
            due = self._start_wall + self._k * self.period_us / 1e6 / self.speed
            if due > now:
                return
            self._advance(due)
            codes, v, i = self._codes(self.mask)
            seq = self._k & 0xFFFF
            data = proto.encode_sample(seq, self.mask, codes)
            status = "sent"
            if self.corrupt and self.rng.random() < self.corrupt:
                data = self._flip_bits(data)
                status = "corrupted"
            if self.drop_bytes:
                keep = self.rng.random(len(data)) >= self.drop_bytes
                if not keep.all():
                    data = bytes(b for b, k in zip(data, keep) if k)
                    status = "bytes-dropped"
            if self.baudrate and not self._fits(len(data), due):
                status = "overflow"
            elif not self._write(data, due):
                status = "unread"
            self._log(SentFrame(self._k, seq, due, self.battery_time_s, v, i, self.charge_Ah,
                                self.temperature_C, codes, status))
            self._k += 1

    def _flip_bits(self, data: bytes) -> bytes:
        buf = bytearray(data)
        n_bits = int(self.rng.integers(1, 4))
        for pos in self.rng.choice(len(buf) * 8, size=n_bits, replace=False):
            buf[pos // 8] ^= 1 << (pos % 8)
        return bytes(buf)

    def _fits(self, n_bytes: int, when: float) -> bool:
        """Can the firmware queue ``n_bytes`` at ``when`` without dropping (UART pacing)?"""
        byte_s = proto.BITS_PER_BYTE_ON_WIRE / self.baudrate
        backlog = max(0.0, self._line_free_at - when) / byte_s
        capacity = TX_BUFFER_BYTES + SAMPLE_RING_ENTRIES * n_bytes
        return backlog + n_bytes <= capacity

    def _write(self, data: bytes, when: float) -> bool:
        if self.baudrate:
            byte_s = proto.BITS_PER_BYTE_ON_WIRE / self.baudrate
            self._line_free_at = max(self._line_free_at, when) + len(data) * byte_s
        try:
            written = os.write(self._master, data)
        except (BlockingIOError, OSError):
            return False
        return written == len(data)

    def _log(self, frame: SentFrame) -> None:
        self.counts["produced"] += 1
        self.counts[frame.status] += 1
        if self.keep_history:
            self.history.append(frame)
        if self._record_writer is not None:
            self._record_writer.writerow((
                frame.index, frame.seq, f"{frame.wall_time:.6f}", f"{frame.device_time_s:.6f}",
                f"{frame.voltage_V:.6f}", f"{frame.current_A:.6f}", f"{frame.charge_Ah:.9f}",
                f"{frame.temperature_C:.4f}", ";".join(map(str, frame.codes)), frame.status))
            if frame.index % 64 == 0:
                self._record_file.flush()

    def _disconnect(self) -> None:
        self.disconnects += 1
        self.disconnected.set()
        end = time.monotonic() + self.disconnect_for_s
        if self.disconnect_mode == "close":
            self._close_pty()
            while not self._stop.is_set() and time.monotonic() < end:
                self._stop.wait(0.05)
            self._advance(time.monotonic())
            self._reboot()
            if not self._stop.is_set():
                self._open_pty()
        else:
            while not self._stop.is_set() and time.monotonic() < end:
                now = time.monotonic()
                try:                              # swallow what the host sends
                    if select.select([self._master], [], [], 0.05)[0]:
                        os.read(self._master, 4096)
                except OSError:
                    pass
                while self.streaming:             # samples taken but never sent
                    due = self._start_wall + self._k * self.period_us / 1e6 / self.speed
                    if due > now:
                        break
                    self._advance(due)
                    codes, v, i = self._codes(self.mask)
                    self._log(SentFrame(self._k, self._k & 0xFFFF, due, self.battery_time_s, v, i,
                                        self.charge_Ah, self.temperature_C, codes, "silent"))
                    self._k += 1
            self._parser = proto.FrameParser()
        self.reconnected.set()


def read_record(path) -> pandas.DataFrame:  # noqa: F821 - pandas imported lazily
    """Read a device record CSV (:data:`RECORD_COLUMNS`)."""
    import pandas as pd

    return pd.read_csv(path)
