"""Testers' text and spreadsheet exports, read by what their columns mean.

Arbin (CSV and ``.xlsx`` from MITS Pro / MITS 7-8), Maccor text exports and
other testers' exports name their columns in many ways (``Test_Time(s)``, ``Test
Time (s)``, ``TestTime``; ``Current(A)``, ``Amps``, ``I/mA``). A column is given a
**role** by its name without the unit, and scaled by the unit in its name
(``(mA)``, ``[mAh]``, ``/mA.h``); the roles are test time, voltage, current,
cycle and step numbers, a state column (charge / discharge / rest), the
tester's charge and discharge counters, a per-step capacity counter,
temperature and date-time. A table is a tester table when it has time, voltage,
current and a cycle or step number. Chinese testers' headers (电压, 电流, 工步号,
循环号, 测试时间...) read the same, their files in UTF-8 or GB 18030.

Time: a test time, else a date-time column. A time that restarts at every step
(Neware BTS's ``Time(h:min:s.ms)``, ``Relative Time``) is added up over the steps, a
pause between steps taken from the date-time column where there is one.

Maccor text: a few preamble lines, then a tab-separated header (``Rec#  Cyc#
Step  TestTime  StepTime  Amp-hr  Watt-hr  Amps  Volts  State ...``); the
current is unsigned and ``State`` (``C``, ``D``, ``R``) gives its sign; test
time is written ``0d 00:00:05.05``.
"""

from __future__ import annotations

import io
import re
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import DataError, require
from .steps import TesterRecords, step_bounds

#: Unit as written -> (scale, offset) to the role's unit, by quantity.
UNITS = {
    "time": {"s": 1.0, "sec": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0, "hr": 3600.0,
             # a clock written out (Neware's ``Time(h:min:s.ms)``): parsed as text
             "h:min:s.ms": 1.0, "h:min:s": 1.0, "hh:mm:ss": 1.0, "hh:mm:ss.ms": 1.0,
             "hh:mm:ss.sss": 1.0, "h:mm:ss": 1.0,
             "second": 1.0, "seconds": 1.0, "minutes": 60.0, "hours": 3600.0},
    "voltage": {"v": 1.0, "mv": 1e-3},
    "current": {"a": 1.0, "ma": 1e-3, "ua": 1e-6, "µa": 1e-6, "μa": 1e-6},
    "capacity": {"ah": 1.0, "a.h": 1.0, "mah": 1e-3, "ma.h": 1e-3, "uah": 1e-6, "µah": 1e-6,
                 "µa.h": 1e-6},
    "temperature": {"c": 0.0, "degc": 0.0, "°c": 0.0, "deg c": 0.0, "k": -273.15},
}

#: Role -> (quantity, names without unit, best first).
ROLES = {
    "time_s": ("time", ("test time", "testtime", "total time", "test", "run time",
                        "prog time", "time",
                        "elapsed time", "test time s", "relative time", "step time",
                        "测试时间", "总时间", "时间", "相对时间", "工步时间")),
    # EC-Lab: the cell's voltage (``Ecell``, ``Ewe-Ece``) before the working electrode's
    # against the reference (``Ewe``), which is the cell's only in a two-electrode set-up
    "voltage_V": ("voltage", ("voltage", "volts", "ecell", "ewe-ece", "cell voltage", "ewe",
                              "potential", "u", "v", "电压")),
    "current_A": ("current", ("current", "amps", "cell current", "i", "<i>", "amp", "cur",
                              "电流")),
    "cycle_index": (None, ("cycle index", "cycle", "cyc#", "cyc", "cycle number", "cycle id",
                           "cycle no", "cycle c", "cyc-count", "循环号", "循环序号", "循环")),
    # BaSyTec numbers its program's lines, one a step
    "step_index": (None, ("step index", "step", "step number", "step id", "step no", "ns",
                          "line", "工步号", "工步序号", "工步")),
    "state": (None, ("state", "status", "md", "step type", "step name", "mode", "command",
                     "工步类型", "工步状态", "状态")),
    "tester_charge_Ah": ("capacity", ("charge capacity", "chg capacity", "charge cap",
                                      "q charge", "chg cap", "充电容量")),
    "tester_discharge_Ah": ("capacity", ("discharge capacity", "dchg capacity",
                                         "discharge cap", "q discharge", "dchg cap",
                                         "放电容量")),
    "tester_step_Ah": ("capacity", ("ah-step", "amp hr", "amp-hr", "capacity", "ah", "cap",
                                    "容量")),
    "temperature_C": ("temperature", ("temperature", "temp", "aux temperature", "t1",
                                      "aux temperature 1", "cell temperature", "温度")),
    "datetime": (None, ("date time", "datetime", "dpt time", "timestamp", "realtime",
                        "absolute time", "date and time", "real time", "system time",
                        "date", "绝对时间", "系统时间", "实际时间", "日期")),
}

_BRACKET = re.compile(r"^(.*?)\s*[(\[]\s*([^)\]]*?)\s*[)\]]\s*$")
_DAY_CLOCK = re.compile(r"^\s*(?:(\d+)\s*d\s*)?(\d+):(\d{1,2}):(\d{1,2}(?:\.\d*)?)\s*$")

#: A clock time without a date: ``11:49:32``, ``9:05 PM`` (and :data:`_DAY_CLOCK`'s).
_CLOCK_ONLY = re.compile(r"^\s*\d{1,2}:\d{2}(:\d{2}(\.\d*)?)?\s*([AaPp][Mm])?\s*$")


def _is_clock(value) -> bool:
    """A clock time without a date."""
    return bool(_DAY_CLOCK.match(str(value)) or _CLOCK_ONLY.match(str(value)))

#: Temperatures outside this range [degC] are not a reading (an unconnected sensor).
PLAUSIBLE_C = (-60.0, 150.0)


def split_header(name: str) -> tuple[str, str | None]:
    """``"Current(mA)"`` -> ``("current", "ma")``; ``"Q charge/discharge/mA.h"`` ->
    ``("q charge/discharge", "ma.h")``; ``"Cyc#"`` -> ``("cyc#", None)``."""
    # BaSyTec marks its header line (and the lines above it) with a leading "~"
    text = str(name).strip().lstrip("\ufeff~").replace("（", "(").replace("）", ")")
    unit = None
    match = _BRACKET.match(text)
    if match and match.group(1):
        text, unit = match.group(1), match.group(2)
    elif "/" in text:
        head, _, tail = text.rpartition("/")
        if any(tail.strip().lower() in table for table in UNITS.values()):
            text, unit = head, tail
    base = re.sub(r"[\s_]+", " ", text.lower()).strip()
    return base, (unit.strip().lower() if unit else None)


def find_roles(names: list[str]) -> dict[str, tuple[int, float]]:
    """Role -> (column position, scale to SI); the best-named column per role.

    Raises
    ------
    DataError
        A column named for a role carries a unit that does not fit it.
    """
    parsed = [split_header(n) for n in names]
    found: dict[str, tuple[int, float]] = {}
    taken: set[int] = set()
    for role, (quantity, spellings) in ROLES.items():
        best = None
        for spelling in spellings:
            for k, (base, unit) in enumerate(parsed):
                if k in taken or base != spelling or (
                        unit is None and spelling in NEEDS_UNIT.get(role, ())):
                    continue
                scale = _scale(quantity, unit)
                if scale is None:
                    continue
                best = (k, scale)
                break
            if best is not None:
                break
        if best is None and role == "temperature_C":
            best = next(((k, 0.0) for k, (base, unit) in enumerate(parsed)
                         if k not in taken and base.startswith(("aux temperature", "temperature"))
                         and _scale("temperature", unit) is not None), None)
        if best is not None:
            found[role] = best
            taken.add(best[0])
    return found


def _scale(quantity: str | None, unit: str | None) -> float | None:
    """The scale (offset for temperature) of ``unit``, the default for none, None if foreign.
    A time whose unit describes a clock (PEC's ``Hours in hh:mm:ss.xxx``) is read as text."""
    if quantity is None:
        return 1.0 if unit is None else None
    table = UNITS[quantity]
    if unit is None:
        return 0.0 if quantity == "temperature" else 1.0
    if quantity == "time" and _CLOCK_UNIT.search(unit):
        return 1.0
    return table.get(unit.replace(" ", ""))


#: A time unit that names a clock: ``h:min:s``, ``hh:mm:ss.xxx``.
_CLOCK_UNIT = re.compile(r"\bh+\s*:\s*m")

#: Column names that hold a role only with a unit: PEC's ``Test`` is the test's number,
#: Maccor's ``Test (Min)`` its time.
NEEDS_UNIT = {"time_s": ("test",)}


def is_tester_table(names: list[str]) -> bool:
    """Time (test, step or clock time), voltage, current and a cycle or step number among
    the column names."""
    roles = find_roles(names)
    return all(r in roles for r in ("voltage_V", "current_A")) and (
        "time_s" in roles or "datetime" in roles) and (
        "cycle_index" in roles or "step_index" in roles)


# --------------------------------------------------------------------------- text

#: A tester table's header is looked for in this many first lines (EC-Lab text exports
#: carry about a hundred lines of settings above it).
HEADER_LINES = 300

#: Records of a tester's table per (cycle, step) run, at least, among its first rows: a
#: tester writes many records per step (a column that changes every row is not a step).
MIN_RECORDS_PER_STEP = 3


def text_header(lines: list[str]) -> tuple[int, str] | None:
    """(line index, delimiter) of a tester table's header among the first lines, or None.

    The rows below the header must hold steps: runs of one (cycle, step) pair of
    :data:`MIN_RECORDS_PER_STEP` records or more on average.
    """
    for k, line in enumerate(lines[:HEADER_LINES]):
        for delimiter in ("\t", ",", ";"):
            if line.count(delimiter) < 3:
                continue
            names = line.rstrip("\r\n").split(delimiter)
            if _words(names) >= 3 and is_tester_table(names):
                return (k, delimiter) if _holds_steps(lines[k:k + 201], delimiter) else None
    return None


def table_lines(text: str) -> list[str]:
    """A text export's lines, each one wrapped whole in double quotes unwrapped (Novonix
    writes ``"Date and Time,Cycle Number,..."``: read as CSV, one field per line)."""
    out = []
    for line in text.splitlines():
        if len(line) >= 2 and line[0] == line[-1] == '"' and '"' not in line[1:-1]:
            line = line[1:-1]
        out.append(line)
    return out


def _words(fields: list[str]) -> int:
    """How many fields are not numbers (a data row has none or few: no header)."""
    count = 0
    for field in fields:
        try:
            float(field.strip().replace(",", "."))
        except ValueError:
            count += 1
    return count


def _holds_steps(lines: list[str], delimiter: str) -> bool:
    try:
        table = pd.read_csv(io.StringIO("\n".join(lines)), sep=delimiter, header=0,
                            decimal=_decimal(lines[1:], delimiter))
    except (ValueError, pd.errors.ParserError):
        return False
    roles = find_roles([str(c) for c in table.columns])
    keys = [table.iloc[:, roles[r][0]] for r in ("cycle_index", "step_index") if r in roles]
    if not keys or len(table) < MIN_RECORDS_PER_STEP:
        return bool(keys)
    values = pd.concat([_text(key) for key in keys], axis=1).agg("|".join, axis=1).to_numpy()
    runs = 1 + int(np.sum(values[1:] != values[:-1]))
    return len(values) / runs >= MIN_RECORDS_PER_STEP


def read_text_export(path, text: str | None = None) -> TesterRecords:
    """A tester's text export (Arbin CSV, Maccor text, others) as :class:`TesterRecords`."""
    path = Path(path)
    if text is None:
        text = decode_text(path.read_bytes())
    lines = table_lines(text)
    found = text_header(lines)
    if found is None:
        raise DataError(f"{path.name}: no tester table header (time, voltage, current and a "
                        f"cycle or step column) in the first {HEADER_LINES} lines")
    k, delimiter = found
    decimal = _decimal(lines[k + 1:k + 51], delimiter)
    try:
        table = pd.read_csv(io.StringIO("\n".join(lines[k:])), sep=delimiter, header=0,
                            low_memory=False, decimal=decimal)
    except (ValueError, pd.errors.ParserError) as exc:
        raise DataError(f"{path.name}: the tester table cannot be parsed "
                        f"({str(exc).splitlines()[0]})") from None
    table = table.loc[:, [c for c in table.columns if not str(c).startswith("Unnamed")]]
    vendor = _vendor(list(table.columns), lines[:k])
    preamble = [line.strip() for line in lines[:k] if line.strip()]
    records = np.arange(len(table)) + k + 2   # the file's line numbers
    meta = {"format": f"{vendor}-text" if vendor else "tester-text", "preamble": preamble,
            "reader": "dischargelab's tester-table reader (columns by name and unit)"}
    return tester_records(table, records, path.name, meta)


#: Header lines above a text export's table that give the test's start: EC-Lab's
#: ``Acquisition started on : 07/02/2017 14:39:13``, PEC's ``Start Time:,01/08/2026
#: 17:40:39``, Maccor's ``Date of Test: 01/15/2025``.
_PREAMBLE_START = re.compile(r"\b(acquisition started on|start time|date of test|test start"
                             r"(?: time)?|start date)\s*[:,\t]+\s*([^\t,]+)", re.IGNORECASE)


def preamble_start(preamble: list[str]) -> tuple[str, str] | None:
    """(ISO 8601 start, the words it was read from) from a text export's header lines, or
    None. Dates are read month first, as these testers write them."""
    for line in preamble:
        match = _PREAMBLE_START.search(line)
        if not match:
            continue
        stamp = _stamps(pd.Series([match.group(2)])).iloc[0]
        if stamp is not pd.NaT and not pd.isna(stamp):
            return stamp.isoformat(timespec="seconds"), " ".join(match.group(0).split())
    return None


def decode_text(data: bytes) -> str:
    """A text export's characters: UTF-8, else GB 18030 when it reads Chinese (电压, 电流:
    Chinese testers' exports), else Latin-1 (EC-Lab's ``°C``); a UTF-8 character cut at
    the end of ``data`` is left out."""
    try:
        return data.decode("utf-8").lstrip("\ufeff")
    except UnicodeDecodeError as exc:
        if exc.start >= len(data) - 3:
            return data[:exc.start].decode("utf-8").lstrip("\ufeff")
    try:
        text = data.decode("gb18030")
    except UnicodeDecodeError:
        return data.decode("latin-1")
    return text if "电" in text else data.decode("latin-1")   # 电压 / 电流: Chinese


def _decimal(rows: list[str], delimiter: str) -> str:
    """``","`` when the numbers are written with a decimal comma (European exports)."""
    if delimiter == ",":
        return "."
    text = "\n".join(rows)
    return "," if re.search(r"\d,\d", text) and not re.search(r"\d\.\d", text) else "."


def _vendor(names: list[str], preamble: list[str]) -> str | None:
    lowered = {str(n).strip().lower() for n in names}
    if {"rec#", "cyc#"} & lowered or any(p.startswith(("Today's Date", "Procedure:"))
                                         for p in preamble):
        return "maccor"
    if {"data_point", "test_time", "step_index", "test_time(s)"} & lowered or any(
            str(n).lower().startswith(("test_time", "step_index")) for n in names):
        return "arbin"
    if any("basytec" in p.lower() for p in preamble[:3]):
        return "basytec"
    if any(p.startswith("EC-Lab ASCII FILE") for p in preamble[:1]):
        return "ec-lab"
    if any(p.startswith("[Summary]") for p in preamble[:1]) and "step number" in {
            split_header(n)[0] for n in names}:
        return "novonix"
    if any((split_header(n)[1] or "").startswith("hours in hh:mm") for n in names):
        return "pec"
    return None


# --------------------------------------------------------------------------- spreadsheets

def is_xlsx(head: bytes, path) -> bool:
    """A zip holding ``xl/workbook.xml``: an Excel workbook."""
    if not head.startswith(b"PK"):
        return False
    try:
        with zipfile.ZipFile(path) as archive:
            return "xl/workbook.xml" in archive.namelist()
    except (zipfile.BadZipFile, OSError):
        return False


def read_xlsx_export(path) -> TesterRecords:
    """A tester's Excel export: every data sheet (a tester table), in time order."""
    require("openpyxl", "cyclers")
    path = Path(path)
    try:
        with warnings.catch_warnings():   # openpyxl's style warnings are not the user's
            warnings.simplefilter("ignore", UserWarning)
            sheets = pd.read_excel(path, sheet_name=None, header=None, engine="openpyxl")
    except (ValueError, KeyError, OSError, zipfile.BadZipFile) as exc:
        raise DataError(f"{path.name}: the workbook cannot be read by openpyxl "
                        f"({str(exc).splitlines()[0]})") from None
    parts, used, names = [], [], None
    for sheet, raw in sheets.items():
        if "stat" in sheet.lower():
            continue   # per-cycle statistics, not records
        rows = raw.head(20).astype(str).values.tolist()
        header = next((k for k, row in enumerate(rows) if is_tester_table(row)), None)
        if header is None:
            continue
        body = raw.iloc[header + 1:].reset_index(drop=True)
        body.columns = [str(c) for c in raw.iloc[header]]
        body = body.loc[:, [c for c in body.columns if c not in ("nan", "None")]]
        if names is not None and list(body.columns) != names:
            continue
        names = list(body.columns)
        parts.append(body)
        used.append(sheet)
    if not parts:
        raise DataError(f"{path.name}: no sheet holds a tester table (time, voltage, current "
                        "and a cycle or step column)")
    table = pd.concat(parts, ignore_index=True)
    vendor = "arbin" if any(s.lower().startswith("channel") for s in sheets) or \
        _vendor(names or [], []) == "arbin" else None
    meta = {"format": f"{vendor}-xlsx" if vendor else "tester-xlsx",
            "reader": "dischargelab's tester-table reader over openpyxl "
                      f"{_version('openpyxl')}",
            "notes": [f"records from sheet(s) {', '.join(used)}"]}
    return tester_records(table, np.arange(len(table)) + 1, path.name, meta)


def _version(module: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(module)
    except PackageNotFoundError:
        return "(version unknown)"


# --------------------------------------------------------------------------- to records

def tester_records(table: pd.DataFrame, records: np.ndarray, name: str, meta: dict
                   ) -> TesterRecords:
    """Canonical :class:`TesterRecords` from a tester table with named columns."""
    names = [str(c) for c in table.columns]
    roles = find_roles(names)
    meta = dict(meta)
    notes = list(meta.pop("notes", []))
    out = pd.DataFrame(index=table.index)
    column_map, units = {}, {}
    for role, (k, scale) in roles.items():
        column = table.iloc[:, k]
        column_map[role] = names[k]
        if role == "time_s":
            out[role] = _seconds(column, scale, name)
        elif role == "state":
            out[role] = state_of(column)
        elif role == "datetime":
            continue
        elif role == "temperature_C":
            values = pd.to_numeric(column, errors="coerce").to_numpy(dtype=float) + scale
            median = float(np.nanmedian(values)) if np.isfinite(values).any() else np.nan
            if not PLAUSIBLE_C[0] <= median <= PLAUSIBLE_C[1]:
                notes.append(f"{names[k]!r} reads {median:.4g} degC, not a temperature (no "
                             "sensor?): not used")
                del column_map[role]
                continue
            out[role] = values
        else:
            values = pd.to_numeric(column, errors="coerce").to_numpy(dtype=float)
            out[role] = values if role in ("cycle_index", "step_index") else values * scale
        unit = split_header(names[k])[1]
        if unit:
            units[role] = unit
    if "step_index" not in out and "state" in out and not out["state"].astype(bool).any():
        numbers = pd.to_numeric(table.iloc[:, roles["state"][0]], errors="coerce")
        if numbers.notna().all():   # a "Step Type" column of numbers: the step's number
            out["step_index"] = numbers.to_numpy()
            notes.append(f"{column_map.pop('state')!r} holds numbers: read as the step number")
            out = out.drop(columns="state")
    for role in ("cycle_index", "step_index"):
        if role not in out:
            out[role] = 0
            notes.append(f"no {role.replace('_', ' ')} column: every record counted as "
                         f"{role.split('_')[0]} 0")
        elif out[role].isna().all():
            notes.append(f"the {role.replace('_', ' ')} column {column_map[role]!r} is empty: "
                         f"every record counted as {role.split('_')[0]} 0")
        out[role] = out[role].fillna(0).astype(np.int64)
    stamps = _date_time_column(table, roles) if "datetime" in roles else None
    clock = _clock_seconds(stamps) if stamps is not None else None
    bounds = step_bounds(out)
    if "time_s" not in out:
        if clock is None:
            raise DataError(f"{name}: the date-time column {column_map['datetime']!r} does "
                            "not parse as dates and times, and no test time column is given")
        out["time_s"] = clock
        notes.append(f"test time from the date-time column {column_map['datetime']!r} "
                     "(no test time column)")
    elif restarts_each_step(out["time_s"].to_numpy(dtype=float), bounds):
        out["time_s"] = test_time_from_steps(out["time_s"].to_numpy(dtype=float), bounds,
                                             clock)
        notes.append(f"{column_map['time_s']!r} restarts at every step: test time "
                     + ("added up over the steps, with the pauses the date-time column shows"
                        if clock is not None else "added up over the steps (a pause between "
                        "two steps is not known without a date-time column)"))
    # the header's start: the day of a clock-only column, else the start itself
    day = preamble_start(meta.get("preamble") or [])
    start = _start_time(stamps, out.get("time_s"), day[0] if day else None) \
        if stamps is not None else None
    if start:
        meta["start_time"] = start
    elif day:
        meta["start_time"] = day[0]
        notes.append(f"start time from the header: {day[1]!r}")
    if "current_A" in column_map and split_header(column_map["current_A"])[0] in INTERVAL_MEANS:
        meta["current_interval_mean"] = column_map["current_A"]
    meta.update({"column_map": column_map, "units": units, "notes": notes})
    return TesterRecords(frame=out, records=np.asarray(records), meta=meta)


#: Current columns that hold the mean over the interval ending at each record, not the
#: current at it: EC-Lab's ``<I>`` (the brackets mark an average; EC-Lab's own ``Q``
#: counters are their sums over the intervals). Flagged for :func:`.steps.finish`.
INTERVAL_MEANS = ("<i>",)


def state_of(column: pd.Series) -> np.ndarray:
    """``"charge"``, ``"discharge"``, ``"rest"`` or ``""`` for each state value
    (Maccor ``C``/``D``/``R``, Neware ``CC_DChg``/``CCCV_Chg``/``Rest``, Digatron
    ``DCH``/``CHA``/``PAU``, words; Chinese
    exports' 恒流放电 / 恒流恒压充电 / 搁置)."""
    text = _text(column).str.strip().str.lower()
    out = np.full(len(text), "", dtype=object)
    values = text.to_numpy(dtype=object)
    for k, value in enumerate(values):
        if value in ("d", "dch") or "dchg" in value or "disch" in value \
                or value.startswith("dis") or "放电" in value:
            out[k] = "discharge"
        elif value in ("c", "cha") or "chg" in value or value.startswith("charg") \
                or "充电" in value:
            out[k] = "charge"
        elif value in ("r", "pau") or value.startswith(("rest", "ocv", "pause")) or value in (
                "搁置", "静置"):
            out[k] = "rest"
    return out


def _text(column: pd.Series) -> pd.Series:
    """A column's values as text, an empty cell as ``""`` (pandas 3 keeps it NaN through
    ``astype(str)``, pandas 2 writes ``"nan"``)."""
    return column.astype(object).where(column.notna(), "").astype(str)


def _seconds(column: pd.Series, scale: float, name: str) -> np.ndarray:
    """Test time [s] from numbers (with the unit's scale) or ``[Nd ]H:MM:SS.f`` text."""
    values = pd.to_numeric(column, errors="coerce")
    if values.notna().mean() > 0.9:
        return values.to_numpy(dtype=float) * scale
    text = column.astype(str)
    parts = text.str.extract(_DAY_CLOCK)
    if parts[1].notna().mean() > 0.9:
        days = pd.to_numeric(parts[0], errors="coerce").fillna(0.0)
        seconds = (days * 86400 + parts[1].astype(float) * 3600 + parts[2].astype(float) * 60
                   + parts[3].astype(float))
        return seconds.to_numpy(dtype=float)
    raise DataError(f"{name}: the test time column holds {str(text.iloc[0])!r}, neither "
                    "seconds nor a clock time")


def restarts_each_step(time_s: np.ndarray, bounds: list[tuple[int, int]]) -> bool:
    """A step time: it goes back, and only where a step starts (``bounds``:
    :func:`~.steps.step_bounds`), to near zero."""
    back = np.flatnonzero(np.diff(time_s) < 0) + 1
    if back.size == 0:
        return False
    first = np.array([a for a, _ in bounds])
    span = np.nanmax(time_s) if np.isfinite(time_s).any() else 0.0
    return bool(np.isin(back, first[1:]).all()
                and np.nanmedian(time_s[first]) <= 0.01 * max(span, 1.0))


#: A date-time column's resolution [s]: a step's start by the clock later than its start by
#: the step times by more than this is a pause between the steps.
CLOCK_RESOLUTION_S = 2.0

#: Test time [s] between a step's last record and the next step's first record written at
#: step time 0 (the tester writes both at the change).
STEP_CHANGE_S = 1e-3


def test_time_from_steps(step_s: np.ndarray, bounds: list[tuple[int, int]],
                         clock_s: np.ndarray | None) -> np.ndarray:
    """Test time [s] from a step time that restarts at every step (``bounds``: each
    step's rows, :func:`~.steps.step_bounds`).

    A step starts where the step before ended (its step time counted from there); a
    date-time column that puts its first record more than :data:`CLOCK_RESOLUTION_S`
    later shows a pause between them, kept.
    """
    out = np.empty_like(step_s, dtype=float)
    for a, b in bounds:
        first = step_s[a] if a == 0 else out[a - 1] + max(step_s[a], STEP_CHANGE_S)
        if a and clock_s is not None and np.isfinite(clock_s[a]) and np.isfinite(clock_s[0]):
            by_clock = clock_s[a] - clock_s[0] + step_s[0]
            if by_clock > first + CLOCK_RESOLUTION_S:
                first = by_clock
        out[a:b] = step_s[a:b] - step_s[a] + first
    return out


#: A date written day first with dots (``05.05.2025``: BaSyTec, German locales).
_DOTTED_DATE = re.compile(r"^\s*\d{1,2}\.\d{1,2}\.\d{2,4}\b")


def _stamps(text: pd.Series) -> pd.Series:
    """Date-times from text, NaT where they do not parse; a date with dots is day first."""
    first = text.dropna()
    dayfirst = bool(len(first)) and bool(_DOTTED_DATE.match(str(first.iloc[0])))
    with warnings.catch_warnings():   # pandas' format inference warning is not the user's
        warnings.simplefilter("ignore", UserWarning)
        return pd.to_datetime(text, errors="coerce", dayfirst=dayfirst)


def _date_time_column(table: pd.DataFrame, roles: dict) -> pd.Series:
    """The date-time column, or a date column joined with a column of clock times beside
    it (BaSyTec's ``Date`` and ``Time``)."""
    column = table.iloc[:, roles["datetime"][0]]
    if split_header(str(table.columns[roles["datetime"][0]]))[0] != "date":
        return column
    for k, name in enumerate(table.columns):
        base, unit = split_header(str(name))
        values = table.iloc[:, k].dropna()
        if base == "time" and unit is None and len(values) and _is_clock(values.iloc[0]):
            return column.astype(str).str.strip() + " " + table.iloc[:, k].astype(str)
    return column


def _clock_seconds(column: pd.Series) -> np.ndarray | None:
    """Seconds since the first date-time of a date-time column, or None when under 90 %
    of it parses (text, UNIX seconds or Excel days)."""
    values = pd.to_numeric(column, errors="coerce")
    if values.notna().mean() > 0.9:
        x = values.to_numpy(dtype=float)
        first = x[np.isfinite(x)][0]
        if 1e9 < first < 4.2e9:
            return x - first
        if 20000 < first < 80000:
            return (x - first) * 86400.0
        return None
    stamps = _stamps(column.astype(str))
    if stamps.notna().mean() <= 0.9:
        return None
    seconds = (stamps - stamps.dropna().iloc[0]).dt.total_seconds()
    return seconds.to_numpy(dtype=float)


def _start_time(column: pd.Series, time_s, day: str | None = None) -> str | None:
    """ISO 8601 time of test time 0 from a date-time column, when it parses; a column of
    clock times only on ``day`` (ISO 8601, from the file's header), else none."""
    first = column.dropna()
    if first.empty:
        return None
    value = first.iloc[0]
    stamp = None
    if isinstance(value, (int, float, np.integer, np.floating)):
        x = float(value)
        if 1e9 < x < 4.2e9:                     # UNIX seconds
            stamp = pd.Timestamp(x, unit="s")
        elif 20000 < x < 80000:                 # Excel / OLE days
            stamp = pd.Timestamp("1899-12-30") + pd.to_timedelta(x, unit="D")
    elif _is_clock(value):
        if day is None:      # a clock without a date (Maccor's DPt Time in some exports)
            return None
        stamp = pd.to_datetime(f"{pd.Timestamp(day):%Y-%m-%d} {str(value).strip()}",
                               errors="coerce")
    else:
        stamp = _stamps(pd.Series([str(value)])).iloc[0]
        if stamp is pd.NaT:
            stamp = None
    if stamp is None or pd.isna(stamp):
        return None
    offset = float(time_s.iloc[first.index[0]]) if time_s is not None else 0.0
    return (stamp - pd.to_timedelta(offset, unit="s")).isoformat(timespec="seconds")


__all__ = ["read_text_export", "read_xlsx_export", "tester_records", "find_roles",
           "split_header", "is_tester_table", "text_header", "table_lines", "is_xlsx",
           "state_of"]
