"""Propagate the fit's parameter uncertainty into mission endurance by covariance sampling.

When the fit stored bootstrap refits (``fit --bootstrap N``, the command-line
default), those parameter sets are flown: each is a real fit of the data with
resampled residuals, so the draws stay on the data even where the model is far
from linear in its parameters. Otherwise the fit's 6x6 covariance
(``Battery.covariance``, :data:`~dischargelab.model.PARAMETER_NAMES` order,
zeros for fixed parameters) is sampled: multivariate normal draws (seeded),
unphysical draws rejected (negative resistance, polarisation or exponential
terms, capacity not above the charge measured during the fit, ...). Either way
the mission is flown once per draw and the percentiles of the outcomes are
reported (95 % interval by default).

Flying the mission for hundreds of draws one by one through
:func:`dischargelab.simulate.simulate` takes seconds to minutes (constant-power
phases integrate an ODE per phase and per root-finding step), so the draws are
evaluated all at once in the *charge domain*: every array below has one entry
per draw (``CellParameters`` fields broadcast), with

* the same split ``V = a(q) - b(q) i`` and the same low-current root of
  ``V i = P`` as :mod:`dischargelab.simulate` (its helpers are reused);
* the charge at which a phase reaches the cutoff (or the power limit) found by
  bisection on the monotone voltage, the time between two charges by
  Gauss-Legendre quadrature of ``dt/dq = 3600 / i(q)``, and the charge after a
  fixed-duration constant-power phase by classical Runge-Kutta in time;
* the longest stretch phase by bisection on the charge at its end.

The nominal values always come from the :mod:`dischargelab.mission` path through
``simulate``; the tests check that this evaluator reproduces them.

References
----------
.. [1] JCGM 101:2008, "Evaluation of measurement data - Supplement 1: Propagation
   of distributions using a Monte Carlo method".
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .errors import DataError
from .model import PARAMETER_NAMES, Battery, CellParameters
from .simulate import linear_in_current, power_current

#: Default number of parameter draws.
DEFAULT_DRAWS = 300

#: Runge-Kutta steps per fixed-duration constant-power phase.
RK4_STEPS = 24

#: Gauss-Legendre nodes for the time between two charges at constant power.
QUADRATURE_NODES = 32

#: Bisection iterations (charge resolution ``capacity * 2**-BISECTION_STEPS``).
BISECTION_STEPS = 50

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(QUADRATURE_NODES)


# ---------------------------------------------------------------------------------------------
# Sampling
# ---------------------------------------------------------------------------------------------

def _physical(values: np.ndarray, min_capacity_Ah: float) -> np.ndarray:
    """Rows of parameter draws (PARAMETER_NAMES order) that describe a physical cell."""
    e0, r, k, a, b, c = values.T
    return (e0 > 0) & (r >= 0) & (k >= 0) & (a >= 0) & (b > 0) & (c > min_capacity_Ah)


def sample_parameters(battery: Battery, draws: int = DEFAULT_DRAWS, *, seed: int = 0,
                      max_rounds: int = 50):
    """Draw cell parameters from the fit covariance, rejecting unphysical draws.

    Parameters
    ----------
    battery : Battery
        Must carry ``covariance`` (6x6).
    draws : int
        Number of accepted draws wanted.
    seed : int
        Seed of ``numpy.random.default_rng``.
    max_rounds : int
        Batches of draws tried before giving up.

    Returns
    -------
    params : CellParameters
        Each field an array of shape ``(draws,)``.
    info : dict
        ``requested``, ``accepted``, ``rejected``, ``rejected_fraction``, ``warnings``.

    Raises
    ------
    DataError
        No covariance, or fewer than half the draws physical after ``max_rounds``.
    """
    boot = bootstrap_parameters(battery)
    if boot is not None:
        params = CellParameters(*[boot[:, k] for k in range(6)])
        return params, {"requested": int(len(boot)), "accepted": int(len(boot)),
                        "tried": int(len(boot)), "rejected": 0, "rejected_fraction": 0.0,
                        "warnings": [], "method": f"bootstrap refits stored by the fit "
                                                  f"({len(boot)} moving-block replicas)"}
    if battery.covariance is None:
        raise DataError("the battery has no covariance (presets and hand-written files); "
                        "fit it from a measured discharge to get an uncertainty")
    if draws < 2:
        raise DataError(f"need at least 2 draws, got {draws}")
    cov = np.asarray(battery.covariance, dtype=float)
    if cov.shape != (6, 6) or not np.all(np.isfinite(cov)):
        raise DataError("battery covariance must be a finite 6x6 matrix")
    cov = 0.5 * (cov + cov.T)
    values, vectors = np.linalg.eigh(cov)
    warnings = []
    scale = max(float(values.max()), 0.0)
    if values.min() < -1e-8 * max(scale, 1e-300):
        warnings.append("the stored covariance is not positive semi-definite; negative "
                        "eigenvalues were set to zero")
    factor = vectors * np.sqrt(np.clip(values, 0.0, None))
    mean = battery.parameters.as_array()
    min_capacity = float(battery.extra.get("measured_capacity_Ah", 0.0) or 0.0)
    if not _physical(mean[None, :], min_capacity)[0]:
        min_capacity = 0.0
    rng = np.random.default_rng(seed)
    accepted, tried = [], 0
    for _ in range(max_rounds):
        need = draws - sum(len(x) for x in accepted)
        if need <= 0:
            break
        batch = mean + rng.standard_normal((max(2 * need, 16), 6)) @ factor.T
        tried += len(batch)
        accepted.append(batch[_physical(batch, min_capacity)])
    sample = np.concatenate(accepted)[:draws] if accepted else np.empty((0, 6))
    if len(sample) < draws:
        raise DataError(f"only {len(sample)} of {tried} parameter draws are physical; the fit "
                        f"covariance is too wide to sample (check the fit warnings)")
    rejected = tried - sum(len(x) for x in accepted)
    fraction = rejected / max(tried, 1)
    if fraction > 0.1:
        warnings.append(f"{100 * fraction:.0f} % of the parameter draws were unphysical and "
                        f"rejected: the interval is a truncated-normal estimate")
    params = CellParameters(*[sample[:, k] for k in range(6)])
    info = {"requested": int(draws), "accepted": int(len(sample)), "tried": int(tried),
            "rejected": int(rejected), "rejected_fraction": float(fraction),
            "warnings": warnings,
            "method": "covariance sampling (multivariate normal, unphysical draws rejected)"}
    return params, info


def bootstrap_parameters(battery: Battery):
    """Bootstrap parameter sets stored in the battery file (n x 6 array) or None."""
    boot = battery.extra.get("bootstrap") if isinstance(battery.extra, dict) else None
    if not boot:
        return None
    if list(boot.get("names", [])) != list(PARAMETER_NAMES):
        raise DataError("battery file bootstrap has unexpected parameter names")
    samples = np.asarray(boot.get("samples", []), dtype=float)
    if samples.ndim != 2 or samples.shape[1] != 6 or len(samples) < 2 or \
            not np.all(np.isfinite(samples)):
        raise DataError("battery file bootstrap must be a list of at least 2 rows of 6 numbers")
    return samples


def interval(values, level: float = 0.95) -> tuple[float, float]:
    """Central percentile interval of finite ``values``."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan")
    tail = 100.0 * (1.0 - level) / 2.0
    lo, hi = np.percentile(v, [tail, 100.0 - tail])
    return float(lo), float(hi)


# ---------------------------------------------------------------------------------------------
# Vectorised mission outcomes in the charge domain
# ---------------------------------------------------------------------------------------------

class DrawFlight:
    """Outcomes of one mission for many parameter sets at once (see the module docstring).

    Parameters
    ----------
    mission : dischargelab.mission.Mission
    params : CellParameters
        Fields are arrays of shape ``(n,)`` (one per draw) or scalars.
    """

    def __init__(self, mission, params: CellParameters):
        arrays = [np.atleast_1d(np.asarray(getattr(params, n), dtype=float))
                  for n in PARAMETER_NAMES]
        n = max(a.size for a in arrays)
        arrays = [np.broadcast_to(a, (n,)).copy() for a in arrays]
        self.params = CellParameters(*arrays)
        self.mission = mission
        self.n = n
        battery = replace(mission.battery, parameters=self.params)
        self.a_b = linear_in_current(battery)
        self.capacity = arrays[5] * battery.strings_parallel
        self.q_start = (1.0 - mission.initial_soc_pct / 100.0) * self.capacity
        self.q_reserve = (1.0 - mission.reserve_pct / 100.0) * self.capacity
        self.v_cut = mission.cutoff_pack_V
        self._stop_cache = {}

    # -- one phase --------------------------------------------------------------------------
    def current(self, phase, q):
        """Pack current [A] of a phase at pack charge ``q`` (NaN beyond the power limit)."""
        if phase.kind == "current":
            return np.full(np.shape(q), float(phase.value))
        a, b = self.a_b(q)
        return power_current(a, b, float(phase.value))

    def _loaded_voltage_gap(self, phase, q):
        """Loaded pack voltage minus the cutoff at charge q (-1 beyond the power limit)."""
        a, b = self.a_b(q)
        if phase.kind == "current":
            gap = a - b * phase.value - self.v_cut
        else:
            disc = a * a - 4.0 * b * phase.value
            gap = np.where(disc >= 0, 0.5 * (a + np.sqrt(np.clip(disc, 0, None))) - self.v_cut,
                           -1.0)
        return np.where(np.isfinite(gap), gap, -1.0)

    def stop_charge(self, phase) -> np.ndarray:
        """Pack charge [Ah] at which this load reaches the cutoff or the power limit."""
        key = (phase.kind, float(phase.value))
        if key not in self._stop_cache:
            lo = np.zeros(self.n)
            hi = self.capacity * (1.0 - 1e-12)
            ok_at_zero = self._loaded_voltage_gap(phase, lo) > 0
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo + hi)
                above = self._loaded_voltage_gap(phase, mid) > 0
                lo = np.where(above, mid, lo)
                hi = np.where(above, hi, mid)
            self._stop_cache[key] = np.where(ok_at_zero, lo, 0.0)
        return self._stop_cache[key]

    def time_between(self, phase, q0, q1) -> np.ndarray:
        """Time [s] for the phase's load to take the charge from ``q0`` to ``q1``."""
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        dq = np.clip(q1 - q0, 0.0, None)
        if phase.kind == "current":
            return dq * 3600.0 / phase.value
        half = 0.5 * dq
        mid = q0 + half
        nodes = mid[None, :] + half[None, :] * _NODES[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            inv = 3600.0 / self.current(phase, nodes)
            total = half * np.sum(_WEIGHTS[:, None] * inv, axis=0)
        return np.where(dq > 0, total, 0.0)

    def advance(self, phase, q0, duration_s) -> np.ndarray:
        """Charge [Ah] after ``duration_s`` (scalar or per draw) at the phase's load.

        NaN where the power failed.
        """
        if phase.value == 0 or np.all(np.asarray(duration_s) == 0):
            return np.array(q0, dtype=float)
        if phase.kind == "current":
            return q0 + phase.value * duration_s / 3600.0
        h = duration_s / RK4_STEPS
        q = np.array(q0, dtype=float)
        f = lambda x: self.current(phase, x) / 3600.0  # noqa: E731
        for _ in range(RK4_STEPS):
            k1 = f(q)
            k2 = f(q + 0.5 * h * k1)
            k3 = f(q + 0.5 * h * k2)
            k4 = f(q + h * k3)
            q = q + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return q

    def fly_phase(self, phase, duration_s, until, state):
        """Advance ``state`` (dict of q, t, alive, reason arrays) through one phase."""
        q, t, alive = state["q"], state["t"], state["alive"]
        if not alive.any():
            return
        if phase.value == 0:  # motors off: time passes, no charge drawn
            t[alive] += duration_s
            return
        stop = self.stop_charge(phase)
        if until is not None or duration_s is None:
            target = stop if until != "reserve" else np.minimum(stop, self.q_reserve)
            target = np.maximum(target, q)
            dt = self.time_between(phase, q, target)
            by_reserve = (until == "reserve") & (self.q_reserve < stop)
            state["reason"][alive] = np.where(by_reserve, 3, 1)[alive]
            t[alive] += dt[alive]
            q[alive] = target[alive]
            alive[:] = False
            return
        self._step(phase, state, stop, np.broadcast_to(float(duration_s), q.shape))

    def _step(self, phase, state, stop, durations, reason=1):
        """Advance the alive draws by ``durations``; those crossing ``stop`` end there.

        ``reason`` (scalar or per draw) is recorded for the draws that end.
        """
        q, t, alive = state["q"], state["t"], state["alive"]
        q_new = self.advance(phase, q, durations)
        crossed = alive & ~(q_new < stop) & (durations > 0)
        ok = alive & ~crossed
        t[ok] += durations[ok]
        q[ok] = q_new[ok]
        if crossed.any():
            target = np.maximum(stop, q)
            dt = self.time_between(phase, q, target)
            t[crossed] += dt[crossed]
            q[crossed] = target[crossed]
            alive[crossed] = False
            state["reason"][crossed] = np.broadcast_to(reason, q.shape)[crossed]

    def _new_state(self, q=None, t=None):
        q = self.q_start.copy() if q is None else np.array(q, dtype=float)
        return {"q": q, "t": np.zeros(self.n) if t is None else np.array(t, dtype=float),
                "alive": np.ones(self.n, dtype=bool), "reason": np.zeros(self.n, dtype=int)}

    def _fly_items(self, items, state, stretch_s=None):
        from .mission import RepeatBlock

        for item in items:
            if isinstance(item, RepeatBlock):
                if item.count is not None:
                    for _ in range(item.count):
                        for ph in item.phases:
                            self.fly_phase(ph, ph.duration_s, None, state)
                else:
                    self._fly_until_block(item, state)
            else:
                duration = stretch_s if item.stretch else item.duration_s
                self.fly_phase(item, duration, item.until, state)

    def _fly_until_block(self, block, state):
        """Repeat the block until every draw reached the cutoff (or the reserve)."""
        passes = 0
        while state["alive"].any():
            for ph in block.phases:
                if block.until == "reserve":
                    self._phase_with_reserve(ph, state)
                else:
                    self.fly_phase(ph, ph.duration_s, None, state)
            passes += 1
            if passes > 100000:  # pragma: no cover - finite capacity
                raise DataError(f"repeat block {block.name!r} never ends")

    def _phase_with_reserve(self, phase, state):
        """A fixed-duration phase that also stops at the reserve."""
        q, t, alive = state["q"], state["t"], state["alive"]
        if not alive.any():
            return
        if phase.value == 0:
            t[alive] += phase.duration_s
            return
        stop = self.stop_charge(phase)
        self._step(phase, state, np.minimum(stop, self.q_reserve),
                   np.broadcast_to(float(phase.duration_s), q.shape),
                   reason=np.where(self.q_reserve < stop, 3, 1))

    # -- whole mission -----------------------------------------------------------------------
    def _suffix_feasible(self, items, q_end_stretch):
        state = self._new_state(q=q_end_stretch)
        self._fly_items(items, state)
        return state["alive"] & (state["q"] <= self.q_reserve * (1 + 1e-12))

    def evaluate(self) -> dict:
        """Outcome arrays: endurance_s, flight_time_s, soc_end_pct, completed, max_stretch_s."""
        m = self.mission
        k = m.stretch_index
        out = {}
        if k is None:
            state = self._new_state()
            self._fly_items(m.items, state)
            flight = state["t"]
            endurance = flight.copy()
            completed = state["alive"] | (state["reason"] == 3)
        else:
            stretch = m.items[k]
            prefix, suffix = m.items[:k], m.items[k + 1:]
            state = self._new_state()
            self._fly_items(prefix, state)
            q_s, t_s = state["q"].copy(), state["t"].copy()
            alive = state["alive"].copy()
            upper = np.minimum(self.stop_charge(stretch), self.q_reserve)
            upper = np.maximum(upper, q_s)
            feasible0 = alive & self._suffix_feasible(suffix, q_s)
            lo, hi = q_s.copy(), upper.copy()
            top_ok = self._suffix_feasible(suffix, hi) & (hi < self.stop_charge(stretch))
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo + hi)
                ok = self._suffix_feasible(suffix, mid)
                lo = np.where(ok, mid, lo)
                hi = np.where(ok, hi, mid)
            q_star = np.where(top_ok, upper, lo)
            max_s = np.where(feasible0, self.time_between(stretch, q_s, q_star), 0.0)
            out["max_stretch_s"] = max_s
            flown = max_s if stretch.duration_s is None else \
                np.full(self.n, float(stretch.duration_s))
            # fly the stretch phase per draw duration (durations may differ per draw)
            flight_state = {"q": q_s.copy(), "t": t_s.copy(), "alive": alive.copy(),
                            "reason": state["reason"].copy()}
            self._fly_stretch(stretch, flown, flight_state)
            self._fly_items(suffix, flight_state)
            flight = flight_state["t"]
            completed = flight_state["alive"].copy()
            endurance = np.where(feasible0, flight - flown + max_s, flight)
            state = flight_state
        out["flight_time_s"] = flight
        out["endurance_s"] = endurance
        out["completed"] = completed
        out["soc_end_pct"] = 100.0 * (1.0 - state["q"] / self.capacity)
        return out

    def _fly_stretch(self, phase, durations, state):
        """The stretch phase with a per-draw duration."""
        self._step(phase, state, self.stop_charge(phase), durations)


def mission_uncertainty(mission, *, draws: int = DEFAULT_DRAWS, seed: int = 0, level=0.95,
                        progress=None, nominal=None) -> dict:
    """Interval of the mission endurance from the fit covariance.

    Parameters
    ----------
    mission : dischargelab.mission.Mission
    draws : int
        Accepted parameter draws (200-500 is plenty for a 95 % interval).
    seed : int
    level : float
        Coverage of the central interval.
    progress : callable, optional
        ``progress(done, total)``.
    nominal : MissionResult, optional
        Nominal result (its values are reported as ``nominal``).

    Returns
    -------
    dict
        ``available`` (False with ``reason`` when the battery has no covariance),
        ``draws``, ``accepted``, ``rejected``, ``seed``, ``level``, and for
        ``endurance_s``, ``soc_end_pct`` (and ``max_stretch_s``): ``nominal``,
        ``median``, ``low``, ``high``, ``std``; ``completed_fraction``; ``warnings``.
    """
    cov = mission.battery.covariance
    has_boot = bootstrap_parameters(mission.battery) is not None
    if not has_boot and (cov is None or not np.any(np.asarray(cov))):
        return {"available": False, "level": level,
                "reason": "the battery file holds no parameter covariance (a preset or a "
                          "hand-written file); fit a measured discharge to get one",
                "warnings": []}
    params, info = sample_parameters(mission.battery, draws, seed=seed)
    if progress is not None:
        progress(0, draws)
    outcome = DrawFlight(mission, params).evaluate()
    if progress is not None:
        progress(draws, draws)
    if nominal is None:
        from .mission import mission_summary

        nom = mission_summary(mission)
    else:
        nom = {"endurance_s": nominal.endurance_s, "soc_end_pct": nominal.soc_end_pct}
        if nominal.stretch is not None:
            nom["max_stretch_s"] = nominal.stretch["max_s"]
    out = {"available": True, "method": info["method"],
           "draws": info["requested"], "accepted": info["accepted"], "tried": info["tried"],
           "rejected": info["rejected"], "rejected_fraction": info["rejected_fraction"],
           "seed": int(seed), "level": level}
    keys = ["endurance_s", "soc_end_pct"] + (["max_stretch_s"] if "max_stretch_s" in outcome
                                             else [])
    for key in keys:
        values = outcome[key]
        lo, hi = interval(values, level)
        out[key] = {"nominal": float(nom[key]), "median": float(np.median(values)),
                    "low": lo, "high": hi, "std": float(np.std(values, ddof=1))}
    out["completed_fraction"] = float(np.mean(outcome["completed"]))
    warnings = list(info["warnings"])
    if out["completed_fraction"] < 0.975 and out["completed_fraction"] > 0:
        warnings.append(f"in {100 * (1 - out['completed_fraction']):.1f} % of the parameter "
                        f"draws the mission does not complete")
    out["warnings"] = warnings
    return out


def simulation_interval(battery: Battery, simulate_one, *, level: float = 0.95) -> dict | None:
    """Interval of a simulation's summary numbers over the stored bootstrap refits.

    Parameters
    ----------
    battery : Battery
        With ``extra["bootstrap"]`` (``fit --bootstrap N``); otherwise None is returned.
    simulate_one : callable
        ``simulate_one(battery) -> SimulationResult`` for one parameter set.

    Returns
    -------
    dict or None
        ``{"level", "draws", "failed", "time_to_cutoff_s": (low, high),
        "capacity_Ah": (low, high), "energy_Wh": (low, high)}``; draws whose
        simulation is impossible (e.g. the cutoff above their start voltage) are
        counted in ``failed``.
    """
    samples = bootstrap_parameters(battery)
    if samples is None:
        return None
    times, charges, energies, failed = [], [], [], 0
    for row in samples:
        try:
            run = simulate_one(replace(battery, parameters=CellParameters.from_array(row)))
        except DataError:
            failed += 1
            continue
        times.append(run.time_to_cutoff_s)
        charges.append(run.capacity_Ah)
        energies.append(run.energy_Wh_total)
    return {"level": level, "draws": int(len(samples)), "failed": failed,
            "time_to_cutoff_s": interval(times, level), "capacity_Ah": interval(charges, level),
            "energy_Wh": interval(energies, level)}


__all__ = ["sample_parameters", "bootstrap_parameters", "simulation_interval", "interval", "DrawFlight", "mission_uncertainty",
           "DEFAULT_DRAWS"]
