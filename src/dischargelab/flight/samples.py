"""The flights of one battery as samples: rest voltages on either side, resampling,
cell count, and the settings of an analysis."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError
from ..ocv import CHARGE_CELL_V, LIHV_FULL_CELL_V, check_chemistry
from ..validate import LOW_VOLTAGE_TIMER_S

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
        return trapezoid(i[keep], t[keep]) / 3600.0


def trapezoid(y, x) -> float:
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
    from ..io.flightlog import MIN_ON_A, ON_FRACTION

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
    cells_V = tuple(_finite_median(frame[c].to_numpy(dtype=float)[rows]) for c in cells) \
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
    from ..io.flightlog import OFF_RATIO

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


def flight_numbers(log, flights) -> list[int]:
    from ..io.flightlog import choose_span

    if not log.spans:
        raise DataError(f"{Path(log.source).name}: no flight found (no arm/disarm, take-off/"
                        "landing or sustained current)")
    if flights is None:
        return [s.number for s in log.spans]
    numbers = [flights] if isinstance(flights, (int, np.integer)) else list(flights)
    if not numbers:
        raise DataError("flights is empty; give flight numbers counting from 1 or leave it out")
    return [choose_span(log, int(n)).number for n in numbers]


#: The lowest a LiPo pack's highest voltage per cell is read at [V]: a pack whose log
#: never rises above it is near empty throughout (3.3 V rests below 5 % of charge on the
#: generic LiPo curve), so a count that puts it there is one cell too many for a
#: high-voltage pack (a 1S LiHV cell at 4.35 V is not two cells at 2.2 V).
LOWEST_TOP_CELL_V = 3.3


def infer_cells(voltage_V, chemistry: str | None = None) -> int:
    """Cells in series of a pack from its highest voltage [V]: the fewest cells that stay
    at or below the chemistry's charge voltage (:data:`CHARGE_CELL_V`) plus 0.05 V; for a
    LiPo pack, one fewer when that count reads below :data:`LOWEST_TOP_CELL_V` per cell and
    one fewer holds the high-voltage (LiHV) charge voltage plus 0.05 V."""
    values = np.asarray(voltage_V, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        raise DataError("no voltage to infer the cell count from; give cells=N (--cells N)")
    top = float(np.percentile(values, 99))
    chem = check_chemistry(chemistry)
    n = max(1, int(np.ceil(top / (CHARGE_CELL_V[chem] + 0.05))))
    if chem == "lipo" and n > 1 and top / n < LOWEST_TOP_CELL_V \
            and top / (n - 1) <= LIHV_FULL_CELL_V + 0.05:
        n -= 1
    return n


#: Rest voltage per cell of a lithium pack just charged full [V]: LiFePO4 (3.65 V charge),
#: and LiPo / Li-ion (4.20 V) with high-voltage LiPo (4.35 V), resting up to a few tens of
#: millivolts below their charge voltage (and a little above it at worst).
FULL_REST_CELL_V = ((3.30, 3.65), (4.05, 4.40))

#: A smart battery's own state of charge [%] that counts as full for
#: :func:`cells_from_gauge`.
GAUGE_FULL_PCT = 95.0


def cells_from_gauge(voltage_V, current_A, soc_pct) -> int | None:
    """Cells in series from a smart battery's own state of charge (a DJI log's
    ``soc_pct``): the one count for which the pack's idle voltage while the gauge reads at
    least :data:`GAUGE_FULL_PCT` is a full cell's rest voltage (:data:`FULL_REST_CELL_V`).

    A 6S high-voltage pack at 26.1 V when full is 4.35 V per cell, not a 7S pack at 3.73 V
    (:func:`infer_cells` cannot tell them from the voltage alone).

    Returns
    -------
    int or None
        None when the gauge never reads full at idle, or more or fewer than one count fits.
    """
    v = np.asarray(voltage_V, dtype=float)
    i = np.abs(np.asarray(current_A, dtype=float))
    soc = np.asarray(soc_pct, dtype=float)
    ok = np.isfinite(v) & np.isfinite(i) & np.isfinite(soc)
    if not ok.any():
        return None
    idle = i <= 0.1 * float(np.percentile(i[ok], 98))
    full = ok & idle & (soc >= GAUGE_FULL_PCT)
    if not full.any():
        return None
    pack = float(np.median(v[full]))
    fits = [n for n in range(1, 1 + int(pack / FULL_REST_CELL_V[0][0]))
            if any(lo <= pack / n <= hi for lo, hi in FULL_REST_CELL_V)]
    return fits[0] if len(fits) == 1 else None


def cell_count(series, cells, chemistry: str, notes: list) -> int:
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


def log_remaining_at(series, time_s: float) -> float | None:
    frame = series.frame
    if "log_remaining_frac" not in frame:
        return None
    t = frame["time_s"].to_numpy(dtype=float)
    r = frame["log_remaining_frac"].to_numpy(dtype=float)
    ok = np.isfinite(r) & (r >= 0) & (t <= time_s + 1.0)
    if not ok.any():
        return None
    return float(np.clip(r[np.flatnonzero(ok)[-1]], 0.0, 1.0))


@dataclass(frozen=True)
class Settings:
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


def _finite_median(values: np.ndarray) -> float:
    """Median of the finite values (a masked cell sample is NaN); NaN when none."""
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if finite.size else float("nan")
