"""What each flight did to the pack (:func:`analyse_flight`): charge, energy, sag,
resistance, charge left, and with a battery model the replay of :mod:`.replay`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import DataError
from ..formatting import duration
from ..ocv import check_chemistry, soc_from_rest_voltage
from ..validate import LOW_VOLTAGE_TIMER_S
from .replay import RECENT_LOAD_S, REPLAY_EVERY_S, fly_model, mid_flight, replay_remaining, time_to
from .samples import (
    FlightSamples,
    Settings,
    cell_count,
    flight_numbers,
    flight_samples,
    trapezoid,
)

#: Rest voltages after landing sooner than this after the load are noted as recovering [s].
RECOVERING_S = 120.0


#: Resistance regression window [s].
RESISTANCE_WINDOW_S = 8.0


#: Fewest samples in a resistance window.
RESISTANCE_MIN_SAMPLES = 5


#: A window determines the resistance when its current varies by at least this [A] ...
RESISTANCE_MIN_STD_A = 1.0


#: ... and its regression explains at least this share of the voltage variance.
RESISTANCE_MIN_R2 = 0.5


@dataclass
class FlightAnalysis:
    """What one flight shows (see :func:`analyse_flight`); times are log times [s].

    ``samples`` holds the flight's samples (``time_s``, ``voltage_V``,
    ``current_A``, cells, ``predicted_voltage_V`` with a model, ``in_flight``);
    ``resistance`` one row per regression window; ``replay`` one row per replay
    moment (``time_s``, ``recent_current_A``, ``model_s``,
    ``model_logged_load_s``, ``px4_s``, ``ardupilot_s``, ``true_s`` (the logged
    voltage stays under the cutoff for the low-voltage timer), ``first_dip_s``
    (its first sample under it); remaining time [s]). ``summary`` holds every
    scalar result.
    """

    number: int
    summary: dict
    samples: pd.DataFrame
    resistance: pd.DataFrame
    replay: pd.DataFrame
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"flight": self.number, **self.summary,
                "resistance_windows": _records(self.resistance),
                "replay": _records(self.replay), "notes": list(self.notes)}


def _records(frame: pd.DataFrame) -> list[dict]:
    return [{k: (None if isinstance(v, float) and not np.isfinite(v) else v)
             for k, v in row.items()} for row in frame.to_dict(orient="records")]


@dataclass
class FlightReport:
    """Result of :func:`analyse_flight`: one :class:`FlightAnalysis` per flight."""

    source: str
    format: str
    battery_label: str
    cells_series: int
    strings_parallel: int
    capacity_Ah: float | None
    capacity_source: str
    chemistry: str
    cutoff_cell_V: float
    model: str | None
    flights: list
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """The ``flight --json`` document."""
        return {"source": self.source, "format": self.format, "battery": self.battery_label,
                "cells_series": self.cells_series, "strings_parallel": self.strings_parallel,
                "capacity_Ah": self.capacity_Ah, "capacity_source": self.capacity_source,
                "chemistry": self.chemistry, "cutoff_cell_V": self.cutoff_cell_V,
                "cutoff_pack_V": self.cutoff_cell_V * self.cells_series,
                "battery_model": self.model, "flights": [f.to_dict() for f in self.flights],
                "notes": list(self.notes)}

    def to_pandas(self, kind: str = "summary") -> pd.DataFrame:
        """A table: ``"summary"`` (one row per flight), ``"samples"``, ``"replay"`` or
        ``"resistance"`` (rows of every flight, with a ``flight`` column)."""
        if kind == "summary":
            rows = []
            for f in self.flights:
                row = {"flight": f.number}
                row.update({k: v for k, v in f.summary.items()
                            if not isinstance(v, (list, dict, tuple))})
                rows.append(row)
            return pd.DataFrame(rows)
        if kind not in ("samples", "replay", "resistance"):
            raise DataError(f"kind must be summary, samples, replay or resistance, got {kind!r}")
        parts = [getattr(f, kind).assign(flight=f.number) for f in self.flights]
        return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()

    def plot(self, axes=None):
        """Three panels against log time: voltage logged vs predicted, current, and the
        remaining-time replay. Returns the three Axes."""
        from ..plot import plot_flight_report

        return plot_flight_report(self, axes=axes)


def analyse_flight(path, model=None, *, flights=None, battery: int | None = None,
                   capacity_Ah: float | None = None, chemistry: str | None = None,
                   cutoff: float | None = None, cells: int | None = None, parallel: int = 1,
                   replay_every_s: float = REPLAY_EVERY_S,
                   recent_load_s: float = RECENT_LOAD_S,
                   window_s: float = RESISTANCE_WINDOW_S,
                   low_timer_s: float = LOW_VOLTAGE_TIMER_S) -> FlightReport:
    """Analyse the flights of a flight log, optionally against a battery model.

    Parameters
    ----------
    path : str or path-like
        Flight log.
    model : Battery, preset name or battery-file path, optional
        Battery model: adds the predicted voltage and the remaining-time replay
        by the model. Its cells are placed in the log's pack (cells in series
        from the log, ``parallel`` strings).
    flights : int or list of int, optional
        Flights to analyse (from 1); default all.
    battery : int, optional
        Battery instance; default the first with samples.
    capacity_Ah : float, optional
        Label capacity [Ah]; default the log's, else the model's capacity.
    chemistry : {"lipo", "li-ion", "lifepo4"}, optional
        For the generic OCV (state of charge from rest voltages) and the default
        cutoff; default the model's chemistry, else ``"lipo"``.
    cutoff : float, optional
        Cutoff per cell [V] of the replay and the truth; default by chemistry
        (:data:`dischargelab.model.CUTOFF_CELL_VOLTAGE_V`).
    cells : int, optional
        Cells in series; default the log's count, else inferred from the highest
        voltage (with a note).
    parallel : int
        Strings in parallel of the flight pack.
    replay_every_s : float
        Replay spacing [s].
    recent_load_s : float
        Averaging window of the recent load [s].
    window_s : float
        Resistance regression window [s].
    low_timer_s : float
        The pack reaches the cutoff when its voltage stays at or below it this long
        [s] (default 10 s, ArduPilot's ``BATT_LOW_TIMER``); 0 counts the first
        sample under it. Applies to the truth and to every model replay alike.

    Returns
    -------
    FlightReport

    Raises
    ------
    DataError
        Not a flight log, no flight, no such battery or flight, no cell count.
    """
    from ..io.flightlog import choose_battery, read_flight_log
    from ..io.flightlog_base import masked_text
    from ..model import CUTOFF_CELL_VOLTAGE_V

    path = Path(path)
    for name, value in (("replay_every_s", replay_every_s), ("recent_load_s", recent_load_s),
                        ("window_s", window_s)):
        if not value > 0:
            raise DataError(f"{name} must be a positive number of seconds, got {value}")
    if not low_timer_s >= 0:
        raise DataError(f"low_timer_s must be 0 or more seconds, got {low_timer_s}")
    if parallel < 1:
        raise DataError(f"parallel must be at least 1, got {parallel}")
    log = read_flight_log(path)
    series, notes = choose_battery(log, battery)
    if masked_text(series):
        notes.append(f"{series.describe()}: {masked_text(series)}")
    numbers = flight_numbers(log, flights)
    bat = None
    if model is not None:
        from ..model import load_battery

        bat = load_battery(model)
    chemistry = check_chemistry(chemistry or (bat.chemistry if bat is not None else None))
    cells = cell_count(series, cells, chemistry, notes)
    if bat is not None:
        bat = bat.with_pack(cells, parallel)
    capacity, capacity_source = _report_capacity(series, capacity_Ah, bat)
    cutoff = float(cutoff) if cutoff is not None else CUTOFF_CELL_VOLTAGE_V[chemistry]
    settings = Settings(cells, parallel, capacity, chemistry, cutoff, replay_every_s,
                         recent_load_s, window_s, float(low_timer_s))
    if bat is not None and "thermal_prior" in bat.extra:
        notes.append("the cell temperature is simulated with the model's thermal prior (no "
                     "temperature logged): " + str(bat.extra["thermal_prior"].get("note", "")))
    elif bat is not None and "fit_temperature_rise_K" not in bat.extra and bat.family.thermal:
        notes.append("the cell temperature is held at the ambient: the model was fitted to data "
                     "without heating, and the log has no battery temperature")
    if capacity is None:
        notes.append("no capacity (from the log, capacity_Ah or a model): charge left and the "
                      "autopilot estimates are not computed")
    analyses = [_analyse_part(part, series, settings, bat)
                for part in flight_samples(series, log.spans, numbers)]
    return FlightReport(str(path), log.format, series.describe(), cells, parallel, capacity,
                        capacity_source, chemistry, cutoff,
                        None if bat is None else (bat.name or str(model)), analyses, notes)


def _report_capacity(series, capacity_Ah, bat) -> tuple[float | None, str]:
    if capacity_Ah is not None:
        if not capacity_Ah > 0:
            raise DataError(f"capacity_Ah must be a positive number of Ah, got {capacity_Ah}")
        return float(capacity_Ah), "given"
    if series.capacity_mAh:
        return float(series.capacity_mAh) / 1000.0, "the log's configured capacity"
    if bat is not None:
        return bat.capacity_Ah, "the battery model's capacity"
    return None, "unknown"


def _analyse_part(part: FlightSamples, series, s: Settings, bat) -> FlightAnalysis:
    raw = series.frame[series.frame["flight"].to_numpy() == part.number]
    t = raw["time_s"].to_numpy(dtype=float)
    v = raw["voltage_V"].to_numpy(dtype=float)
    i = raw["current_A"].to_numpy(dtype=float)
    cells = [c for c in raw.columns if c.startswith("cell") and c.endswith("_V")]
    notes: list[str] = []
    summary: dict[str, Any] = {
        "start_s": part.start_s, "end_s": part.end_s, "duration_s": part.duration_s,
        "found_by": part.found_by, "load_start_s": part.load_start_s,
        "load_end_s": part.load_end_s,
        "charge_Ah": trapezoid(i, t) / 3600.0,
        "energy_Wh": trapezoid(i * v, t) / 3600.0,
        "mean_current_A": trapezoid(i, t) / max(float(t[-1] - t[0]), 1e-9)
        if t.size > 1 else float(i[0]),
        "min_loaded_V": float(np.min(v)),
        "min_loaded_cell_V": [float(raw[c].min()) for c in cells] or None,
        "rest_before": None if part.rest_before is None else part.rest_before.to_dict(),
        "rest_after": None if part.rest_after is None else part.rest_after.to_dict()}
    rests = [r.voltage_V for r in (part.rest_before, part.rest_after) if r is not None]
    summary["min_rest_V"] = min(rests) if rests else None
    summary.update(_sag(part, raw, cells))
    resistance = resistance_windows(t, v, i, s.window_s,
                                    raw["log_resistance_ohm"].to_numpy(dtype=float)
                                    if "log_resistance_ohm" in raw else None)
    summary.update(_resistance_summary(resistance, s))
    summary.update(_charge_left(part, s, notes))
    summary.update(_cutoff_crossings(t, v, s, notes))
    samples = part.frame.assign(in_flight=part.in_flight)
    predicted = None
    if bat is not None:
        predicted, model_summary, states = fly_model(part, series, s, bat, notes)
        summary.update(model_summary)
        samples = samples.assign(predicted_voltage_V=predicted)
    else:
        states = {}
    replayed = replay_remaining(part, series, s, bat, states, predicted)
    summary["replay_mid_flight"] = mid_flight(replayed, part)
    return FlightAnalysis(part.number, summary, samples, resistance, replayed,
                          notes + _rest_notes(part))


def _cutoff_crossings(t, v, s: Settings, notes: list) -> dict:
    """When the logged voltage first went under the cutoff, and when it stayed there."""
    dip = time_to(t, v, s.cutoff_pack_V, 0.0)
    reached = time_to(t, v, s.cutoff_pack_V, 0.0, s.low_timer_s)
    out = {"cutoff_dip_at_s": dip if np.isfinite(dip) else None,
           "cutoff_reached_at_s": reached if np.isfinite(reached) else None}
    if np.isfinite(dip) and not (np.isfinite(reached) and reached <= dip):
        notes.append(f"the voltage dipped under the cutoff ({s.cutoff_cell_V:g} V/cell) at "
                     f"{duration(dip)} for less than {s.low_timer_s:g} s: a sag at a current peak, "
                     f"which a low-voltage timer of {s.low_timer_s:g} s ignores"
                     + (f"; it stayed under it from {duration(reached)}" if np.isfinite(reached)
                        else "; the pack did not reach the cutoff in this flight"))
    return out


def _rest_notes(part: FlightSamples) -> list[str]:
    if part.load_start_s is None:
        return ["the flight draws no load current (below the flight threshold): no rest "
                "voltages, resistance or replay"]
    notes = []
    if part.rest_before is None:
        notes.append("no rest voltage before the flight (the log starts in the air or under "
                     "load): the state of charge at take-off is not measured")
    if part.rest_after is None:
        notes.append("no rest voltage after landing (the log ends under load or at disarm)")
    elif part.rest_after.relaxed_s is not None and part.rest_after.relaxed_s < RECOVERING_S:
        notes.append(f"the rest voltage after landing is {part.rest_after.relaxed_s:.0f} s after "
                     "the last load: the cells were still recovering, so the charge left by "
                     "the OCV is an underestimate")
    return notes


def _sag(part: FlightSamples, frame, cells) -> dict:
    """Peak current of the flight's samples ``frame`` and the sag from the rest before."""
    i = frame["current_A"].to_numpy(dtype=float)
    k = int(np.argmax(i))
    out: dict[str, Any] = {
        "peak_current_A": float(i[k]), "peak_time_s": float(frame["time_s"].iloc[k]),
        "peak_voltage_V": float(frame["voltage_V"].iloc[k]), "sag_V": None, "sag_cells_V": None}
    rest = part.rest_before
    if rest is not None:
        out["sag_V"] = rest.voltage_V - out["peak_voltage_V"]
        if rest.cells_V is not None:
            sags = [float(r - frame[c].iloc[k]) for r, c in zip(rest.cells_V, cells)]
            out["sag_cells_V"] = [x if np.isfinite(x) else None for x in sags]
    return out


def resistance_windows(time_s, voltage_V, current_A, window_s: float = RESISTANCE_WINDOW_S,
                       log_resistance_ohm=None) -> pd.DataFrame:
    """Internal resistance [ohm] through a flight: ``V = a - R I`` over short windows.

    In each window of ``window_s`` seconds the pack voltage is regressed on the
    current with an intercept (the slow fall of the open-circuit voltage is the
    intercept's): ``R = -cov(V, I) / var(I)``, the resistance the pack shows to
    current changes of a few seconds (series resistance plus the fast
    polarisation). Windows where the current hardly varies leave ``R`` as NaN.

    Parameters
    ----------
    time_s, voltage_V, current_A : array_like
        Samples [s], [V pack], [A].
    window_s : float
        Window length [s].
    log_resistance_ohm : array_like, optional
        The log's own estimate at the same samples [ohm]; its window mean is
        reported beside.

    Returns
    -------
    pandas.DataFrame
        ``start_s``, ``end_s``, ``samples``, ``mean_current_A``, ``current_std_A``,
        ``resistance_ohm`` (pack), ``r2``, ``determined`` and ``log_resistance_ohm``.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_V, dtype=float)
    i = np.asarray(current_A, dtype=float)
    rows = []
    if t.size == 0:
        return pd.DataFrame(columns=["start_s", "end_s", "samples", "mean_current_A",
                                     "current_std_A", "resistance_ohm", "r2", "determined",
                                     "log_resistance_ohm"])
    edges = np.arange(t[0], t[-1] + window_s, window_s)
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (t >= a) & (t < b)
        n = int(sel.sum())
        row = {"start_s": float(a), "end_s": float(b), "samples": n,
               "mean_current_A": float(np.mean(i[sel])) if n else float("nan"),
               "current_std_A": float(np.std(i[sel])) if n else float("nan"),
               "resistance_ohm": float("nan"), "r2": float("nan"), "determined": False,
               "log_resistance_ohm": float("nan")}
        if log_resistance_ohm is not None and n:
            values = np.asarray(log_resistance_ohm, dtype=float)[sel]
            values = values[np.isfinite(values)]
            row["log_resistance_ohm"] = float(np.mean(values)) if values.size else float("nan")
        if n >= RESISTANCE_MIN_SAMPLES and row["current_std_A"] >= max(
                RESISTANCE_MIN_STD_A, 0.05 * abs(row["mean_current_A"])):
            di, dv = i[sel] - i[sel].mean(), v[sel] - v[sel].mean()
            slope = float(np.sum(di * dv) / np.sum(di * di))
            total = float(np.sum(dv * dv))
            r2 = 1.0 - float(np.sum((dv - slope * di) ** 2)) / total if total > 0 else 0.0
            row.update(resistance_ohm=-slope, r2=r2,
                       determined=bool(r2 >= RESISTANCE_MIN_R2 and slope < 0))
        rows.append(row)
    return pd.DataFrame(rows)


def _resistance_summary(windows: pd.DataFrame, s: Settings) -> dict:
    good = windows[windows["determined"]] if len(windows) else windows
    pack = float(np.median(good["resistance_ohm"])) if len(good) else None
    logged = windows["log_resistance_ohm"].to_numpy(dtype=float) if len(windows) else np.array([])
    logged = logged[np.isfinite(logged)]
    return {"resistance_ohm": pack,
            "resistance_cell_ohm": None if pack is None else pack * s.parallel / s.cells,
            "resistance_windows_used": int(len(good)),
            "log_resistance_ohm": float(np.median(logged)) if logged.size else None}


def _charge_left(part: FlightSamples, s: Settings, notes: list) -> dict:
    out: dict[str, Any] = {"soc_start": None, "soc_landing_ocv": None, "charge_left_ocv_Ah": None,
           "charge_left_label_Ah": None, "charge_left_start_Ah": None}
    used = part.charge_Ah(until_s=None if part.rest_after is None else part.rest_after.time_s,
                          from_s=None if part.rest_before is None else part.rest_before.time_s)
    if part.rest_before is not None:
        out["soc_start"] = soc_from_rest_voltage(part.rest_before.voltage_V / s.cells,
                                                 s.chemistry)
    if part.rest_after is not None:
        out["soc_landing_ocv"] = soc_from_rest_voltage(part.rest_after.voltage_V / s.cells,
                                                       s.chemistry)
    if s.capacity_Ah is not None:
        out["charge_left_label_Ah"] = s.capacity_Ah - used
        if out["soc_landing_ocv"] is not None:
            out["charge_left_ocv_Ah"] = out["soc_landing_ocv"] * s.capacity_Ah
        if out["soc_start"] is not None:
            out["charge_left_start_Ah"] = out["soc_start"] * s.capacity_Ah - used
    return out
