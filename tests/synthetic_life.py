"""Seeded synthetic lives of a cell, logged as a BMS or a tester would: missions, rests,
charges and capacity tests, from the project's one engine (``dischargelab.engine.run``).

The cell is the ``ecm`` family (open-circuit voltage of the generic Li-ion curve, series
resistance, a fast and a slow RC pair for the relaxation, solid diffusion, a lumped
thermal state with Arrhenius resistances). Its life, cycle by cycle:

* a mission like the CMU eVTOL missions (take-off 75 s at 54 W, cruise 800 s at 16 W,
  landing 105 s at 54 W per cell: Bills et al. 2023), stopped at the cutoff if the cell
  cannot finish it;
* a rest, a charge at 1C to 4.2 V then at 4.2 V while the current falls to C/30, a
  rest;
* every ``test_every`` cycles a capacity test: the charge, a rest, C/5 to the cutoff, a
  rest (its delivered charge is the test's capacity, as the CMU tests measure it).

The chemistry (``chemistry``) sets the generic curve the cell's own is made from:
``"li-ion"`` (NMC, the default), ``"lipo"`` (LiCoO2, charged to 4.2 V), ``"lihv"`` (the
high-voltage LiCoO2 curve, charged to 4.35 V) or ``"lifepo4"`` (LFP, charged to 3.65 V,
its long flat middle), each raised near full so that a constant-voltage charge at its
charge voltage ends at C/30 as a real cell's does (:data:`TOP_RAISE`). The routine charge
may stop before full (``charge_stop_soc``: constant current only, stopped at that state
of charge, as a timer or an operator stops it; a storage charge at ~55 %), and the rest
before each mission may be longer than the others (``storage_rest_s``).

The cell's own open-circuit curve is the generic one off by ``ocv_wiggle_V`` (a
smooth wave, zero at both ends), and ageing moves it: the state of charge on the
fresh curve is ``s - 4 lli_share fade s (1 - s)`` (the ends fixed by the charge and
cutoff voltages, the middle moved as a loss of lithium inventory shifts the electrodes'
windows against each other: Dubarry et al. 2012, Birkl et al. 2017).

Ageing by a known law: capacity ``C(efc) = C0 (1 - a efc - b max(0, efc - knee)^2)``
(a slow linear fade and a knee, Attia et al. 2022), resistances growing linearly with
the equivalent full cycles; the ambient temperature follows a slow season. The log is
sampled at ``sample_hz`` (1-10 Hz) with voltage and current noise. The truth (capacity
per cycle, the tests) comes with it.

References: A. Bills et al., Sci. Data 10, 344 (2023); P. M. Attia et al., J.
Electrochem. Soc. 169, 060517 (2022); M. Dubarry, C. Truchot, B. Y. Liaw, J. Power
Sources 219 (2012) 204-216; C. R. Birkl et al., J. Power Sources 341 (2017) 373-386.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from dischargelab.engine import Step, run
from dischargelab.models import get_family
from dischargelab.models.ecm import OCV_DROP_NAMES, OCV_NODES
from dischargelab.ocv import LIHV_OCV_V, OCV_SOC, ocv_from_soc

FAMILY = get_family("ecm")

#: The cell's open-circuit voltage: the generic Li-ion curve (a C/10 discharge, which
#: reads 4.14 V full) raised near full by this times SOC^3 [V], so that a 4.2 V
#: constant-voltage charge ends at C/30 as a real cell's does (its OCV at full ~4.2 V).
TOP_RAISE_V = 0.07

#: Per chemistry: the generic table (:mod:`dischargelab.ocv`), and the raise near full
#: ``(V, power)``: ``V SOC^power`` lifts the table's full value (a slow discharge's first
#: voltage) to ~12 mV above the charge voltage, as :data:`TOP_RAISE_V` does for Li-ion;
#: LFP's rise is confined to its last per cent (its plateau left flat: a high power).
TOP_RAISE = {"li-ion": (TOP_RAISE_V, 3.0), "lipo": (0.031, 3.0), "lihv": (0.031, 3.0),
             "lifepo4": (0.232, 200.0)}

#: Per chemistry whose curve rises steeply at the top (LFP: ~15 V per unit of charge in
#: its last per cent): the constant-current phase stops this far below the charge voltage
#: (settled at the charge current) [V] and the constant-voltage steps are this long [s],
#: so that the charge does not overshoot its voltage as a charger's regulation would not.
STEEP_TOP = {"lifepo4": (0.05, 2.0)}

#: Version of the generator: lives cached by a benchmark are made again when it changes
#: (4: chemistries, partial charges, storage rests; 5: an LFP charge no longer overshoots
#: its voltage; a Li-ion life is unchanged).
GENERATOR_VERSION = 5

#: Bound on the steps of one constant-voltage phase.
MAX_CV_STEPS = 2000

#: Mission per cell: (name, power [W], duration [s]) (CMU eVTOL profile).
MISSION = (("take-off", 54.0, 75.0), ("cruise", 16.0, 800.0), ("landing", 54.0, 105.0))


@dataclass
class LifeSpec:
    """What a synthetic life is made of (units in the names)."""

    cycles: int = 60
    test_every: int = 20
    sample_hz: float = 1.0
    capacity_Ah: float = 3.0
    fade_per_efc: float = 4e-4
    knee_efc: float = 25.0
    knee_per_efc2: float = 2e-5
    resistance_growth_per_efc: float = 4e-3
    ambient_C: float = 25.0
    season_C: float = 6.0
    rest_s: float = 900.0
    charge_C: float = 1.0
    cv_V: float = 4.2               # the routine charge's stop voltage per cell
    cv: bool = True                 # the routine charge holds it (False: constant current only)
    test_cv_V: float = 4.2          # the capacity tests' charge (constant current, then voltage)
    cutoff_V: float = 2.5
    test_C: float = 0.2
    noise_V: float = 0.001
    noise_A: float = 0.005
    mission_scale: float = 1.0
    mission_dt_s: float = 2.0
    cv_step_s: float = 10.0
    ocv_wiggle_V: float = 0.0       # the cell's own curve off the generic one [V]
    lli_share: float = 0.0          # how far ageing moves the curve (module docstring)
    seed: int = 0
    chemistry: str = "li-ion"       # "li-ion", "lipo", "lihv", "lifepo4" (module docstring)
    charge_stop_soc: float | None = None   # the routine charge stops there (CC only)
    storage_rest_s: float | None = None    # the rest before each mission, if not rest_s


@dataclass
class Life:
    """A synthetic life: the log, and the truth."""

    frame: pd.DataFrame
    cycles: pd.DataFrame            # per cycle: start_s, efc, capacity_Ah
    tests: list = field(default_factory=list)   # (start_s, end_s, capacity_Ah, efc)


def capacity_at(spec: LifeSpec, efc: float) -> float:
    """The cell's capacity [Ah] after ``efc`` equivalent full cycles (the known law)."""
    knee = max(0.0, efc - spec.knee_efc)
    return spec.capacity_Ah * (1.0 - spec.fade_per_efc * efc - spec.knee_per_efc2 * knee ** 2)


def cell_ocv(spec: LifeSpec, soc, efc: float) -> np.ndarray:
    """The cell's open-circuit voltage [V] at ``soc`` after ``efc`` cycles: the generic
    Li-ion curve raised near full, off it by the cell's own wiggle, and moved by ageing
    (module docstring)."""
    soc = np.asarray(soc, dtype=float)
    fade = 1.0 - capacity_at(spec, efc) / spec.capacity_Ah
    moved = np.clip(soc - 4.0 * spec.lli_share * fade * soc * (1.0 - soc), 0.0, 1.0)
    phase = 2 * np.pi * np.random.default_rng(spec.seed + 1000).random()
    wiggle = spec.ocv_wiggle_V * np.sin(6 * np.pi * soc + phase) * 4 * soc * (1 - soc)
    raise_V, power = TOP_RAISE[spec.chemistry]
    if spec.chemistry == "lihv":
        base = np.interp(moved, OCV_SOC[::-1], LIHV_OCV_V[::-1])
    else:
        base = ocv_from_soc(moved, spec.chemistry)
    return base + raise_V * soc ** power + wiggle


def parameters(spec: LifeSpec, efc: float) -> dict:
    """ECM parameters of the cell at ``efc`` [per cell]."""
    p = FAMILY.defaults()
    soc = 1.0 - OCV_NODES
    ocv = cell_ocv(spec, soc, efc)
    p["U_full_V"] = float(ocv[0])
    for name, d in zip(OCV_DROP_NAMES, -np.diff(ocv)):
        p[name] = float(max(d, 0.0))
    grow = 1.0 + spec.resistance_growth_per_efc * efc
    p.update(R0_ohm=0.018 * grow, R1_ohm=0.008 * grow, tau1_s=12.0, R2_ohm=0.012 * grow,
             tau2_s=900.0, tau_d_s=40.0, C_Ah=capacity_at(spec, efc), beta_K=2500.0,
             Cth_J_per_K=45.0, Rth_K_per_W=12.0)
    return p


class _Logger:
    """Runs engine steps from a carried state and keeps the recorded series."""

    def __init__(self, spec: LifeSpec):
        self.spec = spec
        self.t0 = 0.0
        self.state = None
        self.parts: list[dict] = []

    def go(self, steps, p, ambient, max_dt_s=1.0) -> float:
        res = run(FAMILY, p, steps, cutoff_pack_V=self.spec.cutoff_V, ambient_C=ambient,
                  initial_state=self.state, initial_temperature_C=ambient, record=True,
                  max_dt_s=max_dt_s, max_engine_steps=400_000)
        s = res.series
        # a step ended at the cutoff may record its crossing as -inf (LFP's steep end)
        keep = np.isfinite(np.asarray(s["voltage_V"], dtype=float))
        s = {k: np.asarray(v)[keep] if np.size(v) == keep.size else v for k, v in s.items()}
        s = dict(s, time_s=s["time_s"] + self.t0)
        self.parts.append(s)
        self.state = {k: np.asarray(v)[:1].copy() for k, v in res.final_state.items()}
        self.t0 = float(s["time_s"][-1])
        return float(res.end_s[0])

    def charge_removed(self) -> float:
        return 0.0 if self.state is None else float(self.state["charge_Ah"][0])

    def rest(self, duration, p, ambient):
        # finer steps first: the fast relaxation is sampled as a logger would see it
        pieces = [d for d in (20.0, 280.0) if d < duration]
        left = duration - sum(pieces)
        self.go([Step("rest", duration_s=d) for d in (*pieces, left) if d > 0], p, ambient)

    def charge(self, p, ambient, test: bool = False):
        """A charge to the routine's stop voltage (or the tests' full charge)."""
        spec = self.spec
        cv_V = spec.test_cv_V if test else spec.cv_V
        hold = test or spec.cv
        cap = p["C_Ah"]
        i_cc = spec.charge_C * spec.capacity_Ah
        q = self.charge_removed()
        if q <= 1e-4:
            return
        if not test and spec.charge_stop_soc is not None:
            # a partial charge: constant current until the counted state of charge
            t_cc = (q - (1.0 - spec.charge_stop_soc) * cap) * 3600.0 / i_cc
            if t_cc > 1.0:
                self.go([Step("profile", profile_time_s=(t_cc,),
                              profile_current_A=(-i_cc,))], p, ambient, max_dt_s=20.0)
            return
        # constant current until the voltage reaches the charge voltage: where the
        # settled voltage at the charge current crosses it (the filtered currents at
        # the charge current, the temperature as it is)
        grid_q = np.linspace(q, 0.0, 400)
        calm = {k: np.full(grid_q.size, float(v[0])) for k, v in self.state.items()}
        calm.update({st.name: np.full(grid_q.size, -i_cc) for st in FAMILY.states
                     if st.kind == "lowpass"}, charge_Ah=grid_q)
        v = FAMILY.voltage(p, calm, -i_cc)
        margin_V, cv_step_s = STEEP_TOP.get(spec.chemistry, (0.0, spec.cv_step_s))
        over = np.flatnonzero(v >= cv_V - (margin_V if hold else 0.0))
        q_cv = float(grid_q[over[0]]) if over.size else 0.0
        t_cc = (q - q_cv) * 3600.0 / i_cc
        if t_cc > 1.0:
            self.go([Step("profile", profile_time_s=(t_cc,), profile_current_A=(-i_cc,))], p,
                    ambient, max_dt_s=20.0)
        # constant voltage: each 10 s the current that holds the charge voltage (the
        # terminal voltage is affine in the current at a given state), until C/30
        i_end = cap / 30.0
        for _ in range(MAX_CV_STEPS if hold else 0):
            a = float(FAMILY.voltage(p, self.state, 0.0)[0])
            b = a - float(FAMILY.voltage(p, self.state, 1.0)[0])
            i = max(min((a - cv_V) / b, 0.0), -i_cc)
            if -i < i_end:
                break
            self.go([Step("profile", profile_time_s=(cv_step_s,),
                          profile_current_A=(i,))], p, ambient, max_dt_s=cv_step_s)

    def series(self) -> dict:
        return {k: np.concatenate([s[k] for s in self.parts]) for k in
                ("time_s", "current_A", "voltage_V", "temperature_C")}


def synthetic_life(spec: LifeSpec | None = None) -> Life:
    """A seeded synthetic life (see the module docstring)."""
    spec = spec or LifeSpec()
    rng = np.random.default_rng(spec.seed)
    log = _Logger(spec)
    efc, rows, tests = 0.0, [], []
    for cycle in range(spec.cycles):
        p = parameters(spec, efc)
        ambient = spec.ambient_C + spec.season_C * np.sin(2 * np.pi * cycle / max(spec.cycles, 1))
        rows.append({"cycle": cycle, "start_s": log.t0, "efc": efc, "capacity_Ah": p["C_Ah"]})
        if cycle == 0:  # the cell arrives part-charged: charged and rested first
            log.go([Step("current", 0.5 * spec.capacity_Ah, duration_s=1800.0)], p, ambient,
                   max_dt_s=20.0)
            log.rest(spec.rest_s, p, ambient)
            log.charge(p, ambient, test=True)
            log.rest(spec.rest_s, p, ambient)
        if cycle % spec.test_every == 0:
            if cycle > 0 and (spec.cv_V != spec.test_cv_V or not spec.cv
                              or spec.charge_stop_soc is not None):
                log.charge(p, ambient, test=True)   # the test starts from a full charge
                log.rest(spec.rest_s, p, ambient)
            start = log.t0
            q0 = log.charge_removed()
            log.go([Step("current", spec.test_C * spec.capacity_Ah)], p, ambient, max_dt_s=20.0)
            delivered = log.charge_removed() - q0
            tests.append((start, log.t0, delivered, efc))
            efc += delivered / spec.capacity_Ah
            log.rest(spec.rest_s, p, ambient)
            log.charge(p, ambient, test=True)
            log.rest(spec.rest_s, p, ambient)
        q0 = log.charge_removed()
        log.go([Step("power", w * spec.mission_scale, duration_s=d, name=n)
                for n, w, d in MISSION], p, ambient, max_dt_s=spec.mission_dt_s)
        efc += (log.charge_removed() - q0) / spec.capacity_Ah
        log.rest(spec.rest_s, p, ambient)
        log.charge(p, ambient)
        log.rest(spec.storage_rest_s or spec.rest_s, p, ambient)
    s = log.series()
    # the logger: samples at a fixed rate, with noise
    t = np.arange(0.0, s["time_s"][-1], 1.0 / spec.sample_hz)
    order = np.argsort(s["time_s"], kind="stable")
    ts = s["time_s"][order]
    frame = pd.DataFrame({
        "time_s": t,
        "voltage_V": np.interp(t, ts, s["voltage_V"][order]) + rng.normal(0, spec.noise_V, t.size),
        "current_A": np.interp(t, ts, s["current_A"][order]) + rng.normal(0, spec.noise_A, t.size),
        "temperature_C": np.round(np.interp(t, ts, s["temperature_C"][order]), 1),
    })
    return Life(frame=frame, cycles=pd.DataFrame(rows), tests=tests)


def bench_discharge(path, spec: LifeSpec, efc: float, *, current_A: float, down: float = 0.0,
                    stop_Ah: float | None = None, rest_s: float = 600.0,
                    storage_rest_s: float = 7200.0, ambient_C: float = 25.0) -> float:
    """One bench discharge of the cell at ``efc``, written as a tester writes it
    (``time_s``, ``voltage_V``, ``current_A`` discharge positive, every second): from a
    full charge, a rest of ``rest_s`` and ``current_A`` to the cutoff; or, with ``down``,
    that share of the capacity drawn at ``current_A`` first and ``storage_rest_s`` of rest
    (a storage charge; the log starts ``rest_s`` before the rest's end). ``stop_Ah``
    stops the discharge after that charge, under load. Returns what a discharge from full
    to the cutoff at ``current_A`` delivers at that age [Ah] (a full discharge's scale)."""
    p = parameters(spec, efc)

    def charged() -> _Logger:
        log = _Logger(spec)     # the cell arrives part-charged: drawn, rested, charged full
        log.go([Step("current", 0.5 * spec.capacity_Ah, duration_s=1800.0)], p, ambient_C,
               max_dt_s=20.0)
        log.rest(spec.rest_s, p, ambient_C)
        log.charge(p, ambient_C, test=True)
        return log

    log = charged()
    if down > 0:
        log.go([Step("current", current_A, duration_s=down * p["C_Ah"] * 3600.0 / current_A)],
               p, ambient_C)
        log.go([Step("rest", duration_s=storage_rest_s - rest_s)], p, ambient_C)
    start = log.t0
    log.rest(rest_s, p, ambient_C)
    if stop_Ah is None:
        log.go([Step("current", current_A)], p, ambient_C, max_dt_s=5.0)
    else:
        log.go([Step("current", current_A, duration_s=stop_Ah * 3600.0 / current_A)], p,
               ambient_C, max_dt_s=5.0)
    s = log.series()
    t = np.arange(start, s["time_s"][-1], 1.0)
    pd.DataFrame({"time_s": t - start, "voltage_V": np.interp(t, s["time_s"], s["voltage_V"]),
                  "current_A": np.interp(t, s["time_s"], s["current_A"])}).to_csv(path,
                                                                                   index=False)
    full = charged()
    q0 = full.charge_removed()
    full.go([Step("current", current_A)], p, ambient_C, max_dt_s=5.0)
    return full.charge_removed() - q0


__all__ = ["GENERATOR_VERSION", "bench_discharge", "cell_ocv", "LifeSpec", "Life",
           "synthetic_life", "capacity_at", "parameters", "MISSION"]


def flight_log(path, loads, *, capacity_Ah: float, cells: int, chemistry: str = "li-ion",
               before_s: float = 120.0, after_s: float = 60.0, seed: int = 3,
               sample_s: float = 1.0, ambient_C: float = 25.0,
               temperature: bool = False) -> float:
    """One flight of a fresh pack written as a logger would (``time_s``, pack
    ``voltage_V``, ``current_A`` discharge positive, every ``sample_s``; the cell's
    ``temperature_C`` if ``temperature``): a rest of ``before_s`` from full, the ``loads``
    (``(current_A, duration_s)`` each), and the log ending ``after_s`` after landing.
    Returns the cell's capacity [Ah] (the truth)."""
    spec = LifeSpec(capacity_Ah=capacity_Ah, ocv_wiggle_V=0.008, seed=seed,
                    chemistry=chemistry, ambient_C=ambient_C, season_C=0.0)
    p = parameters(spec, 0.0)
    log = _Logger(spec)
    log.rest(before_s, p, ambient_C)
    log.go([Step("current", a, duration_s=d) for a, d in loads], p, ambient_C)
    log.go([Step("rest", duration_s=after_s)], p, ambient_C)
    s = log.series()
    t = np.arange(0.0, s["time_s"][-1], sample_s)
    frame = pd.DataFrame({"time_s": t,
                          "voltage_V": cells * np.interp(t, s["time_s"], s["voltage_V"]),
                          "current_A": np.interp(t, s["time_s"], s["current_A"])})
    if temperature:
        frame["temperature_C"] = np.interp(t, s["time_s"], s["temperature_C"])
    frame.to_csv(path, index=False)
    return float(p["C_Ah"])
