"""Fleet-scale ingest: files per second in process and on Dask workers, client memory, cost.

The 68 cell C cycle files of ../shared/data/samsung30q_ageing_cellC copied under
several pack folders (default 9: 612 files), each copy changed by trailing newlines
so that its SHA-256 differs, are added to fresh SQLite logbooks:

1. in process (``--workers 1``, no Dask);
2. on a local Dask cluster of 2 worker processes (``--workers 2``), and more if asked.

Each run is its own process (what ``dischargelab logbook add --workers N`` runs), so its
peak memory (the client: hashing, the scheduler thread, the database writes) is measured
alone from ``getrusage`` of that process. The events stored are compared with the in-process
run's. The table gives files per second (wall clock, cluster start included),
speed-up against one worker, the client's peak RSS, and the costs per file and per
event that docs/fleet.md extrapolates from.

Usage: python benchmarks/fleet.py [--packs N] [--workers 2,...] [--keep DIR] [--no-formats]
       [--repeats N]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line

ROOT = Path(__file__).resolve().parents[1]
CELL_C = ROOT.parent / "shared" / "data" / "samsung30q_ageing_cellC"

#: One ingest in a child process (what ``logbook add --workers N`` runs): prints, as JSON,
#: the wall time, the time of each file's completion, and the child's peak RSS and CPU time
#: (the client alone: Dask workers are other processes).
CHILD = """
import json, resource, sys, time
start = time.perf_counter()
from dischargelab.fleet import executor
from dischargelab.logbook import Logbook
folder, db, workers = sys.argv[1], sys.argv[2], int(sys.argv[3])
done_at = []
with Logbook(db) as lb, executor(workers=workers) as ex:
    ready = time.perf_counter()
    result = lb.add(folder, pack_from="parent", recursive=True, executor=ex,
                    progress=lambda done, total, name: done_at.append(time.perf_counter()))
wall = time.perf_counter() - start
usage = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"wall_s": wall, "ready_s": ready - start,
                  "done_at": [t - start for t in done_at], "added": len(result.added),
                  "rejected": result.rejected, "peak_rss_MB": usage.ru_maxrss / 1024,
                  "cpu_s": usage.ru_utime + usage.ru_stime}))
"""


def make_packs(root: Path, packs: int) -> int:
    files = sorted(CELL_C.glob("DischargeCycle*.txt"))
    for k in range(packs):
        folder = root / f"pack-{k + 1:02d}"
        folder.mkdir(parents=True)
        for f in files:
            (folder / f.name).write_bytes(f.read_bytes() + b"\n" * (k + 1))
    return packs * len(files)


def add(folder: Path, db: Path, workers: int) -> dict:
    proc = subprocess.run([sys.executable, "-c", CHILD, str(folder), str(db), str(workers)],
                          capture_output=True, text=True, timeout=3600)
    if proc.returncode:
        raise SystemExit(f"ingest failed: {proc.stderr[-2000:]}")
    stats = json.loads(proc.stdout.strip().splitlines()[-1])
    done = stats["done_at"]
    # steady state: the middle 80 % of the files (start-up and the last stragglers left out)
    a, b = len(done) // 10, len(done) - len(done) // 10 - 1
    stats["steady_files_per_s"] = (b - a) / (done[b] - done[a])
    return stats


def events(db: Path) -> dict:
    from dischargelab.logbook import Logbook

    with Logbook(str(db)) as lb:
        return {(name, r["source"], r["idx"]): {k: v for k, v in r.items() if k != "id"}
                for name in lb.pack_names() for r in lb.events(name).to_dict()["events"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--packs", type=int, default=9, help="pack folders (68 files each)")
    parser.add_argument("--workers", default="2", help="worker counts to try, e.g. 2,4")
    parser.add_argument("--keep", type=Path, help="keep the files and databases here")
    parser.add_argument("--no-formats", action="store_true",
                        help="skip the per-format cost of one file")
    parser.add_argument("--repeats", type=int, default=3,
                        help="runs per file for the per-format cost (median)")
    opts = parser.parse_args()
    if not CELL_C.is_dir():
        raise SystemExit(f"needs {CELL_C}")
    work = Path(opts.keep or tempfile.mkdtemp(prefix="dischargelab-fleet-"))
    folder = work / "packs"
    if folder.exists():
        shutil.rmtree(folder)
    n = make_packs(folder, opts.packs)
    size_MB = sum(p.stat().st_size for p in folder.rglob("*.txt")) / 1e6
    runs = []
    for workers in [1] + [int(w) for w in opts.workers.split(",")]:
        db = work / f"logbook-{workers}.sqlite"
        db.unlink(missing_ok=True)
        stats = add(folder, db, workers)
        stats.update(workers=workers, db=db, db_MB=db.stat().st_size / 1e6)
        runs.append(stats)
    reference = events(runs[0]["db"])
    base = runs[0]
    n_events = len(reference)
    print(f"Fleet ingest: {n} files ({size_MB:.0f} MB, {n_events} events) in {opts.packs} "
          f"pack folders")
    print("| workers | wall [s] | files/s (whole run) | speed-up | files/s (steady) | speed-up "
          "| client peak RSS [MB] | client CPU [s] | database [MB] | events identical |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for r in runs:
        same = "reference" if r is base else ("yes" if events(r["db"]) == reference else "NO")
        assert r["added"] == n and not r["rejected"], (r["added"], n, r["rejected"][:3])
        print(f"| {r['workers']} | {r['wall_s']:.1f} | {n / r['wall_s']:.1f} | "
              f"{base['wall_s'] / r['wall_s']:.2f}x | {r['steady_files_per_s']:.1f} | "
              f"{r['steady_files_per_s'] / base['steady_files_per_s']:.2f}x | "
              f"{r['peak_rss_MB']:.0f} | {r['cpu_s']:.1f} | {r['db_MB']:.1f} | {same} |")
    print("(whole run: from the command's start, imports and cluster start-up included; "
          "steady: the middle 80 % of the files)")
    per_file_ms = 1000 * base["wall_s"] / n
    print(f"\nin process: {per_file_ms:.1f} ms per file, {1000 * base['wall_s'] / n_events:.1f} "
          f"ms per event (read, summarise, hash, compress, write); database "
          f"{1000 * base['db_MB'] / n:.0f} kB per file ({base['db_MB'] / size_MB:.2f} of the "
          f"raw size, the raw file kept compressed)")
    print(machine_line(), f"; load average at the end {os.getloadavg()[0]:.2f}")
    if not opts.keep:
        shutil.rmtree(work)
    if not opts.no_formats:
        per_format_costs(opts.repeats)


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

    data = CELL_C.parent
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
