"""The live test bench behind the page: attach a running acquisition, or start demo runs.

Two ways to feed the live page:

* :meth:`LiveBench.attach`: an :class:`~dischargelab.acquire.acquisition.Acquisition`
  prepared by ``dischargelab acquire ... --serve``; it was started from the command line, the
  page can watch it and stop it (the same clean stop as Ctrl-C).
* :class:`DemoBench`: ``dischargelab serve --demo``; the page's Start runs a virtual logger
  (:class:`~dischargelab.acquire.virtual_device.VirtualDevice` on a pseudo-terminal, real
  pyserial) through the same acquisition, with the cutoff settings the command line takes,
  checked by the same :class:`~dischargelab.acquire.safety.SafetyLimits`.
"""

from __future__ import annotations

import math
import threading
from datetime import datetime
from pathlib import Path

from ..errors import DataError, DischargelabError
from .live import LiveHub


class BenchError(DischargelabError):
    """A start or stop request that cannot be done now (already running, watch-only, ...)."""


class LiveBench:
    """Watches one acquisition at a time and publishes it through a :class:`LiveHub`."""

    can_start = False

    def __init__(self, hub: LiveHub | None = None):
        self.hub = hub or LiveHub()
        self.acquisition = None
        self.result = None
        self._lock = threading.Lock()

    @property
    def running(self) -> bool:
        return self.acquisition is not None and self.result is None

    def attach(self, acquisition, info: dict | None = None) -> None:
        """Publish ``acquisition`` (before its pipeline starts)."""
        limits = acquisition.limits
        settings = acquisition.settings
        self.acquisition = acquisition
        self.result = None
        meta = {"out": Path(settings.out).name, "port": settings.port, "source": settings.source,
                "limits": limits.to_dict(), "rate_Hz": settings.rate_Hz,
                "current_given_A": settings.current_A, "can_start": self.can_start}
        meta.update(info or {})
        if settings.battery_model is not None:
            meta.setdefault("battery_model", settings.battery_model.name)
        self.hub.begin(meta, cells_series=limits.cells_series,
                       cutoff_pack_V=limits.cutoff_pack_V, current_given_A=settings.current_A,
                       stats=lambda: acquisition.pipeline.stats, safety=acquisition.safety,
                       battery=settings.battery_model)
        acquisition.pipeline.add(self.hub)

    def finished(self, result) -> None:
        """Record the end of the attached run (``AcquireResult``)."""
        self.result = result
        self.hub.finish(result.ended_by, result.message)

    def stop(self) -> dict:
        """Stop the running test: load off, file closed (as Ctrl-C on the command line)."""
        acq = self.acquisition
        if acq is None or not self.running:
            raise BenchError("no test is running")
        acq.pipeline.request_stop("user", "stopped from the web page", kind="user-stop")
        return {"stopping": True}

    def start(self, settings: dict) -> dict:
        raise BenchError("this server watches a test started from the command line; start "
                         "tests there (or run `dischargelab serve --demo`)")

    def state(self) -> dict:
        out = self.hub.status()
        out["mode"] = "demo" if self.can_start else "watch"
        out["can_start"] = self.can_start and not self.running
        out["can_stop"] = self.running
        return out


#: Settings the demo's Start form takes, with the command line's ranges:
#: name -> (type, low, high).
DEMO_FIELDS = {
    "battery": (str, None, None),
    "cells": (int, 1, 24),
    "chemistry": (str, None, None),
    "cutoff_cell_V": (float, 0.5, 4.5),
    "max_temperature_C": (float, -40.0, 150.0),
    "debounce": (int, 1, 1000),
    "rate_Hz": (float, 0.0003, 50.0),
    "c_rate": (float, 0.05, 20.0),
    "speed": (float, 1.0, 10_000.0),
    "duration_s": (float, 0.0, 1e7),
}
DEMO_DEFAULTS = {"battery": "zippy-1100-2s", "chemistry": "lipo", "max_temperature_C": 60.0,
                 "debounce": 3, "rate_Hz": 1.0, "c_rate": 1.0, "speed": 60.0}


def parse_demo_settings(raw: dict) -> dict:
    """Check a Start request (JSON object) against :data:`DEMO_FIELDS`; raises DataError."""
    if not isinstance(raw, dict):
        raise DataError("start settings must be a JSON object")
    unknown = sorted(set(raw) - set(DEMO_FIELDS))
    if unknown:
        raise DataError(f"unknown setting {unknown[0]!r}; known: {', '.join(DEMO_FIELDS)}")
    out = dict(DEMO_DEFAULTS)
    for name, value in raw.items():
        if value is None or value == "":
            continue                                   # the default (or none)
        kind, low, high = DEMO_FIELDS[name]
        try:
            if kind is str:
                if not isinstance(value, str):
                    raise ValueError
                parsed = value
            elif kind is int:
                parsed = int(value)
                if parsed != float(value):
                    raise ValueError
            else:
                parsed = float(value)
                if not math.isfinite(parsed):
                    raise ValueError
        except (TypeError, ValueError, OverflowError):   # int(inf) overflows
            raise DataError(f"{name} must be {'a whole number' if kind is int else 'a number'}"
                            f", got {value!r}") from None
        if low is not None and not low <= parsed <= high:
            raise DataError(f"{name} must be between {low:g} and {high:g}, got {parsed:g}")
        out[name] = parsed
    if out.get("duration_s") == 0:
        out.pop("duration_s")
    return out


class DemoBench(LiveBench):
    """Starts virtual-logger runs from the page; logs go to ``run_dir`` under names it makes.

    Parameters
    ----------
    run_dir : path
        Folder of the runs' log files (``run-YYYYmmdd-HHMMSS.csv``); created when needed.
        The page never names a path.
    """

    can_start = True

    def __init__(self, run_dir, hub: LiveHub | None = None):
        super().__init__(hub)
        self.run_dir = Path(run_dir)
        self.device = None
        self._thread: threading.Thread | None = None

    def start(self, settings: dict) -> dict:
        """Open a virtual logger and start a test with ``settings`` (:data:`DEMO_FIELDS`)."""
        from ..acquire.acquisition import AcquireSettings, prepare_acquisition
        from ..acquire.calibration import Calibration
        from ..acquire.safety import SafetyLimits
        from ..acquire.sensors import CURRENT_SENSORS, Thermistor
        from ..acquire.virtual_device import VirtualDevice
        from ..model import PRESETS, load_battery

        opts = parse_demo_settings(settings)
        with self._lock:
            if self.running:
                raise BenchError("a test is already running; stop it first")
            if opts["battery"] not in PRESETS:   # a preset, never a file on the server
                raise DataError(f"battery must be one of the presets: {', '.join(PRESETS)}; "
                                f"got {opts['battery']!r}")
            bat = load_battery(opts["battery"])
            cells = int(opts.get("cells") or bat.cells_series)
            SafetyLimits.for_chemistry(opts["chemistry"], cells,    # checks them as acquire does
                                       cutoff_cell_V=opts.get("cutoff_cell_V"),
                                       max_temperature_C=opts["max_temperature_C"],
                                       debounce_samples=opts["debounce"])
            current = opts["c_rate"] * bat.capacity_Ah
            out = self._new_log_path()
            gain = 4.38
            device = VirtualDevice(bat, cells_series=cells, current_A=current,
                                   rate_Hz=opts["rate_Hz"], speed=opts["speed"],
                                   divider_gain=gain, seed=int(datetime.now().timestamp()))
            port = device.start()
            try:
                acq = prepare_acquisition(AcquireSettings(
                    port=port, out=out, cells=cells, chemistry=opts["chemistry"],
                    cutoff_cell_V=opts.get("cutoff_cell_V"),
                    max_temperature_C=opts["max_temperature_C"],
                    debounce_samples=opts["debounce"], rate_Hz=opts["rate_Hz"],
                    calibration=Calibration(gain=gain, divider="virtual"),
                    current_sensor=CURRENT_SENSORS["acs712-20a"], thermistor=Thermistor(),
                    duration_s=opts.get("duration_s"), battery_model=device.battery,
                    extra_meta={"virtual_device": device.truth(), "demo": True}))
            except BaseException:
                device.stop()
                raise
            self.device = device
            self.attach(acq, {"battery": bat.name, "demo": True, "speed": opts["speed"],
                              "settings": opts})
            self._thread = threading.Thread(target=self._run, args=(acq, device),
                                            name="dischargelab-web-bench", daemon=True)
            self._thread.start()
        return {"started": True, "out": out.name, "settings": opts}

    def _new_log_path(self) -> Path:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        for k in range(1000):
            path = self.run_dir / (f"run-{stamp}.csv" if k == 0 else f"run-{stamp}-{k}.csv")
            if not path.exists():
                return path
        raise BenchError(f"too many runs started this second in {self.run_dir}")

    def _run(self, acq, device) -> None:
        try:
            result = acq.run(view="none")
        except Exception as exc:  # the thread's end: the page learns it and can Start again
            self.acquisition = None
            self.hub.finish("error", f"the test stopped on an error: {exc}")
            raise
        finally:
            device.stop()
        self.finished(result)

    def shutdown(self, timeout_s: float = 10.0) -> None:
        """Stop a running demo test and wait for it (server shutdown)."""
        if self.running:
            self.acquisition.pipeline.request_stop("user", "server stopped", kind="user-stop")
        if self._thread is not None:
            self._thread.join(timeout_s)
