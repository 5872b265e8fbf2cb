"""dischargelab: from a battery discharge test to a battery model and a UAV endurance estimate.

Light on import: matplotlib, pyserial and other optional dependencies are only
imported by the functions that need them.
"""

from .errors import DataError, DischargelabError, FitError, SimulationError
from .model import PARAMETER_NAMES, PRESETS, Battery, CellParameters, cell_voltage, load_battery

__version__ = "0.1.0"

__all__ = [
    "Battery", "CellParameters", "PARAMETER_NAMES", "PRESETS", "cell_voltage", "load_battery",
    "DataError", "DischargelabError", "FitError", "SimulationError",
    "__version__",
]
