"""Is a measured discharge physically plausible for the pack described? Checked before a fit.

A reader can parse a file perfectly and still hand over garbage: millivolts read
as volts, a 12-cell pack described as one cell, a flat line with no discharge in
it, an ``E0`` given for the pack instead of the cell. The fit would then run
and return confident nonsense. Each check here compares magnitudes with what a
lithium cell can show and returns a :class:`Finding`: an error (the data cannot
be what the arguments say) or a warning (probably wrong; it changes the result),
each with the fix in plain words.

The limits, per cell in series:

* rest (open-circuit) voltage of a lithium cell (LiPo, Li-ion, LiFePO4):
  2.0 to 4.4 V (:data:`REST_RANGE_V`); up to :data:`WARN_BAND_V` beyond that
  is a warning, further is an error;
* a value in the thousands is millivolts (or milliamperes) read as volts
  (amperes);
* the cell count is inferred from the rest (else highest) voltage and the full
  charge voltage of the chemistry (:data:`FULL_CHARGE_V`);
* a discharge changes the voltage: a span below 2 % of the mean
  (:data:`MIN_SPAN_FRACTION`) means no discharge is visible (a warning: a short
  flight at mid charge can be that flat), below 0.5 % (:data:`FLAT_ERROR_FRACTION`)
  the voltage is flat to within noise (an error);
* a fixed ``E0`` is a per-cell voltage inside the rest range.

Messages speak of the arguments of :func:`check_discharge` (``cells_series=12``);
:meth:`Finding.text` can name them as command-line options instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import DataError
from .formatting import duration as fmt_duration

#: Rest voltage range of one lithium cell [V] (fully discharged .. fully charged, with margin).
REST_RANGE_V = {"lipo": (2.0, 4.4), "li-ion": (2.0, 4.4), "lifepo4": (2.0, 4.4)}
#: Range used when the chemistry is not given [V].
DEFAULT_REST_RANGE_V = (2.0, 4.4)
#: Beyond the rest range by less than this [V per cell]: a warning, not an error.
WARN_BAND_V = 0.3
#: Full-charge voltage per cell [V], used to infer the cell count from a pack voltage.
FULL_CHARGE_V = {"lipo": 4.35, "li-ion": 4.2, "lifepo4": 3.65}
#: Nominal cell voltage [V], the example given for a wrong E0.
NOMINAL_CELL_V = {"lipo": 3.7, "li-ion": 3.6, "lifepo4": 3.3}
#: A voltage span (2nd to 98th percentile) below this share of the mean shows no discharge.
MIN_SPAN_FRACTION = 0.02
#: Below this share of the mean the voltage is flat (noise only): an error, not a warning.
FLAT_ERROR_FRACTION = 0.005
#: Values at or above this are taken for milli-units read as base units.
MILLI_THRESHOLD = 1000.0
#: Current per string [A] and charge per string [Ah] beyond which mA read as A is suspected.
SUSPECT_CURRENT_A = 100.0
SUSPECT_CHARGE_AH = 100.0


@dataclass(frozen=True)
class Finding:
    """One plausibility problem.

    Attributes
    ----------
    level : {"error", "warning"}
    check : str
        ``"millivolts"``, ``"cell_count"``, ``"cell_voltage"``, ``"milliamperes"``,
        ``"flat"`` or ``"e0"``.
    source : str
        File (or argument) the finding is about.
    message : str
        What is wrong, with the numbers.
    fix : str
        How to fix it; ``{name}`` placeholders stand for the entries of
        ``arguments`` (rendered by :meth:`text`).
    arguments : dict
        Suggested argument values, e.g. ``{"cells_series": 12}``.
    """

    level: str
    check: str
    source: str
    message: str
    fix: str
    arguments: dict = field(default_factory=dict)

    def text(self, options: dict | None = None) -> str:
        """One line: source, message and fix.

        Parameters
        ----------
        options : dict, optional
            Argument name -> command-line option (``{"cells_series": "--cells"}``);
            arguments are then written ``--cells 12`` instead of ``cells_series=12``.
        """
        rendered = {name: _render(name, value, options)
                    for name, value in self.arguments.items()}
        fix = self.fix.format(**rendered)
        head = f"{self.source}: " if self.source else ""
        return f"{head}{self.message}; {fix}"


def _render(name: str, value, options: dict | None) -> str:
    if options and name in options:
        return f"{options[name]} {value}"
    return f"{name}={value!r}" if isinstance(value, str) else f"{name}={value}"


class PlausibilityError(DataError):
    """The data cannot be what the arguments describe; ``findings`` says why."""

    def __init__(self, findings: list[Finding]):
        self.findings = list(findings)
        super().__init__(" | ".join(f.text() for f in self.findings))

    def text(self, options: dict | None = None) -> str:
        """The message with arguments named as in ``options`` (see :meth:`Finding.text`)."""
        return " | ".join(f.text(options) for f in self.findings)


# ----------------------------------------------------------------------------- checks

def rest_range(chemistry: str | None) -> tuple[float, float]:
    """Per-cell rest voltage range [V] of a chemistry (``None``: any lithium cell)."""
    if chemistry is None:
        return DEFAULT_REST_RANGE_V
    try:
        return REST_RANGE_V[chemistry]
    except KeyError:
        raise DataError(f"chemistry must be one of {', '.join(REST_RANGE_V)}; "
                        f"got {chemistry!r}") from None


def infer_cells(voltage_V: float, chemistry: str | None = None) -> int:
    """Fewest cells in series that bring a pack's rest voltage within one cell's full charge.

    Parameters
    ----------
    voltage_V : float
        Rest (or highest) pack voltage [V].
    chemistry : str, optional
        ``"lipo"``, ``"li-ion"`` or ``"lifepo4"``; unknown uses the upper rest limit.
    """
    full = FULL_CHARGE_V.get(chemistry or "", rest_range(chemistry)[1])
    return max(1, math.ceil(voltage_V / (full + 0.05) - 1e-9))


def _reference_voltage(frame, meta) -> tuple[float, str]:
    rest = (meta or {}).get("rest_sample")
    if rest and np.isfinite(rest.get("voltage_V", np.nan)):
        return float(rest["voltage_V"]), "at rest"
    return float(np.nanmax(frame["voltage_V"].to_numpy(dtype=float))), "at most"


def _voltage_findings(level_V, how, cells, chemistry, source) -> list[Finding]:
    low, high = rest_range(chemistry)
    per_cell = level_V / cells
    what = f"{chemistry} cell" if chemistry else "lithium cell"
    pack = f"{level_V:.4g} V {how}" + ("" if cells == 1 else f", {per_cell:.4g} V per cell")
    if per_cell > high and level_V >= MILLI_THRESHOLD:
        volts = level_V / 1000.0
        fix = "read the voltage column in millivolts ({units})"
        arguments = {"units": "voltage_V=mV"}
        if volts / cells > high + WARN_BAND_V:
            fix += " and give the cell count ({cells_series})"
            arguments["cells_series"] = infer_cells(volts, chemistry)
        return [Finding("error", "millivolts", source,
                        f"the voltage is {pack}: values in the thousands are millivolts "
                        f"({volts:.4g} V), not volts", fix, arguments)]
    in_series = f"{cells} cell{'' if cells == 1 else 's'} in series"
    if per_cell > high:
        n = infer_cells(level_V, chemistry)
        level = "error" if per_cell > high + WARN_BAND_V else "warning"
        return [Finding(level, "cell_count", source,
                        f"the voltage is {pack} for {in_series}, above the {high:g} V a {what} "
                        "reaches", f"looks like a {n}S pack: pass {{cells_series}}",
                        {"cells_series": n})]
    if per_cell < low:
        level = "error" if per_cell < low - WARN_BAND_V else "warning"
        n = infer_cells(level_V, chemistry)
        if n < cells:
            message = (f"the voltage is {pack} for {in_series}, below the {low:g} V of a flat "
                       f"{what}")
            return [Finding(level, "cell_count", source, message,
                            f"looks like a {n}S pack: pass {{cells_series}}",
                            {"cells_series": n})]
        return [Finding(level, "cell_voltage", source,
                        f"the voltage is {pack}, below the {low:g} V of a flat {what}",
                        "check the voltage column and its calibration, or the cell count "
                        "({cells_series})", {"cells_series": cells})]
    return []


def _current_findings(frame, strings, source) -> list[Finding]:
    if "current_A" not in frame:
        return []
    t = frame["time_s"].to_numpy(dtype=float)
    i = frame["current_A"].to_numpy(dtype=float) / strings
    mean_i = float(np.nanmean(i))
    charge = float(np.nansum(0.5 * (i[1:] + i[:-1]) * np.diff(t)) / 3600.0) if t.size > 1 else 0.0
    if mean_i >= MILLI_THRESHOLD:
        level = "error"
    elif mean_i >= SUSPECT_CURRENT_A and charge >= SUSPECT_CHARGE_AH:
        level = "warning"
    else:
        return []
    per = "" if strings == 1 else " per string"
    return [Finding(level, "milliamperes", source,
                    f"the current averages {mean_i:.4g} A{per} and delivers {charge:.4g} Ah"
                    f"{per}: values like these are milliamperes read as amperes",
                    "read the current column in milliamperes ({units})",
                    {"units": "current_A=mA"})]


def _flat_findings(frame, source) -> list[Finding]:
    v = frame["voltage_V"].to_numpy(dtype=float)
    v = v[np.isfinite(v)]
    if v.size < 2:
        return []
    low, high = np.percentile(v, [2.0, 98.0])
    mean = float(np.mean(v))
    span = float(high - low)
    if mean > 0 and span < MIN_SPAN_FRACTION * mean:
        level = "error" if span < FLAT_ERROR_FRACTION * mean else "warning"
        return [Finding(level, "flat", source,
                        f"no discharge visible: the voltage spans only {span * 1000:.3g} mV "
                        f"({100 * span / mean:.2g} % of its mean {mean:.4g} V; a discharge "
                        f"changes it by more than {100 * MIN_SPAN_FRACTION:g} %)",
                        "give a file that covers a discharge, or choose the voltage column "
                        "({columns})", {"columns": "voltage_V=<column>"})]
    return []


def check_e0(e0_V: float | None, cells_series: int = 1, chemistry: str | None = None
             ) -> list[Finding]:
    """A fixed ``E0`` [V per cell] outside the chemistry's rest range is an error."""
    if e0_V is None:
        return []
    low, high = rest_range(chemistry)
    if not math.isfinite(e0_V):
        return [Finding("error", "e0", "", f"e0_V = {e0_V} is not a number",
                        "give E0 per cell in volts, e.g. {e0_V}", {"e0_V": 3.7})]
    if low <= e0_V <= high:
        return []
    what = f"{chemistry} cell" if chemistry else "lithium cell"
    per_cell = e0_V / cells_series
    if cells_series > 1 and low <= per_cell <= high:
        fix = (f"E0 is per cell: {e0_V:g} V over {cells_series} cells is {per_cell:.4g} V "
               "({e0_V})")
        suggestion = round(per_cell, 4)
    else:
        fix = "give E0 per cell in volts, e.g. {e0_V}"
        suggestion = NOMINAL_CELL_V.get(chemistry or "", 3.7)
    return [Finding("error", "e0", "", f"e0_V = {e0_V:g} V per cell is outside the "
                    f"{low:g}-{high:g} V of a {what}", fix, {"e0_V": suggestion})]


#: Cutoff voltages per cell [V] a chemistry's cells are discharged to: below the low end the
#: cell is over-discharged, above the high end most of its charge is left unused. From
#: manufacturers' data sheets: LiPo 3.0-3.3 V (RC packs; 2.75 V the cell's absolute minimum),
#: Li-ion 2.5-3.0 V (e.g. Samsung INR18650-30Q: 2.5 V), LiFePO4 2.0-2.8 V (e.g. A123
#: ANR26650: 2.0 V; the paper's packs end at 2.5 V).
CUTOFF_RANGE_V = {"lipo": (2.75, 3.6), "li-ion": (2.5, 3.4), "lifepo4": (2.0, 3.0)}


def check_cutoff(cutoff_cell_V: float | None, chemistry: str | None,
                 source: str = "") -> list[Finding]:
    """A cutoff per cell [V] outside its chemistry's usual range (:data:`CUTOFF_RANGE_V`)
    is a warning (a cutoff of another chemistry, or a pack voltage given per cell)."""
    if cutoff_cell_V is None or chemistry not in CUTOFF_RANGE_V:
        return []
    low, high = CUTOFF_RANGE_V[chemistry]
    if low - 1e-9 <= cutoff_cell_V <= high + 1e-9:
        return []
    from .cell import CUTOFF_CELL_VOLTAGE_V

    usual = CUTOFF_CELL_VOLTAGE_V[chemistry]
    side = "below" if cutoff_cell_V < low else "above"
    return [Finding("warning", "cutoff", source,
                    f"a cutoff of {cutoff_cell_V:g} V per cell is {side} the {low:g}-{high:g} V "
                    f"a {chemistry} cell is discharged to",
                    f"check the chemistry, or give a {chemistry} cutoff ({{cutoff_cell_V}})",
                    {"cutoff_cell_V": usual})]


#: How far the charge a given current implies (current x the file's duration) may lie from
#: the cell's capacity. A lithium cell's capacity changes by well under this between C/10
#: and 4C (the Samsung 30Q set: 2.97 Ah at C/10, 2.90 Ah at 4C; the rate-capacity effect,
#: paper section 2), so a larger factor means the current is not this file's.
CHARGE_FACTOR_LIMIT = 1.5


def _given_charge(frame, meta):
    """(source name, current [A], duration [s], charge [Ah]) of a file read with a given
    current, None for a measured current."""
    if (meta or {}).get("current_source") != "given" or "current_A" not in frame:
        return None
    t = frame["time_s"].to_numpy(dtype=float)
    amps = float(np.nanmedian(frame["current_A"].to_numpy(dtype=float)))
    if t.size < 2 or not amps > 0:
        return None
    duration = float(t[-1] - t[0])
    name = Path(str(meta["source"])).name if meta.get("source") else ""
    return name, amps, duration, amps * duration / 3600.0


def check_given_current(loaded, *, capacity_Ah: float | None = None,
                        cutoff_pack_V: float | None = None) -> list[Finding]:
    """A current given for files without one (``--current``) against each file's duration.

    The charge it implies (current x the file's duration) is compared with the battery's
    capacity, else (three files or more) with the median of the files' charges. A file
    whose charge is more than :data:`CHARGE_FACTOR_LIMIT` times that (or, for a run that
    ends at the cutoff, less than its inverse) gets a warning naming the file and the
    current: the current was not this file's.

    Parameters
    ----------
    loaded : list of (frame, meta)
        As read (``meta["current_source"] == "given"`` marks a given current).
    capacity_Ah : float, optional
        The pack's capacity [Ah] (``Battery.capacity_Ah``).
    cutoff_pack_V : float, optional
        Pack cutoff [V]: a run whose last voltage is within 3 % of it is a full discharge.
    """
    rows = [(_given_charge(frame, meta), frame) for frame, meta in loaded]
    rows = [(g, frame) for g, frame in rows if g is not None]
    if not rows:
        return []
    reference, what = capacity_Ah, "the battery's capacity"
    if reference is None:
        if len(rows) < 3:
            return []
        reference = float(np.median([g[3] for g, _ in rows]))
        what = "the other files' median"
    found = []
    for (name, amps, duration, charge), frame in rows:
        ratio = charge / reference
        ends = True
        if cutoff_pack_V is not None:
            ends = float(frame["voltage_V"].to_numpy(dtype=float)[-1]) <= 1.03 * cutoff_pack_V
        if ratio > CHARGE_FACTOR_LIMIT or (ends and ratio < 1.0 / CHARGE_FACTOR_LIMIT
                                           and capacity_Ah is not None):
            right = reference * 3600.0 / duration
            found.append(Finding(
                "warning", "given_current", name,
                f"{amps:.4g} A for its {fmt_duration(duration)} would take {charge:.3g} Ah, "
                f"x{ratio:.2g} {what} ({reference:.3g} Ah): that current is not this file's "
                f"(its duration suggests about {right:.3g} A)",
                "give each file its own current ({current})",
                {"current": "A1,A2,..."}))
    return found


def check_discharge(frame, meta=None, *, cells_series: int = 1, strings_parallel: int = 1,
                    chemistry: str | None = None) -> list[Finding]:
    """Plausibility of one read discharge (see the module notes for the limits).

    Parameters
    ----------
    frame : pandas.DataFrame
        Canonical columns from :func:`dischargelab.io.read_discharge`.
    meta : dict, optional
        Its metadata (``source`` and ``rest_sample`` are used).
    cells_series, strings_parallel : int
        The pack the data are said to come from.
    chemistry : {"lipo", "li-ion", "lifepo4"}, optional

    Returns
    -------
    list of Finding
        Empty when nothing looks wrong.
    """
    meta = meta or {}
    source = Path(str(meta["source"])).name if meta.get("source") else ""
    if len(frame) == 0:
        return [Finding("error", "flat", source, "no rows", "give a file with a discharge")]
    level_V, how = _reference_voltage(frame, meta)
    found = _voltage_findings(level_V, how, int(cells_series), chemistry, source)
    found += _current_findings(frame, int(strings_parallel), source)
    if not any(f.check == "millivolts" for f in found):
        found += _flat_findings(frame, source)
    return found


def check_discharges(loaded, *, cells_series: int = 1, strings_parallel: int = 1,
                     chemistry: str | None = None, e0_V: float | None = None) -> list[Finding]:
    """:func:`check_discharge` for each ``(frame, meta)`` pair, plus :func:`check_e0`."""
    found = check_e0(e0_V, cells_series, chemistry)
    for frame, meta in loaded:
        found += check_discharge(frame, meta, cells_series=cells_series,
                                 strings_parallel=strings_parallel, chemistry=chemistry)
    return found


def raise_for(findings, strict: bool = False) -> list[Finding]:
    """Raise on errors (and on warnings when ``strict``); return the warnings otherwise.

    Raises
    ------
    PlausibilityError
        Holding the fatal findings.
    """
    fatal = [f for f in findings if f.level == "error" or strict]
    if fatal:
        raise PlausibilityError(fatal)
    return [f for f in findings if f.level == "warning"]


__all__ = ["Finding", "PlausibilityError", "check_cutoff", "check_discharge", "check_discharges",
           "check_e0", "check_given_current", "CHARGE_FACTOR_LIMIT", "CUTOFF_RANGE_V",
           "infer_cells", "raise_for", "rest_range", "REST_RANGE_V", "FULL_CHARGE_V",
           "MIN_SPAN_FRACTION", "WARN_BAND_V"]
