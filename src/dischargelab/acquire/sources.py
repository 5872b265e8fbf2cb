"""One factory for every kind of sample source: ``open_source(kind, port, **options)``.

The ``acquire`` command builds its source only through :func:`open_source`, so
a new instrument needs a module with an opener function and one entry in
:data:`SOURCE_KINDS` (or a call to :func:`register_source`).

Options the command passes (an opener uses what applies to its instrument
and ignores the rest): ``rate_Hz``, ``calibration`` (Calibration or None),
``current_sensor``, ``thermistor``, ``baudrate``, ``switch_load``,
``current_A`` (set/known discharge current [A] or None), ``cutoff_pack_V``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from ..errors import DataError


@dataclass(frozen=True)
class SourceKind:
    """Where a source kind's opener lives (imported only when used) and a one-line help."""

    module: str
    function: str
    help: str


#: Known source kinds (``--source`` choices). The first is the default.
SOURCE_KINDS: dict[str, SourceKind] = {
    "arduino": SourceKind("dischargelab.acquire.sources", "open_arduino",
                          "dischargelab Arduino logger (firmware/arduino), 115200 baud"),
    "ebc-a20": SourceKind("dischargelab.acquire.sources", "open_ebc",
                          "ZKETECH EBC-A20 electronic load, constant-current discharge "
                          "(needs --current)"),
}


def register_source(kind: str, module: str, function: str, help: str = "") -> None:
    """Add (or replace) a source kind."""
    SOURCE_KINDS[kind] = SourceKind(module, function, help)


def open_source(kind: str, port: str, **options):
    """Open a :class:`~dischargelab.acquire.pipeline.SampleSource` of ``kind`` on ``port``.

    Raises
    ------
    DataError
        Unknown kind or unusable options.
    SourceDisconnected
        The port cannot be opened or the instrument does not answer.
    """
    spec = SOURCE_KINDS.get(kind)
    if spec is None:
        raise DataError(f"unknown source {kind!r}; choose one of {', '.join(SOURCE_KINDS)}")
    opener = getattr(importlib.import_module(spec.module), spec.function)
    return opener(port, **options)


def open_arduino(port: str, *, rate_Hz: float = 1.0, calibration=None, current_sensor=None,
                 thermistor=None, baudrate: int | None = None, switch_load: bool = False,
                 **_ignored):
    """The dischargelab Arduino logger (:class:`~dischargelab.acquire.arduino.ArduinoSource`)."""
    from .arduino import ArduinoSource

    return ArduinoSource(port, rate_Hz=rate_Hz, calibration=calibration,
                         current_sensor=current_sensor, thermistor=thermistor,
                         baudrate=baudrate or 115200, switch_load=switch_load)


def open_ebc(port: str, *, current_A: float | None = None, cutoff_pack_V: float | None = None,
             calibration=None, baudrate: int | None = None, parity: str | None = None,
             **_ignored):
    """A ZKETECH EBC-A load running a CC discharge
    (:class:`~dischargelab.acquire.ebc.EbcSource`)."""
    from .ebc import BAUDRATE, EbcSource

    if current_A is None:
        raise DataError("the EBC load needs the discharge current: give --current A")
    if cutoff_pack_V is None:
        raise DataError("the EBC load needs a cutoff voltage: give --cells or --cutoff-cell")
    options = {} if parity is None else {"parity": parity}
    return EbcSource(port, current_A=current_A, cutoff_V=cutoff_pack_V, calibration=calibration,
                     baudrate=baudrate or BAUDRATE, **options)
