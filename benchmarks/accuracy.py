"""Accuracy: fit each real cell at one rate (and at several), predict every other rate.

For each real multi-rate set in ../shared/data the model is fitted on one rate,
on the lowest + highest rate, and (Samsung 30Q) on C/10 + 1C + 4C; every
measured rate is then predicted with its measured current and compared:
measured vs predicted time to the cutoff, endurance error [%], voltage RMS error
[%] over the curve and over the operational part (state of charge > 20 %), and
the largest voltage error in the operational part.

Usage: python benchmarks/accuracy.py [--data ../shared/data] [--sets samsung,enertech]
"""

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line  # noqa: E402

from dischargelab.fit import Curve, fit_battery  # noqa: E402
from dischargelab.io import read_discharge  # noqa: E402
from dischargelab.validate import validate_discharge  # noqa: E402

SAMSUNG_COLUMNS = {"time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4}

#: name -> (folder, cutoff per cell [V], [(rate label, file, read options)], extra fits)
SETS = {
    "samsung": ("samsung30q_S001", 2.5, [
        (rate, f"Q30_S001_{rate.replace('/', '')}.csv", {"columns": SAMSUNG_COLUMNS})
        for rate in ("C10", "1C", "2C", "3C", "4C")], [("C10", "1C", "4C")]),
    "enertech": ("enertech_lco", 3.0, [
        (f"{c}C", f"{c}C_discharge_U.txt", {"current_A": c * 2.28})
        for c in (0.1, 0.5, 1, 2)], []),
}


def default_data_dir() -> Path:
    env = os.environ.get("DISCHARGELAB_SHARED_DATA")
    if env:
        return Path(env)
    here = Path(__file__).resolve()
    for parent in here.parents:
        if (parent / "shared" / "data").is_dir():
            return parent / "shared" / "data"
    return here.parents[2] / "shared" / "data"


def load_set(data_dir: Path, name: str):
    folder, cutoff, files, extra = SETS[name]
    loaded = {}
    for rate, filename, options in files:
        data, meta = read_discharge(data_dir / folder / filename, **options)
        loaded[rate] = (data, meta, Curve.from_frame(data, meta, name=rate))
    return loaded, cutoff, extra


def evaluate(name, loaded, cutoff, extra):
    rates = list(loaded)
    trainings = [(r,) for r in rates] + [(rates[0], rates[-1])] + list(extra)
    rows = []
    for train in trainings:
        t0 = time.perf_counter()
        res = fit_battery([loaded[r][2] for r in train])
        fit_ms = (time.perf_counter() - t0) * 1000
        for rate in rates:
            data, meta, _ = loaded[rate]
            v = validate_discharge(res.battery, data, meta, cutoff_cell_V=cutoff)
            rows.append({"set": name, "train": " + ".join(train), "test": rate,
                         "fitted": rate in train, "fit_ms": fit_ms, **v})
    return rows


def fmt(x, spec):
    return "n/a" if x is None else format(x, spec)


def print_table(rows):
    print("| set | fitted on | rate | current [A] | measured [s] | predicted [s] | "
          "endurance error | V RMSE | V RMSE SOC>20% | V max SOC>20% |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        mark = " (fit)" if r["fitted"] else ""
        print(f"| {r['set']} | {r['train']} | {r['test']}{mark} | {r['current_A']:.3g} | "
              f"{fmt(r['endurance_measured_s'], '.0f')} | "
              f"{fmt(r['endurance_predicted_s'], '.0f')} | "
              f"{fmt(r['endurance_error_pct'], '+.2f')} % | {r['voltage_rmse_pct']:.2f} % | "
              f"{r['voltage_rmse_operational_pct']:.2f} % | "
              f"{r['voltage_max_error_operational_pct']:.2f} % |")


def check_targets(rows):
    def err(train, test):
        for r in rows:
            if r["set"] == "samsung" and r["train"] == train and r["test"] == test:
                return r["endurance_error_pct"]
        return None

    lines = []
    triple = [err("C10 + 1C + 4C", t) for t in ("C10", "1C", "2C", "3C", "4C")]
    if all(e is not None for e in triple):
        worst = max(abs(e) for e in triple)
        lines.append(f"- Samsung 30Q fitted on C/10 + 1C + 4C: worst endurance error "
                     f"{worst:.2f} % at the five rates (target < 3 %): "
                     f"{'met' if worst < 3 else 'NOT met'}")
    e2 = err("1C", "2C")
    if e2 is not None:
        lines.append(f"- Samsung 30Q fitted on 1C alone, predicted at 2C: {e2:+.2f} % "
                     f"(target within 5 %): {'met' if abs(e2) < 5 else 'NOT met'}; "
                     f"at 4C: {err('1C', '4C'):+.2f} %")
    others = [r for r in rows if not r["fitted"]]
    if others:
        errs = [abs(r["endurance_error_pct"]) for r in others
                if r["endurance_error_pct"] is not None]
        op = [r["voltage_rmse_operational_pct"] for r in others]
        lines.append(f"- all predictions of rates not in the fit: endurance error median "
                     f"{sorted(errs)[len(errs) // 2]:.2f} %, max {max(errs):.2f} %; voltage RMSE "
                     f"(SOC > 20 %) max {max(op):.2f} % (paper: 0.5-6.3 % endurance, < 2 % "
                     f"voltage)")
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=default_data_dir())
    parser.add_argument("--sets", default=",".join(SETS))
    args = parser.parse_args(argv)
    rows = []
    for name in args.sets.split(","):
        loaded, cutoff, extra = load_set(args.data, name)
        rows += evaluate(name, loaded, cutoff, extra)
    print_table(rows)
    print()
    for line in check_targets(rows):
        print(line)
    print(f"\nMachine: {machine_line()}")


if __name__ == "__main__":
    main()
