"""End of life and capacity today: the acceptance figures of the logbook's trend and forecast.

1. Samsung 30Q cell C (../shared/data): the end of life (80 % of the first full
   discharge) forecast from the cycles up to 220 and 330 (the acceptance: a finite
   95 % interval that covers the observed crossing, centre within 20 % of it), and
   from other points of the life, each through a fresh SQLite logbook as
   ``dischargelab logbook health`` makes it. The observed crossing: from all 68
   logged cycles (first capacity under the threshold for good, interpolated).
2. Calibration on seeded synthetic lives (``_lives.py``: shapes from the literature,
   with and without knees, white and wandering scatter, outliers), forecast from the
   first third and the first half of each life: how often the 95 % interval holds
   the true crossing, the median |centre error| and the median width (both relative
   to the true end of life), and how many intervals are open. The reference is the
   first logged capacity, as in a logbook without a label capacity.
3. Capacity today on synthetic estimate series (capacity tests only, half partial
   estimates, partial estimates only; "today" anywhere from 15 % to 110 % of the
   life): how often its 95 % interval holds the true capacity, its median width and
   the median |error|.

Usage: python benchmarks/forecast.py [--lives N] [--skip-cell-c]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _lives import make_life
from _machine import machine_line, shared_data, table
from dischargelab.logbook import Logbook
from dischargelab.logbook.forecast import forecast_capacity
from dischargelab.logbook.outliers import flag_outliers, observed_crossing
from dischargelab.logbook.trend import smooth

ROOT = Path(__file__).resolve().parents[1]


CELL_C = shared_data() / "samsung30q_ageing_cellC"
ACCEPTANCE = (220, 330)
ORIGINS = (150, 220, 270, 330, 390, 450)


def cycle_of(path: Path) -> int:
    return int(path.stem.replace("DischargeCycle", ""))


def cell_c(folder: Path, files: list[Path]) -> list[list]:
    with Logbook(folder / "all.sqlite") as lb:
        lb.add(files, pack="cell C")
        everything = lb.health("cell C")
    usable = [e for e in everything.events if e.capacity_Ah is not None and not e.outlier]
    rows = []
    for origin in ORIGINS:
        start = time.perf_counter()
        with Logbook(folder / f"upto{origin}.sqlite") as lb:
            lb.add([p for p in files if cycle_of(p) <= origin], pack="cell C")
            f = lb.health("cell C").forecast
        seconds = time.perf_counter() - start
        seen = observed_crossing([e.efc for e in usable], [e.capacity_Ah for e in usable],
                                 f.threshold_Ah)
        truth = None if seen is None else seen[0]
        lo, hi = f.eol_efc_interval95
        finite = lo is not None and hi is not None
        covers = truth is not None and finite and lo <= truth <= hi
        err = None if truth is None or f.eol_efc is None else f.eol_efc / truth - 1
        goal = "acceptance" if origin in ACCEPTANCE else "-"
        rows.append([origin, f"{f.last_efc:.0f}", f"{f.threshold_Ah:.3f}", f.shape,
                     "-" if f.knee_efc is None else f"{f.knee_efc:.0f}",
                     "-" if f.eol_efc is None else f"{f.eol_efc:.0f}",
                     f"[{_n(lo)}, {_n(hi)}]", "-" if truth is None else f"{truth:.0f}",
                     "yes" if covers else "NO", "-" if err is None else f"{100 * err:+.1f} %",
                     goal, f"{seconds:.1f}"])
    return rows


def _n(v) -> str:
    return "open" if v is None else f"{v:.0f}"


def forecast_life(life, share: float):
    """Forecast of one synthetic life from ``share`` of its nominal end of life."""
    x, q, lo, hi = life.upto(share * life.eol_efc)
    out = flag_outliers(x, q)
    x, q, lo, hi = x[~out], q[~out], lo[~out], hi[~out]
    reference = float(q[0])
    threshold = 0.8 * reference
    weights = smooth(x, q, lo, hi).weights
    made = forecast_capacity(x, q, lo, hi, reference, threshold, weights=weights)
    truth = life.crossing(threshold)
    return made[1], truth


def calibration(lives: int) -> list[list]:
    rows = []
    for knee in (False, True):
        for share, name in ((1 / 3, "first third"), (1 / 2, "first half")):
            cover, err, width, opened, low, high = [], [], [], 0, 0, 0
            start = time.perf_counter()
            for seed in range(lives):
                life = make_life(100_000 * knee + seed, knee)
                ahead, truth = forecast_life(life, share)
                a, b = ahead.interval95
                opened += a is None or b is None
                a = -np.inf if a is None else a
                b = np.inf if b is None else b
                cover.append(a <= truth <= b)
                low += truth < a
                high += truth > b
                centre = np.inf if ahead.eol_efc is None else ahead.eol_efc
                err.append(abs(centre / truth - 1))
                width.append((b - a) / truth)
            each = (time.perf_counter() - start) / lives
            rows.append(["with knee" if knee else "without knee", name, lives,
                         f"{100 * np.mean(cover):.1f} %", f"{low} / {high}",
                         f"{100 * np.median(err):.1f} %", f"{100 * np.median(width):.0f} %",
                         opened, f"{each:.2f}"])
    return rows


def capacity_today(lives: int) -> list[list]:
    rows = []
    for share, name in ((0.0, "capacity tests"), (0.5, "half partial estimates"),
                        (1.0, "partial estimates only")):
        cover, width, err = [], [], []
        for seed in range(lives):
            life = make_life(200_000 + seed, seed % 2 == 0, partial_share=share)
            rng = np.random.default_rng(300_000 + seed)
            x, q, lo, hi = life.upto(rng.uniform(0.15, 1.1) * life.eol_efc)
            value, (a, b) = smooth(x, q, lo, hi).interval95(float(x[-1]))
            truth = float(life.truth(x[-1])[()])
            cover.append(a <= truth <= b)
            width.append((b - a) / truth)
            err.append(abs(value / truth - 1))
        rows.append([name, lives, f"{100 * np.mean(cover):.1f} %",
                     f"{100 * np.median(width):.2f} %", f"{100 * np.median(err):.2f} %"])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lives", type=int, default=100,
                        help="synthetic lives per row (default 100)")
    parser.add_argument("--skip-cell-c", action="store_true")
    args = parser.parse_args()
    if not args.skip_cell_c:
        files = sorted(CELL_C.glob("DischargeCycle*.txt"), key=cycle_of)
        if not files:
            sys.exit(f"no cell C files in {CELL_C}")
        with tempfile.TemporaryDirectory(prefix="dischargelab-bench-") as tmp:
            table("End of life (80 % of the first full discharge), Samsung 30Q cell C, "
                  "forecast from the cycles up to N (goal: finite interval covering the "
                  "observed crossing, centre within 20 %)",
                  ["N", "EFC then", "threshold Ah", "trend", "knee EFC", "forecast EFC",
                   "95 % interval", "observed EFC", "covers", "centre error", "", "s"],
                  cell_c(Path(tmp), files))
    table("Calibration of the end-of-life interval on synthetic lives (goal: coverage ~95 %, "
          ">= 90 %)", ["lives", "forecast from", "n", "coverage", "truth below / above",
                       "median |centre error|", "median width", "open", "s each"],
          calibration(args.lives))
    table("Capacity today on synthetic estimate series (goal: coverage >= 90 %, narrow)",
          ["estimates", "n", "coverage", "median width", "median |error|"],
          capacity_today(2 * args.lives))
    print(f"\n{machine_line()}; load average {os.getloadavg()[0]:.2f} (shared machine)")


if __name__ == "__main__":
    main()
