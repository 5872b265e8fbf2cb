"""Fit speed: dischargelab's variable-projection fit vs plain scipy least_squares.

Both fit the same 3,600-sample curves in the same run, with the same free
parameters and bounds, from the same data-derived guess. The baseline is
``scipy.optimize.least_squares`` (trf, bounds) with a 2-point numeric Jacobian
on all six parameters, the straightforward implementation of the paper's eq. (8).

Usage: python benchmarks/fit_speed.py [--repeats N]
"""

import os

# Small matrices: BLAS threads only add jitter. Set before numpy loads; applies
# to both methods alike.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from _machine import machine_line  # noqa: E402
from synthetic import measurement_noise, synthetic_curve  # noqa: E402

from dischargelab.fit import DEFAULT_BOUNDS, fit_battery, guess_parameters  # noqa: E402
from dischargelab.io import read_discharge  # noqa: E402
from dischargelab.fit import Curve  # noqa: E402
from dischargelab.model import PARAMETER_NAMES, CellParameters, cell_voltage  # noqa: E402

BUNDLED = Path(__file__).resolve().parents[1] / "src" / "dischargelab" / "data" / "samsung30q"


def baseline_fit(curve: Curve):
    """Plain least_squares, numeric Jacobian, rest sample included as in our fit."""
    g = guess_parameters(curve)
    t_i, q = curve.current_A, curve.charge_Ah
    v = curve.voltage_V
    if curve.rest_voltage_V is not None:
        t_i, q, v = np.append(t_i, 0.0), np.append(q, 0.0), np.append(v, curve.rest_voltage_V)
    lo = [DEFAULT_BOUNDS[n][0] for n in PARAMETER_NAMES]
    hi = [DEFAULT_BOUNDS[n][1] for n in PARAMETER_NAMES]
    lo[5] = q.max() * (1 + 1e-4)
    x0 = np.clip([g[n] for n in PARAMETER_NAMES], np.array(lo) + 1e-9, np.array(hi) - 1e-9)

    def resid(x):
        return cell_voltage(CellParameters.from_array(x), t_i, q) - v

    sol = least_squares(resid, x0, bounds=(lo, hi), method="trf", x_scale="jac")
    r = resid(sol.x)[: curve.time_s.size]
    return float(np.sqrt(np.mean(r ** 2)))


def median_time(func, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = func()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1000, value


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args(argv)
    spec = {"time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4}
    data, meta = read_discharge(BUNDLED / "Q30_S001_1C.csv", columns=spec)
    cases = [
        ("synthetic 3 A, 3 mV noise + 10-bit ADC", synthetic_curve(3.0, dt_s=1.0, seed=0)),
        ("Samsung 30Q 1C (measured)", Curve.from_frame(data, meta, name="1C")),
    ]
    rows = []
    for name, curve in cases:
        fit_battery(curve)  # warm-up (imports, caches)
        ours_ms, res = median_time(lambda: fit_battery(curve), args.repeats)
        base_ms, base_rmse = median_time(lambda: baseline_fit(curve), max(3, args.repeats // 3))
        rows.append((name, curve.time_s.size, ours_ms, base_ms, base_ms / ours_ms,
                     res.rmse_V * 1000, base_rmse * 1000))
    noise = measurement_noise() * 1000
    print("| curve | samples | dischargelab median [ms] | numeric-Jacobian least_squares "
          "median [ms] | speed-up | RMSE ours [mV] | RMSE baseline [mV] |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]:.1f} | {r[3]:.1f} | {r[4]:.1f}x | {r[5]:.2f} | "
              f"{r[6]:.2f} |")
    print(f"\nTargets: median < 20 ms and >= 5x faster than the baseline; synthetic RMSE "
          f"within 1.5x the measurement noise ({noise:.2f} mV -> limit {1.5 * noise:.2f} mV).")
    print(f"Machine: {machine_line()}")


if __name__ == "__main__":
    main()
