"""From canonical rows to a clean discharge: masking, checks, sign, segment, summary.

Every reader ends here, so every format gets the same checks and the same
metadata (see :func:`dischargelab.io.read_discharge` for the keys).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..errors import DataError
from .columns import CANONICAL_COLUMNS, COLUMN_KEYS, CanonicalTable
from .segment import (
    MIN_SEGMENT_ROWS,
    SENTINEL_ABS,
    SOC_JUMP_PCT,
    charge_trend_V,
    choose_segment,
    detect_sign,
    find_segments,
    voltage_step_rest,
)

#: A required column with more missing values than this share of rows is an error.
MAX_MISSING_SHARE = 0.10

#: Values above these look like mV / mA read as V / A.
IMPLAUSIBLE_V = 1000.0
IMPLAUSIBLE_A = 1000.0

#: A median below this is not a battery voltage (the lowest common cell cutoff is ~0.9 V).
MIN_PLAUSIBLE_V = 0.5

DROP_REASONS = ("rest", "charge", "relaxation", "other_segments", "short_load", "sentinel",
                "nan", "duplicate_time", "partial_last_line", "logger_stop")

#: What a logger-stop record is, for notes (a test cut short often ends with one).
LOGGER_STOP = "the logger's record of zeros (voltage and current 0, not a battery reading)"

SIGNS = ("auto", "positive", "negative")


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def check_segment_option(segment):
    """Normalise ``segment``: ``"auto"``, ``"none"`` or an int >= 1."""
    if isinstance(segment, str):
        text = segment.strip().lower()
        if text in ("auto", "none"):
            return text
        if text.isdigit():
            segment = int(text)
        else:
            raise DataError(f"--segment must be auto, none or a segment number (1, 2, ...); "
                            f"got {segment!r}")
    if isinstance(segment, (bool, np.bool_)) or not isinstance(segment, (int, np.integer)):
        raise DataError(f"--segment must be auto, none or a segment number; got {segment!r}")
    if segment < 1:
        raise DataError(f"--segment counts from 1; got {segment}")
    return int(segment)


def check_current_option(current_A) -> float | None:
    """Validate ``current_A`` (``--current``): None or a positive finite number [A]."""
    if current_A is None:
        return None
    try:
        value = float(current_A)
    except (TypeError, ValueError):
        raise DataError(f"--current must be a number of amperes, got {current_A!r}") from None
    if not np.isfinite(value) or value <= 0:
        raise DataError(f"--current must be the discharge current, a positive number of amperes; "
                        f"got {current_A!r}")
    return value


def prepare(table: CanonicalTable, path_name: str, *, current_A=None, sign="auto",
            segment="auto", rest_sample="auto", rows_read: int | None = None,
            discharge_only: bool = True) -> tuple[pd.DataFrame, dict]:
    """Clean canonical rows and keep the discharge.

    Parameters
    ----------
    table : CanonicalTable
        Rows from a reader, canonical names and SI units.
    path_name : str
        File name for messages.
    current_A, sign, segment, rest_sample
        See :func:`dischargelab.io.read_discharge`.
    rows_read : int, optional
        Data rows in the file when the reader already dropped some (partial line).
    discharge_only : bool
        Refuse rows whose voltage rises overall (not a discharge); False for a whole
        tester file of charges and discharges read with ``segment="none"``.

    Returns
    -------
    frame : pandas.DataFrame
    meta : dict
    """
    if sign not in SIGNS:
        raise DataError(f"--sign must be auto, positive or negative; got {sign!r}")
    if rest_sample not in ("auto", "none"):
        raise DataError(f"rest_sample must be 'auto' or 'none'; got {rest_sample!r}")
    segment = check_segment_option(segment)
    given = check_current_option(current_A)

    frame = table.frame.reset_index(drop=True).copy()
    lines = np.asarray(table.line_numbers)
    meta = dict(table.meta)
    notes: list[str] = list(meta.pop("notes", []))
    dropped = dict.fromkeys(DROP_REASONS, 0)
    if meta.pop("partial_last_line", False):
        dropped["partial_last_line"] = 1
    for reason, count in meta.pop("reader_dropped", {}).items():
        dropped[reason] = dropped.get(reason, 0) + int(count)
    total = len(frame) + sum(dropped.values()) if rows_read is None else rows_read
    if len(frame) == 0:
        raise DataError(f"{path_name} has no data rows")

    # ---- current: measured column or given constant
    has_current = "current_A" in frame and bool(np.isfinite(frame["current_A"]).any())
    if "current_A" in frame and not has_current:
        notes.append("the current column is empty")
        frame = frame.drop(columns="current_A")

    # ---- sentinels and missing values
    required = ["time_s", "voltage_V"] + (["current_A"] if has_current else [])
    bad_sentinel = np.zeros(len(frame), dtype=bool)
    bad_nan = np.zeros(len(frame), dtype=bool)
    masked: dict[str, int] = {}
    last_partial = bool(meta.pop("partial_last_row_in_data", False))
    for key in [c for c in frame.columns if c in COLUMN_KEYS and c != "flight_mode"]:
        values = frame[key].to_numpy(dtype=float)
        sentinel = np.isinf(values) | (np.abs(np.nan_to_num(values)) > SENTINEL_ABS)
        missing = np.isnan(values)
        if key in required:
            bad_sentinel |= sentinel
            bad_nan |= missing & ~sentinel
            share = (missing.sum() - (1 if last_partial and missing[-1] else 0)) / len(values)
            if share > MAX_MISSING_SHARE:
                first = int(np.flatnonzero(missing)[0])
                source = meta.get("column_map", {}).get(key, key)
                raise DataError(
                    f"{path_name}: {key} ({source}) is empty or NaN in {int(missing.sum())} of "
                    f"{len(values)} rows (first at line {int(lines[first])}); fix the file or "
                    f"choose another column with --columns {key}=...")
        elif sentinel.any():
            frame.loc[sentinel, key] = np.nan
            masked[key] = int(sentinel.sum())
    bad_nan &= ~bad_sentinel
    if last_partial and bad_nan[-1]:
        bad_nan[-1] = False
        bad_sentinel[-1] = False
        dropped["partial_last_line"] += 1
        keep = np.ones(len(frame), dtype=bool)
        keep[-1] = False
    else:
        keep = np.ones(len(frame), dtype=bool)
    dropped["sentinel"] = int(bad_sentinel.sum())
    dropped["nan"] = int(bad_nan.sum())
    keep &= ~(bad_sentinel | bad_nan)
    frame, lines = frame[keep].reset_index(drop=True), lines[keep]
    if len(frame) == 0:
        raise DataError(f"{path_name}: no row has valid time, voltage"
                        + (" and current" if has_current else ""))
    frame, lines = _drop_logger_stop(frame, lines, has_current, dropped, notes)

    # ---- time must advance
    t = frame["time_s"].to_numpy(dtype=float)
    dt = np.diff(t)
    back = np.flatnonzero(dt < 0)
    if back.size:
        k = int(back[0]) + 1
        raise DataError(f"{path_name} line {int(lines[k])}: time goes backwards ({t[k]:g} s "
                        f"after {t[k - 1]:g} s on line {int(lines[k - 1])}); the rows must be in "
                        f"time order (is --columns time_s the right column?)")
    same = np.concatenate(([False], dt == 0))
    if same.sum() > 0.5 * len(t):
        raise DataError(f"{path_name}: the time column does not advance (the same value on "
                        f"{int(same.sum())} rows); choose the time column with "
                        f"--columns time_s=...")
    if same.any():
        dropped["duplicate_time"] = int(same.sum())
        frame, lines = frame[~same].reset_index(drop=True), lines[~same]

    # ---- plausibility of units
    explicit = set(meta.pop("explicit_units", []))
    v = frame["voltage_V"].to_numpy(dtype=float)
    if not meta.pop("cell_voltage_known", False):  # a tester's half cell may sit near 0 V
        _check_positive_voltage(v, lines, path_name)
    if "voltage_V" not in explicit and np.percentile(np.abs(v), 98) > IMPLAUSIBLE_V:
        raise DataError(f"{path_name}: voltages up to {np.max(v):g} V look like millivolts; "
                        f"add --units voltage_V=mV (or --units voltage_V=V if they are volts)")
    if not has_current and given is None:
        mapped = ", ".join(f"{k} = {v}" for k, v in meta.get("column_map", {}).items())
        raise DataError(f"{path_name} has no current column ({mapped}); give the constant "
                        f"discharge current with --current AMPS, or name the current column "
                        f"with --columns current_A=<column number or name>")
    if has_current and "current_A" not in explicit \
            and np.percentile(np.abs(frame["current_A"]), 98) > IMPLAUSIBLE_A:
        raise DataError(f"{path_name}: currents up to {np.max(np.abs(frame['current_A'])):g} A "
                        f"look like milliamperes; add --units current_A=mA "
                        f"(or --units current_A=A if they are amperes)")

    # ---- sign convention
    if has_current:
        if sign == "auto":
            discharge_sign, evidence = detect_sign(frame["time_s"], frame["current_A"],
                                                   frame["voltage_V"])
            flip = discharge_sign < 0
            meta["sign_source"] = "detected"
            meta["sign_evidence"] = evidence
        else:
            flip = sign == "negative"
            meta["sign_source"] = "given"
        if flip:
            frame["current_A"] = -frame["current_A"]
        meta["sign_convention"] = "discharge negative (flipped)" if flip else "discharge positive"
        meta["current_source"] = "column"
    else:
        meta["sign_convention"] = "discharge positive"
        meta["sign_source"] = "given current"
        meta["current_source"] = "given"
        if sign != "auto":
            notes.append("--sign ignored: the current is given with --current")

    # ---- segment
    rest = None
    segments_meta: list[dict] = []
    selected = None
    n = len(frame)
    if segment == "none":
        start, stop = 0, n
        if not has_current:
            frame["current_A"] = given
    else:
        if not has_current:
            frame["current_A"] = given
        try:
            search = find_segments(frame, breaks_s=table.breaks_s)
        except DataError as exc:
            raise DataError(_no_discharge(path_name, str(exc), frame, has_current, sign)) from None
        if not search.segments:
            raise DataError(_no_discharge(
                path_name, f"no run of {MIN_SEGMENT_ROWS} or more rows with discharge current "
                           "above "
                f"{search.threshold_A:.3g} A", frame, has_current, sign))
        chosen = choose_segment(search, frame, segment)
        state = search.state
        if rest_sample == "auto" and not has_current and chosen.start == 0:
            # no measured current: the ohmic step says whether row 0 was taken before the load
            is_rest, why = voltage_step_rest(frame["voltage_V"].to_numpy()[:chosen.stop])
            if is_rest:
                rest = _rest_row(frame, 0, lines, why, current_A=0.0)
                chosen.start = 1
                state = state.copy()
                state[0] = 0
            else:
                notes.append(f"first row not taken as a rest sample: {why}")
        elif rest_sample == "auto" and has_current and chosen.start > 0 \
                and state[chosen.start - 1] == 0:
            k, start = chosen.start - 1, chosen.start
            swapped = ("soc_pct" in frame and frame["soc_pct"].iloc[start]
                       - frame["soc_pct"].iloc[k] >= SOC_JUMP_PCT)
            if not swapped:
                rest = _rest_row(frame, k, lines, "idle row just before the load step")
        start, stop = chosen.start, chosen.stop
        t = frame["time_s"].to_numpy(dtype=float)
        i = frame["current_A"].to_numpy(dtype=float)
        for s in search.segments:
            seg_t, seg_i = t[s.start:s.stop], i[s.start:s.stop]
            segments_meta.append({
                "number": s.number,
                "first_line": int(lines[s.start]), "last_line": int(lines[s.stop - 1]),
                "start_time_s": float(seg_t[0]), "duration_s": float(seg_t[-1] - seg_t[0]),
                "rows": s.rows, "mean_current_A": float(np.mean(seg_i)),
                "charge_Ah": float(np.sum(0.5 * (seg_i[1:] + seg_i[:-1]) * np.diff(seg_t))
                                   / 3600.0),
                "ended_by": s.ended_by,
            })
        selected = chosen.number
        meta["current_profile"] = "variable" if search.variable else "constant"
        meta["load_threshold_A"] = float(search.threshold_A)
        if search.gap_limit_s is not None:
            meta["gap_limit_s"] = search.gap_limit_s
        # classify the dropped rows
        before, after = np.arange(n) < start, np.arange(n) >= stop
        in_other = np.zeros(n, dtype=bool)
        for s in search.segments:
            if s.number != chosen.number:
                in_other[s.start:s.stop] = True
        dropped["rest"] = int(np.sum(before & (state == 0)))
        dropped["relaxation"] = int(np.sum(after & (state == 0)))
        dropped["charge"] = int(np.sum((before | after) & (state == -1)))
        dropped["other_segments"] = int(np.sum(in_other))
        dropped["short_load"] = int(np.sum(search.short_rows & (before | after)))
    kept = frame.iloc[start:stop].reset_index(drop=True)
    kept_lines = lines[start:stop]
    if len(kept) < 2:
        raise DataError(f"{path_name}: the discharge has only {len(kept)} row(s)")
    if has_current and given is not None:
        notes.append(f"current column replaced by the given --current {given:g} A "
                     f"(the column was used only to find the discharge)")
        kept["current_A"] = given
        meta["current_source"] = "given"

    # every row of a long log read whole (segment "none") is not one discharge
    if discharge_only and segment != "none":
        _check_voltage(kept, kept_lines, path_name)

    offset = float(kept["time_s"].iloc[0])
    kept["time_s"] = kept["time_s"] - offset
    if rest is not None:
        rest["time_s"] = rest["time_s"] - offset
    ordered = [c for c in CANONICAL_COLUMNS if c in kept] + \
              [c for c in kept.columns if c not in CANONICAL_COLUMNS]
    kept = kept[ordered]

    meta.update({
        "source": meta.get("source", path_name),
        "rows_read": int(total),
        "rows_kept": int(len(kept)),
        "dropped": dropped,
        "rest_sample": rest,
        "time_offset_s": offset,
        "segments": segments_meta,
        "segment": selected,
        "first_line": int(kept_lines[0]),
        "last_line": int(kept_lines[-1]),
    })
    if masked:
        meta["masked"] = masked
    meta["notes"] = notes
    meta["summary"] = summary_sentence(meta)
    return kept, meta


def _drop_logger_stop(frame: pd.DataFrame, lines, has_current: bool, dropped: dict,
                      notes: list) -> tuple[pd.DataFrame, np.ndarray]:
    """Drop the records of zeros a logger writes when it starts or stops (first or last rows
    with voltage <= 0 and no current): a test cut short keeps its discharge.

    A zero inside the data, or a file of nothing but zeros, is left for the voltage check
    (the wrong column, a temperature file).
    """
    v = frame["voltage_V"].to_numpy(dtype=float)
    zero = v <= 0
    if has_current:
        zero &= np.nan_to_num(frame["current_A"].to_numpy(dtype=float), nan=0.0) == 0
    n = zero.size
    if not zero.any() or zero.all():
        return frame, lines
    lead = int(np.argmin(zero))                 # first row that is a reading
    trail = int(np.argmin(zero[::-1]))          # rows of zeros at the end
    if lead == 0 and trail == 0:
        return frame, lines
    keep = np.zeros(n, dtype=bool)
    keep[lead:n - trail] = True
    for rows, where in ((lines[:lead], "first"), (lines[n - trail:], "last")):
        if len(rows):
            at = f"line {int(rows[0])}" if len(rows) == 1 else \
                f"lines {int(rows[0])}-{int(rows[-1])}"
            notes.append(f"dropped {_plural(len(rows), 'row')} at {at}, the {where} of the "
                         f"file: {LOGGER_STOP}")
    dropped["logger_stop"] = int(lead + trail)
    return frame[keep].reset_index(drop=True), lines[keep]


def _rest_row(frame: pd.DataFrame, k: int, lines, why: str, current_A=None) -> dict:
    current = frame["current_A"].iloc[k] if current_A is None else current_A
    row = {"voltage_V": float(frame["voltage_V"].iloc[k]),
           "time_s": float(frame["time_s"].iloc[k]),
           "current_A": float(current),
           "line": int(lines[k]), "rule": why}
    if "temperature_C" in frame and np.isfinite(frame["temperature_C"].iloc[k]):
        row["temperature_C"] = float(frame["temperature_C"].iloc[k])
    return row


def _no_discharge(path_name, reason, frame, has_current, sign) -> str:
    text = f"{path_name}: no discharge found ({reason.removeprefix('no discharge found: ')})"
    if has_current:
        i = frame["current_A"].to_numpy(dtype=float)
        text += f"; current after the sign convention spans {i.min():.3g} to {i.max():.3g} A"
        if sign == "auto":
            text += ("; if the file is a discharge with another sign convention, use "
                     "--sign positive or --sign negative")
        else:
            text += "; check --sign"
    return text


def _check_positive_voltage(v: np.ndarray, lines, path_name: str) -> None:
    hint = ("is this a temperature file or the wrong column? Give the voltage file, or choose "
            "the column with --columns voltage_V=...")
    low = np.flatnonzero(v <= 0)
    if low.size:
        raise DataError(
            f"{path_name}: the voltage column holds {v[low[0]]:g} at line {int(lines[low[0]])} "
            f"(values <= 0 V are not a battery voltage); {hint}")
    median = float(np.median(v))
    if median < MIN_PLAUSIBLE_V:
        raise DataError(f"{path_name}: the voltage column is around {median:.3g} V, too low for a "
                        f"battery under test; {hint}")


def _check_voltage(kept: pd.DataFrame, lines, path_name: str) -> None:
    """A discharge's voltage falls with the charge it moves: the change the charge explains
    (:func:`~.segment.charge_trend_V`, the drop that follows the current's level set
    apart: a flight from a take-off burst to a light hover) rises by no more than 2 %."""
    v = kept["voltage_V"].to_numpy(dtype=float)
    k = max(1, len(v) // 10)
    start = float(np.median(v[:k]))
    rise = charge_trend_V(kept["time_s"].to_numpy(dtype=float),
                          np.abs(kept["current_A"].to_numpy(dtype=float)), v)
    if rise > start * 0.02 + 0.005:
        end = start + rise
        raise DataError(
            f"{path_name}: the 'voltage' rises from {start:.4g} to {end:.4g} during the "
            f"discharge; that is not a discharge voltage (a temperature file, a charge, or the "
            f"wrong column?). Check the file, --columns voltage_V=... and --sign")


def summary_sentence(meta: dict) -> str:
    """One line saying what was kept and dropped, e.g. for the command line."""
    d = meta["dropped"]
    parts = []
    if d["rest"]:
        text = f"{_plural(d['rest'], 'rest row')} before load start"
        if meta.get("rest_sample"):
            text += " (the last one kept as rest sample)"
        parts.append(text)
    if d["relaxation"]:
        parts.append(f"{_plural(d['relaxation'], 'relaxation row')} after load end")
    if d["charge"]:
        parts.append(_plural(d["charge"], "charge row"))
    if d["other_segments"]:
        others = max(len(meta.get("segments", [])) - 1, 1)
        parts.append(f"{_plural(d['other_segments'], 'row')} of {_plural(others, 'other segment')}")
    if d["short_load"]:
        parts.append(f"{_plural(d['short_load'], 'row')} of load too short to be a discharge")
    if d["sentinel"]:
        parts.append(f"{_plural(d['sentinel'], 'row')} with sentinel values (|x| > 1e30)")
    if d["nan"]:
        parts.append(f"{_plural(d['nan'], 'row')} with empty or NaN values")
    if d["duplicate_time"]:
        parts.append(f"{_plural(d['duplicate_time'], 'row')} repeating the previous time")
    if d["partial_last_line"]:
        parts.append("an incomplete last line")
    if d.get("logger_stop"):
        parts.append(f"{_plural(d['logger_stop'], 'logger record')} of zeros (a start or stop "
                     "record)")
    if d.get("malformed"):
        parts.append(f"{_plural(d['malformed'], 'malformed line')}")
    text = f"kept {meta['rows_kept']} of {meta['rows_read']} rows"
    if parts:
        text += " (dropped " + ", ".join(parts) + ")"
    segments = meta.get("segments") or []
    if len(segments) > 1:
        text += f"; segment {meta['segment']} of {len(segments)}"
    if meta.get("sign_convention", "").endswith("(flipped)"):
        text += "; current sign flipped (discharge negative in the file)"
    if meta.get("current_source") == "given":
        text += "; current given"
    return text


def describe(frame: pd.DataFrame, meta: dict) -> str:
    """Several lines describing a loaded discharge (for ``--verbose`` style output)."""
    t = frame["time_s"].to_numpy(dtype=float)
    v = frame["voltage_V"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float)
    charge = float(np.sum(0.5 * (i[1:] + i[:-1]) * np.diff(t)) / 3600.0) if t.size > 1 else 0.0
    out = [
        f"{meta.get('source')}: {meta.get('format')}",
        f"  {meta.get('summary')}",
        f"  duration {t[-1]:.1f} s, {len(t)} rows, voltage {v.max():.4g} -> {v[-1]:.4g} V "
        f"(min {v.min():.4g}), current mean {i.mean():.4g} A ({meta.get('current_source')}), "
        f"charge {charge:.4g} Ah",
        f"  sign: {meta.get('sign_convention')}"
        + (f" ({meta['sign_evidence']})" if meta.get("sign_evidence") else ""),
    ]
    if meta.get("column_map"):
        out.append("  columns: " + ", ".join(f"{k} = {v}" for k, v in meta["column_map"].items()))
    if meta.get("units"):
        out.append("  units: " + ", ".join(f"{k} {v}" for k, v in meta["units"].items()))
    rest = meta.get("rest_sample")
    if rest:
        out.append(f"  rest sample: {rest['voltage_V']:.4g} V at {rest['time_s']:.3g} s "
                   f"(line {rest['line']}; {rest['rule']})")
    segments = meta.get("segments") or []
    if len(segments) > 1:
        out.append(f"  {len(segments)} discharge segments (kept {meta.get('segment')}):")
        for s in segments:
            mark = "*" if s["number"] == meta.get("segment") else " "
            out.append(f"   {mark}{s['number']:>3}: lines {s['first_line']}-{s['last_line']}, "
                       f"{s['duration_s']:.0f} s, {s['rows']} rows, {s['mean_current_A']:.3g} A "
                       f"mean, {s['charge_Ah']:.3g} Ah, ended by {s['ended_by']}")
    for note in meta.get("notes", []):
        out.append(f"  note: {note}")
    return "\n".join(out)


__all__ = ["prepare", "describe", "summary_sentence", "check_segment_option",
           "check_current_option", "DROP_REASONS", "SIGNS", "LOGGER_STOP"]
