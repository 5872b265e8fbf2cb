"""A long log as events: discharges, charges, rests and gaps, each with its own figures.

One file can hold a day of flights, a charger session, a BMS log or a tester's
whole life of a cell. :func:`split_log` cuts its rows into events:

* **With the tester's step numbers** (``step_index``, and ``cycle_index`` when
  given): one event per step, its kind from the step's median current (charge,
  rest or discharge); consecutive steps of one kind (a constant-current then a
  constant-voltage charge) form one event.
* **Otherwise from the current and the time:** a row is idle when the current is
  within the idle threshold of zero (:func:`idle_threshold`: three times the
  quietest current of the log, at least :data:`MIN_IDLE_A` or, for a small cell whose
  current stands above its noise, that share of its load, at most
  :data:`IDLE_MAX_SHARE` of the load level), discharging above it and charging
  below it. An idle stretch shorter than :data:`MIN_REST_S` between two loads of
  one kind belongs to them (a flight's low-throttle moments, a tester's pause of one
  sample), so does a stretch of the other sign shorter than :data:`MIN_BLIP_S`.
* **Gaps:** where consecutive samples are more than :func:`gap_limit` apart the
  logger was off; a gap event sits there and no event spans it. With step numbers only
  an interval between two steps is a gap (a tester records a long step sparsely and
  always records a step's start); without them, a long interval inside a steady load
  (same sign, current within :data:`SPARSE_LOAD_SHARE`) is the load recorded sparsely,
  and the longest such interval sets the pace below which an idle interval is no gap.

:func:`rest_reading` gives a rest's reading for the events on either side: its
voltage at the end, how far it has relaxed and what it relaxes to
(:func:`dischargelab.logbook.relaxation.relaxation`), its idle current and
temperature. :func:`charge_figures` gives a charge's: charge moved and whether it
ended in a constant-voltage taper (full, as the charger defines it).

Kinds (``KINDS``): ``"discharge"`` (a bench or tester discharge, a mission, a
capacity test), ``"flight"`` (a discharge read from a flight log), ``"charge"``,
``"rest"``, ``"gap"``.

References
----------
.. [1] cellpy and BEEP documentation: cycler data as cycles and steps, one kind per
   step (the tester's own numbering).
.. [2] Texas Instruments, SLUA364B (relaxation and charge-termination states of a
   fuel gauge: a taper current at the charge voltage means full).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .cells import cell_columns, cell_figures
from .estimates import counted_charge, sampling_figures, step_resistance
from .relaxation import relaxation

#: Event kinds.
KINDS = ("discharge", "flight", "charge", "rest", "gap")

#: Smallest idle threshold [A] (logger noise).
MIN_IDLE_A = 0.005

#: Idle threshold: this many times the quietest current of the log ...
IDLE_QUIET_FACTOR = 3.0

#: ... and this many times the current's sample noise (second differences), ...
IDLE_NOISE_FACTOR = 5.0

#: ... at most this share of the load level (98th percentile of |current|).
IDLE_MAX_SHARE = 0.1

#: Rows of the rolling median that finds the quietest current.
QUIET_WINDOW = 5

#: A gap is a sample interval longer than this many times the median interval ...
GAP_FACTOR = 10.0

#: ... and than this [s].
MIN_GAP_S = 60.0

#: Without step numbers, a long interval between two samples of one load whose currents
#: differ by at most this share is the load recorded sparsely, not a gap.
SPARSE_LOAD_SHARE = 0.25
#: ... and a log recorded that sparsely inside its loads has a gap only where its samples
#: are more than this many times its longest interval inside a load apart.
SPARSE_GAP_FACTOR = 2.0

#: Idle stretches shorter than this [s] between two loads of one kind belong to them.
MIN_REST_S = 60.0

#: Stretches of the other sign (or load between rests) shorter than this [s] belong to
#: their neighbours.
MIN_BLIP_S = 10.0

#: A charge ends in a constant-voltage taper when its current has fallen below this share
#: of its median current while the voltage stayed within :data:`TAPER_HOLD_CELL_V` per
#: cell of its highest value, and stayed below it to the end (the samples between the
#: taper and the rest may fall in voltage: a log resampled between a record every few
#: minutes draws a ramp from the taper's last sample to the rest's first).
TAPER_SHARE = 0.3
TAPER_HOLD_CELL_V = 0.015

#: Bound on the passes that absorb short stretches into their neighbours.
MAX_PASSES = 5

#: Points of the compact charge-voltage curve kept per discharge or charge (fewer when
#: the event has fewer samples).
CURVE_POINTS = 101

#: The end of a discharge is at its knee when the voltage falls this many times faster
#: over the last :data:`KNEE_SPAN` of its charge than over the middle (20-80 %) of it.
KNEE_RATIO = 4.0

#: Share of the charge over which the end slope is measured.
KNEE_SPAN = 0.03

#: A log is split into events by :func:`split_log` (rather than by its discharge
#: segments) when it has the tester's step numbers or charges moving at least this share
#: of the charge its discharges move.
LONG_LOG_CHARGE_SHARE = 0.05


@dataclass
class Span:
    """Rows ``start`` to ``stop - 1`` of a log as one event (a gap has ``start == stop``,
    the first row after it)."""

    kind: str
    start: int
    stop: int
    steps: tuple = ()

    @property
    def rows(self) -> int:
        return self.stop - self.start


def idle_threshold(current_A) -> float:
    """Current below which a row is idle [A] (see the module docstring): the larger of
    :data:`IDLE_QUIET_FACTOR` times the quietest current (the lowest rolling median of
    ``|i|``) and :data:`IDLE_NOISE_FACTOR` times the current's sample noise, at least
    :data:`MIN_IDLE_A` (or, for a cell in mA or uA whose current stands above that noise,
    :data:`IDLE_MAX_SHARE` of its load level), at most :data:`IDLE_MAX_SHARE` of the load
    level."""
    from .estimates import sample_noise

    i = np.asarray(current_A, dtype=float)
    a = np.abs(i)
    if a.size == 0:
        return MIN_IDLE_A
    level = float(np.percentile(a, 98))
    w = min(QUIET_WINDOW, a.size)
    quiet = float(np.min(np.median(np.lib.stride_tricks.sliding_window_view(a, w), axis=1)))
    # a small cell (mA or uA) has its idle threshold in proportion to its load, as long as
    # its current stands above its own noise; else (a logger's noise, no load) MIN_IDLE_A
    least = min(MIN_IDLE_A, IDLE_MAX_SHARE * level)
    top = max(least, IDLE_MAX_SHARE * level)
    floor = max(IDLE_QUIET_FACTOR * quiet, IDLE_NOISE_FACTOR * sample_noise(i), least)
    if floor > top and level < MIN_IDLE_A / IDLE_MAX_SHARE:
        return MIN_IDLE_A
    return float(min(floor, top))


def gap_limit(time_s) -> float:
    """Sample interval above which the logger was off [s]."""
    t = np.asarray(time_s, dtype=float)
    if t.size < 2:
        return MIN_GAP_S
    return float(max(GAP_FACTOR * np.median(np.diff(t)), MIN_GAP_S))


def split_log(time_s, current_A, *, step_index=None, cycle_index=None,
              idle_A: float | None = None, gap_s: float | None = None,
              step_kinds: dict | None = None) -> list[Span]:
    """Events of a log, in order (discharge current positive).

    A tester's file decides its own events: with ``step_kinds`` (the kind of each of the
    tester's ``(cycle, step)``, from its step table) every step is what the tester says
    it is, consecutive steps of one kind (a CC then a CV charge) are one event, and the
    log is not cut at long sample intervals (a tester logging by voltage change writes
    sparsely while it runs). The current's scale never enters, so a cell in mA or uA
    splits as one in A does.

    Parameters
    ----------
    time_s, current_A : array_like
        Sample times [s] (increasing) and currents [A], discharge positive.
    step_index, cycle_index : array_like of int, optional
        The tester's step and cycle numbers per row.
    idle_A : float, optional
        Idle threshold [A] (default :func:`idle_threshold`).
    gap_s : float, optional
        Longest sample interval that is not a gap [s] (default :func:`gap_limit`).
    step_kinds : dict, optional
        ``{(cycle, step): kind}`` from the tester's step table (with ``step_index``).

    Returns
    -------
    list of Span
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    n = t.size
    if n == 0:
        return []
    idle = idle_threshold(i) if idle_A is None else float(idle_A)
    if step_kinds is not None and step_index is not None:
        return [Span(kind, s, e, st) for kind, s, e, st in
                _by_tester(i, step_index, cycle_index, step_kinds, idle)]
    gap = gap_limit(t) if gap_s is None else float(gap_s)
    long_intervals = np.diff(t) > gap
    if step_index is not None:
        # a step is recorded sparsely but always at its start: gaps only between steps
        key = np.asarray(step_index).astype(np.int64)
        change = np.diff(key) != 0
        if cycle_index is not None:
            change |= np.diff(np.asarray(cycle_index).astype(np.int64)) != 0
        long_intervals &= change
    elif n > 1:
        # without steps, a steady load recorded sparsely (a tester's export without its
        # step numbers) goes on across a long interval: same sign, a current within
        # SPARSE_LOAD_SHARE of the one before
        state = np.where(i > idle, 1, np.where(i < -idle, -1, 0))
        steady = (state[1:] == state[:-1]) & (state[1:] != 0) & (
            np.abs(np.diff(i)) <= SPARSE_LOAD_SHARE * np.maximum(np.abs(i[1:]), np.abs(i[:-1])))
        long_intervals &= ~steady
        if np.any(long_intervals) and np.any(steady & (np.diff(t) > gap)):
            # the logger records this sparsely inside a load: an idle stretch recorded at
            # the same pace is a rest, not the logger off
            pace = float(np.max(np.diff(t)[steady]))
            long_intervals &= np.diff(t) > SPARSE_GAP_FACTOR * pace
    bounds = [0, *(np.flatnonzero(long_intervals) + 1).tolist(), n]
    out: list[Span] = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if a > 0:
            out.append(Span("gap", a, a))
        if step_index is not None:
            steps = np.asarray(step_index)[a:b]
            cycles = None if cycle_index is None else np.asarray(cycle_index)[a:b]
            pieces = _by_steps(i[a:b], steps, cycles, idle)
        else:
            pieces = _by_current(t[a:b], i[a:b], idle)
        out += [Span(kind, s + a, e + a, st) for kind, s, e, st in pieces]
    return out


_CODES = {1: "discharge", -1: "charge", 0: "rest"}


def _by_steps(i, steps, cycles, idle) -> list[tuple]:
    key = np.asarray(steps).astype(np.int64)
    change = np.diff(key) != 0
    if cycles is not None:
        change |= np.diff(np.asarray(cycles).astype(np.int64)) != 0
    bounds = [0, *(np.flatnonzero(change) + 1).tolist(), key.size]
    # the tester says where its steps are: a step rests when its mean current is within
    # the testers' rest share of the file's largest current, however small that is (a coin
    # cell at 80 uA), as the tester-file readers class them
    from ..io.cyclers.steps import REST_FRACTION

    largest = float(np.max(np.abs(i))) if i.size else 0.0
    if largest > 0:
        idle = min(idle, REST_FRACTION * largest)
    pieces: list[list] = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        m = float(np.mean(i[a:b]))
        code = 1 if m > idle else -1 if m < -idle else 0
        step = int(key[a])
        if pieces and pieces[-1][0] == code:
            pieces[-1][2] = b
            pieces[-1][3].append(step)
        else:
            pieces.append([code, a, b, [step]])
    return [(_CODES[c], a, b, tuple(st)) for c, a, b, st in pieces]


def _by_tester(i, steps, cycles, kinds: dict, idle) -> list[tuple]:
    """Runs of the tester's own steps, each of the kind its step table gives."""
    key = np.asarray(steps).astype(np.int64)
    cyc = np.zeros_like(key) if cycles is None else np.asarray(cycles).astype(np.int64)
    change = (np.diff(key) != 0) | (np.diff(cyc) != 0)
    bounds = [0, *(np.flatnonzero(change) + 1).tolist(), key.size]
    pieces: list[list] = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        kind = kinds.get((int(cyc[a]), int(key[a])))
        if kind is None:        # a step the table does not know: by its mean current
            m = float(np.mean(i[a:b]))
            kind = "discharge" if m > idle else "charge" if m < -idle else "rest"
        step = int(key[a])
        if pieces and pieces[-1][0] == kind:
            pieces[-1][2] = b
            pieces[-1][3].append(step)
        else:
            pieces.append([kind, a, b, [step]])
    return [(kind, a, b, tuple(st)) for kind, a, b, st in pieces]


def _span_s(t, a: int, b: int) -> float:
    """Time a run of rows ``a..b-1`` covers [s]: the mean of its own span and the span
    between its neighbours (a single sample covers about one interval)."""
    n = t.size
    inner = t[b - 1] - t[a]
    outer = t[min(b, n - 1)] - t[max(a - 1, 0)]
    return float(0.5 * (inner + outer))


def _by_current(t, i, idle) -> list[tuple]:
    state = np.where(i > idle, 1, np.where(i < -idle, -1, 0))
    edges = np.flatnonzero(np.diff(state) != 0) + 1
    runs = [[int(state[a]), int(a), int(b)] for a, b in
            zip([0, *edges.tolist()], [*edges.tolist(), state.size])]
    for _ in range(MAX_PASSES):
        changed = False
        for k in range(1, len(runs) - 1):
            code, a, b = runs[k]
            prev, nxt = runs[k - 1][0], runs[k + 1][0]
            if prev != nxt or code == prev:
                continue
            limit = MIN_REST_S if (code == 0 and prev != 0) else MIN_BLIP_S
            if _span_s(t, a, b) < limit:
                runs[k][0] = prev
                changed = True
        merged: list[list] = []
        for run in runs:
            if merged and merged[-1][0] == run[0]:
                merged[-1][2] = run[2]
            else:
                merged.append(list(run))
        runs = merged
        if not changed:
            break
    return [(_CODES[c], a, b, ()) for c, a, b in runs]


def is_long_log(spans: list[Span], time_s, current_A, step_index=None) -> bool:
    """Whether a log is split by :func:`split_log`: it has step numbers, or its charges move
    at least :data:`LONG_LOG_CHARGE_SHARE` of what its discharges move."""
    if step_index is not None:
        return True
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    moved = {"charge": 0.0, "discharge": 0.0}
    for sp in spans:
        if sp.kind in moved and sp.rows >= 2:
            moved[sp.kind] += abs(counted_charge(t[sp.start:sp.stop], i[sp.start:sp.stop])[0])
    return moved["charge"] > 0 and moved["charge"] >= LONG_LOG_CHARGE_SHARE * moved["discharge"]


# --------------------------------------------------------------------------- figures

@dataclass
class LogArrays:
    """The samples of a whole log as arrays (pack values, discharge positive)."""

    time_s: np.ndarray
    voltage_V: np.ndarray
    current_A: np.ndarray
    temperature_C: np.ndarray | None = None
    cells_V: np.ndarray | None = None

    @classmethod
    def from_frame(cls, frame) -> LogArrays:
        cols = cell_columns(frame.columns)
        return cls(time_s=frame["time_s"].to_numpy(dtype=float),
                   voltage_V=frame["voltage_V"].to_numpy(dtype=float),
                   current_A=frame["current_A"].to_numpy(dtype=float),
                   temperature_C=frame["temperature_C"].to_numpy(dtype=float)
                   if "temperature_C" in frame else None,
                   cells_V=frame[cols].to_numpy(dtype=float) if len(cols) >= 2 else None)

    def rows(self, a: int, b: int) -> LogArrays:
        return LogArrays(self.time_s[a:b], self.voltage_V[a:b], self.current_A[a:b],
                         None if self.temperature_C is None else self.temperature_C[a:b],
                         None if self.cells_V is None else self.cells_V[a:b])


@dataclass
class Rest:
    """The rows of a rest (``a`` to ``b - 1``) and the reading they give."""

    a: int
    b: int
    reading: dict
    since_load_s: np.ndarray | None
    direction: int


def rest_of(log: LogArrays, a: int, b: int, *, load_row: int | None = None,
            direction: int = 0) -> Rest:
    """The rest of rows ``a..b-1``; ``load_row`` is the last loaded row before it (its load
    ended half-way to the rest's first sample), ``direction`` +1 after a discharge, -1
    after a charge."""
    t = log.time_s
    load_end = None if load_row is None else 0.5 * (t[load_row] + t[a])
    reading = rest_reading(t[a:b], log.voltage_V[a:b], log.current_A[a:b], load_end_s=load_end,
                           direction=direction,
                           loaded_V=None if load_row is None else float(log.voltage_V[load_row]),
                           temperature_C=None if log.temperature_C is None
                           else log.temperature_C[a:b])
    since = None if load_end is None else t[a:b] - load_end
    return Rest(a, b, reading, since, direction if load_end is not None else 0)


def rest_reading(time_s, voltage_V, current_A, *, load_end_s: float | None = None,
                 direction: int = 0, loaded_V: float | None = None,
                 temperature_C=None) -> dict:
    """The reading a rest gives the events on either side of it (pack values).

    Parameters
    ----------
    time_s, voltage_V, current_A : array_like
        The rest's samples [s, V, A].
    load_end_s : float, optional
        When the load before the rest ended [s, same clock]; None when the rest starts
        the log (or follows a gap).
    direction : {1, -1, 0}
        +1 after a discharge, -1 after a charge, 0 without a load before it.
    loaded_V : float, optional
        Last loaded voltage before the rest [V].
    temperature_C : array_like, optional

    Returns
    -------
    dict
        ``time_s`` (its last sample: where the reading is), ``duration_s``, ``samples``,
        ``since_load_s`` (time from the load to the reading, None without a load),
        ``current_A`` (idle current at the reading: the mean of the samples whose
        voltage it reads), ``temperature_C``, and the keys of
        :func:`~dischargelab.logbook.relaxation.relaxation` (``voltage_V``,
        ``relaxed_V``, ``left_V``, ``half95_V``, ``method``).
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_V, dtype=float)
    i = np.asarray(current_A, dtype=float)
    since = None if load_end_s is None else t - float(load_end_s)
    out = relaxation(since if since is not None else t - t[0], v,
                     direction if load_end_s is not None else 0, loaded_V=loaded_V)
    out.update(time_s=float(t[-1]), duration_s=float(t[-1] - t[0]), samples=int(t.size),
               since_load_s=None if since is None else float(since[-1]),
               current_A=float(np.mean(i[-3:])), temperature_C=_last_finite(temperature_C))
    return out


def charge_figures(time_s, voltage_V, current_A, *, cells: int | None = None) -> dict:
    """What a charge moved and how it ended (charge current negative in, reported positive).

    Returns
    -------
    dict
        ``charged_Ah``, ``duration_s``, ``mean_current_A`` and ``max_current_A``
        (positive), ``start_voltage_V``, ``max_voltage_V``, ``end_voltage_V``,
        ``end_current_A``, ``taper`` (ended in a constant-voltage taper: the current
        below :data:`TAPER_SHARE` of the median while the voltage held within
        :data:`TAPER_HOLD_CELL_V` per cell of its highest value, and below it to the end).
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_V, dtype=float)
    i = -np.asarray(current_A, dtype=float)
    q = float(np.sum(0.5 * (i[1:] + i[:-1]) * np.diff(t))) / 3600.0 if t.size > 1 else 0.0
    tail = slice(max(0, t.size - 3), t.size)
    end_i = float(np.mean(i[tail]))
    median_i = float(np.median(i)) if i.size else 0.0
    hold = TAPER_HOLD_CELL_V * (cells or 1)
    vmax = float(np.max(v))
    low = TAPER_SHARE * median_i
    held = np.flatnonzero(v >= vmax - hold)     # none when a voltage is not a number
    last_held = int(held[-1]) if held.size else -1
    taper = bool(t.size >= 3 and median_i > 0 and held.size
                 and np.mean(i[max(0, last_held - 2):last_held + 1]) < low
                 and np.all(i[last_held + 1:] < low))
    return {"charged_Ah": q, "duration_s": float(t[-1] - t[0]) if t.size else 0.0,
            "mean_current_A": float(q * 3600.0 / (t[-1] - t[0])) if t.size > 1 and t[-1] > t[0]
            else float(np.mean(i)), "max_current_A": float(np.max(i)),
            "start_voltage_V": float(v[0]), "max_voltage_V": vmax,
            "end_voltage_V": float(np.median(v[tail])), "end_current_A": end_i,
            "taper": taper}


def compact_curve(charge_Ah, voltage_V, current_A, points: int = CURVE_POINTS) -> dict:
    """Voltage and current at ``points`` evenly spaced charges from 0 to the end [Ah, V, A]."""
    q = np.maximum.accumulate(np.asarray(charge_Ah, dtype=float))
    grid = np.linspace(0.0, q[-1], points)
    keep = np.concatenate(([True], np.diff(q) > 0))
    qv, vv, iv = q[keep], np.asarray(voltage_V, float)[keep], np.asarray(current_A, float)[keep]
    return {"charge_Ah": np.round(grid, 6).tolist(),
            "voltage_V": np.round(np.interp(grid, qv, vv), 5).tolist(),
            "current_A": np.round(np.interp(grid, qv, iv), 5).tolist()}


def knee_ratio(charge_Ah, voltage_V) -> float:
    """How many times faster the voltage falls at the end of a discharge than in its middle.

    End slope: voltage drop over the last :data:`KNEE_SPAN` of the charge; middle
    slope: over 20-80 % of it (both per Ah). A discharge to its cutoff ends on the
    steep end of the voltage curve (ratios of 10 and more); one stopped on the
    plateau gives about 1. Returns 0 for fewer than 10 samples or no charge.
    """
    q = np.maximum.accumulate(np.asarray(charge_Ah, dtype=float))
    v = np.asarray(voltage_V, dtype=float)
    total = q[-1] if q.size else 0.0
    if q.size < 10 or total <= 0:
        return 0.0
    at = lambda frac: float(np.interp(frac * total, q, v))  # noqa: E731
    middle = (at(0.2) - at(0.8)) / (0.6 * total)
    end = (at(1.0 - KNEE_SPAN) - float(np.median(v[-3:]))) / (KNEE_SPAN * total)
    if middle <= 0:
        return float("inf") if end > 0 else 0.0
    return float(end / middle)


def load_figures(log: LogArrays, *, rest: dict | None = None, after: dict | None = None,
                 points: int = CURVE_POINTS, ambient_C=None) -> dict:
    """The numbers of one discharge or charge (pack values; the keys of the logbook's
    event rows, see :mod:`dischargelab.logbook.summarise`).

    Parameters
    ----------
    log : LogArrays
        The event's samples, time from any origin.
    rest : dict, optional
        The rest sample just before the load: ``voltage_V``, ``time_s`` (same clock),
        ``current_A``, ``temperature_C``.
    after : dict, optional
        The rest after it: ``voltage_V`` (its last reading), ``relaxed_s`` (since the
        load), ``first_voltage_V``, ``first_current_A``, ``first_gap_s``.
    points : int
        Points of the compact curve.
    ambient_C : array_like, optional
        Ambient temperature of the samples [degC].
    """
    t, v, i = log.time_s, log.voltage_V, log.current_A
    charging = float(np.sum(i)) < 0
    sign = -1.0 if charging else 1.0
    dt = np.diff(t)
    charge = np.concatenate(([0.0], np.cumsum(0.5 * (i[1:] + i[:-1]) * dt))) / 3600.0
    energy = float(np.sum(0.5 * (i[1:] * v[1:] + i[:-1] * v[:-1]) * dt)) / 3600.0
    tail = slice(max(0, t.size - 3), t.size)
    resistance = step_resistance(t, v, i, rest=rest, after=after)
    method = "load steps" if resistance[0] is not None else None
    if resistance[0] is None and not charging:
        from .estimates import regression_resistance

        resistance = regression_resistance(t, v, i)
        method = "regression" if resistance[0] is not None else None
    event: dict = {
        "duration_s": float(t[-1] - t[0]),
        "discharged_Ah": 0.0 if charging else float(charge[-1]),
        "discharged_Wh": 0.0 if charging else energy,
        "mean_current_A": float(charge[-1] * 3600.0 / (t[-1] - t[0])) if t[-1] > t[0]
        else float(np.mean(i)),
        "max_current_A": float(np.min(i) if charging else np.max(i)),
        "rest_voltage_V": None if rest is None else float(rest["voltage_V"]),
        "rest_after_V": None if after is None else after["voltage_V"],
        "rest_after_s": None if after is None else after["relaxed_s"],
        "min_voltage_V": float(np.min(v)),
        "end_voltage_V": float(np.median(v[tail])),
        "end_current_A": float(np.mean(i[tail])),
        "resistance_ohm": resistance[0],
        "resistance_interval95": resistance[1],
        "resistance_method": method,
        "reaches_knee": bool(not charging and knee_ratio(charge, v) >= KNEE_RATIO),
        "samples": int(t.size),
    }
    event.update(_temperatures(log.temperature_C, rest, ambient_C))
    event["cell_spread_V"] = _cell_spread(log.cells_V)
    event["curve"] = compact_curve(sign * charge, v, sign * i, points)
    return event


def quiet_figures(log: LogArrays, kind: str, *, gap_s: float | None = None) -> dict:
    """The numbers of a rest or a gap (a gap has no samples: ``gap_s`` is its length)."""
    t, v, i = log.time_s, log.voltage_V, log.current_A
    n = int(t.size)
    q = counted_charge(t, i)[0] if n > 1 else 0.0
    event: dict = {"duration_s": float(gap_s if kind == "gap" else (t[-1] - t[0] if n else 0.0)),
                   "discharged_Ah": max(0.0, q), "discharged_Wh": None,
                   "mean_current_A": float(np.mean(i)) if n else None,
                   "max_current_A": float(np.max(i)) if n else None,
                   "rest_voltage_V": float(np.median(v[-3:])) if n else None,
                   "rest_after_V": None, "rest_after_s": None,
                   "min_voltage_V": float(np.min(v)) if n else None,
                   "end_voltage_V": float(np.median(v[-3:])) if n else None,
                   "end_current_A": float(np.mean(i[-3:])) if n else None,
                   "resistance_ohm": None, "resistance_interval95": None,
                   "reaches_knee": False, "samples": n, "curve": {}}
    event.update(_temperatures(log.temperature_C, None, None) if n else
                 {"temperature_start_C": None, "temperature_max_C": None, "ambient_C": None})
    event["cell_spread_V"] = _cell_spread(log.cells_V) if n else None
    return event


def rest_sample(log: LogArrays, rest: Rest | None) -> dict | None:
    """The last sample of a rest, as :func:`load_figures` takes it."""
    if rest is None:
        return None
    k = rest.b - 1
    out = {"voltage_V": float(log.voltage_V[k]), "time_s": float(log.time_s[k]),
           "current_A": float(log.current_A[k])}
    if log.temperature_C is not None and np.isfinite(log.temperature_C[k]):
        out["temperature_C"] = float(log.temperature_C[k])
    return out


def after_sample(log: LogArrays, rest: Rest | None, load_stop: int) -> dict | None:
    """The rest after a load, as :func:`load_figures` takes it (``load_stop``: the row
    after the load's last)."""
    if rest is None:
        return None
    t, v = log.time_s, log.voltage_V
    end = t[load_stop - 1]
    last = slice(max(rest.a, rest.b - 3), rest.b)
    return {"voltage_V": float(np.median(v[last])), "relaxed_s": float(t[rest.b - 1] - end),
            "first_voltage_V": float(v[rest.a]), "first_current_A": float(log.current_A[rest.a]),
            "first_gap_s": float(t[rest.a] - end)}


def event_details(log: LogArrays, a: int, b: int, before: Rest | None,
                  after: Rest | None) -> dict:
    """The figures of a load (rows ``a..b-1``) a capacity estimate needs.

    Returns
    -------
    dict
        ``rest_before`` and ``rest_after`` (readings, or None), ``counted_Ah`` and
        ``counted_sd_Ah`` (charge from the reading before, else the load's start, to the
        reading after, else its end; discharge positive), ``sampling`` (how well the
        samples count it, :func:`~dischargelab.logbook.estimates.sampling_figures` over
        the load and one sample either side), ``cells`` (per-cell figures or None).
    """
    t, i = log.time_s, log.current_A
    n = t.size
    first = before.b - 1 if before is not None else a
    last = after.b - 1 if after is not None else b - 1
    lo, hi = max(a - 1, 0), min(b + 1, n)
    sampling = sampling_figures(t[lo:hi], i[lo:hi], charge=float(np.sum(i[a:b])) < 0)
    counted, counted_sd = counted_charge(t[first:last + 1], i[first:last + 1],
                                         unresolved=not sampling["resolved"],
                                         idle_A=idle_threshold(i[lo:hi]))
    cells = None
    if log.cells_V is not None:
        cells = cell_figures(t[a:b], i[a:b], log.cells_V[a:b],
                             before=_cell_block(log, before), after=_cell_block(log, after))
    return {"rest_before": None if before is None else before.reading,
            "rest_after": None if after is None else after.reading,
            "counted_Ah": counted, "counted_sd_Ah": counted_sd,
            "sampling": sampling, "cells": cells}


def _cell_block(log: LogArrays, rest: Rest | None) -> dict | None:
    if rest is None or log.cells_V is None:
        return None
    return {"time_s": log.time_s[rest.a:rest.b], "cells_V": log.cells_V[rest.a:rest.b],
            "since_load_s": rest.since_load_s, "direction": rest.direction}


def log_events(frame, spans: list[Span], *, start_time_of=None, cells: int | None = None
               ) -> list[dict]:
    """Every event of a long log with its figures (see :func:`split_log`).

    Parameters
    ----------
    frame : pandas.DataFrame
        The whole log (canonical columns, discharge positive; ``cellN_V`` when logged).
    spans : list of Span
    start_time_of : callable, optional
        ``start_time_of(time_s)`` -> ISO 8601 clock time of a log time, or None.
    cells : int, optional
        Cells in series when the log says.

    Returns
    -------
    list of dict
        Event dicts (the keys of :func:`load_figures` or :func:`quiet_figures`, plus
        ``index``, ``kind``, ``start_time``, ``cycle`` (the tester's cycle number at the
        event's start when the log has ``cycle_index``, else None), ``cells``,
        ``details``).
    """
    log = LogArrays.from_frame(frame)
    cycle_index = frame["cycle_index"].to_numpy() if "cycle_index" in frame else None
    t = log.time_s
    ambient = frame["ambient_temperature_C"].to_numpy(dtype=float) \
        if "ambient_temperature_C" in frame else None
    rests: dict[int, Rest] = {}
    for k, sp in enumerate(spans):
        if sp.kind != "rest" or sp.rows == 0:
            continue
        prev = spans[k - 1] if k > 0 else None
        if prev is not None and prev.kind in ("discharge", "charge") and prev.rows:
            rests[k] = rest_of(log, sp.start, sp.stop, load_row=prev.stop - 1,
                               direction=1 if prev.kind == "discharge" else -1)
            if prev.kind == "charge" and prev.rows >= 2:
                # what the charge before it ended like: a taper at its highest voltage is
                # full (health checks that voltage against the pack's full voltage)
                fig = charge_figures(t[prev.start:prev.stop], log.voltage_V[prev.start:prev.stop],
                                     log.current_A[prev.start:prev.stop], cells=cells)
                rests[k].reading["after_charge"] = {"taper": fig["taper"],
                                                    "max_voltage_V": fig["max_voltage_V"]}
        else:
            rests[k] = rest_of(log, sp.start, sp.stop)
    events = []
    for k, sp in enumerate(spans):
        details: dict = {"rows": [sp.start, sp.stop], "long_log": True}
        if sp.steps:
            details["steps"] = list(sp.steps)
        if sp.kind in ("discharge", "charge"):
            event = _load_event(log, spans, k, rests, ambient, cells, details)
        else:
            gap = float(t[sp.start] - t[sp.start - 1]) if sp.kind == "gap" else None
            event = quiet_figures(log.rows(sp.start, sp.stop), sp.kind, gap_s=gap)
            if k in rests:
                details["reading"] = rests[k].reading
        row = min(sp.start, t.size - 1)
        cycle = None if cycle_index is None else int(cycle_index[row])
        event.update(index=k, kind=sp.kind, cycle=cycle, cells=cells, details=details,
                     start_time=None if start_time_of is None else start_time_of(float(t[row])))
        events.append(event)
    return events


def _load_event(log: LogArrays, spans: list[Span], k: int, rests: dict, ambient,
                cells: int | None, details: dict) -> dict:
    """A discharge's or a charge's figures in a long log (``details`` filled in place)."""
    sp = spans[k]
    t, n = log.time_s, log.time_s.size
    # one sample of load is seen through the samples either side of it
    a, b = (sp.start, sp.stop) if sp.rows >= 2 else (max(sp.start - 1, 0), min(sp.stop + 1, n))
    part = log.rows(a, b)
    before, after = rests.get(k - 1), rests.get(k + 1)
    rest = rest_sample(log, before) if sp.rows >= 2 else None
    if rest is not None:
        rest["time_s"] -= t[a]
    rel = LogArrays(part.time_s - t[a], part.voltage_V, part.current_A, part.temperature_C,
                    part.cells_V)
    event = load_figures(rel, rest=rest,
                         after=after_sample(log, after, b) if sp.rows >= 2 else None,
                         points=int(min(CURVE_POINTS, max(b - a, 2))),
                         ambient_C=None if ambient is None else ambient[a:b])
    details.update(event_details(log, a, b, before, after))
    details["resistance_method"] = event.pop("resistance_method")
    if sp.kind == "charge":
        details["charge"] = charge_figures(part.time_s, part.voltage_V, part.current_A,
                                           cells=cells)
        if sp.rows >= 2 and k > 0 and spans[k - 1].kind == "rest" and spans[k - 1].rows:
            details["charge"]["start"] = charge_start(log, sp.start)
    # what the load moved, with its first and last steps: from the sample before it to the
    # one after it (a coarse log loses up to a sample interval at each end), and its curve
    # over the same samples (the rests' voltages at its ends), so that the curve's charge
    # scale is the charge it moved
    lo, hi = max(a - 1, 0), min(b + 1, n)
    if sp.rows >= 2 and lo < a and hi > b and spans[k - 1].kind != "gap" \
            and k + 1 < len(spans) and spans[k + 1].kind != "gap":
        i_b = log.current_A[lo:hi]
        sign = -1.0 if sp.kind == "charge" else 1.0
        q = np.concatenate(([0.0], np.cumsum(0.5 * (i_b[1:] + i_b[:-1])
                                             * np.diff(t[lo:hi])))) / 3600.0
        if not sp.steps:
            if sp.kind == "charge":
                details["charge"]["charged_Ah"] = max(-float(q[-1]), 0.0)
            else:
                event["discharged_Ah"] = max(float(q[-1]), 0.0)
        event["curve"] = compact_curve(sign * q, log.voltage_V[lo:hi], sign * i_b,
                                       int(min(CURVE_POINTS, hi - lo)))
    if sp.steps and sp.rows >= 2:
        # a tester's step starts right after the record before it and ends at its own last
        # record: its charge is the current of its first record over that first interval
        # plus the trapezoid over its records, as the tester's counter adds it
        i_s, t_s = log.current_A[a:b], t[a:b]
        moved = float(i_s[0] * (t[a] - t[lo])
                      + np.sum(0.5 * (i_s[1:] + i_s[:-1]) * np.diff(t_s))) / 3600.0
        if sp.kind == "charge":
            details["charge"]["charged_Ah"] = max(-moved, 0.0)
        else:
            event["discharged_Ah"] = max(moved, 0.0)
    return event


def charge_start(log: LogArrays, a: int) -> dict:
    """The samples around a charge's start (row ``a`` its first, ``a - 1`` a rest's last):
    what :func:`~dischargelab.logbook.estimates.charge_start_corrections` places the start
    inside that sample interval with. Currents positive into the pack [A], voltages [V]."""
    t, v, i = log.time_s, log.voltage_V, log.current_A
    return {"interval_s": float(t[a] - t[a - 1]), "rest_V": float(v[a - 1]),
            "first_V": float(v[a]), "first_A": float(-i[a]), "next_V": float(v[a + 1]),
            "next_A": float(-i[a + 1]), "next_interval_s": float(t[a + 1] - t[a])}


def _temperatures(temperature_C, rest: dict | None, ambient_C) -> dict:
    out: dict = {"temperature_start_C": None, "temperature_max_C": None, "ambient_C": None}
    if temperature_C is not None:
        temp = np.asarray(temperature_C, dtype=float)
        temp = temp[np.isfinite(temp)]
        if temp.size:
            start = rest.get("temperature_C") if rest else None
            out["temperature_start_C"] = float(start if start is not None else temp[0])
            out["temperature_max_C"] = float(np.max(temp))
    if ambient_C is not None:
        amb = np.asarray(ambient_C, dtype=float)
        amb = amb[np.isfinite(amb)]
        if amb.size:
            out["ambient_C"] = float(np.median(amb))
    return out


def _cell_spread(cells_V) -> float | None:
    """Largest minus smallest cell voltage [V], median over the last 10 % of the samples."""
    if cells_V is None:
        return None
    values = np.asarray(cells_V, dtype=float)
    values = values[np.all(np.isfinite(values), axis=1)]
    if values.size == 0:
        return None
    spread = values.max(axis=1) - values.min(axis=1)
    return float(np.median(spread[-max(1, spread.size // 10):]))


def _last_finite(values) -> float | None:
    if values is None:
        return None
    arr = np.asarray(values, dtype=float)
    arr = arr[np.isfinite(arr)]
    return float(np.median(arr[-3:])) if arr.size else None


__all__ = ["Span", "split_log", "is_long_log", "idle_threshold", "gap_limit", "rest_reading",
           "charge_figures", "load_figures", "quiet_figures", "log_events", "event_details",
           "compact_curve", "knee_ratio", "LogArrays", "Rest", "rest_of", "KINDS",
           "CURVE_POINTS", "MIN_REST_S", "MIN_BLIP_S"]
