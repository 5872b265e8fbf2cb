"""Wire format of the dischargelab Arduino logger: pure encode/decode, no I/O.

Every message, in both directions, is one *frame*::

    COBS( version | type | payload ... | crc16_lo | crc16_hi ) 0x00

* ``version`` (u8) is :data:`PROTOCOL_VERSION`; a frame of another version is
  rejected (counted as corrupt), so host and firmware never misread each other.
* ``type`` (u8) is one of :class:`MessageType`.
* ``crc16`` is CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF,
  no reflection, no final XOR; check value 0x29B1 for ``b"123456789"``) over
  version, type and payload, sent little-endian.
* The whole frame is byte-stuffed with COBS [1]_ so that 0x00 never occurs
  inside it; a single 0x00 ends each frame. A receiver that starts mid-stream or
  meets garbage resynchronises at the next 0x00.

Why COBS rather than sync bytes plus a length field: with COBS the decoded
length is fixed by the delimiters, so a frame that lost or gained bytes always
has the wrong length for its content and is rejected without relying on the
CRC; the CRC then guarantees detection of every 1-, 2- and 3-bit error and every
burst up to 16 bits in a frame [2]_. Overhead: one stuffing byte plus the
delimiter, the same two bytes a sync word would cost.

Multi-byte integers are little-endian (the AVR's native order). Message types
and payloads (``docs/acquisition.md`` has the byte tables):

==========  =====  =========================================================
type        value  payload
==========  =====  =========================================================
SAMPLE      0x01   seq u16, channel mask u8, one u16 ADC code per set bit
                   (lowest channel first, 0..1023)
INFO        0x02   ASCII ``key=value`` pairs separated by ``;``
ACK         0x03   command type u8, status u8, value u32
IDENTIFY    0x10   (none)                      -> INFO
SET_PERIOD  0x11   sample period u32 [us]      -> ACK, value = period applied
SET_CHANNELS 0x12  channel mask u8             -> ACK, value = mask applied
START       0x13   (none); restarts seq at 0   -> ACK
STOP        0x14   (none)                      -> ACK
SET_LOAD    0x15   u8 1 = load relay on, 0 = off -> ACK, value = state
==========  =====  =========================================================

References
----------
.. [1] S. Cheshire, M. Baker, "Consistent Overhead Byte Stuffing",
   IEEE/ACM Transactions on Networking 7(2), 1999.
.. [2] P. Koopman, T. Chakravarty, "Cyclic redundancy code (CRC) polynomial
   selection for embedded networks", DSN 2004 (0x1021 has Hamming distance 4
   up to 32751 data bits).
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass, field
from enum import IntEnum

from ..errors import DataError

#: Version byte of every frame; bump on any incompatible change of the layout.
PROTOCOL_VERSION = 1

#: Frame delimiter (never occurs inside a COBS-encoded frame).
DELIMITER = 0x00

#: Largest decoded frame (version + type + payload + CRC) either side accepts [bytes].
MAX_FRAME_BYTES = 200

#: Analog inputs the firmware can sample (Arduino Uno A0..A5).
MAX_CHANNELS = 6

#: ADC full scale of the ATmega328P (10 bits).
ADC_MAX_CODE = 1023

#: Serial line format: 1 start bit, 8 data bits, 1 stop bit per byte.
BITS_PER_BYTE_ON_WIRE = 10

CRC_INIT = 0xFFFF


class MessageType(IntEnum):
    """Frame types (see the module docstring for payloads)."""

    SAMPLE = 0x01
    INFO = 0x02
    ACK = 0x03
    IDENTIFY = 0x10
    SET_PERIOD = 0x11
    SET_CHANNELS = 0x12
    START = 0x13
    STOP = 0x14
    SET_LOAD = 0x15


COMMAND_TYPES = frozenset({MessageType.IDENTIFY, MessageType.SET_PERIOD,
                           MessageType.SET_CHANNELS, MessageType.START, MessageType.STOP,
                           MessageType.SET_LOAD})


class AckStatus(IntEnum):
    """Status byte of an ACK frame."""

    OK = 0
    BAD_ARGUMENT = 1      # value out of range; ACK value = the setting kept


class FrameError(ValueError):
    """A byte sequence is not a valid frame (the parser counts it as corrupt)."""


# --------------------------------------------------------------------------- CRC and COBS

def crc16(data: bytes, value: int = CRC_INIT) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (poly 0x1021, init 0xFFFF, no reflection)."""
    return binascii.crc_hqx(data, value)


def cobs_encode(data: bytes) -> bytes:
    """COBS-encode ``data`` (no trailing delimiter); output has no 0x00 byte."""
    out = bytearray()
    for part in bytes(data).split(b"\x00"):
        while len(part) >= 254:
            out.append(0xFF)
            out += part[:254]
            part = part[254:]
        out.append(len(part) + 1)
        out += part
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises :class:`FrameError` on invalid input."""
    out = bytearray()
    i = 0
    n = len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise FrameError("zero byte inside a COBS frame")
        end = i + code
        if end > n:
            raise FrameError("COBS group runs past the end of the frame")
        block = data[i + 1:end]
        if 0 in block:
            raise FrameError("zero byte inside a COBS frame")
        out += block
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)


# --------------------------------------------------------------------------- frames

@dataclass(frozen=True)
class SampleFrame:
    """One sample of the enabled analog channels.

    Attributes
    ----------
    seq : int
        16-bit sample counter, restarted at 0 by START, incremented for every
        timer tick even when a frame could not be sent (so gaps reveal loss).
    mask : int
        Bit ``k`` set = analog input ``Ak`` sampled.
    codes : tuple of int
        ADC codes (0..1023), one per set bit, lowest channel first.
    """

    seq: int
    mask: int
    codes: tuple[int, ...]

    def channel_codes(self) -> dict[int, int]:
        """``{channel: code}`` for the channels in the frame."""
        return dict(zip(channels_of_mask(self.mask), self.codes))


@dataclass(frozen=True)
class InfoFrame:
    """Identification text sent in answer to IDENTIFY."""

    text: str
    fields: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class AckFrame:
    """Answer to a host command."""

    command: int
    status: int
    value: int = 0

    @property
    def ok(self) -> bool:
        return self.status == AckStatus.OK


@dataclass(frozen=True)
class CommandFrame:
    """A host command as the device sees it."""

    command: int
    payload: bytes = b""


Frame = SampleFrame | InfoFrame | AckFrame | CommandFrame


def channels_of_mask(mask: int) -> tuple[int, ...]:
    """Channel numbers of the set bits of ``mask``, lowest first."""
    return tuple(k for k in range(MAX_CHANNELS) if mask >> k & 1)


def _seal(message_type: int, payload: bytes) -> bytes:
    body = bytes((PROTOCOL_VERSION, message_type)) + payload
    if len(body) + 2 > MAX_FRAME_BYTES:
        raise FrameError(f"frame of {len(body) + 2} bytes exceeds {MAX_FRAME_BYTES}")
    return cobs_encode(body + struct.pack("<H", crc16(body))) + b"\x00"


def encode_sample(seq: int, mask: int, codes) -> bytes:
    """Bytes on the wire for one SAMPLE frame (delimiter included)."""
    codes = tuple(int(c) for c in codes)
    if not 0 < mask < (1 << MAX_CHANNELS):
        raise FrameError(f"channel mask {mask:#x} must select 1..{MAX_CHANNELS} channels")
    if len(codes) != bin(mask).count("1"):
        raise FrameError(f"mask {mask:#x} needs {bin(mask).count('1')} codes, got {len(codes)}")
    if any(not 0 <= c <= ADC_MAX_CODE for c in codes):
        raise FrameError(f"ADC codes must be 0..{ADC_MAX_CODE}, got {codes}")
    payload = struct.pack(f"<HB{len(codes)}H", seq & 0xFFFF, mask, *codes)
    return _seal(MessageType.SAMPLE, payload)


def encode_info(fields: dict) -> bytes:
    """Bytes for an INFO frame from ``{key: value}`` (``;`` and ``=`` not allowed)."""
    text = ";".join(f"{k}={v}" for k, v in fields.items())
    return _seal(MessageType.INFO, text.encode("ascii"))


def encode_ack(command: int, status: int = AckStatus.OK, value: int = 0) -> bytes:
    """Bytes for an ACK frame."""
    return _seal(MessageType.ACK, struct.pack("<BBI", command, status, value & 0xFFFFFFFF))


def encode_command(command: MessageType, argument: int | None = None) -> bytes:
    """Bytes for a host command; ``argument`` as the command defines it."""
    command = MessageType(command)
    if command not in COMMAND_TYPES:
        raise FrameError(f"{command.name} is not a host command")
    if command == MessageType.SET_PERIOD:
        payload = struct.pack("<I", int(argument))
    elif command in (MessageType.SET_CHANNELS, MessageType.SET_LOAD):
        payload = struct.pack("<B", int(argument))
    else:
        payload = b""
    return _seal(command, payload)


def parse_info_text(text: str) -> dict:
    """``"a=1;b=x"`` -> ``{"a": "1", "b": "x"}``."""
    result = {}
    for item in text.split(";"):
        key, sep, value = item.partition("=")
        if sep and key:
            result[key.strip()] = value.strip()
    return result


def decode_frame(encoded: bytes, *, adc_max: int = ADC_MAX_CODE) -> Frame:
    """Decode one frame (COBS bytes WITHOUT the delimiter) or raise :class:`FrameError`."""
    if len(encoded) > MAX_FRAME_BYTES + 2:
        raise FrameError("frame too long")
    raw = cobs_decode(encoded)
    if len(raw) < 4:
        raise FrameError("frame too short")
    body, crc = raw[:-2], raw[-2] | raw[-1] << 8
    if crc16(body) != crc:
        raise FrameError("CRC mismatch")
    version, kind, payload = body[0], body[1], body[2:]
    if version != PROTOCOL_VERSION:
        raise FrameError(f"protocol version {version}, expected {PROTOCOL_VERSION}")
    if kind == MessageType.SAMPLE:
        if len(payload) < 5:
            raise FrameError("sample frame too short")
        seq, mask = struct.unpack_from("<HB", payload)
        n = bin(mask).count("1")
        if mask == 0 or mask >> MAX_CHANNELS or len(payload) != 3 + 2 * n:
            raise FrameError("sample frame length does not match its channel mask")
        codes = struct.unpack_from(f"<{n}H", payload, 3)
        if max(codes) > adc_max:
            raise FrameError("ADC code out of range")
        return SampleFrame(seq, mask, codes)
    if kind == MessageType.INFO:
        try:
            text = payload.decode("ascii")
        except UnicodeDecodeError:
            raise FrameError("INFO text is not ASCII") from None
        return InfoFrame(text, parse_info_text(text))
    if kind == MessageType.ACK:
        if len(payload) != 6:
            raise FrameError("ACK frame has the wrong length")
        return AckFrame(*struct.unpack("<BBI", payload))
    if kind in COMMAND_TYPES:
        expected = {MessageType.SET_PERIOD: 4, MessageType.SET_CHANNELS: 1,
                    MessageType.SET_LOAD: 1}.get(MessageType(kind), 0)
        if len(payload) != expected:
            raise FrameError(f"{MessageType(kind).name} frame has the wrong length")
        return CommandFrame(kind, bytes(payload))
    raise FrameError(f"unknown frame type {kind:#04x}")


class FrameParser:
    """Incremental parser: feed arbitrary byte chunks, get whole frames.

    Never raises on bad input: every rejected byte run between two delimiters
    counts once in :attr:`frames_corrupt`. The bytes before the first delimiter
    (a frame cut by connecting mid-stream) count in :attr:`bytes_skipped`
    instead, because they are expected rather than corrupt.

    Attributes
    ----------
    frames_ok, frames_corrupt : int
    bytes_skipped : int
        Bytes of the initial partial frame, ignored.
    """

    def __init__(self, *, adc_max: int = ADC_MAX_CODE, synced: bool = False):
        self._buffer = bytearray()
        self._synced = synced
        self._adc_max = adc_max
        self.frames_ok = 0
        self.frames_corrupt = 0
        self.bytes_skipped = 0
        self.last_error = ""

    def reset(self, *, synced: bool = False) -> None:
        """Forget buffered bytes (after a reconnect); counters are kept."""
        self._buffer.clear()
        self._synced = synced

    def feed(self, data: bytes) -> list[Frame]:
        """Parse ``data`` appended to what is buffered; return the complete frames."""
        if not data:
            return []
        self._buffer += data
        if DELIMITER not in data:
            if len(self._buffer) > 4 * MAX_FRAME_BYTES:  # garbage without delimiters
                if self._synced:
                    self.frames_corrupt += 1
                else:
                    self.bytes_skipped += len(self._buffer)
                self._buffer.clear()
                self._synced = True
            return []
        *segments, rest = bytes(self._buffer).split(b"\x00")
        self._buffer = bytearray(rest)
        frames = []
        for segment in segments:
            if not self._synced:
                # bytes before the first delimiter: usually the tail of a frame cut
                # by connecting mid-stream; kept only if they form a valid frame
                self._synced = True
                try:
                    frames.append(decode_frame(segment, adc_max=self._adc_max))
                except FrameError:
                    self.bytes_skipped += len(segment)
                continue
            if not segment:
                continue
            try:
                frames.append(decode_frame(segment, adc_max=self._adc_max))
            except FrameError as exc:
                self.frames_corrupt += 1
                self.last_error = str(exc)
        self.frames_ok += len(frames)
        return frames


# --------------------------------------------------------------------------- timing

#: Timer1 tick with prescaler 64 at 16 MHz [us].
TIMER_TICK_US = 4
#: Largest compare interval of the 16-bit Timer1 [ticks].
TIMER_MAX_TICKS = 65536
#: Shortest and longest sample period the firmware accepts [us].
MIN_PERIOD_US = 500
MAX_PERIOD_US = 3_600_000_000


def quantize_period_us(period_us: int) -> int:
    """Sample period [us] the firmware applies for a requested one.

    Timer1 counts 4 us ticks (prescaler 64); one compare interval holds at most
    65536 ticks (262.144 ms), so longer periods use ``n`` intervals (software
    postscaler): ``n = ceil(P / 262144)``, ``ticks = round(P / (4 n))``,
    applied period ``4 n ticks``. The firmware does the same integer arithmetic.

    Raises
    ------
    DataError
        Outside ``MIN_PERIOD_US .. MAX_PERIOD_US`` (the firmware answers BAD_ARGUMENT).
    """
    p = int(period_us)
    if not MIN_PERIOD_US <= p <= MAX_PERIOD_US:
        raise DataError(f"sample period {p} us is outside what the logger can do "
                        f"({MIN_PERIOD_US}..{MAX_PERIOD_US} us, i.e. "
                        f"{1e6 / MAX_PERIOD_US:.3g} to {1e6 / MIN_PERIOD_US:.4g} Hz)")
    span = TIMER_TICK_US * TIMER_MAX_TICKS
    n = (p + span - 1) // span
    ticks = (p + 2 * n) // (TIMER_TICK_US * n)
    ticks = min(max(ticks, 1), TIMER_MAX_TICKS)
    return n * ticks * TIMER_TICK_US


# --------------------------------------------------------------------------- link budget

def sample_frame_bytes(n_channels: int) -> int:
    """Bytes on the wire of one SAMPLE frame with ``n_channels`` channels.

    version 1 + type 1 + seq 2 + mask 1 + 2 per channel + CRC 2, plus one COBS
    overhead byte and the delimiter: ``9 + 2 n``.
    """
    return len(encode_sample(0xFFFF, (1 << n_channels) - 1, [ADC_MAX_CODE] * n_channels))


def max_frame_rate_Hz(n_channels: int, baudrate: int = 115200) -> float:
    """Highest SAMPLE frame rate the serial link carries [frames/s] (8N1, 10 bits per byte)."""
    return baudrate / BITS_PER_BYTE_ON_WIRE / sample_frame_bytes(n_channels)


class SequenceTracker:
    """Unwrap the 16-bit sample counter and count lost samples.

    ``expected_step`` (optional, from the elapsed time and the rate) resolves
    gaps longer than one counter period (65536 samples).
    """

    MODULO = 1 << 16

    def __init__(self):
        self.index: int | None = None
        self._last_seq: int | None = None
        self.lost = 0

    def restart(self, first_seq: int | None = None) -> None:
        """The device restarted its counter; ``first_seq`` is the value it restarts at
        (0 after START): samples missing before the first one received count as lost."""
        if first_seq is None:
            self.index = None
            self._last_seq = None
        else:
            self.index = first_seq - 1
            self._last_seq = (first_seq - 1) & 0xFFFF

    def update(self, seq: int, expected_step: float | None = None) -> int:
        """Unwrapped index of ``seq``; adds the skipped samples to :attr:`lost`."""
        if self.index is None:
            self.index, self._last_seq = seq, seq
            return seq
        step = (seq - self._last_seq) % self.MODULO
        if step == 0:
            step = self.MODULO
        if expected_step is not None and expected_step > self.MODULO / 2:
            wraps = round((expected_step - step) / self.MODULO)
            step += max(0, wraps) * self.MODULO
        self.lost += step - 1
        self.index += step
        self._last_seq = seq
        return self.index
