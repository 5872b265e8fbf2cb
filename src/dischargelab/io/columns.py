"""Column names and units: from a source table to the canonical columns.

Canonical columns (the glossary of dischargelab): ``time_s`` [s], ``voltage_V``
[V], ``current_A`` [A, discharge positive], ``temperature_C`` [degC]. Readers may
add ``soc_pct`` [%], ``ambient_temperature_C`` [degC] and ``flight_mode`` (text).

A source column is chosen, in this order, by the ``columns`` mapping the user
gave (``--columns time_s=0,voltage_V=2`` or header names), then by recognising
its header name (``"Voltage (mV)"``, ``"current_mA"``, ``"Time [h]"``). Units
come from ``units`` (``--units voltage_V=mV``), then from the header name, then
default to the canonical unit. Every choice is recorded in the metadata.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import DataError

#: Required and optional canonical columns, in output order.
CANONICAL_COLUMNS: tuple[str, ...] = ("time_s", "voltage_V", "current_A", "temperature_C")

#: Extra numeric columns a reader may keep.
EXTRA_COLUMNS: tuple[str, ...] = ("soc_pct", "ambient_temperature_C")

#: Extra text columns a reader may keep.
TEXT_COLUMNS: tuple[str, ...] = ("flight_mode",)

#: Every name accepted as a key of ``columns`` / ``--columns``.
COLUMN_KEYS: tuple[str, ...] = CANONICAL_COLUMNS + EXTRA_COLUMNS + TEXT_COLUMNS

COLUMNS_HELP = ("--columns time_s=0,current_A=1,voltage_V=2,temperature_C=4 "
                "(0-based column numbers or header names)")

#: Unit name -> (scale, offset) giving the canonical value as scale * x + offset.
UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "time_s": {"s": (1.0, 0.0), "ms": (1e-3, 0.0), "min": (60.0, 0.0), "h": (3600.0, 0.0)},
    "voltage_V": {"V": (1.0, 0.0), "mV": (1e-3, 0.0)},
    "current_A": {"A": (1.0, 0.0), "mA": (1e-3, 0.0)},
    "temperature_C": {"degC": (1.0, 0.0), "K": (1.0, -273.15)},
    "ambient_temperature_C": {"degC": (1.0, 0.0), "K": (1.0, -273.15)},
    "soc_pct": {"%": (1.0, 0.0)},
}

_UNIT_SPELLINGS = {
    "s": "s", "sec": "s", "secs": "s", "second": "s", "seconds": "s",
    "ms": "ms", "msec": "ms", "millisecond": "ms", "milliseconds": "ms",
    "min": "min", "mins": "min", "minute": "min", "minutes": "min",
    "h": "h", "hr": "h", "hrs": "h", "hour": "h", "hours": "h",
    "v": "V", "volt": "V", "volts": "V",
    "mv": "mV", "millivolt": "mV", "millivolts": "mV",
    "a": "A", "amp": "A", "amps": "A", "ampere": "A", "amperes": "A",
    "ma": "mA", "milliamp": "mA", "milliamps": "mA", "milliampere": "mA",
    "degc": "degC", "deg c": "degC", "°c": "degC", "ºc": "degC", "c": "degC", "celsius": "degC",
    "k": "K", "kelvin": "K",
    "%": "%", "pct": "%", "percent": "%",
}


def normalise_unit(text: str) -> str | None:
    """Canonical spelling of a unit name (``"mA"``, ``"degC"``...), or None if unknown."""
    return _UNIT_SPELLINGS.get(text.strip().lower().replace("_", " "))


def _split_pairs(text: str, what: str, example: str) -> dict[str, str]:
    result: dict[str, str] = {}
    for item in text.split(","):
        if not item.strip():
            continue
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise DataError(f"{what} expects NAME=VALUE pairs separated by commas, e.g. {example}; "
                            f"got {item.strip()!r}")
        if key in result:
            raise DataError(f"{what} names {key} twice")
        result[key] = value
    if not result:
        raise DataError(f"{what} is empty; e.g. {example}")
    return result


def parse_columns(text: str) -> dict[str, int | str]:
    """Parse the ``--columns`` option.

    ``"time_s=0,current_A=1,voltage_V=2,temperature_C=4"`` gives
    ``{"time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4}``.
    Values are 0-based column numbers or header names (a header name may not
    contain a comma).
    """
    pairs = _split_pairs(text, "--columns", COLUMNS_HELP.removeprefix("--columns "))
    return validate_columns(pairs)


def validate_columns(columns: dict) -> dict[str, int | str]:
    """Check the keys of a columns mapping; digits become integers (column numbers)."""
    result: dict[str, int | str] = {}
    for key, value in columns.items():
        if key not in COLUMN_KEYS:
            raise DataError(f"--columns: unknown name {key!r}; use {', '.join(COLUMN_KEYS)}")
        if isinstance(value, (bool, np.bool_)):
            raise DataError(f"--columns {key}: give a column number or header name, not {value!r}")
        if isinstance(value, (int, np.integer)):
            value = int(value)
        elif isinstance(value, str) and re.fullmatch(r"\s*\d+\s*", value):
            value = int(value)
        elif not isinstance(value, str) or not value.strip():
            raise DataError(f"--columns {key}: give a column number or header name, got {value!r}")
        if isinstance(value, int) and value < 0:
            raise DataError(f"--columns {key}={value}: column numbers start at 0")
        result[key] = value
    used = list(result.values())
    dupes = {v for v in used if used.count(v) > 1}
    if dupes:
        raise DataError(f"--columns uses column {sorted(map(str, dupes))[0]} for two names")
    return result


def parse_units(text: str) -> dict[str, str]:
    """Parse the ``--units`` option: ``"voltage_V=mV,time_s=h"`` -> dict."""
    return validate_units(_split_pairs(text, "--units", "voltage_V=mV,current_A=mA,time_s=h"))


def validate_units(units: dict) -> dict[str, str]:
    """Check a units mapping; returns canonical unit spellings."""
    result = {}
    for key, value in units.items():
        if key not in UNITS:
            raise DataError(f"--units: unknown column {key!r}; use {', '.join(UNITS)}")
        unit = normalise_unit(str(value))
        if unit not in UNITS[key]:
            raise DataError(f"--units {key}={value}: unit not understood; "
                            f"use one of {', '.join(UNITS[key])}")
        result[key] = unit
    return result


# --------------------------------------------------------------------------- names

_BRACKETED_UNIT = re.compile(r"^(.*?)[\s_]*[(\[{]\s*([^()\[\]{}]*?)\s*[)\]}]\s*$")
_SLASH_UNIT = re.compile(r"^(.*?\S)\s*/\s*([^/\s]+)\s*$")
_SUFFIX_UNIT = re.compile(r"^(.*?\S)[\s_-]+([^\s_-]+)\s*$")


def split_name_unit(name: str) -> tuple[str, str | None, str | None]:
    """Split a header name into (base name, canonical unit, unit as written).

    ``"Voltage (mV)"`` -> ``("voltage", "mV", "mV")``; ``"current_mA"`` ->
    ``("current", "mA", "mA")``; ``"Battery Temp"`` -> ``("battery temp", None, None)``.
    """
    text = str(name).strip().lstrip("\ufeff")
    written = None
    for pattern in (_BRACKETED_UNIT, _SLASH_UNIT, _SUFFIX_UNIT):
        match = pattern.match(text)
        if match and match.group(1).strip() and normalise_unit(match.group(2)) is not None:
            text, written = match.group(1), match.group(2)
            break
    base = re.sub(r"[\s_\-.]+", " ", text.lower()).strip()
    return base, (normalise_unit(written) if written else None), written


_EXACT = {
    "time_s": {"time", "t", "elapsed", "elapsed time", "test time", "time elapsed", "total time",
               "runtime", "run time", "x value", "seconds", "relative time"},
    "voltage_V": {"voltage", "v", "u", "ecell", "ewe", "vcell", "cell voltage", "pack voltage",
                  "battery voltage", "terminal voltage", "potential", "volt", "volts",
                  "currentvoltage"},
    "current_A": {"current", "i", "<i>", "amps", "amp", "cell current", "pack current",
                  "battery current", "load current", "currentcurrent"},
    "temperature_C": {"temperature", "temp", "t cell", "tcell", "cell temperature",
                      "battery temperature", "cell temp", "battery temp", "surface temperature"},
    "ambient_temperature_C": {"ambient", "ambient temperature", "ambient temp",
                              "chamber temperature", "chamber temp", "room temperature"},
    "soc_pct": {"soc", "state of charge", "remainpowerpercent", "charge remaining"},
    "flight_mode": {"flight mode", "flight mode last event"},
}


def name_score(base: str, column: str, unit: str | None = None) -> int:
    """How well a normalised header name (and its unit) fits a canonical column (0 = not at all).

    A unit that does not belong to the column's quantity rules the column out,
    so ``"T [degC]"`` is a temperature, not a time.
    """
    if unit is not None and column in UNITS and unit not in UNITS[column]:
        return 0
    if column == "temperature_C" and base == "t" and unit in ("degC", "K"):
        return 3
    if base in _EXACT[column]:
        return 3
    if column == "time_s" and "time" in base:
        if any(w in base for w in ("date", "stamp", "clock", "remaining", "step")):
            return 0
        return 2
    if column == "voltage_V" and "volt" in base:
        return 2
    if column == "current_A" and ("current" in base or base.startswith("curr")) \
            and "volt" not in base and "set" not in base.split():
        return 2
    if column == "temperature_C" and "temp" in base:
        if any(w in base for w in ("ambient", "chamber", "air", "room", "rise")):
            return 0
        return 3 if any(w in base for w in ("cell", "batt", "surface", "pack")) else 2
    if column == "ambient_temperature_C" and "temp" in base \
            and any(w in base for w in ("ambient", "chamber", "air", "room")):
        return 2
    return 0


# --------------------------------------------------------------------------- mapping

@dataclass
class SourceTable:
    """Rows as read from a file, before the columns are given their meaning.

    Attributes
    ----------
    data : pandas.DataFrame
        One column per source column, labelled 0..n-1; values as parsed
        (float, or object where a column holds text).
    names : list of str or None
        Header names (None for a file without header).
    line_numbers : numpy.ndarray
        1-based line of the file each row came from (for error messages).
    meta : dict
        What the reader learnt (format, delimiter, preamble, notes...).
    names_inferred : str or None
        Set when ``names`` were not read from a header line but inferred (e.g.
        from a LabVIEW ``Description``); the text says from what.
    """

    data: pd.DataFrame
    names: list[str] | None
    line_numbers: np.ndarray
    meta: dict = field(default_factory=dict)
    names_inferred: str | None = None


@dataclass
class CanonicalTable:
    """Rows with canonical column names and units (not yet cleaned or segmented).

    ``breaks_s`` are times (same clock as ``time_s``) where a segment must end
    (e.g. a landing event); ``events`` are reader events for the metadata.
    """

    frame: pd.DataFrame
    line_numbers: np.ndarray
    meta: dict = field(default_factory=dict)
    breaks_s: list[float] = field(default_factory=list)


def _describe_source(index: int, names: list[str] | None) -> str:
    if names is None or index >= len(names):
        return f"column {index}"
    return f"column {index} {names[index]!r}"


def _resolve(key: str, spec, table: SourceTable, path_name: str) -> int:
    ncols = table.data.shape[1]
    names = table.names
    if isinstance(spec, int):
        if spec >= ncols:
            raise DataError(f"--columns {key}={spec}: {path_name} has only {ncols} columns "
                            f"(numbered 0 to {ncols - 1})")
        return spec
    if names is None:
        raise DataError(f"--columns {key}={spec!r}: {path_name} has no header, so give a column "
                        f"number (0 to {ncols - 1}) instead of a name")
    for matcher in (lambda n: n == spec, lambda n: n.strip().lower() == spec.strip().lower()):
        hits = [k for k, n in enumerate(names) if matcher(n)]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            raise DataError(f"--columns {key}={spec!r}: {path_name} has {len(hits)} columns with "
                            f"that name; give the column number instead ({hits})")
    raise DataError(f"--columns {key}={spec!r}: no such column in {path_name}; "
                    f"columns are: {', '.join(repr(n) for n in names)}")


def _auto_map(table: SourceTable, taken: set[int], wanted: list[str]) -> tuple[dict, list[str]]:
    """Recognise columns by header name; returns {key: index} and notes."""
    names = table.names or []
    parsed = [split_name_unit(n) for n in names]
    found: dict[str, int] = {}
    notes: list[str] = []
    # Strongest matches first so that e.g. "Battery Temp" beats "Chamber Temp".
    candidates = []
    for key in wanted:
        for k, (base, unit, _) in enumerate(parsed):
            score = 4 if names[k].strip() == key else name_score(base, key, unit)
            if score and k not in taken:
                candidates.append((-score, k, key))
    by_key: dict[str, list[tuple[int, int]]] = {}
    for neg, k, key in sorted(candidates):
        by_key.setdefault(key, []).append((-neg, k))
    for neg, k, key in sorted(candidates):
        if key in found or k in taken:
            continue
        best = [c for c in by_key[key] if c[0] == -neg and c[1] not in taken]
        if len(best) > 1 and key in ("time_s", "voltage_V", "current_A"):
            options = ", ".join(f"{names[c[1]]!r} (column {c[1]})" for c in best)
            raise DataError(f"{key}: several columns could be it: {options}; choose one with "
                            f"--columns {key}=<column number or name>")
        found[key] = k
        taken.add(k)
        if len(best) > 1:
            notes.append(f"{key}: took {names[k]!r}; also matched "
                         + ", ".join(repr(names[c[1]]) for c in best if c[1] != k))
    return found, notes


def to_numeric_column(series: pd.Series, key: str, label: str, lines: np.ndarray,
                      path_name: str, last_row_partial_ok: bool = True) -> tuple[np.ndarray, int]:
    """Convert one source column to float; text that is not a number is an error.

    Empty fields become NaN. A bad value on the last row only is tolerated (a
    line cut short when the logger stopped) and reported by the returned count.

    Returns
    -------
    values : numpy.ndarray
    partial_last_row : int
        1 if the last row held text that is not a number (then set to NaN), else 0.
    """
    if pd.api.types.is_numeric_dtype(series.dtype):
        return series.to_numpy(dtype=float), 0
    text = series.astype("string").str.strip()
    values = pd.to_numeric(text.str.replace("\ufeff", "", regex=False), errors="coerce")
    bad = values.isna() & text.notna() & (text != "") & ~text.str.lower().isin(
        ["nan", "na", "n/a", "null", "none", "-", "inf", "-inf"])
    bad_rows = np.flatnonzero(bad.to_numpy())
    partial = 0
    if bad_rows.size and last_row_partial_ok and bad_rows[-1] == len(series) - 1 \
            and bad_rows.size == 1 and len(series) > 1:
        partial, bad_rows = 1, bad_rows[:0]
    if bad_rows.size:
        row = int(bad_rows[0])
        raise DataError(f"{path_name} line {int(lines[row])}: {label} ({key}) holds "
                        f"{str(text.iloc[row])[:40]!r}, which is not a number; fix the line or "
                        f"choose another column with --columns {key}=...")
    return values.to_numpy(dtype=float), partial


_CLOCK = re.compile(r"^(\d+):(\d{2}):(\d{2}(?:\.\d*)?)$")
_ISO_STAMP = re.compile(r"^\d{4}-\d{2}-\d{2}[T ]\d{1,2}:\d{2}(:\d{2}(\.\d*)?)?")


def time_from_text(series: pd.Series) -> tuple[np.ndarray, str] | None:
    """Seconds from clock times (``H:MM:SS.fff``) or ISO 8601 time stamps, or None.

    Clock times are elapsed time or time of day; a time of day more than 12 h
    earlier than the row before is taken as a midnight rollover. Time stamps
    (``2023-09-06 15:36:28.1``) become seconds since the first row.

    Returns
    -------
    (seconds, note) or None when the column holds neither form.
    """
    if pd.api.types.is_numeric_dtype(series.dtype):
        return None
    text = series.astype("string").str.strip()
    filled = text[text.notna() & (text != "")]
    if filled.empty:
        return None
    sample = filled.iloc[:50]
    if sample.str.match(_CLOCK).mean() >= 0.9:
        parts = text.str.extract(_CLOCK)
        seconds = (parts[0].astype(float) * 3600 + parts[1].astype(float) * 60
                   + parts[2].astype(float)).to_numpy(dtype=float)
        steps = np.diff(seconds)
        rollover = np.concatenate(([0.0], np.cumsum(np.where(steps < -43200, 86400.0, 0.0))))
        seconds = seconds + np.where(np.isnan(rollover), 0.0, rollover)
        note = f"time read from clock times H:MM:SS (first {filled.iloc[0]})"
        if (steps < -43200).any():
            note += "; times after midnight were shifted by 24 h"
        return seconds, note
    if sample.str.match(_ISO_STAMP).mean() >= 0.9:
        stamps = pd.to_datetime(text, errors="coerce", format="ISO8601")
        first = stamps.dropna().iloc[0]
        seconds = (stamps - first).dt.total_seconds().to_numpy(dtype=float)
        return seconds, f"time read from time stamps, 0 s = {first.isoformat()}"
    return None


def map_columns(table: SourceTable, path_name: str, columns: dict | None = None,
                units: dict | None = None) -> CanonicalTable:
    """Give the source columns their canonical meaning and scale them to SI units.

    Parameters
    ----------
    table : SourceTable
    path_name : str
        File name used in messages.
    columns : dict, optional
        ``{canonical name: column number or header name}``; others are found by
        header name.
    units : dict, optional
        ``{canonical name: unit}`` overriding units read from the header.

    Raises
    ------
    DataError
        Unknown or ambiguous columns; a headerless file with more than two
        columns and no ``--columns``; text in a numeric column.
    """
    columns = validate_columns(columns or {})
    units = validate_units(units or {})
    ncols = table.data.shape[1]
    chosen: dict[str, int] = {}
    how: dict[str, str] = {}
    notes: list[str] = []
    for key, spec in columns.items():
        chosen[key] = _resolve(key, spec, table, path_name)
        how[key] = "given"
    taken = set(chosen.values())
    if table.names is not None:
        wanted = [k for k in COLUMN_KEYS if k not in chosen]
        found, auto_notes = _auto_map(table, taken, wanted)
        for key, k in found.items():
            chosen[key] = k
            how[key] = "header name" if table.names_inferred is None else "inferred name"
        notes += auto_notes
        if table.names_inferred and found:
            notes.append(f"column meaning inferred from {table.names_inferred}: "
                         + ", ".join(f"{key} = {_describe_source(k, table.names)}"
                                     for key, k in found.items())
                         + "; override with --columns if wrong")
    elif not columns:
        if ncols == 2:
            chosen = {"time_s": 0, "voltage_V": 1}
            how = {"time_s": "two-column rule", "voltage_V": "two-column rule"}
            notes.append("no header and two columns: read as time [s], voltage [V]; "
                         "use --columns and --units if that is wrong")
        else:
            shown = table.meta.get("first_data_line")
            if shown is None:
                shown = ", ".join(str(x) for x in table.data.iloc[0].tolist())
            shown = shown.strip()
            shown = shown if len(shown) <= 120 else shown[:117] + "..."
            raise DataError(f"{path_name} has no header and {ncols} columns (first row: {shown}); "
                            f"say which column is which, e.g. {COLUMNS_HELP}")
    missing = [k for k in ("time_s", "voltage_V") if k not in chosen]
    if missing:
        listing = (", ".join(repr(n) for n in table.names) if table.names
                   else f"{ncols} unnamed columns")
        raise DataError(f"{path_name}: no {' or '.join(missing)} column found among {listing}; "
                        f"name it with --columns {missing[0]}=<column number or name>")

    frame = pd.DataFrame()
    column_map: dict[str, str] = {}
    unit_map: dict[str, str] = {}
    partial = 0
    lines = table.line_numbers
    for key in COLUMN_KEYS:
        if key not in chosen:
            continue
        k = chosen[key]
        label = _describe_source(k, table.names)
        series = table.data.iloc[:, k]
        if key in TEXT_COLUMNS:
            frame[key] = series.astype("string").str.strip().to_numpy(dtype=object)
            column_map[key] = f"{label} ({how[key]})"
            continue
        clock = time_from_text(series) if key == "time_s" else None
        if clock is not None:
            frame[key], clock_note = clock
            notes.append(clock_note)
            if key in units:
                notes.append(f"--units {key}={units[key]} ignored: the column holds clock times")
            column_map[key] = f"{label} ({how[key]})"
            unit_map[key] = "s (clock)"
            continue
        values, bad_last = to_numeric_column(series, key, label, lines, path_name)
        partial = max(partial, bad_last)
        header_unit, written = None, None
        if table.names is not None and k < len(table.names):
            _, header_unit, written = split_name_unit(table.names[k])
        if key in units:
            unit, source = units[key], "given"
            if header_unit and header_unit != unit:
                notes.append(f"{key}: header says {written!r} but --units gives {unit}; "
                             f"using {unit}")
        elif header_unit is not None:
            if header_unit not in UNITS.get(key, {}):
                raise DataError(f"{path_name}: {label} is used as {key} but its unit {written!r} "
                                f"is not a unit of that quantity; fix --columns or give --units "
                                f"{key}=<unit>")
            unit, source = header_unit, "header"
        else:
            unit, source = next(iter(UNITS[key])), "default"
        scale, offset = UNITS[key][unit]
        if scale != 1.0 or offset != 0.0:
            values = values * scale + offset
        frame[key] = values
        column_map[key] = f"{label} ({how[key]})"
        unit_map[key] = f"{unit} ({source})"
    meta = dict(table.meta)
    meta["column_map"] = column_map
    meta["units"] = unit_map
    meta.setdefault("notes", [])
    meta["notes"] = list(meta["notes"]) + notes
    meta["explicit_units"] = sorted(k for k, v in unit_map.items() if "(default)" not in v)
    if partial:
        meta["partial_last_row_in_data"] = True
    return CanonicalTable(frame=frame, line_numbers=np.asarray(lines), meta=meta)


__all__ = [
    "CANONICAL_COLUMNS", "EXTRA_COLUMNS", "TEXT_COLUMNS", "COLUMN_KEYS", "UNITS",
    "parse_columns", "parse_units", "validate_columns", "validate_units", "normalise_unit",
    "split_name_unit", "name_score", "SourceTable", "CanonicalTable", "map_columns",
    "to_numeric_column", "time_from_text",
]
