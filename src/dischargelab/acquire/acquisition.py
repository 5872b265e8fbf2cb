"""A complete acquisition run: source + data file + safety + live view, until the test ends.

This is what ``dischargelab acquire`` does, as a library call:
:func:`prepare_acquisition` opens the source, settles the cell count and the
limits, creates the log file and the consumers; :meth:`Acquisition.run` runs
the pipeline with a terminal view (or periodic lines), handles Ctrl-C and
SIGTERM as a clean stop, and returns an :class:`AcquireResult`.
"""

from __future__ import annotations

import math
import platform
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..atomic import check_outputs
from ..errors import DataError, DischargelabError
from .pipeline import EXIT_STATUS, Pipeline, ReconnectPolicy, SourceDisconnected
from .safety import SafetyLimits, SafetyMonitor, infer_cells


@dataclass
class AcquireSettings:
    """Everything ``dischargelab acquire`` is told (see its ``--help``)."""

    port: str
    out: Path
    source: str = "arduino"
    cells: int | None = None
    chemistry: str = "lipo"
    cutoff_cell_V: float | None = None
    max_temperature_C: float | None = 60.0
    debounce_samples: int = 3
    rate_Hz: float = 1.0
    calibration: object | None = None
    current_A: float | None = None
    current_sensor: object | None = None
    thermistor: object | None = None
    baudrate: int | None = None
    parity: str | None = None
    switch_load: bool = False
    duration_s: float | None = None
    force: bool = False
    logview: str | None = None
    give_up_after_s: float | None = None
    fsync_interval_s: float = 0.5
    extra_meta: dict = field(default_factory=dict)
    #: Battery model of the pack on test (a Battery): the live time to cutoff is the model's.
    battery_model: object | None = None


@dataclass
class AcquireResult:
    """How a run ended and what it measured.

    ``load_switched_off`` is True when the source drove the load (relay or
    electronic load) and switched it off at the end, False when it drove the
    load but could not switch it off, None when it drove no load (the load,
    if any, is still on).
    """

    ended_by: str
    message: str
    exit_status: int
    out: Path
    summary: dict
    stats: dict
    limits: dict
    error: str | None = None
    load_switched_off: bool | None = None

    @property
    def load_state(self) -> str:
        """What happened to the load: ``"switched off"``, ``"not switched off"`` (the source
        drives it but could not switch it off) or ``"not driven"`` (no relay or load control)."""
        return {True: "switched off", False: "not switched off",
                None: "not driven"}[self.load_switched_off]

    def to_dict(self) -> dict:
        return {"ended_by": self.ended_by, "message": self.message,
                "exit_status": self.exit_status, "out": str(self.out), "summary": self.summary,
                "stats": self.stats, "limits": self.limits, "error": self.error,
                "load": self.load_state}


class Acquisition:
    """An opened source with its consumers, ready to :meth:`run`."""

    def __init__(self, settings: AcquireSettings, source, prefill, limits: SafetyLimits,
                 meta: dict, cells_inferred: bool):
        from ..io.logfile import LogWriter
        from .live import LiveDisplay

        self.settings = settings
        self.source = source
        self.limits = limits
        self.meta = meta
        self.cells_inferred = cells_inferred
        self.writer = LogWriter(settings.out, meta, settings.fsync_interval_s,
                                overwrite=settings.force)
        consumers = [self.writer]
        self.pipeline = Pipeline(
            source, [], prefill=prefill, duration_s=settings.duration_s,
            reconnect=ReconnectPolicy(give_up_after_s=settings.give_up_after_s))
        self.safety = SafetyMonitor(limits, self._on_trip)
        self.display = LiveDisplay(
            cells_series=limits.cells_series, cutoff_pack_V=limits.cutoff_pack_V,
            current_given_A=settings.current_A, stats=lambda: self.pipeline.stats,
            safety=self.safety, title=f"dischargelab acquire  {settings.port} -> {settings.out}",
            battery=settings.battery_model)
        consumers += [self.display, self.safety]
        if settings.logview:
            from .logview import LogViewWriter

            consumers.append(LogViewWriter(settings.logview))
        for consumer in consumers:
            self.pipeline.add(consumer)
        if cells_inferred:
            self.pipeline.emit("alarm", message=(
                f"cell count inferred from {prefill[0].voltage_V:.2f} V: {limits.cells_series} "
                f"cells; give --cells to be sure"))

    def _on_trip(self, kind: str, message: str, fields: dict) -> None:
        self.pipeline.request_stop(kind, message, kind=kind, **fields)

    # ------------------------------------------------------------------ running
    def run(self, *, view: str = "live", console=None, every_s: float = 10.0,
            plot: bool = False, on_tick=None) -> AcquireResult:
        """Run until the test ends; ``view`` is "live" (rich panel), "lines" or "none".

        Ctrl-C (SIGINT) and SIGTERM stop the test cleanly: load off, file closed.
        """
        from rich.console import Console

        console = console or Console(stderr=True)
        plotter = None
        if plot:
            from .live import LivePlot

            plotter = LivePlot(self.display)
        pipe = self.pipeline
        previous = _install_sigterm()
        pipe.start()
        try:
            while True:
                try:
                    self._watch(view, console, every_s, plotter, on_tick)
                    break
                except KeyboardInterrupt:
                    pipe.request_stop("user", "stopped by the user (Ctrl-C)", kind="user-stop")
        finally:
            _restore_sigterm(previous)
            pipe.wait(30)
            if plotter is not None:
                plotter.close()
        error = None
        try:
            pipe.close()
        except DischargelabError as exc:
            error = str(exc)
        if pipe.error is not None and error is None:
            error = f"{type(pipe.error).__name__}: {pipe.error}"
        ended = pipe.ended_by or "user"
        summary = self.display.summary()
        summary["rows_written"] = self.writer.rows_written
        return AcquireResult(ended, pipe.end_message, EXIT_STATUS.get(ended, 6),
                             self.settings.out, summary, pipe.stats, self.limits.to_dict(),
                             error, pipe.load_switched_off)

    def _watch(self, view, console, every_s, plotter, on_tick) -> None:
        pipe = self.pipeline
        if view == "live":
            from rich.live import Live

            with Live(self.display.render(), console=console, refresh_per_second=4,
                      transient=False) as live:
                while not pipe.wait(0.25):
                    live.update(self.display.render())
                    if plotter is not None:
                        plotter.update()
                    if on_tick is not None:
                        on_tick(self)
                live.update(self.display.render())
            return
        next_line = time.monotonic() + (every_s if view == "lines" else math.inf)
        while not pipe.wait(0.25):
            if plotter is not None:
                plotter.update()
            if on_tick is not None:
                on_tick(self)
            if time.monotonic() >= next_line:
                console.print(self.display.status_line(), markup=False, highlight=False)
                next_line += every_s


def _install_sigterm():
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        raise KeyboardInterrupt

    try:
        return signal.signal(signal.SIGTERM, handler)
    except (ValueError, OSError):
        return None


def _restore_sigterm(previous) -> None:
    if previous is not None:
        try:
            signal.signal(signal.SIGTERM, previous)
        except (ValueError, OSError):
            pass


def _first_samples(source, timeout_s: float) -> list:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        samples = source.read(0.2)
        if samples:
            return samples
    raise SourceDisconnected(f"no samples from {getattr(source, 'name', 'the source')} within "
                             f"{timeout_s:g} s of starting")


def prepare_acquisition(settings: AcquireSettings) -> Acquisition:
    """Open the source, settle cells and limits, create the log file (refusing to overwrite).

    Raises
    ------
    DataError
        Bad settings.
    OutputError
        ``out`` exists without ``force``, or is a folder.
    SourceDisconnected
        The instrument cannot be reached.
    """
    from .._version import __version__
    from .sources import open_source

    out = Path(settings.out)
    check_outputs([out], force=settings.force)
    chemistry = settings.chemistry.lower()
    provisional = None
    if settings.cells is not None:
        provisional = SafetyLimits.for_chemistry(
            chemistry, settings.cells, cutoff_cell_V=settings.cutoff_cell_V,
            max_temperature_C=settings.max_temperature_C,
            debounce_samples=settings.debounce_samples)
    source = open_source(
        settings.source, settings.port, rate_Hz=settings.rate_Hz,
        calibration=settings.calibration, current_sensor=settings.current_sensor,
        thermistor=settings.thermistor, baudrate=settings.baudrate, parity=settings.parity,
        switch_load=settings.switch_load, current_A=settings.current_A,
        cutoff_pack_V=None if provisional is None else provisional.cutoff_pack_V)
    try:
        info = dict(getattr(source, "info", {}) or {})
        first_wait = max(5.0, 3.0 / settings.rate_Hz * (1.0 / float(info.get("time_scale", 1))))
        prefill = _first_samples(source, first_wait)
        inferred = settings.cells is None
        cells = infer_cells(prefill[0].voltage_V, chemistry) if inferred else settings.cells
        limits = provisional or SafetyLimits.for_chemistry(
            chemistry, cells, cutoff_cell_V=settings.cutoff_cell_V,
            max_temperature_C=settings.max_temperature_C,
            debounce_samples=settings.debounce_samples)
        if prefill[0].voltage_V <= limits.cutoff_pack_V:
            raise DataError(f"the pack reads {prefill[0].voltage_V:.3f} V, at or below the cutoff "
                            f"{limits.cutoff_pack_V:.3f} V ({cells} x {limits.cutoff_cell_V:g} V); "
                            "charge it, or check --cells, --ke/--calibration and the wiring")
        meta = {
            "port": settings.port, "source_kind": settings.source,
            "rate_Hz": info.get("rate_Hz", settings.rate_Hz),
            "calibration": info.get("calibration"),
            "cells_series": cells, "cells_inferred": inferred, "chemistry": chemistry,
            "cutoff_cell_V": limits.cutoff_cell_V, "cutoff_pack_V": limits.cutoff_pack_V,
            "max_temperature_C": limits.max_temperature_C,
            "debounce_samples": limits.debounce_samples,
            "current_given_A": settings.current_A,
            "battery_model": getattr(settings.battery_model, "name", None),
            "firmware": info.get("firmware"),
            "source_info": info,
            "host": platform.node(), "dischargelab_version": __version__,
        }
        meta.update(settings.extra_meta)
        return Acquisition(settings, source, prefill, limits, meta, inferred)
    except BaseException:
        try:
            source.close()
        except Exception:
            pass
        raise
