"""A thermal prior for cells whose temperature was not logged.

A pack drained slowly on the bench (or flown without a temperature sensor) hardly heats,
so its log cannot show how the cell warms at a higher current, and a model held at the
ambient keeps the cold resistance when a fast drain would heat the cell and lower it.
This prior gives each cell a lumped heat capacity and thermal resistance to the ambient
from what is known: its capacity, its chemistry, the cells in the pack and how it is
cooled. The thermal families then simulate the self-heating with the same lumped model
(:mod:`dischargelab.models.base`) they use with a logged temperature.

Per cell, nominal energy ``E = C U_nom`` [Wh]:

* mass ``m = E / e_m`` and volume ``V = E / e_v`` from the chemistry's specific energy
  ``e_m`` [Wh/kg] and energy density ``e_v`` [Wh/L] (:data:`CELL_DATA`);
* heat capacity ``C_th = m c_p`` with ``c_p = 1000 J/(kg K)`` for a lithium-ion cell as a
  whole (calorimetry of 18650 cells gives 0.9-1.1 J/(g K): Maleki et al. 1999 [1]_;
  Bernardi et al. 1985 [2]_ for the energy balance);
* cooling area: the pack (``cells`` cells side by side) as a box with sides in the ratio
  1 : 2 : 3, whose surface ``22 a^2`` (volume ``6 a^3``) is shared by its cells; a single
  cell alone is the same box. An 18650 comes out at 46 cm^2 (real: 42 cm^2);
* thermal resistance ``R_th = 1 / (h A)`` with ``h`` for still air, natural convection
  plus radiation from a bare cell (:data:`STILL_AIR_H`, 10 W/(m^2 K), the value of the
  virtual cells in ``tests/data/virtual``), or the airflow over a pack in flight
  (:data:`AIRFLOW_H`, 30 W/(m^2 K): laminar flow over a 10 cm plate at 5-10 m/s,
  ``Nu = 0.664 Re^0.5 Pr^(1/3)``, gives 25-40 W/(m^2 K) [3]_, less where the pack is
  strapped to the frame on one side).

References
----------
.. [1] H. Maleki, S. Al Hallaj, J. R. Selman, R. B. Dinwiddie, H. Wang, "Thermal
   properties of lithium-ion battery and components", J. Electrochem. Soc. 146 (1999)
   947-954.
.. [2] D. Bernardi, E. Pawlikowski, J. Newman, "A general energy balance for battery
   systems", J. Electrochem. Soc. 132 (1985) 5-12.
.. [3] F. P. Incropera, D. P. DeWitt, "Fundamentals of Heat and Mass Transfer", 5th ed.,
   Wiley (2002), section 7.2 (laminar flat plate) and table 1.1 (h of air: 2-25
   W/(m^2 K) free, 25-250 W/(m^2 K) forced convection).
.. [4] Datasheets: Samsung INR18650-30Q (3.0 Ah, 3.6 V, 48 g, 18.3 x 65 mm: 225 Wh/kg,
   630 Wh/L); A123 ANR26650M1 (2.3-2.5 Ah, 3.3 V, 76 g, 26 x 65 mm: 100-110 Wh/kg,
   220-240 Wh/L). LiPo pouch cells of drone packs: 130-200 Wh/kg and 300-400 Wh/L
   (D. Linden, T. B. Reddy, "Handbook of Batteries", 4th ed., McGraw-Hill (2011),
   ch. 26).
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import DataError

#: Specific heat of a lithium-ion cell as a whole [J/(kg K)] [1].
SPECIFIC_HEAT_J_PER_KG_K = 1000.0

#: Heat transfer coefficients [W/(m^2 K)]: still air (bench), airflow (in flight).
STILL_AIR_H = 10.0
AIRFLOW_H = 30.0
COOLING_H = {"still-air": STILL_AIR_H, "airflow": AIRFLOW_H}

#: Pack box: sides a, 2a, 3a -> surface 22 a^2, volume 6 a^3.
_BOX_SURFACE, _BOX_VOLUME = 22.0, 6.0


@dataclass(frozen=True)
class CellData:
    """Nominal voltage [V], specific energy [Wh/kg] and energy density [Wh/L] of a cell."""

    nominal_V: float
    specific_energy_Wh_per_kg: float
    energy_density_Wh_per_L: float


#: Per chemistry (keys as :data:`dischargelab.model.CUTOFF_CELL_VOLTAGE_V`) [4].
CELL_DATA = {
    "lipo": CellData(3.7, 160.0, 350.0),
    "li-ion": CellData(3.6, 225.0, 630.0),
    "lifepo4": CellData(3.2, 105.0, 230.0),
}

#: Open-circuit voltage per cell when full [V] above which a cell is read as lithium
#: cobalt / nickel (LiPo), below which as LiFePO4 (3.6 V full).
LIFEPO4_FULL_BELOW_V = 3.75


def chemistry_from_full_voltage(full_cell_V: float) -> str:
    """``"lifepo4"`` for a full cell under 3.75 V, else ``"lipo"``."""
    return "lifepo4" if full_cell_V < LIFEPO4_FULL_BELOW_V else "lipo"


def thermal_prior(capacity_Ah: float, chemistry: str = "lipo", *, cells: int = 1,
                  cooling: str = "still-air") -> dict:
    """Heat capacity and thermal resistance to the ambient of one cell (see module doc).

    Parameters
    ----------
    capacity_Ah : float
        Cell capacity [Ah] (a string of ``p`` cells: the capacity of one).
    chemistry : {"lipo", "li-ion", "lifepo4"}
    cells : int
        Cells in the pack (series times parallel), which share its surface.
    cooling : {"still-air", "airflow"}

    Returns
    -------
    dict
        ``Cth_J_per_K``, ``Rth_K_per_W``, ``mass_kg``, ``area_m2`` (cooling area per
        cell), ``h_W_per_m2K``, ``chemistry``, ``cooling`` and ``note`` (one line).

    Raises
    ------
    DataError
        Unknown chemistry or cooling, capacity not positive, cells below 1.
    """
    if chemistry not in CELL_DATA:
        raise DataError(f"chemistry must be one of {', '.join(CELL_DATA)}, got {chemistry!r}")
    if cooling not in COOLING_H:
        raise DataError(f"cooling must be one of {', '.join(COOLING_H)}, got {cooling!r}")
    if not capacity_Ah > 0:
        raise DataError(f"capacity must be positive to size a thermal prior, got {capacity_Ah}")
    if cells < 1:
        raise DataError(f"cells must be at least 1, got {cells}")
    data = CELL_DATA[chemistry]
    energy_Wh = capacity_Ah * data.nominal_V
    mass = energy_Wh / data.specific_energy_Wh_per_kg
    volume_m3 = energy_Wh / data.energy_density_Wh_per_L * 1e-3
    side = (cells * volume_m3 / _BOX_VOLUME) ** (1.0 / 3.0)
    area = _BOX_SURFACE * side * side / cells
    h = COOLING_H[cooling]
    cth = mass * SPECIFIC_HEAT_J_PER_KG_K
    rth = 1.0 / (h * area)
    note = (f"thermal prior ({chemistry}, {capacity_Ah:.3g} Ah per cell, {cells} cell(s), "
            f"{cooling.replace('-', ' ')}): {1000 * mass:.0f} g x "
            f"{SPECIFIC_HEAT_J_PER_KG_K:.0f} J/(kg K) = {cth:.3g} J/K per cell, "
            f"{1e4 * area:.0f} cm^2 of the pack's surface per cell at h = {h:g} W/(m^2 K): "
            f"{rth:.3g} K/W (time constant {cth * rth / 60:.0f} min)")
    return {"Cth_J_per_K": float(cth), "Rth_K_per_W": float(rth), "mass_kg": float(mass),
            "area_m2": float(area), "h_W_per_m2K": float(h), "chemistry": chemistry,
            "cooling": cooling, "note": note}


__all__ = ["thermal_prior", "chemistry_from_full_voltage", "CELL_DATA", "COOLING_H",
           "STILL_AIR_H", "AIRFLOW_H", "SPECIFIC_HEAT_J_PER_KG_K"]
