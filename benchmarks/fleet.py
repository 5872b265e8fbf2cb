"""Fleet-scale ingest: the whole `logbook add` command in process and on Dask workers.

The 68 cell C cycle files of ../shared/data/samsung30q_ageing_cellC copied under several
pack folders (default 9: 612 files), each copy changed by trailing newlines so that its
SHA-256 differs, are added to fresh SQLite logbooks by the command a user types,

    dischargelab logbook add PACKS --pack-from parent -r --workers N --db FILE

run as a subprocess and timed from its start to its exit (imports, the cluster's start,
listing and hashing, reading, writing, the packs' figures, the cluster's end), for
``--workers 1`` (in this process, no Dask) and 2 (a local cluster), in turns (1, 2, 1, 2...)
so that a change of the machine's load falls on both alike. The table gives the median and
the spread of the runs, the speed-up of the medians, the load average around the runs, and
whether the stored events and figures equal the in-process run's.

Usage: python benchmarks/fleet.py [--packs N] [--workers 2,...] [--repeats N] [--keep DIR]
       [--no-formats]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line, shared_data

CELL_C = shared_data() / "samsung30q_ageing_cellC"

#: The command's own process: ``dischargelab`` beside this interpreter.
COMMAND = [sys.executable, "-c", "from dischargelab.cli import main; main()"]


def make_packs(root: Path, packs: int) -> int:
    files = sorted(CELL_C.glob("DischargeCycle*.txt"))
    for k in range(packs):
        folder = root / f"pack-{k + 1:02d}"
        folder.mkdir(parents=True)
        for f in files:
            (folder / f.name).write_bytes(f.read_bytes() + b"\n" * (k + 1))
    return packs * len(files)


def add(folder: Path, db: Path, workers: int) -> dict:
    """One run of the command; its wall time and the load average before and after."""
    db.unlink(missing_ok=True)
    load = os.getloadavg()[0]
    start = time.perf_counter()
    proc = subprocess.run([*COMMAND, "logbook", "add", str(folder), "--pack-from", "parent",
                           "-r", "--workers", str(workers), "--db", str(db), "--json"],
                          capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - start
    if proc.returncode:
        raise SystemExit(f"logbook add failed: {proc.stderr[-2000:]}")
    return {"wall_s": wall, "load": (load, os.getloadavg()[0]), "db": db}


def contents(db: Path) -> tuple:
    """Every stored event and every pack's stored figures (ids and times left out)."""
    from dischargelab.logbook import Logbook

    with Logbook(str(db), create=False) as lb:
        events = {(name, r["source"], r["idx"]): {k: v for k, v in r.items() if k != "id"}
                  for name in lb.pack_names() for r in lb.events(name).to_dict()["events"]}
        assert lb.stale() == [], "figures left stale"
        health = {name: lb.health(name).to_dict() for name in lb.pack_names()}
    for h in health.values():
        for e in h["events"]:
            e.pop("event_id")
    return events, health


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--packs", type=int, default=9, help="pack folders (68 files each)")
    parser.add_argument("--workers", default="2", help="worker counts to try, e.g. 2,4")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each worker count")
    parser.add_argument("--keep", type=Path, help="keep the files and databases here")
    parser.add_argument("--no-formats", action="store_true",
                        help="skip the per-format cost of one file")
    opts = parser.parse_args()
    if not CELL_C.is_dir():
        raise SystemExit(f"needs {CELL_C}")
    work = Path(opts.keep or tempfile.mkdtemp(prefix="dischargelab-fleet-"))
    folder = work / "packs"
    if folder.exists():
        shutil.rmtree(folder)
    n = make_packs(folder, opts.packs)
    size_MB = sum(p.stat().st_size for p in folder.rglob("*.txt")) / 1e6
    counts = [1] + [int(w) for w in opts.workers.split(",")]
    runs: dict[int, list] = {w: [] for w in counts}
    for _ in range(opts.repeats):
        for workers in counts:
            runs[workers].append(add(folder, work / f"logbook-{workers}.sqlite", workers))
    reference = contents(runs[1][-1]["db"])
    n_events = len(reference[0])
    base = statistics.median(r["wall_s"] for r in runs[1])
    print(f"Fleet ingest, the whole command: {n} files ({size_MB:.0f} MB, {n_events} events) "
          f"in {opts.packs} pack folders, median of {opts.repeats} runs in turns")
    print("| workers | wall [s], median | runs [s] | files/s | speed-up | load average "
          "around the runs | database [MB] | events and figures identical |")
    print("|---:|---:|---|---:|---:|---|---:|---|")
    for workers in counts:
        rs = runs[workers]
        wall = statistics.median(r["wall_s"] for r in rs)
        db = rs[-1]["db"]
        same = "reference" if workers == 1 else ("yes" if contents(db) == reference else "NO")
        loads = ", ".join(f"{a:.1f}-{b:.1f}" for a, b in (r["load"] for r in rs))
        walls = ", ".join(f"{r['wall_s']:.1f}" for r in rs)
        print(f"| {workers} | {wall:.1f} | {walls} | "
              f"{n / wall:.1f} | {base / wall:.2f}x | {loads} | "
              f"{db.stat().st_size / 1e6:.1f} | {same} |")
    print("(from the command's start to its exit: imports, cluster start-up, hashing, reading, "
          "writing, each pack's figures)")
    print(machine_line(), f"; load average at the end {os.getloadavg()[0]:.2f}")
    if not opts.keep:
        shutil.rmtree(work)
    if not opts.no_formats:
        per_format_costs()


#: One shared file of each format the logbook reads (docs/fleet.md extrapolates from them).
FORMAT_FILES = [
    ("samsung30q_ageing_cellC/DischargeCycle100.txt", "LabVIEW text"),
    ("flight_logs/ina3221_fpv_4s/29.csv", "in-flight INA3221 CSV"),
    ("flight_logs/px4_ulog_rs/esc_status_log.ulg", "PX4 ULog"),
    ("flight_logs/pyulog_sample/sample_log_small.ulg", "PX4 ULog"),
    ("flight_logs/ardupilot_loganalyzer/mechanical_fail.log", "ArduPilot DataFlash text"),
    ("flight_logs/betaflight_diatone/btfl_001.bbl", "Betaflight blackbox"),
]


def per_format_costs(repeats: int = 3) -> None:
    """What one file costs a worker (read, split, summarise, compress), median of runs."""
    from dischargelab.logbook.summarise import summarise_source

    data = shared_data()
    print("\nOne file's task, one core (summarise_source: read, split into events, summarise, "
          "compress), median of", repeats)
    print("| file | format | size [MB] | events | time [ms] | per MB [ms] | kept bytes / size |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for relative, label in FORMAT_FILES:
        path = data / relative
        if not path.is_file():
            print(f"| {path.name} | {label} | missing | | | | |")
            continue
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            summary = summarise_source(path)
            times.append(time.perf_counter() - t0)
        size_MB = path.stat().st_size / 1e6
        ms = 1000 * sorted(times)[len(times) // 2]
        print(f"| {path.name} | {label} | {size_MB:.2f} | {len(summary.events)} | {ms:.0f} | "
              f"{ms / size_MB:.0f} | {len(summary.raw_zlib) / (1e6 * size_MB):.2f} |")


if __name__ == "__main__":
    start = time.perf_counter()
    main()
    print(f"benchmark took {time.perf_counter() - start:.0f} s")
