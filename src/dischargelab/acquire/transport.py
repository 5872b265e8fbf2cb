"""Serial-port access: the only module of dischargelab that imports pyserial.

Every pyserial failure (port missing, cable pulled, device gone) becomes a
:class:`~dischargelab.acquire.pipeline.SourceDisconnected` with the port name,
so sources and the pipeline handle one exception type.
"""

from __future__ import annotations

import time

from ..errors import DataError, require
from .pipeline import SourceDisconnected

_PARITY_NAMES = {"N": "PARITY_NONE", "E": "PARITY_EVEN", "O": "PARITY_ODD"}


def _serial():
    return require("serial", "acquire")


def list_serial_ports() -> list[tuple[str, str]]:
    """Serial ports the operating system knows: ``[(device, description), ...]``."""
    require("serial", "acquire")
    from serial.tools import list_ports

    return [(p.device, p.description or "") for p in sorted(list_ports.comports())]


def _port_hint() -> str:
    try:
        ports = list_serial_ports()
    except Exception:
        return ""
    if not ports:
        return " (no serial ports found; is the board plugged in?)"
    return " (ports found: " + ", ".join(p for p, _ in ports[:6]) + ")"


def open_serial(port: str, *, baudrate: int = 115200, parity: str = "N",
                timeout_s: float = 0.1, write_timeout_s: float = 2.0):
    """Open ``port`` 8-bit, 1 stop bit; returns a ``serial.Serial``.

    Raises
    ------
    SourceDisconnected
        The port does not exist or cannot be opened (message names the port and
        lists the ports that exist).
    """
    serial = _serial()
    if parity not in _PARITY_NAMES:
        raise DataError(f"parity must be one of {sorted(_PARITY_NAMES)}, got {parity!r}")
    try:
        return serial.Serial(port, baudrate=int(baudrate), bytesize=serial.EIGHTBITS,
                             parity=getattr(serial, _PARITY_NAMES[parity]),
                             stopbits=serial.STOPBITS_ONE, timeout=timeout_s,
                             write_timeout=write_timeout_s, exclusive=True)
    except (serial.SerialException, OSError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise SourceDisconnected(f"cannot open serial port {port}: {reason}{_port_hint()}") \
            from None


class SerialTransport:
    """A byte pipe over a serial port, with batched reads.

    Parameters
    ----------
    port : str
        Device path (``/dev/ttyACM0``, ``COM3``, a pseudo-terminal).
    baudrate : int
    coalesce_s : float
        After the first byte of a read arrives, wait this long for more before
        returning [s]: fewer, larger reads (less CPU) at the cost of that much latency.
    """

    def __init__(self, port: str, baudrate: int = 115200, *, coalesce_s: float = 0.01):
        self.port = port
        self.baudrate = int(baudrate)
        self.coalesce_s = float(coalesce_s)
        self._ser = None
        self._timeout = None
        self.bytes_read = 0
        self.bytes_written = 0

    @property
    def is_open(self) -> bool:
        return self._ser is not None

    def open(self) -> SerialTransport:
        self.close()
        self._ser = open_serial(self.port, baudrate=self.baudrate, timeout_s=0.05)
        self._timeout = 0.05
        return self

    def _lost(self, exc: Exception) -> SourceDisconnected:
        self.close()
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        return SourceDisconnected(f"serial port {self.port} lost: {reason}")

    def read(self, timeout_s: float) -> bytes:
        """Bytes received within ``timeout_s`` (b"" if none); raises SourceDisconnected."""
        ser = self._ser
        if ser is None:
            raise SourceDisconnected(f"serial port {self.port} is not open")
        serial = _serial()
        try:
            waiting = ser.in_waiting
            if not waiting:
                if self._timeout != timeout_s:
                    ser.timeout = timeout_s
                    self._timeout = timeout_s
                first = ser.read(1)
                if not first:
                    return b""
                if self.coalesce_s > 0:
                    time.sleep(self.coalesce_s)
                waiting = ser.in_waiting
                data = first + (ser.read(waiting) if waiting else b"")
            else:
                data = ser.read(waiting)
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            # pyserial raises TypeError/AttributeError when the port is closed under it
            raise self._lost(exc) from None
        self.bytes_read += len(data)
        return data

    def write(self, data: bytes) -> None:
        """Send ``data`` completely; raises SourceDisconnected."""
        ser = self._ser
        if ser is None:
            raise SourceDisconnected(f"serial port {self.port} is not open")
        serial = _serial()
        try:
            ser.write(data)
            ser.flush()
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            raise self._lost(exc) from None
        self.bytes_written += len(data)

    def discard_input(self) -> None:
        """Drop bytes waiting in the receive buffer."""
        if self._ser is not None:
            try:
                self._ser.reset_input_buffer()
            except (OSError, _serial().SerialException) as exc:
                raise self._lost(exc) from None

    def close(self) -> None:
        """Close the port (idempotent, never raises)."""
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:
                pass
