"""A virtual ZKETECH EBC-A load on a pseudo-terminal, driven by the battery model.

It speaks the same bytes as the real load (:mod:`dischargelab.acquire.ebc`):
it answers Connect by streaming 19-byte status frames, runs a constant-current
discharge on the CC command, stops on Stop, and ends the discharge itself at
its cutoff voltage or time limit. The pack it discharges is a
:class:`dischargelab.model.Battery`: terminal voltage from ``Battery.voltage``,
discharged charge from :func:`dischargelab.model.charge_from_current`.

Because it sits on a real pty, the host side goes through pyserial exactly as
with hardware, so tests exercise the whole path without a load on the bench.
Simulated time can run faster than wall-clock time (``time_scale``) so that a
one-hour discharge takes seconds.

Examples
--------
>>> with VirtualEbcLoad("zippy-1100-2s", time_scale=600) as load:   # doctest: +SKIP
...     src = EbcSource(load.port, current_A=2.0, cutoff_V=6.0)
"""

from __future__ import annotations

import os
import select
import threading
import time

import numpy as np

from ..model import charge_from_current, load_battery
from .ebc import (
    BASE,
    HOST_FRAME_BYTES,
    Command,
    EbcFrameError,
    FrameSplitter,
    Status,
    decode_command,
    encode_status,
    xor_checksum,
)
from .pseudo_terminal import close_fds, open_raw_pty


class VirtualEbcLoad:
    """Simulated EBC-A load behind a pty; use ``.port`` as the serial device.

    Parameters
    ----------
    battery : str or Battery
        Pack being discharged (preset name, battery file or object).
    model_code : int
        Model byte sent in every frame (0x09 = EBC-A20).
    frame_period_s : float
        Wall-clock time between status frames [s].
    time_scale : float
        Simulated seconds per wall-clock second.
    current_unit_A : float
        Unit of the measured-current field [A] (0.01 or 0.001; sources disagree).
    initial_charge_Ah : float
        Charge already taken out of the pack [Ah].
    firmware_frames : int
        Number of firmware-report frames sent right after Connect.
    ignore_stops : int
        Ignore this many Stop commands (to test the host's resend).
    checksum_mod240 : bool
        Send checksums >= 0xF0 reduced modulo 240 (a variant one source uses).
    noise_V : float
        Standard deviation of Gaussian noise on the voltage reading [V].
    seed : int
        Seed of the noise generator.
    """

    def __init__(self, battery="zippy-1100-2s", *, model_code: int = 0x09,
                 frame_period_s: float = 0.02, time_scale: float = 1.0,
                 current_unit_A: float = 0.01, initial_charge_Ah: float = 0.0,
                 firmware_frames: int = 2, firmware_version: int = 302, ignore_stops: int = 0,
                 checksum_mod240: bool = False, noise_V: float = 0.0, seed: int = 0):
        self.battery = load_battery(battery)
        self.model_code = int(model_code)
        self.frame_period_s = float(frame_period_s)
        self.time_scale = float(time_scale)
        self.current_unit_A = float(current_unit_A)
        self.charge_Ah = float(initial_charge_Ah)
        self.firmware_frames = int(firmware_frames)
        self.firmware_version = int(firmware_version)
        self.ignore_stops = int(ignore_stops)
        self.checksum_mod240 = bool(checksum_mod240)
        self.noise_V = float(noise_V)
        self._rng = np.random.default_rng(seed)
        self.sim_time_s = 0.0
        self.connected = False
        self.state = 0              # 0 idle, 1 active, 2 finished
        self.set_current_A = 0.0
        self.cutoff_V = 0.0
        self.time_limit_min = 0
        self.current_A = 0.0
        self.capacity_mAh = 0.0
        self.run_time_s = 0.0
        self.commands: list[tuple[int, int, int, int]] = []
        self.frames_sent = 0
        self.bad_commands = 0
        self._fw_left = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self.port: str | None = None

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> VirtualEbcLoad:
        self._master, self._slave, self.port = open_raw_pty()
        self._thread = threading.Thread(target=self._run, name="virtual-ebc", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        close_fds(self._master, self._slave)
        self._master = self._slave = None

    def __enter__(self) -> VirtualEbcLoad:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ physics
    def voltage_V(self) -> float:
        """Pack terminal voltage [V] at the present current and charge."""
        return float(self.battery.voltage(self.current_A, self.charge_Ah))

    def _advance(self, dt_s: float) -> None:
        if self.state != 1:
            return
        q = charge_from_current([0.0, dt_s], [self.current_A, self.current_A], self.charge_Ah)
        self.capacity_mAh += (q[-1] - self.charge_Ah) * 1000.0
        self.charge_Ah = float(q[-1])
        self.run_time_s += dt_s
        if self.charge_Ah >= self.battery.capacity_Ah:
            self._finish()
            return
        if self.voltage_V() <= self.cutoff_V:
            self._finish()
        elif self.time_limit_min and self.run_time_s >= 60.0 * self.time_limit_min:
            self._finish()

    def _finish(self) -> None:
        self.state = 2
        self.current_A = 0.0

    # ------------------------------------------------------------------ commands
    def wait_for_command(self, code: int, timeout_s: float) -> bool:
        """Whether the load has received command ``code`` within ``timeout_s`` [s].

        The load's thread handles bytes asynchronously: a command the host has sent may not
        be in :attr:`commands` yet.
        """
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if any(c[0] == code for c in self.commands):
                return True
            time.sleep(0.01)
        return False

    def _handle(self, frame: bytes) -> None:
        try:
            code, a, b, c = decode_command(frame)
        except EbcFrameError:
            self.bad_commands += 1
            return
        self.commands.append((code, a, b, c))
        if code == Command.CONNECT:
            self.connected = True
            self._fw_left = self.firmware_frames
        elif code == Command.DISCONNECT:
            self.connected = False
        elif code == Command.STOP:
            if self.ignore_stops > 0:
                self.ignore_stops -= 1
                return
            self.state = 0
            self.current_A = 0.0
        elif code in (Command.CC_DISCHARGE, Command.CC_ADJUST, Command.CC_RESUME):
            self.set_current_A = a * 0.01
            self.cutoff_V = b * 0.01
            self.time_limit_min = c
            if code == Command.CC_DISCHARGE:
                self.capacity_mAh = 0.0
                self.run_time_s = 0.0
            if code == Command.CC_ADJUST and self.state != 1:
                return
            self.state = 1
            self.current_A = self.set_current_A
            if self.voltage_V() <= self.cutoff_V:
                self._finish()

    # ------------------------------------------------------------------ frames
    def status(self) -> Status:
        """The status frame the load would send now."""
        voltage = self.voltage_V()
        if self.noise_V:
            voltage += float(self._rng.normal(0.0, self.noise_V))
        current_raw = int(round(self.current_A / self.current_unit_A))
        if self._fw_left > 0:
            code = 110 if self.state == 1 else 100          # 0x6E / 0x64: firmware report
            settings = (self.firmware_version, 2988, 2087)   # constants seen by [1]
        else:
            code = 10 * self.state                           # CC mode: 0x00 / 0x0A / 0x14
            settings = (int(round(self.set_current_A / 0.01)), int(round(self.cutoff_V / 0.01)),
                        self.time_limit_min)
        return Status(code, current_raw, max(int(round(voltage * 1000)), 0),
                      int(round(self.capacity_mAh)), 0, *settings, model_code=self.model_code)

    def _frame(self, status: Status) -> bytes:
        frame = bytearray(encode_status(status))
        if self.checksum_mod240 and frame[-2] >= BASE:
            frame[-2] = xor_checksum(frame[1:-2]) % BASE
        return bytes(frame)

    def _run(self) -> None:
        splitter = FrameSplitter(HOST_FRAME_BYTES)
        next_frame = time.monotonic() + self.frame_period_s
        while not self._stop.is_set():
            wait = max(next_frame - time.monotonic(), 0.0)
            try:
                ready, _, _ = select.select([self._master], [], [], wait)
            except (OSError, ValueError):
                return
            if ready:
                try:
                    data = os.read(self._master, 256)
                except OSError:
                    data = b""
                with self._lock:
                    for frame in splitter.feed(data):
                        self._handle(frame)
            if time.monotonic() >= next_frame:
                next_frame += self.frame_period_s
                with self._lock:
                    dt = self.frame_period_s * self.time_scale
                    self.sim_time_s += dt
                    self._advance(dt)
                    if self.connected:
                        status = self.status()
                        if self._fw_left > 0:
                            self._fw_left -= 1
                        try:
                            os.write(self._master, self._frame(status))
                            self.frames_sent += 1
                        except OSError:
                            pass


__all__ = ["VirtualEbcLoad"]
