"""Fit speed per model family, against a plain numeric-Jacobian least_squares, plus predictions.

For every registered model family (``dischargelab.models.FAMILIES``):

* **fit**: median wall time of ``fit_battery(curve, model=family)`` over
  ``--repeats`` runs (after one warm-up) on two curves of about 3,600 samples:
  the bundled Samsung 30Q 1C discharge (measured, with the logged cell
  temperature) and a seeded synthetic 3 A discharge (the paper's model plus
  3 mV noise and a 10-bit ADC step, no temperature).
* **baseline**: in the same process, ``scipy.optimize.least_squares`` (trf,
  bounds, 2-point numeric Jacobian) over the *same* free parameters of the same
  family, on the *same* stacked samples the fitter uses (``family.fit_voltage``,
  same weights), with the same bounds, started from the family's own
  ``guess()``. It is the straightforward implementation of the paper's eq. (8).
  dischargelab's time includes what the baseline does not do: the multi-start
  grid, the covariance, the identifiability analysis and (thermal families) the
  regression of the thermal parameters on the logged temperature.
* **prediction**: ``simulate_current`` of the ``shepherd-thermal`` fit of the
  1C curve at 12 A (4C) with the 4C run's ambient temperature, to 2.5 V.
* **large input**: a synthetic 1,000,000-row CSV (time, current, voltage,
  temperature) read with ``dischargelab.read`` and fitted, per family, each in
  a fresh process: wall time and peak resident memory (``ru_maxrss`` of that
  process, cross-checked with ``VmHWM`` from ``/proc/self/status``).

Goals: fit median <= 20 ms (``shepherd``), <= 200 ms (other families);
1C -> 4C prediction <= 50 ms.

Usage: python benchmarks/fit_speed.py [--repeats N] [--large-rows N] [--families a,b]
"""

import os

# Small matrices: BLAS threads only add jitter. Set before numpy loads; applies
# to both methods alike.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from _baseline import plain_least_squares  # noqa: E402
from _machine import machine_line  # noqa: E402
from dischargelab.fit import Curve, fit_battery  # noqa: E402
from dischargelab.fit.family import steady_dynamics  # noqa: E402
from dischargelab.io import read_discharge  # noqa: E402
from dischargelab.model import cell_voltage  # noqa: E402
from dischargelab.models import FAMILIES, get_family  # noqa: E402
from dischargelab.simulate import simulate_current  # noqa: E402
from synthetic import TRUE, adc_step, synthetic_curve  # noqa: E402

BUNDLED = HERE.parent / "src" / "dischargelab" / "data" / "samsung30q"
SAMSUNG_COLUMNS = {"time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4}

#: Goals for the median fit time [ms] (shepherd; every other family).
GOAL_FIT_MS = {"shepherd": 20.0}
GOAL_FIT_OTHER_MS = 200.0
#: Goal for the 1C -> 4C prediction with temperature [ms].
GOAL_PREDICT_MS = 50.0



def baseline_fit(curve: Curve, family_name: str):
    """The plain numeric-Jacobian fit (``_baseline.plain_least_squares``) with a family's
    ``steady_fixed`` held as the fit holds them on one constant current. Returns (RMSE [V]
    over the load samples, function evaluations, number of free parameters)."""
    held, _ = steady_dynamics([curve], family_name, None, None)  # as the fit holds them
    rmse, nfev, n_free, _ = plain_least_squares([curve], family_name, held=held)
    return rmse, nfev, n_free


def median_ms(func, repeats):
    """Median wall time [ms], median CPU time of this process [ms] over ``repeats`` calls,
    and the last return value (on a loaded, shared machine the CPU time shows the work
    done apart from waiting for a core)."""
    times, cpu, value = [], [], None
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        value = func()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return 1000.0 * float(np.median(times)), 1000.0 * float(np.median(cpu)), value


# ---- large input (each family in a fresh process, so ru_maxrss is its own) ----------

_CHILD = r"""
import json, resource, sys, time
t0 = time.perf_counter()
import dischargelab as dl
from dischargelab.fit import fit_battery
rss_import = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t1 = time.perf_counter()
d = dl.read(sys.argv[1])
t2 = time.perf_counter()
res = fit_battery(d.to_curve(), model=sys.argv[2])
t3 = time.perf_counter()
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
with open("/proc/self/status") as fh:
    hwm = [int(line.split()[1]) for line in fh if line.startswith("VmHWM:")]
print(json.dumps({"rows": int(d.time_s.size), "import_s": t1 - t0, "read_s": t2 - t1,
                  "fit_s": t3 - t2, "rmse_mV": 1000 * res.rmse_V,
                  "rss_import_MiB": rss_import / 1024, "peak_rss_MiB": peak / 1024,
                  "vmhwm_MiB": hwm[0] / 1024 if hwm else float("nan")}))
"""


def write_large_csv(path: Path, rows: int, seed: int = 0) -> float:
    """A synthetic 3 A discharge to 2.7 V in ``rows`` rows (1 s of rest first); returns dt [s].

    Voltage from the paper's model (tests/synthetic.py parameters) plus 3 mV noise,
    quantised to a 10-bit ADC step; a cell temperature rising from 25 degC.
    """
    rng = np.random.default_rng(seed)
    current = 3.0
    q_end = TRUE.C_Ah * 0.999
    t_end = q_end * 3600 / current
    # load end where the model reaches 2.7 V
    tt = np.linspace(0, t_end, 20001)
    v = cell_voltage(TRUE, current, current * tt / 3600)
    t_end = float(tt[np.argmax(v <= 2.7)]) if np.any(v <= 2.7) else t_end
    n_rest = max(rows // 1000, 2)
    n_load = rows - n_rest
    dt = t_end / n_load
    t = np.r_[np.linspace(0.0, 1.0, n_rest, endpoint=False), 1.0 + dt * np.arange(n_load)]
    i = np.r_[np.zeros(n_rest), np.full(n_load, current)]
    q = np.r_[np.zeros(n_rest), current * (t[n_rest:] - 1.0) / 3600]
    volt = np.where(i > 0, cell_voltage(TRUE, current, q), TRUE.E0_V + TRUE.A_V)
    step = adc_step()
    volt = np.round((volt + rng.normal(0, 0.003, rows)) / step) * step
    temp = 25.0 + 10.0 * (1.0 - np.exp(-np.maximum(t - 1.0, 0.0) / 1200.0))
    import pandas as pd

    pd.DataFrame({"time_s": np.round(t, 4), "current_A": i, "voltage_V": np.round(volt, 5),
                  "temperature_C": np.round(temp, 3)}).to_csv(path, index=False)
    return dt


def large_input(families, rows: int):
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "large.csv"
        dt = write_large_csv(path, rows)
        size_mb = path.stat().st_size / 1e6
        for name in families:
            # Started from a forked shell, not spawned from this process: on Linux a
            # process's ru_maxrss keeps the peak of the image it was exec'd from, so a
            # direct spawn would report this (large) process's memory.
            command = " ".join(shlex.quote(a) for a in (sys.executable, "-c", _CHILD,
                                                         str(path), name))
            done = subprocess.run(["/bin/sh", "-c", f"{command}; exit $?"],
                                  capture_output=True, text=True, timeout=900)
            if done.returncode != 0:
                tail = done.stderr.strip().splitlines()[-1:] or ["?"]
                out.append({"family": name, "error": tail[0]})
                continue
            out.append(dict(json.loads(done.stdout.strip().splitlines()[-1]), family=name))
    return out, dt, size_mb


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7,
                        help="timed runs per fit (median reported; default 7)")
    parser.add_argument("--baseline-repeats", type=int, default=None,
                        help="timed runs of the baseline (default: 5, or --repeats if fewer)")
    parser.add_argument("--large-rows", type=int, default=1_000_000,
                        help="rows of the synthetic large CSV (0 skips it)")
    parser.add_argument("--families", default=",".join(FAMILIES),
                        help="comma-separated family names (default: every registered one)")
    args = parser.parse_args(argv)
    if args.baseline_repeats is None:
        args.baseline_repeats = min(5, args.repeats)
    families = [f for f in args.families.split(",") if f]
    for f in families:
        get_family(f)

    data, meta = read_discharge(BUNDLED / "Q30_S001_1C.csv", columns=SAMSUNG_COLUMNS)
    samsung = Curve.from_frame(data, meta, name="1C")
    cases = [("Samsung 30Q 1C (measured, with temperature)", samsung),
             ("synthetic 3 A, 3 mV noise + 10-bit ADC", synthetic_curve(3.0, dt_s=1.0, seed=0))]

    print("## Fit time per model family\n")
    print("| family | curve | samples | free parameters | dischargelab median [ms] (CPU) | "
          "numeric-Jacobian least_squares median [ms] (CPU) | speed-up | RMSE ours [mV] | "
          "RMSE baseline [mV] | goal | met |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for fam in families:
        goal = GOAL_FIT_MS.get(fam, GOAL_FIT_OTHER_MS)
        for label, curve in cases:
            try:
                fit_battery(curve, model=fam)  # warm-up (imports, caches)
                ours_ms, ours_cpu, res = median_ms(lambda c=curve, f=fam: fit_battery(c, model=f),
                                                   args.repeats)
            except Exception as exc:  # report, do not hide: library failures are results
                print(f"| {fam} | {label} | {curve.time_s.size} | | fit failed: "
                      f"{type(exc).__name__}: {exc} | | | | | {goal:.0f} ms | not met |")
                continue
            try:
                baseline_fit(curve, fam)
                base_ms, base_cpu, (base_rmse, nfev, n_free) = median_ms(
                    lambda c=curve, f=fam: baseline_fit(c, f), args.baseline_repeats)
                base = (f"{base_ms:.1f} ({base_cpu:.1f}) | {base_ms / ours_ms:.1f}x | "
                        f"{res.rmse_V * 1000:.2f} | {base_rmse * 1000:.2f}")
            except Exception as exc:
                n_free = len(res.free)
                base = f"failed: {type(exc).__name__}: {exc} | | {res.rmse_V * 1000:.2f} | "
            met = "met" if ours_ms <= goal else "not met"
            print(f"| {fam} | {label} | {curve.time_s.size} | {n_free} | {ours_ms:.1f} "
                  f"({ours_cpu:.1f}) | {base} | {goal:.0f} ms | {met} |")

    print("\n## Prediction 1C -> 4C with temperature\n")
    if "shepherd-thermal" in FAMILIES:
        fit1 = fit_battery(samsung, model="shepherd-thermal")
        four, _ = read_discharge(BUNDLED / "Q30_S001_4C.csv", columns=SAMSUNG_COLUMNS)
        ambient = float(four["temperature_C"].iloc[0])  # the cell at rest before the 4C load
        measured_4c = float(four["time_s"].iloc[-1])
        bat = fit1.battery

        def run():
            return simulate_current(bat, 12.0, cutoff_cell_V=2.5, ambient_C=ambient)

        run()
        ms, cpu_ms, sim = median_ms(run, max(args.repeats, 5))
        met = "met" if ms <= GOAL_PREDICT_MS else "not met"
        print("| prediction | median [ms] (CPU) | time to 2.5 V [s] (measured) | peak cell "
              "temperature [degC] | goal | met |")
        print("|---|---:|---:|---:|---:|---|")
        print(f"| shepherd-thermal fitted on 1C, `simulate_current` at 12 A (4C), ambient "
              f"{ambient:.1f} degC | {ms:.1f} ({cpu_ms:.1f}) | {sim.time_to_cutoff_s:.0f} "
              f"({measured_4c:.0f}) | "
              f"{sim.peak_temperature_C:.1f} | {GOAL_PREDICT_MS:.0f} ms | {met} |")
    else:
        print("shepherd-thermal is not registered; skipped")

    if args.large_rows > 0:
        print(f"\n## Large input: {args.large_rows:,}-row CSV -> read + fit (fresh process "
              f"per family)\n")
        rows, dt, size_mb = large_input(families, args.large_rows)
        print("| family | rows read | read [s] | fit [s] | read + fit [s] | peak RSS [MiB] | "
              "peak RSS after import only [MiB] | /proc VmHWM [MiB] |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            if "error" in r:
                print(f"| {r['family']} | failed: {r['error']} | | | | | | |")
                continue
            print(f"| {r['family']} | {r['rows']:,} | {r['read_s']:.2f} | {r['fit_s']:.2f} | "
                  f"{r['read_s'] + r['fit_s']:.2f} | {r['peak_rss_MiB']:.0f} | "
                  f"{r['rss_import_MiB']:.0f} | {r['vmhwm_MiB']:.0f} |")
        print(f"\nFile: {size_mb:.1f} MB, synthetic 3 A discharge sampled every "
              f"{dt * 1000:.2f} ms, 4 columns with header; the fitter thins each curve to "
              f"at most 4,000 samples.")

    print(f"\nGoals: fit median <= {GOAL_FIT_MS['shepherd']:.0f} ms (shepherd), <= "
          f"{GOAL_FIT_OTHER_MS:.0f} ms (other families); 1C -> 4C prediction <= "
          f"{GOAL_PREDICT_MS:.0f} ms, judged on the wall-clock median. speed-up = baseline "
          f"median / dischargelab median (wall clock). CPU = median process CPU time.")
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.1f} "
          f"(shared machine)")


if __name__ == "__main__":
    main()
