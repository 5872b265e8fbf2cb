"""Cell parameters and the cell/pack voltage of the paper's model: pure numpy physics.

Sign convention (used everywhere in dischargelab): discharge current is
**positive**; ``charge_Ah`` is the charge taken out of the cell since full
charge, ``q = integral(i dt) / 3600`` [Ah].

Per cell (eq. 6 of the reference paper, Tremblay & Dessaint 2009)::

    V = E0 - R*i - K*C/(C - q) * (i_f + q) + A*exp(-B*q)

A pack of ``s`` cells in series and ``p`` strings in parallel carries the pack
current ``I`` and the pack charge ``Q``; each cell sees ``I/p`` and ``Q/p``, and
``V_pack = s * V_cell``. This module sits at the bottom of the package: it imports
only the model families; :mod:`dischargelab.model` builds the battery file on it.

References
----------
.. [1] "Measuring battery discharge characteristics for accurate UAV endurance
   estimation", eq. (6) and Tables 2-4 (see ``../shared/paper``).
.. [2] O. Tremblay, L.-A. Dessaint, "Experimental validation of a battery
   dynamic model for EV applications", World Electric Vehicle Journal 3 (2009).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .errors import DataError
from .models import DEFAULT_FAMILY, get_family

#: Parameter names of the paper's model (``shepherd``), in the order of its arrays.
PARAMETER_NAMES: tuple[str, ...] = ("E0_V", "R_ohm", "K_V_per_Ah", "A_V", "B_per_Ah", "C_Ah")

#: Parameters of the paper's model that enter the voltage linearly (for fixed B and C).
LINEAR_PARAMETERS: tuple[str, ...] = ("E0_V", "R_ohm", "K_V_per_Ah", "A_V")

#: Name of the default model family in battery files and JSON output.
MODEL_NAME = DEFAULT_FAMILY

#: Cell currents beyond this factor of the fitted range are extrapolations.
EXTRAPOLATION_FACTOR = 2.0


class CellParameters(Mapping):
    """Coefficients of a cell model: an immutable ``{name: value}`` mapping.

    Values are read as items (``p["R_ohm"]``) or attributes (``p.R_ohm``).
    Positional arguments are the paper's six parameters in
    :data:`PARAMETER_NAMES` order (``CellParameters(E0, R, K, A, B, C)``).
    Values may be numpy arrays (parameter draws); the families broadcast.
    """

    __slots__ = ("_values",)

    def __init__(self, *args, **kwargs):
        if len(args) == 1 and isinstance(args[0], Mapping) and not kwargs:
            values = dict(args[0])
        else:
            if len(args) > len(PARAMETER_NAMES):
                raise DataError(f"expected at most {len(PARAMETER_NAMES)} positional "
                                f"parameters, got {len(args)}")
            values = dict(zip(PARAMETER_NAMES, args))
            values.update(kwargs)
        object.__setattr__(self, "_values", values)

    def __getitem__(self, name):
        return self._values[name]

    def __iter__(self):
        return iter(self._values)

    def __len__(self):
        return len(self._values)

    def __getattr__(self, name):
        try:
            return object.__getattribute__(self, "_values")[name]
        except KeyError:
            raise AttributeError(name) from None

    def __setattr__(self, name, value):
        raise AttributeError("CellParameters is immutable; use .replace(...)")

    def __repr__(self):
        inner = ", ".join(f"{k}={v!r}" for k, v in self._values.items())
        return f"CellParameters({inner})"

    def __eq__(self, other):
        if not isinstance(other, Mapping):
            return NotImplemented
        return set(self) == set(other) and all(np.array_equal(self[k], other[k]) for k in self)

    __hash__ = None

    def __reduce__(self):  # pickled as its values (a worker process gets a copy)
        return (self.__class__, (dict(self._values),))

    def as_dict(self) -> dict[str, float]:
        """Parameters as ``{name: float}``."""
        return {name: float(value) for name, value in self._values.items()}

    def as_array(self, names=None) -> np.ndarray:
        """Parameters as an array in ``names`` order (default: insertion order)."""
        names = tuple(self._values) if names is None else names
        return np.array([self._values[n] for n in names], dtype=float)

    @classmethod
    def from_array(cls, values, names=PARAMETER_NAMES) -> CellParameters:
        """Build from a sequence in ``names`` order."""
        values = list(values)
        if len(values) != len(names):
            raise DataError(f"expected {len(names)} parameter values, got {len(values)}")
        return cls(dict(zip(names, values)))

    @classmethod
    def from_dict(cls, values: dict, names=PARAMETER_NAMES) -> CellParameters:
        """Build from a mapping holding at least ``names``."""
        missing = [n for n in names if n not in values]
        if missing:
            raise DataError(f"battery parameters are missing {', '.join(missing)}")
        try:
            return cls({n: float(values[n]) for n in names})
        except (TypeError, ValueError):
            raise DataError("battery parameters must be numbers") from None

    def replace(self, **changes) -> CellParameters:
        """Copy with some parameters changed."""
        values = dict(self._values)
        values.update(changes)
        return CellParameters(values)


def cell_voltage(params, current_A, charge_Ah, filtered_current_A=None):
    """Terminal voltage of one cell of the paper's model, eq. (6) of [1]_ [V].

    Kept for scripts; the model itself lives in :mod:`dischargelab.models.shepherd`.
    ``filtered_current_A`` is ``i_f`` of the polarisation term (default: the
    current). Where ``charge_Ah >= C_Ah`` the value is ``-inf``.

    References
    ----------
    .. [1] paper eq. (6); Tremblay & Dessaint (2009).
    """
    state = {"charge_Ah": charge_Ah}
    if filtered_current_A is not None:
        state["i_f_A"] = filtered_current_A
    return get_family("shepherd").voltage(params, state, current_A)


def charge_from_current(time_s, current_A, initial_charge_Ah: float = 0.0) -> np.ndarray:
    """Discharged charge [Ah] by trapezoidal integration of current [A] over time [s]."""
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    if t.shape != i.shape:
        raise DataError(f"time and current lengths differ ({t.size} vs {i.size})")
    q = np.empty_like(t)
    if t.size:
        q[0] = 0.0
        np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t), out=q[1:])
    return initial_charge_Ah + q / 3600.0


def pack_voltage(params, current_A, charge_Ah, cells_series: int = 1,
                 strings_parallel: int = 1, filtered_current_A=None):
    """Pack terminal voltage [V] of the paper's model for pack current [A] and charge [Ah].

    Each of the ``strings_parallel`` strings carries ``current_A / p``; the pack
    voltage is ``cells_series`` times the cell voltage (balanced cells, paper 2.1).
    """
    p = float(strings_parallel)
    i = np.asarray(current_A, dtype=float) / p
    i_f = None if filtered_current_A is None else np.asarray(filtered_current_A, dtype=float) / p
    return cells_series * cell_voltage(params, i, np.asarray(charge_Ah, dtype=float) / p, i_f)



#: Nominal cell voltages [V] assumed for E0 where the paper does not print it.
NOMINAL_CELL_VOLTAGE_V = {"lipo": 3.7, "li-ion": 3.6, "lifepo4": 3.3}

#: Usual per-cell cutoff voltages [V] by chemistry (discharge end of life).
CUTOFF_CELL_VOLTAGE_V = {"lipo": 3.0, "li-ion": 2.5, "lifepo4": 2.5}

