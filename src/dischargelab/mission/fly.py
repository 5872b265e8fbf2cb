"""Flying a mission through the one engine, for many parameter draws at once.

Nothing here integrates the battery model on its own: every flight is
:func:`dischargelab.engine.run`. The longest stretch is found per draw by a
bracketed secant (regula falsi with a bisection safeguard, bounded rounds) on the
pack charge at the end of the stretch phase, each round one engine run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import engine
from ..engine import Step
from ..errors import DataError, SimulationError
from ..simulate import SimulationResult
from .spec import Mission, Phase, RepeatBlock

#: Engine time steps per phase of a flown mission (also its output samples per phase).
#: Constant-power phases are integrated with Heun's method: 25 steps keep the
#: endurance of the bundled missions within 1e-6 of a 1e-9-tolerance ODE solution.
POINTS_PER_PHASE = 25

#: Engine time steps per phase in searches and draws when the result does not depend
#: on the step (constant-current phases of a family whose only state is the charge).
EXACT_POINTS_PER_PHASE = 2

#: Tolerance of the longest stretch, as a fraction of the pack capacity in charge [-].
STRETCH_TOLERANCE = 1e-9

#: Bound on the rounds of the longest-stretch search.
STRETCH_MAX_ROUNDS = 40

#: Rungs of the candidate ladder per side in a round of the longest-stretch search
#: (offsets of 1, 10, ..., 10**(n-1) times half the tolerance).
STRETCH_LADDER = 10

#: Passes of a repeat-until block per engine run, at most.
MAX_PASSES_PER_RUN = 500

#: Engine runs of a repeat-until block before it is declared endless.
MAX_REPEAT_RUNS = 8



# ---------------------------------------------------------------------------------------------
# Flying a mission through the engine
# ---------------------------------------------------------------------------------------------

@dataclass
class _Leg:
    """Flights in progress: one entry per flight, arrays of shape (entries,).

    ``rows`` maps each entry to its parameter draw (the stretch search flies
    several candidate flights per draw). ``steps``, ``labels`` and ``series`` are
    only kept for a recorded flight (one draw).
    """

    rows: np.ndarray
    end_s: np.ndarray              # time since take-off [s]
    charge_Ah: np.ndarray          # pack charge removed [Ah]
    ended_by: np.ndarray           # "end" while the flight goes on
    energy_Wh: np.ndarray          # energy delivered [Wh]
    min_voltage_V: np.ndarray      # lowest pack voltage so far [V]
    peak_temperature_C: np.ndarray
    state: dict                    # cell states of the engine
    steps: list = field(default_factory=list)
    labels: list = field(default_factory=list)   # (phase name, item index, repetition)
    series: list = field(default_factory=list)   # engine series, time from take-off

    @property
    def going(self) -> np.ndarray:
        """Entries still flying."""
        return self.ended_by == "end"

    def take(self, index) -> _Leg:
        """A copy of the entries ``index`` (nothing recorded)."""
        def pick(values):
            return np.array(values[index], copy=True)

        return _Leg(pick(self.rows), pick(self.end_s), pick(self.charge_Ah), pick(self.ended_by),
                    pick(self.energy_Wh), pick(self.min_voltage_V), pick(self.peak_temperature_C),
                    {k: pick(v) for k, v in self.state.items()})


class Flyer:
    """Flies mission steps for one or many parameter draws through :func:`engine.run`.

    Parameters
    ----------
    mission : Mission
    params : mapping, optional
        ``{name: value or array of draws}``; default the battery's parameters.
    points : int
        Engine time steps per phase (``steps_per_discharge`` of the engine).
    record : bool
        Keep the time series (one draw only).
    """

    def __init__(self, mission: Mission, params=None, *, points: int, record: bool = False):
        battery = mission.battery
        values = dict(battery.parameters if params is None else params)
        arrays = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in values.items()}
        self.m = max(v.size for v in arrays.values())
        self.params = {k: np.broadcast_to(v, (self.m,)) for k, v in arrays.items()}
        self.mission = mission
        self.points = max(int(points), 1)
        self.record = record
        self.capacity = self.params["C_Ah"] * battery.strings_parallel
        self.q_start = (1.0 - mission.initial_soc_pct / 100.0) * self.capacity
        self.q_reserve = (1.0 - mission.reserve_pct / 100.0) * self.capacity

    def start(self) -> _Leg:
        """Every draw on the ground, charged to the take-off state of charge."""
        fam = self.mission.battery.family
        ambient = self.mission.resolved_ambient_C
        state = fam.initial_state(self.params, temperature_C=ambient,
                                  charge_Ah=self.q_start / self.mission.battery.strings_parallel)
        m = self.m
        return _Leg(np.arange(m), np.zeros(m), self.q_start.copy(), np.full(m, "end", object),
                    np.zeros(m), np.full(m, np.inf),
                    np.broadcast_to(np.asarray(fam.temperature_C(state, ambient), float),
                                    (m,)).copy(), state)

    def run(self, leg: _Leg, steps, labels=(), *, reserve=None, only=None) -> _Leg:
        """Continue the flights of ``leg`` through ``steps``.

        Parameters
        ----------
        leg : _Leg
        steps : sequence of Step
        labels : sequence
            Phase label of each step (recorded flight).
        reserve : numpy.ndarray, optional
            Per entry: stop ("reserve") when the pack charge removed reaches it [Ah].
        only : numpy.ndarray of bool, optional
            Fly only these entries (the others keep their state).
        """
        steps = list(steps)
        out = leg.take(slice(None))
        if self.record:
            out.steps, out.labels = leg.steps + steps, leg.labels + list(labels)
            out.series = list(leg.series)
        fly = leg.going if only is None else leg.going & only
        idx = np.flatnonzero(fly)
        if not steps or idx.size == 0:
            return out
        bat = self.mission.battery
        try:
            res = engine.run(
                bat.family, {k: v[leg.rows[idx]] for k, v in self.params.items()}, steps,
                cutoff_pack_V=self.mission.cutoff_pack_V, cells_series=bat.cells_series,
                strings_parallel=bat.strings_parallel, ambient_C=self.mission.resolved_ambient_C,
                initial_state={k: v[idx] for k, v in leg.state.items()},
                reserve_charge_Ah=None if reserve is None else np.asarray(reserve)[idx],
                record=self.record, steps_per_discharge=self.points)
        except SimulationError as exc:
            raise SimulationError(f"mission {self.mission.name!r}: {exc}") from None
        out.end_s[idx] += res.end_s
        out.charge_Ah[idx] = res.charge_end_Ah
        out.ended_by[idx] = res.ended_by
        out.energy_Wh[idx] += res.energy_Wh
        lowest = np.min([s.min_voltage_V for s in res.steps], axis=0)
        out.min_voltage_V[idx] = np.minimum(out.min_voltage_V[idx], lowest)
        out.peak_temperature_C[idx] = np.maximum(out.peak_temperature_C[idx],
                                                 res.peak_temperature_C)
        for name in out.state:
            out.state[name][idx] = res.final_state[name]
        if self.record and res.series["time_s"].size:
            series = dict(res.series)
            series["time_s"] = series["time_s"] + leg.end_s[0]
            series["step"] = series["step"] + len(leg.steps)
            out.series.append(series)
        return out


def _expand(items, first_index: int = 0, stretch_s: float | None = None):
    """Steps and labels of fixed items (repeat-until blocks are flown by _repeat_until)."""
    steps, labels = [], []
    for k, item in enumerate(items, start=first_index):
        if isinstance(item, RepeatBlock):
            for r in range(item.count or 0):
                for ph in item.phases:
                    steps.append(ph.to_step(ph.duration_s))
                    labels.append((ph.name, k, r + 1))
        else:
            steps.append(item.to_step(stretch_s if item.stretch else item.duration_s))
            labels.append((item.name, k, None))
    return steps, labels


def _pass_charge_estimate_Ah(mission: Mission, block: RepeatBlock) -> float:
    """Charge of one block pass at the pack's rest voltage when full (only to size a batch)."""
    nominal_V = max(float(mission.battery.voltage(0.0, 0.0)), 0.1 * mission.battery.cells_series)
    charge = 0.0
    for ph in block.phases:
        current = ph.value if ph.kind == "current" else ph.value / nominal_V
        charge += current * ph.duration_s / 3600.0
    return max(charge, 1e-12)


def _repeat_until(fl: Flyer, leg: _Leg, block: RepeatBlock, index: int, reserve) -> _Leg:
    """Fly a final repeat-until block in batches of passes until every flight ended.

    Bounded: at most :data:`MAX_REPEAT_RUNS` engine runs of at most
    :data:`MAX_PASSES_PER_RUN` passes each.
    """
    per_pass = _pass_charge_estimate_Ah(fl.mission, block)
    done = 0
    for _ in range(MAX_REPEAT_RUNS):
        going = leg.going
        if not going.any():
            return leg
        left = float(np.max(fl.capacity[leg.rows[going]] - leg.charge_Ah[going]))
        passes = int(min(MAX_PASSES_PER_RUN, math.ceil(1.3 * left / per_pass) + 1))
        steps, labels = [], []
        for r in range(done + 1, done + passes + 1):
            for ph in block.phases:
                steps.append(ph.to_step(ph.duration_s))
                labels.append((ph.name, index, r))
        leg = fl.run(leg, steps, labels, reserve=reserve)
        done += passes
    if leg.going.any():
        raise SimulationError(
            f"mission {fl.mission.name!r}: repeat block {block.name!r} did not reach the "
            f"{block.until} within {done} passes: the model never reaches the {block.until} "
            f"under this load (check the loads and the battery's capacity)")
    return leg


def fly_mission(fl: Flyer, stretch_s: float | None = None) -> _Leg:
    """Fly the whole mission (the stretch phase for ``stretch_s``); the reserve only
    stops a final 'until reserve' item."""
    items = fl.mission.items
    last = items[-1]
    head = items[:-1] if last.until is not None else items
    steps, labels = _expand(head, 0, stretch_s)
    leg = fl.run(fl.start(), steps, labels)
    if last.until is None:
        return leg
    k = len(items) - 1
    reserve = fl.q_reserve[leg.rows] if last.until == "reserve" else None
    if isinstance(last, RepeatBlock):
        return _repeat_until(fl, leg, last, k, reserve)
    return fl.run(leg, [last.to_step(None)], [(last.name, k, None)], reserve=reserve)


def _exact_in_time(mission: Mission) -> bool:
    """True when the engine's answer does not depend on its step size (constant-current
    phases, a family whose only state is the charge: exact integration)."""
    fam = mission.battery.family
    return all(st.kind == "charge" for st in fam.states) and \
        all(ph.kind == "current" for ph in mission.phases())


def _search_points(mission: Mission, points: int) -> int:
    return EXACT_POINTS_PER_PHASE if _exact_in_time(mission) else points


# ---------------------------------------------------------------------------------------------
# The longest stretch: bracketed secant per draw over the engine
# ---------------------------------------------------------------------------------------------

def _try_stretch(fl: Flyer, pre: _Leg, phase: Phase, suffix, target) -> dict:
    """Fly the stretch phase until the pack charge ``target`` [Ah], then the rest.

    Returns per entry the feasibility margin ``g`` (>= 0 feasible: the rest ends
    at or above the reserve without reaching the cutoff), the stretch duration
    and the flight's end. ``g`` falls monotonically through 0 at the longest
    stretch: ``min(SOC gap, voltage gap)`` when completed, minus the fraction of
    the remaining phases not flown when the cutoff came first, below -1 when the
    stretch phase itself reached the cutoff before ``target``.
    """
    rows = pre.rows
    need = target > pre.charge_Ah
    flown = fl.run(pre, [phase.to_step(None)], reserve=target, only=need)
    reached = np.where(need, flown.ended_by == "reserve", pre.going)
    stop_q = flown.charge_Ah.copy()
    flown.ended_by = np.where(reached, "end", flown.ended_by).astype(object)
    after = fl.run(flown, suffix)
    cap = fl.capacity[rows]
    soc_gap = (fl.q_reserve[rows] - after.charge_Ah) / cap
    cutoff = fl.mission.cutoff_pack_V
    volt_gap = (after.min_voltage_V - cutoff) / cutoff
    planned = float(sum(st.duration_s for st in suffix))
    if planned > 0:
        left = np.maximum(planned - (after.end_s - flown.end_s), 0.0) / planned
    else:
        left = np.zeros(rows.size)
    completed = after.going
    g = np.where(completed, np.minimum(soc_gap, volt_gap), -left - 1e-12)
    short = -(1.0 if planned > 0 else 0.0) - np.maximum(target - stop_q, 0.0) / cap - 1e-12
    g = np.where(reached, g, short)
    return {"g": g, "stretch_s": flown.end_s - pre.end_s,
            "end_s": after.end_s, "charge_Ah": after.charge_Ah, "completed": completed,
            "soc_gap": np.where(completed, soc_gap, g),
            "volt_gap": np.where(completed, volt_gap, g)}


def _crossing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Fraction of the bracket where a line from ``a`` (>= 0) to ``b`` (< 0) crosses 0;
    NaN where it does not."""
    cross = (a >= 0) & (b < 0)
    return np.where(cross, a / np.where(cross, a - b, 1.0), np.nan)


def _secant_fraction(lo: dict, hi: dict) -> np.ndarray:
    """Where in the bracket the margin crosses 0: linear interpolation of the state of
    charge gap and of the voltage gap, the first crossing wins (each is nearly linear
    in the charge, their minimum is not); the margin itself when neither crosses."""
    both = np.fmin(_crossing(lo["soc_gap"], hi["soc_gap"]),
                   _crossing(lo["volt_gap"], hi["volt_gap"]))
    return np.where(np.isfinite(both), both, _crossing(lo["g"], hi["g"]))


def _search_stretch(fl: Flyer) -> dict:
    """Longest stretch per draw (arrays): ``max_s``, ``feasible``, ``binding`` and the
    flight at the longest stretch (``end_s``, ``charge_Ah``, ``completed``).

    The unknown is the pack charge at the end of the stretch phase, between its
    start and the reserve. Each round flies, for every unfinished draw at once, a
    ladder of candidates around the regula-falsi point (Illinois variant; the
    bracket's middle when three rounds did not halve it): offsets of +-1, 10,
    100, ... times half the tolerance, so the next bracket is at most one rung
    wide and a nearly linear margin is bracketed to the tolerance in one or two
    rounds. At most :data:`STRETCH_MAX_ROUNDS` rounds.
    """
    mission = fl.mission
    k = mission.stretch_index
    phase = mission.items[k]
    pre_steps, _ = _expand(mission.items[:k])
    suffix, _ = _expand(mission.items[k + 1:], k + 1)
    pre = fl.run(fl.start(), pre_steps)
    m = fl.m
    lo = pre.charge_Ah.copy()
    hi = np.maximum(fl.q_reserve, lo)
    both = np.r_[np.arange(m), np.arange(m)]
    ends = _try_stretch(fl, pre.take(both), phase, suffix, np.r_[lo, hi])
    best = {key: value[:m].copy() for key, value in ends.items()}
    upper = {key: value[m:].copy() for key, value in ends.items()}
    feasible = best["g"] >= 0
    top_ok = feasible & (upper["g"] >= 0)
    for key in best:
        best[key] = np.where(top_ok, upper[key], best[key])
    lo = np.where(top_ok, hi, lo)
    tol = STRETCH_TOLERANCE * fl.capacity
    active = feasible & ~top_ok & (hi - lo > tol)
    kept = np.zeros((2, m))           # rounds each side of the bracket was kept in a row
    width = [np.full(m, np.inf)] * 2 + [hi - lo]     # bracket widths of the last rounds
    rungs = 10.0 ** np.arange(STRETCH_LADDER)
    for _ in range(STRETCH_MAX_ROUNDS):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        span = hi[idx] - lo[idx]
        weight = 0.5 ** np.maximum(kept[:, idx] - 1.0, 0.0)    # Illinois
        frac = _secant_fraction({k: v[idx] * weight[0] for k, v in best.items()},
                                {k: v[idx] * weight[1] for k, v in upper.items()})
        stuck = span > 0.5 * width[0][idx]          # no halving in three rounds: bisect
        x = lo[idx] + span * np.where(stuck, 0.5, frac)
        d = 0.45 * tol[idx]
        offsets = d[:, None] * np.r_[-rungs[::-1], rungs][None, :]
        cands = np.clip(x[:, None] + offsets, (lo[idx] + 0.5 * d)[:, None],
                        (hi[idx] - 0.5 * d)[:, None])
        n, width_c = cands.shape
        ev = _try_stretch(fl, pre.take(np.repeat(idx, width_c)), phase, suffix, cands.ravel())
        g = ev["g"].reshape(n, width_c)
        rows = np.arange(n)
        top = np.argmax(np.where(g >= 0, cands, -np.inf), axis=1)     # highest feasible
        bottom = np.argmin(np.where(g < 0, cands, np.inf), axis=1)     # lowest infeasible
        up = (g[rows, top] >= 0) & (cands[rows, top] > lo[idx])
        down = (g[rows, bottom] < 0) & (cands[rows, bottom] < hi[idx])
        lo[idx[up]] = cands[rows, top][up]
        hi[idx[down]] = cands[rows, bottom][down]
        for key in best:
            values = ev[key].reshape(n, width_c)
            best[key][idx[up]] = values[rows, top][up]
            upper[key][idx[down]] = values[rows, bottom][down]
        kept[:, idx] = np.where(np.vstack([up, down]), 0.0, kept[:, idx] + 1.0)
        width = width[1:] + [hi - lo]
        active &= hi - lo > tol
    binding = np.where(~feasible, "infeasible",
                       np.where(best["soc_gap"] <= best["volt_gap"], "reserve", "cutoff"))
    return {"max_s": np.where(feasible, best["stretch_s"], 0.0), "feasible": feasible,
            "binding": binding, "end_s": best["end_s"], "charge_Ah": best["charge_Ah"],
            "completed": best["completed"]}


def mission_outcomes(mission: Mission, params=None, *,
                     points_per_step: int | None = None) -> dict:
    """Scalar outcomes of a mission for one or many parameter sets, flown at once.

    Parameters
    ----------
    mission : Mission
    params : mapping, optional
        ``{name: value or array of draws}`` per cell; default the battery's.
    points_per_step : int, optional
        Engine time steps per phase (default :data:`POINTS_PER_PHASE`).

    Returns
    -------
    dict
        Arrays per draw: ``endurance_s``, ``flight_time_s``, ``soc_end_pct``,
        ``completed`` and, with a stretch phase, ``max_stretch_s`` and ``binding``.
    """
    points = _search_points(mission, POINTS_PER_PHASE if points_per_step is None
                            else points_per_step)
    fl = Flyer(mission, params, points=points)
    k = mission.stretch_index
    out = {}
    if k is None:
        leg = fly_mission(fl)
        flight, charge = leg.end_s, leg.charge_Ah
        completed = (leg.ended_by == "end") | (leg.ended_by == "reserve")
        endurance = flight.copy()
    else:
        found = _search_stretch(fl)
        planned = mission.items[k].duration_s
        if planned is None:
            flight, charge, completed = found["end_s"], found["charge_Ah"], found["completed"]
            flown = found["max_s"]
        else:
            leg = fly_mission(fl, planned)
            flight, charge = leg.end_s, leg.charge_Ah
            completed = (leg.ended_by == "end") | (leg.ended_by == "reserve")
            flown = planned
        endurance = np.where(found["feasible"], flight - flown + found["max_s"], flight)
        out.update(max_stretch_s=found["max_s"], binding=found["binding"])
    out.update(flight_time_s=flight, endurance_s=endurance, completed=completed.astype(bool),
               soc_end_pct=100.0 * (1.0 - charge / fl.capacity))
    return out


def max_stretch_s(mission: Mission, *, points: int | None = None) -> dict:
    """Longest duration of the stretch phase that still completes the mission.

    The remaining phases must end at or above the reserve and never reach the
    cutoff; found per draw by a bracketed secant over the engine (see
    :func:`_search_stretch`), to :data:`STRETCH_TOLERANCE` of the capacity in charge.

    Parameters
    ----------
    mission : Mission
    points : int, optional
        Engine time steps per phase (default :data:`POINTS_PER_PHASE`).

    Returns
    -------
    dict
        ``phase`` (name), ``planned_s`` (None when not given), ``max_s`` [s],
        ``margin_s`` (max - planned, None without a plan) and ``binding``:
        "reserve" (the mission ends exactly at the reserve), "cutoff" (a later
        phase would reach the cutoff) or "infeasible" (even a zero-length stretch
        does not complete the mission; ``max_s`` is 0).
    """
    k = mission.stretch_index
    if k is None:
        raise DataError("the mission has no phase with stretch = true")
    phase = mission.items[k]
    fl = Flyer(mission, points=_search_points(mission, POINTS_PER_PHASE if points is None
                                               else points))
    found = _search_stretch(fl)
    max_s = float(found["max_s"][0])
    binding = str(found["binding"][0])
    if binding == "infeasible":
        margin = None if phase.duration_s is None else -phase.duration_s
    else:
        margin = None if phase.duration_s is None else max_s - phase.duration_s
    return {"phase": phase.name, "planned_s": phase.duration_s, "max_s": max_s,
            "binding": binding, "margin_s": margin}


def load_at_start(mission: Mission, leg: _Leg, sim: SimulationResult) -> dict | None:
    """The load a recorded flight (one draw) could not even start, or None.

    A flight that ended by the cutoff or the power limit at the very start of a phase
    (no time flown in it) met a load the pack cannot deliver in that state; the pack's
    largest current and power there come from :func:`dischargelab.engine.load_limits`.

    Returns
    -------
    dict or None
        ``phase`` (its label), ``kind`` ("current" or "power"), ``load`` [A or W],
        ``soc_pct`` (when it met the load) and the keys of
        :func:`~dischargelab.engine.load_limits`.
    """
    if sim.ended_by not in ("cutoff", "power limit") or not leg.steps:
        return None
    k = int(sim.step[-1])
    step = leg.steps[k]
    flown = sim.time_s[sim.step == k]
    if step.kind not in ("current", "power") or flown[-1] > flown[0]:
        return None
    bat = mission.battery
    limits = engine.load_limits(
        bat.family, dict(bat.parameters), leg.state, cutoff_pack_V=mission.cutoff_pack_V,
        ambient_C=mission.resolved_ambient_C, cells_series=bat.cells_series,
        strings_parallel=bat.strings_parallel)
    name, _, repetition = leg.labels[k]
    return {"phase": name if repetition is None else f"{name} #{repetition}",
            "kind": step.kind, "load": float(step.value), **limits,
            "soc_pct": float(100.0 * (1.0 - sim.charge_Ah[-1] / mission.capacity_Ah))}


def leg_simulation(mission: Mission, leg: _Leg) -> SimulationResult:
    """The recorded flight (one draw) as a SimulationResult."""
    keys = ("time_s", "current_A", "voltage_V", "charge_Ah", "temperature_C", "step")
    if leg.series:
        ser = {key: np.concatenate([s[key] for s in leg.series]) for key in keys}
    else:  # nothing flown (every phase of zero length): the pack at take-off
        q0 = mission.initial_charge_Ah
        ser = {"time_s": np.zeros(1), "current_A": np.zeros(1),
               "voltage_V": np.atleast_1d(mission.battery.voltage(0.0, q0)).astype(float),
               "charge_Ah": np.full(1, q0), "step": np.zeros(1, dtype=int),
               "temperature_C": np.full(1, mission.resolved_ambient_C)}
    if str(leg.ended_by[0]) == "cutoff":
        # a load step that starts below the cutoff ends the flight as its load rises
        # through the cutoff: the flight ends at the cutoff voltage
        ser["voltage_V"] = ser["voltage_V"].copy()
        ser["voltage_V"][-1] = mission.cutoff_pack_V
    power = ser["current_A"] * ser["voltage_V"]
    t = ser["time_s"]
    energy = np.zeros_like(t)
    if t.size > 1:
        np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t), out=energy[1:])
    return SimulationResult(
        time_s=t, current_A=ser["current_A"], voltage_V=ser["voltage_V"], power_W=power,
        charge_Ah=ser["charge_Ah"], energy_Wh=energy / 3600.0, step=ser["step"].astype(int),
        steps=list(leg.steps) or [Step("rest", 0.0, 0.0)], cutoff_pack_V=mission.cutoff_pack_V,
        ended_by=str(leg.ended_by[0]), battery=mission.battery,
        initial_charge_Ah=mission.initial_charge_Ah, temperature_C=ser["temperature_C"],
        ambient_C=mission.resolved_ambient_C)
