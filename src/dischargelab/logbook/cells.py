"""Cells apart: per-cell figures of one event, and a cell drifting away over a pack's life.

Where a log measures each cell (INA3221 CSV, ArduPilot BCL, Betaflight, LogView:
columns ``cell1_V``, ``cell2_V``, ...), each event gets (:func:`cell_figures`):

* the cells' rest voltages before and after the load (relaxed as the pack's are,
  :func:`dischargelab.logbook.relaxation.relaxation`) and their spread;
* each cell's sag (rest voltage before the load minus its lowest loaded voltage)
  and its resistance from the load steps (the pack's steps, the cell's voltage);
* the cells whose resistance or sag stands off the others' median (by
  :data:`OFF_RESISTANCE_RATIO` or :data:`OFF_SAG_V`).

Over the pack's events (:func:`drift_flags`), a cell *drifts* when it has stood off
the others in at least :data:`DRIFT_EVENTS` events in a row and its distance from
them has grown since the pack's first events: a weak cell shows in its sag and its
resistance long before it limits the pack's capacity (its share of it, from the
cells' own swings through the open-circuit voltage, is
:func:`weakest_share`).

References
----------
.. [1] G. L. Plett, "Battery Management Systems, Vol. 2: Equivalent-Circuit
   Methods", Artech House (2016), ch. 6 (cell balancing; the weakest cell limits
   a series pack's usable capacity).
"""

from __future__ import annotations

import re

import numpy as np

from .estimates import capacity_between_rests, step_resistance
from .relaxation import relaxation

#: A cell's resistance stands off when it is this many times the others' median ...
OFF_RESISTANCE_RATIO = 1.3

#: ... or its sag is this much more than their median [V].
OFF_SAG_V = 0.05

#: Events in a row a cell must stand off the others to drift.
DRIFT_EVENTS = 2

_CELL = re.compile(r"cell(\d+)_V")


def cell_columns(columns) -> list[str]:
    """Per-cell voltage columns (``cell1_V``, ``cell2_V`` ...) in cell order."""
    found = [(int(m.group(1)), c) for c in columns if (m := _CELL.fullmatch(str(c)))]
    return [c for _, c in sorted(found)]


def _cell_rest(t, cells, since, direction, loaded):
    """Relaxed rest voltage of each cell [V] (``cells``: rows x cells)."""
    out = []
    for k in range(cells.shape[1]):
        v = cells[:, k]
        r = relaxation(since, v, direction, loaded_V=None if loaded is None else loaded[k])
        out.append(float(r["relaxed_V"]))
    return out


def cell_figures(time_s, current_A, cells_V, *, before=None, after=None) -> dict | None:
    """Per-cell figures of one event.

    Parameters
    ----------
    time_s, current_A : array_like
        The event's samples [s, A] (discharge positive).
    cells_V : array_like
        Cell voltages of those samples [V], rows x cells.
    before, after : dict, optional
        The rests around the event: ``{"time_s": array, "cells_V": rows x cells,
        "since_load_s": array or None, "direction": int}``.

    Returns
    -------
    dict or None
        ``count``, ``rest_before_V`` and ``rest_after_V`` (per cell or None),
        ``rest_spread_V`` (largest minus smallest rest voltage, before the load, else
        after it), ``sag_V`` and ``resistance_ohm`` (per cell), ``off`` (numbers,
        from 1, of the cells standing off the others). None without cell columns.
    """
    cells = np.asarray(cells_V, dtype=float)
    if cells.ndim != 2 or cells.shape[1] < 2 or cells.shape[0] < 2:
        return None
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    ok = np.all(np.isfinite(cells), axis=1)
    if ok.sum() < 2:
        return None
    t, i, cells = t[ok], i[ok], cells[ok]
    rest_before = rest_after = None
    if before is not None and len(before["cells_V"]):
        rest_before = _cell_rest(before["time_s"], np.asarray(before["cells_V"], float),
                                 before.get("since_load_s"), before.get("direction", 0), None)
    if after is not None and len(after["cells_V"]):
        rest_after = _cell_rest(after["time_s"], np.asarray(after["cells_V"], float),
                                after.get("since_load_s"), after.get("direction", 0),
                                cells[-1])
    top = np.asarray(rest_before if rest_before is not None else cells[0], dtype=float)
    sag = top - np.min(cells, axis=0)
    resistance = [step_resistance(t, cells[:, k], i)[0] for k in range(cells.shape[1])]
    spread_of = rest_before if rest_before is not None else rest_after
    off = set()
    r = np.array([np.nan if x is None else x for x in resistance])
    for k in range(cells.shape[1]):
        others = np.delete(np.arange(cells.shape[1]), k)
        r_med = np.nanmedian(r[others]) if np.isfinite(r[others]).any() else np.nan
        if np.isfinite(r[k]) and np.isfinite(r_med) and r_med > 0 \
                and r[k] > OFF_RESISTANCE_RATIO * r_med:
            off.add(k + 1)
        if sag[k] > np.median(sag[others]) + OFF_SAG_V:
            off.add(k + 1)
    return {"count": int(cells.shape[1]), "rest_before_V": rest_before,
            "rest_after_V": rest_after,
            "rest_spread_V": None if spread_of is None else float(np.ptp(spread_of)),
            "sag_V": [float(x) for x in sag], "resistance_ohm": resistance,
            "off": sorted(off)}


def weakest_share(curve, figures: dict, charge_Ah: float, charge_sd_Ah: float
                  ) -> tuple[float | None, int | None]:
    """The weakest cell's capacity as a share of the cells' mean, and its number (from 1).

    Each cell's capacity is the event's counted charge over the change of that
    cell's state of charge between the rests (its relaxed voltages through the
    pack's open-circuit voltage per cell, ``curve``); None when the event has no
    rest on one side or a swing too small for every cell.
    """
    from .estimates import READING_SD_CELL_V

    before, after = figures.get("rest_before_V"), figures.get("rest_after_V")
    if not before or not after:
        return None, None
    caps = []
    for vb, va in zip(before, after):
        sb, sa = curve.soc_at(vb), curve.soc_at(va)
        sd_b = np.hypot(curve.sd_V, READING_SD_CELL_V) / max(curve.slope(sb), 1e-6)
        sd_a = np.hypot(curve.sd_V, READING_SD_CELL_V) / max(curve.slope(sa), 1e-6)
        cap, _, _ = capacity_between_rests(charge_Ah, charge_sd_Ah, sb, sd_b, sa, sd_a)
        caps.append(np.nan if cap is None else cap)
    caps = np.array(caps)
    if not np.isfinite(caps).all():
        return None, None
    k = int(np.argmin(caps))
    return float(caps[k] / np.mean(caps)), k + 1


def drift_flags(off_per_event: list[list[int]], spread_per_event: list[float | None]
                ) -> list[bool]:
    """Per event (in life order): is a cell drifting away from the others by then?

    A cell drifts at an event when it stood off the others (``off`` of
    :func:`cell_figures`) in this and the :data:`DRIFT_EVENTS` - 1 events before it
    that have cell figures, and the pack's rest-voltage spread has not shrunk since
    its first such event (a cell pulled back by balancing is not drifting).
    """
    out = []
    history: list[set] = []
    first_spread = None
    for off, spread in zip(off_per_event, spread_per_event):
        if off is None:
            out.append(False)
            continue
        history.append(set(off))
        if first_spread is None and spread is not None:
            first_spread = spread
        recent = history[-DRIFT_EVENTS:]
        common = set.intersection(*recent) if len(recent) == DRIFT_EVENTS else set()
        growing = spread is None or first_spread is None or spread >= first_spread
        out.append(bool(common) and growing)
    return out


__all__ = ["cell_columns", "cell_figures", "weakest_share", "drift_flags",
           "OFF_RESISTANCE_RATIO", "OFF_SAG_V"]
