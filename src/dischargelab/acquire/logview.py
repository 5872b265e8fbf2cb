"""Stream samples as LogView "OpenFormat" lines (file or serial port).

LogView (logview.info) displays serial data of chargers and loggers; its
"OpenFormat" (OF) lets any device describe itself with an INI file and send
ASCII lines [1]_::

    $1;1;12.500;7.812;5.002;39.07;0.0174;;3F<CR><LF>
    |  | |      '---------- data items -----' '- checksum
    |  | '- time stamp [s], starting at 0
    |  '- state (names a data set, e.g. 1 = discharge, 2 = rest)
    '- channel (1..8)

Facts from the format description [1]_: a line starts with ``$``, items are
separated by ``;``, the line ends with CR LF; channel, state and time stamp
come first (time in seconds, fractions allowed, starting at 0, or an empty
item when the device gives no time); up to 40 data items per channel; the
optional checksum is the XOR of every byte from ``$`` up to and including the
last ``;``. The description does not say how the checksum is written; GNU
DataExplorer, which reads the same lines, parses it as hexadecimal [2]_, so
it is written here as two upper-case hex digits. (The example line in [1]_,
``...;0;16``, has an XOR of 0x14, so it settles neither way.)

Missing values (current or temperature not measured) are left empty.

References
----------
.. [1] LogView, "OpenFormat - Format description" (D. Schmidt, 2008),
   http://www.logview.info (copy in cweiske/usb-wde1-tools,
   doc/logview-openformat-Formatbeschreibung.htm).
.. [2] GNU DataExplorer, ``gde/io/DataParser.java`` (``$1;1;0;...`` lines,
   checksum ``Integer.parseInt(..., 16)`` over the bytes up to the last ``;``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import reduce
from pathlib import Path

from ..atomic import write_text
from ..errors import DataError

#: Data items written after channel, state and time: (key, name, unit, symbol).
DEFAULT_COLUMNS: tuple[tuple[str, str, str, str], ...] = (
    ("voltage_V", "Voltage", "V", "U"),
    ("current_A", "Current", "A", "I"),
    ("power_W", "Power", "W", "P"),
    ("charge_Ah", "Charge", "Ah", "Q"),
    ("temperature_C", "Temperature", "degC", "T"),
)

#: State numbers written in the state item, and their names in the INI file.
STATES = {1: "Discharge", 2: "Rest"}

#: Events after which the load is off, so further samples are "Rest".
REST_EVENTS = frozenset({"cutoff", "stop", "load-stopped", "over-temperature", "alarm"})

_DEVICE_PATH = re.compile(r"^(/dev/|COM\d+$|\\\\\.\\)", re.IGNORECASE)


def xor_checksum(text: str) -> int:
    """XOR of the ASCII bytes of ``text``."""
    return reduce(lambda acc, b: acc ^ b, text.encode("ascii"), 0)


def _fmt(value, digits: int) -> str:
    if value is None:
        return ""
    return f"{value:.{digits}f}"


def format_line(channel: int, state: int, time_s: float | None, values, *, checksum: bool = True,
                digits=None) -> str:
    """One OpenFormat line including CR LF.

    Parameters
    ----------
    channel : int
        1..8.
    state : int
        State number (defined in the INI file).
    time_s : float or None
        Time stamp [s] (None: empty item, LogView counts TimeStep instead).
    values : sequence of float or None
        Data items; None is written as an empty item.
    checksum : bool
        Append the XOR checksum (two hex digits); otherwise the last item is 0
        ("Checksum = 0" when the INI says none [1]_).
    digits : sequence of int, optional
        Decimal places per value (default 4).
    """
    if not 1 <= int(channel) <= 8:
        raise DataError(f"LogView channel must be 1..8, got {channel}")
    values = list(values)
    if len(values) > 40:
        raise DataError(f"LogView takes at most 40 data items per channel, got {len(values)}")
    digits = list(digits) if digits is not None else [4] * len(values)
    items = [str(int(channel)), str(int(state)), _fmt(time_s, 3)]
    items += [_fmt(v, d) for v, d in zip(values, digits)]
    body = "$" + ";".join(items) + ";"
    tail = f"{xor_checksum(body):02X}" if checksum else "0"
    return body + tail + "\r\n"


@dataclass(frozen=True)
class OpenFormatLine:
    """A parsed OpenFormat line."""

    channel: int
    state: int
    time_s: float | None
    values: tuple[float | None, ...]
    checksum: int | None


def parse_line(line: str, *, checksum: bool = True) -> OpenFormatLine:
    """Parse one OpenFormat line (CR LF optional); verifies the checksum if asked."""
    text = line.rstrip("\r\n")
    if not text.startswith("$") or ";" not in text:
        raise DataError(f"not a LogView OpenFormat line: {line!r}")
    body, _, tail = text.rpartition(";")
    body += ";"
    items = body[1:-1].split(";")
    if len(items) < 3:
        raise DataError(f"OpenFormat line needs channel;state;time: {line!r}")
    value = None
    if checksum:
        try:
            value = int(tail, 16)
        except ValueError:
            raise DataError(f"OpenFormat checksum {tail!r} is not hexadecimal") from None
        if value != xor_checksum(body):
            raise DataError(f"OpenFormat checksum {tail} != XOR {xor_checksum(body):02X}")

    def number(item):
        item = item.strip().replace(",", ".")
        return float(item) if item else None

    try:
        return OpenFormatLine(int(items[0]), int(items[1]), number(items[2]),
                              tuple(number(i) for i in items[3:]), value)
    except ValueError:
        raise DataError(f"OpenFormat line has a non-numeric item: {line!r}") from None


def device_ini(columns=DEFAULT_COLUMNS, *, name: str = "dischargelab", baudrate: int = 115200,
               time_step_s: float = 1.0, checksum: bool = True, channel: int = 1) -> str:
    """The LogView device description (INI) matching :class:`LogViewWriter` output.

    Setting names are those of the OpenFormat description [1]_ (German names
    where it gives them: Messgröße, Einheit, Faktor, OffsetWert, OffsetSumme;
    the ``[Stati]`` block is in the documented layout). LogView's own
    OpenFormat editor writes these files; check the generated one there once
    before relying on it (see docs/electronic-loads.md).
    """
    lines = [
        "; LogView OpenFormat device description written by dischargelab",
        "; setting names follow the OpenFormat description (logview.info); only the [Stati]",
        "; block is quoted there verbatim: open this file once in LogView's OpenFormat editor",
        "; line: $channel;state;time[s];" + ";".join(f"{c[1]}[{c[2]}]" for c in columns)
        + ";checksum CR LF",
        "",
        "[Geraet]",
        f"Name = {name}",
        "Hersteller = dischargelab",
        "HerstellerLink = ",
        f"TimeStep = {time_step_s:g}",
        "ZeitVomGeraet = 1",
        "WertFormat = ASCII",
        f"Checksumme = {'xor' if checksum else 'none'}",
        "",
        "[Anschluss]",
        f"Baudrate = {int(baudrate)}",
        "Datenbits = 8",
        "Stopbits = 1",
        "Parity = none",
        "Flowcontrol = none",
        "DTR = 1",
        "RTS = 1",
        "Clustersize = -1",
        "",
        "[Stati]",
        f"StatiAnzahl = {len(STATES)}",
        "",
    ]
    lines += [f"{number:03d} = {label}" for number, label in STATES.items()]
    lines += ["", f"[Kanal{channel}]", f"Messgroessen = {len(columns)}", ""]
    for i, (_, label, unit, symbol) in enumerate(columns, start=1):
        lines += [f"[Kanal{channel}Wert{i}]", f"Messgroesse = {label}", f"Einheit = {unit}",
                  f"Symbol = {symbol}", "Faktor = 1.0", "OffsetWert = 0.0",
                  "OffsetSumme = 0.0", ""]
    return "\r\n".join(lines)


def is_serial_target(target) -> bool:
    """True when ``target`` names a serial port (COM3, /dev/ttyUSB0...), not a file."""
    return bool(_DEVICE_PATH.match(str(target)))


class LogViewWriter:
    """Consumer writing every sample as an OpenFormat line to a file or serial port.

    Parameters
    ----------
    target : str or path
        A file path, or a serial device (``/dev/ttyUSB0``, ``/dev/pts/3``,
        ``COM7``) to feed a LogView running on another port / machine.
    channel : int
        OpenFormat channel (1..8).
    baudrate : int
        For a serial target.
    checksum : bool
        Append the XOR checksum.
    ini_path : str or path, optional
        Also write the matching device description there.

    Values written: pack voltage [V], current [A], power [W], charge [Ah]
    (trapezoidal integral of the current since the first sample) and
    temperature [degC]; time starts at 0 with the first sample.
    """

    def __init__(self, target, *, channel: int = 1, baudrate: int = 115200,
                 checksum: bool = True, ini_path=None, serial: bool | None = None):
        self.target = str(target)
        self.channel = int(channel)
        self.checksum = bool(checksum)
        self.baudrate = int(baudrate)
        self.state = 1
        self.lines_written = 0
        self._t0: float | None = None
        self._last = None
        self.charge_Ah = 0.0
        is_serial = is_serial_target(self.target) if serial is None else serial
        self.is_serial = is_serial
        if ini_path is not None:
            write_text(ini_path, device_ini(baudrate=baudrate, checksum=checksum,
                                            channel=channel))
        if is_serial:
            from .transport import open_serial

            self._port = open_serial(self.target, baudrate=self.baudrate, timeout_s=0.1)
            self._file = None
        else:
            path = Path(self.target)
            path.parent.mkdir(parents=True, exist_ok=True)
            self._file = path.open("w", encoding="ascii", newline="")
            self._port = None

    def _write(self, text: str) -> None:
        if self._file is not None:
            self._file.write(text)
            self._file.flush()
        else:
            self._port.write(text.encode("ascii"))

    def handle(self, sample) -> None:
        if self._t0 is None:
            self._t0 = sample.time_s
        last = self._last
        if last is not None and sample.current_A is not None and last.current_A is not None:
            self.charge_Ah += 0.5 * (sample.current_A + last.current_A) \
                * (sample.time_s - last.time_s) / 3600.0
        self._last = sample
        power = None if sample.current_A is None else sample.voltage_V * sample.current_A
        values = (sample.voltage_V, sample.current_A, power, self.charge_Ah, sample.temperature_C)
        self._write(format_line(self.channel, self.state, sample.time_s - self._t0, values,
                                checksum=self.checksum, digits=(4, 4, 3, 5, 2)))
        self.lines_written += 1

    def event(self, kind: str, **fields) -> None:
        """OpenFormat has no event lines; an end of discharge switches the state to Rest."""
        if kind in REST_EVENTS:
            self.state = 2

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        if self._port is not None:
            try:
                self._port.close()
            finally:
                self._port = None


def read_openformat(path, *, checksum: bool = True) -> list[OpenFormatLine]:
    """Parse every line of an OpenFormat file (blank lines skipped)."""
    with Path(path).open(encoding="ascii", newline="") as fh:
        return [parse_line(line, checksum=checksum) for line in fh if line.strip()]


__all__ = ["DEFAULT_COLUMNS", "STATES", "LogViewWriter", "OpenFormatLine", "device_ini",
           "format_line", "is_serial_target", "parse_line", "read_openformat", "xor_checksum"]
