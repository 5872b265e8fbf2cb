"""The one time-stepping engine: flies load steps through any model family.

Every simulation in dischargelab (constant current or power, missions, logged
load profiles, parameter draws for intervals) goes through :func:`run`. It
advances the family's states step by step, for all parameter draws at once
(vectorised), until each draw reaches the cutoff voltage, a charge reserve, a
power it cannot deliver, or the end of the profile. Every loop is bounded: a
step limit raises :class:`~dischargelab.errors.SimulationError` rather than
hanging.

Stepping
--------
Over one time step the load is held: a current step at its current; a power
step at the current that delivers the power (Heun's method: the mean of the
currents at the start and at the predicted end). Charge and lowpass states are
advanced exactly for that current, the thermal state exactly for the mean of the
heat at the start and at the end of the step (Heun's predictor-corrector). The
instant a stop condition is crossed is then located by bisection on the length
of the last step (exact to ~1e-9 of the step for charge/lowpass states), so the
time to cutoff does not depend on the step size for the paper's model.

Constant power: every family's terminal voltage is affine in the instantaneous
current for a given state, ``V = a - b i``; the low-current root of
``(a - b i) i = P`` is ``i = 2P / (a + sqrt(a^2 - 4bP))``; where
``a^2 < 4bP`` the battery cannot deliver the power ("power limit").

Sign convention: current and power positive on discharge; the pack carries
``I`` and each of its ``p`` strings ``I/p``; ``V_pack = s V_cell``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .errors import SimulationError

STEP_KINDS = ("current", "power", "rest", "profile")

#: Engine time steps per step that runs until the cutoff (the answer does not
#: depend on it for charge/lowpass states; it sets the thermal integration error).
STEPS_PER_DISCHARGE = 100

#: Longest engine time step [s] (thermal and RC dynamics are slower than this).
MAX_DT_S = 60.0

#: Hard bound on engine time steps in one run (memory and time stay bounded).
MAX_ENGINE_STEPS = 200_000

#: Bisection iterations that locate a stop inside a time step (2^-34 of the step).
BISECTION_ITERATIONS = 34

#: Bits of the bisection's grid tried at once at most (one batched advance of
#: 2**bits - 1 points per draw) ...
BISECTION_GRID_BITS = 7

#: ... and points of one batched advance at most: many draws stopping in one step are
#: halved together, one point each (a batch costs its size once it is large).
BISECTION_BATCH_POINTS = 128

#: Default ambient temperature [degC] when neither the battery nor the call gives one.
DEFAULT_AMBIENT_C = 25.0

ENDED = ("cutoff", "power limit", "reserve", "end")


@dataclass(frozen=True)
class Step:
    """One load step (PyBaMM-experiment style).

    Parameters
    ----------
    kind : {"current", "power", "rest", "profile"}
    value : float
        Pack current [A] or pack electric power [W] (discharge positive); ignored
        for rest and profile.
    duration_s : float or None
        Duration [s]; None runs until the cutoff (not allowed for rest).
    name : str
        Label (flight phase name, ...).
    profile_time_s, profile_current_A : tuple of float
        For ``kind="profile"``: sample times [s from the step start] and pack
        currents [A]; sample ``k``'s current is held over ``(t[k-1], t[k]]`` (a
        logger's reading covers the interval before it).
    """

    kind: str
    value: float = 0.0
    duration_s: float | None = None
    name: str = ""
    profile_time_s: tuple = ()
    profile_current_A: tuple = ()

    def __post_init__(self):
        if self.kind not in STEP_KINDS:
            raise SimulationError(f"step kind must be one of {', '.join(STEP_KINDS)}, "
                                  f"got {self.kind!r}")
        label = self.name or self.kind
        if not np.isfinite(self.value) or (self.kind in ("current", "power") and self.value < 0):
            raise SimulationError(f"step {label!r}: load must be a finite value >= 0 "
                                  f"(discharge positive), got {self.value}")
        if self.duration_s is None and self.kind == "rest":
            raise SimulationError("a rest step needs a duration")
        if self.duration_s is not None and not (self.duration_s >= 0 and
                                                np.isfinite(self.duration_s)):
            raise SimulationError(f"step {label!r}: duration must be >= 0 s, "
                                  f"got {self.duration_s}")
        if self.kind == "profile":
            t = np.asarray(self.profile_time_s, dtype=float)
            i = np.asarray(self.profile_current_A, dtype=float)
            if t.size < 1 or t.shape != i.shape or not np.all(np.isfinite(t)) or \
                    not np.all(np.isfinite(i)) or np.any(np.diff(t) <= 0) or t[0] < 0:
                raise SimulationError(f"step {label!r}: a profile needs increasing times >= 0 "
                                      "and finite currents of the same length")

    def describe(self) -> str:
        """Human-readable step, e.g. 'discharge at 20 A for 60 s'."""
        if self.kind == "rest":
            load = "rest"
        elif self.kind == "current":
            load = f"discharge at {self.value:g} A"
        elif self.kind == "power":
            load = f"hold {self.value:g} W"
        else:
            load = f"logged profile of {len(self.profile_time_s)} samples"
        until = "until cutoff" if self.duration_s is None else f"for {self.duration_s:g} s"
        return f"{load} {until}"

    @cached_property
    def profile_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``(time_s, current_A)`` of a profile as arrays (converted once)."""
        return (np.asarray(self.profile_time_s, dtype=float),
                np.asarray(self.profile_current_A, dtype=float))

    @property
    def end_s(self) -> float | None:
        """Duration [s]: the given one, or the last profile time for a profile."""
        if self.duration_s is not None:
            return float(self.duration_s)
        if self.kind == "profile":
            return float(self.profile_time_s[-1])
        return None


@dataclass
class StepSummary:
    """Per-draw outcome of one step: arrays of shape (draws,)."""

    start_s: np.ndarray
    end_s: np.ndarray
    charge_end_Ah: np.ndarray  # pack
    min_voltage_V: np.ndarray  # pack
    peak_temperature_C: np.ndarray
    energy_Wh: np.ndarray


@dataclass
class EngineResult:
    """Outcome of :func:`run`.

    Per draw (arrays of shape (draws,)): ``end_s``, ``ended_by`` (str array of
    :data:`ENDED`), ``charge_end_Ah`` (pack), ``peak_temperature_C``,
    ``energy_Wh``; ``steps`` per-step summaries. With ``record=True`` (one draw)
    also the time series ``time_s``, ``current_A``, ``voltage_V``, ``charge_Ah``,
    ``temperature_C`` and ``step`` (pack level).
    """

    end_s: np.ndarray
    ended_by: np.ndarray
    charge_end_Ah: np.ndarray
    peak_temperature_C: np.ndarray
    energy_Wh: np.ndarray
    steps: list[StepSummary]
    series: dict = field(default_factory=dict)
    final_state: dict = field(default_factory=dict)


#: The two currents at which :meth:`_Pack.affine` evaluates the cell voltage [A].
_AFFINE_CURRENTS = np.array([[0.0], [1.0]])


class _Pack:
    """Cell family + parameters (arrays over draws) + pack configuration."""

    def __init__(self, family, params: dict, series: int, parallel: int, ambient_C):
        self.family = family
        self.p = params
        self.s = float(series)
        self.par = float(parallel)
        self.ambient = ambient_C
        self.kinds = {st.name: st for st in family.states}

    def voltage(self, state, current_pack):
        return self.s * self.family.voltage(self.p, state, current_pack / self.par)

    def affine(self, state):
        """(a, b): pack voltage = a - b I for the pack current I at this state."""
        # one evaluation at 0 A and 1 A together (the families broadcast over currents)
        v0, v1 = self.family.voltage(self.p, state, _AFFINE_CURRENTS)
        with np.errstate(invalid="ignore"):  # -inf - -inf beyond the capacity: NaN (no power)
            return self.s * v0, self.s * (v0 - v1) / self.par

    def power_current(self, state, power):
        """Pack current delivering ``power`` [W]; NaN where it cannot be delivered."""
        a, b = self.affine(state)
        disc = a * a - 4.0 * b * power
        with np.errstate(invalid="ignore", divide="ignore"):
            root = np.sqrt(np.where(disc >= 0, disc, np.nan))
            i = 2.0 * power / (a + root)
        return np.where(np.isfinite(a) & (a > 0), i, np.nan)

    def advance(self, state, current_pack, dt):
        """States after ``dt`` [s] (scalar or per draw) at constant pack current."""
        i = current_pack / self.par
        new = {}
        for name, st in self.kinds.items():
            x = state[name]
            if st.kind == "charge":
                new[name] = x + i * dt / 3600.0
            elif st.kind == "lowpass":
                tau = st.time_constant(self.p)
                with np.errstate(divide="ignore", over="ignore", under="ignore"):
                    decay = np.where(tau > 0, np.exp(-dt / np.where(tau > 0, tau, 1.0)), 0.0)
                new[name] = i + (x - i) * decay
        if any(st.kind == "thermal" for st in self.kinds.values()):
            for name, st in self.kinds.items():
                if st.kind == "thermal":
                    q0 = self._heat(state, i)
                    pred = dict(new)
                    pred[name] = self._relax(state[name], q0, dt)
                    new[name] = self._relax(state[name], 0.5 * (q0 + self._heat(pred, i)), dt)
        return new

    def _heat(self, state, i):
        """Heat [W]; 0 where the cell is past empty (the step is cut there anyway)."""
        with np.errstate(invalid="ignore", over="ignore"):
            heat = self.family.heat_W(self.p, state, i)
        return np.where(np.isfinite(heat), heat, 0.0)

    def _relax(self, temperature, heat, dt):
        """Lumped temperature after ``dt`` [s] at a constant heat [W], solved exactly:
        ``T_amb + Q R_th + (T - T_amb - Q R_th) exp(-dt / (R_th C_th))`` (stable for any
        step, however short the thermal time constant)."""
        rth = np.asarray(self.p["Rth_K_per_W"], dtype=float)
        steady = self.ambient + heat * rth
        with np.errstate(under="ignore"):
            decay = np.exp(-dt / (rth * np.asarray(self.p["Cth_J_per_K"], dtype=float)))
        return steady + (temperature - steady) * decay

    def temperature(self, state):
        return self.family.temperature_C(state, self.ambient)


def run(family, params: dict, steps, *, cutoff_pack_V: float, cells_series: int = 1,
        strings_parallel: int = 1, ambient_C: float = DEFAULT_AMBIENT_C,
        initial_charge_Ah=0.0, initial_temperature_C=None, reserve_charge_Ah=None,
        record: bool = False, steps_per_discharge: int = STEPS_PER_DISCHARGE,
        max_engine_steps: int = MAX_ENGINE_STEPS, initial_state=None,
        max_dt_s: float = MAX_DT_S) -> EngineResult:
    """Fly ``steps`` for every parameter draw until each stops.

    Parameters
    ----------
    family : models.Family
    params : dict
        ``{name: value or array of draws}`` per cell.
    steps : sequence of Step
    cutoff_pack_V : float
        Pack cutoff voltage [V].
    cells_series, strings_parallel : int
        Pack configuration.
    ambient_C : float
        Ambient temperature [degC] (thermal families).
    initial_charge_Ah : float or array
        Pack charge already removed at the start [Ah].
    initial_temperature_C : float or None
        Cell temperature at the start [degC]; default the ambient.
    reserve_charge_Ah : float, array or None
        Stop ("reserve") when the pack charge removed reaches this [Ah].
    record : bool
        Keep the time series (first draw only).
    steps_per_discharge : int
        Engine steps for a step that runs until the cutoff.
    max_engine_steps : int
        Bound on the total number of engine steps (SimulationError beyond it).
    initial_state : dict or None
        Cell states per draw to start from (e.g. ``final_state`` of an earlier
        run, to continue a flight); replaces ``initial_charge_Ah`` and
        ``initial_temperature_C``.
    max_dt_s : float
        Longest engine time step [s] (:data:`MAX_DT_S`; a larger one, up to infinity,
        where only the time to the cutoff counts: charge and filtered currents are
        advanced exactly, the cutoff located by bisection, and the heat of a step is
        its predictor-corrector mean).

    Returns
    -------
    EngineResult
    """
    params = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in params.items()}
    m = int(np.broadcast(*params.values()).size) if params else 1
    params = {k: np.broadcast_to(v, (m,)) for k, v in params.items()}
    pack = _Pack(family, params, cells_series, strings_parallel, float(ambient_C))
    temp0 = float(ambient_C if initial_temperature_C is None else initial_temperature_C)
    q0 = np.broadcast_to(np.asarray(initial_charge_Ah, dtype=float), (m,)) / pack.par
    state = family.initial_state(params, charge_Ah=q0.copy(), temperature_C=temp0)
    if initial_state is not None:
        state = {name: np.broadcast_to(np.asarray(initial_state[name], dtype=float),
                                       (m,)).copy() for name in state}
    reserve = None if reserve_charge_Ah is None else \
        np.broadcast_to(np.asarray(reserve_charge_Ah, dtype=float), (m,))
    active = np.ones(m, bool)
    ended = np.full(m, "end", dtype=object)
    t_now = np.zeros(m)
    energy = np.zeros(m)
    peak_t = np.asarray(pack.temperature(state), dtype=float) * np.ones(m)
    summaries: list[StepSummary] = []
    rec = _Recorder(record)
    budget = [int(max_engine_steps)]
    for k, st in enumerate(steps):
        start = t_now.copy()
        vmin = np.full(m, np.inf)
        e_start = energy.copy()
        if active.any():
            state = _run_step(pack, st, k, state, active, ended, t_now, energy, vmin, peak_t,
                              cutoff_pack_V, reserve, steps_per_discharge, rec, budget,
                              max_dt_s)
        summaries.append(StepSummary(
            start_s=start, end_s=t_now.copy(), charge_end_Ah=state["charge_Ah"] * pack.par,
            min_voltage_V=vmin, peak_temperature_C=peak_t.copy(), energy_Wh=energy - e_start))
    return EngineResult(end_s=t_now, ended_by=ended.astype(str),
                        charge_end_Ah=state["charge_Ah"] * pack.par, peak_temperature_C=peak_t,
                        energy_Wh=energy, steps=summaries, series=rec.arrays(),
                        final_state=state)


class _Recorder:
    def __init__(self, on: bool):
        self.on = on
        self.rows = {key: [] for key in ("time_s", "current_A", "voltage_V", "charge_Ah",
                                          "temperature_C", "step")}

    def add(self, t, i, v, q, temp, k):
        if self.on:
            for key, val in zip(self.rows, (t, i, v, q, temp, k)):
                self.rows[key].append(float(np.asarray(val).ravel()[0]))

    def arrays(self):
        if not self.on:
            return {}
        out = {k: np.asarray(v, dtype=float) for k, v in self.rows.items()}
        out["step"] = out["step"].astype(int)
        return out


def start_load(family, params: dict, step: Step, *, charge_Ah: float, ambient_C: float,
               cells_series: int = 1, strings_parallel: int = 1) -> tuple[float, float, float]:
    """Pack current [A], voltage [V] and maximum power [W] as ``step`` starts from rest
    with ``charge_Ah`` [Ah, pack] removed: what the engine applies first. The current
    is NaN where a power step cannot be delivered."""
    pack = _Pack(family, {k: np.atleast_1d(np.asarray(v, dtype=float))
                          for k, v in params.items()},
                 cells_series, strings_parallel, float(ambient_C))
    state = family.initial_state(pack.p, charge_Ah=np.atleast_1d(charge_Ah) / pack.par,
                                 temperature_C=float(ambient_C))
    current = _current_at(pack, step, state, np.zeros(1))
    a, b = pack.affine(state)
    max_power = float(a[0] * a[0] / (4.0 * b[0])) if b[0] > 0 else float("inf")
    return float(current[0]), float(pack.voltage(state, current)[0]), max_power


def load_limits(family, params: dict, state: dict, *, cutoff_pack_V: float, ambient_C: float,
                cells_series: int = 1, strings_parallel: int = 1) -> dict:
    """What the pack can deliver at ``state`` (one draw) without its voltage falling below
    ``cutoff_pack_V`` [V].

    At a given state the pack voltage is affine in the current, ``V = a - b I``, so the
    largest current is ``(a - V_cut) / b`` and the largest power the largest ``I (a - b I)``
    up to it: ``a^2 / 4b`` when the voltage at that optimum (``a / 2``) is above the cutoff,
    else ``I_max V_cut``. Both are 0 where ``a`` is already at or below the cutoff.

    Returns
    -------
    dict
        ``max_current_A`` [A], ``max_power_W`` [W] and ``no_load_voltage_V`` (``a``, the
        pack voltage at zero current in this state) [V].
    """
    def first(values):
        return {k: np.atleast_1d(np.asarray(v, dtype=float))[:1] for k, v in values.items()}

    pack = _Pack(family, first(params), cells_series, strings_parallel, float(ambient_C))
    a, b = (float(x[0]) for x in pack.affine(first(state)))
    out = {"max_current_A": 0.0, "max_power_W": 0.0, "no_load_voltage_V": a}
    if not (np.isfinite(a) and a > cutoff_pack_V):
        return out
    if not (np.isfinite(b) and b > 0):
        return {**out, "max_current_A": float("inf"), "max_power_W": float("inf")}
    current = (a - cutoff_pack_V) / b
    power = a * a / (4.0 * b) if a / 2.0 >= cutoff_pack_V else current * cutoff_pack_V
    return {**out, "max_current_A": current, "max_power_W": power}


def _current_at(pack, st, state, t_in_step):
    """Pack current for step ``st`` at ``state`` (NaN where a power cannot be delivered)."""
    if st.kind == "rest":
        return np.zeros_like(state["charge_Ah"])
    if st.kind == "current":
        return np.full_like(state["charge_Ah"], float(st.value))
    if st.kind == "power":
        return pack.power_current(state, float(st.value))
    t, current = st.profile_arrays
    idx = np.clip(np.searchsorted(t, t_in_step, side="right"), 0, t.size - 1)
    return current[idx] * np.ones_like(state["charge_Ah"])


def _advance_step(pack, st, state, i0, dt):
    """States and current after ``dt``; power steps use the Heun mean current."""
    if st.kind != "power":
        return pack.advance(state, i0, dt), i0
    pred = pack.advance(state, i0, dt)
    i1 = pack.power_current(pred, float(st.value))
    i_mean = np.where(np.isfinite(i1), 0.5 * (i0 + i1), i0)
    new = pack.advance(state, i_mean, dt)
    return new, pack.power_current(new, float(st.value))


def _take(state, mask):
    return {k: v[mask] for k, v in state.items()}


def _put(state, mask, sub):
    for k in state:
        state[k] = state[k].copy()
        state[k][mask] = sub[k]


def _dt_for(pack, st, state, steps_per_discharge, max_dt_s=MAX_DT_S):
    """Engine step [s] per draw (each draw's own, so batching does not change results)."""
    m = state["charge_Ah"].size
    end = st.end_s
    if st.kind == "profile":
        t = st.profile_arrays[0]
        gaps = np.diff(np.r_[0.0, t])
        typical = float(np.median(gaps[gaps > 0])) if (gaps > 0).any() else 1.0
        return np.full(m, min(MAX_DT_S, max(typical, 1e-3)))
    if st.kind == "rest":
        return np.full(m, min(MAX_DT_S, max(end / 50.0, 1e-3)))
    cap = np.asarray(pack.family.capacity_Ah(pack.p, state), dtype=float) * pack.par
    left = np.maximum(cap - state["charge_Ah"] * pack.par, cap * 1e-3)
    if st.kind == "current":
        i = np.full(m, max(float(st.value), 1e-9))
    else:
        a, _ = pack.affine(state)
        i = float(st.value) / np.maximum(np.where(np.isfinite(a), a, 1.0), 1e-9)
        i = np.maximum(i, 1e-9)
    horizon = left * 3600.0 / i
    if end is not None:
        horizon = np.minimum(horizon, end)
    return np.clip(horizon / steps_per_discharge, 1e-3, max_dt_s)


def _run_step(pack, st, k, state, active, ended, t_now, energy, vmin, peak_t, cutoff, reserve,
              steps_per_discharge, rec, budget, max_dt_s=MAX_DT_S):
    """Advance the active draws through one step, in place; returns the new state."""
    end = st.end_s
    t_in = np.zeros(t_now.size)
    dt = _dt_for(pack, st, state, steps_per_discharge, max_dt_s)
    running = active.copy()
    if end is not None and end <= 0:
        return state
    i_now = _current_at(pack, st, state, t_in)
    v_now = pack.voltage(state, i_now)
    # stop at once where the step cannot start (power limit / below cutoff / reserve reached)
    _check_start(st, running, active, ended, i_now, v_now, state, pack, cutoff, reserve)
    vmin[running] = np.minimum(vmin[running], v_now[running])
    rec.add(t_now, i_now, v_now, state["charge_Ah"] * pack.par, pack.temperature(state), k)
    while running.any():
        budget[0] -= 1
        if budget[0] < 0:
            raise SimulationError(
                "the simulation did not end within its step limit: the model never reaches "
                "the cutoff under this load (check the cutoff voltage and the battery's "
                "capacity parameter)")
        idx = running
        h = dt.copy()
        if st.kind == "profile":
            t = st.profile_arrays[0]
            nxt = t[np.clip(np.searchsorted(t, t_in, side="right"), 0, t.size - 1)]
            h = np.where(nxt > t_in, np.minimum(nxt - t_in, dt), dt)
        if end is not None:
            h = np.minimum(h, end - t_in)
        sub = _take(state, idx)
        p_sub = {kk: v[idx] for kk, v in pack.p.items()}
        sub_pack = _SubPack(pack, p_sub)
        i0 = _current_at(sub_pack, st, sub, t_in[idx])
        new, i1 = _advance_step(sub_pack, st, sub, i0, h[idx])
        v1 = sub_pack.voltage(new, i1)
        stop = _stop_reason(st, sub_pack, new, i1, v1, cutoff,
                            None if reserve is None else reserve[idx])
        crossed = stop != ""
        if crossed.any():
            frac = _bisect(sub_pack, st, sub, i0, h[idx], crossed, cutoff,
                           None if reserve is None else reserve[idx])
            h_idx = h[idx].copy()
            h_idx[crossed] = frac[crossed] * h_idx[crossed]
            cross_pack = _SubPack(pack, {kk: v[crossed] for kk, v in p_sub.items()})
            new_c, i1_c = _advance_step(cross_pack, st, _take(sub, crossed), i0[crossed],
                                        h_idx[crossed])
            _put(new, crossed, new_c)
            i1 = i1.copy()
            i1[crossed] = np.where(np.isfinite(i1_c), i1_c, i0[crossed])
            v1 = sub_pack.voltage(new, i1)
            v1 = np.where(crossed & (stop == "cutoff"), cutoff, v1)
            h[idx] = h_idx
        # bookkeeping
        v0 = sub_pack.voltage(sub, i0)
        with np.errstate(invalid="ignore"):  # 0 A at -inf V beyond the capacity: no power
            p0 = np.where(np.isfinite(i0) & np.isfinite(v0), i0 * v0, 0.0)
            p1 = np.where(np.isfinite(i1) & np.isfinite(v1), i1 * v1, 0.0)
        energy[idx] += 0.5 * (p0 + p1) * h[idx] / 3600.0
        t_now[idx] += h[idx]
        t_in[idx] += h[idx]
        _put(state, idx, new)
        vmin_idx = vmin[idx]
        vmin[idx] = np.minimum(vmin_idx, np.where(np.isfinite(v1), v1, cutoff))
        peak_t[idx] = np.maximum(peak_t[idx], sub_pack.temperature(new))
        rec.add(t_now, i1, v1, state["charge_Ah"] * pack.par, pack.temperature(state), k)
        done = np.zeros(t_now.size, bool)
        done_idx = np.flatnonzero(idx)
        stopped = done_idx[crossed]
        ended[stopped] = stop[crossed]
        active[stopped] = False
        done[stopped] = True
        if end is not None:
            finished = done_idx[(t_in[idx] >= end - 1e-9 * max(end, 1.0)) & ~crossed]
            done[finished] = True
        running &= ~done
    return state


class _SubPack(_Pack):
    """The same pack restricted to a subset of draws."""

    def __init__(self, pack: _Pack, params: dict):
        self.family, self.p, self.s, self.par = pack.family, params, pack.s, pack.par
        self.ambient, self.kinds = pack.ambient, pack.kinds


def _check_start(st, running, active, ended, i_now, v_now, state, pack, cutoff, reserve):
    if st.kind == "power":
        bad = running & ~np.isfinite(i_now)
        ended[bad] = "power limit"
        active[bad] = False
        running &= ~bad
    if st.kind != "rest":
        low = running & ~(v_now > cutoff)
        ended[low] = "cutoff"
        active[low] = False
        running &= ~low
    if reserve is not None and st.kind != "rest":
        out = running & (state["charge_Ah"] * pack.par >= reserve)
        ended[out] = "reserve"
        active[out] = False
        running &= ~out


def _stop_reason(st, pack, state, current, voltage, cutoff, reserve):
    """'' / 'cutoff' / 'power limit' / 'reserve' per draw after a step."""
    out = np.full(voltage.shape, "", dtype=object)
    if st.kind == "rest":
        return out
    if reserve is not None:
        out[state["charge_Ah"] * pack.par >= reserve] = "reserve"
    out[~(voltage > cutoff)] = "cutoff"
    if st.kind == "power":
        out[~np.isfinite(current)] = "power limit"
    return out


def _bisect(pack, st, state, i0, h, crossed, cutoff, reserve):
    """Fraction of the step at which each crossed draw stops (bounded).

    The same answer as :data:`BISECTION_ITERATIONS` halvings of the step (the first
    stopped point of the grid of ``2**-BISECTION_ITERATIONS`` steps), found in a few
    rounds that each try up to :data:`BISECTION_GRID_BITS` bits of that grid at once:
    every round advances each draw to all the grid's points as one batch of draws, so a
    few draws cost a few batched advances instead of one per halving (many draws, whose
    batch would be large, are halved one point each as before).
    """
    out = np.ones(h.size)
    sel = np.flatnonzero(crossed)
    m = sel.size
    if m == 0:
        return out
    lo_s, hi_s = np.zeros(m), np.ones(m)
    per_round = int(np.clip(np.floor(np.log2(BISECTION_BATCH_POINTS / m)), 1,
                            BISECTION_GRID_BITS))
    bits_left = BISECTION_ITERATIONS
    while bits_left > 0:  # bounded: bits_left falls by at least one per round
        bits = min(per_round, bits_left)
        bits_left -= bits
        n = 2 ** bits
        frac = np.arange(1, n) / n  # the grid's inner points; the last is hi, stopped
        pts = (lo_s[:, None] + (hi_s - lo_s)[:, None] * frac[None, :]).ravel()
        rows = np.repeat(sel, n - 1)
        sub = _take(state, rows)
        sub_pack = _SubPack(pack, {k: v[rows] for k, v in pack.p.items()})
        new, i1 = _advance_step(sub_pack, st, sub, i0[rows], pts * h[rows])
        v1 = sub_pack.voltage(new, i1)
        res = None if reserve is None else reserve[rows]
        gone = (_stop_reason(st, sub_pack, new, i1, v1, cutoff, res) != "").reshape(m, n - 1)
        gone = np.concatenate([gone, np.ones((m, 1), bool)], axis=1)
        first = np.argmax(gone, axis=1)  # the first stopped point of each draw's grid
        width = hi_s - lo_s
        hi_s = lo_s + width * ((first + 1) / n)
        lo_s = lo_s + width * (first / n)
    out[sel] = hi_s
    return out
