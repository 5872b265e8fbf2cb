"""The on-board script against the time actually left, beside what a pilot has today.

For each case a pack model (a preset) is flown through the one engine
(:mod:`dischargelab.simulate`) to its cutoff: a constant current (2C), a stepped flight (10
s at 1.5C and 5 s at 3C in turn, to the cutoff: the 30 s mean is 2C), and a hover to empty
at constant power (1C, 3C and 5C of the rated capacity at the start). The readings
ArduPilot's battery monitor would give (voltage, current, consumed mAh every 200 ms, 5 s at
rest first) are replayed through the generated script in a real ``lua5.3`` with the stand-in
of the bindings (``tests/ardupilot_standin.lua``). At 25, 50, 75 and 90 % of the time to
cutoff it prints ``DL_TREM`` minus the time actually left, in % of the flight's time to
cutoff, beside:

* label: the label-capacity coulomb count (rated capacity minus the consumed charge, over
  the same 30 s mean current), what ``BATT_CAPACITY`` and the counted mAh give;
* px4: PX4's voltage-based estimate with its defaults (``BAT1_V_EMPTY`` 3.6 V,
  ``BAT1_V_CHARGED`` 4.05 V, 5 mOhm per cell load compensation; see
  ``dischargelab.flight.replay``) times the label capacity over the same current.

and the largest instruction count of one call and the heap after a full collection.

Usage: python benchmarks/onboard.py [--quick] [--skip-real]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from _machine import shared_data as _shared_data  # noqa: E402
from ardupilot_replay import lua, replay  # noqa: E402
from dischargelab import autopilot_script  # noqa: E402
from dischargelab.engine import Step  # noqa: E402
from dischargelab.flight.replay import (  # noqa: E402
    PX4_R_INTERNAL_OHM,
    PX4_V_CHARGED,
    PX4_V_EMPTY,
)
from dischargelab.model import load_battery  # noqa: E402
from dischargelab.onboard import RECENT_LOAD_S, flight_samples  # noqa: E402
from dischargelab.predict import default_cutoff  # noqa: E402
from dischargelab.simulate import simulate  # noqa: E402

FRACTIONS = (0.25, 0.5, 0.75, 0.9)
REST_S = 5.0

#: (preset, cells in series of the flight pack)
PACKS = (("zippy-1100-2s", 3), ("nanotech-1700-2s", 4), ("hacker-4100-4s-lifepo4", 4))


def cases(bat, quick: bool):
    rated = bat.rated_capacity_Ah
    nominal_V = float(bat.voltage(0.0, 0.5 * bat.capacity_Ah))
    out = [("constant 2C", [Step("current", 2.0 * rated)]),
           ("stepped", [Step("current", 1.5 * rated, 10.0), Step("current", 3.0 * rated, 5.0)]
            * 400)]
    for c in ((3.0,) if quick else (1.0, 3.0, 5.0)):
        out.append((f"hover {c:g}C", [Step("power", c * rated * nominal_V)]))
    return out


def errors_at(t, i, v_cell, used_Ah, total, rep, label_Ah, step_s=None):
    """Per fraction of the flight ``total`` [s]: (DL_TREM, label count, PX4) minus the time
    left, % of the flight. ``t``, ``i``, ``v_cell``, ``used_Ah``: the flight's time [s],
    pack current [A], cell voltage [V] and charge used [Ah]; the recent load is averaged on
    a grid of ``step_s`` (None: at the samples themselves)."""
    if step_s is None:
        grid, amps, volts = t, i, v_cell
    else:
        grid = np.arange(0.0, total, step_s)
        amps, volts = np.interp(grid, t, i), np.interp(grid, t, v_cell)
    ts, trem = rep.series("DL_TREM")
    rows = []
    for f in FRACTIONS:
        now = f * total
        left = total - now
        k = int(np.argmin(np.abs(ts - REST_S - now)))
        window = (grid > now - RECENT_LOAD_S) & (grid <= now)
        load = float(np.mean(amps[window]))
        label = max(label_Ah - float(np.interp(now, t, used_Ah)), 0.0) * 3600.0 / load
        recent = (grid > now - 1.0) & (grid <= now)
        cell = float(np.mean(volts[recent])) + PX4_R_INTERNAL_OHM * float(np.mean(amps[recent]))
        px4 = float(np.clip((cell - PX4_V_EMPTY) / (PX4_V_CHARGED - PX4_V_EMPTY), 0, 1)) \
            * label_Ah * 3600.0 / load
        rows.append(tuple(100.0 * (x - left) / total for x in (float(trem[k]), label, px4)))
    return rows


#: Held-out real drains: the Samsung 30Q cell of ``samsung30q_S001`` fitted as a user
#: would (``dl.fit``, automatic family) on its C/10 drain, the script replayed on its 1C,
#: 2C and 4C drains (3, 6, 12 A), cutoff 3.0 V, label capacity 3.0 Ah.
SAMSUNG = "samsung30q_S001"
SAMSUNG_COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
REAL_CUTOFF_V = 3.0


def shared_data() -> Path:
    """The shared real data (:func:`_machine.shared_data`), or exit saying where it was
    looked for."""
    data = _shared_data()
    if not (data / SAMSUNG).is_dir():
        raise SystemExit(f"{data} not found (set DISCHARGELAB_SHARED_DATA)")
    return data


def real_rows(d, rest_s: float = REST_S):
    """Battery-monitor readings of a measured drain: rest first, then every sample."""
    import dischargelab.discharge as discharge

    t, v, i = d.time_s - d.time_s[0], d.voltage_V, d.current_A
    used = np.concatenate([[0.0], np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t))]) / 3.6
    rest_v = d.rest_voltage_V if d.rest_voltage_V else float(v[0])
    rows = [(int(k * 200), False, rest_v, 0.0, 0.0) for k in range(int(rest_s / 0.2))]
    rows += [(int(round((rest_s + tk) * 1000)), True, float(vk), float(ik), float(qk))
             for tk, vk, ik, qk in zip(t, v, i, used)]
    total = discharge.measured_time_to_cutoff(t, v, REAL_CUTOFF_V)
    return rows, total, t, v, i, used / 1000.0


def real_drains(label_Ah: float = 3.0):
    import dischargelab as dl

    data = shared_data() / SAMSUNG
    slow = dl.read(data / "Q30_S001_C10.csv", columns=SAMSUNG_COLUMNS)
    model = dl.fit(slow, bootstrap=0, cells=1).battery
    script = autopilot_script(model, cells=1, cutoff=REAL_CUTOFF_V)
    for rate in ("1C", "2C", "4C"):
        d = dl.read(data / f"Q30_S001_{rate}.csv", columns=SAMSUNG_COLUMNS)
        rows, total, t, v, i, used = real_rows(d)
        rep = replay(script.text, rows)
        errs = errors_at(t, i, v, used, total, rep, label_Ah)
        yield "Samsung 30Q, C/10 model", f"real {rate}", total, errs, rep


#: Logged flights with a current sensor (INA3221 logger, 4S FPV): a model fitted on one
#: flight log (``dischargelab fit LOG --capacity 1.5``), the other replayed through the script
#: and through the Python replay of the same model (``dischargelab.flight``). No flight goes
#: to the cutoff, so the comparison is with the Python time left at the recent load.
FPV = "flight_logs/ina3221_fpv_4s"


def logged_flights():
    import subprocess
    import tempfile

    import dischargelab as dl
    from ardupilot_replay import against_python_replay
    from dischargelab.flight import analyse_flight

    logs = shared_data() / FPV
    for fitted, flown in (("28.csv", "29.csv"), ("29.csv", "28.csv")):
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "model.json"
            done = subprocess.run([sys.executable, "-m", "dischargelab", "fit",
                                   str(logs / fitted), "--capacity", "1.5", "--bootstrap", "0",
                                   "-o", str(path)], capture_output=True, text=True,
                                  timeout=600, check=False)
            if done.returncode:
                raise SystemExit(done.stderr.strip())
            bat = dl.load_battery(path)
        report = analyse_flight(logs / flown, bat, cutoff=3.3)
        script = autopilot_script(bat, cutoff=3.3)
        for flight in report.flights:
            worst, rep = against_python_replay(script.text, flight)
            yield f"{flown} flight {flight.number} (model of {fitted})", worst, rep


#: Logs whose autopilot recorded its own consumed-charge counter (ArduPilot DataFlash,
#: MAVLink telemetry), flown with packs of the Zippy 1100 mAh cells sized to about 3C.
COUNTER_LOGS = ("flight_logs/ardupilot_loganalyzer/mechanical_fail.log",
                "flight_logs/mavlink_tlog/olivieri_20211202-132614.tlog",
                "flight_logs/mavlink_tlog/thayer_rural.tlog")


def counter_flights():
    """The script fed the log's own charge counter, against the Python replay."""
    from ardupilot_replay import against_python_replay
    from dischargelab.flight import analyse_flight

    cell = load_battery("zippy-1100-2s")
    for rel in COUNTER_LOGS:
        path = shared_data() / rel
        for flight in analyse_flight(path, cell).flights:
            if flight.summary["load_start_s"] is None or flight.summary["mean_current_A"] < 1:
                continue
            parallel = max(1, round(flight.summary["mean_current_A"] / (3 * 1.1)))
            report = analyse_flight(path, cell, parallel=parallel, flights=flight.number)
            bat = cell.with_pack(report.cells_series, parallel)
            script = autopilot_script(bat, cutoff=report.cutoff_cell_V)
            worst, rep = against_python_replay(script.text, report.flights[0], counter=True)
            yield (f"{path.name} flight {flight.number} ({report.cells_series}S{parallel}P)",
                   worst, rep)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one hover rate only")
    parser.add_argument("--counter-logs-only", action="store_true",
                        help="only the logs with the autopilot's own charge counter")
    parser.add_argument("--skip-real", action="store_true",
                        help="leave out the held-out real drains (Samsung 30Q)")
    args = parser.parse_args(argv)
    if lua() is None:
        print("lua5.3 not found (make lua)")
        return 1
    if args.counter_logs_only:
        print_counter_logs()
        return 0
    head = (f"{'pack':<24} {'case':<12} {'min':>6} "
            + " ".join(f"{int(100 * f):>3}%: dl/label/px4" for f in FRACTIONS)
            + f" {'instr':>6} {'heap KB':>7}")
    print(head)
    worst = 0.0
    for preset, cells in PACKS:
        bat = load_battery(preset).with_pack(cells)
        cut = default_cutoff(bat)["cutoff_cell_V"]
        script = autopilot_script(bat, cells=cells, cutoff=cut)
        for name, steps in cases(bat, args.quick):
            sim = simulate(bat, steps, cutoff_cell_V=cut)
            rep = replay(script.text, flight_samples(sim, rest_s=REST_S))
            errs = errors_at(sim.time_s, sim.current_A, sim.voltage_V / cells, sim.charge_Ah,
                             sim.time_to_cutoff_s, rep, bat.rated_capacity_Ah, step_s=0.2)
            worst = max(worst, max(abs(e[0]) for e in errs))
            cols = " ".join(f"{e[0]:+6.1f}/{e[1]:+5.1f}/{e[2]:+6.1f}" for e in errs)
            print(f"{bat.name[:24]:<24} {name:<12} {sim.time_to_cutoff_s / 60:6.1f} {cols} "
                  f"{rep.max_instructions:6d} {rep.heap_kb:7.1f}")
    print(f"largest |DL_TREM - time left|: {worst:.1f} % of the flight (goal 3 %)")
    if args.skip_real:
        return 0
    real_worst = 0.0
    for pack, name, total, errs, rep in real_drains():
        real_worst = max(real_worst, max(abs(e[0]) for e in errs))
        cols = " ".join(f"{e[0]:+6.1f}/{e[1]:+5.1f}/{e[2]:+6.1f}" for e in errs)
        print(f"{pack[:24]:<24} {name:<12} {total / 60:6.1f} {cols} "
              f"{rep.max_instructions:6d} {rep.heap_kb:7.1f}")
    print(f"held-out real drains, largest |DL_TREM - time left|: {real_worst:.1f} % of the "
          "flight (goal 3 %)")
    print("logged flights: largest |DL_TREM - Python replay at the recent load|, % of the "
          "flight")
    for name, worst, rep in logged_flights():
        print(f"  {name:<40} {worst:5.2f} %  {rep.max_instructions:6d} instr "
              f"{rep.heap_kb:5.1f} KB")
    print_counter_logs()
    return 0


def print_counter_logs() -> None:
    print("logged flights with the autopilot's charge counter (as logged): largest "
          "|DL_TREM - Python replay at the recent load|, % of the flight")
    for name, worst, rep in counter_flights():
        print(f"  {name:<48} {worst:5.2f} %  {rep.max_instructions:6d} instr "
              f"{rep.heap_kb:5.1f} KB")


if __name__ == "__main__":
    raise SystemExit(main())
