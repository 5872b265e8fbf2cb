"""Modified Shepherd (Tremblay) battery model: pure, vectorised numpy physics.

Sign convention (used everywhere in dischargelab): discharge current is
**positive**; ``charge_Ah`` is the charge taken out of the cell since full
charge, ``q = integral(i dt) / 3600`` [Ah].

Per cell (eq. 6 of the reference paper, Tremblay & Dessaint 2009)::

    V = E0 - R*i - K*C/(C - q) * (i_f + q) + A*exp(-B*q)

A pack of ``s`` cells in series and ``p`` strings in parallel carries the pack
current ``I`` and the pack charge ``Q``; each cell sees ``I/p`` and ``Q/p``, and
``V_pack = s * V_cell``.

References
----------
.. [1] "Measuring battery discharge characteristics for accurate UAV endurance
   estimation", eq. (6) and Tables 2-4 (see ``../shared/paper``).
.. [2] O. Tremblay, L.-A. Dessaint, "Experimental validation of a battery
   dynamic model for EV applications", World Electric Vehicle Journal 3 (2009).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .errors import DataError
from .jsonfile import read_json, write_json

#: Canonical parameter names, in the order used by every array and matrix.
PARAMETER_NAMES: tuple[str, ...] = ("E0_V", "R_ohm", "K_V_per_Ah", "A_V", "B_per_Ah", "C_Ah")

#: Parameters that enter the model linearly (for fixed B and C).
LINEAR_PARAMETERS: tuple[str, ...] = ("E0_V", "R_ohm", "K_V_per_Ah", "A_V")

#: Name of the model in battery files and JSON output.
MODEL_NAME = "tremblay"

#: Cell currents beyond this factor of the fitted range are extrapolations.
EXTRAPOLATION_FACTOR = 2.0


@dataclass(frozen=True)
class CellParameters:
    """Coefficients of the modified Shepherd model for ONE cell.

    Attributes
    ----------
    E0_V : battery constant voltage [V]
    R_ohm : internal resistance [ohm]
    K_V_per_Ah : polarisation constant [V/Ah]
    A_V : exponential zone amplitude [V]
    B_per_Ah : exponential zone time constant inverse [1/Ah]
    C_Ah : maximum capacity [Ah]

    Each field may also be a numpy array (e.g. samples for uncertainty
    propagation); all functions below broadcast.
    """

    E0_V: float
    R_ohm: float
    K_V_per_Ah: float
    A_V: float
    B_per_Ah: float
    C_Ah: float

    def as_dict(self) -> dict[str, float]:
        """Parameters as ``{name: float}`` in :data:`PARAMETER_NAMES` order."""
        return {name: float(getattr(self, name)) for name in PARAMETER_NAMES}

    def as_array(self) -> np.ndarray:
        """Parameters as an array in :data:`PARAMETER_NAMES` order."""
        return np.array([getattr(self, name) for name in PARAMETER_NAMES], dtype=float)

    @classmethod
    def from_array(cls, values) -> "CellParameters":
        """Build from a sequence in :data:`PARAMETER_NAMES` order."""
        values = list(values)
        if len(values) != len(PARAMETER_NAMES):
            raise DataError(f"expected {len(PARAMETER_NAMES)} parameter values, got {len(values)}")
        return cls(*values)

    @classmethod
    def from_dict(cls, values: dict) -> "CellParameters":
        """Build from a mapping with exactly the canonical keys."""
        missing = [n for n in PARAMETER_NAMES if n not in values]
        if missing:
            raise DataError(f"battery parameters are missing {', '.join(missing)}")
        return cls(**{n: float(values[n]) for n in PARAMETER_NAMES})

    def replace(self, **changes) -> "CellParameters":
        """Copy with some parameters changed."""
        return replace(self, **changes)


def cell_voltage(params: CellParameters, current_A, charge_Ah, filtered_current_A=None):
    """Terminal voltage of one cell, eq. (6) of [1]_.

    Parameters
    ----------
    params : CellParameters
    current_A : array_like
        Cell current [A], discharge positive.
    charge_Ah : array_like
        Charge removed since full charge [Ah].
    filtered_current_A : array_like, optional
        Filtered current ``i_f`` [A] of the polarisation-resistance term;
        defaults to ``current_A`` (the paper's simplification).

    Returns
    -------
    numpy.ndarray
        Voltage [V]. Where ``charge_Ah >= C_Ah`` the model is undefined and the
        value is ``-inf`` (the limit as ``q -> C`` from below).

    References
    ----------
    .. [1] paper eq. (6); Tremblay & Dessaint (2009).
    """
    i = np.asarray(current_A, dtype=float)
    q = np.asarray(charge_Ah, dtype=float)
    i_f = i if filtered_current_A is None else np.asarray(filtered_current_A, dtype=float)
    C = np.asarray(params.C_Ah, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        gain = C / (C - q)
        v = (
            params.E0_V
            - params.R_ohm * i
            - params.K_V_per_Ah * gain * (i_f + q)
            + params.A_V * np.exp(-params.B_per_Ah * q)
        )
    return np.where(q < C, v, -np.inf)


def voltage_jacobian(params: CellParameters, current_A, charge_Ah, filtered_current_A=None):
    """Partial derivatives of :func:`cell_voltage` with respect to each parameter.

    Returns
    -------
    numpy.ndarray, shape (n, 6)
        Columns in :data:`PARAMETER_NAMES` order: dV/dE0 [-], dV/dR [A],
        dV/dK [Ah], dV/dA [-], dV/dB [V Ah], dV/dC [V/Ah]. Only valid where
        ``charge_Ah < C_Ah``.
    """
    i = np.asarray(current_A, dtype=float)
    q = np.asarray(charge_Ah, dtype=float)
    i_f = i if filtered_current_A is None else np.asarray(filtered_current_A, dtype=float)
    i, q, i_f = np.broadcast_arrays(i, q, i_f)
    C, K = params.C_Ah, params.K_V_per_Ah
    denom = C - q
    gain = C / denom
    pol = i_f + q
    expo = np.exp(-params.B_per_Ah * q)
    jac = np.empty(q.shape + (6,))
    jac[..., 0] = 1.0
    jac[..., 1] = -i
    jac[..., 2] = -gain * pol
    jac[..., 3] = expo
    jac[..., 4] = -params.A_V * q * expo
    jac[..., 5] = K * q * pol / denom**2  # d/dC [C/(C-q)] = -q/(C-q)^2
    return jac


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


def pack_voltage(params: CellParameters, current_A, charge_Ah, cells_series: int = 1,
                 strings_parallel: int = 1, filtered_current_A=None):
    """Pack terminal voltage [V] for pack current [A] and pack charge [Ah].

    Each of the ``strings_parallel`` strings carries ``current_A / p``; the pack
    voltage is ``cells_series`` times the cell voltage (balanced cells, [1]_ 2.1).
    """
    p = float(strings_parallel)
    i_f = None if filtered_current_A is None else np.asarray(filtered_current_A, dtype=float) / p
    return cells_series * cell_voltage(
        params, np.asarray(current_A, dtype=float) / p, np.asarray(charge_Ah, dtype=float) / p, i_f
    )


@dataclass(frozen=True)
class Battery:
    """A cell model placed in a pack, as stored in a battery file (JSON).

    Attributes
    ----------
    parameters : CellParameters
        Per-cell coefficients.
    cells_series, strings_parallel : int
        Pack configuration ``sSpP``.
    name : str
        Free text label.
    chemistry : str or None
        ``"lipo"``, ``"li-ion"``, ``"lifepo4"`` or None when unknown.
    covariance : numpy.ndarray or None
        6x6 covariance of the parameters in :data:`PARAMETER_NAMES` order
        (zero rows/columns for fixed parameters), from the fit.
    fit_currents_A : tuple of float
        Cell currents [A] of the curves the model was fitted to (empty for presets).
    extra : dict
        Everything else stored in the file (fit statistics, warnings, source).
    """

    parameters: CellParameters
    cells_series: int = 1
    strings_parallel: int = 1
    name: str = ""
    chemistry: str | None = None
    covariance: np.ndarray | None = None
    fit_currents_A: tuple[float, ...] = ()
    extra: dict = field(default_factory=dict)

    @property
    def capacity_Ah(self) -> float:
        """Pack model capacity ``C * p`` [Ah]."""
        return float(self.parameters.C_Ah) * self.strings_parallel

    @property
    def rated_capacity_Ah(self) -> float:
        """Pack capacity that defines C-rates [Ah]: the nominal capacity if known,
        else the capacity measured in the lowest-rate fitted curve, else ``C * p``."""
        for key in ("nominal_capacity_Ah", "measured_capacity_Ah"):
            value = self.extra.get(key)
            if value:
                return float(value) * self.strings_parallel
        return self.capacity_Ah

    def extrapolation(self, cell_current_A: float) -> str | None:
        """"above" / "below" when a cell current [A] lies far outside the fitted currents.

        Far means more than :data:`EXTRAPOLATION_FACTOR` times the highest or less
        than the lowest divided by it (paper 4.4: accuracy falls away from the
        fitted rate). None inside the range or when no fit currents are known.
        """
        fitted = [abs(x) for x in self.fit_currents_A if x]
        cell = abs(float(cell_current_A))
        if not fitted or cell == 0:
            return None
        if cell > EXTRAPOLATION_FACTOR * max(fitted):
            return "above"
        if cell < min(fitted) / EXTRAPOLATION_FACTOR:
            return "below"
        return None

    def voltage(self, current_A, charge_Ah, filtered_current_A=None):
        """Pack voltage [V] for pack current [A] and pack charge [Ah]."""
        return pack_voltage(self.parameters, current_A, charge_Ah, self.cells_series,
                            self.strings_parallel, filtered_current_A)

    def with_pack(self, cells_series: int | None = None,
                  strings_parallel: int | None = None) -> "Battery":
        """Same cells in another pack configuration."""
        return replace(
            self,
            cells_series=self.cells_series if cells_series is None else int(cells_series),
            strings_parallel=self.strings_parallel if strings_parallel is None
            else int(strings_parallel),
        )

    def to_dict(self) -> dict:
        """JSON-ready dictionary (the battery file format)."""
        out = dict(self.extra)
        out.update({
            "model": MODEL_NAME,
            "name": self.name,
            "chemistry": self.chemistry,
            "cells_series": int(self.cells_series),
            "strings_parallel": int(self.strings_parallel),
            "parameters": self.parameters.as_dict(),
            "fit_currents_A": [float(x) for x in self.fit_currents_A],
        })
        if self.covariance is not None:
            out["covariance"] = {"names": list(PARAMETER_NAMES),
                                 "matrix": np.asarray(self.covariance).tolist()}
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "Battery":
        """Inverse of :meth:`to_dict`; raises :class:`DataError` on a malformed file."""
        if not isinstance(data, dict) or "parameters" not in data:
            raise DataError("not a battery file: no 'parameters' object")
        model = data.get("model", MODEL_NAME)
        if model != MODEL_NAME:
            raise DataError(f"battery file model is {model!r}; only {MODEL_NAME!r} is supported")
        cov = None
        if data.get("covariance"):
            names = data["covariance"].get("names", list(PARAMETER_NAMES))
            if list(names) != list(PARAMETER_NAMES):
                raise DataError("battery file covariance has unexpected parameter names")
            cov = np.asarray(data["covariance"]["matrix"], dtype=float)
            if cov.shape != (6, 6):
                raise DataError(f"battery file covariance must be 6x6, got {cov.shape}")
        known = {"model", "name", "chemistry", "cells_series", "strings_parallel",
                 "parameters", "fit_currents_A", "covariance"}
        return cls(
            parameters=CellParameters.from_dict(data["parameters"]),
            cells_series=int(data.get("cells_series", 1)),
            strings_parallel=int(data.get("strings_parallel", 1)),
            name=str(data.get("name", "")),
            chemistry=data.get("chemistry"),
            covariance=cov,
            fit_currents_A=tuple(float(x) for x in data.get("fit_currents_A", ())),
            extra={k: v for k, v in data.items() if k not in known},
        )

    def save(self, path) -> Path:
        """Write the battery file (JSON, atomically); returns the path."""
        return write_json(path, self.to_dict())


def load_battery(source) -> Battery:
    """Load a battery from a battery file path or a preset name (see :data:`PRESETS`)."""
    if isinstance(source, Battery):
        return source
    text = str(source)
    if text in PRESETS:
        return PRESETS[text]
    data = read_json(text, f"battery file {text!r} not found (and not a preset: "
                           f"{', '.join(sorted(PRESETS))})")
    return Battery.from_dict(data)


#: Nominal cell voltages [V] assumed for E0 where the paper does not print it.
NOMINAL_CELL_VOLTAGE_V = {"lipo": 3.7, "li-ion": 3.6, "lifepo4": 3.3}

#: Usual per-cell cutoff voltages [V] by chemistry (discharge end of life).
CUTOFF_CELL_VOLTAGE_V = {"lipo": 3.0, "li-ion": 2.5, "lifepo4": 2.5}


def _paper_preset(name, chemistry, cells, R, K, A, B, C, current, nominal_Ah, table):
    return Battery(
        parameters=CellParameters(NOMINAL_CELL_VOLTAGE_V[chemistry], R, K, A, B, C),
        cells_series=cells,
        name=name,
        chemistry=chemistry,
        fit_currents_A=(current,),
        extra={"nominal_capacity_Ah": nominal_Ah, "source": {
            "reference": f"paper Table {table}",
            "note": "E0 is not printed in the paper; assumed equal to the nominal cell voltage "
                    f"({NOMINAL_CELL_VOLTAGE_V[chemistry]} V for {chemistry}).",
        }},
    )


#: The paper's fitted coefficients (Tables 2-4), per cell. E0 is ASSUMED: the
#: paper gives it as an input but does not print it; we use the nominal cell
#: voltage of the chemistry (3.7 V LiPo, 3.3 V LiFePO4). The fit currents are the
#: paper's measured test currents.
PRESETS: dict[str, Battery] = {
    "zippy-1100-2s": _paper_preset("Zippy 1100mAh 2S LiPo", "lipo", 2,
                                   0.0373, 0.0115, 0.0807, 2.88, 1.075, 0.6, 1.1, 2),
    "nanotech-1700-2s": _paper_preset("Turnigy Nano-Tech 1700mAh 2S LiPo", "lipo", 2,
                                      0.0187, 0.0152, 0.2491, 0.0888, 1.7720, 1.7, 1.7, 3),
    "hacker-4100-4s-lifepo4": _paper_preset("Hacker TopFuel 4100mAh 4S LiFePO4", "lifepo4", 4,
                                            0.0047, 0.0003, 0.0936, 10.0354, 3.9746, 50.0, 4.1,
                                            4),
}


def preset_table() -> list[dict]:
    """Presets as rows (name, chemistry, pack, parameters) for display."""
    rows = []
    for key, bat in PRESETS.items():
        row = {"preset": key, "name": bat.name, "chemistry": bat.chemistry,
               "cells_series": bat.cells_series}
        row.update(bat.parameters.as_dict())
        rows.append(row)
    return rows


__all__ = [
    "PARAMETER_NAMES", "LINEAR_PARAMETERS", "MODEL_NAME", "CellParameters", "Battery",
    "cell_voltage", "voltage_jacobian", "charge_from_current", "pack_voltage",
    "load_battery", "PRESETS", "NOMINAL_CELL_VOLTAGE_V", "CUTOFF_CELL_VOLTAGE_V",
    "preset_table",
]
