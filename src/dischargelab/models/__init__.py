"""Battery model families. Each family is one module; register it in :data:`FAMILIES`.

- ``shepherd``: the paper's eq. (6), isothermal.
- ``shepherd-thermal``: eq. (6) with temperature-dependent parameters and a lumped thermal
  state.
- ``shepherd-dynamic``: shepherd-thermal whose polarisation reads Tremblay's filtered current,
  its resistance at full charge a parameter of its own.
- ``ecm``: OCV(SOC) + series R + RC pairs + solid-diffusion state + thermal state.
"""

from __future__ import annotations

from ..errors import DataError
from .base import Family, Parameter, Samples, State
from .dynamic import ShepherdDynamic
from .ecm import EquivalentCircuit
from .shepherd import Shepherd
from .thermal import ShepherdThermal

#: Registered families by name (the value of ``model`` in battery files). A new family
#: is one new module plus its entry here.
FAMILIES: dict[str, Family] = {f.name: f for f in (Shepherd(), ShepherdThermal(),
                                                   ShepherdDynamic(), EquivalentCircuit())}

#: Names written by older versions of dischargelab.
ALIASES = {"tremblay": "shepherd"}

DEFAULT_FAMILY = "shepherd"


def get_family(name) -> Family:
    """The family called ``name`` (a :class:`Family` is returned as is)."""
    if isinstance(name, Family):
        return name
    key = ALIASES.get(str(name), str(name))
    try:
        return FAMILIES[key]
    except KeyError:
        raise DataError(f"unknown model {name!r}; choose one of {', '.join(FAMILIES)}") from None


def family_table() -> list[dict]:
    """One row per family: name, version, title, parameters (for ``dischargelab models``)."""
    return [f.describe() for f in FAMILIES.values()]


__all__ = ["FAMILIES", "ALIASES", "DEFAULT_FAMILY", "Family", "Parameter", "State", "Samples",
           "get_family", "family_table"]
