"""Which chemistry a pack is, read from how its voltage falls under load.

A LiPo pouch's open-circuit voltage is flat from 60 % to 20 % of its charge (3.84 to
3.71 V per cell on the generic curve); an NMC cylinder's falls three times as steeply
(3.79 to 3.41 V); a LiFePO4 cell rests below 3.45 V per cell when full and holds
3.2-3.35 V over most of its charge, where the 4.2 V curves are empty. A load that starts
from a rest and moves a tenth of the charge or more shows which: for each chemistry, the
rest reads the start on its curve and the loaded
voltage is fitted as ``OCV_c(s0 - q / C) - r I`` over the capacity ``C`` (a grid) and
the resistance ``r >= 0`` (least squares), the first :data:`SETTLE_SHARE` of the load left
out (its polarisation still building). The chemistry whose fits leave clearly less
(rms below :data:`CLEAR_RATIO` of the other's over the pack's loads) is the pack's;
otherwise it stays unknown.

References: G. L. Plett, "Battery Management Systems, Vol. 1", Artech House (2015),
ch. 2 (the open-circuit voltage against state of charge per chemistry).
"""

from __future__ import annotations

import numpy as np

#: Chemistries told apart (the first two charged to 4.2 V per cell, LiFePO4 to 3.65 V).
CANDIDATES = ("lipo", "li-ion", "lifepo4")

#: Share of a load's charge left out at its start (the polarisation building).
SETTLE_SHARE = 0.15

#: A chemistry is chosen when its fits' rms is below this share of the other's.
CLEAR_RATIO = 0.6

#: Capacities tried, as the share of it the load moved.
_SHARES = np.linspace(0.95, 0.08, 140)


def _fit_rms(q, v_cell, i, s0: float, table_soc, table_v) -> float:
    """Least rms [V per cell] of ``OCV(s0 - q / C) - r i`` over the capacity grid."""
    best = np.inf
    total = float(q[-1])
    for share in _SHARES:
        cap = total / share
        soc = s0 - q / cap
        if soc[-1] < 0.0:
            continue
        ocv = np.interp(soc, table_soc, table_v)
        gap = ocv - v_cell
        # a resistance is not negative: a curve below the loaded voltage does not fit
        r = max(float(gap @ i / (i @ i)), 0.0) if i @ i > 0 else 0.0
        rms = float(np.sqrt(np.mean((gap - r * i) ** 2)))
        best = min(best, rms)
    return best


def chemistry_from_loads(loads: list[tuple[dict, int]]) -> tuple[str | None, str]:
    """The pack's chemistry from its loads (``(event, cells)`` pairs), or None, with why."""
    from ..ocv import OCV_SOC, generic_ocv

    sums = dict.fromkeys(CANDIDATES, 0.0)
    used = 0
    for e, cells in loads:
        curve = e.get("curve") or {}
        q = np.asarray(curve.get("charge_Ah") or [], dtype=float)
        before = ((e.get("details") or {}).get("rest_before") or {}).get("relaxed_V") \
            or e.get("rest_voltage_V")
        if q.size < 10 or before is None or q[-1] <= 0:
            continue
        keep = q >= SETTLE_SHARE * q[-1]
        v = np.asarray(curve["voltage_V"], dtype=float)[keep] / cells
        i = np.asarray(curve["current_A"], dtype=float)[keep]
        for chem in CANDIDATES:
            table, _ = generic_ocv(chem)
            soc, volts = OCV_SOC[::-1], np.maximum.accumulate(table[::-1])
            s0 = float(np.interp(float(before) / cells, volts, soc))
            sums[chem] += _fit_rms(q[keep], v, i, s0, soc, volts) ** 2
        used += 1
    if not used:
        return None, "no load from a rest to read the chemistry from"
    rms = {c: np.sqrt(s / used) for c, s in sums.items()}
    best, other = sorted(CANDIDATES, key=rms.get)[:2]
    if rms[best] < CLEAR_RATIO * rms[other]:
        return best, (f"read from {used} load(s): the {best} curve fits to "
                      f"{1000 * rms[best]:.0f} mV, the {other} curve to "
                      f"{1000 * rms[other]:.0f} mV per cell")
    return None, (f"not told apart by {used} load(s) (the {best} and {other} curves fit to "
                  f"{1000 * rms[best]:.0f} and {1000 * rms[other]:.0f} mV per cell)")


def infer_chemistry(full_cell_V: float, end_cell_V: float) -> str:
    """The chemistry whose charge and cutoff voltages per cell lie nearest to a full
    discharge's rest (or first) voltage and end voltage [V] (tables
    :data:`dischargelab.ocv.CHARGE_CELL_V`, :data:`dischargelab.cell.CUTOFF_CELL_VOLTAGE_V`)."""
    from ..cell import CUTOFF_CELL_VOLTAGE_V
    from ..ocv import CHARGE_CELL_V

    return min(CHARGE_CELL_V, key=lambda c: abs(CHARGE_CELL_V[c] - full_cell_V)
               + abs(CUTOFF_CELL_VOLTAGE_V[c] - end_cell_V))


__all__ = ["chemistry_from_loads", "infer_chemistry", "CANDIDATES", "CLEAR_RATIO"]
