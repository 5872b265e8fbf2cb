"""A tester's records as canonical columns, their current sign, and their steps.

Every tester reader (:mod:`.neware`, :mod:`.biologic`, :mod:`.arbin`, :mod:`.exports`)
returns a :class:`TesterRecords`: the file's rows in canonical columns and units,
with the current **as signed in the file**, the tester's cycle and step numbers
and, where the file has them, its own charge and discharge counters and a per-row
state (charge, discharge, rest). :func:`finish` then

* finds which current sign is discharge **from the file itself**: the state
  column (Maccor ``State``, Neware ``Status``, BioLogic's ox/red flag), else the
  tester's discharge counter (the sign of the current while it grows), else the
  charge counter, else the voltage trend (:func:`dischargelab.io.segment.detect_sign`);
* splits the rows into steps: runs of one (cycle, step) pair, numbered 1, 2, ...
  in file order, each with its kind (``charge``, ``discharge``, ``rest``), its
  control mode, times, voltages and the charge moved, counted by the current and
  by the tester's own counter.

Sign convention of the result: discharge current positive, charge negative.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ...errors import DataError
from ..segment import detect_sign

#: Kinds of step.
STEP_KINDS = ("charge", "discharge", "rest")

#: Columns every tester reader returns (besides optional ``temperature_C``, the
#: tester's counters ``tester_charge_Ah`` / ``tester_discharge_Ah`` and ``state``).
REQUIRED = ("time_s", "voltage_V", "current_A", "cycle_index", "step_index")

#: A step whose mean |current| is below this share of the file's largest |current| rests
#: (a tester's one-record transition steps carry a few microamperes of offset).
REST_FRACTION = 1e-2

#: Constant current: the current spans less than this share of its median.
CC_SPREAD = 0.05
#: Constant voltage: the voltage spans less than this share of its median.
CV_SPREAD = 0.01

#: A discharge ends at the tester's lower voltage limit when its last voltage is within
#: this share of its lowest and of the median end voltage of the file's discharges (the
#: median, as fast discharges overshoot the limit).
LIMIT_SHARE = 0.02


@dataclass
class TesterRecords:
    """A tester file's rows in canonical columns (current still as signed in the file).

    Attributes
    ----------
    frame : pandas.DataFrame
        ``time_s`` [s] test time, ``voltage_V`` [V], ``current_A`` [A, the file's
        sign], ``cycle_index`` and ``step_index`` (int, as the tester numbered them);
        optional ``temperature_C`` [degC], ``tester_charge_Ah`` and
        ``tester_discharge_Ah`` (the tester's counters, as it resets them) [Ah],
        ``tester_step_Ah`` (an unsigned counter that restarts every step) [Ah] and
        ``state`` (``"charge"``, ``"discharge"``, ``"rest"`` or ``""``).
    records : numpy.ndarray
        Record (row) number in the file of each row, for messages.
    meta : dict
        ``format``, ``reader`` (library and version), ``notes``, ``column_map``,
        ``units``, ``start_time`` (ISO 8601 of test time 0, when the file says).
    """

    frame: pd.DataFrame
    records: np.ndarray
    meta: dict = field(default_factory=dict)


@dataclass
class TesterFile:
    """A tester file read: discharge-positive rows, their steps and what was found.

    Attributes
    ----------
    frame : pandas.DataFrame
        As :class:`TesterRecords`, current discharge positive.
    records : numpy.ndarray
        Record numbers in the file.
    meta : dict
        As :class:`TesterRecords` plus ``sign_source``.
    steps : list of dict
        One per step (see :func:`step_table`).
    bounds : list of (int, int)
        Row positions ``[start, stop)`` of each step in ``frame``.
    """

    frame: pd.DataFrame
    records: np.ndarray
    meta: dict
    steps: list[dict]
    bounds: list[tuple[int, int]]

    def step(self, number: int) -> dict:
        """The step numbered ``number`` (1-based)."""
        return self.steps[number - 1]

    def to_pandas(self) -> pd.DataFrame:
        """The steps, one row each (the keys of :func:`step_table`)."""
        return pd.DataFrame(self.steps)

    def to_dict(self) -> dict:
        """What was read, without the records (for JSON)."""
        fit, why = fit_steps(self.steps)
        return {"source": self.meta.get("source"), "format": self.meta.get("format"),
                "reader": self.meta.get("reader"), "records": int(len(self.frame)),
                "start_time": self.meta.get("start_time"),
                "sign_source": self.meta.get("sign_source"),
                "notes": list(self.meta.get("notes", [])), "steps": list(self.steps),
                "fit_steps": fit, "fit_steps_reason": why}

    def plot(self):
        """Voltage and current over the test, the steps shaded by kind; returns (fig, axes)."""
        from ...plot import plot_tester_steps

        return plot_tester_steps(self.frame, self.steps, self.meta)


def finish(raw: TesterRecords, name: str, sign: str = "auto") -> TesterFile:
    """Resolve the current's sign, check the rows and find the steps.

    Parameters
    ----------
    raw : TesterRecords
    name : str
        File name for messages.
    sign : {"auto", "positive", "negative"}
        Sign of the discharge current in the file; ``"auto"`` reads it from the file.

    Raises
    ------
    DataError
        No rows, or time that does not advance.
    """
    frame = raw.frame.reset_index(drop=True)
    missing = [c for c in REQUIRED if c not in frame]
    if missing:
        raise DataError(f"{name}: the tester file has no {', '.join(missing)}")
    keep = np.isfinite(frame[["time_s", "voltage_V", "current_A"]].to_numpy(dtype=float)).all(1)
    meta = dict(raw.meta)
    meta["notes"] = list(meta.get("notes", []))
    if not keep.all():
        meta["notes"].append(f"{int((~keep).sum())} record(s) without time, voltage or current "
                             "left out")
    frame, records = frame[keep].reset_index(drop=True), np.asarray(raw.records)[keep]
    if len(frame) < 2:
        raise DataError(f"{name}: the tester file holds {len(frame)} usable record(s)")
    frame["cycle_index"] = frame["cycle_index"].astype(np.int64)
    frame["step_index"] = frame["step_index"].astype(np.int64)
    t = frame["time_s"].to_numpy(dtype=float)
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise DataError(f"{name} record {int(records[k])}: test time goes back ({t[k]:g} s after "
                        f"{t[k - 1]:g} s); the file is damaged or holds two tests")
    if t[-1] <= t[0]:
        column = (meta.get("column_map") or {}).get("time_s", "time")
        raise DataError(f"{name}: the test time ({column!r}) stays at {t[0]:g} s over all "
                        f"{len(t)} records: it is not a time (name the time column in the "
                        "export, or export the test time in seconds)")
    if meta.get("current_interval_mean"):
        frame, records = interval_means_held(frame, records)
        meta["notes"].append(f"{meta['current_interval_mean']!r} is the mean current over the "
                             "interval before each record: counted over that interval")
    flip, source = _discharge_sign(frame, sign)
    if flip:
        frame["current_A"] = -frame["current_A"]
    meta["sign_source"] = source
    meta["sign_convention"] = ("discharge negative in the file (flipped)" if flip
                               else "discharge positive in the file")
    bounds = step_bounds(frame)
    steps = step_table(frame, records, bounds)
    return TesterFile(frame=frame, records=records, meta=meta, steps=steps, bounds=bounds)


def _discharge_sign(frame: pd.DataFrame, sign: str) -> tuple[bool, str]:
    """(flip the current?, where the sign came from)."""
    if sign == "positive":
        return False, "given (discharge positive)"
    if sign == "negative":
        return True, "given (discharge negative)"
    i = frame["current_A"].to_numpy(dtype=float)
    if "state" in frame:
        state = frame["state"].to_numpy(dtype=object)
        loaded = np.abs(i) > 0
        dis, chg = loaded & (state == "discharge"), loaded & (state == "charge")
        if dis.any() or chg.any():
            signed = np.sign(i[dis]).sum() - np.sign(i[chg]).sum()
            if np.all(i >= 0) and chg.any():
                frame["current_A"] = np.where(state == "charge", -np.abs(i), np.abs(i))
                return False, ("the state column (the current is unsigned; charge rows made "
                               "negative)")
            return bool(signed < 0), "the state column (charge / discharge of each record)"
    for column, discharge_grows in (("tester_discharge_Ah", True), ("tester_charge_Ah", False)):
        if column not in frame:
            continue
        counter = frame[column].to_numpy(dtype=float)
        grows = np.concatenate(([False], np.diff(counter) > 0)) & (np.abs(i) > 0)
        if grows.sum() >= 3:
            sign_there = np.sign(np.median(i[grows]))
            negative = sign_there < 0 if discharge_grows else sign_there > 0
            what = "discharge" if discharge_grows else "charge"
            return bool(negative), (f"the tester's {what} counter grows while the current is "
                                    f"{'negative' if sign_there < 0 else 'positive'}")
    detected, evidence = detect_sign(frame["time_s"], i, frame["voltage_V"])
    return detected < 0, f"the voltage trend ({evidence})"


def step_bounds(frame: pd.DataFrame) -> list[tuple[int, int]]:
    """Row positions ``[start, stop)`` of each run of one (cycle_index, step_index)."""
    cycle = frame["cycle_index"].to_numpy()
    step = frame["step_index"].to_numpy()
    change = np.flatnonzero((np.diff(cycle) != 0) | (np.diff(step) != 0)) + 1
    edges = np.concatenate(([0], change, [len(frame)]))
    return list(zip(edges[:-1].tolist(), edges[1:].tolist()))


def step_table(frame: pd.DataFrame, records: np.ndarray, bounds) -> list[dict]:
    """One dict per step, in file order.

    Keys: ``number`` (1, 2, ... in the file), ``cycle`` and ``step`` (the tester's
    numbers), ``kind`` (:data:`STEP_KINDS`), ``mode`` (``"CC"``, ``"CV"``,
    ``"CC-CV"``, ``"varying"`` or ``"rest"``), ``first_record``, ``last_record``,
    ``rows``, ``start_s``, ``end_s``, ``duration_s`` [s, test time],
    ``mean_current_A`` [A, discharge positive], ``start_voltage_V``,
    ``end_voltage_V``, ``min_voltage_V``, ``max_voltage_V`` [V], ``charge_Ah``
    (charge moved [Ah, positive] by the current, from the end of the step before:
    the tester starts the step there), ``tester_Ah`` (the same by the tester's own
    counter, or None), and for discharges ``after_charge`` (the step before, rests
    aside, is a charge: the cell starts full) and ``to_limit`` (the step ends at
    the lowest voltage of the file's discharges: the tester's lower limit).
    """
    t = frame["time_s"].to_numpy(dtype=float)
    v = frame["voltage_V"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    state = frame["state"].to_numpy(dtype=object) if "state" in frame else None
    rest_level = REST_FRACTION * float(np.max(np.abs(i))) if i.size else 0.0
    steps = []
    for number, (a, b) in enumerate(bounds, start=1):
        kind = _kind(i[a:b], None if state is None else state[a:b], rest_level)
        lead = 0.0 if a == 0 else i[a] * _lead_s(t, a, b)   # the step starts after row a-1
        moved = (float(np.sum(0.5 * (i[a + 1:b] + i[a:b - 1]) * np.diff(t[a:b]))) + lead) / 3600
        steps.append({
            "number": number, "cycle": int(frame["cycle_index"].iat[a]),
            "step": int(frame["step_index"].iat[a]), "kind": kind,
            "mode": _mode(i[a:b], v[a:b], kind),
            "first_record": int(records[a]), "last_record": int(records[b - 1]),
            # a file's records (a reader may have added companions: exports.INTERVAL_MEANS)
            "rows": int(np.unique(records[a:b]).size),
            "start_s": float(t[a]), "end_s": float(t[b - 1]),
            "duration_s": float(t[b - 1] - t[a]),
            "mean_current_A": float(np.mean(i[a:b])),
            "start_voltage_V": float(v[a]), "end_voltage_V": float(v[b - 1]),
            "min_voltage_V": float(np.min(v[a:b])), "max_voltage_V": float(np.max(v[a:b])),
            "charge_Ah": abs(moved), "tester_Ah": _tester_Ah(frame, a, b, kind),
        })
    _discharge_flags(steps)
    return steps


def _lead_s(t: np.ndarray, a: int, b: int) -> float:
    """Time [s] the step's first current ran before its first record: since the record
    before, at most the step's longest sample interval (a pause between steps is not run)."""
    inside = np.diff(t[a:b])
    gap = float(t[a] - t[a - 1])
    return min(gap, float(np.max(inside))) if inside.size else gap


def _kind(i: np.ndarray, state, rest_level: float) -> str:
    if state is not None:
        known = [s for s in state if s in STEP_KINDS]
        if known:
            values, counts = np.unique(known, return_counts=True)
            return str(values[np.argmax(counts)])
    mean = float(np.mean(i))
    if abs(mean) <= rest_level:
        return "rest"
    return "discharge" if mean > 0 else "charge"


def _mode(i: np.ndarray, v: np.ndarray, kind: str) -> str:
    if kind == "rest":
        return "rest"
    a = np.abs(i)
    if _steady(a, CC_SPREAD):
        return "CC"
    if _steady(v, CV_SPREAD):
        return "CV"
    n = a.size
    if _steady(a[: max(1, n // 3)], CC_SPREAD) and _steady(v[-max(1, n // 3):], CV_SPREAD):
        return "CC-CV"
    return "varying"


def _steady(x: np.ndarray, share: float) -> bool:
    """The 10th to 90th percentile of ``x`` spans at most ``share`` of its median (a ramp
    over the first samples or a spike does not count)."""
    median = abs(float(np.median(x)))
    low, high = np.percentile(x, [10, 90])
    return median > 0 and high - low <= share * median


def _tester_Ah(frame: pd.DataFrame, a: int, b: int, kind: str) -> float | None:
    """Charge moved in rows ``[a, b)`` by the tester's own counter [Ah], or None."""
    if kind == "rest":
        return None
    column = {"discharge": "tester_discharge_Ah", "charge": "tester_charge_Ah"}[kind]
    if column not in frame:
        column = "tester_step_Ah"
    if column not in frame:
        return None
    counter = frame[column].to_numpy(dtype=float)
    end = counter[b - 1]
    # the file's first record: what the counter held there (a file cut from a longer test)
    before = counter[a - 1] if a > 0 else counter[0]
    # a counter that restarts with the step (Maccor's Amp-hr) or the cycle counts from 0
    # there; one that runs on over the test (some Maccor exports) from the step before
    if counter[a] < before or not np.isfinite(before):
        before = 0.0
    value = abs(end - before)    # some counters count a discharge down (BaSyTec's Ah-Step)
    return float(value) if np.isfinite(value) else None


def interval_means_held(frame: pd.DataFrame, records: np.ndarray
                        ) -> tuple[pd.DataFrame, np.ndarray]:
    """Records whose current is the mean over the interval before each, as a current held
    over each interval: every record after the first gets a companion a moment after the
    record before it (a thousandth of the interval, at most 1 ms) with its own values, so
    that trapezoids count ``sum(I_k (t_k - t_(k-1)))``. The companions carry their
    record's number."""
    t = frame["time_s"].to_numpy(dtype=float)
    dt = np.diff(t)
    later = np.flatnonzero(dt > 0) + 1
    companions = frame.iloc[later].copy()
    companions["time_s"] = t[later - 1] + np.minimum(1e-3, 1e-3 * dt[later - 1])
    order = np.argsort(np.r_[np.arange(len(frame)), later - 0.5], kind="stable")
    held = pd.concat([frame, companions], ignore_index=True).iloc[order]
    return held.reset_index(drop=True), np.r_[records, records[later]][order]


def _discharge_flags(steps: list[dict]) -> None:
    discharges = [s for s in steps if s["kind"] == "discharge" and s["rows"] >= MIN_STEP_ROWS]
    if not discharges:
        return
    floor = float(np.median([s["end_voltage_V"] for s in discharges]))
    previous = None
    for s in steps:
        if s["kind"] == "discharge":
            s["after_charge"] = previous is not None and previous["kind"] == "charge" \
                and s["rows"] >= MIN_STEP_ROWS
            low = s["min_voltage_V"] + LIMIT_SHARE * abs(s["min_voltage_V"])
            # a pulse ends near the file's other pulses, but falls by far less than a run
            # from full to a limit (the least: LFP's 3.4 -> 2.5 V)
            falls = s["max_voltage_V"] - s["end_voltage_V"] >= FULL_FALL_SHARE * abs(
                s["end_voltage_V"])
            s["to_limit"] = bool(falls and s["end_voltage_V"]
                                 <= min(low, floor + LIMIT_SHARE * abs(floor)))
        if s["kind"] != "rest" and s["rows"] > 1:
            previous = s


#: A discharge to the lower limit falls by at least this share of its end voltage: LFP
#: from its plateau (~3.3 V) to 2.5 V falls 30 %, an NMC cell from 4.2 V to 2.5 V 70 %,
#: a 10-second pulse under 1 %.
FULL_FALL_SHARE = 0.1

#: A discharge step needs this many records to be read as a discharge (a tester's
#: one-record transition steps are not).
MIN_STEP_ROWS = 3


def discharge_numbers(steps: list[dict]) -> list[int]:
    """Numbers of the discharge steps (of at least :data:`MIN_STEP_ROWS` records)."""
    return [s["number"] for s in steps if s["kind"] == "discharge"
            and s["rows"] >= MIN_STEP_ROWS]


def full_discharges(steps: list[dict]) -> list[dict]:
    """Discharge steps from a charge down to the lower voltage limit (capacity tests)."""
    return [s for s in steps if s["kind"] == "discharge" and s.get("after_charge")
            and s.get("to_limit")]


#: Discharges whose mean currents differ by less than this share are at one rate.
SAME_RATE = 0.05


def fit_steps(steps: list[dict]) -> tuple[list[int], str]:
    """The discharge steps worth fitting by default, and why.

    The first full discharge (:func:`full_discharges`) at constant current of each
    rate (the cell at its freshest; the repeats are left to validate on), else every
    full discharge, else the discharges that reach the lower limit, else the longest
    discharge.

    Returns
    -------
    (numbers, reason)
    """
    full = full_discharges(steps)
    constant = [s for s in full if s["mode"] in ("CC", "CC-CV")]
    if constant:
        chosen: list[dict] = []
        for s in constant:
            if not any(abs(s["mean_current_A"] - c["mean_current_A"])
                       <= SAME_RATE * c["mean_current_A"] for c in chosen):
                chosen.append(s)
        reason = ("the first full discharge (from a charge to the lower voltage limit) at "
                  f"constant current of each rate: {len(chosen)} of {len(constant)}")
        return [s["number"] for s in chosen], reason
    if full:
        return [s["number"] for s in full], "the full discharges (from a charge to the limit)"
    limited = [s for s in steps if s["kind"] == "discharge" and s.get("to_limit")]
    if limited:
        return [s["number"] for s in limited], ("the discharges that reach the lower voltage "
                                                "limit (none starts after a charge)")
    discharges = [s for s in steps if s["number"] in discharge_numbers(steps)]
    if not discharges:
        return [], "no discharge step"
    longest = max(discharges, key=lambda s: s["duration_s"])
    return [longest["number"]], "the longest discharge (none reaches the lower voltage limit)"


def describe_step(step: dict) -> str:
    """``"step 7 (cycle 2, tester step 7): discharge CC, -3 A, 5.807 Ah, 4.2 -> 2.5 V"``."""
    text = (f"step {step['number']} (cycle {step['cycle']}, tester step {step['step']}): "
            f"{step['kind']}")
    if step["kind"] == "rest":
        return text + f", {step['duration_s']:.0f} s, {step['end_voltage_V']:.4g} V at the end"
    return text + (f" {step['mode']}, {step['mean_current_A']:.4g} A mean, "
                   f"{step['charge_Ah']:.4g} Ah, {step['start_voltage_V']:.4g} -> "
                   f"{step['end_voltage_V']:.4g} V")


__all__ = ["TesterRecords", "TesterFile", "finish", "step_bounds", "step_table",
           "discharge_numbers", "full_discharges", "fit_steps", "describe_step", "STEP_KINDS"]
