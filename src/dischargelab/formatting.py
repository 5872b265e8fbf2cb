"""How a number is written: one rounding per quantity, one mark for "no value", one open
interval, one unit text, one way to write a duration.

The terminal, the text fields of the JSON answers, the HTML report, the figures and the
pages all write numbers through here, so a figure reads the same wherever it is shown (the
pages show the ``text`` the JSON API carries, and ``web/static/common.js`` holds the twins
of :func:`number`, :func:`interval` and :func:`duration` for the numbers they draw, such
as the live page's elapsed time).

Plain functions of values, no imports from the rest of the package (bottom layer).
"""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal

#: Written where a value is unknown.
MISSING = "-"
#: Written for the end of an interval that is not bounded (e.g. a forecast whose upper end
#: lies beyond anything simulated).
OPEN = "open"
#: Between the two ends of an interval.
SEPARATOR = " - "

#: Decimals, scale and unit of the quantities shown in more than one place:
#: ``name: (decimals, scale, unit)``; the value shown is ``value * scale``.
QUANTITIES: dict[str, tuple[int, float, str]] = {
    "efc": (1, 1.0, "EFC"),
    "eol_efc": (0, 1.0, "EFC"),
    "capacity_Ah": (3, 1.0, "Ah"),
    "capacity_fraction": (0, 100.0, "%"),
    "resistance_ohm": (1, 1000.0, "mOhm"),
    "discharged_Ah": (3, 1.0, "Ah"),
}


def _finite(value) -> bool:
    if value is None or isinstance(value, bool):
        return False
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def number(value, digits: int = 3, scale: float = 1.0) -> str:
    """``value * scale`` with ``digits`` decimals; :data:`MISSING` for None, NaN or inf.

    Rounds the exact binary value half away from zero, as JavaScript's ``toFixed``
    does, so that the pages' helper writes the same digits.
    """
    if not _finite(value):
        return MISSING
    exact = Decimal(float(value) * scale)
    return f"{exact.quantize(Decimal(1).scaleb(-digits), rounding=ROUND_HALF_UP):f}"


def quantity(name: str, value, unit: bool = False) -> str:
    """A value of a quantity of :data:`QUANTITIES` at its decimals (and with its unit)."""
    digits, scale, text = QUANTITIES[name]
    shown = number(value, digits, scale)
    if unit and shown != MISSING:
        return f"{shown} {text}" if text != "%" else f"{shown} %"
    return shown


def interval(pair, digits: int = 0, scale: float = 1.0) -> str:
    """``low - high``; an end that is None (unbounded) is written :data:`OPEN`,
    no interval at all :data:`MISSING`."""
    if not pair:
        return MISSING
    lo, hi = pair
    if lo is None and hi is None:
        return MISSING
    ends = [OPEN if end is None else number(end, digits, scale) for end in (lo, hi)]
    return SEPARATOR.join(ends)


def quantity_interval(name: str, pair) -> str:
    """:func:`interval` at the decimals and scale of a quantity of :data:`QUANTITIES`."""
    digits, scale, _ = QUANTITIES[name]
    return interval(pair, digits, scale)


def ratio(value) -> str:
    """An extrapolation (or any) ratio: ``x1.4``."""
    return MISSING if not _finite(value) else f"x{float(value):.1f}"


def percent(value, digits: int = 1, signed: bool = False) -> str:
    """A percentage: ``12.3 %`` (``+12.3 %`` when signed)."""
    if not _finite(value):
        return MISSING
    text = number(value, digits)
    if signed and not text.startswith("-") and float(text) != 0:
        text = "+" + text
    return f"{text} %"


def _whole(value: float) -> int:
    """``value`` (>= 0) rounded to a whole number half up, on its exact binary value (what
    JavaScript's ``toFixed(0)`` does)."""
    return int(Decimal(value).quantize(Decimal(1), rounding=ROUND_HALF_UP))


def duration(seconds, signed: bool = False) -> str:
    """A duration as every view writes it (terminal, JSON texts, report, pages).

    * under a minute: whole seconds, ``42 s``;
    * under two hours: minutes and seconds, ``69 min 29 s`` (a pilot's timer and a
      flight's endurance read in minutes; the seconds always two digits);
    * from two hours: hours and minutes, ``2 h 05 min`` (seconds no longer matter).

    Rounded to the last unit shown, half away from zero on the exact value (so
    ``DL.duration`` in ``web/static/common.js``, its twin, writes the same). A negative
    duration (a margin that is short) starts with ``-``; ``signed`` writes ``+`` before a
    positive one (an error, a difference). :data:`MISSING` for None, NaN or inf.
    """
    if not _finite(seconds):
        return MISSING
    value = float(seconds)
    total = _whole(abs(value))
    if total < 60:
        body = f"{total} s"
    elif total < 7200:
        body = f"{total // 60} min {total % 60:02d} s"
    else:
        minutes = _whole(abs(value) / 60.0)
        body = f"{minutes // 60} h {minutes % 60:02d} min"
    if total == 0:
        return body
    return ("-" if value < 0 else "+" if signed else "") + body


def duration_interval(pair) -> str:
    """An interval of durations, ``67 min 10 s - 71 min 40 s``: :func:`interval`'s
    separator and open ends, each end a :func:`duration`."""
    if not pair:
        return MISSING
    lo, hi = pair
    if lo is None and hi is None:
        return MISSING
    return SEPARATOR.join(OPEN if end is None else duration(end) for end in (lo, hi))


#: The durations of a mission result (``MissionResult.to_dict()``) that carry a text.
MISSION_DURATIONS = ("flight_time_s", "endurance_s", "cutoff_time_s", "reserve_time_s")


def mission_text(row: dict) -> dict:
    """The texts of a mission result's durations as every view shows them: the keys of
    :data:`MISSION_DURATIONS`, ``endurance_interval95`` (the 95 % interval, when flown),
    ``stretch_max_s`` and ``stretch_margin_s`` (with a stretched phase)."""
    out = {key: duration(row.get(key)) for key in MISSION_DURATIONS if key in row}
    unc = row.get("uncertainty") or {}
    if unc.get("available") and unc.get("endurance_s"):
        e = unc["endurance_s"]
        out["endurance_interval95"] = duration_interval([e.get("low"), e.get("high")])
    st = row.get("stretch")
    if st:
        out["stretch_max_s"] = duration(st.get("max_s"))
        out["stretch_margin_s"] = duration(st.get("margin_s"))
    return out


def pack_text(row: dict) -> dict:
    """The texts of a pack's figures (a row of the pack list, a pack's summary) as every
    view shows them: ``efc``, ``capacity_Ah``, ``capacity_interval95``,
    ``capacity_fraction``, ``resistance_ohm``, ``eol_efc``, ``eol_efc_interval95``."""
    out = {}
    for name in ("efc", "capacity_Ah", "resistance_ohm", "eol_efc"):
        if name in row:
            out[name] = quantity(name, row.get(name))
    if "capacity_fraction" in row:
        out["capacity_fraction"] = quantity("capacity_fraction", row.get("capacity_fraction"),
                                            unit=True)
    if "capacity_interval95" in row:
        out["capacity_interval95"] = quantity_interval("capacity_Ah",
                                                       row.get("capacity_interval95"))
    if "eol_efc_interval95" in row:
        out["eol_efc_interval95"] = quantity_interval("eol_efc", row.get("eol_efc_interval95"))
    return out


def runs_label(names) -> str:
    """The runs a battery was fitted on, in one label: ``"a.csv, b.csv"``, with the steps of
    one tester file together (``"maccor_001 steps 7, 12, 17"`` for ``"maccor_001 step 7"``...)."""
    groups: dict[str, list[str]] = {}
    for name in names:
        head, sep, step = str(name).rpartition(" step ")
        key, item = (head, step) if sep and step.isdigit() else (str(name), "")
        groups.setdefault(key, []).append(item)
    parts = []
    for key, items in groups.items():
        steps = [i for i in items if i]
        if not steps:
            parts.append(key)
        else:
            parts.append(f"{key} step{'s' if len(steps) > 1 else ''} {', '.join(steps)}")
    return ", ".join(parts)


__all__ = ["MISSING", "OPEN", "SEPARATOR", "QUANTITIES", "number", "quantity", "interval",
           "quantity_interval", "ratio", "percent", "duration", "duration_interval",
           "MISSION_DURATIONS", "mission_text", "pack_text", "runs_label"]
