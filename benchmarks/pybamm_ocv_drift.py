"""How the open-circuit curve of the PyBaMM lives moves with age, and what a curve held
at its first test reads from a mission.

For each PyBaMM condition of ``health_matrix.py`` (the lives from
``tests/pybamm_life.py``, made or read from its cache) and each capacity test: the test's
capacity, the cell's losses (lithium inventory, active material of each electrode; the
lithium taken by SEI since the first test and the lithium plated now), the open-circuit
voltage at 50 % state of charge and at a mission's charge below full (``Q``, the median
of the life's missions) against the first test's, and the capacity that a mission from
full taking ``Q`` gives when its end is read on the first test's curve: ``Q / (1 - s')``,
``s'`` where the first curve meets the aged cell's open-circuit voltage at the mission's
end (what "capacity between two rests" reads when the curve is not learned again),
against the cell's open-circuit capacity.

The curve of a cell at a state: PyBaMM's electrode-SOH windows (Mohtat et al. 2019),
``pybamm_life.ocv``.

References: P. Mohtat et al., J. Electrochem. Soc. 166, A3614 (2019); M. Dubarry,
C. Truchot, B. Y. Liaw, J. Power Sources 219 (2012) 204-216.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT / "tests"))

from _machine import machine_line  # noqa: E402


def mission_charge(frame) -> float:
    """The median charge [Ah] of a life's missions (its discharges above 1 A)."""
    t = frame["time_s"].to_numpy(float)
    i = frame["current_A"].to_numpy(float)
    on = np.r_[False, i > 1.0, False].astype(int)
    starts, stops = np.flatnonzero(np.diff(on) == 1), np.flatnonzero(np.diff(on) == -1)
    charges = [np.trapezoid(i[a:b], t[a:b]) / 3600.0 for a, b in zip(starts, stops)
               if t[b - 1] - t[a] > 600.0]
    return float(np.median(charges))


def state_at_test(cycles, test_cycle: int):
    """The cell's state when a test starts: the end of the cycle before it."""
    return cycles.iloc[max(test_cycle - 1, 0)]


def rows_of(spec, life) -> list[dict]:
    import pybamm_life as pl

    test_cycles = [int(np.searchsorted(life.cycles["start_s"].to_numpy(), a, side="right")) - 1
                   for a, _, _, _ in life.tests]
    states = [state_at_test(life.cycles, c) for c in test_cycles]
    grid = np.linspace(0.0, 1.0, 401)
    taken = mission_charge(life.frame)
    first = pl.ocv(spec, states[0], grid)
    out = []
    for (_, _, q, efc), state in zip(life.tests, states):
        cap = state["ocv_capacity_Ah"]
        here = pl.ocv(spec, state, np.array([0.5, 1.0 - taken / cap]))
        fresh = pl.ocv(spec, states[0], np.array([0.5, 1.0 - taken
                                                   / states[0]["ocv_capacity_Ah"]]))
        read_soc = float(np.interp(here[1], first, grid))
        read = taken / (1.0 - read_soc)
        out.append({"efc": efc, "test_Ah": q, "ocv_Ah": cap, "lli": state["lli_pct"],
                    "lam_n": state["lam_neg_pct"], "lam_p": state["lam_pos_pct"],
                    "sei": state["sei_Ah"] + state["sei_cracks_Ah"] - states[0]["sei_Ah"]
                    - states[0]["sei_cracks_Ah"],
                    "plating": state["plating_Ah"],
                    "d50": 1000 * (here[0] - fresh[0]), "dtop": 1000 * (here[1] - fresh[1]),
                    "read_Ah": read, "read_err": 100 * (read / cap - 1), "taken": taken})
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="*", default=None,
                        help="conditions whose name contains one of these words")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cycles", type=int, default=None,
                        help="cycles per life (default: health_matrix.py's)")
    parser.add_argument("--cache", type=Path, default=None,
                        help="folder keeping the lives (default: pybamm_life.cache_folder())")
    args = parser.parse_args(argv)
    print(f"# The PyBaMM lives' open-circuit curve with age ({machine_line()})\n")
    import importlib.util

    if importlib.util.find_spec("pybamm") is None:
        print("skipped: pybamm not installed")
        return
    import pybamm_life as pl
    from health_matrix import BASE, PYBAMM

    started = time.perf_counter()
    for name, changes in PYBAMM.items():
        if args.only and not any(w.lower() in name.lower() for w in args.only):
            continue
        cycles = args.cycles or BASE["cycles"]
        spec = pl.PybammLifeSpec(seed=args.seed, **dict(changes, cycles=cycles))
        life, _ = pl.cached_life(spec, args.cache)
        print(f"\n## {name}\n")
        print(f"lowest voltage of a mission: {life.cycles['mission_min_V'].min():.3f} V "
              f"(cutoff {spec.cutoff_V:g} V)\n")
        print(f"a mission takes {mission_charge(life.frame):.2f} Ah (median)\n")
        print("| EFC | test | OCV capacity | LLI | LAM neg | LAM pos | SEI since | plated | "
              "OCV at 50 % | OCV a mission below full | read on the first curve | its error |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in rows_of(spec, life):
            print(f"| {r['efc']:.1f} | {r['test_Ah']:.3f} Ah | {r['ocv_Ah']:.3f} Ah | "
                  f"{r['lli']:.1f} % | {r['lam_n']:.1f} % | {r['lam_p']:.1f} % | "
                  f"{r['sei']:.3f} Ah | {r['plating']:.4f} Ah | {r['d50']:+.0f} mV | "
                  f"{r['dtop']:+.0f} mV | {r['read_Ah']:.3f} Ah | {r['read_err']:+.1f} % |")
    print(f"\n(total {time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
