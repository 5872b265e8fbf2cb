"""What the testers' readers and the telemetry-log reader get from the shared real files.

Table 1, battery testers' files (``../shared/data/cyclers``): for each file its
format and reader, records, steps, the first full discharge (from a charge to
the lower voltage limit), the charge of that step counted from the current
(trapezoid, from the end of the step before) against the tester's own capacity
counter, and the read time. The acceptance: every file reads, and the two
agree within 0.1 %.

Table 2, telemetry logs (``../shared/data/flight_logs/mavlink_tlog``): flights,
charge by the current against the log's consumed-charge counter
(``current_consumed``), corrupt messages, sessions and read time; then the same
for files built in a temporary folder from the shared ones: two recordings
joined (the clock going back), and bytes flipped at random (seeded). The
acceptance: within 1 % of the counter, or one counter step (1 mAh) for a log
whose whole flight is 30 mAh.

Usage: python benchmarks/tester_files.py [--data ../shared/data]
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from _machine import machine_line  # noqa: E402
from dischargelab.errors import DischargelabError  # noqa: E402
from dischargelab.io.cyclers import full_discharges, read_tester  # noqa: E402
from dischargelab.io.flightlog import read_flight_log  # noqa: E402


def _default_data() -> Path:
    for parent in [ROOT, *ROOT.parents]:
        if (parent / "shared" / "data" / "cyclers").is_dir():
            return parent / "shared" / "data"
    return ROOT.parent / "shared" / "data"


def tester_table(folder: Path) -> list[str]:
    rows = ["| file | format | reader | records | steps | first full discharge | charge by "
            "current [mAh] | tester's counter [mAh] | difference | read [s] |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for path in sorted(p for p in folder.glob("*/*") if p.parent.name != "LICENSES"):
        start = time.perf_counter()
        try:
            tester = read_tester(path)
        except DischargelabError as exc:
            rows.append(f"| {path.name} | - | - | - | - | {exc} | | | | |")
            continue
        elapsed = time.perf_counter() - start
        first = full_discharges(tester.steps)[0]
        diff = 100.0 * (first["charge_Ah"] / first["tester_Ah"] - 1.0)
        rows.append(
            f"| {path.name} | {tester.meta['format']} | {tester.meta['reader'].split(' (')[0]} "
            f"| {len(tester.frame)} | {len(tester.steps)} | step {first['number']} (cycle "
            f"{first['cycle']}), {first['mode']} {first['mean_current_A']:.4g} A | "
            f"{1e3 * first['charge_Ah']:.5g} | {1e3 * first['tester_Ah']:.5g} | "
            f"{diff:+.4f} % | {elapsed:.2f} |")
    return rows


def _tlog_row(label: str, path: Path) -> str:
    start = time.perf_counter()
    try:
        log = read_flight_log(path)
    except DischargelabError as exc:
        return f"| {label} | {exc} | | | | | | |"
    elapsed = time.perf_counter() - start
    cells = []
    for series in log.batteries:
        charge, counter = series.charge_mAh(), series.counter_mAh()
        diff = "-" if not counter else f"{100.0 * (charge / counter - 1.0):+.2f} %"
        cells.append((series.label, charge, counter, diff))
    sessions = max(int(b.frame["session"].max()) for b in log.batteries if b.rows)
    return (f"| {label} | {len(log.spans)} | "
            + "; ".join(f"{c[1]:.1f}" for c in cells) + " | "
            + "; ".join("-" if c[2] is None else f"{c[2]:.0f}" for c in cells) + " | "
            + "; ".join(c[3] for c in cells)
            + f" | {log.skipped.get('corrupt_messages', 0)} | {sessions} | {elapsed:.2f} |")


def tlog_table(folder: Path, scratch: Path) -> list[str]:
    rows = ["| file | flights | charge by current [mAh] | log's counter [mAh] | difference | "
            "corrupt messages | sessions | read [s] |", "|---|---|---|---|---|---|---|---|"]
    for path in sorted(folder.glob("*.tlog")):
        rows.append(_tlog_row(path.name, path))
    olivieri = (folder / "olivieri_20211202-132614.tlog").read_bytes()
    joined = scratch / "joined.tlog"
    joined.write_bytes(olivieri + olivieri)
    rows.append(_tlog_row("olivieri twice, joined (clock goes back)", joined))
    both = scratch / "two_vehicles.tlog"
    both.write_bytes((folder / "thayer_rural.tlog").read_bytes()
                     + (folder / "ardusub_small.tlog").read_bytes())
    rows.append(_tlog_row("thayer + ardusub joined (one system id)", both))
    for flips in (100, 1000):
        data = bytearray(olivieri)
        for position in np.random.default_rng(flips).integers(0, len(data), flips):
            data[position] ^= 0xFF
        damaged = scratch / f"flipped_{flips}.tlog"
        damaged.write_bytes(bytes(data))
        rows.append(_tlog_row(f"olivieri, {flips} bytes flipped (seeded)", damaged))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=_default_data())
    args = parser.parse_args(argv)
    print("Battery testers' files: first full discharge, charge by the current vs the "
          "tester's counter\n")
    print("\n".join(tester_table(args.data / "cyclers")))
    print("\nTelemetry logs (.tlog): charge by the current vs the log's current_consumed\n")
    with tempfile.TemporaryDirectory(prefix="dischargelab-bench-") as scratch:
        print("\n".join(tlog_table(args.data / "flight_logs" / "mavlink_tlog", Path(scratch))))
    print(f"\n{machine_line()}; load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
