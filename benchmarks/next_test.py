"""The next test, checked: the narrowing one more run was predicted to give, against a real
second fit.

For each cell, a one-rate fit (``dischargelab.fit``, ``auto``, ``bootstrap=30``) predicts a
faster run (``Battery.predict`` at its mean current, cutoff and ambient). Its
``next_test`` names one more run and the half-width of the 95 % interval after it. That run
is then really added: the cell's run at the named current is fitted together with the
first one (``auto``), and the same prediction's interval is measured again. Reported: the
half-width now, the predicted half-width after, the actual one, their ratio (goal: within a
factor 1.5 either way) and whether the new interval covers the measured time.

Cells: Samsung 30Q S001 (real, temperature logged), Enertech LCO (real, no temperature),
and PyBaMM virtual cells at 25 degC (``tests/data/virtual``).

Usage: python benchmarks/next_test.py [--cells samsung,...]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import accuracy  # noqa: E402
import dischargelab as dl  # noqa: E402
import one_rate_errors  # noqa: E402
from _machine import machine_line  # noqa: E402

#: (series title, fitted run, predicted run): the predicted run is 2-4x the fitted one.
CASES = [
    ("Samsung 30Q", "1C", "4C"),
    ("Samsung 30Q", "1C", "3C"),
    ("Enertech LCO", "0.5C", "2C"),
    ("virtual NMC 25degC", "0.5C", "2C"),
    ("virtual LCO-POUCH 25degC", "1C", "3C"),
    ("virtual NCA 25degC", "1C", "3C"),
    ("virtual NMC532 25degC", "1C", "3C"),
    ("virtual NMC-POUCH 25degC", "1C", "3C"),
    ("virtual LFP SPMe 2.5 V 25degC", "0.5C", "2C"),
]
GOAL_FACTOR = 1.5
BOOTSTRAP = 30


def half_width(out) -> float:
    lo, hi = out["interval95"]["time_to_cutoff_s"]
    return 100.0 * (hi - lo) / 2.0 / out["time_to_cutoff_s"]


def check(series, fitted_key, target_key):
    """One row: the advice of a one-rate fit and the interval of the real second fit."""
    fitted, target = series.runs[fitted_key], series.runs[target_key]
    load = dict(current=target.current_A, cutoff=target.cutoff_V, ambient=target.ambient_C)
    one = dl.fit(fitted.discharge, bootstrap=BOOTSTRAP, seed=0)
    out = one.battery.predict(**load).to_dict()
    advice = out.get("next_test")
    row = {"cell": series.title, "fitted": fitted_key, "target": target_key,
           "model": one.model, "now": half_width(out),
           "error_now": 100.0 * (out["time_to_cutoff_s"] / target.measured_s - 1.0)}
    if advice is None:
        return dict(row, advice=None)
    # the run the advice names: the cell's run nearest that current
    run_key = min(series.runs, key=lambda k: abs(series.runs[k].current_A
                                                 - advice["current_A"]))
    two = dl.fit([fitted.discharge, series.runs[run_key].discharge], bootstrap=BOOTSTRAP,
                 seed=0)
    after = two.battery.predict(**load).to_dict()
    lo, hi = after["interval95"]["time_to_cutoff_s"]
    return dict(row, advice=advice, run=run_key, model_after=two.model,
                predicted=advice["half_width_pct_after"], actual=half_width(after),
                covered=bool(lo <= target.measured_s <= hi),
                error_after=100.0 * (after["time_to_cutoff_s"] / target.measured_s - 1.0))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=accuracy.default_data_dir())
    parser.add_argument("--cells", default=None,
                        help="only cases whose cell contains one of these (comma list)")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    series = one_rate_errors.real_series(args.data) if \
        (args.data / "samsung30q_S001").is_dir() else []
    series = {s.title: s for s in series + one_rate_errors.virtual_series()}
    cases = [c for c in CASES if c[0] in series]
    if args.cells:
        wanted = [w.lower() for w in args.cells.split(",")]
        cases = [c for c in cases if any(w in c[0].lower() for w in wanted)]
    print("| cell | fitted on | predicted | model | error now | half-width now | next test "
          "| predicted half-width after | model after | actual half-width after | "
          "predicted / actual | error after | covered |")
    print("|---|---|---|---|---:|---:|---|---:|---|---:|---:|---:|---|")
    within = checked = 0
    for title, fitted_key, target_key in cases:
        r = check(series[title], fitted_key, target_key)
        head = (f"| {title} | {fitted_key} | {target_key} | {r['model']} | "
                f"{r['error_now']:+.2f} % | {r['now']:.2f} % | ")
        if r["advice"] is None:
            print(head + "none (would not narrow) | | | | | | |")
            continue
        ratio = r["predicted"] / r["actual"]
        checked += 1
        within += 1.0 / GOAL_FACTOR <= ratio <= GOAL_FACTOR
        print(head + f"{r['advice']['current_A']:.3g} A ({r['run']}) | {r['predicted']:.2f} % | "
              f"{r['model_after']} | {r['actual']:.2f} % | {ratio:.2f} | "
              f"{r['error_after']:+.2f} % | {'yes' if r['covered'] else 'no'} |")
    print(f"\nPredicted within a factor {GOAL_FACTOR:g} of the actual half-width: {within} of "
          f"{checked} cells checked (goal: at least 3) -> "
          f"{'met' if within >= 3 and checked else 'NOT met'}")
    print(f"\nRun time {time.perf_counter() - t0:.0f} s. Machine: {machine_line()}; load average "
          f"{os.getloadavg()[0]:.1f} (shared machine)")


if __name__ == "__main__":
    main()
