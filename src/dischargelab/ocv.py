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
