"""Residuals of two-rate fits: where a model fitted on 1C + 3C misses 2C, and why.

For each ``cell/family`` pair (PyBaMM virtual cells at 25 degC, ``tests/data/virtual``),
the family is fitted (``dischargelab.fit``, no bootstrap) on the 1C and 3C runs, and the
1C, 2C (held out) and 3C runs are simulated from rest at their mean current, cutoff and
ambient (``dischargelab.predict.predict``, no interval). Printed: the time-to-cutoff error
of each run and the end temperature measured and simulated. ``--plot`` draws, per pair,
the voltage against the charge (measured and model), the model minus the measured
voltage, and the cell temperature (measured and model).

Usage: python benchmarks/two_rate_residuals.py [--cases lco-pouch/ecm,nmc/shepherd-thermal]
       [--plot two-rate.png]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import dischargelab as dl  # noqa: E402
from _machine import machine_line  # noqa: E402
from dischargelab.cell import charge_from_current  # noqa: E402
from dischargelab.predict import predict  # noqa: E402
from dischargelab.validate import measured_time_to_cutoff  # noqa: E402

VIRTUAL = HERE.parent / "tests" / "data" / "virtual"
RATES = ((1.0, "fitted", "tab:blue"), (2.0, "held out", "tab:red"), (3.0, "fitted", "tab:green"))
DEFAULT_CASES = "lco-pouch/ecm,lfp-a123/ecm,nmc/shepherd-thermal,lco-pouch/shepherd-thermal"


def runs_of(cell: str) -> dict:
    """The 25 degC runs of a virtual cell at 1C, 2C and 3C: ``{rate: (Discharge, cutoff)}``."""
    index = json.loads((VIRTUAL / "index.json").read_text(encoding="utf-8"))
    out = {}
    for e in index["files"]:
        if e["file"].startswith(cell + "_") and abs(e["ambient_C"] - 25.0) < 0.1 \
                and e.get("rate_C") in (1.0, 2.0, 3.0):
            out[e["rate_C"]] = (dl.read(VIRTUAL / e["file"]), float(e["cutoff_V"]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=DEFAULT_CASES, help="cell/family pairs")
    parser.add_argument("--plot", type=Path, help="write the residual figure here (PNG)")
    args = parser.parse_args()
    cases = [c.split("/") for c in args.cases.split(",")]
    axs = None
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(3, len(cases), figsize=(5.0 * len(cases), 10.5), squeeze=False)
    print("| cell | family fitted on 1C + 3C | run | time-to-cutoff error | end temperature "
          "measured | simulated |")
    print("|---|---|---|---:|---:|---:|")
    for j, (cell, family) in enumerate(cases):
        runs = runs_of(cell)
        res = dl.fit([runs[1.0][0], runs[3.0][0]], model=family, bootstrap=0, seed=0)
        for rate, role, colour in RATES:
            d, cutoff = runs[rate]
            sim = predict(res.battery, current=float(d.mean_current_A), cutoff=cutoff,
                          ambient=25.0, interval=False).simulation
            measured = measured_time_to_cutoff(d.time_s, d.voltage_V, cutoff)
            err = 100.0 * (sim.time_to_cutoff_s - measured) / measured
            t_sim = None if sim.temperature_C is None else float(np.asarray(sim.temperature_C)[-1])
            t_meas = None if d.temperature_C is None else float(d.temperature_C[-1])
            print(f"| {cell} | {res.model} | {rate:g}C ({role}) | {err:+.2f} % | "
                  f"{'n/a' if t_meas is None else f'{t_meas:.1f} degC'} | "
                  f"{'n/a' if t_sim is None else f'{t_sim:.1f} degC'} |")
            if axs is None:
                continue
            q = charge_from_current(d.time_s, d.current_A)
            sq, sv = np.asarray(sim.charge_Ah), np.asarray(sim.voltage_V)
            axs[0, j].plot(q, d.voltage_V, color=colour, lw=1.5,
                           label=f"{rate:g}C {role}: {err:+.2f} %")
            axs[0, j].plot(sq, sv, color=colour, ls="--", lw=1.0)
            axs[1, j].plot(q, 1000.0 * (np.interp(q, sq, sv, right=np.nan) - d.voltage_V),
                           color=colour, label=f"{rate:g}C")
            if t_meas is not None:
                axs[2, j].plot(q, d.temperature_C, color=colour, lw=1.5)
            if t_sim is not None:
                axs[2, j].plot(sq, sim.temperature_C, color=colour, ls="--", lw=1.0)
        if axs is not None:
            axs[0, j].set_title(f"{cell}: {res.model} on 1C + 3C (dashed: model)", fontsize=10)
            axs[0, j].set_ylabel("cell voltage [V]")
            axs[0, j].legend(fontsize=8)
            axs[1, j].axhline(0.0, color="0.5", lw=0.8)
            axs[1, j].set_ylim(-200, 200)
            axs[1, j].set_ylabel("model - measured [mV]")
            axs[2, j].set_ylabel("cell temperature [degC] (dashed: model)")
            axs[2, j].set_xlabel("charge [Ah]")
    print()
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.1f} (shared machine)")
    if axs is not None:
        fig.tight_layout()
        fig.savefig(args.plot, dpi=80)
        print(f"figure: {args.plot}")


if __name__ == "__main__":
    main()
