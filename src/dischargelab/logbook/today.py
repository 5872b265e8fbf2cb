"""A pack's model at its health today when it has no fitted model: the chemistry's prior.

A pack that only flies (no full discharge, so no fitted model) still has a capacity
and a resistance today (:mod:`.trend`). Its model is then the ``ecm`` family built
from what is known about the chemistry and scaled to those figures:

* open-circuit voltage: the chemistry's generic curve
  (:data:`dischargelab.ocv.GENERIC_OCV_V`) on the family's grid;
* capacity: the pack's capacity today (one string of cells in series);
* series resistance: the pack's resistance today per cell (the load-step
  resistance: series resistance plus the fastest polarisation), no RC pairs;
* solid diffusion: the family's prior steady lead (:data:`STEADY_TAU_D_S`);
* heat: the thermal prior of a pack of that capacity
  (:func:`dischargelab.thermalprior.thermal_prior`).

It is a prior, not a fit: flight times from it carry the generic curve's error
(tens of millivolts, a few per cent of state of charge), and the note says so.
"""

from __future__ import annotations

import numpy as np

from ..errors import LogbookError
from ..formatting import quantity, quantity_interval
from .trend import sd_from_interval

#: Pack resistance per cell assumed when no event measured one [ohm]: the ``ecm``
#: family's default start.
DEFAULT_CELL_OHM = 0.02


def prior_battery(name: str, chemistry: str, cells: int, capacity_Ah: float,
                  resistance_ohm: float | None, note: str, rest_cell_V: float | None = None,
                  capacity_sd: float | None = None, resistance_interval95=None):
    """The chemistry's prior (module docstring) as a Battery of ``cells`` in series.

    Parameters
    ----------
    name : str
        The pack.
    chemistry : {"lipo", "li-ion", "lifepo4"}
    cells : int
        Cells in series.
    capacity_Ah : float
        Pack capacity today [Ah].
    resistance_ohm : float or None
        Pack resistance today [ohm].
    note : str
        Where the figures come from (the Battery's ``extra["note"]`` starts with it).
    rest_cell_V : float, optional
        The pack's highest rest voltage per cell [V]: a LiPo pack resting above 4.25 V
        gets the high-voltage (LiHV) curve (:func:`dischargelab.ocv.generic_ocv`).
    capacity_sd : float, optional
        Relative standard deviation of ``capacity_Ah`` [-]; with
        ``resistance_interval95`` (pack [ohm]) it becomes the Battery's covariance, so
        that flight times drawn from it carry how well today's figures are known.
    """
    from ..cell import CellParameters
    from ..model import Battery
    from ..models import get_family
    from ..models.ecm import OCV_DROP_NAMES, OCV_NODES, STEADY_TAU_D_S
    from ..ocv import OCV_SOC, check_chemistry, generic_ocv
    from ..thermalprior import thermal_prior

    chemistry = check_chemistry(chemistry)
    if not capacity_Ah or capacity_Ah <= 0:
        raise LogbookError(f"pack {name!r} has no capacity today to build a model from")
    table, source = generic_ocv(chemistry, rest_cell_V)
    ocv = np.interp(1.0 - OCV_NODES, OCV_SOC[::-1], table[::-1])
    cell_ohm = DEFAULT_CELL_OHM if resistance_ohm is None else float(resistance_ohm) / cells
    heat = thermal_prior(capacity_Ah, chemistry, cells=cells)
    fam = get_family("ecm")
    values = {p.name: p.default for p in fam.parameters}
    values.update({"U_full_V": float(ocv[0]), "R0_ohm": max(cell_ohm, 0.0), "R1_ohm": 0.0,
                   "R2_ohm": 0.0, "tau_d_s": STEADY_TAU_D_S, "C_Ah": float(capacity_Ah),
                   "Cth_J_per_K": heat["Cth_J_per_K"], "Rth_K_per_W": heat["Rth_K_per_W"]})
    values.update({k: float(max(d, 0.0)) for k, d in zip(OCV_DROP_NAMES, -np.diff(ocv))})
    resistance = ("no resistance measured: 20 mOhm per cell assumed" if resistance_ohm is None
                  else f"its resistance today {1000 * cell_ohm:.1f} mOhm per cell")
    text = (f"{note}; no fitted model (no full discharge): the {chemistry} prior "
            f"({source}) scaled to its capacity today {capacity_Ah:.3g} Ah and "
            f"{resistance} - a prior, not a fit: expect a few per cent of error in time")
    variance = np.zeros(len(fam.names))
    if capacity_sd:
        variance[fam.names.index("C_Ah")] = (capacity_sd * capacity_Ah) ** 2
    band = resistance_interval95
    if resistance_ohm is not None and band and None not in band:
        variance[fam.names.index("R0_ohm")] = (float(sd_from_interval(*band)) / cells) ** 2
    return Battery(parameters=CellParameters.from_dict(values, fam.names), cells_series=cells,
                   covariance=np.diag(variance) if np.any(variance) else None,
                   name=f"{name} (today, {chemistry} prior)", chemistry=chemistry,
                   extra={"nominal_capacity_Ah": float(capacity_Ah), "note": text,
                          "logbook": {"pack": name, "prior": chemistry},
                          "thermal_prior": heat["note"]},
                   model="ecm")


def figures_note(health, name: str) -> str:
    """One line: the pack's capacity and resistance today and the events they come from."""
    t = health.today
    parts = [f"logbook pack {name!r} at EFC {quantity('efc', t.get('efc'))}"]
    if t.get("capacity_Ah") is not None:
        parts.append(f"capacity today {quantity('capacity_Ah', t['capacity_Ah'], unit=True)} "
                     f"(95 %: {quantity_interval('capacity_Ah', t.get('capacity_interval95'))})"
                     f" from {_events(t.get('capacity_from'))}")
    if t.get("resistance_ohm") is not None:
        parts.append(f"resistance {quantity('resistance_ohm', t['resistance_ohm'], unit=True)} "
                     f"({t.get('resistance_basis')}) from {_events(t.get('resistance_from'))}")
    return ", ".join(parts)


def _events(sources) -> str:
    """``3 events: a.csv, b.csv, c.csv (flight, flight, full)``, the latest last."""
    sources = list(sources or [])
    if not sources:
        return "no event"
    names = [s["source"] for s in sources]
    kinds = sorted({str(s.get("kind")) for s in sources})
    shown = ", ".join(names[-4:]) if len(names) <= 4 else f"... {', '.join(names[-3:])}"
    return (f"{len(names)} event{'s' if len(names) > 1 else ''} ({'/'.join(kinds)}: "
            f"{shown})")


__all__ = ["prior_battery", "figures_note", "DEFAULT_CELL_OHM"]
