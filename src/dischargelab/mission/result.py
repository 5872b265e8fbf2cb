"""Flown missions: :func:`run_mission` and its :class:`MissionResult` (time series,
per-phase table, endurance, margins, warnings), and the mission's 95 % interval
(:func:`mission_uncertainty`: parameter draws flown through the mission plus the
model's own error, see :mod:`dischargelab.uncertainty`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import SimulationError
from ..formatting import duration, mission_text
from ..model import Battery
from ..simulate import SimulationResult
from ..uncertainty import (
    DEFAULT_DRAWS,
    error_factors,
    lognormal_spread,
    model_error_info,
    parameter_draws,
    spread,
    z_level,
)
from .fly import (
    POINTS_PER_PHASE,
    Flyer,
    fly_mission,
    leg_simulation,
    load_at_start,
    max_stretch_s,
    mission_outcomes,
)
from .spec import Mission, RepeatBlock


@dataclass
class MissionResult:
    """A flown mission: time series, per-phase table, endurance, margins, warnings.

    Attributes
    ----------
    mission : Mission
    simulation : SimulationResult
        Pack-level time series of the flight as flown.
    phases : list of dict
        Per flown phase: name, repetition, start/end [s], charge [Ah], energy [Wh],
        mean current [A] and power [W], end voltage [V], end state of charge [%].
    completed : bool
        All phases flown without reaching the cutoff (or power limit).
    ended_by : {"end", "cutoff", "power limit", "reserve"}
    flight_time_s : float
        Duration of the flight as flown [s].
    endurance_s : float
        Headline flight time [s]: with a stretch phase, the flight with the longest
        stretch (landing at the reserve); otherwise the flight as flown.
    cutoff_time_s, reserve_time_s : float
        When the cutoff / reserve was reached during the flight (NaN if not).
    stretch : dict or None
        See :func:`max_stretch_s`.
    uncertainty : dict or None
        See :func:`dischargelab.uncertainty.mission_uncertainty`.
    warnings : list of str
    notes : list of str
        What the result rests on that the caller should know (e.g. a logbook pack's
        model scaled to its health today).
    cannot_deliver : dict or None
        When the flight ended at the very start of a phase, the load the pack cannot
        deliver: :func:`dischargelab.mission.fly.load_at_start` plus ``message``, the
        sentence that says so (also the first warning).
    """

    mission: Mission
    simulation: SimulationResult
    labels: list
    phases: list
    completed: bool
    ended_by: str
    flight_time_s: float
    endurance_s: float
    cutoff_time_s: float
    reserve_time_s: float
    soc_end_pct: float
    min_voltage_V: float
    stretch: dict | None
    warnings: list
    uncertainty: dict | None = None
    notes: list = field(default_factory=list)
    cannot_deliver: dict | None = None

    @property
    def soc_pct(self) -> np.ndarray:
        """State of charge through the flight [%]."""
        return 100.0 * (1.0 - self.simulation.charge_Ah / self.mission.capacity_Ah)

    @property
    def voltage_margin_V(self) -> float:
        """Lowest pack voltage in flight minus the pack cutoff [V]."""
        return self.min_voltage_V - self.mission.cutoff_pack_V

    def to_pandas(self):
        """Time series: time_s, voltage_V, current_A, power_W, charge_Ah, soc_pct, phase."""
        df = self.simulation.to_pandas()
        df["soc_pct"] = self.soc_pct
        df["phase"] = [_label_text(self.labels[k]) for k in self.simulation.step]
        return df.drop(columns=["step"])

    def to_dict(self) -> dict:
        """Summary for JSON output (keys are only ever added, never renamed)."""
        m = self.mission
        out = {
            "mission": m.name,
            "source": m.source,
            "battery": m.battery.name,
            "cells_series": m.battery.cells_series,
            "strings_parallel": m.battery.strings_parallel,
            "chemistry": m.battery.chemistry,
            "capacity_Ah": m.capacity_Ah,
            "cutoff_cell_V": m.cutoff_cell_V,
            "cutoff_pack_V": m.cutoff_pack_V,
            "reserve_pct": m.reserve_pct,
            "initial_soc_pct": m.initial_soc_pct,
            "completed": self.completed,
            "ended_by": self.ended_by,
            "flight_time_s": self.flight_time_s,
            "endurance_s": self.endurance_s,
            "cutoff_time_s": self.cutoff_time_s,
            "reserve_time_s": self.reserve_time_s,
            "soc_end_pct": self.soc_end_pct,
            "soc_margin_pct": self.soc_end_pct - m.reserve_pct,
            "min_voltage_V": self.min_voltage_V,
            "voltage_margin_V": self.voltage_margin_V,
            "charge_used_Ah": self.simulation.capacity_Ah,
            "energy_used_Wh": self.simulation.energy_Wh_total,
            "stretch": self.stretch,
            "model": m.battery.model,
            "model_family": m.battery.family.title,
            "ambient_C": m.resolved_ambient_C,
            "peak_temperature_C": self.simulation.peak_temperature_C,
            "phases": self.phases,
            "uncertainty": self.uncertainty,
            "warnings": list(self.warnings),
            "notes": list(self.notes),
            "cannot_deliver": None if self.cannot_deliver is None else
            dict(self.cannot_deliver),
        }
        out["text"] = mission_text(out)    # the durations as every view writes them
        return out

    def plot(self, ax=None, **kwargs):
        """Voltage through the flight with the phases shaded (paper Fig. 11); returns the Axes."""
        from ..plot import plot_mission

        return plot_mission(self, ax=ax, **kwargs)


def _label_text(label) -> str:
    name, _, rep = label
    return name if rep is None else f"{name} #{rep}"


def _phase_detail(mission: Mission, label) -> dict:
    name, index, _ = label
    item = mission.items[index]
    phases = item.phases if isinstance(item, RepeatBlock) else (item,)
    return next((dict(ph.detail) for ph in phases if ph.name == name), {})


def _phase_table(mission: Mission, sim: SimulationResult, labels: list) -> list[dict]:
    rows = []
    for k, label in enumerate(labels):
        sel = np.flatnonzero(sim.step == k)
        if sel.size == 0:
            continue
        a, b = sel[0], sel[-1]
        # each step starts where the previous ended
        t0 = sim.time_s[a - 1] if a > 0 else sim.time_s[a]
        q0 = sim.charge_Ah[a - 1] if a > 0 else sim.charge_Ah[a]
        e0 = sim.energy_Wh[a - 1] if a > 0 else sim.energy_Wh[a]
        duration = float(sim.time_s[b] - t0)
        charge = float(sim.charge_Ah[b] - q0)
        energy = float(sim.energy_Wh[b] - e0)
        st = sim.steps[k]
        rows.append({
            "phase": label[0],
            "repetition": label[2],
            "load": f"{st.value:g} A" if st.kind == "current" else f"{st.value:.4g} W",
            "start_s": float(t0),
            "end_s": float(sim.time_s[b]),
            "duration_s": duration,
            "charge_Ah": charge,
            "energy_Wh": energy,
            "mean_current_A": charge * 3600.0 / duration if duration > 0 else
            float(sim.current_A[b]),
            "max_current_A": float(np.max(sim.current_A[sel])),
            "mean_power_W": energy * 3600.0 / duration if duration > 0 else
            float(sim.power_W[b]),
            "end_voltage_V": float(sim.voltage_V[b]),
            "end_soc_pct": float(100.0 * (1.0 - sim.charge_Ah[b] / mission.capacity_Ah)),
        })
        detail = _phase_detail(mission, label)
        if detail:
            rows[-1]["flight_condition"] = detail
    return rows


def _crossing_time(sim: SimulationResult, q_target: float) -> float:
    """First time the charge reaches ``q_target`` (NaN if never)."""
    idx = np.flatnonzero(sim.charge_Ah >= q_target * (1.0 - 1e-9))
    if idx.size == 0:
        return float("nan")
    k = int(idx[0])
    if k == 0:
        return float(sim.time_s[0])
    return float(np.interp(q_target, sim.charge_Ah[k - 1:k + 1], sim.time_s[k - 1:k + 1]))


def extrapolation_warnings(battery: Battery, phase_rows: list[dict]) -> list[str]:
    """Warn when phase cell currents lie far outside the currents the battery was fitted at.

    See :meth:`dischargelab.model.Battery.extrapolation` (more than 2x above the
    highest or below half the lowest fitted cell current). The ratio the warning names
    is the mission's (:func:`mission_extrapolation_ratio`), the one its interval is
    widened with.
    """
    fitted = [abs(x) for x in battery.fit_currents_A if x]
    if not fitted:
        return ["the battery file lists no fit currents; cannot check whether the mission "
                "currents lie inside the fitted range"]
    p = battery.strings_parallel
    found = {"above": {}, "below": {}}
    for row in phase_rows:
        cell = row["mean_current_A"] / p
        side = battery.extrapolation(cell)
        if side:
            found[side].setdefault(row["phase"], cell)
    from ..predict import extrapolation_warning

    mission_ratio = mission_extrapolation_ratio(battery, phase_rows)
    out = []
    for side, phases in found.items():
        if phases:
            # the phase furthest out speaks for the group, in the one wording of predict/curves
            worst = max(phases.values(), key=battery.extrapolation_ratio)
            names = ", ".join(f"{n} ({c:.3g} A)" for n, c in phases.items())
            out.append(f"{extrapolation_warning(battery, worst, side, mission_ratio)} "
                       f"[phases: {names}]")
    return out


def cannot_deliver_text(mission: Mission, found: dict) -> str:
    """One sentence: the load of :func:`~dischargelab.mission.fly.load_at_start` that the
    pack cannot deliver, and the most it can deliver there."""
    bat = mission.battery
    where = f"'{found['phase']}' at {found['soc_pct']:.0f} % charge"
    cutoff = f"the {mission.cutoff_pack_V:.2f} V cutoff"
    if found["max_current_A"] <= 0:
        return (f"the pack cannot fly {where}: even without load its voltage "
                f"({found['no_load_voltage_V']:.2f} V) is at or below {cutoff}; check the "
                "cutoff, the cells in series and the state of charge at take-off")
    if found["kind"] == "power":
        return (f"the pack cannot deliver the {found['load']:g} W of {where}: its voltage "
                f"would fall below {cutoff} at once; it can deliver at most "
                f"{found['max_power_W']:.4g} W there")
    p = bat.strings_parallel
    rated = bat.rated_capacity_Ah / p

    def per_cell(pack_A: float) -> str:
        amps = "" if p == 1 else f"{pack_A / p:.3g} A, "
        return f"{amps}{pack_A / p / rated:.3g}C per cell"

    return (f"the pack cannot deliver the {found['load']:g} A of {where} "
            f"({per_cell(found['load'])}): its voltage would fall below {cutoff} at once; "
            f"it can deliver at most {found['max_current_A']:.3g} A there "
            f"({per_cell(found['max_current_A'])})")


def run_mission(mission: Mission, *, draws: int = 0, seed: int = 0,
                points_per_step: int = POINTS_PER_PHASE, progress=None) -> MissionResult:
    """Fly a mission: time series, endurance, maximum stretch, margins and warnings.

    Parameters
    ----------
    mission : Mission
    draws : int
        Parameter draws for the 95 % interval of the endurance (0 = no interval); see
        :func:`dischargelab.uncertainty.mission_uncertainty` (a battery without draws
        gets the model error alone).
    seed : int
        Seed of the draws.
    points_per_step : int
        Engine time steps (output samples) per phase.
    progress : callable, optional
        ``progress(done, total)`` during the uncertainty draws.

    Returns
    -------
    MissionResult

    Raises
    ------
    SimulationError
        One line when the model never reaches the cutoff (or a repeat block its end).
    """
    stretch = max_stretch_s(mission, points=points_per_step) \
        if mission.stretch_index is not None else None
    stretch_flown = None
    if stretch is not None:
        planned = stretch["planned_s"]
        stretch_flown = stretch["max_s"] if planned is None else planned
    leg = fly_mission(Flyer(mission, points=points_per_step, record=True), stretch_flown)
    sim = leg_simulation(mission, leg)
    ended_by = sim.ended_by
    completed = ended_by in ("end", "reserve")
    cutoff_time = sim.duration_s if ended_by in ("cutoff", "power limit") else float("nan")
    reserve_time = _crossing_time(sim, mission.reserve_charge_Ah)
    flight_time = sim.duration_s
    endurance = flight_time
    if stretch is not None and stretch["binding"] != "infeasible":
        endurance = flight_time - stretch_flown + stretch["max_s"]
    labels = leg.labels[:int(sim.step.max()) + 1]
    rows = _phase_table(mission, sim, labels)
    soc_end = float(100.0 * (1.0 - sim.charge_Ah[-1] / mission.capacity_Ah))
    warnings = list(mission.warnings)
    cannot = load_at_start(mission, leg, sim)
    if cannot is not None:
        cannot["message"] = cannot_deliver_text(mission, cannot)
        warnings.append(cannot["message"])
    elif not completed:
        where = _label_text(labels[-1])
        warnings.append(f"the mission does not complete: the {ended_by} is reached "
                        f"after {duration(flight_time)}, during '{where}'")
    elif soc_end < mission.reserve_pct - 1e-6:
        warnings.append(f"the flight ends at {soc_end:.1f} % state of charge, below the "
                        f"{mission.reserve_pct:g} % reserve (reached at {duration(reserve_time)})")
    if stretch is not None:
        if stretch["binding"] == "infeasible":
            warnings.append(f"even without '{stretch['phase']}' the mission cannot be completed "
                            f"within the reserve and cutoff")
        elif stretch["margin_s"] is not None and stretch["margin_s"] < 0:
            warnings.append(f"planned '{stretch['phase']}' of {duration(stretch['planned_s'])} "
                            f"is {duration(-stretch['margin_s'])} longer than the maximum "
                            f"{duration(stretch['max_s'])}")
    warnings += extrapolation_warnings(mission.battery, rows)
    result = MissionResult(
        mission=mission, simulation=sim, labels=labels, phases=rows,
        completed=completed, ended_by=ended_by, flight_time_s=flight_time,
        endurance_s=float(endurance), cutoff_time_s=cutoff_time, reserve_time_s=reserve_time,
        soc_end_pct=soc_end, min_voltage_V=float(np.min(sim.voltage_V)), stretch=stretch,
        warnings=warnings, cannot_deliver=cannot,
    )
    result.notes.extend(mission.notes)
    extra = mission.battery.extra
    if extra.get("logbook") and extra.get("note"):  # a logbook pack at today's health
        result.notes.append(str(extra["note"]))
    if draws:
        result.uncertainty = mission_uncertainty(mission, draws=draws, seed=seed,
                                                 progress=progress, nominal=result,
                                                 points_per_step=points_per_step)
        result.warnings += result.uncertainty.get("warnings", [])
    return result


def mission_summary(mission: Mission, *, points_per_step: int = POINTS_PER_PHASE) -> dict:
    """Scalar outcomes of a mission with the battery's own parameters (no time series).

    Returns ``endurance_s``, ``flight_time_s``, ``soc_end_pct``, ``completed`` and,
    with a stretch phase, ``max_stretch_s`` (see :func:`mission_outcomes`).
    """
    found = mission_outcomes(mission, points_per_step=points_per_step)
    out = {key: (bool(value[0]) if key == "completed" else
                 str(value[0]) if key == "binding" else float(value[0]))
           for key, value in found.items()}
    out.pop("binding", None)
    return out


# ---------------------------------------------------------------------------------------------
# The interval of a mission: parameter draws flown through it plus the model's own error
# ---------------------------------------------------------------------------------------------

def mission_extrapolation_ratio(battery: Battery, phase_rows: list[dict]) -> float:
    """Effective extrapolation ratio of a mission: the charge-weighted geometric mean of
    its phases' ratios (each phase at its mean cell current), so that
    ``s0 (1 + 0.8 ln r_eff)`` is the charge-weighted mean of the phases' model error.
    A mission that draws no charge (it cannot take off) gets its largest phase ratio."""
    weights, logs = [], []
    for row in phase_rows:
        current = row.get("mean_current_A")
        if current is None or not np.isfinite(current):
            continue
        charge = float(row.get("charge_Ah") or 0.0)
        weights.append(max(charge, 0.0))
        logs.append(math.log(battery.extrapolation_ratio(current / battery.strings_parallel)))
    if not logs:
        return 1.0
    if sum(weights) <= 0:
        return float(math.exp(max(logs)))
    return float(math.exp(np.average(logs, weights=weights)))


def _mission_samples(outcome: dict, rows: np.ndarray, factor: np.ndarray) -> dict:
    """Outcome samples with the model error: endurance times the factor, the extra time
    on the stretch phase, the charge used divided by it (the usable capacity scales)."""
    endurance = outcome["endurance_s"][rows]
    out = {"endurance_s": endurance * factor,
           "soc_end_pct": 100.0 - (100.0 - outcome["soc_end_pct"][rows]) / factor}
    if "max_stretch_s" in outcome:
        out["max_stretch_s"] = np.maximum(outcome["max_stretch_s"][rows]
                                          + endurance * (factor - 1.0), 0.0)
    return out


def mission_uncertainty(mission, *, draws: int = DEFAULT_DRAWS, seed: int = 0, level=0.95,
                        progress=None, nominal=None, points_per_step: int | None = None) -> dict:
    """95 % interval of a mission's endurance: parameter draws plus the model error.

    The draws are flown all at once through the engine
    (:func:`dischargelab.mission.mission_outcomes`, the longest stretch found per
    draw). Each draw's endurance is multiplied by ``exp(sigma z)`` with ``sigma``
    from :func:`model_error_sd` at the mission's effective extrapolation ratio
    (:func:`mission_extrapolation_ratio`); the longest stretch takes the same extra
    time, the state of charge at landing the same relative change of the usable
    capacity. Without parameter draws the interval is the model error alone.

    Parameters
    ----------
    mission : dischargelab.mission.Mission
    draws : int
        Covariance draws when the battery has no bootstrap refits (200-500 is plenty).
    seed : int
    level : float
        Coverage of the central interval.
    progress : callable, optional
        ``progress(done, total)``.
    nominal : MissionResult, optional
        Nominal result (flown here when not given).
    points_per_step : int, optional
        Engine time steps per phase.

    Returns
    -------
    dict
        ``available``, ``interval_includes``, ``model_error``, ``method``, ``draws``,
        ``accepted``, ``tried``, ``rejected``, ``rejected_fraction``, ``seed``, ``level``;
        for ``endurance_s``, ``soc_end_pct`` (and ``max_stretch_s``): ``nominal``,
        ``median``, ``low``, ``high``, ``std``; the same without the model error in
        ``parameters_only`` (with parameter draws); ``completed_fraction``,
        ``draws_not_completed`` and ``warnings``.
    """
    battery = mission.battery
    if nominal is None:
        nominal = run_mission(mission) if points_per_step is None else \
            run_mission(mission, points_per_step=points_per_step)
    error = model_error_info(battery, mission_extrapolation_ratio(battery, nominal.phases))
    nom = {"endurance_s": nominal.endurance_s, "soc_end_pct": nominal.soc_end_pct}
    if nominal.stretch is not None:
        nom["max_stretch_s"] = nominal.stretch["max_s"]
    out = {"available": True, "seed": int(seed), "level": level,
           "model_error": {k: v for k, v in error.items() if k != "label"}}
    params, info = parameter_draws(battery, draws, seed)
    outcome = None
    if params is not None:
        n = len(params["C_Ah"])
        if progress is not None:
            progress(0, n)
        try:
            outcome = mission_outcomes(mission, params, points_per_step=points_per_step)
        except SimulationError as exc:
            info = f"the parameter draws could not be flown: {exc}"
        if progress is not None:
            progress(n, n)
    if outcome is None:
        out.update(_mission_model_error_only(nom, nominal.completed, error, level, info))
        return out
    rows, factor = error_factors(n, error["relative_sd"], seed, error["dof"])
    samples = _mission_samples(outcome, rows, factor)
    alone = _mission_samples(outcome, np.arange(n), np.ones(n))
    not_completed = int(np.count_nonzero(~outcome["completed"]))
    out.update({"method": info["method"], "interval_includes": ["parameters", error["label"]],
                "draws": info["requested"], "accepted": info["accepted"], "tried": info["tried"],
                "rejected": info["rejected"], "rejected_fraction": info["rejected_fraction"],
                "completed_fraction": float(np.mean(outcome["completed"])),
                "draws_not_completed": not_completed})
    for key, values in samples.items():
        out[key] = spread(values, nom[key], level)
    out["parameters_only"] = {key: spread(values, nom[key], level)
                              for key, values in alone.items()}
    warnings = list(info["warnings"])
    if 0 < not_completed < n and out["completed_fraction"] < 0.975:
        warnings.append(f"in {100 * (1 - out['completed_fraction']):.1f} % of the parameter "
                        f"draws the mission does not complete")
    out["warnings"] = warnings
    return out


def _mission_model_error_only(nom: dict, completed: bool, error: dict, level: float,
                              reason: str) -> dict:
    sd = error["relative_sd"]
    out = {"method": f"model error only: {reason}", "interval_includes": [error["label"]],
           "draws": 0, "accepted": 0, "tried": 0, "rejected": 0, "rejected_fraction": 0.0,
           "completed_fraction": 1.0 if completed else 0.0, "draws_not_completed": 0,
           "warnings": []}
    out["endurance_s"] = lognormal_spread(nom["endurance_s"], sd, level, error["dof"])
    z = z_level(level, error["dof"])
    factors = np.array([math.exp(-z * sd), 1.0, math.exp(z * sd)])
    used = 100.0 - nom["soc_end_pct"]
    soc = 100.0 - used / factors
    out["soc_end_pct"] = {"nominal": float(nom["soc_end_pct"]), "median": float(soc[1]),
                          "low": float(soc[0]), "high": float(soc[2]),
                          "std": float(used * sd)}
    if "max_stretch_s" in nom:
        stretch = np.maximum(nom["max_stretch_s"] + nom["endurance_s"] * (factors - 1.0), 0.0)
        out["max_stretch_s"] = {"nominal": float(nom["max_stretch_s"]),
                                "median": float(stretch[1]), "low": float(stretch[0]),
                                "high": float(stretch[2]), "std": float(nom["endurance_s"] * sd)}
    return out
