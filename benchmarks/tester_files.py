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

Table 3, the logbook's events of each tester file against the tester's own steps:
the tester's discharge and charge steps, its runs of them (a CC then a CV charge is one
charge), the logbook's discharge and charge events, whether the sequence of kinds is
the tester's, and the largest difference between an event's discharged charge and the
tester's for the same steps, by its counter and by its records (the current over the
step's time, as the tester counts it). The acceptance: events equal to the tester's runs
of steps on every file, capacities within 1 % of the records' count.

Table 4, the DJI M100 flights (``../shared/data/dji_m100_flights``): events and EFC
of its raw logs alone against the whole folder (raw logs plus their CSV exports), and
the files skipped as copies. The acceptance: the same within 5 %.

Table 5, small full cells of known truth (built here, seeded): a cell of 3.179 Ah,
mAh and uAh, cycled at C/5 (rest, discharge, rest, CC charge, CV charge whose current
decays, rest; three cycles), written as a tester's CSV export with its step and cycle
numbers or as bare records (time, voltage, current in mA), each recorded every 30 s or
sparsely (every second for 30 s after a step starts, then every 300 s, as a tester
logging a flat curve by voltage change). The logbook's discharges, charges and gaps
against the truth, and the largest error of a discharge's charge. The acceptance: three
discharges and three charges, no gap, each discharge within 1 %, at every scale.

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

from _machine import machine_line, shared_data  # noqa: E402
from dischargelab.errors import DischargelabError  # noqa: E402
from dischargelab.io.cyclers import full_discharges, read_tester  # noqa: E402
from dischargelab.io.flightlog import read_flight_log  # noqa: E402


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
        fulls = full_discharges(tester.steps)
        if not fulls:
            rows.append(f"| {path.name} | {tester.meta['format']} | | {len(tester.frame)} | "
                        f"{len(tester.steps)} | no full discharge | | | | {elapsed:.2f} |")
            continue
        first = fulls[0]
        diff = 100.0 * (first["charge_Ah"] / first["tester_Ah"] - 1.0)
        rows.append(
            f"| {path.name} | {tester.meta['format']} | {tester.meta['reader'].split(' (')[0]} "
            f"| {len(tester.frame)} | {len(tester.steps)} | step {first['number']} (cycle "
            f"{first['cycle']}), {first['mode']} {first['mean_current_A']:.4g} A | "
            f"{1e3 * first['charge_Ah']:.5g} | {1e3 * first['tester_Ah']:.5g} | "
            f"{diff:+.4f} % | {elapsed:.2f} |")
    return rows


def tester_runs(steps: list[dict]) -> list[dict]:
    """The tester's steps as events: consecutive steps of one kind are one run."""
    runs: list[dict] = []
    for step in steps:
        moved = step["tester_Ah"] if step.get("tester_Ah") is not None else step["charge_Ah"]
        if runs and runs[-1]["kind"] == step["kind"]:
            runs[-1]["Ah"] += moved
            runs[-1]["counted_Ah"] += step["charge_Ah"]
            runs[-1]["steps"] += 1
        else:
            runs.append({"kind": step["kind"], "Ah": moved, "counted_Ah": step["charge_Ah"],
                         "steps": 1})
    return runs


def events_table(folder: Path) -> tuple[list[str], bool]:
    from dischargelab.logbook.summarise import summarise_source

    rows = ["| file | tester's discharge / charge steps | tester's runs (discharge / charge "
            "/ rest) | logbook events (discharge / charge / rest) | same kinds in order | "
            "first discharge: tester [mAh] | logbook [mAh] | largest difference from the "
            "tester's counter | largest difference from the tester's records |",
            "|---|---|---|---|---|---|---|---|---|"]
    ok = True
    for path in sorted(p for p in folder.glob("*/*") if p.parent.name != "LICENSES"):
        try:
            tester = read_tester(path)
            summary = summarise_source(path, keep_raw=False)
        except DischargelabError as exc:
            rows.append(f"| {path.name} | {exc} | | | | | | |")
            ok = False
            continue
        steps = tester.steps
        runs = tester_runs(steps)
        events = [e for e in summary.events if e["kind"] != "gap"]
        count = lambda items, kind: sum(1 for x in items if x["kind"] == kind)  # noqa: E731
        same = [r["kind"] for r in runs] == [e["kind"] for e in events]
        pairs = [(r["Ah"], e.get("discharged_Ah") or 0.0, r["counted_Ah"])
                 for r, e in zip(runs, events)
                 if same and r["kind"] == "discharge" and r["Ah"] > 0 and r["counted_Ah"] > 0]
        worst = max((abs(b / a - 1.0) for a, b, _ in pairs), default=float("nan"))
        # the records' own count: a file whose clock is rounded to 0.1 s cannot give a 2 s
        # step's charge to better than a few per cent, however it is counted
        worst_records = max((abs(b / c - 1.0) for _, b, c in pairs), default=float("nan"))
        ok = ok and same and (not pairs or worst_records <= 0.01)
        first = pairs[0] if pairs else (float("nan"), float("nan"), float("nan"))
        rows.append(
            f"| {path.name} | {count(steps, 'discharge')} / {count(steps, 'charge')} | "
            f"{count(runs, 'discharge')} / {count(runs, 'charge')} / {count(runs, 'rest')} | "
            f"{count(events, 'discharge')} / {count(events, 'charge')} / "
            f"{count(events, 'rest')} | {'yes' if same else 'NO'} | {1e3 * first[0]:.5g} | "
            f"{1e3 * first[1]:.5g} | {100 * worst:.2f} % | {100 * worst_records:.2f} % |")
    return rows, ok


def dji_table(folder: Path, scratch: Path) -> tuple[list[str], bool]:
    from dischargelab.logbook import Logbook

    rows = ["| files added | files | events | flights | EFC | skipped as copies |",
            "|---|---|---|---|---|---|"]
    found = {}
    for label, paths in (("raw logs alone", sorted(folder.glob("raw_*"))),
                         ("whole folder", [folder])):
        with Logbook(scratch / f"{label.replace(' ', '_')}.sqlite") as book:
            result = book.add(paths, pack="M100")
            health = book.health("M100").to_dict()
        flights = sum(1 for e in health["events"] if e["kind"] == "flight")
        found[label] = (result.events, flights, health["efc_now"] or 0.0)
        copies = "; ".join(name for name, _ in result.copies) or "-"
        rows.append(f"| {label} | {len(result.added)} | {result.events} | {flights} | "
                    f"{health['efc_now']:.2f} | {copies} |")
    (e1, f1, c1), (e2, f2, c2) = found.values()
    ok = e1 == e2 and f1 == f2 and abs(c2 / c1 - 1.0) <= 0.05
    return rows, ok


def small_cell(path: Path, capacity_Ah: float, steps: bool, sparse: bool,
               seed: int = 0) -> list[float]:
    """Write a small cell's test (Table 5); returns each discharge's charge [Ah]."""
    rng = np.random.default_rng(seed)
    rate = capacity_Ah / 5
    rows, moved, state = [], [], {"clock": 0.0, "charge": capacity_Ah}

    def step(duration, amps, number, cycle, cv=False):
        times = [*np.arange(0.0, min(30.0, duration)),
                 *np.arange(30.0, duration, 300.0 if sparse else 30.0), duration]
        last, before = 0.0, state["charge"]
        for s in times:
            now = -rate / 2 * np.exp(-s / 1200.0) if cv else amps
            state["charge"] -= now * (s - last) / 3600
            last = s
            soc = min(max(state["charge"] / capacity_Ah, 0.0), 1.0)
            volts = 3.0 + 1.2 * soc - 0.15 * np.exp(-25 * soc) - now * 0.16 / capacity_Ah
            current = now + rng.normal(0.0, abs(now) * 1e-3 + capacity_Ah * 1e-5)
            rows.append((state["clock"] + s, volts + rng.normal(0, 2e-4), 1e3 * current,
                         cycle, number))
        state["clock"] += duration + 1.0
        return before - state["charge"]

    step(3600, 0.0, 1, 1)
    for cycle in (1, 2, 3):
        moved.append(step(0.97 * 5 * 3600, rate, 2, cycle))
        step(1800, 0.0, 3, cycle)
        step(0.9 * 5 * 3600, -rate, 4, cycle)
        step(3600, 0.0, 5, cycle, cv=True)
        step(1800, 0.0, 6, cycle)
    head = "Test_Time(s),Voltage(V),Current(mA),Cycle_Index,Step_Index" if steps \
        else "time_s,voltage_V,current_mA"
    body = [f"{t:.1f},{v:.5f},{i:.7g}" + (f",{c},{n}" if steps else "")
            for t, v, i, c, n in rows]
    path.write_text("\n".join([head, *body]) + "\n")
    return moved


def small_cells_table(scratch: Path) -> tuple[list[str], bool]:
    from dischargelab.logbook.summarise import summarise_source

    rows = ["| cell | step numbers | records | discharges | charges | gaps | largest "
            "discharge error |", "|---|---|---|---|---|---|---|"]
    ok = True
    for capacity, label in ((3.179, "3.179 Ah"), (3.179e-3, "3.179 mAh"),
                            (3.179e-6, "3.179 uAh")):
        for steps in (True, False):
            for sparse in (False, True):
                path = scratch / f"small_{int(steps)}{int(sparse)}.csv"
                truth = small_cell(path, capacity, steps, sparse)
                try:
                    events = summarise_source(path, keep_raw=False).events
                except DischargelabError as exc:
                    rows.append(f"| {label} | {'yes' if steps else 'no'} | "
                                f"{'sparse' if sparse else 'every 30 s'} | {exc} | | | |")
                    ok = False
                    continue
                found = {k: [e for e in events if e["kind"] == k]
                         for k in ("discharge", "charge", "gap")}
                worst = max((abs(e["discharged_Ah"] / t - 1.0) for e, t in
                             zip(found["discharge"], truth)), default=float("nan"))
                good = (len(found["discharge"]) == len(truth) == len(found["charge"])
                        and not found["gap"] and worst <= 0.01)
                ok = ok and good
                rows.append(f"| {label} | {'yes' if steps else 'no'} | "
                            f"{'sparse' if sparse else 'every 30 s'} | "
                            f"{len(found['discharge'])} of {len(truth)} | "
                            f"{len(found['charge'])} of {len(truth)} | {len(found['gap'])} | "
                            f"{100 * worst:.2f} % |")
    return rows, ok


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
    parser.add_argument("--data", type=Path, default=shared_data())
    args = parser.parse_args(argv)
    print("Battery testers' files: first full discharge, charge by the current vs the "
          "tester's counter\n")
    print("\n".join(tester_table(args.data / "cyclers")))
    print("\nTelemetry logs (.tlog): charge by the current vs the log's current_consumed\n")
    with tempfile.TemporaryDirectory(prefix="dischargelab-bench-") as scratch:
        print("\n".join(tlog_table(args.data / "flight_logs" / "mavlink_tlog", Path(scratch))))
        print("\nLogbook events of each tester file vs the tester's own steps\n")
        rows, ok = events_table(args.data / "cyclers")
        print("\n".join(rows))
        print(f"\nevents equal to the tester's steps, capacity within 1 %: "
              f"{'met' if ok else 'NOT met'}")
        print("\nDJI M100 flights: raw logs alone vs the whole folder (raw logs and their "
              "CSV exports)\n")
        rows, ok = dji_table(args.data / "dji_m100_flights", Path(scratch))
        print("\n".join(rows))
        print(f"\nsame events, flights and EFC within 5 %: {'met' if ok else 'NOT met'}")
        print("\nSmall full cells of known truth: the logbook's events at every scale\n")
        rows, ok = small_cells_table(Path(scratch))
        print("\n".join(rows))
        print(f"\nevery cell's discharges and charges, no gap, within 1 %: "
              f"{'met' if ok else 'NOT met'}")
    print(f"\n{machine_line()}; load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
