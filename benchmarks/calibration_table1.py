"""Calibration on the paper's Table 1: Ke, linear range and resolution for both dividers.

Target: the 3.3 kOhm divider gives Ke = 4.38 +/- 0.01 (paper 3.3); the 2.7 kOhm
divider departs from linear near 15 V.

Usage: python benchmarks/calibration_table1.py
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line
from dischargelab.acquire.calibration import fit_calibration, read_points_csv

TABLE1 = Path(__file__).resolve().parents[1] / "tests" / "data" / "paper_table1.csv"


def main(argv=None):
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    print("| divider | points | Ke | std. error | offset | non-linear points | linear up to "
          "[V] | resolution [mV] |")
    print("|---|---:|---:|---:|---|---|---:|---:|")
    results = {}
    for divider in ("3.3k", "2.7k"):
        real, measured = read_points_csv(TABLE1, divider=divider)
        fit = fit_calibration(real, measured, divider=divider)
        cal = fit.calibration
        bad = [f"{p.real_V:g} V" for p in fit.points if p.status != "linear"]
        results[divider] = cal.gain
        print(f"| {divider} | {len(real)} | {cal.gain:.4f} | {fit.gain_stderr:.4f} | "
              f"{cal.offset_V:+.3f} V | {', '.join(bad) or 'none'} | "
              f"{fit.linear_up_to_V:.2f} | {cal.resolution_V * 1000:.2f} |")
    ke = results["3.3k"]
    print(f"\nTarget: 3.3 kOhm Ke = 4.38 +/- 0.01 -> {ke:.4f}: "
          f"{'met' if abs(ke - 4.38) <= 0.01 else 'NOT met'}")
    print(f"Machine: {machine_line()}")


if __name__ == "__main__":
    main()
