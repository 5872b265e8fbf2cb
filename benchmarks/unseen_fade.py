"""What the routine of a real eVTOL life can show of its fade, block by block.

The shared eVTOL lives (CMU VAH27 and VAH30; Bills et al. 2023) as logged, every capacity
test cut out but the first (as ``health_matrix.py`` does): per block of missions (between
two tests), the median of the charges' capacity estimates (each from the rest after a
mission, read through the first test's curve, to full) against the two tests around the
block, the state of charge those estimates start from (median), the pack's resistance rise
since the first test (``over_life.resistance_rise``) and the median rest voltage after a
full charge. Then, per cell, how much of the fade the charges miss by the last block
(their error's change since block 1: the "drift") against each candidate signal.

A charge between a mission's rest and full sees the curve above that rest only. Lithium
lost as the cell ages (SEI growth) empties the negative electrode first and takes its
charge from the bottom of the curve, below every rest the routine reaches: the charges read
the capacity of the part they swing through. The same SEI raises the resistance: the
logbook takes ``over_life.HIDDEN_FADE_PER_RISE`` (0.1, chosen on the PyBaMM lives of
``health_matrix.py``) of the capacity per unit of rise off capacity today. A signal that
tells the missing part gives the same drift per unit on both cells, whatever the sampling
(the log resampled to 60 s, as ``health_matrix.py`` does, reads the rise again); the
drop of the rest voltage after a full charge is shown for comparison.

References: A. Bills et al., Sci. Data 10, 344 (2023); C. R. Birkl et al., J. Power
Sources 341 (2017) 373-386 (degradation modes and the open-circuit curve).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line, table  # noqa: E402
from dischargelab.logbook import Logbook  # noqa: E402
from dischargelab.logbook.over_life import REFERENCE_KIND, estimate_kind, resistance_rise  # noqa: E402
from dischargelab.logbook.results import DEFAULT_EOL, build_health  # noqa: E402
from health_from_use import blocks_of, current_runs  # noqa: E402
from health_matrix import logbook_of, real_log  # noqa: E402

CELLS = ("VAH27", "VAH30")


def top_rests(frame: pd.DataFrame, full_cell_V: float = 4.19) -> pd.DataFrame:
    """Time [s] and voltage [V] of the last sample of each rest after a charge that
    reached ``full_cell_V``."""
    i = frame["current_A"].to_numpy(float)
    v = frame["voltage_V"].to_numpy(float)
    state, runs = current_runs(i)
    rows = [(frame["time_s"].iloc[b - 1], v[b - 1])
            for (pa, pb), (a, b) in zip(runs, runs[1:])
            if state[a] == 0 and state[pa] == -1 and v[pa:pb].max() >= full_cell_V]
    return pd.DataFrame(rows, columns=["time_s", "voltage_V"])


def cell_rows(cell: str, cache: Path, period_s: float | None = None) -> list[dict]:
    """Per block of ``cell``'s life as logged (or resampled to ``period_s``)."""
    frame, truth = real_log(cell, period_s, None)
    how = "as logged" if period_s is None else f"resampled {period_s:.0f} s"
    db = logbook_of(frame, f"{cell} {how}/0", cache)
    with Logbook(db) as lb:
        row, events, model = lb._pack_data("cell")
    health = build_health(row, events, model, DEFAULT_EOL)
    tops = top_rests(frame)
    starts = [x["start_s"] for x in truth]
    anchor = next(e.efc for e in health.events
                  if e.capacity_Ah is not None and estimate_kind(e) == REFERENCE_KIND)
    out = []
    for k, (block, so_far) in enumerate(blocks_of(health)):
        if k + 1 >= len(truth):
            break
        charges = [e for e in block if e.kind == "charge" and e.capacity_Ah is not None
                   and not e.outlier and e.soc_start is not None]
        mid = 0.5 * (truth[k]["Ah"] + truth[k + 1]["Ah"])
        efc = max(e.efc for e in so_far if e.efc is not None)
        inside = tops[(tops.time_s > starts[k]) & (tops.time_s < starts[k + 1])]
        out.append({"block": k + 1, "EFC": efc, "tests_Ah": mid,
                    "charges_Ah": float(np.median([e.capacity_Ah for e in charges])),
                    "start": float(np.median([e.soc_start for e in charges])),
                    "rise": float(resistance_rise(so_far, anchor, [efc])[0]),
                    "top_rest_V": float(inside.voltage_V.median())})
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cells", nargs="*", default=list(CELLS), choices=CELLS,
                        help="the eVTOL cells to read (default: both)")
    parser.add_argument("--cache", type=Path, default=ROOT / ".cache" / "health_matrix",
                        help="folder keeping the logbooks (shared with health_matrix.py)")
    args = parser.parse_args(argv)
    cache = args.cache
    cache.mkdir(parents=True, exist_ok=True)
    print(f"# What the routine shows of the fade ({machine_line()})\n")
    summary = []
    for cell in args.cells:
        rows = cell_rows(cell, cache)
        err = [100 * (r["charges_Ah"] / r["tests_Ah"] - 1) for r in rows]
        table(f"{cell} as logged: per block", ["block", "EFC", "tests (mean) [Ah]",
                                                "charges (median) [Ah]", "error",
                                                "charges start at", "resistance rise",
                                                "rest after full [V]"],
              [[r["block"], f"{r['EFC']:.0f}", f"{r['tests_Ah']:.3f}",
                f"{r['charges_Ah']:.3f}", f"{e:+.1f} %", f"{r['start']:.0%}",
                f"{r['rise']:.2f}", f"{r['top_rest_V']:.4f}"] for r, e in zip(rows, err)])
        first, last = rows[0], rows[-1]
        fade = 100 * (1 - last["tests_Ah"] / first["tests_Ah"])
        drift = err[-1] - err[0]
        drop_mV = 1000 * (first["top_rest_V"] - last["top_rest_V"])
        rise = last["rise"]
        rise_60 = cell_rows(cell, cache, 60.0)[-1]["rise"]
        summary.append([cell, f"{last['EFC'] - first['EFC']:.0f}", f"{fade:.1f} %",
                        f"{fade - drift:.1f} %", f"{drift:+.1f} %",
                        f"{rise:.2f} ({drift / rise:.1f} % per unit)" if rise > 0 else "-",
                        f"{rise_60:.2f}",
                        f"{drift / drop_mV:.2f} % per mV" if drop_mV > 0 else "-"])
    table("The fade the charges miss, against what might tell it",
          ["cell", "EFC (block 1 to last)", "fade of the tests", "fade the charges show",
           "missed (drift)", "resistance rise", "the rise resampled to 60 s",
           "per mV of the full rest's drop"],
          summary)


if __name__ == "__main__":
    main()
