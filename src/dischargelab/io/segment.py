"""Find the discharge in a canonical frame: sign, load segments, rest sample.

Works on canonical columns (``time_s``, ``voltage_V``, ``current_A``; optional
``soc_pct``, ``flight_mode``). The rules, stated once:

* **Load threshold.** A row carries load when its discharge current exceeds
  ``IDLE_FRACTION`` (20 %) of the load level, the 98th percentile of the
  positive currents (and at least ``MIN_LOAD_A``, 1 mA, or for a cell in mA or uA
  ``SMALL_LOAD_NOISE_FACTOR`` times its current's noise and resolution, see
  :func:`load_floor`). Below that in
  magnitude a row is *idle* (rest before the load, relaxation after it, or a
  landed aircraft); a current beyond it in the other direction is *charge*.
  Rows whose ``flight_mode`` is ``LANDED`` are idle.
* **Segments.** A segment is a run of consecutive load rows. It also ends at a
  pack swap (state of charge up by ``SOC_JUMP_PCT`` or more, or voltage up by
  more than ``VOLTAGE_JUMP_FRACTION`` without the current falling), at a
  take-off or landing event supplied by the reader, and, for variable current
  without flight modes, at a gap in the samples longer than ``GAP_FACTOR``
  times the usual sampling interval. When the frame has a ``flight_mode``
  column the flight events decide and gaps do not split (a flight log pauses
  while the app reconnects, even in flight). Runs shorter than
  ``MIN_SEGMENT_ROWS`` rows are not segments.
* **Choice.** By default the longest segment (in time); an integer picks the
  N-th (counting from 1).
* **Rest sample.** The idle row just before the chosen segment is its rest
  sample (open-circuit voltage before the load step, used for ``R = dV/dI``
  and ``E0``). When the current is given rather than measured, the first row is
  the rest sample if the voltage step to the second row is more than
  ``REST_STEP_FACTOR`` times the typical step of the next ten rows (the
  instantaneous ohmic drop at switch-on).
* **Sign.** Discharge makes the voltage fall. In each run of loaded rows of one
  current sign the voltage trend says whether that sign is discharge; runs vote
  by duration (steps larger than ``VOLTAGE_JUMP_FRACTION`` are ignored as pack
  swaps). Without a clear trend, the sign carrying most charge is taken as the
  discharge.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..cell import charge_from_current
from ..errors import DataError

IDLE_FRACTION = 0.2
LOAD_PERCENTILE = 98.0
MIN_SEGMENT_ROWS = 3
SOC_JUMP_PCT = 5.0
VOLTAGE_JUMP_FRACTION = 0.05
GAP_FACTOR = 4.0
VARIABLE_SPREAD = 0.05
REST_STEP_FACTOR = 10.0
#: Currents below 1 mA are idle whatever the load level (logger noise).
MIN_LOAD_A = 1e-3
SENTINEL_ABS = 1e30
#: A small cell's load (below 1 mA) counts when it is this many times the current's
#: sample noise and its logging resolution.
SMALL_LOAD_NOISE_FACTOR = 10.0

CUT_REASONS = {1: "state of charge jumps up (pack swap?)", 2: "voltage jumps up (pack swap?)",
               3: "take-off or landing event", 4: "gap in the samples"}


@dataclass
class Segment:
    """One discharge segment: rows ``start`` to ``stop - 1`` (positions in the frame)."""

    number: int
    start: int
    stop: int
    ended_by: str

    @property
    def rows(self) -> int:
        return self.stop - self.start


@dataclass
class SegmentSearch:
    """Result of :func:`find_segments`.

    Attributes
    ----------
    state : numpy.ndarray of int
        Per row: 1 load, 0 idle, -1 charge.
    segments : list of Segment
    short_rows : numpy.ndarray of bool
        Load rows in runs too short to be segments.
    threshold_A : float
        Idle/load threshold [A].
    load_level_A : float
        Load level [A] (98th percentile of the positive currents).
    variable : bool
        True when the load current varies (flight log), False for constant current.
    """

    state: np.ndarray
    segments: list[Segment]
    short_rows: np.ndarray
    threshold_A: float
    load_level_A: float
    variable: bool
    gap_limit_s: float | None = None
    notes: list[str] = field(default_factory=list)


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True values."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))


def detect_sign(time_s, current_A, voltage_V) -> tuple[int, str]:
    """Which current sign is discharge in a file: +1 or -1, with the evidence.

    Parameters
    ----------
    time_s, current_A, voltage_V : array_like
        As in the file (any sign convention), without NaN.

    Returns
    -------
    sign : int
        +1 when discharge current is positive in the file, -1 when negative.
    evidence : str
        One sentence saying why.
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    v = np.asarray(voltage_V, dtype=float)
    if i.size == 0 or not np.any(i != 0):
        return 1, "no current flows"
    level = np.percentile(np.abs(i), LOAD_PERCENTILE)
    loaded = np.abs(i) > IDLE_FRACTION * level
    tolerance_V = 1e-3 * float(np.median(np.abs(v)))
    score = 0.0
    votes = {1: 0, -1: 0}
    for sign in (1, -1):
        for start, stop in runs(loaded & (np.sign(i) == sign)):
            if stop - start < MIN_SEGMENT_ROWS:
                continue
            dv = charge_trend_V(t[start:stop], np.abs(i[start:stop]), v[start:stop])
            if abs(dv) <= tolerance_V:
                continue
            vote = -np.sign(dv) * sign  # +1: positive current is discharge
            score += vote * max(t[stop - 1] - t[start], 1e-9)
            votes[int(vote)] += 1
    if score > 0:
        return 1, (f"the voltage falls while the current is positive "
                   f"({votes[1]} run(s) agree, {votes[-1]} disagree)")
    if score < 0:
        return -1, (f"the voltage falls while the current is negative "
                    f"({votes[-1]} run(s) agree, {votes[1]} disagree)")
    dt = np.gradient(t) if t.size > 1 else np.ones_like(t)
    charge = float(np.sum(i[loaded] * dt[loaded]))
    sign = 1 if charge >= 0 else -1
    return sign, ("no clear voltage trend; the current is mostly "
                  + ("positive" if sign > 0 else "negative"))


def charge_trend_V(t: np.ndarray, i: np.ndarray, v: np.ndarray) -> float:
    """The voltage change [V] a loaded run's charge explains: ``v = a + b q + c |i|``
    fitted by least squares over each stretch between jumps (a jump of more than
    :data:`VOLTAGE_JUMP_FRACTION` is a pack swap, not a trend), ``b q`` summed. The
    ``c |i|`` term takes the drop that follows the current's level, so a run that starts
    at a take-off burst and ends at a light hover still falls with its charge."""
    jumps = np.flatnonzero(np.abs(np.diff(v)) > VOLTAGE_JUMP_FRACTION * np.abs(v[:-1])) + 1
    total = 0.0
    for a, b in zip(np.concatenate(([0], jumps)), np.concatenate((jumps, [v.size]))):
        if b - a < MIN_SEGMENT_ROWS:
            continue
        q = charge_from_current(t[a:b], i[a:b])
        if q[-1] <= 0:
            continue
        level = i[a:b] - i[a:b].mean()
        columns = [np.ones(b - a), q / q[-1]] + ([level] if np.ptp(level) > 0 else [])
        coef = np.linalg.lstsq(np.column_stack(columns), v[a:b], rcond=None)[0]
        total += float(coef[1])
    return total


def load_floor(current_A) -> float:
    """Smallest load current [A]: :data:`MIN_LOAD_A`, or less for a small cell whose
    current is resolved (:data:`SMALL_LOAD_NOISE_FACTOR` times the larger of its sample
    noise, from the median step between consecutive samples, and the logger's resolution,
    its smallest step)."""
    i = np.asarray(current_A, dtype=float)
    i = i[np.isfinite(i)]
    if i.size < 3:
        return MIN_LOAD_A
    steps = np.abs(np.diff(i))
    nonzero = steps[steps > 0]
    if nonzero.size == 0:
        return MIN_LOAD_A
    noise = max(float(np.median(steps)) / np.sqrt(2.0), float(np.min(nonzero)))
    return float(min(MIN_LOAD_A, SMALL_LOAD_NOISE_FACTOR * noise))


def voltage_jumps_up(voltage_V, current_A, threshold_A: float) -> np.ndarray:
    """Per step from row ``k - 1`` to row ``k``: the voltage rose by more than
    :data:`VOLTAGE_JUMP_FRACTION` while the current (discharge positive) did not fall by
    more than ``threshold_A`` [A]: a pack swap. A load's end lifts the voltage by its
    resistive drop, 5-10 % at 2C and more (that is a rest beginning, not another pack)."""
    v = np.asarray(voltage_V, dtype=float)
    i = np.asarray(current_A, dtype=float)
    return (np.diff(v) > VOLTAGE_JUMP_FRACTION * v[:-1]) & (i[1:] >= i[:-1] - threshold_A)


def find_segments(frame: pd.DataFrame, *, breaks_s=(), threshold_A: float | None = None
                  ) -> SegmentSearch:
    """Split a canonical frame (discharge positive, no NaN) into discharge segments.

    Parameters
    ----------
    frame : pandas.DataFrame
        ``time_s``, ``voltage_V``, ``current_A`` (discharge positive); optional
        ``soc_pct`` and ``flight_mode``.
    breaks_s : sequence of float
        Times [s] (same clock as ``time_s``) at which a segment must end, e.g.
        take-off and landing events.
    threshold_A : float, optional
        Idle/load threshold [A]; default ``IDLE_FRACTION`` x load level, at
        least ``MIN_LOAD_A``.

    Raises
    ------
    DataError
        When no row carries discharge current.
    """
    t = frame["time_s"].to_numpy(dtype=float)
    v = frame["voltage_V"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    n = t.size
    positive = i[i > 0]
    if positive.size == 0:
        raise DataError("no discharge found: the current is never positive (discharge) "
                        "after the sign convention was applied")
    level = float(np.percentile(positive, LOAD_PERCENTILE))
    if threshold_A is None:
        threshold = max(IDLE_FRACTION * level, load_floor(i))
    else:
        threshold = float(threshold_A)
    state = np.where(i > threshold, 1, np.where(i < -threshold, -1, 0))
    if "flight_mode" in frame:
        landed = frame["flight_mode"].astype(str).str.upper().to_numpy() == "LANDED"
        state = np.where(landed & (state == 1), 0, state)
    load = state == 1
    if not load.any():
        raise DataError("no discharge found: no row carries discharge current")

    load_i = i[load]
    median_i = float(np.median(load_i))
    spread = (np.percentile(load_i, 75) - np.percentile(load_i, 25)) / max(median_i, 1e-12)
    variable = bool(spread > VARIABLE_SPREAD)

    # cut[k] > 0: a segment cannot continue from row k-1 into row k (code into CUT_REASONS).
    cut = np.zeros(n, dtype=np.int8)
    gap_limit = None
    if n > 1:
        step = cut[1:]
        if "soc_pct" in frame:
            soc = frame["soc_pct"].to_numpy(dtype=float)
            step[np.diff(soc) >= SOC_JUMP_PCT] = 1
        step[voltage_jumps_up(v, i, threshold) & (step == 0)] = 2
        breaks = np.sort(np.asarray(list(breaks_s), dtype=float))
        if breaks.size:
            # a break strictly after row k-1 and at or before row k
            after = np.searchsorted(breaks, t[:-1], side="right")
            next_break = breaks[np.minimum(after, breaks.size - 1)]
            has_break = (after < breaks.size) & (next_break <= t[1:])
            step[has_break & (step == 0)] = 3
        both = load[1:] & load[:-1]
        if variable and both.any() and "flight_mode" not in frame:
            gap_limit = GAP_FACTOR * float(np.median(np.diff(t)[both]))
            step[(np.diff(t) > gap_limit) & (step == 0)] = 4

    previous_load = np.concatenate(([False], load[:-1]))
    starts = load & (~previous_load | (cut > 0))
    seg_id = np.cumsum(starts)
    seg_id[~load] = 0
    changes = np.flatnonzero(np.diff(seg_id) != 0) + 1
    segments: list[Segment] = []
    short = np.zeros(n, dtype=bool)
    for start in np.flatnonzero(starts).tolist():
        k = np.searchsorted(changes, start, side="right")
        stop = int(changes[k]) if k < changes.size else n
        if stop - start < MIN_SEGMENT_ROWS:
            short[start:stop] = True
            continue
        if stop >= n:
            ended = "end of file"
        elif state[stop] == 1:
            ended = CUT_REASONS.get(int(cut[stop]), "split")
        elif state[stop] == -1:
            ended = "charge follows"
        elif "flight_mode" in frame and str(frame["flight_mode"].iloc[stop]).upper() == "LANDED":
            ended = "landed"
        else:
            ended = "current falls to idle"
        segments.append(Segment(len(segments) + 1, start, stop, ended))
    return SegmentSearch(state=state, segments=segments, short_rows=short, threshold_A=threshold,
                         load_level_A=level, variable=variable, gap_limit_s=gap_limit)


def choose_segment(search: SegmentSearch, frame: pd.DataFrame, segment) -> Segment:
    """The segment to keep: ``"auto"`` (longest in time) or the N-th, counting from 1."""
    found = search.segments
    if not found:
        raise DataError(f"no discharge found: no run of {MIN_SEGMENT_ROWS} or more rows with "
                        f"discharge current above {search.threshold_A:.3g} A")
    t = frame["time_s"].to_numpy(dtype=float)
    if segment == "auto":
        durations = [t[s.stop - 1] - t[s.start] for s in found]
        return found[int(np.argmax(durations))]
    k = int(segment)
    if not 1 <= k <= len(found):
        raise DataError(f"--segment {k}: the file has {len(found)} discharge segment(s); "
                        f"choose 1 to {len(found)} (counting from 1)")
    return found[k - 1]


def voltage_step_rest(voltage_V) -> tuple[bool, str]:
    """Is the first row a rest sample? (for a current that is given, not measured).

    True when the voltage drop from row 0 to row 1 exceeds ``REST_STEP_FACTOR``
    times the median step over the next ten rows: the instantaneous ohmic drop
    when the load is switched on.
    """
    v = np.asarray(voltage_V, dtype=float)
    if v.size < 4:
        return False, "too few rows to tell"
    first = v[0] - v[1]
    typical = float(np.median(np.abs(np.diff(v[1:12]))))
    if first > 0 and first > REST_STEP_FACTOR * max(typical, 1e-12):
        return True, (f"the voltage drops {first * 1e3:.1f} mV from the first row to the second, "
                      f"{first / max(typical, 1e-12):.0f} times the typical step after it "
                      "(load switched on after the first row)")
    return False, "no voltage step after the first row"


__all__ = ["detect_sign", "charge_trend_V", "find_segments", "choose_segment",
           "voltage_step_rest", "runs",
           "Segment", "SegmentSearch", "IDLE_FRACTION", "MIN_SEGMENT_ROWS", "SENTINEL_ABS",
           "SOC_JUMP_PCT", "VOLTAGE_JUMP_FRACTION", "voltage_jumps_up", "GAP_FACTOR",
           "REST_STEP_FACTOR",
           "MIN_LOAD_A"]
