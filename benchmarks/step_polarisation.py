"""The polarisation a load step builds, against its current: linear, or Butler-Volmer?

Every run with a rest sample before its load step (the real Samsung 30Q S001 and Enertech
LCO pouch, and the PyBaMM virtual cells at 25 degC, ``tests/data/virtual``) is read as
``shepherd-dynamic`` reads a one-rate file
(:func:`dischargelab.models.dynamic.load_step`): the apparent resistance over the first
minutes after the step, ``R + r_p (1 - exp(-t / 30 s)) + s t``. The overpotential the step
built, ``eta = r_p i``, is then compared across the rates of one cell with the
charge-transfer law, ``eta = b asinh(Rp i / b)``, ``b = R_g T / (alpha F)``
(Bard and Faulkner, Electrochemical Methods, 2nd ed., eq. 3.4.11): the transfer coefficient
``alpha`` that fits the cell's rates best (0 is linear), and the run-to-run RMS of the
overpotential with ``alpha`` = 0 (linear), 0.5 (a symmetric reaction) and the best.

Usage: python benchmarks/step_polarisation.py [--cells samsung,...]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import accuracy  # noqa: E402
import one_rate_errors  # noqa: E402
from _machine import machine_line  # noqa: E402
from dischargelab.fit.problem import _stack  # noqa: E402
from dischargelab.models.base import ZERO_CELSIUS_K  # noqa: E402
from dischargelab.models.dynamic import load_step  # noqa: E402
from dischargelab.models.thermal import BETA_PRIOR_K  # noqa: E402

ALPHAS = np.round(np.arange(0.0, 2.001, 0.05), 2)

#: Faraday constant over the gas constant [K/V].
F_OVER_R_K_PER_V = 96485.33212 / 8.314462618


def butler_volmer(x_V, alpha, temperature_C):
    """``b asinh(x / b)`` [V], ``b = R_g T / (alpha F)``; ``x`` itself at ``alpha`` = 0."""
    x = np.asarray(x_V, dtype=float)
    if alpha == 0:
        return x
    b = (np.asarray(temperature_C, dtype=float) + ZERO_CELSIUS_K) / (alpha * F_OVER_R_K_PER_V)
    return b * np.arcsinh(x / b)


def step_readings(series):
    """(current [A], R [ohm], r_p [ohm], temperature [degC]) of every run with a step."""
    out = []
    for label, run in series.runs.items():
        stack = _stack([run.discharge.to_curve()], 1, 1, True, "equal")
        step = load_step(stack, BETA_PRIOR_K)
        if step is None:
            continue
        out.append((label, run.current_A, step[0], step[1], run.ambient_C))
    return out


def fit_law(currents, eta, temperature, alpha):
    """Best Rp [ohm] and RMS [V] of ``eta = b asinh(Rp i / b)`` at ``alpha``."""
    best = (np.inf, 0.0)
    for rp in np.geomspace(1e-4, 1.0, 2000):
        model = butler_volmer(rp * currents, alpha, temperature)
        cost = float(np.sqrt(np.mean((model - eta) ** 2)))
        best = min(best, (cost, rp))
    return best[1], best[0]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=accuracy.default_data_dir())
    parser.add_argument("--cells", default=None)
    args = parser.parse_args(argv)
    series = one_rate_errors.real_series(args.data) if (
        args.data / "samsung30q_S001").is_dir() else []
    series += one_rate_errors.virtual_series()
    if args.cells:
        wanted = [w.lower() for w in args.cells.split(",")]
        series = [s for s in series if any(w in s.title.lower() for w in wanted)]
    print("| cell | steps: rate R + r_p [mOhm] | best alpha | RMS of eta [mV]: linear | "
          "alpha 0.5 | best |")
    print("|---|---|---:|---:|---:|---:|")
    for s in series:
        rows = step_readings(s)
        if len(rows) < 2:
            continue
        i = np.array([r[1] for r in rows])
        eta = np.array([r[3] * r[1] for r in rows])
        temp = np.array([r[4] for r in rows])
        fits = {a: fit_law(i, eta, temp, a) for a in ALPHAS}
        best = min(fits, key=lambda a: fits[a][1])
        steps = ", ".join(f"{r[0]} {1000 * r[2]:.0f} + {1000 * r[3]:.0f}" for r in rows)
        print(f"| {s.title} | {steps} | {best:.2f} | {1000 * fits[0.0][1]:.2f} | "
              f"{1000 * fits[0.5][1]:.2f} | {1000 * fits[best][1]:.2f} |")
    print(f"\nMachine: {machine_line()}; load average {os.getloadavg()[0]:.1f} (shared machine)")


if __name__ == "__main__":
    main()
