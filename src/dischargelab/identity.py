"""A pack's identity: cells in series, strings, chemistry, cutoff and capacity, wherever used.

A battery that knows what it is (a logbook pack, a battery file of a pack, a preset) keeps
its cells, strings, chemistry and cutoff wherever it is flown: the command line, the report
and the pack pages all build a mission through :func:`resolve`. A mission's ``[battery]``
table (``series``, ``parallel``, ``chemistry``, ``cutoff_cell_V``) is a default for a battery
that has none of these, never an override of a known pack:

* a battery of one cell (``1S1P``, e.g. a cell fitted on the bench or a logbook of one
  cell) is placed in the mission's pack; a pack (more than one cell) keeps its own layout,
  and a mission that says otherwise gets a one-line warning naming both values;
* a battery of unknown chemistry takes the mission's; a known one keeps its own;
* the cutoff per cell is the battery's own (``cutoff_cell_V`` stored in its file), else the
  mission's when it was written for the same chemistry (or the chemistry is unknown), else
  the usual cutoff of the battery's chemistry (:data:`dischargelab.cell.CUTOFF_CELL_VOLTAGE_V`);
* values given explicitly by the user (``--cells``, ``--parallel``, ``--cutoff``) win,
  except that the measured layout of a logbook pack of several cells cannot be changed:
  asking for another is an error (:class:`dischargelab.errors.DataError`), one line.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from .cell import CUTOFF_CELL_VOLTAGE_V
from .errors import DataError

#: Chemistries a mission or a battery may name.
CHEMISTRIES = tuple(CUTOFF_CELL_VOLTAGE_V)


@dataclass(frozen=True)
class Identity:
    """What a battery says it is.

    Attributes
    ----------
    cells_series, strings_parallel : int
    chemistry : str or None
    cutoff_cell_V : float or None
        The battery's own cutoff per cell [V] (stored in its file), None when it has none.
    capacity_Ah : float
        Pack model capacity [Ah].
    pack : bool
        The layout is the battery's own (more than one cell); one cell is placed in the
        mission's pack.
    measured : bool
        A logbook pack of more than one cell: its layout is measured and cannot be
        changed.
    label : str
        How the battery is named in messages.
    """

    cells_series: int
    strings_parallel: int
    chemistry: str | None
    cutoff_cell_V: float | None
    capacity_Ah: float
    pack: bool
    measured: bool
    label: str


def battery_identity(battery) -> Identity:
    """The :class:`Identity` of a :class:`dischargelab.model.Battery`."""
    logbook = battery.extra.get("logbook") or {}
    measured = bool(logbook.get("pack"))
    if measured:
        label = f"pack {logbook['pack']!r}"
    else:
        label = repr(battery.name) if battery.name else "the battery"
    own = battery.extra.get("cutoff_cell_V")
    multi = battery.cells_series > 1 or battery.strings_parallel > 1
    return Identity(
        cells_series=int(battery.cells_series), strings_parallel=int(battery.strings_parallel),
        chemistry=battery.chemistry or None,
        cutoff_cell_V=float(own) if isinstance(own, (int, float)) else None,
        capacity_Ah=float(battery.capacity_Ah),
        pack=multi, measured=measured and multi, label=label)


@dataclass(frozen=True)
class Resolved:
    """The battery as flown, its cutoff per cell [V], the warnings on the way (conflicts)
    and the notes (what was taken from the mission's defaults)."""

    battery: object
    cutoff_cell_V: float | None
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)


def _layout(ident, warnings, where, key, own, default, given, option):
    """Cells in series or strings in parallel as flown."""
    what = "cells in series" if key == "series" else "strings in parallel"
    if given is not None and given != own:
        if ident.measured:
            raise DataError(f"{ident.label} has {own} {what} (from its logbook); {option} "
                            f"{given} cannot change that: leave {option} out")
        return int(given)
    if given is not None:
        return own
    if default is not None and default != own:
        if ident.pack:
            warnings.append(f"{where} says {key} = {default}, {ident.label} has {own} {what}; "
                            f"flying {own}")
            return own
        return int(default)
    return own


def resolve(battery, *, where: str = "the mission's [battery]", series: int | None = None,
            parallel: int | None = None, chemistry: str | None = None,
            cutoff_cell_V: float | None = None, cells_given: int | None = None,
            parallel_given: int | None = None, cutoff_given: float | None = None) -> Resolved:
    """The battery as flown and its cutoff, from its identity and a mission's defaults.

    Parameters
    ----------
    battery : Battery
    where : str
        Names the defaults in messages (e.g. ``"paper-table5 [battery]"``).
    series, parallel, chemistry, cutoff_cell_V : optional
        The mission's defaults (see the module notes for when each applies).
    cells_given, parallel_given, cutoff_given : optional
        Values the user gave explicitly (command-line options).

    Returns
    -------
    Resolved
        ``cutoff_cell_V`` is None when neither the battery, the mission nor the chemistry
        gives one.

    Raises
    ------
    DataError
        A logbook pack asked to fly with another layout; an unknown chemistry.
    """
    if chemistry is not None and chemistry not in CHEMISTRIES:
        raise DataError(f"{where}: chemistry must be one of {', '.join(CHEMISTRIES)}, "
                        f"got {chemistry!r}")
    ident = battery_identity(battery)
    warnings: list[str] = []
    cells = _layout(ident, warnings, where, "series", ident.cells_series, series,
                    cells_given, "--cells")
    strings = _layout(ident, warnings, where, "parallel", ident.strings_parallel, parallel,
                      parallel_given, "--parallel")
    flown = battery.with_pack(cells, strings)
    chem = ident.chemistry
    notes: list[str] = []
    if chem is None and chemistry is not None:
        chem = chemistry
        flown = replace(flown, chemistry=chem)
        notes.append(f"{ident.label} does not say its chemistry: {chem} from {where}")
    elif chemistry is not None and chemistry != chem and cutoff_given is None:
        # (with the cutoff given, the mission's chemistry decides nothing)
        warnings.append(f"{where} says chemistry = {chemistry}, {ident.label} is {chem}; "
                        f"flying {chem}")
    cutoff = _cutoff(ident, warnings, where, chem, chemistry, cutoff_cell_V, cutoff_given)
    return Resolved(flown, cutoff, warnings, notes)


def _cutoff(ident, warnings, where, chem, mission_chem, default, given):
    usual = CUTOFF_CELL_VOLTAGE_V.get(chem or "")
    if given is not None:
        return float(given)
    if ident.cutoff_cell_V is not None:
        if default is not None and abs(default - ident.cutoff_cell_V) > 1e-9:
            warnings.append(f"{where} says cutoff_cell_V = {default:g} V, {ident.label}'s "
                            f"own cutoff is {ident.cutoff_cell_V:g} V; flying "
                            f"{ident.cutoff_cell_V:g} V")
        return ident.cutoff_cell_V
    if default is None:
        return usual
    if mission_chem is not None and chem is not None and mission_chem != chem:
        if abs(default - usual) > 1e-9:
            warnings.append(f"{where} says cutoff_cell_V = {default:g} V (a {mission_chem} "
                            f"cutoff), {ident.label} is {chem}: flying the {chem} cutoff "
                            f"{usual:g} V")
        return usual
    return float(default)


__all__ = ["CHEMISTRIES", "Identity", "Resolved", "battery_identity", "resolve"]
