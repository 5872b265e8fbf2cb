"""A slow drain predicts a fast flight: a synthetic self-heating pack and the INA3221 logs.

**Synthetic pack** (no model family of dischargelab writes its voltage): a 3S 12 Ah LiPo,
per cell the generic LiPo open-circuit voltage (:data:`dischargelab.ocv.GENERIC_OCV_V`) read
at a surface state of charge that leads the bulk by a diffusion term (2 % of the capacity
per C at a steady current, time constant 54 s: the measured cells lose 0.6 to 2 % of their
slow-drain charge per C, the Samsung 30Q 2.4 % at 4C and the Enertech LCO pouch 4 % at 2C,
which bounds the diffusion share from above), a series resistance of 2.8 mOhm and an RC pair
of 1.5 mOhm / 60 s, both Arrhenius with 3000 K, and a lumped thermal mass of 305 J/K (a 290
g cell) heated by current x overpotential and cooled through 7.5 K/W on the bench (still
air) or 3.0 K/W in flight (airflow). Integrated here with its own 0.1 s / 1 s explicit
steps, not by dischargelab's engine. Runs, logged like an INA3221 monitor (pack and cell
voltages, current; no temperature):

* **slow drain**: a 2.13 Ohm resistor from full to 3.0 V/cell (5.9 A falling to 4.4 A),
  on the bench, 1 Hz;
* **fast drain**: 36.5 A with 1.5 s bursts of 110 A every 20 s (42 A mean, 3.5C) until the
  pack stays under 3.3 V/cell for 10 s, in flight, 10 Hz;
* **27 A flight**: 200 s around 27 A (+-8 A, bursts to 60 A) from full, in flight, 10 Hz.

The slow drain is fitted (``dischargelab.fit``) six ways: as a flight log (``auto``:
ecm with its RC pairs held absent and its diffusion lead at the steady prior, the thermal
prior for airflow), the same with ecm's RC
pairs and diffusion state fitted anyway (their bounds given), as a bench discharge
(``auto``: shepherd-dynamic, eq. 6 with Tremblay's filtered current and the load step's
series and polarisation resistances, with the thermal prior for still air), the same
without its rest sample (a logger started with the load on: the build over the first
minutes still gives the polarisation resistance, nothing gives the series one), as a bench
discharge forced to shepherd-thermal (what ``auto`` chose before: eq. 6, its polarisation
present at once with the current, the series resistance left to the fit), and as a bench
discharge with the cell held at the ambient (``cooling=None``: the behaviour without a
thermal prior: eq. 6).
Each fit is checked with ``dischargelab.validate`` on the fast drain (endurance to
3.3 V/cell held 10 s, its 95 % interval, the extrapolation warning) and on the 27 A
flight (voltage RMS in % of the mean pack voltage).

**Slow drains of measured and virtual cells** (no model writes them; the truth at every
faster rate is measured): the slowest run of each cell with a rate series, its temperature
column dropped, is fitted three of the ways above (``ecm`` on one steady rate holds its
RC pairs absent and its diffusion lead at the prior, with the airflow prior, as the
flight-log path does; ``ecm`` with them
fitted anyway; ``auto`` as a bench discharge) and predicts every faster run's time to its
cutoff (``Battery.predict`` at its mean current and ambient) and flies each faster run
from its rest (``dischargelab.validate``: voltage RMS in % of the run's mean voltage,
the knee included): Samsung 30Q C/10, Enertech LCO 0.1C, the PyBaMM NMC, LCO and LFP
cells at 0.1C (``benchmarks/accuracy.py`` loads them), and the PyBaMM NMC cell's mission
(3C take-off, then 2C with 3.5C bursts: a DFN model's flight, no dischargelab model
writes it). The bench path is shown as ``auto`` picks it now (shepherd-dynamic) and as
it picked it before (shepherd-thermal).

**Real logs** (``../shared/data/flight_logs/ina3221_fpv_4s``): the 29.csv flight (a
Dinogy 1600 mAh 4S, 24 A mean) is fitted as a flight log (``auto``: ecm; and forced to
shepherd-dynamic, whose time constant the varying current shows, and to shepherd-thermal)
and flies its own log and the 28.csv flight (a CNHL 1500 mAh 4S, 28 A mean, another
pack): voltage RMS in % of the mean pack voltage. Neither log is a slow full drain, so
the slow -> fast figure itself is measured on the synthetic pack only.

Goals (issue): endurance within 5 %, voltage RMS <= 1.3 % on ~27 A flights.

Usage: python benchmarks/slow_to_fast.py [--data DIR] [--cells samsung,enertech,...|none]
       [--logs auto,shepherd-dynamic,shepherd-thermal|none] [--bootstrap N]
       [--plot FIGURE.png]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import dischargelab as dl  # noqa: E402
from _machine import machine_line, shared_data  # noqa: E402
from dischargelab.discharge import Discharge  # noqa: E402
from dischargelab.flight import flight_curves  # noqa: E402
from dischargelab.ocv import ocv_from_soc  # noqa: E402

CELLS, CAPACITY_AH = 3, 12.0
R0_OHM, R1_OHM, TAU1_S, BETA_K = 0.0028, 0.0015, 60.0, 3000.0
CTH_J_PER_K, RTH_BENCH, RTH_FLIGHT = 305.0, 7.5, 3.0
AMBIENT_C = 25.0
#: Idle current of the logged rest before each run [A].
REST_A = 0.05
LEAD_PER_TAU = 4.493409457909064 ** 2 / 15.0
#: Steady diffusion lead of the surface charge, in capacity fractions per C [h].
LEAD_PER_C = 0.02
TAU_D_S = LEAD_PER_C * 3600.0 / LEAD_PER_TAU
GOAL_ENDURANCE_PCT, GOAL_RMS_PCT = 5.0, 1.3


def truth(current_of, *, dt, rth, stop, t_max):
    """Integrate the synthetic cell: ``current_of(t, pack_V_prev)`` -> pack current [A];
    ``stop(t, pack_V, history)`` ends the run. Returns arrays t, i, pack V, cell T."""
    q = i1 = i_d = 0.0
    temp = AMBIENT_C
    t, v_prev = 0.0, CELLS * float(ocv_from_soc(1.0, "lipo"))
    out = []
    while t <= t_max:
        i = float(current_of(t, v_prev))
        f = np.exp(BETA_K * (1.0 / (temp + 273.15) - 1.0 / 298.15))
        soc_s = 1.0 - (q + LEAD_PER_TAU * TAU_D_S * i_d / 3600.0) / CAPACITY_AH
        ocv_s = float(ocv_from_soc(soc_s, "lipo"))
        cell = ocv_s - f * (R0_OHM * i + R1_OHM * i1)
        out.append((t, i, CELLS * cell, temp))
        if stop(t, CELLS * cell, out):
            break
        ocv_bulk = float(ocv_from_soc(1.0 - q / CAPACITY_AH, "lipo"))
        heat = i * (ocv_bulk - cell)
        temp += dt * (heat - (temp - AMBIENT_C) / rth) / CTH_J_PER_K
        q += i * dt / 3600.0
        i1 += (i - i1) * (1.0 - np.exp(-dt / TAU1_S))
        i_d += (i - i_d) * (1.0 - np.exp(-dt / TAU_D_S))
        v_prev = CELLS * cell
        t += dt
    return [np.array(c) for c in zip(*out)]


def rest_pack_V(rest_A=REST_A):
    """Pack voltage of the full, rested pack at the idle current ``rest_A`` [A] (the
    truth's open-circuit voltage less the series drop; the RC pair and the diffusion
    lead are relaxed)."""
    return CELLS * (float(ocv_from_soc(1.0, "lipo")) - R0_OHM * rest_A)


def write_ina(path, t, i, v, rest_s=20.0, rest_A=REST_A):
    """INA3221-style CSV (time ms, pack V, equal cells, current mA, shunt mV), after
    ``rest_s`` at rest, full, at the idle current ``rest_A``."""
    n_rest = int(rest_s)
    rows = [(k * 1.0, rest_A, rest_pack_V(rest_A)) for k in range(n_rest)]
    rows += [(rest_s + tk, ik, vk) for tk, ik, vk in zip(t, i, v)]
    with open(path, "w", encoding="utf-8") as fh:
        for tk, ik, vk in rows:
            cell = vk / CELLS
            fh.write(f"{tk * 1000:.0f},{vk:.3f}," + ",".join([f"{cell:.3f}"] * CELLS)
                     + f",{ik * 1000:.1f},{ik * 0.5:.2f},\n")
    return path


def synthetic_runs(folder: Path):
    # slow: a resistor from full to 3.0 V/cell, 1 s steps, bench
    load_ohm = CELLS * 4.2 / 5.9
    t, i, v, temp = truth(lambda _t, vp: vp / load_ohm, dt=1.0, rth=RTH_BENCH,
                          stop=lambda _t, vv, _h: vv <= 3.0 * CELLS, t_max=6 * 3600)
    slow = {"t": t, "i": i, "v": v, "T": temp}
    write_ina(folder / "slow.csv", t, i, v)

    # fast: 36.5 A with 110 A bursts (1.5 s every 20 s), to 3.3 V/cell held 10 s, 0.1 s
    def fast_current(tt, _vp):
        return 110.0 if (tt % 20.0) < 1.5 else 36.5

    def held_under(tt, vv, hist):
        under = [h for h in hist[-int(10 / 0.1) - 1:] if h[2] <= 3.3 * CELLS]
        return len(under) > 10 / 0.1
    t, i, v, temp = truth(fast_current, dt=0.1, rth=RTH_FLIGHT, stop=held_under,
                          t_max=3600)
    fast = {"t": t, "i": i, "v": v, "T": temp}
    write_ina(folder / "fast.csv", t, i, v)

    # ~27 A flight for 200 s from full, then landed (30 s at rest)
    def flight_current(tt, _vp):
        if tt > 200.0:
            return 0.05
        burst = 60.0 if (tt % 25.0) < 1.0 else 0.0
        return max(burst, 27.0 + 8.0 * np.sin(2 * np.pi * tt / 37.0))
    t, i, v, temp = truth(flight_current, dt=0.1, rth=RTH_FLIGHT,
                          stop=lambda tt, _v, _h: tt >= 230.0, t_max=240)
    write_ina(folder / "flight27.csv", t, i, v)
    return slow, fast


def delivered(run, until_s=None) -> float:
    """Charge [Ah] a synthetic run delivered (up to ``until_s`` [s])."""
    keep = run["t"] <= (run["t"][-1] if until_s is None else until_s)
    return float(np.trapezoid(run["i"][keep], run["t"][keep]) / 3600.0)


def slow_discharge(slow) -> Discharge:
    """The slow drain as a bench discharge (no temperature), rest voltage first."""
    return Discharge(slow["t"], slow["v"], slow["i"], None,
                     rest_pack_V(0.0), "slow drain (bench)")


#: Cells with a rate series whose slowest run is fitted alone (``accuracy.SETS`` keys):
#: (the slowest run, the faster ones predicted).
SLOW_CELLS = {
    "samsung": ("C10", ("1C", "2C", "3C", "4C")),
    "enertech": ("0.1C", ("0.5C", "1C", "2C")),
    "nmc": ("0.1C", ("0.5C", "1C", "2C", "3C")),
    "lco": ("0.1C", ("0.5C", "1C", "2C", "3C")),
    "lfp": ("0.1C", ("0.5C", "1C", "2C")),
}


def dynamics_free() -> dict:
    """Bounds (the family's own) on the ecm parameters a fit to one steady drain holds
    absent: given bounds, the fit fits them instead."""
    from dischargelab.models import get_family

    family = get_family("ecm")
    return {n: (family.parameter(n).lower, family.parameter(n).upper)
            for n in family.steady_fixed}


def slow_cells(data: Path, names):
    """Slowest run of each cell fitted as a flight log's steady drain would be and as a
    bench discharge, predicting the faster runs: one table row per cell and way."""
    import accuracy

    print("\n## Slow drains of measured and virtual cells (temperature dropped): the "
          "faster runs predicted\n")
    print("| cell | fitted on | way | model | faster runs: endurance error (in / OUT: "
          "the 95 % interval covers / misses) | faster runs flown from rest: voltage RMS |")
    print("|---|---|---|---|---|---|")
    for name in names:
        title, runs, _ = accuracy.SETS[name](data)
        slow_key, fast_keys = SLOW_CELLS[name]
        drain = replace(runs[slow_key].discharge, temperature_C=None)
        flown = [(key, runs[key].discharge, runs[key].cutoff_V) for key in fast_keys]
        if name == "nmc":  # the virtual cell's mission: a DFN model's flight
            flown.append(("mission", dl.read(accuracy.VIRTUAL / "nmc_mission_25C.csv"), 2.5))
        for way, kw in (("flight-log rule: ecm, airflow prior", dict(model="ecm",
                                                                    cooling="airflow")),
                        ("ecm, dynamics fitted anyway, airflow prior",
                         dict(model="ecm", cooling="airflow", bounds=dynamics_free())),
                        ("bench: auto, still-air prior", {}),
                        ("bench before: shepherd-thermal, still-air prior",
                         dict(model="shepherd-thermal"))):
            res = dl.fit(drain, bootstrap=20, **kw)
            cells = []
            for key in fast_keys:
                run = runs[key]
                out = res.battery.predict(current=run.current_A, cutoff=run.cutoff_V,
                                          ambient=run.ambient_C).to_dict()
                lo, hi = out["interval95"]["time_to_cutoff_s"]
                err = 100.0 * (out["time_to_cutoff_s"] / run.measured_s - 1.0)
                cells.append(f"{key} {err:+.1f} % "
                             f"({'in' if lo <= run.measured_s <= hi else 'OUT'})")
            rms = []
            for key, discharge, cutoff in flown:
                (case,) = dl.validate(res.battery, discharge, cutoff=cutoff)
                rms.append(f"{key} {case.to_dict()['voltage_rmse_pct']:.2f} %")
            print(f"| {title} | {slow_key} | {way} | {res.model} | {', '.join(cells)} | "
                  f"{', '.join(rms)} |")


def plot_flight(path: Path, flown) -> None:
    """The truth and the models of the slow drain flying the 27 A flight: pack voltage,
    model minus truth, current (the flight-log and bench ``auto`` paths, the bench path
    before)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keep = [(label, model, case) for label, model, case in flown
            if "auto" in label and "cooling=None" not in label]
    fig, (ax_v, ax_e, ax_i) = plt.subplots(3, 1, figsize=(9, 8.5), sharex=True)
    truth = keep[0][2]
    flying = truth.current_A > 1.0
    t = truth.time_s[flying] - truth.time_s[flying][0]
    mean_v = float(np.mean(truth.voltage_measured_V[flying]))
    ax_v.plot(t, truth.voltage_measured_V[flying], color="black", lw=1.2,
              label="truth (synthetic pack)")
    for label, model, case in keep:
        way = "flight-log fit" if label.startswith("flight log") else (
            "bench fit, before" if "before" in label else "bench fit")
        line, = ax_v.plot(t, case.voltage_predicted_V[flying], lw=1,
                          label=f"{way}: {model} ({pct_rms(case.to_dict(), mean_v):.2f} % RMS)")
        ax_e.plot(t, case.voltage_predicted_V[flying] - case.voltage_measured_V[flying], lw=1,
                  color=line.get_color(), label=f"{way}: {model}")
    ax_e.axhline(0.0, color="0.6", lw=0.8)
    ax_i.plot(t, truth.current_A[flying], color="black", lw=1)
    ax_v.set_ylabel("pack V")
    ax_e.set_ylabel("model - truth [V]")
    ax_i.set_ylabel("current [A]")
    ax_i.set_xlabel("time from take-off [s]")
    ax_v.set_title("Synthetic 3S 12 Ah pack: models of its slow drain flying a 27 A flight",
                   fontsize=10)
    ax_v.legend(fontsize=8)
    ax_e.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    print(f"\nFigure: {path}")


def pct_rms(row, pack_mean_V):
    value = row.get("voltage_rmse_V")
    return float("nan") if value is None else 100.0 * value / pack_mean_V


#: Models fitted to the real log, with their row labels.
LOG_MODELS = {"auto": "auto, thermal prior (airflow)",
              "shepherd-dynamic": "shepherd-dynamic (tau from the flight)",
              "shepherd-thermal": "shepherd-thermal"}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None,
                        help="shared data folder (default: ../shared/data beside the repo)")
    parser.add_argument("--cells", default=",".join(SLOW_CELLS),
                        help="cells whose slowest run is fitted alone (default all; 'none')")
    parser.add_argument("--logs", default=",".join(LOG_MODELS),
                        help="models fitted to the real INA3221 log (default all: "
                             f"{','.join(LOG_MODELS)}; 'none')")
    parser.add_argument("--bootstrap", type=int, default=30,
                        help="bootstrap replicas of the bench fits (default 30)")
    parser.add_argument("--plot", type=Path, default=None,
                        help="draw the auto paths (and the bench path before) flying the 27 A "
                             "flight to this PNG")
    args = parser.parse_args(argv)
    log_models = [m for m in args.logs.split(",") if m and m != "none"]
    unknown = sorted(set(log_models) - set(LOG_MODELS))
    if unknown:
        parser.error(f"--logs: unknown {', '.join(unknown)}; choose from "
                     f"{', '.join(LOG_MODELS)} or 'none'")
    data = args.data if args.data is not None else shared_data()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        slow, fast = synthetic_runs(folder)
        fast_log, flight_log = folder / "fast.csv", folder / "flight27.csv"
        true_s = float(fast["t"][-1] - 10.0)
        flight_v = np.loadtxt(flight_log, delimiter=",", usecols=(1, 5))
        flying = flight_v[:, 1] > 1000.0
        mean_27 = float(np.mean(flight_v[flying, 0]))
        print("## Synthetic 3S 12 Ah LiPo: slow drain -> fast drain and a 27 A flight\n")
        print(f"Truth: slow drain {slow['t'][-1] / 3600:.2f} h at {slow['i'][0]:.1f} -> "
              f"{slow['i'][-1]:.1f} A, heats {np.max(slow['T']) - AMBIENT_C:.1f} K; fast drain "
              f"{np.mean(fast['i']):.1f} A mean, {np.max(fast['i']):.0f} A peaks, 3.3 V/cell "
              f"held 10 s after {true_s:.0f} s, heats {np.max(fast['T']) - AMBIENT_C:.1f} K; "
              f"27 A flight: {np.mean(flight_v[flying, 1]) / 1000:.1f} A mean, pack "
              f"{mean_27:.2f} V mean. The slow drain delivers {delivered(slow):.2f} Ah to "
              f"3.0 V/cell, the fast drain {delivered(fast, true_s):.2f} Ah "
              f"({100 * delivered(fast, true_s) / delivered(slow):.0f} %): the diffusion "
              f"lead alone costs {LEAD_PER_TAU * TAU_D_S / 3600:.3f} Ah per ampere "
              f"({100 * LEAD_PER_TAU * TAU_D_S / 3600:.0f} % of "
              f"the capacity per C).\n")
        fits = [
            ("flight log, auto (ecm: RC pairs absent, lead prior; thermal prior: airflow)",
             lambda: dl.fit(flight_curves(folder / "slow.csv"), bootstrap=0)),
            ("flight log, ecm with its dynamics fitted anyway (bounds given)",
             lambda: dl.fit(flight_curves(folder / "slow.csv"), model="ecm",
                            bounds=dynamics_free(), bootstrap=0)),
            ("bench discharge, auto (shepherd-dynamic: R and Rp from the load step, Tremblay's "
             "filtered current; thermal prior: still air)",
             lambda: dl.fit(slow_discharge(slow), cells=CELLS, bootstrap=args.bootstrap)),
            ("bench discharge without its rest sample (a logger started with the load on), "
             "auto: Rp from the build, R not separable from E0",
             lambda: dl.fit(replace(slow_discharge(slow), rest_voltage_V=None), cells=CELLS,
                            bootstrap=args.bootstrap)),
            ("bench discharge, shepherd-thermal (auto before; thermal prior: still air)",
             lambda: dl.fit(slow_discharge(slow), cells=CELLS, bootstrap=args.bootstrap,
                            model="shepherd-thermal")),
            ("bench discharge, auto, cooling=None (held at the ambient: eq. 6)",
             lambda: dl.fit(slow_discharge(slow), cells=CELLS, bootstrap=args.bootstrap,
                            cooling=None)),
        ]
        print("| fitted on the slow drain | model | endurance error, fast drain | 95 % "
              "interval [s] (truth) | warnings | voltage RMS, fast drain | voltage RMS, "
              "27 A flight |")
        print("|---|---|---:|---|---|---:|---:|")
        flown = []
        for label, fit in fits:
            res = fit()
            (case,) = dl.validate(res.battery, [fast_log], cutoff=3.3)
            row = case.to_dict()
            (case27,) = dl.validate(res.battery, [flight_log], cutoff=3.3)
            row27 = case27.to_dict()
            flown.append((label, res.model, case27))
            iv = row.get("interval_s")
            ivs = "-" if not iv else f"{iv[0]:.0f} - {iv[1]:.0f} ({true_s:.0f})"
            warn = "; ".join(w for w in row.get("warnings", []) if "extrapolat" in w
                             or "beyond" in w)[:120] or "-"
            fast_mean = float(np.mean(fast["v"]))
            print(f"| {label} | {res.model} | {row['endurance_error_pct']:+.1f} % | {ivs} | "
                  f"{warn} | {pct_rms(row, fast_mean):.2f} % | "
                  f"{pct_rms(row27, mean_27):.2f} % |")
        if args.plot is not None:
            plot_flight(args.plot, flown)
    names = [n for n in args.cells.split(",") if n and n != "none"]
    if names and data is not None and (data / "samsung30q_S001").is_dir():
        slow_cells(data, names)
    if log_models and data is not None and (data / "flight_logs" / "ina3221_fpv_4s").is_dir():
        folder = data / "flight_logs" / "ina3221_fpv_4s"
        print("\n## Real logs: 29.csv fitted as a flight log, flying 29.csv and 28.csv\n")
        print("| fit of 29.csv | model | voltage RMS, 29.csv (same pack, 24 A) | voltage RMS, "
              "28.csv (another pack, 28 A) |")
        print("|---|---|---:|---:|")
        from dischargelab.flight import fit_flights

        for model in log_models:
            label = LOG_MODELS[model]
            flights = flight_curves(folder / "29.csv", capacity_Ah=1.6)
            res = fit_flights(flights, model=model)
            cells = []
            for name, cap in (("29.csv", 1.6), ("28.csv", 1.5)):
                from dischargelab.flight import analyse_flight

                rep = analyse_flight(folder / name, res.battery, capacity_Ah=cap, cutoff=3.3)
                s = rep.flights[0].summary
                mean_v = rep.flights[0].summary.get("mean_voltage_V")
                if mean_v is None:
                    mean_v = s["energy_Wh"] / s["charge_Ah"]
                cells.append(f"{100 * s['rmse_V'] / mean_v:.2f} % ({1000 * s['rmse_V']:.0f} mV)")
            print(f"| {label} | {res.model} | {cells[0]} | {cells[1]} |")
    print(f"\nGoals: endurance within {GOAL_ENDURANCE_PCT:g} %, voltage RMS <= "
          f"{GOAL_RMS_PCT:g} % on ~27 A flights. Run time {time.perf_counter() - t0:.0f} s.")
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.1f} (shared machine)")


if __name__ == "__main__":
    main()
