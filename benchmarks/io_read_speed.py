"""Reading speed of ``read_discharge`` on the real data sets and on a large written file.

Goal: the 35 605-row Samsung C/10 file reads (parse, checks, segment) well
under a second. Each file is read ``--repeats`` times; the table shows the
fastest and the median wall-clock time. The large file is a written
constant-current discharge of ``--rows`` rows (comma separated, with header).

Usage: python benchmarks/io_read_speed.py [--repeats N] [--rows N]
"""

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line, shared_data
from dischargelab.io import read_discharge

ROOT = Path(__file__).resolve().parents[1]
SHARED = shared_data()
COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"


def cases(shared: Path):
    yield "Samsung 30Q C/10 (csv)", shared / "samsung30q_S001" / "Q30_S001_C10.csv", {
        "columns": COLUMNS}
    yield "Samsung 30Q 1C (csv)", shared / "samsung30q_S001" / "Q30_S001_1C.csv", {
        "columns": COLUMNS}
    yield "Enertech 0.1C (tsv, --current)", shared / "enertech_lco" / "0.1C_discharge_U.txt", {
        "current_A": 0.228}
    yield "K2 LFP 20 degC (lvm)", shared / "k2_lfp26650" / "K2_Discharge_Test_20C.txt", {
        "columns": COLUMNS}
    yield "DJI raw log (8 flights)", (shared / "dji_m100_flights"
                                      / "raw_19-11-28_waddle1_2019_11_28_18_28.txt"), {}


def time_read(path, options, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        frame, _ = read_discharge(path, **options)
        times.append(time.perf_counter() - start)
    return len(frame), min(times), statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--rows", type=int, default=1_000_000)
    args = parser.parse_args()

    rows = []
    for label, path, options in cases(SHARED):
        if not path.exists():
            print(f"skipped (not found): {path}", file=sys.stderr)
            continue
        kept, best, median = time_read(path, options, args.repeats)
        rows.append((label, path.stat().st_size / 1e6, kept, best, median))
    with tempfile.TemporaryDirectory() as folder:
        big = Path(folder) / "big.csv"
        t = 0.1 * np.arange(args.rows)
        v = 4.1 - 1.5 * t / max(t[-1], 1.0)
        np.savetxt(big, np.c_[t, v, np.full(args.rows, 2.0)], delimiter=",", fmt="%.5f",
                   header="time_s,voltage_V,current_A", comments="")
        kept, best, median = time_read(big, {}, max(1, args.repeats // 3))
        rows.append((f"written csv, {args.rows} rows", big.stat().st_size / 1e6, kept, best,
                     median))

    print(f"{'file':<34} {'MB':>7} {'rows kept':>10} {'best ms':>9} {'median ms':>10}")
    for label, size, kept, best, median in rows:
        print(f"{label:<34} {size:7.2f} {kept:10d} {best * 1e3:9.1f} {median * 1e3:10.1f}")
    print(machine_line())


if __name__ == "__main__":
    main()
