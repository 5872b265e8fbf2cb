"""Fitting a battery model from flights that neither start full nor reach the cutoff
(:func:`flight_curves`, :func:`fit_flights`); see the package docstring."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError, FitError
from ..fit.family import one_steady_rate, steady_current  # noqa: F401  (steady_current: API)
from ..ocv import (
    OCV_SOURCE,
    check_chemistry,
    model_charge_at_rest,
    ocv_from_soc,
    soc_from_rest_voltage,
    soc_per_10mV,
)
from .samples import (
    REST_WINDOW_S,
    FlightSamples,
    cell_count,
    flight_numbers,
    flight_samples,
    log_remaining_at,
)

#: The capacity is held within this fraction of the label when the flights do not
#: reach the knee of the OCV curve.
CAPACITY_TOLERANCE = 0.10


#: Flights ending at or below this state of charge [-] reach the knee of the OCV curve
#: (below it the generic curves steepen): there they determine the capacity.
KNEE_SOC = 0.15


#: A rest voltage after landing counts for the knee only this long after the load [s]
#: (sooner, the cells are far from their open-circuit voltage).
KNEE_REST_S = 30.0


#: Flights that reach the knee determine the capacity; the OCV prior still holds the
#: intervals they cannot reach for any capacity up to this factor times the label.
KNEE_PRIOR_CAPACITY_FACTOR = 1.3


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
        from ..models.ecm import OCV_DROP_NAMES, OCV_NODES

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
        Flight log (ArduPilot, PX4 ULog, blackbox, MAVLink .tlog, in-flight logger CSV).
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
    from ..fit import Curve
    from ..io.flightlog import choose_battery, read_flight_log

    path = Path(path)
    chemistry = check_chemistry(chemistry)
    log = read_flight_log(path)
    series, battery_notes = choose_battery(log, battery)
    numbers = flight_numbers(log, flights)
    cells = cell_count(series, cells, chemistry, battery_notes)
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
    from ..model import load_battery

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
    remaining = log_remaining_at(series, part.frame["time_s"].iloc[0])
    if remaining is not None:
        row.update(soc_start=remaining, initial_charge_Ah=(1.0 - remaining) * capacity,
                   source="the log's own state-of-charge estimate at the first sample (no rest "
                          "voltage before the flight)")
        return row
    raise DataError(f"{path.name}: flight {part.number} has no rest voltage before take-off and "
                    "the log has no state-of-charge estimate, so its initial charge is unknown; "
                    "choose flights that start on the ground (--flight N)")


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
        notes.append("the log has no battery temperature: the fit simulates the cells' "
                     "self-heating with a thermal prior for a pack in the airflow of flight "
                     "(see the fit's notes)")
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
        state driven by the logged current when it varies, else (near-constant drains
        at one rate, :func:`~dischargelab.fit.family.one_steady_rate`) with those held
        absent (OCV and series resistance only: one constant current cannot show the
        cell's dynamics, and RC pairs fitted to it extrapolate to other currents badly;
        the fit does this for any ``ecm`` fit of such data).
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
    from ..fit import AUTO, fit_battery
    from ..models import get_family

    if not isinstance(flights, FlightCurves):
        raise FitError(f"expected FlightCurves (from flight_curves), got {type(flights).__name__}")
    if strings_parallel < 1:
        raise FitError("strings_parallel must be at least 1")
    name = "ecm" if model == AUTO else model
    family = get_family(name)
    steady = model == AUTO and one_steady_rate(flights.curves)
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
                         use_rest=use_rest, bootstrap=bootstrap, seed=seed, model=name,
                         cooling="airflow", chemistry=flights.chemistry)
    notes = list(flights.notes)
    if steady:
        notes.insert(0, "model ecm chosen for flights, with its RC pairs held absent and its "
                        "diffusion lead at a prior (OCV and series resistance fitted): the "
                        "flights are near-constant drains at one rate, which cannot show the "
                        "cell's dynamics")
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
