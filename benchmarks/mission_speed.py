"""Mission speed: the bundled missions flown through the one engine, with and without intervals.

Times (median over repeats, wall clock):

* ``run_mission``: the full result (time series at the default engine steps per
  phase, longest-stretch search, per-phase table) of the paper's Table 5 mission
  (6 current phases) and of the fixed-wing survey (7 constant-power phases, a
  stretchable survey phase);
* ``mission_summary``: the scalar outcomes only;
* ``run_mission(draws=N)``: the same plus N parameter draws flown at once (the
  longest stretch searched per draw) and the model error. The presets carry no
  covariance, so a diagonal one with a 2 % standard deviation on every parameter
  is attached (only the timing matters here);
* the multirotor repeat-until-reserve mission.

Targets: a single flight of Table 5 (search included) under 50 ms; a 100-draw
interval under 2 s.

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

from _machine import machine_line
from dischargelab.mission import load_mission, mission_summary, run_mission

SINGLE_TARGET_S = 0.050
DRAWS_TARGET_S = 2.0


def median_time(func, repeats: int) -> tuple[float, object]:
    func()  # warm up (imports, caches)
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = func()
        times.append(time.perf_counter() - start)
    return statistics.median(times), value


def with_covariance(mission, relative_sd=0.02):
    """The mission on its battery with a diagonal covariance (relative sd per parameter)."""
    sd = relative_sd * mission.battery.parameters.as_array()
    return mission.with_battery(replace(mission.battery, covariance=np.diag(sd**2)))


def describe(result) -> str:
    if not hasattr(result, "endurance_s"):
        return f"{result['endurance_s'] / 60:.2f} min"
    text = f"{result.endurance_s / 60:.2f} min"
    unc = result.uncertainty or {}
    if unc.get("available"):
        e = unc["endurance_s"]
        text += f" [{e['low'] / 60:.2f}, {e['high'] / 60:.2f}]"
    return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    repeats = parser.parse_args().repeats
    few = max(1, repeats // 5)

    table5 = load_mission("paper-table5")
    survey = load_mission("fixed-wing-survey")
    hover = load_mission("multirotor-hover")
    table5_cov, survey_cov = with_covariance(table5), with_covariance(survey)

    cases = [
        ("Table 5: run_mission (single flight + stretch search)", lambda: run_mission(table5),
         repeats, SINGLE_TARGET_S),
        ("Table 5: mission_summary (scalars only)", lambda: mission_summary(table5),
         repeats, None),
        ("Table 5: run_mission + 300 draws", lambda: run_mission(table5_cov, draws=300),
         few, DRAWS_TARGET_S),
        ("fixed-wing survey: run_mission (single flight + stretch search)",
         lambda: run_mission(survey), few, None),
        ("fixed-wing survey: run_mission + 100 draws",
         lambda: run_mission(survey_cov, draws=100), few, DRAWS_TARGET_S),
        ("fixed-wing survey: run_mission + 300 draws",
         lambda: run_mission(survey_cov, draws=300), few, None),
        ("multirotor hover: run_mission (repeat until reserve)", lambda: run_mission(hover),
         few, None),
    ]
    rows = []
    for label, func, n, target in cases:
        seconds, result = median_time(func, n)
        verdict = "" if target is None else \
            f"{'PASS' if seconds < target else 'FAIL'} (< {target * 1000:g} ms)"
        rows.append((label, n, seconds * 1000, describe(result), verdict))

    width = max(len(r[0]) for r in rows)
    print(f"{'case':<{width}}  {'repeats':>7}  {'median [ms]':>11}  {'endurance [95 %]':<26}  "
          f"target")
    for label, n, ms, detail, verdict in rows:
        print(f"{label:<{width}}  {n:>7}  {ms:>11.1f}  {detail:<26}  {verdict}")
    print("intervals include parameter draws and the model error (prior, growing with the "
          "extrapolation ratio)")
    print(machine_line())


if __name__ == "__main__":
    main()
