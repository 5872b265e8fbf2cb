"""Capacity now against the truth over a matrix of conditions: does its 95 % band hold?

Each condition is a pack life with a known truth, logged as a BMS or a tester would, with
every capacity test cut out but the first: after each block of use (the cycles between
two tests) the logbook's capacity now is compared with the next test's capacity.

* **Synthetic lives** from the project's one engine (``tests/synthetic_life.py``: an
  ``ecm`` cell with relaxation, diffusion, self-heating and a known fade with a knee,
  its open-circuit curve 8 mV off the generic one and moved by ageing), one condition
  changed at a time from the base (CV charge to 4.2 V, 1 Hz samples, 15-minute rests,
  25 degC): the curve (the generic one; moving faster with age), the routine charge's
  stop voltage (3.9-4.1 V, the tests still charged to 4.2 V; constant current only),
  the sampling period (30-200 s, the missions' power steps between samples), the ambient
  (0 and 45 degC), short rests (60 s), shallow missions; the chemistry (a LiPo LiCoO2
  cell charged to 4.2 V, a LiHV one to 4.35 V, both cut off at 3.0 V; an LFP cell charged
  to 3.65 V, its curve flat over most of its charge); a partial routine charge (constant
  current stopped at 80 %, no constant voltage); flights from a storage charge (the
  routine charge stopped at 60 %, ~3.8 V per cell, two hours' rest before each mission,
  the missions at 60 % so that they end above the cutoff: compare with the shallow
  missions).
* **PyBaMM lives** (``tests/pybamm_life.py``, only where PyBaMM is installed; skipped
  otherwise): physics the estimators were not built from. PyBaMM's ``OKane2022`` cell
  (LG M50, NMC811 / graphite-SiOx, scaled to ~3 Ah) in the SPM with SEI growth (also on
  cracks), partially reversible lithium plating, particle cracking and the loss of active
  material it drives, its rates raised so that 40 cycles fade it by 12-16 %; missions
  at constant power per step, CC-CV charges to 4.2 V, a C/5 test every 5 cycles. The
  base at 25 degC, the routine charge stopping at 4.0 V, a cold ambient (5 degC, where
  the loss of active material leads), and deeper missions (the cruise 1.8 times as long:
  the missions end where the lithium lost shortens the curve); and the base and the cold
  ambient five times as long at a fifth of the degradation rates (200 cycles, a test
  every 25: :data:`SLOW_PACE`). The lives are kept in ``~/.cache/dischargelab-bench``
  (``tests/pybamm_life.py``: ``cache_folder``).
* **The shared eVTOL lives** (CMU, VAH27 and VAH30; Bills et al. 2023): as logged,
  resampled to 30 s and 60 s (interpolated between the logged samples, 166.5 s apart),
  and with the routine charges ending at 4.0 V: every voltage of the routine moved to
  the state of charge a 4.0 V constant-voltage end leaves (the cell's own curve, from
  its latest C/5 test's samples at its full current, over the charge not put in, at
  each sample's state of charge counted from the charge's end, each mission's charge
  taken from the recharge after it: :func:`recharged_counts`), the tests and the
  4.2 V charge before each untouched; its blocks end at the first test
  after a mission that the shift takes below the cutoff (a cell charged to 4.0 V would
  have stopped there, which a shift cannot show). And with every test cut out, the pack
  given only its label capacity (3.0 Ah) and chemistry: no full discharge sets the scale.

Prints per condition: blocks, capacity now's error against the next test (median and
largest), blocks within 2 %, the band's coverage of the next test, its median half
width, and the mean error (bias); then how the constants were chosen (the drift share, the
hidden fade per resistance rise and its spread), each condition left out in turn.
``--rows FILE.csv`` keeps every block.

References: A. Bills et al., Sci. Data 10, 344 (2023).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import pickle
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT / "tests"))

from _machine import machine_line  # noqa: E402
from dischargelab.logbook import Logbook  # noqa: E402
from dischargelab.logbook.over_life import CapacityNow  # noqa: E402
from dischargelab.logbook.results import DEFAULT_EOL, build_health, capacity_now  # noqa: E402
from health_from_use import (  # noqa: E402
    CMU,
    blocks_of,
    current_runs,
    cut_copy,
    find_tests,
    load_avg,
)

#: The base life of the synthetic conditions.
BASE = dict(cycles=40, test_every=5, sample_hz=1.0, fade_per_efc=3e-3, knee_efc=40.0,
            knee_per_efc2=1e-4, ocv_wiggle_V=0.008, lli_share=0.3)

#: Synthetic conditions: name -> changes to the base.
SYNTHETIC = {
    "base: CV 4.2 V, 1 Hz, 15 min rests, 25 degC": {},
    "the generic curve, not ageing": dict(ocv_wiggle_V=0.0, lli_share=0.0),
    "the curve moves fast with age": dict(lli_share=0.8),
    "routine charge CV 4.1 V": dict(cv_V=4.1),
    "routine charge CV 4.0 V": dict(cv_V=4.0),
    "routine charge CV 3.9 V": dict(cv_V=3.9),
    "routine charge CC only to 4.2 V": dict(cv=False),
    "samples every 30 s": dict(sample_hz=1 / 30),
    "samples every 60 s": dict(sample_hz=1 / 60),
    "samples every 200 s": dict(sample_hz=1 / 200),
    "ambient 0 degC": dict(ambient_C=0.0, season_C=3.0),
    "ambient 45 degC": dict(ambient_C=45.0, season_C=3.0),
    "rests of 60 s": dict(rest_s=60.0),
    "shallow missions (60 %)": dict(mission_scale=0.6),
    "LiPo (LiCoO2) 4.2 V, cutoff 3.0 V": dict(chemistry="lipo", cutoff_V=3.0),
    "LiHV 4.35 V, cutoff 3.0 V": dict(chemistry="lihv", cv_V=4.35, test_cv_V=4.35,
                                      cutoff_V=3.0),
    "LFP 3.65 V, flat curve": dict(chemistry="lifepo4", cv_V=3.65, test_cv_V=3.65),
    "partial routine charge: CC to 80 %": dict(charge_stop_soc=0.8),
    "flights from a storage charge (60 %, 2 h rest; missions 60 %)":
        dict(charge_stop_soc=0.6, storage_rest_s=7200.0, mission_scale=0.6),
}

#: A PyBaMM life five times as long at a fifth of the degradation rates (the SEI's
#: diffusion-limited growth goes as the square root of time, so its rate / 5 over five
#: times the cycles; the loss of active material's proportional term / 5): ~25 % of the
#: pace of the other PyBaMM conditions, a capacity test every 25 cycles.
SLOW_PACE = dict(cycles=200, test_every=25, sei_factor=3000.0, lam_factor=10.0)

#: PyBaMM conditions: name -> changes to ``pybamm_life.PybammLifeSpec`` (their own
#: ``cycles`` over ``--cycles``).
PYBAMM = {
    "PyBaMM SEI+plating+LAM NMC (OKane2022 SPM), 25 degC": {},
    "PyBaMM OKane2022, routine charge CV 4.0 V": dict(cv_V=4.0),
    "PyBaMM OKane2022, ambient 5 degC": dict(ambient_C=5.0),
    "PyBaMM OKane2022, deep missions (cruise x1.8)": dict(cruise_scale=1.8),
    "PyBaMM OKane2022 at a fifth of the pace (200 cycles), 25 degC":
        dict(SLOW_PACE),
    "PyBaMM OKane2022 at a fifth of the pace (200 cycles), ambient 5 degC":
        dict(SLOW_PACE, ambient_C=5.0),
}

#: The eVTOL cells' cutoff [V].
CUTOFF_CELL_V = 2.5

#: Real conditions: name -> (cell file, resampling period [s] or None, routine CV [V] or None).
REAL = {f"{cell} {how}": (cell, period, cv)
        for cell in ("VAH27", "VAH30")
        for how, period, cv in (("as logged", None, None), ("resampled 30 s", 30.0, None),
                                ("resampled 60 s", 60.0, None),
                                ("charges to 4.0 V", None, 4.0))}

#: Real conditions with every test cut out, the pack given its label capacity and
#: chemistry only (no full discharge in the logbook).
LABEL_ONLY = {f"{cell} label only (3.0 Ah, Li-ion)": cell for cell in ("VAH27", "VAH30")}


# --------------------------------------------------------------------------- real variants

def resample(frame: pd.DataFrame, period_s: float) -> pd.DataFrame:
    """The log on a ``period_s`` grid, each column interpolated linearly between its
    samples (the shared eVTOL logs hold one sample every 166.5 s: a finer grid adds no
    information, and an estimator must not read it as a load resolved)."""
    t = frame["time_s"].to_numpy(float)
    grid = np.arange(t[0], t[-1], period_s)
    return pd.DataFrame({c: np.interp(grid, t, frame[c].to_numpy(float)) if c != "time_s"
                         else grid for c in frame.columns})


def recharged_counts(t: np.ndarray, i: np.ndarray) -> np.ndarray:
    """The charge [Ah] each sample moves (trapezoids; positive out), each discharge's samples
    scaled to the charge the next charge puts back: one sample every 166.5 s does not
    follow a mission's power steps (its trapezoids miss its charge by up to 40 %), while
    the recharge's constant current does."""
    dq = np.r_[0.0, np.diff(t) * 0.5 * (i[1:] + i[:-1]) / 3600.0]
    state, runs = current_runs(i)
    charges = [(a, b) for a, b in runs if state[a] == -1]
    for (_, since), (a, b) in zip([(0, 0)] + charges, charges):
        out = np.flatnonzero(dq[since + 1:a] > 0) + since + 1
        back = -dq[a:b + 1].sum()
        if out.size and back > 0:
            dq[out] *= back / dq[out].sum()
    return dq


def routine_cv(frame: pd.DataFrame, tests: list[dict], cv_cell_V: float,
               full_cell_V: float = 4.2) -> pd.DataFrame:
    """The log as if the routine charges had stopped at ``cv_cell_V`` (module docstring):
    between two tests, every voltage moves down by the cell's own curve's drop (the
    earlier test's C/5 discharge, whose resistive drop cancels in a difference) between
    the state of charge counted from the last charge's end and that less the share a
    ``cv_cell_V`` end leaves out. The tests (and their charges, before and after) keep
    their voltages."""
    t = frame["time_s"].to_numpy(float)
    i = frame["current_A"].to_numpy(float)
    v = frame["voltage_V"].to_numpy(float).copy()
    curves = []
    for test in tests:
        a, b = test["start"], test["stop"]
        q = np.r_[0.0, np.cumsum(np.diff(t[a:b]) * 0.5 * (i[a + 1:b] + i[a:b - 1]))] / 3600
        soc = 1.0 - q / q[-1]
        # only the samples at the test's full current: one taken as the current was
        # still rising sits up to 60 mV above the loaded curve, and a shift read from it
        # would move a whole block's voltages by that much
        steady = np.abs(i[a:b] - np.median(i[a:b])) <= 0.05 * abs(np.median(i[a:b]))
        curve = (soc[steady][::-1], v[a:b][steady][::-1], float(q[-1]))
        # the share left out: where the curve lies (full - cv) below its start
        top = float(np.median(v[a:b][steady][:3]))
        short = 1.0 - float(np.interp(top - (full_cell_V - cv_cell_V), curve[1], curve[0]))
        curves.append((curve, short))
    in_test = np.zeros(t.size, bool)
    which = np.zeros(t.size, int)
    for k, test in enumerate(tests):
        # the test, and the charge to 4.2 V before it with the rest between (a capacity
        # test starts full whatever the routine charges stop at)
        first = max(test["start"] - 1, 0)
        while first > 0 and i[first - 1] >= -0.02:
            first -= 1
        while first > 0 and i[first - 1] < -0.02:
            first -= 1
        in_test[first:test["cut_stop"]] = True
        which[test["start"]:] = k
    dq = recharged_counts(t, i)
    removed = 0.0
    for k in range(t.size):
        removed = max(removed + dq[k], 0.0)
        if i[k] < -0.02 and v[k] >= full_cell_V - 0.01:
            removed = 0.0  # a charge's constant-voltage end: full in the logged life
        if in_test[k]:
            continue
        (soc, volts, capacity), short = curves[which[k]]
        at = max(1.0 - removed / capacity, 0.0)
        v[k] -= np.interp(at, soc, volts) - np.interp(max(at - short, 0.0), soc, volts)
    out = frame.copy()
    out["voltage_V"] = v
    return out


# --------------------------------------------------------------------------- the lives

def _key(*parts) -> str:
    return hashlib.sha256(repr(parts).encode()).hexdigest()[:12]


def _events_code() -> str:
    """A hash of the code that turns a log into events (the readers and the logbook): a
    logbook cached by an older version is built again."""
    src = ROOT / "src" / "dischargelab"
    digest = hashlib.sha256()
    for path in sorted([*src.glob("io/**/*.py"), *src.glob("logbook/*.py")]):
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def synthetic_log(name: str, changes: dict, seed: int, cache: Path):
    """(log frame, tests) of one synthetic condition, cached by its spec."""
    import synthetic_life as sl

    spec = replace(sl.LifeSpec(**BASE, seed=seed), **changes)
    path = cache / f"life_{_key(asdict(spec), sl.GENERATOR_VERSION)}.pkl"
    if path.exists():
        life = pickle.loads(path.read_bytes())
    else:
        life = sl.synthetic_life(spec)
        path.write_bytes(pickle.dumps(life))
    truth = [{"start_s": a, "Ah": q} for a, _, q, _ in life.tests]
    return life.frame, truth


def pybamm_installed() -> bool:
    """PyBaMM can be imported (found, not imported: importing it starts a thread)."""
    return importlib.util.find_spec("pybamm") is not None


def pybamm_log(changes: dict, seed: int):
    """(log frame, tests) of one PyBaMM condition, kept in the generator's own cache (the
    lives take a minute or more each). Prints the wall time of a life made now."""
    import pybamm_life as pl

    started = time.perf_counter()
    life, cached = pl.cached_life(pl.PybammLifeSpec(seed=seed, **changes))
    if not cached:
        print(f"  (life made in {time.perf_counter() - started:.0f} s)", file=sys.stderr,
              flush=True)
    truth = [{"start_s": a, "Ah": q} for a, _, q, _ in life.tests]
    return life.frame, truth


def real_log(cell: str, period, cv):
    frame = pd.read_csv(CMU / f"{cell}.csv")
    tests = find_tests(frame)
    truth = [{"start_s": float(frame["time_s"].iloc[x["start"]]), "Ah": x["Ah"]}
             for x in tests]
    if cv is not None:
        frame = routine_cv(frame, tests, cv)
        # the emulation holds while every mission ends above the cutoff: a cell charged
        # to 4.0 V that ran deeper would have stopped, which a shift cannot show
        below = np.flatnonzero(frame["voltage_V"].to_numpy(float) < CUTOFF_CELL_V)
        if below.size:
            stop = float(frame["time_s"].iloc[below[0]])
            truth = [x for x in truth if x["start_s"] <= stop]
    if period is not None:
        frame = resample(frame, period)
    return frame, truth


def logbook_of(frame: pd.DataFrame, label: str, cache: Path, first: bool = True) -> Path:
    """A logbook holding the log with every test but the first cut out (``first`` false:
    every test, and the pack given its label capacity and chemistry), cached."""
    db = cache / (f"lb_{_key(label, len(frame), float(frame['voltage_V'].sum()), _events_code())}"
                  f"{'' if first else '_label'}.sqlite")
    if db.exists():
        return db
    tests = find_tests(frame)
    csv = cache / f"{db.stem}.csv"
    cut_copy(frame, tests, first, csv)
    part = db.with_suffix(".part")
    part.unlink(missing_ok=True)
    with Logbook(part) as lb:
        if first:
            lb.set_pack("cell")
        else:
            lb.set_pack("cell", label_capacity_Ah=3.0, chemistry="li-ion")
        lb.add(csv, pack="cell", refresh=False)
    part.rename(db)
    csv.unlink()
    return db


def blocks(db: Path, truth: list[dict]) -> list[dict]:
    """Per block of use: capacity now at its end against the next test."""
    with Logbook(db) as lb:
        row, events, model = lb._pack_data("cell")
    health = build_health(row, events, model, DEFAULT_EOL)
    out = []
    for k, (_block, so_far) in enumerate(blocks_of(health)):
        if k + 1 >= len(truth):
            break
        now = capacity_now([e for e in so_far if e.capacity_Ah is not None
                            and not e.outlier and e.efc is not None],
                           per_event=so_far)
        if now is None:
            out.append({"block": k + 1, "truth_Ah": truth[k + 1]["Ah"], "now_Ah": None,
                        "low": None, "high": None, "why": "no estimate"})
            continue
        low, high = now.interval95()
        out.append({"block": k + 1, "truth_Ah": truth[k + 1]["Ah"], "now_Ah": now.estimate(),
                    "trend_Ah": now.value_Ah,
                    "low": low, "high": high, "why": "", "trend_sd": now.trend_sd_Ah,
                    "drift_unit": now.drift_unit_Ah, "quantile": now.quantile,
                    "rise": now.rise, "seen_fade": now.seen_fade, "tested": now.tested})
    return out


def summary(name: str, rows: list[dict]) -> str:
    got = [r for r in rows if r["now_Ah"] is not None]
    if not got:
        return f"| {name} | {len(rows)} | - | - | - | - | - | - |"
    err = np.array([100 * (r["now_Ah"] / r["truth_Ah"] - 1) for r in got])
    cover = np.array([r["low"] <= r["truth_Ah"] <= r["high"] for r in got])
    half = np.array([50 * (r["high"] - r["low"]) / r["now_Ah"] for r in got])
    return (f"| {name} | {len(rows)} | {np.median(np.abs(err)):.2f} % | "
            f"{np.abs(err).max():.2f} % | {np.sum(np.abs(err) <= 2)}/{len(got)} | "
            f"{cover.sum()}/{len(got)} ({cover.mean():.0%}) | {np.median(half):.1f} % | "
            f"{err.mean():+.2f} % |")


#: Drift shares tried by the calibration (over_life.DRIFT_SHARE).
SHARES = np.round(np.arange(0.0, 2.01, 0.05), 2)

#: Hidden fade per unit of resistance rise tried (over_life.HIDDEN_FADE_PER_RISE).
PER_RISE = np.round(np.arange(0.0, 0.301, 0.01), 2)


#: Spreads of the hidden fade tried, as shares of it (over_life.HIDDEN_FADE_SD_SHARE).
SD_SHARES = np.round(np.arange(0.0, 2.01, 0.1), 2)


def _held(got: pd.DataFrame, share: float, per_rise: float,
          sd_share: float | None = None) -> pd.Series:
    """Whether each block's band holds the next test at ``share``, ``per_rise`` and
    ``sd_share`` (default: the one in use)."""
    low, high = _band(got, share, per_rise, sd_share)
    return (low <= got["truth_Ah"]) & (got["truth_Ah"] <= high)


def needed(rows: pd.DataFrame, tried, held, coverage: float = 0.9) -> float:
    """The smallest of ``tried`` whose band (``held(blocks, value)``) holds the next test
    in ``coverage`` of the blocks (inf when none does)."""
    got = rows.dropna(subset=["now_Ah"])
    if got.empty:
        return 0.0
    for value in tried:
        if held(got, value).mean() >= coverage:
            return float(value)
    return float("inf")


def calibration(rows: pd.DataFrame) -> None:
    """The drift share each condition needs, the share chosen without it (the largest
    the other synthetic conditions need) and the coverage that gives it; each real cell
    checked at the share the other cell needs. Then the hidden fade per resistance rise
    that fits each condition best, and the value chosen without it: the median of the best
    values of the PyBaMM and real conditions whose resistance rose, that condition (and for a
    real cell, all of that cell's) left out; the rest checked at the value in use. And the
    hidden fade's spread each condition needs, chosen for each PyBaMM life as the largest
    the other PyBaMM lives need."""
    if rows.empty or "drift_unit" not in rows:
        return
    from dischargelab.logbook.over_life import (
        DRIFT_SHARE,
        HIDDEN_FADE_PER_RISE,
        HIDDEN_FADE_SD_SHARE,
        RISE_MIN,
    )

    groups = dict(list(rows.groupby("condition", sort=False)))
    need = {c: needed(g, SHARES, lambda b, v: _held(b, v, 0.0)) for c, g in groups.items()}
    synthetic = [c for c in need if c in SYNTHETIC]
    print(f"\n## The drift share (in use: {DRIFT_SHARE}; no hidden fade)\n")
    print("| condition | needs | chosen without it | band holds the test at that share |")
    print("|---|---|---|---|")
    for c, n in need.items():
        if c in SYNTHETIC or c in PYBAMM:
            others = [need[o] for o in synthetic if o != c]
        else:
            cell = c.split()[0]
            others = [need[o] for o in need if o not in SYNTHETIC and o not in PYBAMM
                      and not o.startswith(cell)]
        if not others:
            print(f"| {c} | {n:.2f} | - | - |")
            continue
        chosen = max(others)
        held = _held(groups[c].dropna(subset=["now_Ah"]), chosen, 0.0).mean()
        print(f"| {c} | {n:.2f} | {chosen:.2f} | {held:.0%} |")
    best = {c: _best_per_rise(g.dropna(subset=["now_Ah"])) for c, g in groups.items()}
    # the conditions that can say: a resistance that rose, a full discharge at the start
    fits = [c for c, g in groups.items() if (c in PYBAMM or c in REAL)
            and (g["rise"].fillna(0.0) >= RISE_MIN).any()]
    pybamm = [c for c in best if c in PYBAMM]
    print(f"\n## The hidden fade per resistance rise (in use: {HIDDEN_FADE_PER_RISE})\n")
    print("| condition | least error at | chosen without it | within 2 % there | band holds "
          "the test there | within 2 % (none / in use) |")
    print("|---|---|---|---|---|---|")
    for c, b in best.items():
        got = groups[c].dropna(subset=["now_Ah"])
        # without the condition (and, for a real cell, without any of that cell's)
        others = [best[o] for o in fits if o != c
                  and not (c in REAL and o in REAL and REAL[o][0] == REAL[c][0])]
        chosen = float(np.median(others)) if c in fits and others else HIDDEN_FADE_PER_RISE
        within = [f"{np.mean(np.abs(_errors(got, v)) <= 2):.0%}"
                  for v in (0.0, HIDDEN_FADE_PER_RISE)]
        print(f"| {c}{'' if c in fits else ' (no rise to fit)'} | {b:.2f} | {chosen:.2f} | "
              f"{np.mean(np.abs(_errors(got, chosen)) <= 2):.0%}"
              f" | {_held(got, DRIFT_SHARE, chosen).mean():.0%} | {' / '.join(within)} |")
    need = {c: needed(g, SD_SHARES, lambda b, v: _held(b, DRIFT_SHARE, HIDDEN_FADE_PER_RISE, v))
            for c, g in groups.items()}
    print(f"\n## The hidden fade's spread (in use: {HIDDEN_FADE_SD_SHARE} of it)\n")
    print("| condition | needs | chosen without it | band holds the test there |")
    print("|---|---|---|---|")
    for c, n in need.items():
        others = [need[o] for o in pybamm if o != c]
        chosen = max(others) if c in PYBAMM and others else HIDDEN_FADE_SD_SHARE
        held = _held(groups[c].dropna(subset=["now_Ah"]), DRIFT_SHARE, HIDDEN_FADE_PER_RISE,
                     chosen).mean()
        print(f"| {c} | {n:.2f} | {chosen:.2f} | {held:.0%} |")


def _errors(got: pd.DataFrame, per_rise: float) -> np.ndarray:
    """Each block's error [%] of capacity today at ``per_rise``."""
    value = _now(got).estimate(per_rise)
    return 100 * (value / got["truth_Ah"].to_numpy(float) - 1)


def _best_per_rise(got: pd.DataFrame) -> float:
    """The hidden fade per resistance rise of :data:`PER_RISE` with the least mean
    absolute error over ``got``'s blocks (the smallest of equals)."""
    if got.empty:
        return 0.0
    return float(min(PER_RISE, key=lambda v: (np.mean(np.abs(_errors(got, v))), v)))


def _band(got: pd.DataFrame, share: float, per_rise: float, sd_share: float | None = None):
    """Each block's 95 % band at ``share``, ``per_rise`` and ``sd_share`` (default: the one
    in use; over_life.CapacityNow's)."""
    from dischargelab.logbook.over_life import HIDDEN_FADE_SD_SHARE

    return _now(got).interval95(share, per_rise,
                                HIDDEN_FADE_SD_SHARE if sd_share is None else sd_share)


def _now(got: pd.DataFrame) -> CapacityNow:
    """The blocks' capacity today with the parts of its spread, as ``blocks`` kept them."""
    return CapacityNow(value_Ah=got["trend_Ah"].to_numpy(float),
                      trend_sd_Ah=got["trend_sd"].to_numpy(float),
                      drift_unit_Ah=got["drift_unit"].to_numpy(float),
                      quantile=got["quantile"].to_numpy(float),
                      rise=got["rise"].to_numpy(float) if "rise" in got else 0.0,
                      seen_fade=got["seen_fade"].to_numpy(float) if "seen_fade" in got else 0.0,
                      tested=got["tested"].to_numpy(bool) if "tested" in got else True)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=1,
                        help="synthetic (and PyBaMM) lives per condition")
    parser.add_argument("--cycles", type=int, default=BASE["cycles"],
                        help="cycles per synthetic or PyBaMM life (a test every 5)")
    parser.add_argument("--only", nargs="*", default=None,
                        help="conditions whose name contains one of these words")
    parser.add_argument("--cache", type=Path, default=ROOT / ".cache" / "health_matrix",
                        help="folder keeping generated lives and their logbooks")
    parser.add_argument("--rows", type=Path, default=None, help="CSV of every block")
    args = parser.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    print(f"# Capacity now over a matrix of conditions ({machine_line()}; {load_avg()})\n")
    print("| condition | blocks | median abs error | largest | within 2 % | band holds "
          "the test | median half width | bias |")
    print("|---|---|---|---|---|---|---|---|")
    started = time.perf_counter()
    every = []
    todo = [(n, "synthetic", c) for n, c in SYNTHETIC.items()] + \
        [(n, "pybamm", c) for n, c in PYBAMM.items()] + \
        [(n, "real", c) for n, c in REAL.items()] + \
        [(n, "label", c) for n, c in LABEL_ONLY.items()]
    for name, kind, conf in todo:
        if args.only and not any(w.lower() in name.lower() for w in args.only):
            continue
        if kind == "pybamm" and not pybamm_installed():
            print(f"| {name} | skipped: pybamm not installed | | | | | | |", flush=True)
            continue
        rows = []
        for seed in range(args.seeds if kind in ("synthetic", "pybamm") else 1):
            if kind == "synthetic":
                frame, truth = synthetic_log(name, dict(conf, cycles=args.cycles), seed,
                                             args.cache)
            elif kind == "pybamm":
                frame, truth = pybamm_log({"cycles": args.cycles, **conf}, seed)
            else:
                frame, truth = real_log(*conf) if kind == "real" else real_log(conf, None, None)
            db = logbook_of(frame, f"{name}/{seed}", args.cache, first=kind != "label")
            got = blocks(db, truth)
            rows += [dict(r, condition=name, seed=seed) for r in got]
        every += rows
        print(summary(name, rows), flush=True)
    if args.rows:
        pd.DataFrame(every).to_csv(args.rows, index=False)
    calibration(pd.DataFrame(every))
    print(f"\n(total {time.perf_counter() - started:.0f} s; {load_avg()})")


if __name__ == "__main__":
    main()
