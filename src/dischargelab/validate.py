"""Validate a battery model against measured discharges it was not fitted to.

For each measured discharge the model is driven with the measured current
through the one engine (:func:`dischargelab.simulate.simulate`): its mean when
the current is constant, otherwise the logged profile itself as one engine
``Step("profile", ...)`` (each sample's current held over the interval ending
at it), continued at the last measured current if the profile ends before the
cutoff. Thermal families simulate the cell temperature from the run's ambient:
its first logged temperature when there is one, else the battery's
``ambient_C``. Every model family works. We report, as in the paper's section
4.4 (Figs 12-14), and beyond it:

* the measured and the predicted time to the cutoff voltage, and the endurance
  error in seconds and in percent of the measured time;
* the 95 % interval of the predicted time (parameter draws and the model's own
  error, :func:`dischargelab.uncertainty.prediction_interval`), whether it
  covered the measured time, and the coverage over all runs (:func:`summarise`):
  about 95 % of held-out runs should be covered if the intervals are honest;
* the voltage error in percent of the measured voltage, RMS and maximum, over
  the whole curve and over its operational part (state of charge above 20 %,
  counted on the charge the measurement delivered to the cutoff).

The measured time to cutoff is interpolated linearly at the first crossing of
the cutoff voltage. A measurement that never reaches the cutoff has no
endurance error and no coverage verdict (``None``) and a warning.

References
----------
.. [1] paper section 4.4 and Figs 12-14 (see ``../shared/paper``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .discharge import measured_time_to_cutoff
from .errors import DataError
from .model import Battery, charge_from_current, load_battery
from .simulate import SimulationResult, Step, simulate
from .uncertainty import DEFAULT_DRAWS, prediction_interval

#: Relative spread of the current (std / mean) below which a discharge is treated as constant.
CONSTANT_CURRENT_CV = 0.03

#: Operational part of a curve: state of charge above this fraction (paper 4.4).
OPERATIONAL_SOC = 0.20

#: Consecutive profile samples whose currents differ less than this fraction of the
#: mean current are merged into one load step.
PROFILE_MERGE_FRACTION = 0.01

#: Logged profiles longer than this are flown merged (:func:`profile_steps`); shorter
#: ones sample by sample (one engine step per sample).
MAX_PROFILE_SAMPLES = 5000

#: Engine time steps of a constant-current prediction to the cutoff.
PREDICTION_STEPS = 200


#: Under a varying load the pack has reached the cutoff when its voltage stays at or
#: below it this long [s]: ArduPilot's default low-battery timer (``BATT_LOW_TIMER``
#: = 10 s), which keeps a sag at a current peak from ending the flight.
LOW_VOLTAGE_TIMER_S = 10.0


def _is_constant(current: np.ndarray) -> bool:
    mean = float(np.mean(current))
    return mean > 0 and float(np.std(current)) <= CONSTANT_CURRENT_CV * mean


def profile_steps(time_s, current_A, *, merge_fraction: float = PROFILE_MERGE_FRACTION):
    """Load steps reproducing a measured current profile.

    Each interval between samples carries the trapezoidal mean of its end
    currents (so the charge equals :func:`~dischargelab.model.charge_from_current`);
    neighbouring intervals closer than ``merge_fraction`` of the mean current are
    merged with their charge-weighted mean. Charging intervals (negative current)
    become rests.

    Returns
    -------
    steps : list of Step
    ends_s : numpy.ndarray
        End time of each step [s] from the first sample.
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    dt = np.diff(t)
    mid = np.clip(0.5 * (i[1:] + i[:-1]), 0.0, None)
    tol = merge_fraction * max(float(np.mean(np.abs(i))), 1e-9)
    steps, ends = [], []
    charge, duration = 0.0, 0.0
    for k in range(dt.size):
        if duration > 0 and abs(mid[k] - charge / duration) > tol:
            steps.append(_step(charge / duration, duration))
            ends.append(t[k] - t[0])
            charge, duration = 0.0, 0.0
        charge += mid[k] * dt[k]
        duration += dt[k]
    if duration > 0:
        steps.append(_step(charge / duration, duration))
        ends.append(t[-1] - t[0])
    return steps, np.asarray(ends)


def _step(current, duration):
    if current <= 0:
        return Step("rest", 0.0, float(duration))
    return Step("current", float(current), float(duration))


@dataclass
class ValidationCase:
    """One measured discharge against its prediction.

    Attributes
    ----------
    summary : dict
        The JSON row (see :func:`validate_discharge`).
    time_s, voltage_measured_V, current_A : numpy.ndarray
        The measurement (time from load start).
    voltage_predicted_V : numpy.ndarray
        Prediction at the measured times (NaN after the predicted cutoff).
    prediction : SimulationResult
        The simulated discharge (to the predicted cutoff).
    """

    summary: dict
    time_s: np.ndarray
    voltage_measured_V: np.ndarray
    voltage_predicted_V: np.ndarray
    prediction: SimulationResult = field(repr=False)
    current_A: np.ndarray = field(default=None, repr=False)

    @property
    def label(self) -> str:
        """Short label: file name and current."""
        s = self.summary
        return f"{Path(s['file']).name} ({s['current_A']:.3g} A)"

    def to_dict(self) -> dict:
        """The JSON row (``validate --json``): errors, coverage, interval, warnings."""
        return dict(self.summary)

    def to_pandas(self):
        """Measured and predicted voltage [V] and the current [A] against time [s]."""
        import pandas as pd

        frame = {"time_s": self.time_s, "voltage_measured_V": self.voltage_measured_V,
                 "voltage_predicted_V": self.voltage_predicted_V}
        if self.current_A is not None:
            frame["current_A"] = self.current_A
        return pd.DataFrame(frame)

    def plot(self, ax=None, **kwargs):
        """Measured and predicted voltage; returns the Axes."""
        from .plot import plot_validation

        return plot_validation([self], ax=ax, **kwargs)


def _same_file(a, b) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, TypeError, ValueError):
        return False


def _same_step(fitted: dict, meta: dict) -> bool:
    """The same step of a tester's file (True for files without steps)."""
    a, b = fitted.get("step"), meta.get("step")
    if isinstance(a, dict) and isinstance(b, dict):
        return a.get("number") == b.get("number")
    return True


def _run_ambient_C(battery: Battery, data) -> float:
    """Ambient of a run [degC]: its first logged temperature, else the battery's."""
    if "temperature_C" in data:
        temp = np.asarray(data["temperature_C"], dtype=float)
        finite = temp[np.isfinite(temp)]
        if finite.size:
            return float(finite[0])
    return battery.ambient_C


def _increasing(t: np.ndarray) -> np.ndarray:
    """Mask of the samples whose time is above every earlier one (duplicates dropped)."""
    before = np.maximum.accumulate(np.r_[-np.inf, t[:-1]])
    return t > before


def logged_profile_step(time_s, current_A) -> Step:
    """One engine step flying a logged current profile (time from 0 at the first sample).

    Sample ``k``'s current is held over ``(t[k-1], t[k]]``; charging samples
    (negative current) are flown as rest; repeated time stamps are dropped.
    Profiles longer than :data:`MAX_PROFILE_SAMPLES` are merged first
    (:func:`profile_steps`).
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    keep = _increasing(t)
    t, i = t[keep], i[keep]
    if t.size > MAX_PROFILE_SAMPLES:
        steps, ends = profile_steps(t, i)
        t = np.r_[0.0, ends]
        i = np.r_[0.0, [st.value for st in steps]]
    return Step("profile", name="measured profile", profile_time_s=tuple(t - t[0]),
                profile_current_A=tuple(np.clip(i, 0.0, None)))


def _constant_current_voltage(battery: Battery, prediction: SimulationResult, t, current_A):
    """Model pack voltage [V] at times ``t`` [s] of a constant-current discharge from rest.

    The states are exact for a constant current (charge linear in time, lowpass
    states ``i (1 - exp(-t / tau))``); a thermal state is taken from the simulation.
    """
    fam, prm = battery.family, battery.parameters
    cell = current_A / battery.strings_parallel
    state = {}
    for st in fam.states:
        if st.kind == "charge":
            state[st.name] = cell * t / 3600.0
        elif st.kind == "lowpass":
            tau = float(st.time_constant(prm))
            state[st.name] = cell * (1.0 - np.exp(-t / tau)) if tau > 0 else np.full(t.size, cell)
        else:
            state[st.name] = np.interp(t, prediction.time_s, prediction.temperature_C)
    with np.errstate(invalid="ignore", over="ignore"):
        return battery.cells_series * fam.voltage(prm, state, cell)


def _initial_charge(battery: Battery, meta: dict) -> tuple[float, str | None]:
    """(pack charge already taken out at the start [Ah], a note or None).

    A flight from a flight log need not start full, nor a tester's discharge step
    that does not follow a charge (``meta["starts_full"]`` False): its charge comes
    from the rest voltage just before the load through the model's own
    open-circuit voltage (:func:`dischargelab.ocv.model_charge_at_rest`). Bench
    discharges start full.
    """
    rest = meta.get("rest_sample")
    partial = meta.get("flight") is not None or meta.get("starts_full") is False
    if not partial or not isinstance(rest, dict) or rest.get("voltage_V") is None:
        return 0.0, None
    from .ocv import model_charge_at_rest

    charge = model_charge_at_rest(battery, float(rest["voltage_V"]),
                                  float(rest.get("current_A") or 0.0))
    soc = 100.0 * (1.0 - charge / battery.capacity_Ah)
    what, when = ("flight", "take-off") if meta.get("flight") is not None else \
        ("discharge", "the load")
    return charge, (f"the {what} starts at {soc:.0f} % of the model's charge ({charge:.3g} Ah "
                    f"out), from the rest voltage {rest['voltage_V']:.2f} V before {when}")


def _predict_run(battery: Battery, t, i, inside, cutoff_pack: float, ambient: float,
                 initial_charge_Ah: float = 0.0, engine_cutoff_pack: float | None = None):
    """(steps, prediction, predicted voltage at the samples, profile label, mean current
    [A], warnings) of one measured run, starting ``initial_charge_Ah`` [Ah] down. A
    measured profile is flown down to ``engine_cutoff_pack`` [V] (default the cutoff)."""
    constant = _is_constant(i[inside]) and initial_charge_Ah == 0.0
    mean_current = float(np.trapezoid(i[inside], t[inside]) / max(t[inside][-1], 1e-12)) \
        if inside.sum() > 1 else float(i[0])
    warnings = []
    if constant:
        steps = [Step("current", mean_current, None, "constant current")]
        prediction = simulate(battery, steps, cutoff_pack_V=cutoff_pack, ambient_C=ambient,
                              points_per_step=PREDICTION_STEPS)
        return steps, prediction, _constant_current_voltage(battery, prediction, t,
                                                            mean_current), \
            "constant", mean_current, warnings
    steps = [logged_profile_step(t, i)]
    tail = t >= t[-1] - min(60.0, 0.1 * t[-1])
    tail_current = float(np.mean(np.clip(i[tail], 0, None)))
    if tail_current > 0:
        steps.append(Step("current", tail_current, None, "extension"))
    prediction = simulate(battery, steps, cutoff_pack_V=engine_cutoff_pack or cutoff_pack,
                          ambient_C=ambient, points_per_step=PREDICTION_STEPS,
                          initial_charge_Ah=initial_charge_Ah)
    if prediction.ended_by == "cutoff" and tail_current > 0 and \
            prediction.step[-1] == len(steps) - 1:
        warnings.append(f"the prediction reaches the cutoff after the measured profile "
                        f"ends; it was extended at the last measured {tail_current:.3g} A")
    # the engine stops at every logged sample: its voltage there is the model's, with the
    # sample's own current and every state (charge, temperature, filters) as flown
    first = np.r_[True, np.diff(prediction.time_s) > 0]
    v_pred = np.interp(t, prediction.time_s[first], prediction.voltage_V[first])
    return steps, prediction, v_pred, "measured", mean_current, warnings


def compare_discharge(battery, data, meta: dict | None, cutoff_cell_V: float, *,
                      draws: int = DEFAULT_DRAWS, seed: int = 0, level: float = 0.95,
                      low_timer_s: float | None = None) -> ValidationCase:
    """Predict one measured discharge; see :func:`validate_discharge` for the numbers.

    ``low_timer_s`` [s]: the cutoff is reached when the voltage stays under it this
    long, for the measurement and the prediction alike (default
    :data:`LOW_VOLTAGE_TIMER_S` under a varying current, where current peaks dip
    under the cutoff long before the pack is empty; 0, the first crossing, under a
    constant current).
    """
    battery = load_battery(battery)
    meta = dict(meta or {})
    for col in ("time_s", "voltage_V", "current_A"):
        if col not in data:
            raise DataError(f"measured data has no {col} column (files without a current "
                            f"column need --current A)")
    t = np.asarray(data["time_s"], dtype=float)
    v = np.asarray(data["voltage_V"], dtype=float)
    i = np.asarray(data["current_A"], dtype=float)
    name = str(meta.get("source") or meta.get("name") or "data")
    if isinstance(meta.get("step"), dict):  # one step of a battery tester's file
        name = f"{name} step {meta['step']['number']}"
    if t.size < 3:
        raise DataError(f"{name}: only {t.size} samples; nothing to validate")
    if not (np.isfinite(cutoff_cell_V) and cutoff_cell_V > 0):
        raise DataError(f"cutoff voltage must be > 0 V per cell, got {cutoff_cell_V}")
    t = t - t[0]
    cutoff_pack = cutoff_cell_V * battery.cells_series
    if v[0] <= cutoff_pack:
        raise DataError(f"{Path(name).name}: the measurement starts at {v[0]:.3f} V, at or "
                        f"below the cutoff {cutoff_pack:.3f} V; check --cutoff and the pack's "
                        f"cells in series ({battery.cells_series})")
    first = measured_time_to_cutoff(t, v, cutoff_pack)
    varying = not _is_constant(i[t <= first] if np.isfinite(first) else i)
    hold = (LOW_VOLTAGE_TIMER_S if varying else 0.0) if low_timer_s is None \
        else float(low_timer_s)
    if not hold >= 0:
        raise DataError(f"low_timer_s must be 0 or more seconds, got {low_timer_s}")
    t_meas = measured_time_to_cutoff(t, v, cutoff_pack, hold)
    reached = np.isfinite(t_meas)
    t_end = t_meas if reached else float(t[-1])
    warnings = []
    if not reached:
        warnings.append(f"the measurement ends at {v[-1]:.3f} V without reaching the cutoff "
                        f"{cutoff_pack:.3f} V; no endurance error")
    inside = t <= t_end
    q_meas = charge_from_current(t, i)
    q_total = float(np.interp(t_end, t, q_meas))
    ambient = _run_ambient_C(battery, data)
    initial, start_note = _initial_charge(battery, meta)
    steps, prediction, v_pred, profile, mean_current, more = _predict_run(
        battery, t, i, inside, cutoff_pack, ambient, initial,
        engine_cutoff_pack=0.5 * cutoff_pack if hold > 0 else None)
    warnings += more
    t_pred = prediction.time_to_cutoff_s
    stretch = 1.0  # the draws are flown to the first crossing: their spread is carried over
    if hold > 0 and profile == "measured":
        t_first = measured_time_to_cutoff(prediction.time_s, prediction.voltage_V, cutoff_pack)
        t_pred = measured_time_to_cutoff(prediction.time_s, prediction.voltage_V, cutoff_pack,
                                         hold)
        if np.isfinite(t_pred) and np.isfinite(t_first) and t_first > 0:
            stretch = t_pred / t_first
    v_pred = np.where(t <= (t_pred if np.isfinite(t_pred) else np.inf), v_pred, np.nan)
    compare = inside & np.isfinite(v_pred) & (v > 0)
    rel = (v_pred[compare] - v[compare]) / v[compare] * 100.0
    soc = 1.0 - q_meas / q_total if q_total > 0 else np.ones_like(q_meas)
    operational = compare & (soc > OPERATIONAL_SOC)
    rel_op = (v_pred[operational] - v[operational]) / v[operational] * 100.0
    q_pred = float(np.interp(t_pred, prediction.time_s, prediction.charge_Ah)) \
        - initial if np.isfinite(t_pred) else prediction.capacity_Ah
    spread = prediction_interval(
        battery, steps, nominal={"time_to_cutoff_s": t_pred / stretch, "capacity_Ah": q_pred,
                                 "energy_Wh": prediction.energy_Wh_total},
        cutoff_pack_V=cutoff_pack, cell_current_A=mean_current / battery.strings_parallel,
        initial_charge_Ah=initial, ambient_C=ambient, draws=draws, seed=seed, level=level)
    warnings += spread["warnings"]
    lo, hi = (stretch * x for x in spread["time_to_cutoff_s"])
    covered = bool(lo <= t_meas <= hi) if reached and np.isfinite(lo) else None

    def rms(x):
        return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")

    def peak(x):
        return float(np.max(np.abs(x))) if x.size else float("nan")

    error_s = t_pred - t_meas if reached else float("nan")
    summary = {
        "file": name,
        "model": battery.model,
        "current_A": mean_current,
        "cell_current_A": mean_current / battery.strings_parallel,
        "profile": profile,
        "cutoff_cell_V": float(cutoff_cell_V),
        "cutoff_pack_V": float(cutoff_pack),
        "endurance_measured_s": t_meas if reached else None,
        "endurance_predicted_s": t_pred if np.isfinite(t_pred) else None,
        "endurance_error_s": error_s if np.isfinite(error_s) else None,
        "endurance_error_pct": 100.0 * error_s / t_meas if reached and t_meas > 0 and
        np.isfinite(error_s) else None,
        "interval_s": [lo, hi] if np.isfinite(lo) else None,
        "interval_level": level,
        "covered": covered,
        "interval_includes": spread["interval_includes"],
        "draws_not_reaching_cutoff": spread["draws_not_reaching_cutoff"],
        "capacity_measured_Ah": q_total if reached else None,
        "capacity_predicted_Ah": q_pred,
        "low_timer_s": hold,
        "voltage_rmse_pct": rms(rel),
        "voltage_max_error_pct": peak(rel),
        "voltage_mean_error_pct": float(np.mean(rel)) if rel.size else float("nan"),
        "voltage_rmse_operational_pct": rms(rel_op),
        "voltage_max_error_operational_pct": peak(rel_op),
        "voltage_rmse_V": rms(v_pred[compare] - v[compare]),
        "compared_until_s": float(t[compare][-1]) if compare.any() else None,
        "n_compared": int(compare.sum()),
        "in_fit": None,
        "extrapolation": None,
        "warnings": warnings,
        "initial_charge_Ah": initial,
        "notes": [start_note] if start_note else [],
    }
    if battery.family.thermal:
        summary["ambient_C"] = ambient
        summary["peak_temperature_C"] = prediction.peak_temperature_C
    sources = battery.extra.get("source")
    if isinstance(sources, list) and meta.get("source"):
        summary["in_fit"] = any(isinstance(s, dict) and _same_file(s.get("source"),
                                                                     meta["source"])
                                and _same_step(s, meta) for s in sources)
        if summary["in_fit"]:
            warnings.append("this file was used in the fit: not an independent validation")
    if any(battery.fit_currents_A):
        from .predict import extrapolation_warning

        cell = summary["cell_current_A"]
        side = battery.extrapolation(cell)
        summary["extrapolation"] = side is not None
        if side:
            warnings.append(extrapolation_warning(battery, cell, side))
    return ValidationCase(summary=summary, time_s=t, voltage_measured_V=v,
                          voltage_predicted_V=v_pred, prediction=prediction, current_A=i)


def input_warnings(battery: Battery, loaded, cases, cutoff_cell_V: float, *,
                   options: dict | None = None) -> list:
    """Check the inputs against each other and add each finding to its case's warnings:
    a given current against the file's duration and the battery's capacity
    (:func:`dischargelab.plausibility.check_given_current`), the battery's cells and
    chemistry against each file's voltages, and the cutoff against the chemistry.

    ``loaded`` are the ``(frame, meta)`` pairs the ``cases`` were made from, in order;
    ``options`` names arguments as command-line options in the fixes (see
    :meth:`dischargelab.plausibility.Finding.text`).
    Returns the findings."""
    from dataclasses import replace

    from .plausibility import check_cutoff, check_discharge, check_given_current

    found = check_given_current(loaded, capacity_Ah=battery.capacity_Ah,
                                cutoff_pack_V=cutoff_cell_V * battery.cells_series)
    for frame, meta in loaded:
        found += [f for f in check_discharge(frame, meta, cells_series=battery.cells_series,
                                             strings_parallel=battery.strings_parallel,
                                             chemistry=battery.chemistry)
                  if f.check in ("cell_count", "cell_voltage")]
    for finding in found:
        text = replace(finding, source="").text(options)
        for case in cases:
            if Path(str(case.summary.get("file", ""))).name == finding.source:
                case.summary["warnings"].append(text)
    cut = check_cutoff(cutoff_cell_V, battery.chemistry)
    for finding in cut:
        for case in cases:
            case.summary["warnings"].append(finding.text(options))
    return found + cut


def validate_discharge(battery, data, meta: dict | None, cutoff_cell_V: float, *,
                       draws: int = DEFAULT_DRAWS, seed: int = 0) -> dict:
    """Endurance and voltage errors of the model on one measured discharge.

    Parameters
    ----------
    battery : Battery, preset name or battery-file path
        The pack the measurement was made on (cells in series / parallel).
    data : pandas.DataFrame or mapping
        Canonical columns ``time_s`` (from load start), ``voltage_V`` (pack),
        ``current_A`` (pack, discharge positive), optionally ``temperature_C``
        (its first value is the run's ambient for thermal families), e.g. from
        :func:`dischargelab.io.read_discharge`.
    meta : dict
        Reader metadata (``source`` names the file).
    cutoff_cell_V : float
        Cutoff voltage per cell [V].
    draws, seed : int
        Covariance draws (when the battery has no bootstrap refits) and seed of
        the 95 % interval.

    Returns
    -------
    dict
        ``file``, ``current_A`` (mean), ``endurance_measured_s``,
        ``endurance_predicted_s``, ``endurance_error_pct`` (100 (pred - meas) / meas),
        ``interval_s`` (95 % interval of the predicted time [s]), ``covered``
        (measured time inside it), ``interval_includes``, ``voltage_rmse_pct``,
        ``voltage_max_error_pct`` (over the compared curve), plus
        ``endurance_error_s``, ``voltage_*_operational_pct`` (SOC > 20 %),
        ``capacity_measured_Ah``, ``capacity_predicted_Ah``, ``profile``
        ("constant" | "measured"), ``low_timer_s`` (how long the voltage stayed
        under the cutoff to count, see :func:`compare_discharge`),
        ``initial_charge_Ah`` (a flight log's flight: from the rest voltage before
        take-off), ``notes``, ``in_fit``, ``extrapolation``, ``warnings``
        (and ``ambient_C``, ``peak_temperature_C`` for thermal families).
        Endurance keys and ``covered`` are None when the measurement never reaches
        the cutoff.
    """
    return compare_discharge(battery, data, meta, cutoff_cell_V, draws=draws, seed=seed).summary


def compare_files(battery, paths, *, cutoff_cell_V: float, columns=None, current_A=None,
                  progress=None, draws: int = DEFAULT_DRAWS, seed: int = 0,
                  **read_options) -> list[ValidationCase]:
    """Read each file with :func:`dischargelab.io.read_discharge` and compare it."""
    from .io import read_discharge

    battery = load_battery(battery)
    paths = list(paths)
    if not paths:
        raise DataError("no measured files to validate against")
    cases, loaded = [], []
    for k, path in enumerate(paths):
        data, meta = read_discharge(path, columns=columns, current_A=current_A, **read_options)
        loaded.append((data, meta))
        cases.append(compare_discharge(battery, data, meta, cutoff_cell_V, draws=draws,
                                       seed=seed))
        if progress is not None:
            progress(k + 1, len(paths))
    input_warnings(battery, loaded, cases, cutoff_cell_V)
    return cases


def validate_files(battery, paths, *, cutoff_cell_V: float, columns=None, current_A=None,
                   draws: int = DEFAULT_DRAWS, seed: int = 0, **read_options) -> list[dict]:
    """:func:`validate_discharge` for each file (read with ``read_discharge``)."""
    return [c.summary for c in compare_files(battery, paths, cutoff_cell_V=cutoff_cell_V,
                                             columns=columns, current_A=current_A,
                                             draws=draws, seed=seed, **read_options)]


def coverage(rows: list[dict]) -> dict:
    """How many measured times to cutoff fell inside their predicted interval.

    Returns
    -------
    dict
        ``covered`` (count), ``runs`` (runs with a measured time and an interval),
        ``fraction`` (None without runs) and ``level`` (nominal coverage).
    """
    judged = [r["covered"] for r in rows if r.get("covered") is not None]
    levels = {r.get("interval_level") for r in rows if r.get("covered") is not None}
    return {"covered": int(sum(judged)), "runs": len(judged),
            "fraction": sum(judged) / len(judged) if judged else None,
            "level": levels.pop() if len(levels) == 1 else None}


def summarise(rows: list[dict]) -> dict:
    """Mean absolute endurance error [%], worst voltage errors and interval coverage."""
    errors = [abs(r["endurance_error_pct"]) for r in rows if r["endurance_error_pct"] is not None]
    rmse = [r["voltage_rmse_pct"] for r in rows if np.isfinite(r["voltage_rmse_pct"])]
    peak_op = [r["voltage_max_error_operational_pct"] for r in rows
               if np.isfinite(r["voltage_max_error_operational_pct"])]
    return {
        "files": len(rows),
        "mean_abs_endurance_error_pct": float(np.mean(errors)) if errors else None,
        "max_abs_endurance_error_pct": float(np.max(errors)) if errors else None,
        "max_voltage_rmse_pct": float(np.max(rmse)) if rmse else None,
        "max_voltage_error_operational_pct": float(np.max(peak_op)) if peak_op else None,
        "coverage": coverage(rows),
    }


__all__ = ["validate_discharge", "validate_files", "compare_discharge", "compare_files",
           "ValidationCase", "measured_time_to_cutoff", "profile_steps", "logged_profile_step",
           "summarise", "coverage"]
