"""Accuracy per model family: fit some rates, predict the time to cutoff of every other run.

For every registered model family and every data set with several runs of one
cell, the family is fitted (``dischargelab.api.fit``, ``bootstrap=30``) on one
run and on two or three runs, and every run left out is predicted with
``Battery.predict(current=<its mean current>, cutoff=<its cutoff>,
ambient=<its ambient>)``. Reported per held-out run: the time to cutoff
measured and predicted, the error [%], the 95 % interval
(``to_dict()["interval95"]["time_to_cutoff_s"]``), whether it covers the
measured time and its half-width [% of the prediction].

Measured time to cutoff: time from load start (the reader's ``time_s = 0``) to
the first sample at or below the cutoff, interpolated linearly between that
sample and the one before.

Data sets (real ones from ``../shared/data``, simulated ones from ``tests/data/virtual``):

* ``samsung``: Samsung 30Q, C/10, 1C, 2C, 3C, 4C with the logged cell
  temperature, cutoff 2.5 V; ambient = the cell temperature at rest before the load.
* ``samsung-notemp``: the same runs with the temperature column dropped, fitted on C/10,
  on 1C and on C/10 + 4C (fits without a logged temperature).
* ``enertech``: Enertech LCO pouch, 0.1C, 0.5C, 1C, 2C (current = C-rate x
  2.28 A; the files have no current column), cutoff 3.0 V, 25 degC. The
  temperature-rise files are not used: 0.1C has none, so a fit including it
  would be isothermal anyway.
* ``k2``: K2 LFP 26650 at one rate (2.6 A) at 20, 30, 40, 50 degC chamber
  temperature, cutoff 2.5 V; fitted on 20 degC and on 20 + 50 degC, the others
  predicted with their chamber temperature as ambient.
* ``nmc``, ``lfp``, ``lco``: PyBaMM DFN virtual cells (``tests/data/virtual/index.json``:
  rate, current, ambient, cutoff); NMC 1C also at 10 and 40 degC ambient. The
  NMC mission (variable current) is not a constant-rate run and is not used.
* ``lco-pouch``, ``nmc-pouch``, ``nca``, ``nmc532``, ``lfp-a123``: the PyBaMM cells of the
  measured one-rate error at 25 degC, fitted on 1C + 3C (the two-rate pouch fits), 0.2C,
  0.5C and 2C predicted.
* ``nmc15`` ... ``lco35``: the same cells at 15 and 35 degC, fitted on 0.2C + 2C;
  ``lfp-spme``, ``lfp-spme15``: the LFP plateau set (SPMe, to 2.5 V, 5 s samples),
  fitted on 1C and on 0.2C + 2C.

Nothing is tuned here: the fitter runs with its defaults and the numbers are
what it produces. A fit or prediction that raises is reported as a failure
with the exception and the library frame it came from.

Usage: python benchmarks/accuracy.py [--sets samsung,samsung-notemp,enertech,k2,nmc,...]
       [--families shepherd,...] [--bootstrap 30] [--detail]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import dischargelab as dl  # noqa: E402
from _machine import machine_line, shared_data  # noqa: E402
from dischargelab.models import FAMILIES  # noqa: E402
from dischargelab.predict import predict as predict_no_interval  # noqa: E402
from dischargelab.validate import measured_time_to_cutoff  # noqa: E402

VIRTUAL = HERE.parent / "tests" / "data" / "virtual"
SAMSUNG_COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
K2_COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"

#: Acceptance thresholds [%].
SAMSUNG_1C_LIMIT = 2.0
VIRTUAL_LIMIT = 2.0
MULTI_RATE_REAL_LIMIT = 2.0
COVERAGE_GOAL = 90.0
HALF_WIDTH_GOAL = 6.0


@dataclass
class Run:
    """One measured (or simulated) constant-current discharge."""

    label: str
    discharge: object
    current_A: float
    cutoff_V: float
    ambient_C: float
    measured_s: float


def default_data_dir() -> Path:
    """The shared data sets (:func:`_machine.shared_data`)."""
    return shared_data()




def make_run(label, discharge, cutoff_V, ambient_C) -> Run:
    return Run(label, discharge, float(discharge.mean_current_A), float(cutoff_V),
               float(ambient_C), measured_time_to_cutoff(discharge.time_s, discharge.voltage_V,
                                                       cutoff_V))


def rest_temperature(d) -> float:
    """Cell temperature at rest before the load (the ambient of a test from rest)."""
    rest = (d.meta.get("rest_sample") or {}).get("temperature_C")
    return float(rest) if rest is not None else float(d.temperature_C[0])


# ---- data sets ---------------------------------------------------------------------------

def load_samsung(data: Path):
    runs = {}
    for rate in ("C10", "1C", "2C", "3C", "4C"):
        d = dl.read(data / "samsung30q_S001" / f"Q30_S001_{rate}.csv", columns=SAMSUNG_COLUMNS)
        runs[rate] = make_run(rate, d, 2.5, rest_temperature(d))
    return ("Samsung 30Q", runs,
            [("1C",), ("C10", "4C"), ("C10", "1C", "4C")])


def load_samsung_without_temperature(data: Path):
    """Samsung 30Q with its temperature column dropped: fits without a logged temperature
    (thermal families then simulate the self-heating with the thermal prior)."""
    from dataclasses import replace

    _, runs, _ = load_samsung(data)
    runs = {k: make_run(k, replace(r.discharge, temperature_C=None), r.cutoff_V, r.ambient_C)
            for k, r in runs.items()}
    return ("Samsung 30Q, no temperature", runs, [("C10",), ("1C",), ("C10", "4C")])


def load_enertech(data: Path):
    runs = {}
    for c in ("0.1", "0.5", "1", "2"):
        d = dl.read(data / "enertech_lco" / f"{c}C_discharge_U.txt", current_A=float(c) * 2.28)
        runs[f"{c}C"] = make_run(f"{c}C", d, 3.0, 25.0)
    return ("Enertech LCO", runs,
            [("1C",), ("0.1C", "2C"), ("0.1C", "1C", "2C")])


def load_k2(data: Path):
    runs = {}
    for temp in (20, 30, 40, 50):
        d = dl.read(data / "k2_lfp26650" / f"K2_Discharge_Test_{temp}C.txt", columns=K2_COLUMNS)
        chamber = d.extra.get("ambient_temperature_C")
        ambient = float(np.median(chamber)) if chamber is not None else rest_temperature(d)
        runs[f"{temp}degC"] = make_run(f"{temp}degC", d, 2.5, ambient)
    return ("K2 LFP", runs,
            [("20degC",), ("20degC", "50degC")])


VIRTUAL_TRAININGS = {
    "NMC": [("1C",), ("0.1C", "2C"), ("0.2C", "2C"), ("0.1C", "1C", "2C")],
    "LFP": [("1C",), ("0.2C", "2C"), ("0.1C", "1C", "2C")],
    "LCO": [("1C",), ("0.1C", "3C"), ("0.2C", "2C"), ("0.1C", "1C", "3C")],
}

#: Extra virtual sets (``index.json`` "set" field, ambient [degC]): 0.2C + 2C fitted,
#: 0.5C and 1C predicted (the plateau LFP also from 1C alone).
EXTRA_VIRTUAL = {
    "nmc15": ("NMC", 15.0), "nmc35": ("NMC", 35.0),
    "lfp15": ("LFP", 15.0), "lfp35": ("LFP", 35.0),
    "lco15": ("LCO", 15.0), "lco35": ("LCO", 35.0),
    "lfp-spme": ("LFP SPMe 2.5 V", 25.0), "lfp-spme15": ("LFP SPMe 2.5 V", 15.0),
}
EXTRA_TRAININGS = [("0.2C", "2C")]
SPME_TRAININGS = [("1C",), ("0.2C", "2C")]
#: Virtual cells of the measured one-rate error (0.2C-3C at 25 degC) fitted on 1C + 3C,
#: the other runs (2C between them) predicted: the two-rate pouch fits.
TWO_RATE_VIRTUAL = {"lco-pouch": "LCO-POUCH", "nmc-pouch": "NMC-POUCH", "nca": "NCA",
                    "nmc532": "NMC532", "lfp-a123": "LFP-A123"}
TWO_RATE_TRAININGS = [("1C", "3C")]
#: Ambients of the main 25 degC virtual sets (NMC 1C also at 10 and 40 degC).
MAIN_AMBIENTS_C = (10.0, 25.0, 40.0)


def load_virtual(chemistry: str, ambient_C: float | None = None):
    """Loader of one virtual set: ``chemistry`` is the index's "set" (its chemistry
    for the DFN runs); ``ambient_C`` None: the 25 degC set (with NMC's 10 and
    40 degC 1C runs), else the runs at that ambient only."""
    def loader(_data: Path):
        index = json.loads((VIRTUAL / "index.json").read_text(encoding="utf-8"))
        runs = {}
        for entry in index["files"]:
            if entry.get("set", entry["chemistry"]) != chemistry or entry.get("rate_C") is None:
                continue
            amb = entry["ambient_C"]
            if ambient_C is None and not any(abs(amb - a) < 0.1 for a in MAIN_AMBIENTS_C):
                continue
            if ambient_C is not None and abs(amb - ambient_C) > 0.1:
                continue
            label = f"{entry['rate_C']:g}C"
            if ambient_C is None and abs(amb - 25.0) > 0.1:
                label += f" {amb:g}degC"
            d = dl.read(VIRTUAL / entry["file"])
            runs[label] = make_run(label, d, entry["cutoff_V"], amb)
        if ambient_C is None:
            title, trainings = f"virtual {chemistry}", VIRTUAL_TRAININGS[chemistry]
        else:
            title = f"virtual {chemistry} {ambient_C:g}degC"
            trainings = SPME_TRAININGS if "SPMe" in chemistry else EXTRA_TRAININGS
            if chemistry in TWO_RATE_VIRTUAL.values():
                trainings = TWO_RATE_TRAININGS
        return (title, runs, trainings)
    return loader


SETS = {
    "samsung": load_samsung, "samsung-notemp": load_samsung_without_temperature,
    "enertech": load_enertech, "k2": load_k2,
    "nmc": load_virtual("NMC"), "lfp": load_virtual("LFP"), "lco": load_virtual("LCO"),
    **{key: load_virtual(name, amb) for key, (name, amb) in EXTRA_VIRTUAL.items()},
    **{key: load_virtual(name, 25.0) for key, name in TWO_RATE_VIRTUAL.items()},
}
REAL_SETS = ("samsung", "samsung-notemp", "enertech", "k2")


# ---- evaluation ----------------------------------------------------------------------------

def failure_text(exc: BaseException) -> str:
    """Exception and the innermost dischargelab frame it came from (file:line function)."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if "dischargelab" in f.filename]
    where = ""
    if frames:
        f = frames[-1]
        where = f" at {f.filename.split('src/')[-1]}:{f.lineno} ({f.name})"
    return f"{type(exc).__name__}: {exc}{where}"


def position(run: Run, train_runs) -> str:
    """Where a held-out run lies relative to the fitted runs.

    ``"inside"``; or ``"current outside"`` (its current more than 10 % beyond the
    fitted currents) and/or ``"ambient outside"`` (its ambient more than 3 K
    beyond the fitted ambients).
    """
    currents = [r.current_A for r in train_runs]
    ambients = [r.ambient_C for r in train_runs]
    out = []
    if not min(currents) / 1.1 <= run.current_A <= max(currents) * 1.1:
        out.append("current outside")
    if not min(ambients) - 3.0 <= run.ambient_C <= max(ambients) + 3.0:
        out.append("ambient outside")
    return ", ".join(out) or "inside"


def evaluate(set_name, title, runs, trainings, family, bootstrap, failures):
    rows = []
    for train in trainings:
        train_runs = [runs[k] for k in train]
        t0 = time.perf_counter()
        try:
            res = dl.fit([r.discharge for r in train_runs], model=family, bootstrap=bootstrap,
                         seed=0)
        except Exception as exc:  # a result: reported, not hidden
            msg = failure_text(exc)
            failures.append((family, set_name, " + ".join(train), "fit", msg))
            for label, run in runs.items():
                if label not in train:
                    rows.append(dict(set=set_name, family=family, train=train, test=label,
                                     failed="fit", position=position(run, train_runs)))
            continue
        fit_s = time.perf_counter() - t0
        bat = res.battery
        for label, run in runs.items():
            if label in train:
                continue
            row = dict(set=set_name, family=family, model=res.model, train=train, test=label,
                       fit_s=fit_s,
                       current_A=run.current_A, ambient_C=run.ambient_C,
                       measured_s=run.measured_s, position=position(run, train_runs),
                       interval=None)
            load = dict(current=run.current_A, cutoff=run.cutoff_V, ambient=run.ambient_C)
            try:
                out = bat.predict(**load).to_dict()
                iv = (out.get("interval95") or {}).get("time_to_cutoff_s")
                row["interval"] = None if iv is None else (float(iv[0]), float(iv[1]))
                row["predicted_s"] = float(out["time_to_cutoff_s"])
                peak_row(row, run, out)
            except Exception as exc:
                failures.append((family, set_name, " + ".join(train), "interval",
                                 failure_text(exc)))
                try:
                    row["predicted_s"] = float(predict_no_interval(
                        bat, interval=False, **load).time_to_cutoff_s)
                except Exception as exc2:
                    failures.append((family, set_name, " + ".join(train), "prediction",
                                     failure_text(exc2)))
                    row["failed"] = "prediction"
                    rows.append(row)
                    continue
            pred, meas = row["predicted_s"], row["measured_s"]
            row["error_pct"] = 100.0 * (pred - meas) / meas if np.isfinite(pred) else np.nan
            if row["interval"] is not None:
                lo, hi = row["interval"]
                row["covered"] = bool(lo <= meas <= hi)
                row["half_width_pct"] = 100.0 * (hi - lo) / 2.0 / pred
            rows.append(row)
    return rows


def peak_row(row, run, out) -> None:
    """Peak temperature measured (logged, up to the cutoff) and predicted, with its
    interval, for thermal families on runs that logged a temperature."""
    d = run.discharge
    band = (out.get("interval95") or {}).get("peak_temperature_C")
    if out.get("peak_temperature_C") is None or d.temperature_C is None or band is None:
        return
    end = int(np.searchsorted(d.time_s, d.time_s[0] + run.measured_s, side="right"))
    row["peak_measured_C"] = float(np.nanmax(d.temperature_C[:max(end, 1)]))
    row["peak_predicted_C"] = float(out["peak_temperature_C"])
    row["peak_interval_C"] = (float(band[0]), float(band[1]))
    row["peak_covered"] = bool(band[0] <= row["peak_measured_C"] <= band[1])


def peak_table(rows, families):
    """Peak cell temperature: error and coverage of its 95 % interval per family."""
    print("| family | held-out runs with a logged temperature | median abs. error [K] | "
          "worst error [K] | coverage of 95 % intervals | median half-width [K] |")
    print("|---|---:|---:|---:|---:|---:|")
    for fam in families:
        fr = [r for r in rows if r["family"] == fam and "peak_covered" in r]
        if not fr:
            continue
        err = np.array([r["peak_predicted_C"] - r["peak_measured_C"] for r in fr])
        half = [(r["peak_interval_C"][1] - r["peak_interval_C"][0]) / 2 for r in fr]
        worst_k = err[np.argmax(np.abs(err))]
        print(f"| {fam} | {len(fr)} | {np.median(np.abs(err)):.1f} | {worst_k:+.1f} | "
              f"{100 * np.mean([r['peak_covered'] for r in fr]):.0f} % "
              f"({sum(r['peak_covered'] for r in fr)}/{len(fr)}) | {np.median(half):.1f} |")


# ---- tables ---------------------------------------------------------------------------------

def fmt_err(row) -> str:
    if row.get("failed"):
        return f"{row['failed']} failed"
    e = row.get("error_pct")
    return "n/a" if e is None or not np.isfinite(e) else f"{e:+.2f} %"


def mark(row) -> str:
    if "covered" not in row:
        return ""
    return " (in)" if row["covered"] else " (OUT)"


def detail_table(rows):
    print("| set | family | fitted on | held out | where | current [A] | measured [s] | "
          "predicted [s] | endurance error | 95 % interval [s] | covered | half-width |")
    print("|---|---|---|---|---|---:|---:|---:|---:|---|---|---:|")
    for r in rows:
        if r.get("failed") == "fit":
            print(f"| {r['set']} | {r['family']} | {' + '.join(r['train'])} | {r['test']} | "
                  f"{r['position']} | | | | fit failed | | | |")
            continue
        iv = r.get("interval")
        ivs = "n/a" if iv is None else f"{iv[0]:.0f} - {iv[1]:.0f}"
        cov = "" if "covered" not in r else ("yes" if r["covered"] else "no")
        hw = "" if "half_width_pct" not in r else f"{r['half_width_pct']:.2f} %"
        pred = r.get("predicted_s")
        print(f"| {r['set']} | {r['family']} | {' + '.join(r['train'])} | {r['test']} | "
              f"{r['position']} | {r['current_A']:.3g} | {r['measured_s']:.0f} | "
              f"{'n/a' if pred is None else format(pred, '.0f')} | {fmt_err(r)} | {ivs} | "
              f"{cov} | {hw} |")


def compact_table(rows, families, titles):
    """One row per (set, training): every held-out error per family, (in)/(OUT) = interval."""
    print("| set | fitted on | held out | " + " | ".join(families) + " |")
    print("|---|---|---|" + "---|" * len(families))
    keys = []
    for r in rows:
        key = (r["set"], r["train"], r["test"])
        if key not in keys:
            keys.append(key)
    for set_name, train, test in keys:
        cells = []
        for fam in families:
            match = [r for r in rows if (r["set"], r["train"], r["test"], r["family"]) ==
                     (set_name, train, test, fam)]
            cells.append(fmt_err(match[0]) + mark(match[0]) if match else "")
        where = next(r["position"] for r in rows if (r["set"], r["train"], r["test"]) ==
                     (set_name, train, test))
        tag = "" if where == "inside" else f" ({where})"
        print(f"| {titles[set_name]} | {' + '.join(train)} | {test}{tag} | "
              + " | ".join(cells) + " |")


def ok_rows(rows):
    return [r for r in rows if not r.get("failed") and np.isfinite(r.get("error_pct", np.nan))]


def worst(rows):
    good = ok_rows(rows)
    n_fail = len(rows) - len(good)
    if not good:
        return None, n_fail
    r = max(good, key=lambda x: abs(x["error_pct"]))
    return r, n_fail


def fmt_worst(rows) -> str:
    r, n_fail = worst(rows)
    fail = f"; {n_fail} failed" if n_fail else ""
    if r is None:
        return "n/a" + fail
    return f"{r['error_pct']:+.2f} % ({r['set']} {r['test']}){fail}"


def summary_table(rows, families):
    print("| family | held-out runs | worst error, single-run fits | worst error, multi-run "
          "fits | coverage of 95 % intervals | median half-width | failures |")
    print("|---|---:|---|---|---:|---:|---:|")
    for fam in families:
        fr = [r for r in rows if r["family"] == fam]
        single = [r for r in fr if len(r["train"]) == 1]
        multi = [r for r in fr if len(r["train"]) > 1]
        with_iv = [r for r in fr if "covered" in r]
        cov = (f"{100 * np.mean([r['covered'] for r in with_iv]):.0f} % "
               f"({sum(r['covered'] for r in with_iv)}/{len(with_iv)})") if with_iv else "n/a"
        med = (f"{np.median([r['half_width_pct'] for r in with_iv]):.2f} %" if with_iv
               else "n/a")
        n_fail = sum(1 for r in fr if r.get("failed"))
        no_iv = len(ok_rows(fr)) - len(with_iv)
        extra = f" (+{no_iv} without interval)" if no_iv else ""
        print(f"| {fam} | {len(fr)} | {fmt_worst(single)} | {fmt_worst(multi)} | {cov}{extra} | "
              f"{med} | {n_fail} |")


def split_table(rows, families):
    """Each family on the runs where ``auto`` picks it and where it is forced on data
    ``auto`` gives to another family (coverage, median half-width, worst error)."""
    picked = {(r["set"], r["train"]): r.get("model") for r in rows if r["family"] == "auto"}
    print("| family | where | held-out runs | coverage of 95 % intervals | median half-width | "
          "worst error |")
    print("|---|---|---:|---:|---:|---|")
    for fam in families:
        if fam == "auto":
            continue
        for where, keep in (("auto picks it", True), ("forced (auto picks another)", False)):
            sel = [r for r in rows if r["family"] == fam and "covered" in r
                   and (picked.get((r["set"], r["train"])) == fam) == keep]
            if not sel:
                continue
            cov = sum(r["covered"] for r in sel)
            print(f"| {fam} | {where} | {len(sel)} | {100 * cov / len(sel):.0f} % "
                  f"({cov}/{len(sel)}) | "
                  f"{np.median([r['half_width_pct'] for r in sel]):.2f} % | {fmt_worst(sel)} |")


def verdict(ok: bool | None) -> str:
    return "n/a" if ok is None else ("met" if ok else "NOT met")


def acceptance(rows, families):
    lines = []

    def pick(set_name, fam, train):
        return [r for r in rows if r["set"] == set_name and r["family"] == fam
                and r["train"] == train]

    # 1. Samsung 1C-only -> 2C, 3C, 4C (auto: shepherd-dynamic with the logged temperature)
    for fam in families:
        sel = [r for r in pick("samsung", fam, ("1C",)) if r["test"] in ("2C", "3C", "4C")]
        if sel and fam in ("shepherd-thermal", "shepherd-dynamic", "auto"):
            ok = ok_rows(sel)
            errs = ", ".join(f"{r['test']} {fmt_err(r)}" for r in sel)
            good = len(ok) == 3 and all(abs(r["error_pct"]) <= SAMSUNG_1C_LIMIT for r in ok)
            lines.append(f"- Samsung 30Q, {fam} fitted on 1C with logged temperature, "
                         f"held-out 2C/3C/4C within {SAMSUNG_1C_LIMIT:g} %: {errs} -> "
                         f"{verdict(good)}")
    # 2. every virtual set: 0.2C + 2C -> 0.5C and 1C within 2 %
    for fam in families:
        sel = [r for r in rows if r["family"] == fam and r["train"] == ("0.2C", "2C")
               and r["test"] in ("0.5C", "1C") and r["set"] not in REAL_SETS]
        if not sel:
            continue
        w, n_fail = worst(sel)
        good = w is not None and n_fail == 0 and abs(w["error_pct"]) <= VIRTUAL_LIMIT
        per_set = ", ".join(
            f"{r['set']} {r['test']} {fmt_err(r)}" for r in sel
            if abs(r.get("error_pct", np.inf)) > 1.0 or r.get("failed"))
        lines.append(f"- virtual cells, {fam} fitted on 0.2C + 2C, held-out 0.5C / 1C within "
                     f"{VIRTUAL_LIMIT:g} % ({len(sel)} runs in "
                     f"{len({r['set'] for r in sel})} sets): worst {fmt_worst(sel)} -> "
                     f"{verdict(good)}" + (f" [over 1 %: {per_set}]" if per_set else ""))
    # 3. the two-rate pouch fits: 1C + 3C -> 2C within 2 % ("every multi-rate fit")
    for fam in families:
        sel = [r for r in rows if r["family"] == fam and r["train"] == ("1C", "3C")
               and r["test"] == "2C" and r["set"] in TWO_RATE_VIRTUAL]
        if sel:
            w, n_fail = worst(sel)
            good = w is not None and n_fail == 0 and abs(w["error_pct"]) <= VIRTUAL_LIMIT
            each = ", ".join(f"{r['set']} {fmt_err(r)}" for r in sel)
            lines.append(f"- two-rate virtual cells, {fam} fitted on 1C + 3C, held-out 2C within "
                         f"{VIRTUAL_LIMIT:g} %: {each} -> {verdict(good)}")
    # 4. multi-rate fits on real cells (Samsung, Enertech) worst held-out <= 2 %
    parts = []
    for fam in families:
        sel = [r for r in rows if r["set"] in ("samsung", "samsung-notemp", "enertech")
               and r["family"] == fam and len(r["train"]) > 1]
        if sel:
            w, n_fail = worst(sel)
            good = w is not None and n_fail == 0 and abs(w["error_pct"]) <= MULTI_RATE_REAL_LIMIT
            parts.append(f"{fam}: {fmt_worst(sel)} -> {verdict(good)}")
    if parts:
        lines.append(f"- multi-rate fits on real cells (Samsung, Enertech), worst held-out "
                     f"<= {MULTI_RATE_REAL_LIMIT:g} %: " + "; ".join(parts))
    # 5. interval coverage and width
    parts = []
    for fam in families:
        fr = [r for r in rows if r["family"] == fam]
        with_iv = [r for r in fr if "covered" in r]
        if not with_iv:
            parts.append(f"{fam}: no intervals ({len(fr)} held-out runs) -> NOT met")
            continue
        cov = 100 * np.mean([r["covered"] for r in with_iv])
        med = float(np.median([r["half_width_pct"] for r in with_iv]))
        missing = len(fr) - len(with_iv)
        good = missing == 0 and cov >= COVERAGE_GOAL and med <= HALF_WIDTH_GOAL
        miss = f", {missing} runs without interval" if missing else ""
        parts.append(f"{fam}: coverage {cov:.0f} % of {len(with_iv)}, median half-width "
                     f"{med:.2f} %{miss} -> {verdict(good)}")
    lines.append(f"- 95 % intervals cover >= {COVERAGE_GOAL:g} % of held-out runs with median "
                 f"half-width <= {HALF_WIDTH_GOAL:g} %: " + "; ".join(parts))
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=default_data_dir())
    parser.add_argument("--sets", default=",".join(SETS))
    parser.add_argument("--families", default=",".join([*FAMILIES, "auto"]))
    parser.add_argument("--bootstrap", type=int, default=30,
                        help="bootstrap refits per fit (the interval draws; default 30)")
    parser.add_argument("--detail", action="store_true",
                        help="also print one row per held-out prediction")
    parser.add_argument("--json", type=Path, help="write every row to this JSON file")
    args = parser.parse_args(argv)
    families = [f for f in args.families.split(",") if f]
    set_names = [s for s in args.sets.split(",") if s]
    t_start = time.perf_counter()
    rows, failures, titles, seconds = [], [], {}, {}
    loaded = {}
    for name in set_names:
        if name not in REAL_SETS and not (VIRTUAL / "index.json").is_file():
            print(f"(set {name}: {VIRTUAL}/index.json not found; skipped)")
            continue
        loaded[name] = SETS[name](args.data)
        titles[name] = loaded[name][0]
    for fam in families:
        t0 = time.perf_counter()
        for name, (title, runs, trainings) in loaded.items():
            rows += evaluate(name, title, runs, trainings, fam, args.bootstrap, failures)
        seconds[fam] = time.perf_counter() - t0

    print(f"## Held-out time to cutoff: endurance error per family (bootstrap={args.bootstrap}; "
          f"(in)/(OUT): the 95 % interval covers / misses the measured time)\n")
    compact_table(rows, families, titles)
    if args.detail:
        print("\n## Every held-out prediction\n")
        detail_table(rows)
    print("\n## Summary per family (held-out runs only)\n")
    summary_table(rows, families)
    if "auto" in families:
        print("\n## Each family where auto picks it and where it is forced\n")
        split_table(rows, families)
    print("\n## Peak cell temperature (thermal families, runs with a logged temperature)\n")
    peak_table(rows, families)
    print("\n## Acceptance figures\n")
    for line in acceptance(rows, families):
        print(line)
    if failures:
        print("\n## Failures (library exceptions, first of each kind)\n")
        seen = set()
        for fam, set_name, train, stage, msg in failures:
            if (fam, stage, msg) in seen:
                continue
            seen.add((fam, stage, msg))
            n = sum(1 for f in failures if (f[0], f[3], f[4]) == (fam, stage, msg))
            print(f"- {fam}, {stage} ({n}x, first: {set_name} fitted on {train}): {msg}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str), encoding="utf-8")
    print(f"\nRun time: {time.perf_counter() - t_start:.0f} s ("
          + ", ".join(f"{f} {s:.0f} s" for f, s in seconds.items()) + ")")
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.1f} (shared machine)")


if __name__ == "__main__":
    main()
