"""A battery model flown through a logged flight, and the remaining flight time
replayed every few seconds next to the autopilots' own estimates."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..errors import SimulationError
from ..models.base import HELD_AT_AMBIENT_HEAT_CAPACITY
from ..ocv import model_charge_at_rest
from .samples import FlightSamples, Settings, log_remaining_at, trapezoid

#: Replay the remaining flight time every this many seconds [s].
REPLAY_EVERY_S = 5.0


#: The recent load of the replay: mean current over the last this many seconds [s]
#: (since the load started, early in a flight).
RECENT_LOAD_S = 30.0


#: Below this recent mean current [A] no remaining time is replayed (on the ground).
MIN_REPLAY_CURRENT_A = 0.5


#: PX4 voltage-based estimate (defaults of PX4 v1.14 [4]_): empty and full cell
#: voltage [V] and internal resistance per cell [ohm] for the load compensation.
PX4_V_EMPTY = 3.6


PX4_V_CHARGED = 4.05


PX4_R_INTERNAL_OHM = 0.005


#: Window of the voltage and current the PX4-style estimate reads [s] (its filter).
PX4_VOLTAGE_WINDOW_S = 1.0


def _engine_params(bat) -> dict:
    params = {n: float(bat.parameters[n]) for n in bat.family.names}
    if bat.family.thermal and "fit_temperature_rise_K" not in bat.extra \
            and "thermal_prior" not in bat.extra:
        params["Cth_J_per_K"] = HELD_AT_AMBIENT_HEAT_CAPACITY
    return params


def _initial_model_charge(part: FlightSamples, series, bat, notes: list) -> tuple[float, str]:
    rest = part.rest_before
    if rest is not None:
        # at the idle current the pack sat at, as validate reads the same rest sample
        return model_charge_at_rest(bat, rest.voltage_V, rest.current_A), \
            (f"rest voltage {rest.voltage_V:.3f} V at {rest.current_A:.2f} A before take-off "
             f"through the model")
    remaining = log_remaining_at(series, part.frame["time_s"].iloc[0])
    if remaining is not None:
        return (1.0 - remaining) * bat.capacity_Ah, \
            "the log's own state-of-charge estimate at the first sample"
    frame = part.frame
    q0 = model_charge_at_rest(bat, float(frame["voltage_V"].iloc[0]),
                              float(frame["current_A"].iloc[0]))
    notes.append("initial charge from the first loaded sample through the model (its RC pairs "
                 "assumed settled at that current): no rest voltage before the flight")
    return q0, "first loaded sample through the model"


def fly_model(part: FlightSamples, series, s: Settings, bat, notes: list):
    """Predicted pack voltage at every sample, the model summary and the states at replay
    moments (``{sample index: engine state}``)."""
    from ..engine import Step, run

    frame = part.frame
    t = frame["time_s"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    v = frame["voltage_V"].to_numpy(dtype=float)
    q0, source = _initial_model_charge(part, series, bat, notes)
    params = _engine_params(bat)
    moments = set(_replay_rows(part, s))
    cuts = sorted(moments | {t.size - 1})
    predicted = np.full(t.size, np.nan)
    with np.errstate(invalid="ignore", over="ignore"):
        predicted[0] = float(bat.voltage(i[0], q0))
    states, state, prev = {}, None, 0
    for k in cuts:
        if k <= prev:
            continue
        step = Step("profile", profile_time_s=tuple(t[prev + 1:k + 1] - t[prev]),
                    profile_current_A=tuple(i[prev + 1:k + 1]))
        res = run(bat.family, params, [step], cutoff_pack_V=0.0, cells_series=bat.cells_series,
                  strings_parallel=bat.strings_parallel, ambient_C=bat.ambient_C,
                  initial_charge_Ah=q0, initial_state=state, record=True)
        rec_t = res.series["time_s"]
        idx = np.clip(np.searchsorted(rec_t, t[prev + 1:k + 1] - t[prev] + 1e-9, "right") - 1,
                      0, rec_t.size - 1)
        predicted[prev + 1:k + 1] = res.series["voltage_V"][idx]
        state = {name: np.asarray(value).copy() for name, value in res.final_state.items()}
        if res.ended_by[0] != "end":
            predicted[prev + 1:k + 1][rec_t[idx] + t[prev] < t[prev + 1:k + 1] - 1e-6] = np.nan
            notes.append(f"the model empties at {t[prev] + float(res.end_s[0]):.1f} s (its "
                         "capacity is reached under this load): no prediction after it")
            break
        states[k] = state
        prev = k
    inside = part.in_flight & np.isfinite(predicted)
    err = predicted[inside] - v[inside]
    summary = {"initial_charge_model_Ah": q0, "initial_charge_model_source": source,
               "soc_start_model": 1.0 - q0 / bat.capacity_Ah,
               "rmse_V": float(np.sqrt(np.mean(err ** 2))) if err.size else None,
               "rmse_cell_V": None, "max_error_V": float(np.max(np.abs(err))) if err.size
               else None}
    cells = [c for c in frame.columns if c.startswith("cell") and c.endswith("_V")]
    if cells and err.size:
        per_cell = predicted[inside] / s.cells
        rmse = []
        for c in cells:  # masked (glitched) cell samples are NaN: left out
            diff = per_cell - frame[c].to_numpy(dtype=float)[inside]
            diff = diff[np.isfinite(diff)]
            rmse.append(float(np.sqrt(np.mean(diff ** 2))) if diff.size else None)
        summary["rmse_cell_V"] = rmse
    last = max(states) if states else None
    if last is not None:
        q_end = float(states[last]["charge_Ah"][0]) * bat.strings_parallel
        summary["charge_left_model_Ah"] = bat.capacity_Ah - q_end
    return predicted, summary, states


def _replay_rows(part: FlightSamples, s: Settings) -> list[int]:
    """Sample indices of the replay moments: every ``replay_every_s`` during the load."""
    if part.load_start_s is None or part.load_end_s is None:
        return []
    t = part.frame["time_s"].to_numpy(dtype=float)
    moments = np.arange(part.load_start_s + s.replay_every_s, part.load_end_s + 1e-9,
                        s.replay_every_s)
    rows = np.searchsorted(t, moments, side="left")
    return sorted({int(k) for k in rows if k < t.size})


#: Most replay moments at which the recent load profile is flown (each one flies the
#: profile bin by bin until the pack is empty): spread over the flight, mid-flight included.
MAX_PROFILE_REPLAYS = 12


def _profile_rows(rows: list[int], t, part: FlightSamples) -> set[int]:
    """The replay rows that also get the repeated-profile replay."""
    if not rows:
        return set()
    stride = int(np.ceil(len(rows) / MAX_PROFILE_REPLAYS))
    chosen = set(rows[::stride])
    if part.load_start_s is not None and part.load_end_s is not None:
        middle = 0.5 * (part.load_start_s + part.load_end_s)
        chosen.add(min(rows, key=lambda k: abs(t[k] - middle)))
    return chosen


def _recent_current(t, i, k: int, window_s: float) -> float:
    """Mean current [A] over the ``window_s`` up to sample ``k`` (trapezoid)."""
    sel = (t >= t[k] - window_s) & (t <= t[k])
    if sel.sum() < 2:
        return float(i[k])
    return trapezoid(i[sel], t[sel]) / float(t[sel][-1] - t[sel][0])


def replay_remaining(part: FlightSamples, series, s: Settings, bat, states: dict,
            predicted) -> pd.DataFrame:
    """Remaining flight time at each replay moment by the model and the autopilots' methods."""
    frame = part.frame
    t = frame["time_s"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    v = frame["voltage_V"].to_numpy(dtype=float)
    inside = part.in_flight
    rows = _replay_rows(part, s)
    ok = inside & (np.isfinite(predicted) if predicted is not None else False)
    consumed = _consumed_Ah(series)
    profiled = _profile_rows(rows, t, part)
    out = []
    for k in rows:
        load = _recent_current(t, i, k, min(s.recent_load_s, t[k] - part.load_start_s))
        after = t >= t[k]
        row = {"time_s": float(t[k]), "recent_current_A": load, "model_s": float("nan"),
               "model_profile_s": float("nan"),
               "model_logged_load_s": time_to(t[ok & after], None if predicted is None else
                                               predicted[ok & after], s.cutoff_pack_V, t[k],
                                               s.low_timer_s),
               "px4_s": float("nan"), "ardupilot_s": float("nan"),
               "true_s": time_to(t[inside & after], v[inside & after], s.cutoff_pack_V, t[k],
                                  s.low_timer_s),
               "first_dip_s": time_to(t[inside & after], v[inside & after], s.cutoff_pack_V,
                                       t[k], 0.0)}
        if load >= MIN_REPLAY_CURRENT_A:
            if bat is not None and k in states:
                row["model_s"] = _model_remaining(bat, states[k], load, s)
            if bat is not None and k in states and k in profiled:
                window = min(s.recent_load_s, t[k] - part.load_start_s)
                row["model_profile_s"] = _model_remaining_profile(
                    bat, states[k], t[(t >= t[k] - window) & (t <= t[k])],
                    i[(t >= t[k] - window) & (t <= t[k])], load, s)
            if s.capacity_Ah is not None:
                px4 = _px4_remaining_frac(series, frame, k, s)
                row["px4_s"] = px4 * s.capacity_Ah * 3600.0 / load
                left = max(s.capacity_Ah - consumed(t[k]), 0.0)
                row["ardupilot_s"] = left * 3600.0 / load
        out.append(row)
    columns = ["time_s", "recent_current_A", "model_s", "model_profile_s", "model_logged_load_s",
               "px4_s", "ardupilot_s", "true_s", "first_dip_s"]
    return pd.DataFrame(out, columns=columns)


#: Bin width [s] of the recent load profile the replay repeats (keeps its peaks).
PROFILE_BIN_S = 0.5


def _model_remaining_profile(bat, state: dict, t_window, i_window, load_A: float,
                             s: Settings) -> float:
    """Time [s] until the cutoff when the recent load profile repeats, peaks included.

    The last ``recent_load_s`` of logged current, averaged in :data:`PROFILE_BIN_S`
    bins, is flown again and again from the engine ``state`` (enough repetitions to
    empty the pack at its mean current, twice over, bounded), and the cutoff is
    reached as in the log: the voltage stays at or below it ``low_timer_s``. A pack
    whose cutoff is set by load peaks reaches it sooner than at the mean load.
    """
    from ..engine import Step, run

    if np.size(t_window) < 3 or not np.ptp(t_window) > PROFILE_BIN_S:
        return _model_remaining(bat, state, load_A, s)
    edges = np.arange(t_window[0], t_window[-1] + PROFILE_BIN_S, PROFILE_BIN_S)
    idx = np.clip(np.searchsorted(edges, t_window, side="right") - 1, 0, edges.size - 2)
    sums = np.bincount(idx, weights=i_window, minlength=edges.size - 1)
    counts = np.bincount(idx, minlength=edges.size - 1)
    binned = np.where(counts > 0, sums / np.maximum(counts, 1), load_A)
    period = binned.size * PROFILE_BIN_S
    left_Ah = float(bat.capacity_Ah) - float(state["charge_Ah"][0]) * bat.strings_parallel
    cycles = int(min(max(np.ceil(2.0 * left_Ah * 3600.0 / max(load_A, 1e-6) / period), 1), 2000))
    times = np.arange(binned.size * cycles) * PROFILE_BIN_S
    try:  # flown past the cutoff (to half of it) so that short dips can recover
        res = run(bat.family, _engine_params(bat),
                  [Step("profile", duration_s=float(times[-1] + PROFILE_BIN_S),
                        profile_time_s=tuple(times), profile_current_A=tuple(np.tile(binned,
                                                                                     cycles)))],
                  cutoff_pack_V=0.5 * s.cutoff_pack_V, cells_series=bat.cells_series,
                  strings_parallel=bat.strings_parallel, ambient_C=bat.ambient_C,
                  initial_state=state, record=True)
    except SimulationError:
        return float("nan")
    series = res.series
    return time_to(np.asarray(series["time_s"], dtype=float),
                    np.asarray(series["voltage_V"], dtype=float), s.cutoff_pack_V, 0.0,
                    s.low_timer_s)


def time_to(t, v, cutoff_V: float, now_s: float, hold_s: float = 0.0) -> float:
    """Time [s] from ``now_s`` until ``v`` goes to or below ``cutoff_V`` and stays there
    ``hold_s`` [s] (:func:`dischargelab.validate.measured_time_to_cutoff`; NaN if never)."""
    from ..validate import measured_time_to_cutoff

    if v is None or np.size(t) == 0:
        return float("nan")
    return measured_time_to_cutoff(t, v, cutoff_V, hold_s) - now_s


def _model_remaining(bat, state: dict, load_A: float, s: Settings) -> float:
    """Time [s] from the engine ``state`` at a constant ``load_A`` [A] until the cutoff."""
    from ..engine import Step, run

    try:
        res = run(bat.family, _engine_params(bat), [Step("current", load_A)],
                  cutoff_pack_V=s.cutoff_pack_V,
                  cells_series=bat.cells_series, strings_parallel=bat.strings_parallel,
                  ambient_C=bat.ambient_C, initial_state=state)
    except SimulationError:  # the model never reaches the cutoff at this load
        return float("nan")
    return float(res.end_s[0]) if res.ended_by[0] == "cutoff" else float("nan")


def _px4_remaining_frac(series, frame, k: int, s: Settings) -> float:
    """PX4-style remaining fraction: the log's ``remaining`` if logged, else from voltage."""
    t_k = float(frame["time_s"].iloc[k])
    logged = log_remaining_at(series, t_k)
    if logged is not None:
        return logged
    t = frame["time_s"].to_numpy(dtype=float)
    sel = (t > t_k - PX4_VOLTAGE_WINDOW_S) & (t <= t_k)
    volts = float(np.mean(frame["voltage_V"].to_numpy(dtype=float)[sel]))
    amps = float(np.mean(frame["current_A"].to_numpy(dtype=float)[sel]))
    cell = volts / s.cells + PX4_R_INTERNAL_OHM * amps
    return float(np.clip((cell - PX4_V_EMPTY) / (PX4_V_CHARGED - PX4_V_EMPTY), 0.0, 1.0))


def _consumed_Ah(series):
    """Charge consumed since the log began at a log time [Ah]: the log's counter, else the
    integrated current (what a charge-counting autopilot shows after booting)."""
    frame = series.frame
    t = frame["time_s"].to_numpy(dtype=float)
    counter = frame["log_discharged_mAh"].to_numpy(dtype=float) / 1000.0 \
        if "log_discharged_mAh" in frame else None
    if counter is not None and np.isfinite(counter).sum() >= 2:
        ok = np.isfinite(counter)
        tc, qc = t[ok], counter[ok] - counter[ok][0]
    else:
        i = frame["current_A"].to_numpy(dtype=float)
        tc = t
        qc = np.r_[0.0, np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t))] / 3600.0

    def at(time_s: float) -> float:
        return float(np.interp(time_s, tc, qc))

    return at


def mid_flight(replay: pd.DataFrame, part: FlightSamples) -> dict | None:
    """The replay row nearest the middle of the load, as a dict."""
    if replay.empty or part.load_start_s is None or part.load_end_s is None:
        return None
    middle = 0.5 * (part.load_start_s + part.load_end_s)
    k = int(np.argmin(np.abs(replay["time_s"].to_numpy() - middle)))
    row: dict[str, Any] = {key: (None if isinstance(val, float) and not np.isfinite(val)
                                 else val) for key, val in replay.iloc[k].to_dict().items()}
    if row.get("true_s") is not None and row.get("model_s") is not None:
        row["model_error_s"] = row["model_s"] - row["true_s"]
    if row.get("true_s") is not None and row.get("model_profile_s") is not None:
        row["model_profile_error_s"] = row["model_profile_s"] - row["true_s"]
    return row
