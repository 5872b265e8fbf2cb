"""Latency of a whole fit against one plain eq. 6 fit of the same data, in one run.

The case users wait for: ``dischargelab fit`` of three rates of the bundled Samsung 30Q
(C/10 + 1C + 4C, about 40,000 samples) with the defaults, i.e. ``model="auto"`` (every
family fitted, each scored on held-out curves, ends and the rate-capacity check) and the
default uncertainty (100 bootstrap replicas). Timed three ways:

* **command**: ``python -m dischargelab fit C10 1C 4C --columns ... -o cell.json`` in a
  fresh process, as a user runs it: start-up and imports included (its CPU time is the
  child's user + system time);
* **CLI**: the same command run in this process, modules already loaded
  (reading the three files, fitting, writing the battery file, printing);
* **library**: ``dischargelab.fit(runs, bootstrap=100)`` on runs already read;
* **baseline**: one ``scipy.optimize.least_squares`` fit of eq. 6 (``shepherd``: trf,
  bounds, 2-point numeric Jacobian) to every sample of the same three curves, from the
  family's ``guess()``: the plain fit the paper describes, with no choice of family, no
  held-out error and no uncertainty.

The held-out folds run in worker processes, one per core (``dischargelab.fit.workers``;
``DISCHARGELAB_WORKERS=1`` for one process): the CPU times include the workers'. Each is
repeated and the minimum taken (the 2 cores are shared: the minimum is the
least disturbed run); the load average is printed. Ratios are given on wall time and on
CPU time (the CPU time is what a loaded machine does not inflate). Goal: the command
<= 20x the baseline (stretch goal 10x).

Usage: python benchmarks/fit_latency.py [--repeats N] [--bootstrap N]
"""

import os

# the caller's own setting ("" none), which the command in a fresh process gets back
os.environ.setdefault("DISCHARGELAB_CALLER_BLAS", os.environ.get("OPENBLAS_NUM_THREADS", ""))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import contextlib
import io
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import dischargelab as dl  # noqa: E402
from _baseline import plain_least_squares  # noqa: E402
from _machine import machine_line  # noqa: E402

BUNDLED = HERE.parent / "src" / "dischargelab" / "data" / "samsung30q"
FILES = [BUNDLED / f"Q30_S001_{r}.csv" for r in ("C10", "1C", "4C")]
COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
GOAL_RATIO, STRETCH_RATIO = 20.0, 10.0


def baseline_fit(curves):
    """Plain bounded least_squares of eq. 6 on every sample; returns (RMSE [V], nfev,
    stacked samples)."""
    rmse, nfev, _, n = plain_least_squares(curves, "shepherd", max_samples=10**9)
    return rmse, nfev, n


def cli_fit(out: Path, bootstrap: int | None):
    from dischargelab.cli import main as cli_main

    args = ["fit", *map(str, FILES), "--columns", COLUMNS, "-o", str(out), "--force"]
    if bootstrap is not None:
        args += ["--bootstrap", str(bootstrap)]
    sink = io.StringIO()
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(io.StringIO()):
        try:
            cli_main(args)
            code = 0
        except SystemExit as exc:  # the entry point always exits with its status
            code = exc.code
    if code not in (0, None):
        raise RuntimeError(f"dischargelab fit exited with {code}")


def command_fit(out: Path, bootstrap: int | None):
    """The command in a fresh process; returns its CPU time (user + system) [s]."""
    args = [sys.executable, "-m", "dischargelab", "fit", *map(str, FILES), "--columns",
            COLUMNS, "-o", str(out), "--force"]
    if bootstrap is not None:
        args += ["--bootstrap", str(bootstrap)]
    # the user's environment, not this script's: the command chooses its own BLAS threads
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "DISCHARGELAB_CALLER_BLAS")}
    if os.environ.get("DISCHARGELAB_CALLER_BLAS"):
        env["OPENBLAS_NUM_THREADS"] = os.environ["DISCHARGELAB_CALLER_BLAS"]
    src = str(HERE.parent / "src")
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"dischargelab fit exited with {done.returncode}: "
                           f"{done.stderr.strip().splitlines()[-1:]}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _children_cpu() -> float:
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime


def best_of(func, repeats):
    """(minimum wall time [s], minimum CPU time [s] of this process and the worker
    processes it waited for, last value)."""
    walls, cpus, value = [], [], None
    for _ in range(repeats):
        c0, k0, t0 = time.process_time(), _children_cpu(), time.perf_counter()
        value = func()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0 + _children_cpu() - k0)
    return min(walls), min(cpus), value


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs each (default 5)")
    parser.add_argument("--bootstrap", type=int, default=None,
                        help="bootstrap replicas (default: the CLI's default)")
    args = parser.parse_args(argv)
    load_before = os.getloadavg()[0]
    runs = [dl.read(p, columns=COLUMNS) for p in FILES]
    curves = [r.to_curve() for r in runs]
    samples = sum(c.time_s.size for c in curves)
    boot = 100 if args.bootstrap is None else args.bootstrap

    base_s, base_cpu, (rmse, nfev, n_stack) = best_of(lambda: baseline_fit(curves),
                                                        args.repeats)
    lib_s, lib_cpu, res = best_of(lambda: dl.fit(runs, bootstrap=boot), args.repeats)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cell.json"
        cli_s, cli_cpu, _ = best_of(lambda: cli_fit(out, args.bootstrap), args.repeats)
        cmd_walls, cmd_cpus = [], []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            cmd_cpus.append(command_fit(out, args.bootstrap))
            cmd_walls.append(time.perf_counter() - t0)
        cmd_s, cmd_cpu = min(cmd_walls), min(cmd_cpus)

    print(f"## Whole fit against one plain eq. 6 fit: Samsung 30Q C/10 + 1C + 4C, "
          f"{samples:,} samples (minimum of {args.repeats} runs each)\n")
    print("| what | wall [s] | CPU [s] | x baseline (wall) | x baseline (CPU) |")
    print("|---|---:|---:|---:|---:|")
    print(f"| baseline: `least_squares` of eq. 6, numeric Jacobian, all {n_stack:,} samples "
          f"({nfev} evaluations, RMSE {1000 * rmse:.1f} mV) | {base_s:.3f} | {base_cpu:.3f} "
          f"| 1.0 | 1.0 |")
    print(f"| library: `dl.fit(runs, bootstrap={boot})` (auto picked `{res.model}`, RMSE "
          f"{1000 * res.rmse_V:.1f} mV) | {lib_s:.3f} | {lib_cpu:.3f} | "
          f"{lib_s / base_s:.1f} | {lib_cpu / base_cpu:.1f} |")
    print(f"| CLI: `dischargelab fit C10 1C 4C --columns ... -o cell.json` (read, fit, write, "
          f"print), in this process | {cli_s:.3f} | {cli_cpu:.3f} | {cli_s / base_s:.1f} | "
          f"{cli_cpu / base_cpu:.1f} |")
    print(f"| command: `python -m dischargelab fit C10 1C 4C --columns ... -o cell.json`, "
          f"fresh process, start-up included | {cmd_s:.3f} | {cmd_cpu:.3f} | "
          f"{cmd_s / base_s:.1f} | {cmd_cpu / base_cpu:.1f} |")
    ratio = cmd_s / base_s
    verdict = "met" if ratio <= GOAL_RATIO else "NOT met"
    stretch = "met" if ratio <= STRETCH_RATIO else "not met"
    print(f"\nGoal: the command <= {GOAL_RATIO:g}x the baseline: {ratio:.1f}x wall, "
          f"{cmd_cpu / base_cpu:.1f}x CPU -> {verdict} "
          f"(stretch goal {STRETCH_RATIO:g}x: {stretch}).")
    print(f"Machine: {machine_line()}; load average {load_before:.1f} before, "
          f"{os.getloadavg()[0]:.1f} after (shared machine)")


if __name__ == "__main__":
    main()
