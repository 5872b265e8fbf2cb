"""``dischargelab demo-acquire``: a whole simulated test in about a minute.

A virtual logger (:class:`~dischargelab.acquire.virtual_device.VirtualDevice`)
discharges a preset pack at 1C with time compression; the real acquisition
path (pyserial over a pty, pipeline, log file, safety cutoff, live view) logs
it until the cutoff trips; then the logged curve is fitted
(:func:`dischargelab.fit.fit_battery`) and the fitted coefficients are set
beside the true ones that drove the device.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..formatting import duration
from ..model import CUTOFF_CELL_VOLTAGE_V, PARAMETER_NAMES, load_battery

#: Battery used by default: the paper's Zippy 1100 mAh 2S LiPo (Table 2); its exponential zone
#: (B = 2.88 /Ah) is well inside one 1C curve, so every coefficient but R is identifiable.
DEMO_BATTERY = "zippy-1100-2s"


#: Files :func:`run_acquire_demo` writes into its folder.
ACQUIRE_DEMO_OUTPUTS = ("demo-acquire.csv", "device-record.csv", "demo-acquire-fit.png")


def check_acquire_demo(out_dir, force: bool = False) -> None:
    """Extras and output files of :func:`run_acquire_demo`, checked before any work.

    Raises
    ------
    MissingExtraError
        pyserial (extra ``acquire``) or matplotlib (extra ``plot``) is missing.
    OutputError
        A demo file exists and ``force`` is false.
    """
    from ..atomic import check_outputs
    from ..errors import require

    require("serial", "acquire")
    require("matplotlib", "plot")
    check_outputs([Path(out_dir) / name for name in ACQUIRE_DEMO_OUTPUTS], force=force)


def run_acquire_demo(out_dir, *, battery=DEMO_BATTERY, wall_seconds: float = 45.0,
                     rate_Hz: float = 1.0, noise_mV: float = 2.0, divider_gain: float = 4.38,
                     seed: int = 1, view: str = "live", console=None,
                     force: bool = False) -> dict:
    """Simulated test -> log file -> fit; returns a summary dict (also printed by the CLI).

    Parameters
    ----------
    out_dir : path
        Receives ``demo-acquire.csv`` (the log), ``device-record.csv`` (what the
        device sent) and ``demo-acquire-fit.png``.
    battery : str or Battery
        Preset or battery file driving the virtual device.
    wall_seconds : float
        Target wall-clock length of the discharge [s]; sets the time compression.
    view : {"live", "lines", "none"}
    force : bool
        Replace the demo's files if they exist (see :func:`check_acquire_demo`).
    """
    from ..fit import Curve, fit_battery
    from ..io.logfile import read_log
    from ..simulate import simulate_current
    from .acquisition import AcquireSettings, prepare_acquisition
    from .calibration import Calibration
    from .virtual_device import VirtualDevice

    out_dir = Path(out_dir)
    check_acquire_demo(out_dir, force)
    out_dir.mkdir(parents=True, exist_ok=True)
    bat = load_battery(battery)
    chemistry = bat.chemistry or "lipo"
    cutoff_cell = CUTOFF_CELL_VOLTAGE_V[chemistry]
    current = bat.capacity_Ah                           # 1C
    expected = simulate_current(bat, current, cutoff_cell_V=cutoff_cell)
    speed = max(1.0, expected.time_to_cutoff_s / wall_seconds)
    log_path = out_dir / "demo-acquire.csv"
    device = VirtualDevice(bat, current_A=current, speed=speed, divider_gain=divider_gain,
                           noise_mV=noise_mV, seed=seed, record=out_dir / "device-record.csv")
    port = device.start()
    try:
        settings = AcquireSettings(
            port=port, out=log_path, cells=bat.cells_series, chemistry=chemistry,
            rate_Hz=rate_Hz, calibration=Calibration(gain=divider_gain, divider="virtual"),
            current_A=current, force=True,
            extra_meta={"virtual_device": device.truth(), "demo": True})
        acquisition = prepare_acquisition(settings)
        if console is not None and view != "none":
            console.print(f"virtual logger on {port}: {bat.name}, {current:g} A (1C), "
                          f"time x{speed:.0f}; expected cutoff after "
                          f"{duration(expected.time_to_cutoff_s)} test time", markup=False)
        result = acquisition.run(view=view, console=console)
    finally:
        device.stop()
    data, meta = read_log(log_path)
    curve = Curve.from_frame(data, meta, name=f"virtual {bat.name} 1C")
    fit = fit_battery([curve], cells_series=bat.cells_series)
    plot_path = out_dir / "demo-acquire-fit.png"
    _save_fit_plot(fit, plot_path)
    true = bat.parameters.as_dict()
    fitted = fit.parameters.as_dict()
    rows = []
    for name in PARAMETER_NAMES:
        err = fit.stderr.get(name)
        rows.append({"parameter": name, "true": true[name], "fitted": fitted[name],
                     "stderr": None if err is None or not math.isfinite(err) else err,
                     "fixed": name in fit.fixed})
    e0r_true = true["E0_V"] - true["R_ohm"] * current / bat.strings_parallel
    e0r_fit = fitted["E0_V"] - fitted["R_ohm"] * current / bat.strings_parallel
    return {
        "battery": bat.name, "current_A": current, "speed": speed,
        "expected_time_to_cutoff_s": expected.time_to_cutoff_s,
        "logged_time_to_cutoff_s": result.summary.get("duration_s"),
        "ended_by": result.ended_by, "message": result.message,
        "exit_status": result.exit_status, "log": str(log_path),
        "device_record": str(out_dir / "device-record.csv"), "plot": str(plot_path),
        "samples": result.summary.get("samples"), "stats": result.stats,
        "device_counts": dict(device.counts),
        "parameters": rows, "E0_minus_Ri_true_V": e0r_true, "E0_minus_Ri_fitted_V": e0r_fit,
        "rmse_V": fit.rmse_V, "warnings": list(fit.warnings), "fit_report": fit.report(),
    }


def _save_fit_plot(fit, path: Path) -> None:
    from ..plot import save

    save(fit.plot(), path, dpi=110)      # measured vs fitted, residual panel below
