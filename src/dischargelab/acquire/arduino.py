"""The dischargelab Arduino logger as a :class:`~dischargelab.acquire.pipeline.SampleSource`.

Talks the protocol of :mod:`dischargelab.acquire.protocol` to the sketch in
``firmware/arduino/dischargelab_logger``: identifies the firmware, sets the
channels and the sample period, starts the hardware-timed stream and turns each
SAMPLE frame into a calibrated :class:`Sample`.

Timing: sample ``k`` after START was taken ``k * period`` after the first one
by the board's Timer1, so ``time_s`` comes from the sample counter, not from
when the bytes happened to arrive. (The Uno's clock is a ceramic resonator,
typically within 0.5 %; the live view shows the rate measured by the host.)
After a reconnect the board has usually been reset (opening the port pulses
DTR), so the counter restarts; the new samples are placed after the last one
by the host's clock and the gap is recorded.
"""

from __future__ import annotations

import math
import time

from ..errors import DataError
from . import protocol as proto
from .pipeline import Sample, SourceDisconnected
from .sensors import (
    CURRENT_CHANNEL,
    TEMPERATURE_CHANNEL,
    VOLTAGE_CHANNEL,
    CurrentSensor,
    Thermistor,
    adc_to_volts,
    finite_or_none,
)
from .transport import SerialTransport


def _as_calibration(calibration):
    from .calibration import Calibration

    if calibration is None:
        raise DataError("the Arduino logger needs the divider gain: give --ke (e.g. 4.38, the "
                        "paper's 3.3 kOhm divider) or --calibration cal.json")
    if isinstance(calibration, (int, float)):
        return Calibration(gain=float(calibration))
    return calibration


class ArduinoSource:
    """Samples from the dischargelab Arduino logger.

    Parameters
    ----------
    port : str
        Serial device (``/dev/ttyACM0``, ``COM3``, a virtual device's pty).
    rate_Hz : float
        Sample rate requested from the board [Hz]; the applied rate (Timer1
        granularity) is in ``info["rate_Hz"]``.
    calibration : Calibration or float
        Divider gain Ke (paper eq. 7) as a Calibration or a plain number.
    current_sensor : CurrentSensor, optional
        Enables channel A1 and converts it to amperes.
    thermistor : Thermistor, optional
        Enables channel A2 and converts it to degC.
    baudrate : int
    switch_load : bool
        Close the load relay (SET_LOAD 1) after START; :meth:`stop_load` opens it.
    connect_timeout_s : float
        How long to wait for the board to answer after opening the port (the
        Uno's bootloader needs 1-2 s after the reset that opening causes).
    stall_timeout_s : float, optional
        No valid sample for this long while streaming = link lost. Default
        ``max(3 s, 3 sample periods)``.
    transport : object, optional
        Something with ``open/read/write/close/discard_input`` (default: a
        :class:`~dischargelab.acquire.transport.SerialTransport`).
    connect : bool
        Open and start streaming in the constructor.
    """

    name = "arduino"

    def __init__(self, port: str, *, rate_Hz: float = 1.0, calibration=None,
                 current_sensor: CurrentSensor | None = None,
                 thermistor: Thermistor | None = None, baudrate: int = 115200,
                 switch_load: bool = False, connect_timeout_s: float = 5.0,
                 command_timeout_s: float = 1.0, stall_timeout_s: float | None = None,
                 transport=None, connect: bool = True, clock=time.monotonic):
        if not (math.isfinite(rate_Hz) and rate_Hz > 0):
            raise DataError(f"sample rate must be a positive number of Hz, got {rate_Hz}")
        self.port = port
        self.calibration = _as_calibration(calibration)
        self.current_sensor = current_sensor
        self.thermistor = thermistor
        self.baudrate = int(baudrate)
        self.switch_load = bool(switch_load)
        self.connect_timeout_s = float(connect_timeout_s)
        self.command_timeout_s = float(command_timeout_s)
        self._clock = clock
        self.mask = 1 << VOLTAGE_CHANNEL
        if current_sensor is not None:
            self.mask |= 1 << CURRENT_CHANNEL
        if thermistor is not None:
            self.mask |= 1 << TEMPERATURE_CHANNEL
        self.channels = proto.channels_of_mask(self.mask)
        n = len(self.channels)
        link_max = proto.max_frame_rate_Hz(n, self.baudrate)
        if rate_Hz > link_max:
            raise DataError(f"{rate_Hz:g} Hz exceeds what {self.baudrate} baud carries with {n} "
                            f"channel{'s' if n > 1 else ''} ({link_max:.0f} frames/s of "
                            f"{proto.sample_frame_bytes(n)} bytes); lower --rate")
        try:
            self.period_us = proto.quantize_period_us(round(1e6 / rate_Hz))
        except ValueError:
            raise DataError(f"sample rate {rate_Hz:g} Hz is outside what the firmware supports "
                            f"({1e6 / proto.MAX_PERIOD_US:.6g}..{1e6 / proto.MIN_PERIOD_US:g} Hz)"
                            ) from None
        self._requested_period_us = self.period_us
        self._stall_timeout_s = stall_timeout_s
        self._transport = transport or SerialTransport(port, self.baudrate)
        self._parser = proto.FrameParser()
        self._tracker = proto.SequenceTracker()
        self._pending: list = []
        self.time_scale = 1.0
        self.streaming = False
        self._time_offset_s = 0.0
        self._last_time_s: float | None = None
        self._last_rx = None
        self._last_sample_wall = None
        self._mask_mismatch = 0
        self._samples_ok = 0
        self._reconnects = 0
        self.info: dict = {"source": "arduino", "port": port, "baudrate": self.baudrate,
                           "channels": [f"A{c}" for c in self.channels],
                           "calibration": _calibration_info(self.calibration)}
        if current_sensor is not None:
            self.info["current_sensor"] = current_sensor.to_dict()
        if thermistor is not None:
            self.info["thermistor"] = thermistor.to_dict()
        if connect:
            self.open()

    # ------------------------------------------------------------------ statistics
    @property
    def stats(self) -> dict:
        return {"frames_ok": self._samples_ok,
                "frames_corrupt": self._parser.frames_corrupt + self._mask_mismatch,
                "frames_lost": self._tracker.lost, "reconnects": self._reconnects,
                "bytes_skipped": self._parser.bytes_skipped}

    # ------------------------------------------------------------------ link
    def open(self) -> ArduinoSource:
        """Open the port, identify the firmware, configure and start streaming."""
        try:
            self._transport.open()
            self._handshake()
        except BaseException:
            self._transport.close()
            raise
        return self

    def _send(self, command, argument=None) -> None:
        self._transport.write(proto.encode_command(command, argument))

    def _frames(self, timeout_s: float) -> list:
        return self._parser.feed(self._transport.read(timeout_s))

    def _handshake(self) -> None:
        self.streaming = False
        self._parser.reset()
        deadline = self._clock() + self.connect_timeout_s
        info = None
        while info is None and self._clock() < deadline:
            self._send(proto.MessageType.STOP)
            self._send(proto.MessageType.IDENTIFY)
            until = min(deadline, self._clock() + 0.3)
            while info is None and self._clock() < until:
                info = next((f for f in self._frames(0.05) if isinstance(f, proto.InfoFrame)), None)
        if info is None:
            if "protocol version" in self._parser.last_error:
                raise SourceDisconnected(
                    f"the logger on {self.port} speaks another {self._parser.last_error}; "
                    "flash firmware/arduino/dischargelab_logger from this version of dischargelab")
            raise SourceDisconnected(
                f"no answer from a dischargelab logger on {self.port} within "
                f"{self.connect_timeout_s:g} s; is firmware/arduino/dischargelab_logger loaded "
                f"and the baud rate {self.baudrate}?")
        fields = info.fields
        self.info["firmware"] = f"{fields.get('fw', '?')} {fields.get('fw_version', '')}".strip()
        self.info["protocol"] = int(fields.get("proto", proto.PROTOCOL_VERSION))
        self.info["board"] = fields.get("board", "")
        self.info["adc_bits"] = int(fields.get("adc_bits", 10))
        self.info["adc_reference_V"] = int(fields.get("vref_mV", 5000)) / 1000.0
        self.time_scale = float(fields.get("time_scale", 1.0))
        if self.time_scale != 1.0:
            self.info["time_scale"] = self.time_scale
        self._command(proto.MessageType.SET_CHANNELS, self.mask)
        ack = self._command(proto.MessageType.SET_PERIOD, self._requested_period_us)
        self.period_us = ack.value
        self.rate_Hz = 1e6 / self.period_us
        self.info["rate_Hz"] = self.rate_Hz
        self.info["period_us"] = self.period_us
        if self._stall_timeout_s is None:
            self.stall_timeout_s = max(3.0, 3.0 * self.period_us / 1e6 / self.time_scale)
        else:
            self.stall_timeout_s = float(self._stall_timeout_s)
        self._pending = []                      # anything before START is stale
        self._command(proto.MessageType.START)
        started = self._clock()
        if self.switch_load:
            self._command(proto.MessageType.SET_LOAD, 1)
        # place the restarted counter after the last sample, by the host's clock
        if self._last_time_s is not None and self._last_sample_wall is not None:
            gap_s = (started - self._last_sample_wall) * self.time_scale
            self._time_offset_s = self._last_time_s + max(gap_s, self.period_us / 1e6)
        self._tracker.restart(first_seq=0)     # START restarts the counter at 0
        self._last_rx = started
        self.streaming = True

    def _command(self, command, argument=None) -> proto.AckFrame:
        """Send a command and wait for its ACK (three tries); keep samples that arrive."""
        for _ in range(3):
            self._send(command, argument)
            deadline = self._clock() + self.command_timeout_s
            while self._clock() < deadline:
                ack = None
                for frame in self._frames(0.05):
                    if isinstance(frame, proto.AckFrame) and frame.command == command:
                        ack = frame
                    elif isinstance(frame, proto.SampleFrame):
                        self._pending.append(frame)
                if ack is not None:
                    if not ack.ok:
                        raise DataError(
                            f"the logger refused {proto.MessageType(command).name} "
                            f"{'' if argument is None else argument} "
                            f"(status {proto.AckStatus(ack.status).name})")
                    return ack
        raise SourceDisconnected(f"the logger on {self.port} did not acknowledge "
                                 f"{proto.MessageType(command).name}")

    # ------------------------------------------------------------------ SampleSource
    def read(self, timeout_s: float) -> list[Sample]:
        """Calibrated samples received within ``timeout_s``."""
        if not self.streaming:
            raise SourceDisconnected(f"the logger on {self.port} is not streaming")
        frames = self._frames(timeout_s)
        now = self._clock()
        if self._pending:
            frames = self._pending + frames
            self._pending = []
        samples = []
        for frame in frames:
            if not isinstance(frame, proto.SampleFrame):
                continue
            if frame.mask != self.mask:
                self._mask_mismatch += 1
                continue
            samples.append(self._sample(frame, now))
        self._samples_ok += len(samples)
        if samples:
            self._last_rx = now
            self._last_sample_wall = now
        elif now - self._last_rx > self.stall_timeout_s:
            self.streaming = False
            raise SourceDisconnected(f"no data from the logger on {self.port} for "
                                     f"{now - self._last_rx:.1f} s")
        return samples

    def _sample(self, frame: proto.SampleFrame, now: float) -> Sample:
        expected = None
        if self._last_rx is not None:
            expected = (now - self._last_rx) * self.time_scale * 1e6 / self.period_us
        index = self._tracker.update(frame.seq, expected)
        t = self._time_offset_s + index * self.period_us / 1e6
        codes = frame.channel_codes()
        vref = self.info.get("adc_reference_V", 5.0)
        bits = self.info.get("adc_bits", 10)
        voltage = float(self.calibration.apply(adc_to_volts(codes[VOLTAGE_CHANNEL], vref, bits)))
        current = temperature = None
        if self.current_sensor is not None:
            current = finite_or_none(self.current_sensor.current_A(
                adc_to_volts(codes[CURRENT_CHANNEL], vref, bits)))
        if self.thermistor is not None:
            temperature = finite_or_none(self.thermistor.temperature_C(
                adc_to_volts(codes[TEMPERATURE_CHANNEL], vref, bits)))
        self._last_time_s = t
        return Sample(time_s=t, voltage_V=voltage, current_A=current,
                      temperature_C=temperature, seq=frame.seq)

    def reconnect(self) -> None:
        """Reopen the port and restart streaming; raises SourceDisconnected if not yet possible."""
        self.streaming = False
        self._transport.close()
        self.open()
        self._reconnects += 1

    @property
    def controls_load(self) -> bool:
        """True when the logger drives the load relay (``switch_load``)."""
        return self.switch_load

    def stop_load(self) -> None:
        """Open the load relay (SET_LOAD 0); harmless when no relay is wired."""
        if not self._transport.is_open:
            raise SourceDisconnected(f"{self.port} is not open: the load could not be switched "
                                     "off by the logger")
        self._send(proto.MessageType.SET_LOAD, 0)

    def close(self) -> None:
        """Stop streaming (best effort) and close the port."""
        if self._transport.is_open:
            try:
                self._send(proto.MessageType.STOP)
            except SourceDisconnected:
                pass
        self.streaming = False
        self._transport.close()


def _calibration_info(calibration) -> dict:
    out = {"gain": float(calibration.gain), "offset_V": float(getattr(calibration, "offset_V", 0))}
    for key in ("divider", "created", "valid_range_V"):
        value = getattr(calibration, key, None)
        if value:
            out[key] = list(value) if isinstance(value, tuple) else value
    return out
