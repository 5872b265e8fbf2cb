"""dischargelab: from a battery discharge test to a battery model and a UAV endurance estimate.

Light on import: ``import dischargelab`` loads only the error classes; the API below
(numpy, pandas, scipy) is loaded on first use of any of its names, and matplotlib,
pyserial and other optional dependencies only by the functions that need them. A
command line that needs none of it (``--help``, a cluster's start) answers at once.
"""

import sys as _sys
import types as _types
from typing import TYPE_CHECKING

from ._version import __version__
from .errors import DataError, DischargelabError, FitError, LogbookError, SimulationError

if TYPE_CHECKING:
    from .api import endurance, fit, load, predict, read, validate
    from .autopilot import autopilot_params
    from .discharge import Discharge
    from .logbook import Logbook
    from .model import (
        PARAMETER_NAMES,
        PRESETS,
        Battery,
        CellParameters,
        cell_voltage,
        load_battery,
    )
    from .models import FAMILIES
    from .onboard import autopilot_script
    from .predict import Prediction

__all__ = [
    "read", "fit", "load", "predict", "endurance", "validate", "Discharge", "Battery",
    "Prediction", "CellParameters", "FAMILIES", "PARAMETER_NAMES", "PRESETS", "cell_voltage",
    "load_battery", "autopilot_params", "autopilot_script", "Logbook", "DataError",
    "DischargelabError", "FitError", "LogbookError",
    "SimulationError",
    "__version__",
]

#: Where each name of the API lives (its module, relative to the package); all are loaded
#: together on first use of any (:func:`__getattr__`).
_API = {
    **dict.fromkeys(("read", "fit", "load", "predict", "endurance", "validate"), "api"),
    **dict.fromkeys(("Battery", "CellParameters", "PARAMETER_NAMES", "PRESETS", "cell_voltage",
                     "load_battery"), "model"),
    "Discharge": "discharge", "Logbook": "logbook", "FAMILIES": "models",
    "Prediction": "predict", "autopilot_params": "api", "autopilot_script": "api",
}

#: Names of the API that are also submodules' names: the package's attribute is always the
#: function (``dischargelab.fit(...)``); the submodules are imported by their full name.
_SHADOWED = frozenset({"fit", "predict", "validate"})


def _load_api() -> None:
    import importlib

    globals().update({name: getattr(importlib.import_module(f".{module}", __name__), name)
                      for name, module in _API.items()})


def __getattr__(name: str):
    if name in _API:
        _load_api()
        return globals()[name]
    raise AttributeError(f"module 'dischargelab' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))


class _Package(_types.ModuleType):
    """The package's module: importing the submodule ``dischargelab.fit`` (or ``.predict``,
    ``.validate``) does not replace the API function of the same name."""

    def __setattr__(self, name: str, value) -> None:
        if name in _SHADOWED and isinstance(value, _types.ModuleType):
            return      # the submodule stays in sys.modules under its full name
        super().__setattr__(name, value)


_package = _sys.modules[__name__]
_package.__class__ = _Package
