"""dischargelab: from a battery discharge test to a battery model and a UAV endurance estimate.

Light on import: matplotlib, pyserial and other optional dependencies are only
imported by the functions that need them.
"""


# The submodules named like API functions are loaded first, so that the functions
# bound below are what ``dischargelab.fit`` / ``.validate`` / ``.predict`` mean.
from . import fit as _fit_module, predict as _predict_module, validate as _validate_module  # noqa: F401, I001
from .api import endurance, fit, load, predict, read, validate
from .discharge import Discharge
from .errors import DataError, DischargelabError, FitError, LogbookError, SimulationError
from .logbook import Logbook
from .model import (
    PARAMETER_NAMES, PRESETS, Battery, CellParameters, cell_voltage, load_battery,
)
from ._version import __version__
from .models import FAMILIES
from .predict import Prediction

__all__ = [
    "read", "fit", "load", "predict", "endurance", "validate", "Discharge", "Battery",
    "Prediction", "CellParameters", "FAMILIES", "PARAMETER_NAMES", "PRESETS", "cell_voltage",
    "load_battery", "Logbook", "DataError", "DischargelabError", "FitError", "LogbookError",
    "SimulationError",
    "__version__",
]
