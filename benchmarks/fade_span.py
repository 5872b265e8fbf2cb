"""Forecast only with evidence: what the fade test says on real lives, and the span it needs.

1. Real ageing lives (Samsung 30Q cell C, CMU eVTOL VAH27 and VAH30 as logged), each
   added once to a fresh logbook; then, at origins through the life, the pack's health
   from the events up to the origin, made as ``build_health`` makes it: the fade so far
   (per cent per 100 EFC, how many sigma, over which span), whether an end of life is
   given (``dated``), and the end of life with its 95 % interval.
2. The span a fade needs before it dates an end of life inside 5x today's EFC: on the
   full discharges (capacity tests) of the same lives, the fade fitted over a window of
   ``S`` EFC against the fade over the ``5 S`` EFC that follow. A fade measured over too
   short a span does not tell the next one: short-term, reversible capacity changes (rest,
   temperature, the charge before) weigh as much as the fade.

Usage: python benchmarks/fade_span.py [--skip-cmu]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line, table
from dischargelab.logbook import Logbook
from dischargelab.logbook.forecast import SOON_FACTOR, SPAN_SOON
from dischargelab.logbook.over_life import _trend, shared_errors
from dischargelab.logbook.results import _forecast
from forecast import CELL_C, cycle_of, shared_data

CMU = shared_data() / "cmu_evtol"
SHARES = (0.05, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0)
SPANS = (5.0, 10.0, 20.0, 40.0, 80.0)


def life(folder: Path, name: str, files: list[Path], chemistry: str) -> list:
    with Logbook(folder / f"{name}.sqlite") as lb:
        lb.set_pack(name, chemistry=chemistry)
        lb.add(files, pack=name)
        health = lb.health(name)
    return health


def at_origins(name: str, health) -> list[list]:
    usable = [e for e in health.events if e.capacity_Ah is not None and not e.outlier
              and e.efc is not None]
    end = max(e.efc for e in usable)
    rows = []
    for share in SHARES:
        upto = [e for e in usable if e.efc <= share * end]
        if len(upto) < 2:
            continue
        trend = _trend(upto, [e.capacity_Ah for e in upto],
                       [e.capacity_interval95 for e in upto], systematic=shared_errors(upto))
        ref = health.reference_capacity_Ah
        fc = _forecast(upto, trend, ref, 0.8, [], chemistry="li-ion", efc_now=upto[-1].efc)
        f = fc.fade
        lo, hi = fc.eol_efc_interval95
        inside = fc.eol_efc is not None and (lo or fc.eol_efc) < SOON_FACTOR * fc.last_efc
        rows.append([name, f"{share:.2f}", f"{fc.last_efc:.0f}", len(upto),
                     "-" if f["rate_per_efc"] is None else f"{1e4 * f['rate_per_efc']:.2f}",
                     f"{f['z']:.1f}", f"{f['span_efc']:.0f}", fc.status,
                     "-" if fc.eol_efc is None else f"{fc.eol_efc:.0f}",
                     f"[{_n(lo)}, {_n(hi)}]", "yes" if inside else "no",
                     "-" if f["efc_needed"] is None else f"{f['efc_needed']:.0f}"])
    return rows


def _n(v) -> str:
    return "-" if v is None else f"{v:.0f}"


def _slope(x, y) -> float:
    return float(-np.polyfit(x, y / np.mean(y), 1)[0])


def span_rows(lives: dict) -> list[list]:
    rows = []
    for span in SPANS:
        ratios = []
        for health in lives.values():
            full = [(e.efc, e.capacity_Ah) for e in health.events if e.health_kind == "full"
                    and not e.outlier and e.capacity_Ah is not None and e.efc is not None]
            if len(full) < 4:
                continue
            x, y = np.array(full).T
            for start in x:
                now = (x >= start) & (x <= start + span)
                ahead = (x >= start + span) & (x <= start + (1 + SOON_FACTOR) * span)
                if now.sum() < 2 or ahead.sum() < 3 or np.ptp(x[ahead]) < 2 * span:
                    continue
                a, b = _slope(x[now], y[now]), _slope(x[ahead], y[ahead])
                if b > 0:
                    ratios.append(a / b)
        r = np.array(ratios)
        if r.size == 0:
            rows.append([f"{span:g}", 0, "-", "-", "-"])
            continue
        within = np.mean((r >= 0.5) & (r <= 2.0))
        rows.append([f"{span:g}", r.size, f"{np.median(r):.2f}",
                     f"{np.percentile(r, 10):.2f} - {np.percentile(r, 90):.2f}",
                     f"{100 * within:.0f} %"])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-cmu", action="store_true", help="cell C only (faster)")
    args = parser.parse_args()
    lives = {}
    with tempfile.TemporaryDirectory(prefix="dischargelab-bench-") as tmp:
        folder = Path(tmp)
        start = time.perf_counter()
        files = sorted(CELL_C.glob("DischargeCycle*.txt"), key=cycle_of)
        lives["cell C"] = life(folder, "cell C", files, "li-ion")
        if not args.skip_cmu:
            for path in sorted(CMU.glob("VAH*.csv")):
                lives[path.stem] = life(folder, path.stem, [path], "li-ion")
        took = time.perf_counter() - start
    rows = [r for name, h in lives.items() for r in at_origins(name, h)]
    table("Real lives from share s of their logged EFC: fade so far [% per 100 EFC], sigma, "
          "span [EFC], and the end of life (80 % of the reference) when dated",
          ["life", "s", "EFC", "estimates", "fade", "sigma", "span", "status", "EOL EFC",
           "95 %", f"inside {SOON_FACTOR:g}x", "EFC needed"], rows)
    table(f"Fade over a window of S EFC (capacity tests) / fade over the {SOON_FACTOR:g} S "
          f"EFC after it (SPAN_SOON = {SPAN_SOON:g})",
          ["S [EFC]", "windows", "median ratio", "10-90 %", "within a factor 2"],
          span_rows(lives))
    print(f"\nadd + health of the lives: {took:.0f} s; {machine_line()}")


if __name__ == "__main__":
    main()
