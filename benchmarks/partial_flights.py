"""A multirotor pack's partial flights through the logbook, as a user meets them.

Flight logs made by the project's one engine (``tests/synthetic_life.py``:
``flight_log``, an ``ecm`` cell with relaxation, diffusion and self-heating, its
open-circuit curve 8 mV off the generic one), written as a logger writes them (time,
pack voltage, current; no temperature, no date), added to a fresh logbook with nothing
told, or with the pack's cells and chemistry:

* **One hover to 30 %**: a 12 Ah pack, 3S and 6S, Li-ion (NMC) and LiPo (LiCoO2), a
  minute's rest from full, 27 A for 19 minutes, the log ending 36 or 100 s after
  landing. The flight's capacity estimate against the cell's capacity, and whether its
  95 % band holds it.
* **Eight flights of a 4S 5 Ah pack**, each from a full charge (20-120 s of rest logged
  first), a take-off burst at 1.5 times the hover current, a hover at 15-30 A with gusts
  every 30 s (+-20 %) to 25-50 % left, the log ending 30-120 s after landing (seeded).
  How many flights read as discharges, how many bands hold the capacity, capacity today
  and its band against the truth, the EFC counted, the forecast's status.

Prints both tables and the machine.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT / "tests"))

from _machine import machine_line  # noqa: E402
from dischargelab.logbook import Logbook  # noqa: E402

CHEMISTRIES = ("li-ion", "lipo")
TOLD = ("nothing", "cells and chemistry")


def _logbook(folder: Path, told: str, cells: int, chemistry: str):
    lb = Logbook(folder / "lb.sqlite")
    if told == "nothing":
        lb.set_pack("pack")
    else:
        lb.set_pack("pack", cells=cells, chemistry=chemistry)
    return lb


def hover_rows(chemistries=CHEMISTRIES) -> list[list]:
    """One hover to 30 % per chemistry, cells, tail and what the user told."""
    import synthetic_life as sl

    rows = []
    for chemistry in chemistries:
        for cells in (3, 6):
            for tail_s in (36.0, 100.0):
                for told in TOLD:
                    with tempfile.TemporaryDirectory() as tmp:
                        folder = Path(tmp)
                        truth = sl.flight_log(folder / "hover.csv",
                                              [(27.0, 0.7 * 12 * 3600 / 27)], capacity_Ah=12.0,
                                              cells=cells, chemistry=chemistry, after_s=tail_s)
                        with _logbook(folder, told, cells, chemistry) as lb:
                            lb.add(folder / "hover.csv", pack="pack")
                            got = [e for e in lb.health("pack").events
                                   if e.capacity_Ah is not None]
                    if not got:
                        rows.append([chemistry, cells, f"{tail_s:.0f}", told, f"{truth:.2f}",
                                     "-", "-", "-", "no estimate"])
                        continue
                    e = got[0]
                    low, high = e.capacity_interval95
                    error = 100 * (e.capacity_Ah / truth - 1)
                    rows.append([chemistry, cells, f"{tail_s:.0f}", told, f"{truth:.2f}",
                                 f"{e.capacity_Ah:.2f}", f"{error:+.1f} %",
                                 f"[{low:.2f}, {high:.2f}]",
                                 "yes" if low <= truth <= high else "NO"])
    return rows


def sequence_rows(n_flights: int = 8, seed: int = 7, chemistries=CHEMISTRIES) -> list[list]:
    """Eight partial flights of a 4S 5 Ah pack per chemistry and what the user told."""
    import synthetic_life as sl

    rows = []
    for chemistry in chemistries:
        for told in TOLD:
            rng = np.random.default_rng(seed)
            with tempfile.TemporaryDirectory() as tmp:
                folder = Path(tmp)
                moved = 0.0
                for k in range(n_flights):
                    hover_A, depth = rng.uniform(15, 30), rng.uniform(0.5, 0.75)
                    after_s, before_s = rng.uniform(30, 120), rng.uniform(20, 120)
                    gusts = np.random.default_rng(k)
                    loads, left = [(1.5 * hover_A, 20.0)], depth * 5.0 * 3600 - 30 * hover_A
                    while left > 0 and len(loads) < 200:
                        amps = hover_A * gusts.uniform(0.8, 1.2)
                        loads.append((amps, min(30.0, left / amps)))
                        left -= amps * loads[-1][1]
                    moved += sum(a * d for a, d in loads) / 3600
                    truth = sl.flight_log(folder / f"flight_{k:02d}.csv", loads, capacity_Ah=5.0,
                                          cells=4, chemistry=chemistry, before_s=before_s,
                                          after_s=after_s, seed=k, sample_s=0.5)
                with _logbook(folder, told, 4, chemistry) as lb:
                    lb.add(folder, pack="pack", recursive=True)
                    health = lb.health("pack")
            flights = [e for e in health.events if e.kind in ("discharge", "flight")]
            got = [e for e in flights if e.capacity_Ah is not None]
            held = sum(e.capacity_interval95[0] <= truth <= e.capacity_interval95[1] for e in got)
            today = health.today.get("capacity_Ah")
            low, high = health.today.get("capacity_interval95") or (np.nan, np.nan)
            rows.append([chemistry, told, f"{len(flights)} of {n_flights}",
                         f"{held} of {len(got)}", f"{today:.2f}",
                         f"{100 * (today / truth - 1):+.1f} %", f"[{low:.2f}, {high:.2f}]",
                         "yes" if low <= truth <= high else "NO",
                         f"{health.today.get('efc') or 0:.2f} ({moved / truth:.2f})",
                         health.forecast.status if health.forecast else "-"])
    return rows


def _markdown(head: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(x) for x in r) + " |" for r in rows]
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", type=int, default=8, help="flights in the sequence")
    parser.add_argument("--chemistries", nargs="+", default=list(CHEMISTRIES),
                        choices=CHEMISTRIES, help="the cells' chemistries")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    print("# One hover to 30 % of a 12 Ah pack (27 A, 19 min), logged 36 or 100 s after "
          "landing\n")
    print(_markdown(["chemistry", "cells", "log after landing [s]", "told", "capacity [Ah]",
                     "estimate [Ah]", "error", "95 % band", "band holds"],
                    hover_rows(args.chemistries)))
    print(f"\n# {args.flights} partial flights of a 4S 5 Ah pack, each from full to 25-50 % "
          "left\n")
    print(_markdown(["chemistry", "told", "read as discharges", "bands hold", "today [Ah]",
                     "error", "95 % band", "band holds", "EFC (truth)", "forecast"],
                    sequence_rows(args.flights, chemistries=args.chemistries)))
    print(f"\n{machine_line()}; {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
