"""The one-rate prior, measured: how far a fit to ONE rate misses the other rates.

A fit to one constant-current run cannot show how the cell's capacity and overpotentials
change with the current, so its predictions at other currents carry a model error that
its own data cannot measure. This script measures it on every cell with a rate series:

* **real cells** (``../shared/data``): Samsung 30Q S001 (C/10 ... 4C, cell temperature
  logged; also with the temperature column dropped), Enertech LCO pouch (0.1C ... 2C, no
  temperature);
* **PyBaMM virtual cells** (``tests/data/virtual``, ``benchmarks/virtual_cells.py``): NMC
  (Chen2020), LFP (Prada2013, DFN to 2.0 V and SPMe to 2.5 V), LCO (Marquis2019) at 15, 25
  and 35 degC, and the NMC pouch (Ecker2015), NCA (NCA_Kim2011), NMC532 (Mohtat2020), LCO
  pouch (Ai2020) and the LFP cell again (3C, 40 degC) at 25 and 40 degC; each with its
  temperature and with the temperature column dropped.

Every series can also be measured with its rest sample before the load dropped (``--rest
without`` or ``both``): a logger started with the load on writes no rest voltage, and then
nothing in one constant current tells the series resistance from E0. Those fits take the
law of their class measured on the runs as logged (as the package does; with ``--rest
without`` alone, on themselves); the acceptance is printed for each kind apart.

Every run of a series (one cell at one ambient) is fitted alone (``dischargelab.fit``,
each family, ``bootstrap=30``) and predicts every other run of the series at its mean
current, cutoff and ambient (``Battery.predict``). The relative error of the time to
cutoff ``e`` and the extrapolation ratio ``r`` (predicted over fitted current) are kept
with what the user's file shows: the family, the curve's shape (``flat`` when the plateau
ratio of :func:`dischargelab.fit.result.plateau_ratio` is below
:data:`dischargelab.onerate.FLAT_PLATEAU_RATIO`: LiFePO4; else ``sloped``) and whether
a cell temperature was logged. Never the cell's name.

**The law.** Per class (family, shape, temperature logged), the relative standard deviation
of a one-rate prediction is ``sd(r) = base + k |ln r|``, with ``base`` the RMS error of the
fitted run's own time to cutoff (at least 0.5 %) and ``k`` set so that the 95th percentile
of ``(|e| - base) / |ln r|`` over the pairs of that class extrapolating up (``r > 1``; and,
separately, down) by at least x1.5 lies at the 95 % interval's edge (the errors are
heavy-tailed: an RMS would be set by the worst few). Runs that collapsed (less than 60 % of
the series' charge: the virtual NMC cell at 3C, twice its rated current, runs out of
electrolyte) are left out of the law and counted in the coverage.

**Leave one cell out**: the law used for a cell's predictions is measured on the
other cells only (a cell is its parameter set or its real cell, whatever its ambient or
cutoff; Ai2020 is the Enertech cell), and the intervals reported here are the package's
own (``Battery.predict``, parameter draws times this model error) with that law. The
law from all cells is written to ``src/dischargelab/data/one_rate_error.json``
(``--write``), which :mod:`dischargelab.onerate` reads.

**Two-rate fits** (for the advice on the next test): every series is also fitted on two
runs a factor 2-5 apart; the median model error (``FitResult.model_error``) of each
class is written to the same file.

Usage: python benchmarks/one_rate_errors.py [--write] [--families shepherd,...]
       [--cells samsung,...] [--rest as-logged|without|both] [--json rows.json]
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import accuracy  # noqa: E402
import dischargelab as dl  # noqa: E402
from _machine import machine_line  # noqa: E402
from dischargelab import onerate, uncertainty  # noqa: E402
from dischargelab.fit.auto import ONE_RATE_FAMILY  # noqa: E402
from dischargelab.predict import predict as predict_point  # noqa: E402

VIRTUAL = accuracy.VIRTUAL
TABLE_PATH = HERE.parent / "src" / "dischargelab" / "data" / "one_rate_error.json"
FAMILIES = ("shepherd", "shepherd-thermal", "shepherd-dynamic", "ecm")
BOOTSTRAP = 30
#: Extrapolations by less than this ratio do not set the growth (``e / ln r`` is noisy).
MIN_GROWTH_RATIO = 1.5
#: The acceptance's range of one-rate extrapolations (up, x2 to x4; mean currents of the
#: measured runs differ from the nominal rates by a little).
ACCEPT_RATIOS = (1.9, 4.2)
#: Two-rate fits: runs a factor 2-5 apart, at most this many pairs per series and family
#: (the pair nearest a factor 3).
TWO_RATE_RATIOS = (1.9, 5.5)
TWO_RATE_PAIRS = 1
COVERAGE_GOAL, HALF_WIDTH_GOAL = 90.0, 6.0
#: A run that delivered less than this fraction of its series' largest charge collapsed
#: (the virtual NMC cell at 3C runs out of electrolyte with half its charge left, at twice
#: its rated current): left out of the law, counted in the coverage.
COLLAPSE_FRACTION = 0.6
#: The law's growth puts this quantile of the measured errors at the 95 % interval's edge.
LAW_QUANTILE, Z95 = 0.95, 1.959964

#: Ambient of the virtual series measured [degC] (the cells' 15, 35 and 40 degC runs
#: repeat the same cells: they would weigh those cells more, and cost the time of the run).
SERIES_AMBIENT_C = 25.0
#: Predicted runs: up to this ratio above the fitted current and down to its inverse below
#: (a C/10 run predicted from a fast fit is ten hours of simulation for one more pair).
TARGET_RATIOS = (1.0 / 4.5, 12.0)

#: Cell identity of each virtual parameter set (leave-one-cell-out groups).
CELL_OF_SET = {"Chen2020": "LG M50 (Chen2020)", "Prada2013": "A123 26650 (Prada2013)",
               "Marquis2019": "Marquis2019 LCO", "Ecker2015": "Kokam pouch (Ecker2015)",
               "NCA_Kim2011": "NCA (Kim2011)", "Mohtat2020": "NMC532 (Mohtat2020)",
               "Ai2020": "Enertech LCO"}


@dataclass
class Series:
    """Runs of one cell at one ambient (``accuracy.Run`` by label)."""

    cell: str
    title: str
    runs: dict
    temperature: bool
    rest: bool = True


def real_series(data: Path):
    out = []
    _, runs, _ = accuracy.load_samsung(data)
    out.append(Series("Samsung 30Q S001", "Samsung 30Q", runs, True))
    _, runs, _ = accuracy.load_enertech(data)
    out.append(Series("Enertech LCO", "Enertech LCO", runs, False))
    return out


def virtual_series():
    """Every virtual constant-current series of ``index.json``, by (set, ambient)."""
    index = json.loads((VIRTUAL / "index.json").read_text(encoding="utf-8"))
    groups = {}
    for entry in index["files"]:
        if entry.get("rate_C") is None:
            continue
        key = (entry.get("set", entry["chemistry"]), float(entry["ambient_C"]))
        groups.setdefault(key, []).append(entry)
    out = []
    for (set_name, ambient), entries in sorted(groups.items()):
        if len(entries) < 2 or abs(ambient - SERIES_AMBIENT_C) > 0.1:
            continue
        runs = {}
        for entry in sorted(entries, key=lambda e: e["rate_C"]):
            d = dl.read(VIRTUAL / entry["file"])
            label = f"{entry['rate_C']:g}C"
            runs[label] = accuracy.make_run(label, d, entry["cutoff_V"], ambient)
        cell = CELL_OF_SET.get(entries[0]["parameter_set"], entries[0]["parameter_set"])
        out.append(Series(cell, f"virtual {set_name} {ambient:g}degC", runs, True))
    return out


def _dropped(series: Series, suffix: str, **discharge) -> Series:
    """The series with ``discharge``'s fields of every run's Discharge set (to None)."""
    runs = {k: accuracy.make_run(k, replace(r.discharge, **discharge), r.cutoff_V,
                                 r.ambient_C) for k, r in series.runs.items()}
    return replace(series, title=series.title + suffix, runs=runs,
                   temperature=series.temperature and "temperature_C" not in discharge,
                   rest=series.rest and "rest_voltage_V" not in discharge)


def without_temperature(series: Series) -> Series:
    return _dropped(series, ", no temperature", temperature_C=None)


def without_rest(series: Series) -> Series:
    """The series as a logger started with the load on writes it: no rest sample before
    the load step."""
    return _dropped(series, ", no rest sample", rest_voltage_V=None)


def delivered_Ah(run) -> float:
    """Charge a run delivered to its cutoff [Ah] (its mean current times its time)."""
    return run.current_A * run.measured_s / 3600.0


def covariates(battery, one_rate: bool = True) -> dict:
    """What the user's file shows, from the fitted battery (``onerate.one_rate_class``)."""
    extra = battery.extra
    return {"plateau": extra.get("fit_plateau_ratio"),
            "temperature": "fit_temperature_rise_K" in extra,
            "class": onerate.one_rate_class(battery, one_rate)}


#: Raise of the cutoff [V per cell] whose effect on the predicted time is kept per row.
FEATURE_SHIFT_V = 0.05

#: Folder of fitted battery files reused between runs (``--cache``), or None.
CACHE: list = []


def code_version() -> str:
    """Hash of the package's model and fit sources: a cached fit is reused only by the
    code that made it."""
    import hashlib

    root = Path(dl.__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted([*root.glob("models/*.py"), *root.glob("fit/*.py"),
                        root / "thermalprior.py", root / "discharge.py"]):
        h.update(path.read_bytes())
    return h.hexdigest()[:12]


def cached_fit(key: str, data, **options):
    """The battery of ``dischargelab.fit(data, **options)``, from the ``--cache`` folder
    when it holds one made by this code; ``(battery, model)``."""
    if not CACHE:
        res = dl.fit(data, **options)
        return res.battery, res.model
    import hashlib

    path = CACHE[0] / code_version() / (hashlib.sha256(key.encode()).hexdigest()[:20]
                                        + ".json")
    if path.is_file():
        bat = dl.load(path)
        return bat, bat.model
    res = dl.fit(data, **options)
    path.parent.mkdir(parents=True, exist_ok=True)
    res.battery.save(path)
    return res.battery, res.model


def one_rate_rows(series: Series, family: str):
    """Fit each run alone, predict the others (point values): one row per pair."""
    rows = []
    for key, run in series.runs.items():
        try:
            bat, model = cached_fit(f"one|{series.title}|{key}|{family}|{BOOTSTRAP}",
                                    run.discharge, model=family, bootstrap=BOOTSTRAP, seed=0)
        except dl.DischargelabError as exc:
            print(f"  ({series.title} {key} {family}: fit failed: {exc})")
            continue
        cov = covariates(bat)
        most = max(delivered_Ah(r) for r in series.runs.values())
        for target_key, target in series.runs.items():
            if not TARGET_RATIOS[0] <= target.current_A / run.current_A <= TARGET_RATIOS[1]:
                continue
            load = dict(current=target.current_A, cutoff=target.cutoff_V,
                        ambient=target.ambient_C)
            try:
                sim = predict_point(bat, interval=False, **load).simulation
                t = sim.time_to_cutoff_s
                feat = {"peak_rise_K": (sim.peak_temperature_C - target.ambient_C
                                        if sim.peak_temperature_C is not None else 0.0),
                        "capacity_Ah": sim.capacity_Ah}
                up = predict_point(bat, interval=False, **dict(
                    load, cutoff=load["cutoff"] + FEATURE_SHIFT_V)).time_to_cutoff_s
                feat["shift"] = 1.0 - up / t
            except dl.DischargelabError:
                t, feat = float("nan"), {}
            rows.append(dict(cell=series.cell, series=series.title, family=family,
                             rest=series.rest,
                             model=model, fitted=key, target=target_key,
                             ratio=target.current_A / run.current_A,
                             error=t / target.measured_s - 1.0, predicted_s=t,
                             measured_s=target.measured_s, load=load, battery=bat,
                             fit_rise_K=bat.extra.get("fit_temperature_rise_K"),
                             collapse=delivered_Ah(target) < COLLAPSE_FRACTION * most,
                             **feat, **cov))
    return rows


# ---- the law --------------------------------------------------------------------------------

def law(rows) -> dict:
    """``{class: {"base", "up", "down", "pairs", "cells"}}`` from one-rate rows.

    ``up``/``down``: the growth per ``|ln r|`` that puts the 95th percentile of the
    measured ``(|e| - base) / |ln r|`` at the 95 % interval's edge (``z = 1.96``): the
    errors are heavy-tailed, so their RMS would be set by the worst few. Runs that
    collapsed (:data:`COLLAPSE_FRACTION`) are left out of the law (no family describes
    them) and counted in the coverage."""
    out = {}
    for cls in sorted({r["class"] for r in rows}):
        sel = [r for r in rows if r["class"] == cls and np.isfinite(r["error"])
               and not r["collapse"]]
        self_err = [r["error"] for r in sel if r["fitted"] == r["target"]]
        base = max(float(np.sqrt(np.mean(np.square(self_err)))) if self_err else 0.0,
                   uncertainty.MIN_HELD_OUT_SD)
        entry = {"base": base, "cells": sorted({r["cell"] for r in sel})}
        for side, keep in (("up", lambda x: x >= MIN_GROWTH_RATIO),
                           ("down", lambda x: x <= 1.0 / MIN_GROWTH_RATIO)):
            part = [r for r in sel if keep(r["ratio"])]
            entry[f"{side}_pairs"] = len(part)
            entry[side] = (float(np.quantile([max(abs(r["error"]) - base, 0.0)
                                              / abs(math.log(r["ratio"])) for r in part],
                                             LAW_QUANTILE) / Z95) if part else None)
        out[cls] = entry
    return out


def apply_law(table: dict, rows) -> None:
    """The interval of each row in the acceptance's range (x2-x4 up) with ``table`` in
    place of the package's (leave one cell out)."""
    for r in rows:
        if not ACCEPT_RATIOS[0] <= r["ratio"] <= ACCEPT_RATIOS[1] or \
                not np.isfinite(r["error"]):
            continue
        with onerate.one_rate_table_override(table):
            out = r["battery"].predict(**r["load"]).to_dict()
        lo, hi = out["interval95"]["time_to_cutoff_s"]
        pred = out["time_to_cutoff_s"]
        r["interval"] = (lo, hi)
        r["covered"] = bool(lo <= r["measured_s"] <= hi)
        r["half_width_pct"] = 100.0 * (hi - lo) / 2.0 / pred


def loco_tables(rows, families):
    """``{cell: table}``: the law of every family measured without that cell."""
    tables = {}
    for cell in sorted({r["cell"] for r in rows}):
        tables[cell] = law([r for r in rows if r["cell"] != cell and r["family"] in families])
    return tables


# ---- two-rate fits ---------------------------------------------------------------------------

def two_rate_rows(series: Series, family: str):
    """Fits to two runs :data:`TWO_RATE_RATIOS` apart (the :data:`TWO_RATE_PAIRS` pairs
    nearest a factor 3) with their held-out model error."""
    keys = list(series.runs)
    pairs = []
    for a in range(len(keys)):
        for b in range(a + 1, len(keys)):
            ratio = series.runs[keys[b]].current_A / series.runs[keys[a]].current_A
            if TWO_RATE_RATIOS[0] <= ratio <= TWO_RATE_RATIOS[1]:
                pairs.append((abs(math.log(ratio / 3.0)), a, b))
    rows = []
    for _, a, b in sorted(pairs)[:TWO_RATE_PAIRS]:
        ra, rb = series.runs[keys[a]], series.runs[keys[b]]
        try:
            bat, model = cached_fit(f"two|{series.title}|{keys[a]}|{keys[b]}|{family}",
                                    [ra.discharge, rb.discharge], model=family, bootstrap=0,
                                    seed=0)
        except dl.DischargelabError:
            continue
        err = bat.extra.get("model_error") or {}
        if "relative_sd" not in err:
            continue
        rows.append(dict(cell=series.cell, series=series.title, family=family,
                         model=model, fitted=f"{keys[a]} + {keys[b]}",
                         sd=float(err["relative_sd"]), dof=float(err.get("dof") or 0),
                         **covariates(bat, one_rate=False)))
    return rows


def two_rate_law(rows) -> dict:
    out = {}
    for cls in sorted({r["class"] for r in rows}):
        sel = [r for r in rows if r["class"] == cls]
        out[cls] = {"sd": float(np.median([r["sd"] for r in sel])),
                    "dof": float(np.median([r["dof"] for r in sel])), "fits": len(sel),
                    "cells": sorted({r["cell"] for r in sel})}
    return out


# ---- tables --------------------------------------------------------------------------------

def pct(x) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * x:.2f} %"


def print_law(table):
    print("| class (family / shape / temperature) | base | growth up (per ln r) | pairs up | "
          "growth down | pairs down | cells |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for cls, e in table.items():
        print(f"| {cls} | {pct(e['base'])} | {pct(e['up'])} | {e['up_pairs']} | "
              f"{pct(e['down'])} | {e['down_pairs']} | {len(e['cells'])} |")


def print_errors_by_ratio(rows):
    """RMS error per class and ratio bin (is the growth linear in ln r?)."""
    bins = [(1.4, 2.6), (2.6, 4.5), (4.5, 12.0), (12.0, 50.0)]
    print("| class | " + " | ".join(f"x{a:g}-{b:g}: RMS (n)" for a, b in bins) + " |")
    print("|---|" + "---:|" * len(bins))
    for cls in sorted({r["class"] for r in rows}):
        cells = []
        for a, b in bins:
            e = [r["error"] for r in rows if r["class"] == cls and a <= r["ratio"] < b
                 and np.isfinite(r["error"])]
            cells.append(f"{pct(float(np.sqrt(np.mean(np.square(e)))))} ({len(e)})" if e
                         else "")
        print(f"| {cls} | " + " | ".join(cells) + " |")


def accept_rows(rows):
    return [r for r in rows if "covered" in r and ACCEPT_RATIOS[0] <= r["ratio"]
            <= ACCEPT_RATIOS[1]]


def print_acceptance(rows, families):
    print("| family | one-rate runs predicting x2-x4 | coverage of 95 % intervals | median "
          "half-width | worst error | verdict |")
    print("|---|---:|---:|---:|---|---|")
    for fam in [*families, "auto"]:
        sel = accept_rows([r for r in rows if r["family"] == fam])
        if not sel:
            continue
        collapsed = [r for r in sel if r["collapse"]]
        cov = 100.0 * np.mean([r["covered"] for r in sel])
        med = float(np.median([r["half_width_pct"] for r in sel]))
        w = max(sel, key=lambda r: abs(r["error"]))
        ok = cov >= COVERAGE_GOAL and med <= HALF_WIDTH_GOAL
        note = (f"; {sum(r['covered'] for r in collapsed)} of {len(collapsed)} collapsed "
                f"runs covered" if collapsed else "")
        print(f"| {fam} | {len(sel)} | {cov:.0f} % ({sum(r['covered'] for r in sel)}/"
              f"{len(sel)}{note}) | {med:.2f} % | {100 * w['error']:+.2f} % ({w['series']} "
              f"{w['fitted']} -> {w['target']}) | {'met' if ok else 'NOT met'} |")


def print_classes(rows):
    print("| family | class | runs x2-x4 | coverage | median half-width | RMS error |")
    print("|---|---|---:|---:|---:|---:|")
    for fam in sorted({r["family"] for r in rows}):
        for cls in sorted({r["class"] for r in rows if r["family"] == fam}):
            sel = accept_rows([r for r in rows if r["family"] == fam and r["class"] == cls])
            if not sel:
                continue
            cov = sum(r["covered"] for r in sel)
            rms = float(np.sqrt(np.mean([r["error"] ** 2 for r in sel])))
            print(f"| {fam} | {cls} | {len(sel)} | {100 * cov / len(sel):.0f} % ({cov}/"
                  f"{len(sel)}) | {np.median([r['half_width_pct'] for r in sel]):.2f} % | "
                  f"{pct(rms)} |")


def write_table(doc: dict) -> None:
    from dischargelab.atomic import write_text

    write_text(TABLE_PATH, json.dumps(doc, indent=1) + "\n")
    print(f"\nwritten: {TABLE_PATH}")


def merge(paths) -> None:
    """The package's table from runs of different families (``--table-out`` files)."""
    docs = [json.loads(Path(p).read_text(encoding="utf-8")) for p in paths]
    doc = dict(docs[0], one_rate={}, two_rate={},
               measured="; ".join(sorted({d["measured"] for d in docs})))
    for d in docs:
        doc["one_rate"].update(d["one_rate"])
        doc["two_rate"].update(d["two_rate"])
    print_law(doc["one_rate"])
    write_table(doc)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=accuracy.default_data_dir())
    parser.add_argument("--families", default=",".join(FAMILIES))
    parser.add_argument("--cells", default=None,
                        help="only series whose title contains one of these (comma list)")
    parser.add_argument("--no-two-rate", action="store_true", help="skip the two-rate fits")
    parser.add_argument("--rest", choices=("as-logged", "without", "both"), default="as-logged",
                        help="the runs as logged (a rest sample before the load; the default), "
                             "with that sample dropped (a logger started with the load on), or "
                             "both")
    parser.add_argument("--cache", type=Path,
                        help="keep the fitted battery files here and reuse those made by the "
                             "same model and fit code (a law can then be measured again "
                             "without fitting again)")
    parser.add_argument("--write", action="store_true",
                        help=f"write the law from all cells to {TABLE_PATH.name}")
    parser.add_argument("--json", type=Path, help="write every one-rate row here")
    parser.add_argument("--table-out", type=Path,
                        help="write this run's law (its families) to a JSON file")
    parser.add_argument("--merge", type=Path, nargs="+",
                        help="only merge the --table-out files of runs of other families "
                             "into the package's table, and print it")
    args = parser.parse_args(argv)
    if args.merge:
        return merge(args.merge)
    families = [f for f in args.families.split(",") if f]
    if args.cache:
        CACHE[:] = [args.cache]
    t0 = time.perf_counter()
    series = real_series(args.data) if (args.data / "samsung30q_S001").is_dir() else []
    series += virtual_series()
    series += [without_temperature(s) for s in series if s.temperature]
    if args.rest != "as-logged":
        series = ([] if args.rest == "without" else series) + [without_rest(s) for s in series]
    if args.cells:
        wanted = [w.lower() for w in args.cells.split(",")]
        series = [s for s in series if any(w in s.title.lower() for w in wanted)]
    rows, two = [], []
    for s in series:
        for fam in families:
            rows += one_rate_rows(s, fam)
            if not args.no_two_rate:
                two += two_rate_rows(s, fam)
        print(f"  {s.title}: {len(s.runs)} runs, {time.perf_counter() - t0:.0f} s",
              file=sys.stderr)
    # auto on one rate is ONE_RATE_FAMILY (choose_model): its rows are that family's
    rows += [dict(r, family="auto") for r in rows if r["family"] == ONE_RATE_FAMILY]
    # the law is measured on the runs as logged (the package's), and applied to both kinds
    logged = [r for r in rows if r["family"] != "auto" and r["rest"]] or \
        [r for r in rows if r["family"] != "auto"]
    tables = loco_tables(logged, families)
    for r in rows:
        r["loco"] = tables[r["cell"]]
    for cell, table in tables.items():
        apply_law(table, [r for r in rows if r["cell"] == cell])
    full = law(logged)
    two_law = two_rate_law(two)

    print(f"## One-rate extrapolation: the law from every cell ({len(rows)} pairs, "
          f"{len({r['cell'] for r in rows})} cells, {len(series)} series)\n")
    print_law(full)
    print("\n## One-rate errors by extrapolation ratio (up)\n")
    print_errors_by_ratio([r for r in rows if r["family"] != "auto" and r["ratio"] > 1])
    print("\n## Acceptance: one-rate 95 % intervals, x2-x4 up, each cell's law measured "
          "without it (leave one cell out)\n")
    for label, rest in (("the runs as logged, a rest sample before the load", True),
                        ("the same runs without their rest sample", False)):
        part = [r for r in rows if r["rest"] is rest]
        if part:
            print(f"\n{label}:\n")
            print_acceptance(part, families)
    print("\n## Per class\n")
    print_classes(rows)
    if two:
        print("\n## Two-rate fits (runs x2-x5 apart): median model error inside the fitted "
              "currents\n")
        print("| class | fits | median sd | median dof | cells |")
        print("|---|---:|---:|---:|---:|")
        for cls, e in two_law.items():
            print(f"| {cls} | {e['fits']} | {pct(e['sd'])} | {e['dof']:.0f} | "
                  f"{len(e['cells'])} |")
    doc = {"generator": "python benchmarks/one_rate_errors.py --write",
           "law": "relative sd of a one-rate time to cutoff = base + growth * |ln r|, "
                  "r = predicted / fitted current (up: r > 1, down: r < 1)",
           "measured": machine_line(), "one_rate": full, "two_rate": two_law}
    if args.table_out:
        args.table_out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    if args.write:
        write_table(doc)
    if args.json:
        keep = ("cell", "series", "rest", "family", "model", "fitted", "target", "ratio", "error",
                "class", "plateau", "temperature", "covered", "half_width_pct", "collapse",
                "shift", "peak_rise_K", "capacity_Ah", "fit_rise_K", "predicted_s",
                "measured_s")
        args.json.write_text(json.dumps([{k: r.get(k) for k in keep} for r in rows],
                                        indent=1, default=str), encoding="utf-8")
    print(f"\nRun time {time.perf_counter() - t0:.0f} s. Machine: {machine_line()}; load "
          f"average {os.getloadavg()[0]:.1f} (shared machine)")


if __name__ == "__main__":
    main()
