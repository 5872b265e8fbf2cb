"""Flight logs in: fit a battery model from flights, replay what the pack did in the air.

Two entry points:

* :func:`flight_curves` turns the flights of a log into fit curves
  (:class:`~dischargelab.fit.Curve`) for a pack that did not start full and did
  not reach its cutoff. The charge already taken out before each flight comes
  from the pack's rest voltage before take-off through an open-circuit voltage
  (OCV) curve: the battery model's own when one is given, else the generic
  per-chemistry table :data:`GENERIC_OCV_V` (a prior), times the label capacity:
  ``initial_charge_Ah = (1 - SOC) * capacity_Ah``. :func:`fit_flights` (what
  ``dischargelab.fit`` runs for a :class:`FlightCurves`) fits them together; when
  the flights do not reach the knee of the OCV curve, the capacity ``C_Ah`` is
  held within :data:`CAPACITY_TOLERANCE` of the label and the OCV outside the
  flown range is held at the prior. Both say so in their notes.
* :func:`analyse_flight` reports, per flight: duration, charge and energy,
  rest and loaded voltages, sag at the peak current, the internal resistance
  through the flight (regression of voltage on current over short windows) next
  to the log's own estimate, and the charge left at landing. With a battery
  model it flies the logged current through the engine
  (:func:`dischargelab.engine.run`, a ``profile`` step) from the charge at
  take-off, compares the voltage, and replays the remaining flight time every
  :data:`REPLAY_EVERY_S` seconds: the model from the state at that moment at the
  recent load, next to the autopilots' own charge-counting estimates and, when
  the logged voltage reached the cutoff, the true value.

Sign convention: discharge current positive; charges are pack charges [Ah]
taken out of the pack since full unless a name says ``cell``. Times are log
times [s] unless a name says otherwise.

References
----------
.. [1] G. L. Plett, "Battery Management Systems, Vol. 1: Battery Modeling",
   Artech House (2015), ch. 2 (open-circuit voltage from a slow discharge
   corrected for the ohmic drop; state of charge from a rested voltage).
.. [2] Y. Ai, et al., "Electrochemical thermal-mechanical modelling of stress
   inhomogeneity in lithium-ion pouch cells", J. Electrochem. Soc. 167 (2020)
   013512 (the Enertech LCO pouch-cell C/10 discharge, ``../shared/data/enertech_lco``).
.. [3] ARTS-Laboratory, "dataset-electrothermal-deformation-characterization-for-
   samsung-30Q-cell" (Samsung INR18650-30Q C/10 discharge, ``../shared/data/samsung30q_S001``)
   and "Dataset-battery-electro-thermal-characterization" (K2 LFP26650 1C discharge,
   ``../shared/data/k2_lfp26650``); CC BY-SA 4.0.
.. [4] PX4 parameter reference: BAT1_V_EMPTY, BAT1_V_CHARGED [V per cell],
   BAT1_R_INTERNAL [ohm per cell]; uORB ``battery_status.time_remaining_s``
   ("time remaining until the battery is empty under the previous averaged load").
.. [5] ArduPilot parameter reference: BATT_CAPACITY [mAh]; DataFlash ``CURR.CurrTot`` /
   ``BAT.CurrTot`` [mAh consumed].
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .errors import DataError, FitError, SimulationError
from .models.base import HELD_AT_AMBIENT_HEAT_CAPACITY
from .models.ecm import TAU_D_BOUNDS_S
from .validate import LOW_VOLTAGE_TIMER_S

# --------------------------------------------------------------------------- constants

#: State of charge of the rows of :data:`GENERIC_OCV_V` [-] (1 full, 0 empty).
OCV_SOC = np.round(np.linspace(1.0, 0.0, 21), 2)

#: Generic open-circuit voltage per cell [V] at :data:`OCV_SOC`, by chemistry: a prior.
#:
#: * ``"lipo"``: LiCoO2/graphite (the chemistry of hobby LiPo packs): the Enertech
#:   2.28 Ah pouch cell's C/10 discharge to 3.0 V [2]_, plus the ohmic drop at its load
#:   step (0.228 A x 25.9 mOhm); the full value is its rest voltage before the load.
#: * ``"li-ion"``: NMC/graphite 18650 (Li-ion drone packs): the Samsung INR18650-30Q
#:   C/10 discharge to 2.5 V [3]_, plus its load-step ohmic drop (0.30 A x 36.3 mOhm).
#: * ``"lifepo4"``: LiFePO4/graphite: the shape of the K2 LFP26650 1C discharge at
#:   30 degC to 2.5 V [3]_ (the first 0.5 % of the charge, the voltage just after
#:   charging, left out), shifted up by 0.1375 V so that 50 % reads the nominal 3.3 V:
#:   that set has no rest voltage, so its level is an assumption.
#:
#: State of charge counts the charge delivered by that discharge (0 % = its cutoff).
#: Real packs differ from these cells by tens of millivolts; the diffusion and
#: polarisation left in a C/10 curve put the table slightly below a true OCV.
#: The state of charge read from them is a prior with an error of about 5 % (LiPo,
#: Li-ion) and far more on the flat LiFePO4 plateau (see :func:`soc_from_rest_voltage`).
GENERIC_OCV_V = {
    "lipo": np.array([4.181, 4.119, 4.070, 4.025, 3.984, 3.947, 3.912, 3.873, 3.837, 3.814,
                      3.796, 3.781, 3.769, 3.759, 3.745, 3.725, 3.708, 3.682, 3.646, 3.551,
                      3.004]),
    "li-ion": np.array([4.142, 4.074, 4.057, 4.038, 3.987, 3.931, 3.884, 3.838, 3.793, 3.749,
                        3.703, 3.659, 3.621, 3.582, 3.521, 3.468, 3.412, 3.305, 3.168, 2.984,
                        2.511]),
    "lifepo4": np.array([3.430, 3.352, 3.347, 3.338, 3.332, 3.326, 3.321, 3.317, 3.312, 3.307,
                         3.300, 3.293, 3.286, 3.275, 3.262, 3.248, 3.232, 3.211, 3.158, 3.032,
                         2.635]),
}

#: Where each table comes from (for notes and reports).
OCV_SOURCE = {
    "lipo": "generic LiPo (LiCoO2) OCV from a C/10 discharge (Enertech pouch cell, Ai et al. "
            "2020)",
    "li-ion": "generic Li-ion (NMC) OCV from a C/10 discharge (Samsung INR18650-30Q)",
    "lifepo4": "generic LiFePO4 OCV shape from a 1C discharge (K2 LFP26650), level assumed "
               "(3.3 V at 50 %)",
}

#: Charge voltage per cell [V] by chemistry (for inferring the cell count).
CHARGE_CELL_V = {"lipo": 4.2, "li-ion": 4.2, "lifepo4": 3.65}

#: Chemistry assumed when none is given (most UAV packs).
DEFAULT_CHEMISTRY = "lipo"

#: The capacity is held within this fraction of the label when the flights do not
#: reach the knee of the OCV curve.
CAPACITY_TOLERANCE = 0.10

#: Flights ending at or below this state of charge [-] reach the knee of the OCV curve
#: (below it the generic curves steepen): there they determine the capacity.
KNEE_SOC = 0.15

#: A rest voltage after landing counts for the knee only this long after the load [s]
#: (sooner, the cells are far from their open-circuit voltage).
KNEE_REST_S = 30.0

#: Rest voltages after landing sooner than this after the load are noted as recovering [s].
RECOVERING_S = 120.0

#: Flights that reach the knee determine the capacity; the OCV prior still holds the
#: intervals they cannot reach for any capacity up to this factor times the label.
KNEE_PRIOR_CAPACITY_FACTOR = 1.3

#: Sampling rates above this [Hz] are averaged into bins of 1/rate (current and voltage
#: alike): RC time constants are seconds, the engine steps once per sample.
MAX_RATE_HZ = 20.0

#: The rest voltage is the median over the last this many seconds of idle samples [s].
REST_WINDOW_S = 2.0

#: Idle samples used before take-off: at most this long before the load starts [s].
REST_LOOKBACK_S = 60.0

#: Rest samples draw at most this much more than the quiet idle current (10th percentile) [A].
QUIET_MARGIN_A = 0.5

#: Idle samples used after landing: at most this long after the last load [s].
MAX_REST_AFTER_S = 300.0

#: Resistance regression window [s].
RESISTANCE_WINDOW_S = 8.0

#: Fewest samples in a resistance window.
RESISTANCE_MIN_SAMPLES = 5

#: A window determines the resistance when its current varies by at least this [A] ...
RESISTANCE_MIN_STD_A = 1.0

#: ... and its regression explains at least this share of the voltage variance.
RESISTANCE_MIN_R2 = 0.5

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



# --------------------------------------------------------------------------- OCV prior

def check_chemistry(chemistry: str | None) -> str:
    """The chemistry name, :data:`DEFAULT_CHEMISTRY` for None.

    Raises
    ------
    DataError
        Not one of the keys of :data:`GENERIC_OCV_V`.
    """
    if chemistry is None:
        return DEFAULT_CHEMISTRY
    if chemistry not in GENERIC_OCV_V:
        raise DataError(f"chemistry must be one of {', '.join(GENERIC_OCV_V)}, got {chemistry!r}")
    return chemistry


def ocv_from_soc(soc, chemistry: str | None = None):
    """Generic open-circuit voltage per cell [V] at state of charge ``soc`` [0-1].

    Linear interpolation in :data:`GENERIC_OCV_V` (a prior, see there).
    """
    table = GENERIC_OCV_V[check_chemistry(chemistry)]
    return np.interp(np.clip(soc, 0.0, 1.0), OCV_SOC[::-1], table[::-1])


def soc_from_rest_voltage(cell_V, chemistry: str | None = None):
    """State of charge [0-1] of a cell resting at ``cell_V`` [V], by the generic OCV.

    Voltages above the table's full value read 1, below its empty value 0.

    Parameters
    ----------
    cell_V : float or array_like
        Rest voltage per cell [V] (pack voltage / cells in series).
    chemistry : {"lipo", "li-ion", "lifepo4"}, optional
        Default :data:`DEFAULT_CHEMISTRY`.

    Returns
    -------
    float or numpy.ndarray
        State of charge [-].

    References
    ----------
    Plett (2015), ch. 2; the tables of :data:`GENERIC_OCV_V`.
    """
    table = GENERIC_OCV_V[check_chemistry(chemistry)]
    out = np.interp(np.asarray(cell_V, dtype=float), table[::-1], OCV_SOC[::-1])
    return float(out) if np.ndim(out) == 0 else out


def soc_per_10mV(cell_V: float, chemistry: str | None = None) -> float:
    """How far 10 mV of rest-voltage error moves the state of charge [0-1] at ``cell_V``."""
    lo = soc_from_rest_voltage(cell_V - 0.005, chemistry)
    hi = soc_from_rest_voltage(cell_V + 0.005, chemistry)
    return float(abs(hi - lo))


def model_charge_at_rest(battery, pack_V: float, current_A: float = 0.0) -> float:
    """Pack charge taken out [Ah] at which ``battery`` reads ``pack_V`` [V].

    With ``current_A`` = 0 this inverts the model's open-circuit voltage; with a
    current it inverts the loaded voltage with every filtered state settled at
    that current (:meth:`dischargelab.model.Battery.voltage`). The result is
    clipped to [0, capacity).
    """
    capacity = battery.capacity_Ah
    q = np.linspace(0.0, capacity * (1.0 - 1e-6), 4001)
    with np.errstate(invalid="ignore", over="ignore"):
        v = np.asarray(battery.voltage(np.full(q.size, float(current_A)), q), dtype=float)
    ok = np.isfinite(v)
    if not ok.any():
        raise SimulationError("the battery model cannot be evaluated at this current")
    v = np.minimum.accumulate(np.where(ok, v, -np.inf))
    if pack_V >= v[0]:
        return 0.0
    k = int(np.argmax(v <= pack_V))
    if v[k] > pack_V:
        return float(q[-1])
    v0, v1 = v[k - 1], v[k]
    frac = (v0 - pack_V) / (v0 - v1) if np.isfinite(v1) and v0 != v1 else 0.0
    return float(q[k - 1] + frac * (q[k] - q[k - 1]))


# --------------------------------------------------------------------------- flight samples

@dataclass
class RestVoltage:
    """Pack voltage at rest next to a flight.

    Attributes
    ----------
    voltage_V : float
        Median pack voltage over the last :data:`REST_WINDOW_S` of idle samples [V].
    current_A : float
        Mean current over those samples [A] (idle draw, sensor offset).
    time_s : float
        Log time of the last sample used [s].
    samples : int
        Samples used.
    cells_V : tuple of float or None
        Median per-cell voltages [V], when the log measures them.
    relaxed_s : float or None
        After landing: time from the last load to ``time_s`` [s].
    which : {"before", "after"}
    """

    voltage_V: float
    current_A: float
    time_s: float
    samples: int
    cells_V: tuple | None = None
    relaxed_s: float | None = None
    which: str = "before"

    def to_dict(self) -> dict:
        return {"voltage_V": self.voltage_V, "current_A": self.current_A, "time_s": self.time_s,
                "samples": self.samples,
                "cells_V": None if self.cells_V is None else list(self.cells_V),
                "relaxed_s": self.relaxed_s}


@dataclass
class FlightSamples:
    """One flight of one battery: its samples (with the rest on either side) and landmarks.

    ``frame`` runs from the first rest sample before the load (or the load start)
    to the last rest sample after it (or the flight's end); ``in_flight`` marks
    the samples inside the flight span. Times are log times [s].
    """

    number: int
    start_s: float
    end_s: float
    found_by: str
    frame: pd.DataFrame
    load_start_s: float | None
    load_end_s: float | None
    rest_before: RestVoltage | None
    rest_after: RestVoltage | None

    @property
    def in_flight(self) -> np.ndarray:
        t = self.frame["time_s"].to_numpy(dtype=float)
        return (t >= self.start_s) & (t <= self.end_s)

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    def charge_Ah(self, until_s: float | None = None, from_s: float | None = None) -> float:
        """Charge drawn [Ah] over the frame (optionally between two log times)."""
        t = self.frame["time_s"].to_numpy(dtype=float)
        i = self.frame["current_A"].to_numpy(dtype=float)
        keep = np.ones(t.size, bool)
        if from_s is not None:
            keep &= t >= from_s
        if until_s is not None:
            keep &= t <= until_s
        return _trapezoid(i[keep], t[keep]) / 3600.0


def _trapezoid(y, x) -> float:
    y, x = np.asarray(y, dtype=float), np.asarray(x, dtype=float)
    if x.size < 2:
        return 0.0
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))


def resample(frame: pd.DataFrame, max_rate_Hz: float = MAX_RATE_HZ) -> pd.DataFrame:
    """Average samples faster than ``max_rate_Hz`` [Hz] into bins (within each flight).

    Every numeric column is averaged; the ``flight`` column is kept (bins never
    straddle two flights). Slower logs are returned unchanged.
    """
    t = frame["time_s"].to_numpy(dtype=float)
    if t.size < 3 or np.median(np.diff(t)) >= 1.0 / max_rate_Hz:
        return frame.reset_index(drop=True)
    bins = np.floor((t - t[0]) * max_rate_Hz).astype(np.int64)
    keys = [frame["flight"].to_numpy(), bins] if "flight" in frame else [bins]
    out = frame.groupby(keys, sort=False).mean(numeric_only=True)
    out = out.reset_index(drop=True).sort_values("time_s").reset_index(drop=True)
    if "flight" in frame:
        out["flight"] = out["flight"].round().astype(int)
    return out


def _load_threshold_A(current: np.ndarray) -> float:
    from .io.flightlog import MIN_ON_A, ON_FRACTION

    if current.size == 0:
        return MIN_ON_A
    return max(MIN_ON_A, ON_FRACTION * float(np.percentile(current, 99)))


def _rest(frame: pd.DataFrame, rows: np.ndarray, which: str,
          load_end_s: float | None = None) -> RestVoltage | None:
    """Rest voltage from the idle ``rows`` (indices, in time order) of ``frame``."""
    if rows.size == 0:
        return None
    t = frame["time_s"].to_numpy(dtype=float)
    last = t[rows[-1]]
    rows = rows[t[rows] >= last - REST_WINDOW_S]
    cells = [c for c in frame.columns if c.startswith("cell") and c.endswith("_V")]
    cells_V = tuple(float(np.median(frame[c].to_numpy(dtype=float)[rows])) for c in cells) \
        if cells else None
    return RestVoltage(
        voltage_V=float(np.median(frame["voltage_V"].to_numpy(dtype=float)[rows])),
        current_A=float(np.mean(frame["current_A"].to_numpy(dtype=float)[rows])),
        time_s=float(last), samples=int(rows.size), cells_V=cells_V,
        relaxed_s=None if load_end_s is None else float(last - load_end_s), which=which)


def flight_samples(series, spans, numbers=None) -> list[FlightSamples]:
    """The flights ``numbers`` (default all) of one battery, with their rest voltages.

    Parameters
    ----------
    series : dischargelab.io.flightlog.BatterySeries
    spans : list of dischargelab.io.flightlog.FlightSpan
    numbers : list of int, optional

    Returns
    -------
    list of FlightSamples

    Notes
    -----
    A flight's load starts at its first sample above the flight threshold of
    :mod:`dischargelab.io.flightlog` (10 % of the 99th-percentile current, at
    least 1 A) and ends at its last one. The rest before is taken from the idle
    samples (below half that threshold) in the :data:`REST_LOOKBACK_S` before
    the load start, inside the flight (armed, before take-off) or before it;
    the rest after from the first run of idle samples after the last load, up
    to :data:`MAX_REST_AFTER_S` or the next flight. Of those, only the quiet
    ones count (within :data:`QUIET_MARGIN_A` of their 10th-percentile
    current), and the rest voltage is their median over the last
    :data:`REST_WINDOW_S`. A flight's samples run from that window before the
    load (or the flight's start) to the end of the rest after it.
    """
    from .io.flightlog import OFF_RATIO

    frame = resample(series.frame)
    t = frame["time_s"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    number = frame["flight"].to_numpy()
    chosen = [s for s in spans if numbers is None or s.number in numbers]
    out = []
    for span in chosen:
        inside = number == span.number
        on = _load_threshold_A(i[inside])
        idle = i <= on * OFF_RATIO
        load = np.flatnonzero(inside & (i > on))
        later = [s.start_s for s in spans if s.start_s > span.start_s]
        load_start: float | None = None
        load_end: float | None = None
        if load.size:
            first, last = int(load[0]), int(load[-1])
            earlier = [s.end_s for s in spans if s.end_s < span.start_s]
            since = max([t[first] - REST_LOOKBACK_S] + earlier)
            before = np.flatnonzero(idle[:first] & (t[:first] >= since))
            stop = min([t[last] + MAX_REST_AFTER_S] + later)
            after = _idle_run_after(idle, t, last, stop)
            rest_before = _rest(frame, _quiet(before, i), "before")
            rest_after = _rest(frame, _quiet(after, i), "after", load_end_s=float(t[last]))
            lo = first if rest_before is None else \
                int(np.searchsorted(t, rest_before.time_s - REST_WINDOW_S))
            lo = min(lo, int(np.argmax(inside)))
            hi = int(after[-1]) if rest_after is not None else int(np.flatnonzero(inside)[-1])
            load_start, load_end = float(t[first]), float(t[last])
        else:
            rows = np.flatnonzero(inside)
            lo, hi = int(rows[0]), int(rows[-1])
            rest_before = rest_after = None
        part = frame.iloc[lo:hi + 1].reset_index(drop=True)
        out.append(FlightSamples(span.number, span.start_s, span.end_s, span.found_by, part,
                                 load_start, load_end, rest_before, rest_after))
    return out


def _idle_run_after(idle: np.ndarray, t: np.ndarray, last: int, stop_s: float) -> np.ndarray:
    """Rows of the first run of idle samples after row ``last`` (before ``stop_s``)."""
    rows = np.arange(last + 1, t.size)
    rows = rows[t[rows] < stop_s]
    start = np.flatnonzero(idle[rows])
    if start.size == 0:
        return np.zeros(0, dtype=int)
    rows = rows[start[0]:]
    busy = np.flatnonzero(~idle[rows])
    return rows[:busy[0]] if busy.size else rows


def _quiet(rows: np.ndarray, current: np.ndarray) -> np.ndarray:
    """The idle ``rows`` drawing no more than their 10th-percentile current plus
    :data:`QUIET_MARGIN_A` (motors stopped rather than idling, no arming beeps)."""
    if rows.size == 0:
        return rows
    floor = float(np.percentile(current[rows], 10))
    return rows[current[rows] <= floor + QUIET_MARGIN_A]


# --------------------------------------------------------------------------- fit from flights

@dataclass
class FlightCurves:
    """Flights of one pack ready to fit, with what they can and cannot determine.

    Behaves like the list of its curves (``len``, iteration, indexing);
    :func:`dischargelab.fit` accepts it directly.

    Attributes
    ----------
    curves : list of dischargelab.fit.Curve
        One per flight, each with its own ``initial_charge_Ah`` [Ah, pack].
    cells_series : int
        Cells in series of the pack.
    capacity_Ah : float
        Label capacity of the pack [Ah].
    capacity_source : str
        Where the label capacity comes from.
    chemistry : str
        Chemistry of the OCV prior.
    flights : list of dict
        Per flight: number, rest voltage, state of charge and initial charge with
        their source, charge drawn, state of charge at the end.
    notes : list of str
        What the flights determine and what they do not, one sentence each.
    source : str
        The log file.
    """

    curves: list
    cells_series: int
    capacity_Ah: float
    capacity_source: str
    chemistry: str
    flights: list
    notes: list = field(default_factory=list)
    source: str = ""

    def __len__(self) -> int:
        return len(self.curves)

    def __iter__(self):
        return iter(self.curves)

    def __getitem__(self, k):
        return self.curves[k]

    @property
    def lowest_soc(self) -> float | None:
        """Lowest state of charge any flight ends at [0-1], or None: by counting the charge
        against the label, or by a rest voltage after landing measured at least
        :data:`KNEE_REST_S` after the load, whichever is lower."""
        values = [f["soc_end"] for f in self.flights if f.get("soc_end") is not None]
        values += [f["soc_end_rest"] for f in self.flights if f.get("soc_end_rest") is not None
                   and f["rest_after_relaxed_s"] >= KNEE_REST_S]
        return min(values) if values else None

    @property
    def knee_reached(self) -> bool:
        """True when a flight ends at or below :data:`KNEE_SOC`."""
        low = self.lowest_soc
        return low is not None and low <= KNEE_SOC

    def capacity_bounds(self, strings_parallel: int = 1) -> dict:
        """``{"C_Ah": (low, high)}`` per cell when the flights do not reach the knee, else {}."""
        if self.knee_reached:
            return {}
        cell = self.capacity_Ah / strings_parallel
        return {"C_Ah": (cell * (1.0 - CAPACITY_TOLERANCE), cell * (1.0 + CAPACITY_TOLERANCE))}

    def prior_capacity_range(self, strings_parallel: int = 1) -> tuple[float, float]:
        """Capacities per cell [Ah] over which :meth:`ocv_prior` checks what the flights
        reach: the fit's bounds, or (knee reached) from the charge drawn to
        :data:`KNEE_PRIOR_CAPACITY_FACTOR` times the label."""
        bounds = self.capacity_bounds(strings_parallel).get("C_Ah")
        if bounds is not None:
            return bounds
        top = self.state_range()[1] / strings_parallel
        return top, max(top, self.capacity_Ah / strings_parallel) * KNEE_PRIOR_CAPACITY_FACTOR

    def state_range(self) -> tuple[float, float]:
        """Lowest and highest pack charge taken out over the flights [Ah]."""
        starts = [c.initial_charge_Ah for c in self.curves]
        ends = [c.initial_charge_Ah + float(c.charge_Ah[-1]) for c in self.curves]
        return min(starts), max(ends)

    def ocv_prior(self, family, strings_parallel: int = 1, c_bounds=None) -> dict:
        """Fixed OCV drops of the ``ecm`` family outside the flown range (generic prior).

        An interval of the ``ecm`` OCV grid that no flight can reach for any
        capacity within ``c_bounds`` (per cell [Ah]) is held at the generic
        curve's drop over it; {} for families without an OCV table.
        """
        from .models.ecm import OCV_DROP_NAMES, OCV_NODES

        if not set(OCV_DROP_NAMES) <= set(family.names) or c_bounds is None:
            return {}
        q_lo, q_hi = (q / strings_parallel for q in self.state_range())
        x_lo, x_hi = q_lo / c_bounds[1], q_hi / c_bounds[0]
        fixed = {}
        for k, name in enumerate(OCV_DROP_NAMES):
            a, b = OCV_NODES[k], OCV_NODES[k + 1]
            if b <= x_lo or a >= x_hi:
                drop = float(ocv_from_soc(1.0 - a, self.chemistry)
                             - ocv_from_soc(1.0 - b, self.chemistry))
                fixed[name] = max(drop, 0.0)
        return fixed

    def to_dict(self) -> dict:
        return {"source": self.source, "cells_series": self.cells_series,
                "capacity_Ah": self.capacity_Ah, "capacity_source": self.capacity_source,
                "chemistry": self.chemistry, "knee_reached": self.knee_reached,
                "flights": [dict(f) for f in self.flights], "notes": list(self.notes)}


def flight_curves(path, flights=None, battery: int | None = None,
                  capacity_Ah: float | None = None, chemistry: str | None = None, *,
                  cells: int | None = None, model=None) -> FlightCurves:
    """Fit curves from the flights of one flight log (partial discharges of one pack).

    Parameters
    ----------
    path : str or path-like
        Flight log (ArduPilot, PX4 ULog, blackbox, in-flight logger CSV).
    flights : int or list of int, optional
        Flights to use, counting from 1; default every flight.
    battery : int, optional
        Battery instance; default the first with samples.
    capacity_Ah : float, optional
        Label capacity of the pack [Ah]. Required when the log does not state
        it; overrides the log's value when given.
    chemistry : {"lipo", "li-ion", "lifepo4"}, optional
        Chemistry of the generic OCV prior; default ``"lipo"``.
    cells : int, optional
        Cells in series; default the log's count, else inferred from the highest
        voltage (with a note).
    model : Battery, preset name or battery-file path, optional
        A battery model whose OCV replaces the generic table for the initial charges.

    Returns
    -------
    FlightCurves
        Curves with their initial charge [Ah] and notes on what the flights
        determine.

    Raises
    ------
    DataError
        Not a flight log, no such flight or battery, no capacity, no cell count,
        or no rest voltage (nor state-of-charge estimate) before a flight.
    """
    from .fit import Curve
    from .io.flightlog import choose_battery, read_flight_log

    path = Path(path)
    chemistry = check_chemistry(chemistry)
    log = read_flight_log(path)
    series, battery_notes = choose_battery(log, battery)
    numbers = _flight_numbers(log, flights)
    cells = _cells(series, cells, chemistry, battery_notes)
    parts = flight_samples(series, log.spans, numbers)
    capacity, capacity_source = _capacity(series, capacity_Ah, path, parts, cells, chemistry)
    bat = _model_pack(model, cells) if model is not None else None
    curves, rows, notes = [], [], list(battery_notes)
    for part in parts:
        if part.load_start_s is None:
            raise DataError(f"{path.name}: flight {part.number} draws no load current; choose "
                            f"flights with flights=[...] (--flight N)")
        row = _initial_state(part, series, cells, capacity, chemistry, bat, path)
        frame = part.frame
        t = frame["time_s"].to_numpy(dtype=float)
        drawn = part.charge_Ah()
        row["charge_Ah"] = drawn
        row["soc_end"] = None if row["initial_charge_Ah"] is None else \
            1.0 - (row["initial_charge_Ah"] + drawn) / capacity
        if part.rest_after is not None:
            row["rest_after_V"] = part.rest_after.voltage_V
            row["soc_end_rest"] = soc_from_rest_voltage(part.rest_after.voltage_V / cells,
                                                        chemistry)
            row["rest_after_relaxed_s"] = part.rest_after.relaxed_s
        rows.append(row)
        meta = {"source": str(path), "format": log.format, "flight": part.number,
                "battery": series.index, "initial_charge_source": row["source"],
                "rest_sample": None if part.rest_before is None else
                {"voltage_V": part.rest_before.voltage_V, "current_A": part.rest_before.current_A,
                 "time_s": float(part.rest_before.time_s - t[0]),
                 "rule": f"median of the last quiet idle {REST_WINDOW_S:g} s before the load"}}
        curves.append(Curve(t - t[0], frame["voltage_V"].to_numpy(dtype=float),
                            frame["current_A"].to_numpy(dtype=float),
                            name=f"{path.stem} flight {part.number}",
                            rest_voltage_V=None if part.rest_before is None
                            else part.rest_before.voltage_V, meta=meta,
                            initial_charge_Ah=row["initial_charge_Ah"]))
    result = FlightCurves(curves, cells, capacity, capacity_source, chemistry, rows,
                          source=str(path))
    result.notes = notes + _flight_notes(result, bat, series)
    return result


def _flight_numbers(log, flights) -> list[int]:
    from .io.flightlog import choose_span

    if not log.spans:
        raise DataError(f"{Path(log.source).name}: no flight found (no arm/disarm, take-off/"
                        "landing or sustained current)")
    if flights is None:
        return [s.number for s in log.spans]
    numbers = [flights] if isinstance(flights, (int, np.integer)) else list(flights)
    if not numbers:
        raise DataError("flights is empty; give flight numbers counting from 1 or leave it out")
    return [choose_span(log, int(n)).number for n in numbers]


def infer_cells(voltage_V, chemistry: str | None = None) -> int:
    """Cells in series of a pack from its highest voltage [V]: the fewest cells that stay
    at or below the chemistry's charge voltage (:data:`CHARGE_CELL_V`) plus 0.05 V."""
    values = np.asarray(voltage_V, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        raise DataError("no voltage to infer the cell count from; give cells=N (--cells N)")
    top = float(np.percentile(values, 99))
    return max(1, int(np.ceil(top / (CHARGE_CELL_V[check_chemistry(chemistry)] + 0.05))))


def _cells(series, cells, chemistry: str, notes: list) -> int:
    if cells is not None:
        if int(cells) < 1:
            raise DataError(f"cells must be at least 1, got {cells}")
        return int(cells)
    if series.cells:
        return int(series.cells)
    count = infer_cells(series.frame["voltage_V"].to_numpy(), chemistry)
    notes.append(f"{count} cells in series inferred from the highest voltage (the log does not "
                 f"say; give cells=N (--cells N) if that is wrong)")
    return count


#: A flight that goes at least this deep in state of charge (rest voltages before
#: and after, generic OCV) gives the capacity when no label capacity is known [-]: a
#: near-full drain, so that the generic OCV's error at the ends matters little (29.csv,
#: 79 % deep by the prior, would give 1.23 Ah for its 1.6 Ah label).
CAPACITY_FROM_DRAIN_SOC = 0.85


def _capacity(series, capacity_Ah, path: Path, parts=(), cells: int = 1,
              chemistry: str = "lipo") -> tuple[float, str]:
    """Pack capacity [Ah]: given, else the log's, else from a deep drain in the log."""
    if capacity_Ah is not None:
        if not np.isfinite(capacity_Ah) or capacity_Ah <= 0:
            raise DataError(f"capacity_Ah must be a positive number of Ah, got {capacity_Ah}")
        source = "given"
        if series.capacity_mAh:
            source += f" (the log says {series.capacity_mAh:g} mAh)"
        return float(capacity_Ah), source
    if series.capacity_mAh:
        return float(series.capacity_mAh) / 1000.0, "the log's configured capacity"
    best = None
    for part in parts:
        if part.rest_before is None:
            continue
        if part.rest_after is not None and part.rest_after.relaxed_s >= KNEE_REST_S:
            end_V, how = part.rest_after.voltage_V, "rest voltages"
        else:  # ends under load (a drain to the cutoff): the loaded voltage is below the OCV
            end_V = float(part.frame["voltage_V"].iloc[-1])
            how = "rest voltage before and last loaded voltage"
        depth = soc_from_rest_voltage(part.rest_before.voltage_V / cells, chemistry) - \
            soc_from_rest_voltage(end_V / cells, chemistry)
        if depth >= CAPACITY_FROM_DRAIN_SOC and (best is None or depth > best[0]):
            best = (depth, part, how)
    if best is not None:
        depth, part, how = best
        drawn = part.charge_Ah()
        return drawn / depth, (f"estimated from flight {part.number}: {drawn:.3g} Ah drawn "
                               f"over {100 * depth:.0f} % of state of charge between its {how} "
                               f"({OCV_SOURCE[chemistry]}); the fit refines it where the "
                               f"flight reaches the knee")
    raise DataError(f"{path.name} does not state the pack capacity and no flight drains the "
                    f"pack deep enough to measure it; give the label capacity with "
                    f"capacity_Ah=AH (--capacity AH)")


def _model_pack(model, cells: int):
    from .model import load_battery

    return load_battery(model).with_pack(cells, None)


def _initial_state(part: FlightSamples, series, cells: int, capacity: float, chemistry: str,
                   bat, path: Path) -> dict:
    """Initial charge of one flight [Ah] and where it comes from."""
    row: dict[str, Any] = {"flight": part.number, "rest_before_V": None, "rest_current_A": None}
    rest = part.rest_before
    if rest is not None:
        row.update(rest_before_V=rest.voltage_V, rest_current_A=rest.current_A)
        cell_V = rest.voltage_V / cells
        if bat is not None:
            q0 = model_charge_at_rest(bat, rest.voltage_V)
            soc = 1.0 - q0 / bat.capacity_Ah
            q0 = (1.0 - soc) * capacity
            source = f"rest voltage {cell_V:.3f} V/cell before take-off through the model's OCV"
        else:
            soc = soc_from_rest_voltage(cell_V, chemistry)
            q0 = (1.0 - soc) * capacity
            source = (f"rest voltage {cell_V:.3f} V/cell before take-off through the "
                      f"{OCV_SOURCE[chemistry]} (a prior)")
            if soc_per_10mV(cell_V, chemistry) > 0.05:
                source += (f"; the OCV is flat there: 10 mV moves the state of charge by "
                           f"{100 * soc_per_10mV(cell_V, chemistry):.0f} %")
        row.update(soc_start=float(soc), initial_charge_Ah=float(q0), source=source)
        return row
    remaining = _log_remaining_at(series, part.frame["time_s"].iloc[0])
    if remaining is not None:
        row.update(soc_start=remaining, initial_charge_Ah=(1.0 - remaining) * capacity,
                   source="the log's own state-of-charge estimate at the first sample (no rest "
                          "voltage before the flight)")
        return row
    raise DataError(f"{path.name}: flight {part.number} has no rest voltage before take-off and "
                    "the log has no state-of-charge estimate, so its initial charge is unknown; "
                    "choose flights that start on the ground (--flight N)")


def _log_remaining_at(series, time_s: float) -> float | None:
    frame = series.frame
    if "log_remaining_frac" not in frame:
        return None
    t = frame["time_s"].to_numpy(dtype=float)
    r = frame["log_remaining_frac"].to_numpy(dtype=float)
    ok = np.isfinite(r) & (r >= 0) & (t <= time_s + 1.0)
    if not ok.any():
        return None
    return float(np.clip(r[np.flatnonzero(ok)[-1]], 0.0, 1.0))


def _flight_notes(fc: FlightCurves, bat, series) -> list[str]:
    notes = []
    for row in fc.flights:
        notes.append(f"flight {row['flight']}: initial charge {row['initial_charge_Ah']:.3f} Ah "
                     f"(state of charge {100 * row['soc_start']:.0f} %) from the {row['source']}")
    low = fc.lowest_soc
    label = f"{fc.capacity_Ah:g} Ah label ({fc.capacity_source})"
    counted = [r["soc_end"] for r in fc.flights if r.get("soc_end") is not None]
    rested = [r["soc_end_rest"] for r in fc.flights if r.get("soc_end_rest") is not None
              and r["rest_after_relaxed_s"] >= KNEE_REST_S]
    ends = []
    if counted:
        ends.append(f"{100 * min(counted):.0f} % by counting the charge against the {label}")
    if rested:
        ends.append(f"{100 * min(rested):.0f} % by the rest voltage after landing (at least "
                    f"{KNEE_REST_S:g} s after the load)")
    where = f" (lowest state of charge reached: {', '.join(ends)})" if ends else ""
    if low is not None and low <= KNEE_SOC:
        notes.append(f"capacity determined by these flights: they reach the knee of the OCV "
                     f"curve at {100 * KNEE_SOC:.0f} %{where}")
    else:
        notes.append(f"capacity not determined by these flights{where}: held within "
                     f"±{100 * CAPACITY_TOLERANCE:.0f} % of the label")
    q_lo, q_hi = fc.state_range()
    notes.append(f"the flights cover {100 * (1 - q_hi / fc.capacity_Ah):.0f}-"
                 f"{100 * (1 - q_lo / fc.capacity_Ah):.0f} % state of charge: the open-circuit "
                 "voltage is determined there only"
                 + ("" if bat is not None else f"; outside it the {fc.chemistry} prior is used"))
    if "temperature_C" not in series.frame:
        notes.append("the log has no battery temperature: temperature effects are not "
                     "determined (the fit is isothermal)")
    notes += _coulomb_checks(fc)
    return notes


def _coulomb_checks(fc: FlightCurves) -> list[str]:
    """Consecutive flights: initial charge by the rest voltage vs by counting the current."""
    notes = []
    rows = fc.flights
    for prev, row in zip(rows, rows[1:]):
        counted = prev["initial_charge_Ah"] + prev["charge_Ah"]
        by_rest = row["initial_charge_Ah"]
        if by_rest < prev["initial_charge_Ah"] - 0.05 * fc.capacity_Ah:
            notes.append(f"flight {row['flight']} starts fuller than flight {prev['flight']} "
                         "did: the pack was recharged or swapped between them")
        elif abs(by_rest - counted) > 0.05 * fc.capacity_Ah:
            notes.append(f"flight {row['flight']} starts at {by_rest:.3f} Ah taken out by its "
                         f"rest voltage, but flight {prev['flight']}'s start plus the "
                         f"{prev['charge_Ah']:.3f} Ah it drew gives {counted:.3f} Ah: a short "
                         "rest between flights (voltage not recovered), a current-sensor scale "
                         "error or a wrong label capacity")
    return notes


#: A flight's load current is steady when its coefficient of variation (over the
#: samples above half the median current) is below this [-].
STEADY_CURRENT_CV = 0.25

#: ``ecm`` parameters held at "effect absent" for steady drains (``fit_flights``).
STEADY_DRAIN_FIXED = {"R1_ohm": 0.0, "R2_ohm": 0.0, "tau_d_s": TAU_D_BOUNDS_S[0]}


def steady_current(current_A) -> bool:
    """True when a load current is a near-constant drain (:data:`STEADY_CURRENT_CV`)."""
    i = np.asarray(current_A, dtype=float)
    load = i[i > 0.5 * np.median(i)] if i.size else i
    return bool(load.size > 1 and np.std(load) < STEADY_CURRENT_CV * np.mean(load))


def fit_flights(flights: FlightCurves, *, model: str = "ecm", strings_parallel: int = 1,
                cells: int | None = None, fixed: dict | None = None,
                bounds: dict | None = None, bootstrap: int = 0, seed: int = 0,
                use_rest: bool = True):
    """Fit a model family to flights of one pack (see :func:`flight_curves`).

    The capacity ``C_Ah`` is bounded within :data:`CAPACITY_TOLERANCE` of the
    label when the flights do not reach the knee, and (``ecm``) the OCV drops no
    flight reaches are held at the generic prior; explicit ``fixed``/``bounds``
    win. The flights' notes are added to the result's notes.

    Parameters
    ----------
    flights : FlightCurves
    model : str
        Model family; ``"auto"`` means ``"ecm"``: with its RC pairs and diffusion
        state driven by the logged current when it varies, else (every flight a
        near-constant drain, :func:`steady_current`) with those held absent (OCV
        and series resistance only: one constant current cannot show the cell's
        dynamics, and RC pairs fitted to it extrapolate to other currents badly).
    strings_parallel : int
        Strings in parallel of the pack.
    cells : int, optional
        Cells in series; default the flights' own count.
    fixed, bounds : dict, optional
        As :func:`dischargelab.fit.fit_battery` (per cell, SI units in the names).
    bootstrap : int
        Bootstrap refits kept for intervals.
    seed : int
    use_rest : bool
        Use each flight's rest voltage before take-off as a data point.

    Returns
    -------
    dischargelab.fit.FitResult
    """
    from .fit import AUTO, fit_battery
    from .models import get_family

    if not isinstance(flights, FlightCurves):
        raise FitError(f"expected FlightCurves (from flight_curves), got {type(flights).__name__}")
    if strings_parallel < 1:
        raise FitError("strings_parallel must be at least 1")
    name = "ecm" if model == AUTO else model
    family = get_family(name)
    steady = model == AUTO and all(steady_current(c.current_A) for c in flights.curves)
    if steady:
        fixed = dict(STEADY_DRAIN_FIXED, **(fixed or {}))
    all_bounds = dict(flights.capacity_bounds(strings_parallel))
    all_bounds.update(bounds or {})
    c_bounds = all_bounds.get("C_Ah")
    all_fixed = flights.ocv_prior(family, strings_parallel,
                                  c_bounds or flights.prior_capacity_range(strings_parallel))
    all_fixed.update(fixed or {})
    if "C_Ah" in (fixed or {}):
        all_bounds.pop("C_Ah", None)
    result = fit_battery(list(flights.curves), cells_series=cells or flights.cells_series,
                         strings_parallel=strings_parallel, fixed=all_fixed, bounds=all_bounds,
                         use_rest=use_rest, bootstrap=bootstrap, seed=seed, model=name)
    notes = list(flights.notes)
    if steady:
        notes.insert(0, "model ecm chosen for flights, with its RC pairs and diffusion state "
                        "held absent (OCV and series resistance only): every flight is a "
                        "near-constant drain, which cannot show the cell's dynamics")
    elif model == AUTO:
        notes.insert(0, "model ecm chosen for flights (RC pairs driven by the logged current)")
    prior = [n for n in all_fixed if n.startswith("ocv_d") and n not in (fixed or {})]
    if prior:
        notes.append(f"{len(prior)} OCV interval{'s' if len(prior) > 1 else ''} beyond the "
                     f"flown range held at the "
                     f"{flights.chemistry} prior ({', '.join(prior)})")
    if c_bounds is not None and "C_Ah" not in (fixed or {}):
        value = float(result.parameters["C_Ah"])
        lo, hi = c_bounds
        if min(value - lo, hi - value) <= 5e-3 * (hi - lo):
            side = "smaller" if value - lo < hi - value else "larger"
            notes.append(f"C_Ah = {value:.4g} Ah per cell sits at its bound: the flights point "
                         f"to a {side} capacity than the label's ±{100 * CAPACITY_TOLERANCE:.0f} "
                         "% (an aged pack, a wrong label, or an OCV prior that does not fit "
                         "this pack)")
    result.notes = notes + list(result.notes)
    return result


# --------------------------------------------------------------------------- analyse a flight

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
    from .io.flightlog import choose_battery, read_flight_log
    from .model import CUTOFF_CELL_VOLTAGE_V

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
    numbers = _flight_numbers(log, flights)
    bat = None
    if model is not None:
        from .model import load_battery

        bat = load_battery(model)
    chemistry = check_chemistry(chemistry or (bat.chemistry if bat is not None else None))
    cells = _cells(series, cells, chemistry, notes)
    if bat is not None:
        bat = bat.with_pack(cells, parallel)
    capacity, capacity_source = _report_capacity(series, capacity_Ah, bat)
    cutoff = float(cutoff) if cutoff is not None else CUTOFF_CELL_VOLTAGE_V[chemistry]
    settings = _Settings(cells, parallel, capacity, chemistry, cutoff, replay_every_s,
                         recent_load_s, window_s, float(low_timer_s))
    if bat is not None and "fit_temperature_rise_K" not in bat.extra and bat.family.thermal:
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


@dataclass(frozen=True)
class _Settings:
    cells: int
    parallel: int
    capacity_Ah: float | None
    chemistry: str
    cutoff_cell_V: float
    replay_every_s: float
    recent_load_s: float
    window_s: float
    low_timer_s: float = LOW_VOLTAGE_TIMER_S

    @property
    def cutoff_pack_V(self) -> float:
        return self.cutoff_cell_V * self.cells


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


def _analyse_part(part: FlightSamples, series, s: _Settings, bat) -> FlightAnalysis:
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
        "charge_Ah": _trapezoid(i, t) / 3600.0,
        "energy_Wh": _trapezoid(i * v, t) / 3600.0,
        "mean_current_A": _trapezoid(i, t) / max(float(t[-1] - t[0]), 1e-9)
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
        predicted, model_summary, states = _fly_model(part, series, s, bat, notes)
        summary.update(model_summary)
        samples = samples.assign(predicted_voltage_V=predicted)
    else:
        states = {}
    replay = _replay(part, series, s, bat, states, predicted)
    summary["replay_mid_flight"] = _mid_flight(replay, part)
    return FlightAnalysis(part.number, summary, samples, resistance, replay,
                          notes + _rest_notes(part))


def _cutoff_crossings(t, v, s: _Settings, notes: list) -> dict:
    """When the logged voltage first went under the cutoff, and when it stayed there."""
    dip = _time_to(t, v, s.cutoff_pack_V, 0.0)
    reached = _time_to(t, v, s.cutoff_pack_V, 0.0, s.low_timer_s)
    out = {"cutoff_dip_at_s": dip if np.isfinite(dip) else None,
           "cutoff_reached_at_s": reached if np.isfinite(reached) else None}
    if np.isfinite(dip) and not (np.isfinite(reached) and reached <= dip):
        notes.append(f"the voltage dipped under the cutoff ({s.cutoff_cell_V:g} V/cell) at "
                     f"{dip:.1f} s for less than {s.low_timer_s:g} s: a sag at a current peak, "
                     f"which a low-voltage timer of {s.low_timer_s:g} s ignores"
                     + (f"; it stayed under it from {reached:.1f} s" if np.isfinite(reached)
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
            out["sag_cells_V"] = [float(r - frame[c].iloc[k]) for r, c in zip(rest.cells_V, cells)]
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


def _resistance_summary(windows: pd.DataFrame, s: _Settings) -> dict:
    good = windows[windows["determined"]] if len(windows) else windows
    pack = float(np.median(good["resistance_ohm"])) if len(good) else None
    logged = windows["log_resistance_ohm"].to_numpy(dtype=float) if len(windows) else np.array([])
    logged = logged[np.isfinite(logged)]
    return {"resistance_ohm": pack,
            "resistance_cell_ohm": None if pack is None else pack * s.parallel / s.cells,
            "resistance_windows_used": int(len(good)),
            "log_resistance_ohm": float(np.median(logged)) if logged.size else None}


def _charge_left(part: FlightSamples, s: _Settings, notes: list) -> dict:
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


# --------------------------------------------------------------------------- model and replay

def _engine_params(bat) -> dict:
    params = {n: float(bat.parameters[n]) for n in bat.family.names}
    if bat.family.thermal and "fit_temperature_rise_K" not in bat.extra:
        params["Cth_J_per_K"] = HELD_AT_AMBIENT_HEAT_CAPACITY
    return params


def _initial_model_charge(part: FlightSamples, series, bat, notes: list) -> tuple[float, str]:
    rest = part.rest_before
    if rest is not None:
        return model_charge_at_rest(bat, rest.voltage_V), \
            f"rest voltage {rest.voltage_V:.3f} V before take-off through the model's OCV"
    remaining = _log_remaining_at(series, part.frame["time_s"].iloc[0])
    if remaining is not None:
        return (1.0 - remaining) * bat.capacity_Ah, \
            "the log's own state-of-charge estimate at the first sample"
    frame = part.frame
    q0 = model_charge_at_rest(bat, float(frame["voltage_V"].iloc[0]),
                              float(frame["current_A"].iloc[0]))
    notes.append("initial charge from the first loaded sample through the model (its RC pairs "
                 "assumed settled at that current): no rest voltage before the flight")
    return q0, "first loaded sample through the model"


def _fly_model(part: FlightSamples, series, s: _Settings, bat, notes: list):
    """Predicted pack voltage at every sample, the model summary and the states at replay
    moments (``{sample index: engine state}``)."""
    from .engine import Step, run

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
        summary["rmse_cell_V"] = [float(np.sqrt(np.mean((per_cell - frame[c].to_numpy()[inside])
                                                        ** 2))) for c in cells]
    last = max(states) if states else None
    if last is not None:
        q_end = float(states[last]["charge_Ah"][0]) * bat.strings_parallel
        summary["charge_left_model_Ah"] = bat.capacity_Ah - q_end
    return predicted, summary, states


def _replay_rows(part: FlightSamples, s: _Settings) -> list[int]:
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
    return _trapezoid(i[sel], t[sel]) / float(t[sel][-1] - t[sel][0])


def _replay(part: FlightSamples, series, s: _Settings, bat, states: dict,
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
               "model_logged_load_s": _time_to(t[ok & after], None if predicted is None else
                                               predicted[ok & after], s.cutoff_pack_V, t[k],
                                               s.low_timer_s),
               "px4_s": float("nan"), "ardupilot_s": float("nan"),
               "true_s": _time_to(t[inside & after], v[inside & after], s.cutoff_pack_V, t[k],
                                  s.low_timer_s),
               "first_dip_s": _time_to(t[inside & after], v[inside & after], s.cutoff_pack_V,
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
                             s: _Settings) -> float:
    """Time [s] until the cutoff when the recent load profile repeats, peaks included.

    The last ``recent_load_s`` of logged current, averaged in :data:`PROFILE_BIN_S`
    bins, is flown again and again from the engine ``state`` (enough repetitions to
    empty the pack at its mean current, twice over, bounded), and the cutoff is
    reached as in the log: the voltage stays at or below it ``low_timer_s``. A pack
    whose cutoff is set by load peaks reaches it sooner than at the mean load.
    """
    from .engine import Step, run

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
    return _time_to(np.asarray(series["time_s"], dtype=float),
                    np.asarray(series["voltage_V"], dtype=float), s.cutoff_pack_V, 0.0,
                    s.low_timer_s)


def _time_to(t, v, cutoff_V: float, now_s: float, hold_s: float = 0.0) -> float:
    """Time [s] from ``now_s`` until ``v`` goes to or below ``cutoff_V`` and stays there
    ``hold_s`` [s] (:func:`dischargelab.validate.measured_time_to_cutoff`; NaN if never)."""
    from .validate import measured_time_to_cutoff

    if v is None or np.size(t) == 0:
        return float("nan")
    return measured_time_to_cutoff(t, v, cutoff_V, hold_s) - now_s


def _model_remaining(bat, state: dict, load_A: float, s: _Settings) -> float:
    """Time [s] from the engine ``state`` at a constant ``load_A`` [A] until the cutoff."""
    from .engine import Step, run

    try:
        res = run(bat.family, _engine_params(bat), [Step("current", load_A)],
                  cutoff_pack_V=s.cutoff_pack_V,
                  cells_series=bat.cells_series, strings_parallel=bat.strings_parallel,
                  ambient_C=bat.ambient_C, initial_state=state)
    except SimulationError:  # the model never reaches the cutoff at this load
        return float("nan")
    return float(res.end_s[0]) if res.ended_by[0] == "cutoff" else float("nan")


def _px4_remaining_frac(series, frame, k: int, s: _Settings) -> float:
    """PX4-style remaining fraction: the log's ``remaining`` if logged, else from voltage."""
    t_k = float(frame["time_s"].iloc[k])
    logged = _log_remaining_at(series, t_k)
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


def _mid_flight(replay: pd.DataFrame, part: FlightSamples) -> dict | None:
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


# --------------------------------------------------------------------------- plot

def plot_flight_report(report: FlightReport, axes=None):
    """Voltage (logged, predicted), current and remaining-time replay against log time.

    Parameters
    ----------
    report : FlightReport
    axes : sequence of three matplotlib Axes, optional

    Returns
    -------
    numpy.ndarray of Axes
    """
    from .plot import pyplot

    plt = pyplot()
    if axes is None:
        fig, axes = plt.subplots(3, 1, figsize=(9, 8.5), sharex=True, layout="constrained",
                                 gridspec_kw={"height_ratios": [3, 2, 3]})
    axes = np.asarray(axes)
    av, ai, ar = axes
    seen = set()

    def label(text):
        if text in seen:
            return None
        seen.add(text)
        return text

    tops = []
    for f in report.flights:
        smp = f.samples
        t = smp["time_s"].to_numpy()
        av.plot(t, smp["voltage_V"], color="0.35", lw=0.6, label=label("logged"))
        if "predicted_voltage_V" in smp:
            av.plot(t, smp["predicted_voltage_V"], color="tab:orange", lw=0.8, alpha=0.85,
                    label=label("model flying the logged current"))
        ai.plot(t, smp["current_A"], color="tab:blue", lw=0.6)
        for ax in axes:
            ax.axvspan(f.summary["start_s"], f.summary["end_s"], color="0.94", zorder=0)
        tops.append(_plot_replay(ar, f.replay, label))
    av.axhline(report.cutoff_cell_V * report.cells_series, color="tab:red", ls="--", lw=0.8,
               label=label(f"cutoff {report.cutoff_cell_V:g} V/cell"))
    av.set_ylabel("pack voltage [V]")
    ai.set_ylabel("current [A]")
    ar.set_ylabel("remaining flight time [s]")
    ar.set_xlabel("log time [s] (flights shaded)")
    limits = [x for x in tops if x is not None]
    if limits:
        ar.set_ylim(0, max(limits))
        ar.legend(fontsize=8, loc="upper right")
    else:
        ar.text(0.5, 0.5, "no remaining-time replay: give a battery model or the pack capacity",
                transform=ar.transAxes, ha="center", va="center", color="0.4")
    title = f"{Path(report.source).name}: {report.battery_label} ({report.cells_series} cells " \
            "in series)"
    if report.model:
        title += f"; model {report.model}"
    av.set_title(title, fontsize=10)
    av.legend(fontsize=8, loc="upper right")
    for ax in axes:
        ax.grid(True, lw=0.3, alpha=0.6)
    return axes


def _plot_replay(ax, replay: pd.DataFrame, label) -> float | None:
    """Draw the replay columns; returns a y-limit that keeps the bulk visible (or None)."""
    if replay.empty:
        return None
    t = replay["time_s"].to_numpy()
    styles = [("true_s", "truth: logged voltage stays under the cutoff", "k", "-", None),
              ("model_profile_s", "model repeating the recent load (peaks kept)", "tab:red",
               "-", "D"),
              ("model_s", "model at the recent mean load", "tab:orange", "-", "o"),
              ("model_logged_load_s", "model flying the logged load (hindsight)", "tab:orange",
               ":", None),
              ("px4_s", "PX4 method (remaining x capacity / mean current)", "tab:green", "-",
               "^"),
              ("ardupilot_s", "ArduPilot method ((capacity - used) / mean current)",
               "tab:purple", "-", "s")]
    values = []
    for column, text, color, ls, marker in styles:
        y = replay[column].to_numpy(dtype=float)
        m = np.isfinite(y)
        if m.any():
            ax.plot(t[m], y[m], color=color, ls=ls, marker=marker, ms=3, lw=1.0, label=label(text))
            values.append(y[m])
    if not values:
        return None
    every = np.concatenate(values)
    return float(min(np.max(every), 2.0 * np.percentile(every, 75))) * 1.05


__all__ = ["GENERIC_OCV_V", "OCV_SOC", "FlightCurves", "FlightReport", "FlightAnalysis",
           "RestVoltage", "flight_curves", "fit_flights", "analyse_flight",
           "soc_from_rest_voltage", "ocv_from_soc", "resistance_windows", "infer_cells",
           "model_charge_at_rest", "plot_flight_report"]
