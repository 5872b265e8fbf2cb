"""Is an aged cell's open-circuit voltage the fresh one re-windowed? The CMU eVTOL C/5 tests.

The logbook reads an aged cell's rests through the curve of its first slow discharge; the
aged curve against its own state of charge drifts from it (``docs/logbook.md``). One idea:
the aged curve is the fresh one over a narrower window, ``V_aged(s) = V_fresh(a + b s)``
(loss of lithium inventory moves the electrodes' windows, Birkl et al. 2017; Dubarry et al.
2012), its top ``a + b`` from the fall of the full rest voltage (what a log of missions and
charges shows) and its bottom ``a`` from a prior relation. This script checks it on the
capacity tests of ``../shared/data/cmu_evtol`` (which the logbook's benchmark cuts out of
the logs, so the estimator never sees them):

1. ``a`` and ``b`` fitted to each aged test (least squares over 5-95 % of its charge): the
   window that fits best and what is left (rms).
2. A rest at 30-45 % of the aged cell's own charge read through: the fresh curve; the
   re-windowed one with its top from the full rest voltage's fall and ``a = 0`` (the
   window shrinks from the top) or ``a = fade`` (lithium inventory lost, the negative
   ending the discharge); the error of a capacity from full down to that reading, and the
   bottom ``a`` (as a share of the fade) that would read it right.

Both curves are the loaded C/5 voltage (0.6 A), as the logbook's learned curve is (the
same drop added back to both, the first test's).

Usage: python benchmarks/cmu_rewindow.py
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import brentq, least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line, shared_data
from health_from_use import find_tests

CMU = shared_data() / "cmu_evtol"

#: The states of charge a mission's rest lands at [-].
MID = (0.30, 0.45)


def tests_of(path: Path) -> list[tuple[np.ndarray, np.ndarray, float, float]]:
    """Each C/5 test of a whole-life log: (its own state of charge, loaded voltage [V], the
    rest voltage before it [V], its capacity [Ah])."""
    frame = pd.read_csv(path)
    t, v, i = (frame[c].to_numpy(float) for c in ("time_s", "voltage_V", "current_A"))
    out = []
    for test in find_tests(frame):
        a, b = test["start"], test["stop"]
        q = np.concatenate(([0.0], np.cumsum(0.5 * (i[a + 1:b] + i[a:b - 1])
                                             * np.diff(t[a:b])))) / 3600.0
        out.append((1.0 - q / q[-1], v[a:b], float(v[a - 1]), float(test["Ah"])))
    return out


def capacity_error(s_true, s_read) -> float:
    """Mean error of a capacity from full down to each reading [%]."""
    return float(100 * np.mean((1 - s_true) / (1 - s_read) - 1))


def main() -> None:
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"# The aged curve as the fresh one re-windowed ({machine_line()}; load average "
          f"{load})")
    for path in sorted(CMU.glob("*.csv")):
        tests = tests_of(path)
        s0, v0, rest0, cap0 = tests[0]
        order = np.argsort(v0)

        def fresh(s, s0=s0, v0=v0):
            return np.interp(s, s0[::-1], v0[::-1])

        def read(v, s0=s0, v0=v0, order=order):
            return np.interp(v, v0[order], s0[order])

        print(f"\n## {path.name}: first test {cap0:.3f} Ah, full rest {rest0:.4f} V\n")
        print("| test | fade | full rest fall [mV] | fitted a | fitted a + b | rms left [mV] "
              "| top from the fall | fresh curve | a = 0 | a = fade | a that reads right "
              "/ fade |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for k, (s, v, rest, cap) in enumerate(tests[1:], 1):
            fade = 1 - cap / cap0
            span = (s > 0.05) & (s < 0.95)
            fit = least_squares(lambda p, s=s, v=v, span=span: fresh(p[0] + p[1] * s[span])
                                - v[span], [0.0, 1.0])
            rms = 1000 * float(np.sqrt(np.mean(fit.fun ** 2)))
            top = float(read(fresh(1.0) + rest - rest0)) if rest < rest0 else 1.0
            mid = (s > MID[0]) & (s < MID[1])
            s_read = read(v[mid])

            def error(a, s=s, mid=mid, s_read=s_read, top=top):
                return capacity_error(s[mid], (s_read - a) / (top - a))

            right = brentq(error, -0.5, 0.5)
            print(f"| {k} | {100 * fade:.1f} % | {1000 * (rest - rest0):+.1f} | "
                  f"{fit.x[0]:+.3f} | {fit.x[0] + fit.x[1]:.3f} | {rms:.1f} | {top:.3f} | "
                  f"{capacity_error(s[mid], s_read):+.1f} % | {error(0.0):+.1f} % | "
                  f"{error(fade):+.1f} % | {right / fade:.2f} |")


if __name__ == "__main__":
    main()
