"""Battery files: a cell model of any family, its pack layout, its fit and its presets.

:class:`Battery` holds a family's parameters (:mod:`dischargelab.models`), the pack's
cells in series and strings in parallel, and what the fit recorded; it reads and writes
the battery file (JSON, atomic). The paper's presets (Tables 2-4) are built here. The
cell's equations, units and sign convention are in :mod:`dischargelab.cell` (eq. 6) and
the family files.

References
----------
.. [1] "Measuring battery discharge characteristics for accurate UAV endurance
   estimation", eq. (6) and Tables 2-4 (see ``../shared/paper``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .cell import (
    CUTOFF_CELL_VOLTAGE_V,
    EXTRAPOLATION_FACTOR,
    LINEAR_PARAMETERS,
    MODEL_NAME,
    NOMINAL_CELL_VOLTAGE_V,
    PARAMETER_NAMES,
    CellParameters,
    cell_voltage,
    charge_from_current,
    pack_voltage,
)
from .errors import DataError
from .jsonfile import read_json, write_json
from .models import DEFAULT_FAMILY, get_family


@dataclass(frozen=True)
class Battery:
    """A cell model placed in a pack, as stored in a battery file (JSON).

    Attributes
    ----------
    parameters : CellParameters
        Per-cell coefficients of the model family ``model``.
    cells_series, strings_parallel : int
        Pack configuration ``sSpP``.
    name : str
        Free text label.
    chemistry : str or None
        ``"lipo"``, ``"li-ion"``, ``"lifepo4"`` or None when unknown.
    covariance : numpy.ndarray or None
        Covariance of the parameters in the family's parameter order (zero
        rows/columns for fixed parameters), from the fit.
    fit_currents_A : tuple of float
        Cell currents [A] of the curves the model was fitted to (empty for presets).
    extra : dict
        Everything else stored in the file (fit statistics, warnings, source).
    model : str
        Model family name (see :func:`dischargelab.models.get_family`).
    """

    parameters: CellParameters
    cells_series: int = 1
    strings_parallel: int = 1
    name: str = ""
    chemistry: str | None = None
    covariance: np.ndarray | None = None
    fit_currents_A: tuple[float, ...] = ()
    extra: dict = field(default_factory=dict)
    model: str = DEFAULT_FAMILY

    @property
    def family(self):
        """The model family object."""
        return get_family(self.model)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Parameter names in the family's order."""
        return self.family.names

    @property
    def capacity_Ah(self) -> float:
        """Pack model capacity ``C * p`` [Ah]."""
        return float(self.parameters["C_Ah"]) * self.strings_parallel

    @property
    def ambient_C(self) -> float:
        """Ambient temperature of the fitted data [degC] (25 when unknown)."""
        value = self.extra.get("ambient_C")
        return 25.0 if value is None else float(value)

    @property
    def rated_capacity_Ah(self) -> float:
        """Pack capacity that defines C-rates [Ah]: the nominal capacity if known,
        else the capacity measured in the lowest-rate fitted curve, else ``C * p``."""
        for key in ("nominal_capacity_Ah", "measured_capacity_Ah"):
            value = self.extra.get(key)
            if value:
                return float(value) * self.strings_parallel
        return self.capacity_Ah

    @property
    def capacity_basis(self) -> str:
        """Where :attr:`rated_capacity_Ah` comes from, in words."""
        if self.extra.get("nominal_capacity_Ah"):
            return "the rated pack capacity"
        if self.extra.get("measured_capacity_Ah"):
            return "the pack capacity measured in the slowest fitted discharge"
        return "the pack capacity of the model"

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

    def extrapolation_ratio(self, cell_current_A: float) -> float:
        """How far a cell current [A] lies outside the fitted currents (1 = inside)."""
        fitted = [abs(x) for x in self.fit_currents_A if x]
        cell = abs(float(cell_current_A))
        if not fitted or cell == 0:
            return 1.0
        return max(1.0, cell / max(fitted), min(fitted) / cell)

    def voltage(self, current_A, charge_Ah, filtered_current_A=None, temperature_C=None):
        """Pack voltage [V] for pack current [A] and pack charge [Ah] with every other
        state at rest (lowpass states at the current, temperature at the ambient)."""
        fam = self.family
        p = self.strings_parallel
        i = np.asarray(current_A, dtype=float) / p
        state = {}
        for st in fam.states:
            if st.kind == "charge":
                state[st.name] = np.asarray(charge_Ah, dtype=float) / p
            elif st.kind == "thermal":
                state[st.name] = self.ambient_C if temperature_C is None else temperature_C
            else:
                state[st.name] = i if filtered_current_A is None else \
                    np.asarray(filtered_current_A, dtype=float) / p
        return self.cells_series * fam.voltage(self.parameters, state, i)

    def with_pack(self, cells_series: int | None = None,
                  strings_parallel: int | None = None) -> Battery:
        """Same cells in another pack configuration."""
        return replace(
            self,
            cells_series=self.cells_series if cells_series is None else int(cells_series),
            strings_parallel=self.strings_parallel if strings_parallel is None
            else int(strings_parallel),
        )

    def to_dict(self) -> dict:
        """JSON-ready dictionary (the battery file format)."""
        from ._version import __version__

        fam = self.family
        out = dict(self.extra)
        out.update({
            "model": fam.name,
            "model_version": fam.version,
            "written_by": f"dischargelab {__version__}",
            "name": self.name,
            "chemistry": self.chemistry,
            "cells_series": int(self.cells_series),
            "strings_parallel": int(self.strings_parallel),
            "parameters": {n: float(self.parameters[n]) for n in fam.names},
            "fit_currents_A": [float(x) for x in self.fit_currents_A],
        })
        if self.covariance is not None:
            out["covariance"] = {"names": list(fam.names),
                                 "matrix": np.asarray(self.covariance).tolist()}
        return out

    @classmethod
    def from_dict(cls, data: dict) -> Battery:
        """Inverse of :meth:`to_dict`; raises :class:`DataError` on a malformed file.

        Files written before model families existed (``"model": "tremblay"``) load
        as ``shepherd``.
        """
        if not isinstance(data, dict) or not isinstance(data.get("parameters"), dict):
            raise DataError("not a battery file: no 'parameters' object")
        fam = get_family(data.get("model", DEFAULT_FAMILY))
        version = data.get("model_version", 1)
        if not isinstance(version, int) or version > fam.version:
            raise DataError(f"battery file model {fam.name!r} version {version!r} is newer than "
                            f"this dischargelab understands ({fam.version}); upgrade dischargelab")
        added = {new: old for v, pairs in fam.upgrades.items() if version <= v
                 for new, old in pairs.items()}
        values = dict(data["parameters"])
        values.update({n: values[o] for n, o in added.items() if n not in values and o in values})
        params = CellParameters.from_dict(values, fam.names)
        cov = None
        if data.get("covariance"):
            cov_data = data["covariance"]
            if not isinstance(cov_data, dict) or "matrix" not in cov_data:
                raise DataError("battery file covariance must have 'names' and 'matrix'")
            names = cov_data.get("names", [n for n in fam.names if n not in added])
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise DataError("battery file covariance 'names' must be a list of parameter "
                                "names")
            try:
                cov = np.asarray(cov_data["matrix"], dtype=float)
            except (TypeError, ValueError):
                raise DataError("battery file covariance matrix is not numeric") from None
            if cov.shape != (len(names), len(names)):
                raise DataError(f"battery file covariance must be {len(names)}x{len(names)}, "
                                f"got {cov.shape}")
            # an older file's parameter that equalled another: the same row and column
            source = [names.index(n) if n in names else
                      names.index(added[n]) if added.get(n) in names else -1 for n in fam.names]
            if len(set(names)) != len(names) or not set(names) <= set(fam.names) \
                    or min(source) < 0:
                raise DataError("battery file covariance has unexpected parameter names")
            cov = cov[np.ix_(source, source)]
        known = {"model", "model_version", "written_by", "name", "chemistry", "cells_series",
                 "strings_parallel", "parameters", "fit_currents_A", "covariance"}
        try:
            cells = int(data.get("cells_series", 1))
            strings = int(data.get("strings_parallel", 1))
            currents = tuple(float(x) for x in data.get("fit_currents_A", ()))
        except (TypeError, ValueError):
            raise DataError("battery file pack fields (cells_series, strings_parallel, "
                            "fit_currents_A) must be numbers") from None
        if cells < 1 or strings < 1:
            raise DataError("battery file cells_series and strings_parallel must be >= 1")
        return cls(
            parameters=params, cells_series=cells, strings_parallel=strings,
            name=str(data.get("name", "")), chemistry=data.get("chemistry"), covariance=cov,
            fit_currents_A=currents, extra={k: v for k, v in data.items() if k not in known},
            model=fam.name,
        )

    def save(self, path) -> Path:
        """Write the battery file (JSON, atomically); returns the path."""
        return write_json(path, self.to_dict())

    def predict(self, *, current=None, c_rate=None, power=None, cutoff=None, cutoff_pack=None,
                soc=100.0, ambient=None):
        """Constant-current or constant-power discharge with its 95 % interval
        (see :func:`dischargelab.predict.predict`)."""
        from .predict import predict

        return predict(self, current=current, c_rate=c_rate, power=power, cutoff=cutoff,
                       cutoff_pack=cutoff_pack, soc=soc, ambient=ambient)


def load_battery(source) -> Battery:
    """Load a battery from a battery file path or a preset name (see :data:`PRESETS`);
    an object with ``to_battery()`` (a logbook pack: its model at today's health) gives
    what that returns."""
    if isinstance(source, Battery):
        return source
    as_battery = getattr(source, "to_battery", None)
    if callable(as_battery):
        return as_battery()
    text = str(source)
    if text in PRESETS:
        return PRESETS[text]
    data = read_json(text, f"battery file {text!r} not found (and not a preset: "
                           f"{', '.join(sorted(PRESETS))})")
    return Battery.from_dict(data)



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
        row["model"] = bat.model
        row.update(bat.parameters.as_dict())
        rows.append(row)
    return rows


__all__ = [
    "PARAMETER_NAMES", "LINEAR_PARAMETERS", "MODEL_NAME", "CellParameters", "Battery",
    "cell_voltage", "charge_from_current", "pack_voltage",
    "load_battery", "PRESETS", "NOMINAL_CELL_VOLTAGE_V", "CUTOFF_CELL_VOLTAGE_V",
    "preset_table",
]
