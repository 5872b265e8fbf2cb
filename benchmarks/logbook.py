"""The pack logbook's acceptance figures, measured on Samsung 30Q cell C (../shared/data).

1. Full discharges: capacity per event against the charge integrated here with
   numpy from the raw LabVIEW columns (goal: within 1 %).
2. Partial discharges: every other cycle cut at 60 % of its charge (the file's
   rows up to there, header kept), the others full; capacity of each cut one
   against the integral of its full file (goal: within 3 %), and how often its
   95 % interval holds that truth. Both parities, so every cycle is cut once.
3. Speed: 300 copies of bench discharges of about 3,500 samples (header bytes
   changed, so each has its own SHA-256) into a fresh SQLite logbook, in process
   (goal: <= 60 s on one core).

The end-of-life forecast and the capacity today are measured by
``benchmarks/forecast.py``.

Usage: python benchmarks/logbook.py [--copies N] [--skip-speed]
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line, shared_data, table
from dischargelab.logbook import Logbook

ROOT = Path(__file__).resolve().parents[1]
CELL_C = shared_data() / "samsung30q_ageing_cellC"
CUT_SHARE = 0.6


def lvm_rows(path: Path) -> tuple[list[str], list[str], np.ndarray]:
    """Header lines, data lines and the (time, current) columns of an LVM file."""
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    start = next(k for k, line in enumerate(lines) if line.startswith("X_Value")) + 1
    data = [line for line in lines[start:] if line.strip()]
    cols = np.array([[float(x) for x in line.split("\t")[:2]] for line in data])
    return lines[:start], data, cols


def integrated_Ah(cols: np.ndarray) -> float:
    load = cols[:, 1] < -1.0  # -3 A discharge, negative in the file
    return float(np.trapezoid(-cols[load, 1], cols[load, 0]) / 3600.0)


def cut_file(path: Path, out: Path, share: float) -> None:
    """The file up to ``share`` of its discharge charge (header and rest row kept)."""
    header, data, cols = lvm_rows(path)
    load = cols[:, 1] < -1.0
    current = np.where(load, -cols[:, 1], 0.0)
    charge = np.concatenate(([0.0], np.cumsum(0.5 * (current[1:] + current[:-1])
                                                * np.diff(cols[:, 0])))) / 3600.0
    stop = int(np.searchsorted(charge, share * charge[-1])) + 1
    out.write_text("".join(header + data[:stop]), encoding="utf-8")


def cycle_of(path: Path) -> int:
    return int(path.stem.replace("DischargeCycle", ""))


def full_and_partial(folder: Path, files: list[Path]) -> tuple[list, list]:
    truth = {p.name: integrated_Ah(lvm_rows(p)[2]) for p in files}
    full_err = []
    with Logbook(folder / "full.sqlite") as lb:
        lb.add(files, pack="cell C")
        health = lb.health("cell C")
    for e in health.events:
        full_err.append(100 * (e.capacity_Ah / truth[e.source] - 1))
    partial = []
    for parity in (0, 1):
        sub = folder / f"mixed{parity}"
        sub.mkdir()
        for k, p in enumerate(files):
            if k % 2 == parity and k > 0:  # cycle 1 stays full: the first reference
                cut_file(p, sub / p.name, CUT_SHARE)
            else:
                (sub / p.name).write_bytes(p.read_bytes())
        with Logbook(folder / f"mixed{parity}.sqlite") as lb:
            lb.add(sub, pack="mixed")
            events = lb.health("mixed").events
        for e in events:
            if e.full:
                continue
            err = 100 * (e.capacity_Ah / truth[e.source] - 1) if e.capacity_Ah else None
            lo, hi = e.capacity_interval95 or (np.nan, np.nan)
            partial.append((e.source, err, lo <= truth[e.source] <= hi))
    return full_err, partial


def speed(folder: Path, copies: int) -> tuple[int, int, float, float]:
    sources = [p for p in sorted(CELL_C.glob("DischargeCycle*.txt")) if cycle_of(p) <= 50]
    bench = folder / "speed"
    bench.mkdir()
    samples = []
    for k in range(copies):
        src = sources[k % len(sources)]
        text = src.read_text(encoding="utf-8").replace("Operator\tadmin",
                                                       f"Operator\tbench copy {k:04d}", 1)
        # each copy a day later: the same discharge at the same clock time is one event
        # logged twice (the logbook keeps one), a copy on another day another discharge
        day = re.search(r"^Date\t(\d{4}/\d{2}/\d{2})", text, re.M).group(1)
        later = (datetime.strptime(day, "%Y/%m/%d") + timedelta(days=k)).strftime("%Y/%m/%d")
        text = text.replace(day, later)
        (bench / f"copy{k:04d}_{src.name}").write_text(text, encoding="utf-8")
        samples.append(len(lvm_rows(src)[1]))
    start = time.perf_counter()
    cpu0 = time.process_time()
    with Logbook(folder / "speed.sqlite") as lb:
        result = lb.add(bench, pack="bench")
    wall = time.perf_counter() - start
    return result.events, int(np.median(samples)), wall, time.process_time() - cpu0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, default=300)
    parser.add_argument("--skip-speed", action="store_true")
    args = parser.parse_args()
    files = sorted(CELL_C.glob("DischargeCycle*.txt"), key=cycle_of)
    if not files:
        sys.exit(f"no cell C files in {CELL_C}")
    with tempfile.TemporaryDirectory(prefix="dischargelab-bench-") as tmp:
        folder = Path(tmp)
        full_err, partial = full_and_partial(folder, files)
        errs = np.array([p[1] for p in partial if p[1] is not None])
        missing = sum(1 for p in partial if p[1] is None)
        cover = np.mean([p[2] for p in partial if p[1] is not None])
        table("Capacity per event, Samsung 30Q cell C (truth: numpy integral of the raw file)",
              ["events", "kind", "goal", "max |error|", "rms error", "95 % interval holds truth",
               "no estimate"],
              [[len(full_err), "full discharge (coulomb count)", "<= 1 %",
                f"{np.max(np.abs(full_err)):.3f} %",
                f"{np.sqrt(np.mean(np.square(full_err))):.3f} %", "-", 0],
               [len(partial), f"cut at {100 * CUT_SHARE:.0f} % (reference curve)", "<= 3 %",
                f"{np.max(np.abs(errs)):.2f} %", f"{np.sqrt(np.mean(errs ** 2)):.2f} %",
                f"{100 * cover:.0f} %", missing]])
        if not args.skip_speed:
            events, samples, wall, cpu = speed(folder, args.copies)
            table("Ingest speed (SQLite, in process, one core)",
                  ["files", "median samples", "wall s", "CPU s", "goal"],
                  [[events, samples, f"{wall:.1f}", f"{cpu:.1f}", "<= 60 s"]])
    print(f"\n{machine_line()}")


if __name__ == "__main__":
    main()
