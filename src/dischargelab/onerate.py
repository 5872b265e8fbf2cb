"""The one-rate model error measured on other cells: its classes and its law.

A fit to one constant-current rate cannot show how its cell's capacity and overpotentials
change with the current, so the error of its predictions at other currents is measured
on other cells instead (``benchmarks/one_rate_errors.py``: every cell with a rate series,
real and PyBaMM virtual, each fitted on one rate and predicting the others, each cell's
law measured without it) and shipped as ``data/one_rate_error.json``. The covariates are
what a user's file shows, never the cell's identity: the model family, the shape of the
discharge (flat LiFePO4 plateau or sloped) and whether a cell temperature was logged.
:func:`dischargelab.uncertainty.model_error_info` reads the law.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
from importlib import resources
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .model import Battery

#: Plateau ratio (:func:`dischargelab.fit.result.plateau_ratio`) below which a constant-current
#: discharge counts as flat (LiFePO4: about 0.1; NMC and LCO 0.3-0.4) for the measured
#: one-rate error (:func:`one_rate_class`).
FLAT_PLATEAU_RATIO = 0.2

#: The one-rate errors measured on other cells (``benchmarks/one_rate_errors.py --write``).
ONE_RATE_TABLE = "one_rate_error.json"

#: Cells a class of the one-rate table must have been measured on to be used (one or two
#: cells say how those cells extrapolate, not how a kind of cell does; their Student-t
#: interval, with one degree of freedom, would be 6x wider than a normal one): else the
#: documented prior.
MIN_MEASURED_CELLS = 3


def one_rate_class(battery: Battery, one_rate: bool = True) -> str | None:
    """The class of a one-rate fit in the measured one-rate error table, from what the
    fitted file shows: ``"<family> / <shape> / <temperature>"`` with shape ``flat``
    (plateau ratio below :data:`FLAT_PLATEAU_RATIO`: LiFePO4) or ``sloped``, and
    temperature ``temperature`` (a cell temperature was logged) or ``no temperature``.
    None when the fit has no constant-current curve to judge the shape by (a flight, a
    preset, a hand-written file), or when it fitted the dynamics that one steady rate cannot
    show (``Family.steady_fixed``, held on such data by default) as the measured fits did
    not. ``one_rate=False`` classes a fit to two rates (the two-rate table), which fits
    those dynamics."""
    extra = battery.extra if isinstance(battery.extra, dict) else {}
    plateau = extra.get("fit_plateau_ratio")
    if isinstance(plateau, bool) or not isinstance(plateau, (int, float)) or \
            not math.isfinite(plateau):
        return None
    fixed = extra.get("fixed") if isinstance(extra.get("fixed"), dict) else {}
    if one_rate and any(name not in fixed for name in battery.family.steady_fixed):
        return None  # dynamics fitted to one steady rate anyway: not what was measured
    shape = "flat" if plateau < FLAT_PLATEAU_RATIO else "sloped"
    logged = "temperature" if "fit_temperature_rise_K" in extra else "no temperature"
    return f"{battery.model} / {shape} / {logged}"


@functools.cache
def _packaged_table() -> dict:
    """The measured table shipped with the package ({} when missing or unreadable)."""
    try:
        text = (resources.files("dischargelab") / "data" / ONE_RATE_TABLE).read_text(
            encoding="utf-8")
        table = json.loads(text)
    except (OSError, ValueError):
        return {}
    return table if isinstance(table, dict) else {}


_table_override: list = []


def one_rate_table() -> dict:
    """The measured one-rate error table: ``{"one_rate": {class: law}, "two_rate": {class:
    {"sd", "dof"}}}`` (see ``benchmarks/one_rate_errors.py``)."""
    return _table_override[-1] if _table_override else _packaged_table()


@contextlib.contextmanager
def one_rate_table_override(table: dict):
    """Use ``{"one_rate": ..., "two_rate": ...}`` (or a bare ``{class: law}``) instead of the
    packaged table inside the ``with`` block (the leave-one-cell-out benchmark)."""
    if "one_rate" not in table and "two_rate" not in table:
        table = {"one_rate": table}
    _table_override.append(table)
    try:
        yield table
    finally:
        _table_override.pop()


def one_rate_law(battery: Battery) -> dict | None:
    """The measured law of a one-rate fit's model error, or None (no class or no entry).

    ``{"base", "up", "down", "cells", ...}``: the relative standard deviation of a time to
    cutoff predicted at ``r`` times the fitted current is ``base + up * ln r`` (``r > 1``)
    or ``base + down * ln(1 / r)``, measured on other cells by
    ``benchmarks/one_rate_errors.py`` (``up``/``down`` None where no pair was measured);
    None for a class measured on fewer than :data:`MIN_MEASURED_CELLS` cells.
    """
    cls = one_rate_class(battery)
    entry = (one_rate_table().get("one_rate") or {}).get(cls) if cls else None
    if not isinstance(entry, dict) or not isinstance(entry.get("base"), (int, float)):
        return None
    if entry.get("up") is None and entry.get("down") is None or \
            len(entry.get("cells", ())) < MIN_MEASURED_CELLS:
        return None
    return dict(entry, name=cls)


__all__ = ["FLAT_PLATEAU_RATIO", "MIN_MEASURED_CELLS", "one_rate_class", "one_rate_law",
           "one_rate_table", "one_rate_table_override"]
