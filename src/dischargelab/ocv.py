"""Open-circuit voltage (OCV): generic per-chemistry curves, a prior, and a battery
model's own; state of charge and charge taken out from a rest voltage.

Used wherever a pack's state is read from its voltage at rest: flights
(:mod:`dischargelab.flight`), validation of runs that do not start full
(:mod:`dischargelab.validate`) and the logbook's health figures.

References
----------
.. [1] G. L. Plett, "Battery Management Systems, Vol. 1: Battery Modeling",
   Artech House (2015), ch. 2 (open-circuit voltage from a slow discharge
   corrected for the ohmic drop; state of charge from a rested voltage).
.. [2] Y. Ai, et al., "Electrochemical thermal-mechanical modelling of stress
   inhomogeneity in lithium-ion pouch cells", J. Electrochem. Soc. 167 (2020)
   013512 (the Enertech LCO pouch-cell C/10 discharge, ``../shared/data/enertech_lco``).
.. [3] ARTS-Laboratory, "dataset-electrothermal-deformation-characterization-for-
   samsung-30Q-cell" (Samsung INR18650-30Q C/10 discharge, ``../shared/data/samsung30q_S001``)
   and "Dataset-battery-electro-thermal-characterization" (K2 LFP26650 1C discharge,
   ``../shared/data/k2_lfp26650``); CC BY-SA 4.0.
.. [4] M. Doyle, "Design and simulation of lithium rechargeable batteries", PhD thesis,
   University of California, Berkeley (1995), and the Dualfoil program (J. Newman's group):
   the LiCoO2 open-circuit potential against lithium, ``U_p(y)``, measured down to a lithium
   fraction below 0.4 (as given in PyBaMM's ``Marquis2019`` parameter set, with its
   stoichiometry window of a 4.2 V LiCoO2/graphite cell: ``y`` from 0.4832 full to 0.9629
   empty; S. G. Marquis et al., J. Electrochem. Soc. 166 (2019) A3693).
"""

from __future__ import annotations

import numpy as np

from .errors import DataError, SimulationError

#: State of charge of the rows of :data:`GENERIC_OCV_V` [-] (1 full, 0 empty).
OCV_SOC = np.round(np.linspace(1.0, 0.0, 21), 2)


#: Generic open-circuit voltage per cell [V] at :data:`OCV_SOC`, by chemistry: a prior.
#:
#: * ``"lipo"``: LiCoO2/graphite (the chemistry of hobby LiPo packs): the Enertech
#:   2.28 Ah pouch cell's C/10 discharge to 3.0 V (ref. [2]), plus the ohmic drop at its load
#:   step (0.228 A x 25.9 mOhm); the full value is its rest voltage before the load.
#: * ``"li-ion"``: NMC/graphite 18650 (Li-ion drone packs): the Samsung INR18650-30Q
#:   C/10 discharge to 2.5 V (ref. [3]), plus its load-step ohmic drop (0.30 A x 36.3 mOhm).
#: * ``"lifepo4"``: LiFePO4/graphite: the shape of the K2 LFP26650 1C discharge at
#:   30 degC to 2.5 V (ref. [3]) (the first 0.5 % of the charge, the voltage just after
#:   charging, left out), shifted up by 0.1375 V so that 50 % reads the nominal 3.3 V:
#:   that set has no rest voltage, so its level is an assumption.
#:
#: State of charge counts the charge delivered by that discharge (0 % = its cutoff).
#: Real packs differ from these cells by tens of millivolts; the diffusion and
#: polarisation left in a C/10 curve put the table slightly below a true OCV.
#: The state of charge read from them is a prior with an error of about 5 % (LiPo,
#: Li-ion) and far more on the flat LiFePO4 plateau (see :func:`soc_from_rest_voltage`).
GENERIC_OCV_V = {
    "lipo": np.array([4.181, 4.119, 4.070, 4.025, 3.984, 3.947, 3.912, 3.873, 3.837, 3.814,
                      3.796, 3.781, 3.769, 3.759, 3.745, 3.725, 3.708, 3.682, 3.646, 3.551,
                      3.004]),
    "li-ion": np.array([4.142, 4.074, 4.057, 4.038, 3.987, 3.931, 3.884, 3.838, 3.793, 3.749,
                        3.703, 3.659, 3.621, 3.582, 3.521, 3.468, 3.412, 3.305, 3.168, 2.984,
                        2.511]),
    "lifepo4": np.array([3.430, 3.352, 3.347, 3.338, 3.332, 3.326, 3.321, 3.317, 3.312, 3.307,
                         3.300, 3.293, 3.286, 3.275, 3.262, 3.248, 3.232, 3.211, 3.158, 3.032,
                         2.635]),
}


#: Spread of real cells' open-circuit curves about :data:`GENERIC_OCV_V` per cell [V] at
#: :data:`OCV_SOC` (a standard deviation at each state of charge), by chemistry. Li-ion:
#: the root mean square of five NMC and NCA cells' deviations from the generic curve: the
#: Sony VTC6 measured in the CMU eVTOL lives (Bills et al. 2023), and the LG M50 (Chen et
#: al. 2020), an NMC532 pouch (Mohtat et al. 2020), a Kokam NMC pouch (Ecker et al. 2015)
#: and an NCA cell (Kim et al. 2011) from their published electrode curves
#: (``benchmarks/ocv_spread.py``, which checks it leaving each cell out). 25-37 mV over the
#: middle, 62-116 mV from 45 to 20 % where the cells part most (an LG M50 rests 57 mV
#: above the 30Q at 30 %), 54-55 mV at the top, where the generic curve sits low (its C/10
#: start). Chemistries not listed carry none beyond the generic curve's own error.
GENERIC_OCV_SPREAD_V = {
    "li-ion": np.array([55, 54, 27, 25, 32, 34, 31, 27, 30, 37, 48, 62, 74, 82, 103, 112,
                        116, 154, 210, 275, 51]) / 1000.0,
}


#: Where each table comes from (for notes and reports).
OCV_SOURCE = {
    "lipo": "generic LiPo (LiCoO2) OCV from a C/10 discharge (Enertech pouch cell, Ai et al. "
            "2020)",
    "li-ion": "generic Li-ion (NMC) OCV from a C/10 discharge (Samsung INR18650-30Q)",
    "lifepo4": "generic LiFePO4 OCV shape from a 1C discharge (K2 LFP26650), level assumed "
               "(3.3 V at 50 %)",
}


#: Charge voltage per cell [V] by chemistry (for inferring the cell count).
CHARGE_CELL_V = {"lipo": 4.2, "li-ion": 4.2, "lifepo4": 3.65}


#: Lithium fractions of LiCoO2 at the full and empty ends of a 4.2 V LiCoO2/graphite
#: cell's window (ref. [4]).
LCO_FULL_Y, LCO_EMPTY_Y = 0.4832, 0.9629

#: Full rest voltage per cell of a high-voltage LiPo (LiHV) cell [V]: charged to 4.35 V.
LIHV_FULL_CELL_V = 4.35

#: A LiPo pack whose rest voltage per cell is above this [V] is a high-voltage one (LiHV):
#: a 4.20 V cell cannot rest there (its charger stops at 4.20 V, +-0.05 V at worst), a
#: 4.35 V cell rests at 4.28-4.35 V after its charge.
LIHV_REST_CELL_V = 4.25


def _lco_potential(y):
    """Open-circuit potential of Li_yCoO2 against lithium [V] (Doyle 1995, ref. [4])."""
    y = 1.062 * np.asarray(y, dtype=float)
    t = np.tanh
    return (2.16216 + 0.07645 * t(30.834 - 54.4806 * y) + 2.1581 * t(52.294 - 50.294 * y)
            - 0.14169 * t(11.0923 - 19.8543 * y) + 0.2051 * t(1.4684 - 5.4888 * y)
            + 0.2531 * t((-y + 0.56478) / 0.1316) - 0.02167 * t((y - 0.525) / 0.006))


def _lihv_table() -> tuple[np.ndarray, float]:
    """The LiHV open-circuit voltage per cell at :data:`OCV_SOC` [V] and the share of its
    charge above the LiPo curve's top (see :data:`LIHV_OCV_V`)."""
    lipo = GENERIC_OCV_V["lipo"]
    offset = float(_lco_potential(LCO_FULL_Y)) - lipo[0]   # the negative's potential, full
    # full is the rest after the charge, as for the LiPo curve (4.181 V after 4.20 V)
    top_v = LIHV_FULL_CELL_V - (CHARGE_CELL_V["lipo"] - lipo[0])
    y = np.linspace(0.25, LCO_FULL_Y, 2001)
    top_y = float(np.interp(top_v, (_lco_potential(y) - offset)[::-1], y[::-1]))
    share = (LCO_FULL_Y - top_y) / (LCO_EMPTY_Y - top_y)
    soc = OCV_SOC
    below = np.interp(soc / (1.0 - share), OCV_SOC[::-1], lipo[::-1])
    above = _lco_potential(LCO_FULL_Y - (soc - (1.0 - share)) / share * (LCO_FULL_Y - top_y))
    return np.round(np.where(soc <= 1.0 - share, below, above - offset), 3), float(share)


#: Generic open-circuit voltage per cell of a high-voltage LiPo (LiHV, charged to 4.35 V:
#: DJI's TB47/TB48 class) at :data:`OCV_SOC` [V], a prior. The same LiCoO2/graphite cell
#: as ``"lipo"`` with its positive electrode taken further: below the LiPo curve's top its
#: voltage against the charge left is the LiPo curve's (the same electrodes, emptied the
#: same way); above it, the LiCoO2 potential (ref. [4]) from the 4.2 V window's full
#: lithium fraction to where the cell reads 4.35 V, less the negative's potential there
#: (the LiPo curve's top). That extension holds :data:`LIHV_EXTRA_SHARE` (0.22) of the
#: charge, 28 % more than the 4.2 V window, an upper bound: commercial LiHV cells are
#: balanced for the extra charge at some cost elsewhere. Chosen from what a log shows (a
#: rest above :data:`LIHV_REST_CELL_V` per cell), not from a label.
LIHV_OCV_V, LIHV_EXTRA_SHARE = _lihv_table()

#: Where the LiHV table comes from.
LIHV_SOURCE = ("generic LiHV (LiCoO2 to 4.35 V) OCV: the LiPo curve extended by the LiCoO2 "
               "potential (Doyle 1995)")


def generic_ocv(chemistry: str | None, rest_cell_V: float | None = None
                ) -> tuple[np.ndarray, str]:
    """The generic open-circuit voltage table per cell at :data:`OCV_SOC` [V] and its source.

    A LiPo pack (``"lipo"`` or None) whose highest rest voltage per cell ``rest_cell_V``
    is above :data:`LIHV_REST_CELL_V` gets the high-voltage table :data:`LIHV_OCV_V`.
    """
    chem = check_chemistry(chemistry)
    if is_lihv(chem, rest_cell_V):
        return LIHV_OCV_V, LIHV_SOURCE
    return GENERIC_OCV_V[chem], OCV_SOURCE[chem]


def is_lihv(chemistry: str | None, rest_cell_V: float | None) -> bool:
    """True for a LiPo pack (``"lipo"`` or None) whose highest rest voltage per cell
    ``rest_cell_V`` [V] is above :data:`LIHV_REST_CELL_V`: a high-voltage (4.35 V) pack."""
    return (check_chemistry(chemistry) == "lipo" and rest_cell_V is not None
            and rest_cell_V > LIHV_REST_CELL_V)


def charge_cell_V(chemistry: str | None, rest_cell_V: float | None = None) -> float:
    """The voltage per cell a pack is charged to [V]: :data:`LIHV_FULL_CELL_V` for a
    high-voltage pack (:func:`is_lihv`), else :data:`CHARGE_CELL_V` of its chemistry."""
    if is_lihv(chemistry, rest_cell_V):
        return LIHV_FULL_CELL_V
    return CHARGE_CELL_V[check_chemistry(chemistry)]


#: Chemistry assumed when none is given (most UAV packs).
DEFAULT_CHEMISTRY = "lipo"


def check_chemistry(chemistry: str | None) -> str:
    """The chemistry name, :data:`DEFAULT_CHEMISTRY` for None.

    Raises
    ------
    DataError
        Not one of the keys of :data:`GENERIC_OCV_V`.
    """
    if chemistry is None:
        return DEFAULT_CHEMISTRY
    if chemistry not in GENERIC_OCV_V:
        raise DataError(f"chemistry must be one of {', '.join(GENERIC_OCV_V)}, got {chemistry!r}")
    return chemistry


def ocv_from_soc(soc, chemistry: str | None = None):
    """Generic open-circuit voltage per cell [V] at state of charge ``soc`` [0-1].

    Linear interpolation in :data:`GENERIC_OCV_V` (a prior, see there).
    """
    table = GENERIC_OCV_V[check_chemistry(chemistry)]
    return np.interp(np.clip(soc, 0.0, 1.0), OCV_SOC[::-1], table[::-1])


def soc_from_rest_voltage(cell_V, chemistry: str | None = None):
    """State of charge [0-1] of a cell resting at ``cell_V`` [V], by the generic OCV.

    Voltages above the table's full value read 1, below its empty value 0.

    Parameters
    ----------
    cell_V : float or array_like
        Rest voltage per cell [V] (pack voltage / cells in series).
    chemistry : {"lipo", "li-ion", "lifepo4"}, optional
        Default :data:`DEFAULT_CHEMISTRY`.

    Returns
    -------
    float or numpy.ndarray
        State of charge [-].

    References
    ----------
    Plett (2015), ch. 2; the tables of :data:`GENERIC_OCV_V`.
    """
    table = GENERIC_OCV_V[check_chemistry(chemistry)]
    out = np.interp(np.asarray(cell_V, dtype=float), table[::-1], OCV_SOC[::-1])
    return float(out) if np.ndim(out) == 0 else out


def soc_per_10mV(cell_V: float, chemistry: str | None = None) -> float:
    """How far 10 mV of rest-voltage error moves the state of charge [0-1] at ``cell_V``."""
    lo = soc_from_rest_voltage(cell_V - 0.005, chemistry)
    hi = soc_from_rest_voltage(cell_V + 0.005, chemistry)
    return float(abs(hi - lo))


def model_charge_at_rest(battery, pack_V: float, current_A: float = 0.0) -> float:
    """Pack charge taken out [Ah] at which ``battery`` reads ``pack_V`` [V].

    With ``current_A`` = 0 this inverts the model's open-circuit voltage; with a
    current it inverts the loaded voltage with every filtered state settled at
    that current (:meth:`dischargelab.model.Battery.voltage`). The result is
    clipped to [0, capacity).
    """
    capacity = battery.capacity_Ah
    q = np.linspace(0.0, capacity * (1.0 - 1e-6), 4001)
    with np.errstate(invalid="ignore", over="ignore"):
        v = np.asarray(battery.voltage(np.full(q.size, float(current_A)), q), dtype=float)
    ok = np.isfinite(v)
    if not ok.any():
        raise SimulationError("the battery model cannot be evaluated at this current")
    v = np.minimum.accumulate(np.where(ok, v, -np.inf))
    if pack_V >= v[0]:
        return 0.0
    k = int(np.argmax(v <= pack_V))
    if v[k] > pack_V:
        return float(q[-1])
    v0, v1 = v[k - 1], v[k]
    frac = (v0 - pack_V) / (v0 - v1) if np.isfinite(v1) and v0 != v1 else 0.0
    return float(q[k - 1] + frac * (q[k] - q[k - 1]))
