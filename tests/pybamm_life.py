"""Seeded lives of a cell simulated by PyBaMM with its degradation submodels, logged as a
BMS or a tester would: missions, rests, charges and capacity tests. A check on physics
the logbook's estimators were not built from (``synthetic_life.py`` is the project's own
engine); PyBaMM is needed only here, at test and benchmark time.

The cell: PyBaMM's ``OKane2022`` set (LG M50 21700, NMC811 / graphite-SiOx: O'Kane et
al. 2022) in the single particle model (SPM), its electrode width scaled so that the
cell holds about 3 Ah (the CMU eVTOL cells' label: the same per-area physics, a smaller
cell), isothermal at the ambient of each step. Ageing, as the set supports it in the SPM:

* SEI growth, solvent-diffusion limited, also on the cracks' new surface;
* lithium plating, partially reversible;
* particle swelling and cracking (negative), swelling (positive), and the loss of active
  material that the particles' stress drives.

The degradation rates are raised (:data:`SEI_FACTOR`, :data:`LAM_FACTOR`) so that a life
of 40 cycles fades by 12-16 % (the real cell takes hundreds); the laws are
PyBaMM's, only their rate constants move. The porosity change of SEI and plating is
left out (at these rates it clogs the pores, which the real cell does not do in so few
cycles).

A life, cycle by cycle (as ``synthetic_life.py``):

* a mission to part depth (take-off, climb, cruise, hover and landing at constant power
  per cell, the cruise's length varying by the seed), each step stopped at the cutoff;
* a rest, the routine charge at 1C to its stop voltage and then at that voltage while
  the current falls to C/30, a rest;
* every ``test_every`` cycles a capacity test: a full charge to 4.2 V if the routine
  charge stops lower, a rest, C/5 to the cutoff, a rest, the full charge and a rest (its
  delivered charge is the test's capacity, the truth).

The ambient follows a slow season as in ``synthetic_life.py``. The solver's output is
sampled at ``sample_hz`` with voltage and current noise.

References: S. E. J. O'Kane et al., Phys. Chem. Chem. Phys. 24, 7909-7922 (2022);
C.-H. Chen et al., J. Electrochem. Soc. 167, 080534 (2020); V. Sulzer et al., J. Open
Res. Softw. 9(1), 14 (2021); A. Bills et al., Sci. Data 10, 344 (2023); P. Mohtat et
al., J. Electrochem. Soc. 166, A3614 (2019).
"""

from __future__ import annotations

import os

os.environ.setdefault("PYBAMM_DISABLE_TELEMETRY", "true")

import hashlib
import pickle
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from synthetic_life import Life

#: Version of the generator: cached lives are made again when it changes.
GENERATOR_VERSION = 3

#: The parameter set (made for ageing studies).
PARAMETER_SET = "OKane2022"

#: The set's electrode width is scaled by this: a ~3 Ah cell instead of 5 Ah.
WIDTH_SCALE = 0.6

#: Degradation sped up: SEI solvent diffusivity and the stress-driven LAM's proportional
#: term, times these (module docstring).
SEI_FACTOR = 15000.0
LAM_FACTOR = 50.0

#: The submodels (PyBaMM options).
OPTIONS = {
    "SEI": "solvent-diffusion limited",
    "SEI on cracks": "true",
    "SEI porosity change": "false",
    "lithium plating": "partially reversible",
    "lithium plating porosity change": "false",
    "particle mechanics": ("swelling and cracking", "swelling only"),
    "loss of active material": "stress-driven",
}

#: Mission per cell: (name, power [W], duration [s]); the cruise is scaled by the seed.
MISSION = (("take-off", 20.0, 75.0), ("climb", 14.0, 120.0), ("cruise", 9.0, 1100.0),
           ("hover", 14.0, 60.0), ("landing", 18.0, 90.0))

#: The cell's state at each cycle's end (PyBaMM's summary variables) kept in
#: ``Life.cycles``: column -> variable. The stoichiometry windows at 100 % and 0 % state
#: of charge give the cell's open-circuit curve (:func:`ocv`).
STATE = {"x_100": "x_100", "x_0": "x_0", "y_100": "y_100", "y_0": "y_0",
         "lli_pct": "Loss of lithium inventory [%]",
         "lam_neg_pct": "Loss of active material in negative electrode [%]",
         "lam_pos_pct": "Loss of active material in positive electrode [%]",
         "sei_Ah": "Loss of capacity to negative SEI [A.h]",
         "sei_cracks_Ah": "Loss of capacity to negative SEI on cracks [A.h]",
         "plating_Ah": "Loss of capacity to negative lithium plating [A.h]",
         "ocv_capacity_Ah": "Capacity [A.h]"}

#: Solver output period of the missions and of a rest's first minute, and of the rest [s].
FINE_S = 1.0
COARSE_S = 10.0


@dataclass
class PybammLifeSpec:
    """What a PyBaMM life is made of (units in the names)."""

    cycles: int = 40
    test_every: int = 5
    sample_hz: float = 1.0
    ambient_C: float = 25.0
    season_C: float = 3.0
    rest_s: float = 900.0
    charge_C: float = 1.0
    cv_V: float = 4.2               # the routine charge's stop voltage per cell
    test_cv_V: float = 4.2          # the capacity tests' charge
    cutoff_V: float = 2.5
    test_C: float = 0.2
    end_C: float = 1 / 30           # a constant-voltage hold ends at this current
    mission_scale: float = 1.0      # power of every mission step times this
    cruise_scale: float = 1.0       # the cruise's length times this (deeper missions)
    cruise_spread: float = 0.15     # the cruise's length varies by +- this share
    sei_factor: float = SEI_FACTOR
    lam_factor: float = LAM_FACTOR
    noise_V: float = 0.001
    noise_A: float = 0.005
    seed: int = 0


def parameter_values(spec: PybammLifeSpec):
    """The set's PyBaMM parameter values: the electrodes narrowed, the degradation sped
    up and the ambient of ``spec``."""
    import pybamm

    values = pybamm.ParameterValues(PARAMETER_SET)
    kelvin = spec.ambient_C + 273.15
    values.update({
        "Electrode width [m]": values["Electrode width [m]"] * WIDTH_SCALE,
        "Nominal cell capacity [A.h]": values["Nominal cell capacity [A.h]"] * WIDTH_SCALE,
        "SEI solvent diffusivity [m2.s-1]":
            values["SEI solvent diffusivity [m2.s-1]"] * spec.sei_factor,
        "Negative electrode LAM constant proportional term [s-1]":
            values["Negative electrode LAM constant proportional term [s-1]"] * spec.lam_factor,
        "Positive electrode LAM constant proportional term [s-1]":
            values["Positive electrode LAM constant proportional term [s-1]"] * spec.lam_factor,
        "Ambient temperature [K]": kelvin,
        "Initial temperature [K]": kelvin,
    })
    return values


def _rest(spec: PybammLifeSpec, kelvin: float, tag: str) -> list:
    import pybamm

    return [pybamm.step.rest(60.0, period=FINE_S, temperature=kelvin, tags=[tag]),
            pybamm.step.rest(spec.rest_s - 60.0, period=COARSE_S, temperature=kelvin,
                             tags=[tag])]


def _charge(spec: PybammLifeSpec, kelvin: float, cv_V: float, tag: str) -> list:
    import pybamm

    cap = spec_capacity()
    return [pybamm.step.current(-spec.charge_C * cap, termination=f"> {cv_V:g} V",
                                period=COARSE_S, temperature=kelvin, tags=[tag]),
            pybamm.step.voltage(cv_V, termination=f"{spec.end_C * cap:.4g} A",
                                period=COARSE_S, temperature=kelvin, tags=[tag])]


def spec_capacity() -> float:
    """The scaled cell's nominal capacity [Ah] (the C-rates' base)."""
    return 5.0 * WIDTH_SCALE


def _cycles(spec: PybammLifeSpec) -> list[tuple]:
    """The experiment's cycles (one per life cycle, its test in front when it has one)."""
    import pybamm

    rng = np.random.default_rng(spec.seed)
    cap = spec_capacity()
    until = f"< {spec.cutoff_V:g} V"
    out = []
    for cycle in range(spec.cycles):
        kelvin = 273.15 + spec.ambient_C + spec.season_C * np.sin(
            2 * np.pi * cycle / max(spec.cycles, 1))
        steps = []
        if cycle == 0:  # the cell arrives half charged: rested and fully charged first
            steps += _rest(spec, kelvin, "start")
            steps += _charge(spec, kelvin, spec.test_cv_V, "start") + _rest(spec, kelvin, "start")
        if cycle % spec.test_every == 0:
            if cycle > 0 and spec.cv_V != spec.test_cv_V:
                steps += _charge(spec, kelvin, spec.test_cv_V, "pre-test")
                steps += _rest(spec, kelvin, "pre-test")
            steps.append(pybamm.step.current(spec.test_C * cap, termination=until,
                                             period=COARSE_S, temperature=kelvin,
                                             tags=["test"]))
            steps += _rest(spec, kelvin, "test")
            steps += _charge(spec, kelvin, spec.test_cv_V, "test") + _rest(spec, kelvin, "test")
        stretch = spec.cruise_scale * (1.0 + spec.cruise_spread * (2.0 * rng.random() - 1.0))
        for name, watts, seconds in MISSION:
            seconds = seconds * stretch if name == "cruise" else seconds
            steps.append(pybamm.step.power(watts * spec.mission_scale, duration=seconds,
                                           termination=until, period=FINE_S,
                                           temperature=kelvin, tags=["mission"]))
        steps += _rest(spec, kelvin, "mission")
        steps += _charge(spec, kelvin, spec.cv_V, "routine") + _rest(spec, kelvin, "routine")
        out.append(tuple(steps))
    return out


def pybamm_life(spec: PybammLifeSpec | None = None) -> Life:
    """A seeded PyBaMM life (module docstring): the log, per cycle the capacity of the
    latest test, the mission's lowest voltage (``mission_min_V``) and the cell's state
    at the cycle's end (:data:`STATE`), and the tests ``(start_s, end_s, capacity_Ah,
    efc)``."""
    import pybamm

    spec = spec or PybammLifeSpec()
    rng = np.random.default_rng(spec.seed + 7919)
    model = pybamm.lithium_ion.SPM(dict(OPTIONS))
    cycles = _cycles(spec)
    experiment = pybamm.Experiment(cycles)
    sim = pybamm.Simulation(model, parameter_values=parameter_values(spec),
                            experiment=experiment, solver=pybamm.IDAKLUSolver())
    solution = sim.solve(initial_soc=0.5)
    if len(solution.cycles) < spec.cycles:
        raise RuntimeError(f"PyBaMM stopped after {len(solution.cycles)} of {spec.cycles} "
                           f"cycles: {solution.termination}")
    summary = solution.summary_variables
    parts, tests, rows = [], [], []
    efc, latest = 0.0, float("nan")
    for cycle, sol in enumerate(solution.cycles):
        mission_min = np.inf
        for planned, step in zip(cycles[cycle], sol.steps):
            if isinstance(step, pybamm.EmptySolution):   # a step PyBaMM skipped
                continue
            t = step["Time [s]"].entries
            i = step["Current [A]"].entries
            v = step["Voltage [V]"].entries
            parts.append((t, i, v, step["Volume-averaged cell temperature [C]"].entries))
            tags = planned.tags
            q = float(np.trapezoid(np.clip(i, 0.0, None), t) / 3600.0)
            if "test" in tags and i.size and np.median(i) > 0:
                latest = q
                tests.append((float(t[0]), float(t[-1]), q, efc))
            if "mission" in tags:
                mission_min = min(mission_min, float(v.min()))
            efc += q / spec_capacity()
        rows.append({"cycle": cycle, "start_s": float(sol["Time [s]"].entries[0]),
                     "efc": efc, "capacity_Ah": latest, "mission_min_V": mission_min,
                     **{k: float(summary[v][cycle]) for k, v in STATE.items()}})
    t = np.concatenate([p[0] for p in parts])
    order = np.argsort(t, kind="stable")
    t = t[order]
    grid = np.arange(0.0, t[-1], 1.0 / spec.sample_hz)
    column = [np.concatenate([p[k] for p in parts])[order] for k in (1, 2, 3)]
    frame = pd.DataFrame({
        "time_s": grid,
        "voltage_V": np.interp(grid, t, column[1]) + rng.normal(0, spec.noise_V, grid.size),
        "current_A": np.interp(grid, t, column[0]) + rng.normal(0, spec.noise_A, grid.size),
        "temperature_C": np.round(np.interp(grid, t, column[2]), 1),
    })
    return Life(frame=frame, cycles=pd.DataFrame(rows), tests=tests)


def ocv(spec: PybammLifeSpec, state, soc) -> np.ndarray:
    """The cell's open-circuit voltage [V] at ``soc`` (a share of its capacity between
    the stoichiometry windows of ``state``, a row of ``Life.cycles``):
    ``U_p(y_100 + (1 - soc)(y_0 - y_100)) - U_n(x_0 + soc (x_100 - x_0))`` (the
    electrode-SOH windows of Mohtat et al. 2019, as PyBaMM computes them)."""
    import pybamm

    values = parameter_values(spec)
    soc = np.atleast_1d(np.asarray(soc, dtype=float))
    y = state["y_100"] + (1.0 - soc) * (state["y_0"] - state["y_100"])
    x = state["x_0"] + soc * (state["x_100"] - state["x_0"])
    up = values.process_symbol(values["Positive electrode OCP [V]"](pybamm.Vector(y)))
    un = values.process_symbol(values["Negative electrode OCP [V]"](pybamm.Vector(x)))
    return up.evaluate().ravel() - un.evaluate().ravel()


def cache_folder() -> Path:
    """Where generated lives are kept: ``$DISCHARGELAB_BENCH_CACHE``, else
    ``$XDG_CACHE_HOME/dischargelab-bench`` (``~/.cache/dischargelab-bench``)."""
    if os.environ.get("DISCHARGELAB_BENCH_CACHE"):
        return Path(os.environ["DISCHARGELAB_BENCH_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "dischargelab-bench"


def cached_life(spec: PybammLifeSpec, folder: Path | None = None) -> tuple[Life, bool]:
    """``(life, True if it came from the cache)``: a life kept by its spec, the
    generator's version and PyBaMM's, made and written (atomically) when missing."""
    import pybamm

    folder = folder or cache_folder()
    key = hashlib.sha256(repr((asdict(spec), GENERATOR_VERSION, pybamm.__version__))
                         .encode()).hexdigest()[:12]
    path = folder / f"pybamm_life_{key}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes()), True
    life = pybamm_life(spec)
    folder.mkdir(parents=True, exist_ok=True)
    part = path.with_suffix(f".part{os.getpid()}")
    part.write_bytes(pickle.dumps(life))
    part.replace(path)
    return life, False


__all__ = ["GENERATOR_VERSION", "PybammLifeSpec", "pybamm_life", "cached_life", "cache_folder",
           "parameter_values", "ocv", "MISSION", "OPTIONS", "STATE"]
