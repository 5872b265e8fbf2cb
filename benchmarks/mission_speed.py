"""Mission speed: endurance of the paper's Table 5 mission, with and without uncertainty.

Times (median over repeats, wall clock):

* ``run_mission``: the full result for the Table 5 mission (6 current phases, time
  series at 200 points per phase, max-cruise root finding, per-phase table);
* ``mission_summary``: the scalar outcomes only (what one parameter draw needs);
* ``run_mission(draws=300)``: the same plus 300 covariance draws evaluated at once.
  The preset has no covariance, so a diagonal one with a 2 % standard deviation on
  every parameter is attached (only the timing matters here);
* the fixed-wing and multirotor example missions (constant-power phases, ODE per
  phase) for comparison.

Target: Table 5 endurance including the max-cruise root finding under 50 ms.

Usage: python benchmarks/mission_speed.py [--repeats N]
"""

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line  # noqa: E402

from dischargelab.mission import load_mission, mission_summary, run_mission  # noqa: E402

TARGET_S = 0.050


def median_time(func, repeats: int) -> tuple[float, object]:
    func()  # warm up (imports, caches)
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = func()
        times.append(time.perf_counter() - start)
    return statistics.median(times), value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    repeats = parser.parse_args().repeats

    table5 = load_mission("paper-table5")
    sd = 0.02 * table5.battery.parameters.as_array()
    table5_cov = table5.with_battery(replace(table5.battery, covariance=np.diag(sd**2)))
    fixed_wing = load_mission("fixed-wing-survey")
    fixed_wing_cov = fixed_wing.with_battery(replace(fixed_wing.battery,
                                                     covariance=np.diag(sd**2)))
    hover = load_mission("multirotor-hover")

    cases = [
        ("Table 5: run_mission (max-cruise root finding)", lambda: run_mission(table5),
         repeats, True),
        ("Table 5: mission_summary (scalars only)", lambda: mission_summary(table5),
         repeats, False),
        ("Table 5: run_mission + 300 draws", lambda: run_mission(table5_cov, draws=300),
         repeats, False),
        ("fixed-wing survey: run_mission (7 power phases)", lambda: run_mission(fixed_wing),
         max(3, repeats // 5), False),
        ("fixed-wing survey: run_mission + 300 draws",
         lambda: run_mission(fixed_wing_cov, draws=300), max(3, repeats // 5), False),
        ("multirotor hover: run_mission (repeat until reserve)", lambda: run_mission(hover),
         max(3, repeats // 5), False),
    ]
    rows = []
    for label, func, n, targeted in cases:
        seconds, result = median_time(func, n)
        if hasattr(result, "endurance_s"):
            endurance = result.endurance_s
            unc = result.uncertainty or {}
            if unc.get("available"):
                e = unc["endurance_s"]
                detail = f"{endurance / 60:.2f} min [{e['low'] / 60:.2f}, {e['high'] / 60:.2f}]"
            else:
                detail = f"{endurance / 60:.2f} min"
        else:
            detail = f"{result['endurance_s'] / 60:.2f} min"
        verdict = ("PASS" if seconds < TARGET_S else "FAIL") if targeted else ""
        rows.append((label, n, seconds * 1000, detail, verdict))

    width = max(len(r[0]) for r in rows)
    print(f"{'case':<{width}}  {'repeats':>7}  {'median [ms]':>11}  {'endurance':<26}  target")
    for label, n, ms, detail, verdict in rows:
        print(f"{label:<{width}}  {n:>7}  {ms:>11.2f}  {detail:<26}  {verdict}")
    print(f"target: Table 5 endurance incl. root finding < {TARGET_S * 1000:.0f} ms")
    print(machine_line())


if __name__ == "__main__":
    main()
