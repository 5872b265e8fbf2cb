"""The result of a fit: :class:`FitResult` (parameters, intervals, warnings,
``.predict()``, ``.save()``, ``.report()``, ``.plot()``)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..cell import CellParameters
from ..discharge import Curve
from ..identifiability import Identifiability
from ..model import Battery
from ..models import Family, get_family
from .problem import CURRENT_SCALE, _stack

#: Current spread (coefficient of variation) up to which a curve counts as one
#: constant-current discharge for :func:`plateau_ratio`.
CONSTANT_CURRENT_CV = 0.25

#: Fitted runs whose last voltages per cell lie within this [V] stopped at one cutoff (a
#: tester's or logger's lower voltage limit): the battery file records it as
#: ``tested_cutoff_cell_V``, the cutoff used when none is given and the chemistry is unknown.
TESTED_CUTOFF_SPREAD_V = 0.02


def plateau_ratio(curve: Curve) -> float | None:
    """How flat a constant-current discharge is [-]: the voltage drop over the middle
    60 % of its delivered charge (20 % to 80 %) divided by the drop from its first to
    its last sample. About 0.3-0.4 for NMC and LCO cells, 0.1 for LiFePO4's plateau;
    None for a curve whose current varies (a flight) or that has no drop."""
    i = curve.current_A
    if i.size < 10 or not np.mean(i) > 0 or np.std(i) > CONSTANT_CURRENT_CV * np.mean(i):
        return None
    q = curve.charge_Ah
    v = curve.voltage_V
    drop = float(v[0] - v[-1])
    if not drop > 0 or not q[-1] > 0:
        return None
    v20, v80 = np.interp([0.2 * q[-1], 0.8 * q[-1]], q, v)
    return float(np.clip((v20 - v80) / drop, 0.0, 1.0))


@dataclass
class FitResult:
    """Outcome of :func:`fit_battery` (values, errors, diagnostics, data)."""

    #: Fitted per-cell parameters of the family :attr:`model` (names carry their units).
    parameters: CellParameters
    #: Standard error of each free parameter (same units).
    stderr: dict
    #: 95 % interval ``(low, high)`` of each free parameter.
    ci95: dict
    #: Covariance of the free parameters, in the order of :attr:`free`.
    covariance: np.ndarray
    #: Correlation of the free parameters, in the order of :attr:`free`.
    correlation: np.ndarray
    #: Names of the fitted parameters.
    free: list
    #: Parameters held fixed: ``{name: value}``.
    fixed: dict
    #: Bounds of the fit: ``{name: (low, high)}``.
    bounds: dict
    #: Root-mean-square voltage residual per cell [V].
    rmse_V: float
    #: Samples fitted.
    n_samples: int
    #: What to worry about, each with its fix, in plain words.
    warnings: list
    #: What the fit did and chose, in plain words.
    notes: list
    identifiability: Identifiability
    curves: list
    cells_series: int
    strings_parallel: int
    current_scale: float
    paper_mode: bool
    elapsed_s: float
    nfev: int
    n_starts: int
    bootstrap: np.ndarray | None = None
    #: The model family fitted (``"shepherd"``, ``"shepherd-thermal"``, ``"ecm"``).
    model: str = "shepherd"
    ambient_C: float = 25.0
    thermal: dict | None = None
    #: The held-out error of the time to cutoff that widens every prediction's interval.
    model_error: dict | None = None
    implausible: list = field(default_factory=list)
    #: The thermal prior of a thermal family fitted without a logged temperature
    #: (:mod:`dischargelab.fit.selfheating`), else None.
    thermal_prior: dict | None = None

    @property
    def physical(self) -> bool:
        """True when no parameter sits at a bound and no value is physically implausible."""
        return not self.identifiability.at_bounds and not self.implausible

    @property
    def family(self) -> Family:
        """The fitted model family."""
        return get_family(self.model)

    # ---- derived ---------------------------------------------------------------
    @property
    def fit_currents_A(self) -> tuple[float, ...]:
        """Mean cell current of each fitted curve [A] (times the scale in paper mode)."""
        return tuple(c.mean_current_A / self.strings_parallel * self.current_scale
                     for c in self.curves)

    def predicted_voltage(self, curve: Curve) -> np.ndarray:
        """Model pack voltage [V] at the samples of ``curve`` (paper mode: fitted current;
        thermal families at the curve's logged temperature)."""
        data = _stack([curve], self.cells_series, self.strings_parallel, use_rest=False,
                      weighting="samples", max_samples=curve.time_s.size)
        if self.current_scale != 1.0:
            data.current = data.current * self.current_scale
            data.charge = data.charge * self.current_scale
        with np.errstate(invalid="ignore", over="ignore"):
            return self.cells_series * self.family.fit_voltage(self.parameters, data)

    @property
    def battery(self) -> Battery:
        """The fitted battery (pack configuration as fitted) with covariance."""
        extra = {k: v for k, v in self._document(advice=False).items()
                 if k not in ("parameters", "cells_series", "strings_parallel",
                              "fit_currents_A", "model")}
        # where each curve came from; a tester file's list of every step stays in the file
        extra["source"] = [dict({k: v for k, v in c.meta.items() if k != "steps"}, name=c.name)
                           for c in self.curves]
        capacities = [float(c.charge_Ah[-1]) / self.strings_parallel for c in self.curves]
        lowest = int(np.argmin([abs(x) for x in self.fit_currents_A]))
        extra["measured_capacity_Ah"] = capacities[lowest]
        extra["ambient_C"] = self.ambient_C
        rises = [float(np.max(c.temperature_C) - c.temperature_C[0]) for c in self.curves
                 if c.temperature_C is not None]
        if rises:
            extra["fit_temperature_rise_K"] = max(rises)
        if self.thermal_prior is not None:
            extra["thermal_prior"] = dict(self.thermal_prior)
        ends = [float(c.voltage_V[-1]) / self.cells_series for c in self.curves]
        flown = any("flight" in (c.meta or {}) for c in self.curves)  # a flight ends landed
        if not flown and max(ends) - min(ends) <= TESTED_CUTOFF_SPREAD_V:  # one stop voltage
            extra["tested_cutoff_cell_V"] = round(float(np.median(ends)), 3)
        plateau = plateau_ratio(self.curves[lowest])
        if plateau is not None:
            extra["fit_plateau_ratio"] = plateau
        if self.bootstrap is not None:
            extra["bootstrap"] = {"names": list(self.family.names),
                                  "samples": np.round(self.bootstrap, 12).tolist()}
        return Battery(self.parameters, self.cells_series, self.strings_parallel,
                       covariance=self.covariance, fit_currents_A=self.fit_currents_A,
                       extra=extra, model=self.model)

    @property
    def next_test(self) -> dict | None:
        """After a one-rate fit: the one more run that would narrow its predictions most
        (:func:`dischargelab.nexttest.fit_next_test`), else None."""
        from ..nexttest import fit_next_test

        return None if self.paper_mode else fit_next_test(self.battery)

    def to_dict(self) -> dict:
        """The ``fit --json`` document (keys are only ever added, never renamed)."""
        return self._document(advice=True)

    def _document(self, advice: bool) -> dict:
        names = self.family.names
        out = {
            "model": self.model,
            "cells_series": self.cells_series,
            "strings_parallel": self.strings_parallel,
            "parameters": self.parameters.as_dict(),
            "units": {p.name: p.unit for p in self.family.parameters},
            "stderr": {n: self.stderr[n] for n in names},
            "ci95": {n: list(self.ci95[n]) for n in names},
            "fixed": {n: v for n, v in self.fixed.items() if n != CURRENT_SCALE
                      or self.paper_mode},
            "rmse_V": self.rmse_V,
            "rmse_pack_V": self.rmse_V * self.cells_series,
            "n_samples": self.n_samples,
            "n_curves": len(self.curves),
            "fit_currents_A": list(self.fit_currents_A),
            "warnings": list(self.warnings),
            "notes": list(self.notes),
            "identifiability": self.identifiability.to_dict(),
            "fit_time_s": self.elapsed_s,
            "ambient_C": self.ambient_C,
        }
        if self.thermal is not None:
            out["thermal"] = dict(self.thermal)
        if self.model_error is not None:
            out["model_error"] = dict(self.model_error)
        if advice and self.next_test is not None:
            out["next_test"] = self.next_test
        if self.paper_mode:
            out["paper_mode"] = {
                "current_scale": self.current_scale,
                "fitted_currents_A": list(self.fit_currents_A),
                "measured_currents_A": [c.mean_current_A / self.strings_parallel
                                        for c in self.curves],
            }
        return out

    def predict(self, **load):
        """Predict a discharge with the fitted battery (see :meth:`Battery.predict`)."""
        return self.battery.predict(**load)

    def save(self, path, *, name: str = "", chemistry: str | None = None):
        """Write the battery file (JSON, atomically); returns the path."""
        from dataclasses import replace as _replace

        bat = self.battery
        bat = _replace(bat, name=name or ", ".join(c.name for c in self.curves),
                       chemistry=chemistry or bat.chemistry)
        return bat.save(path)

    def report(self) -> str:
        """Plain-text summary: parameters with 95 % intervals, RMSE, warnings."""
        lines = [f"{self.family.title} [{self.model}], per cell ({self.cells_series}S"
                 f"{self.strings_parallel}P pack), {len(self.curves)} curve(s), "
                 f"{self.n_samples} samples"]
        for n in self.family.names:
            value = self.parameters[n]
            if n in self.fixed:
                lines.append(f"  {n:12s} {value:12.6g}   (fixed)")
            else:
                lo, hi = self.ci95[n]
                lines.append(f"  {n:12s} {value:12.6g}   +/- {self.stderr[n]:.3g}   "
                             f"95% [{lo:.6g}, {hi:.6g}]")
        if self.paper_mode:
            lines.append(f"  fitted current scale {self.current_scale:.4f} "
                         f"(fitted/measured current)")
        if self.thermal is not None:
            lines.append(f"  thermal: heat capacity {self.thermal['Cth_J_per_K']:.3g} J/K, "
                         f"thermal resistance {self.thermal['Rth_K_per_W']:.3g} K/W "
                         f"({self.thermal['source']})")
        lines.append(f"  RMSE {self.rmse_V * 1000:.2f} mV per cell "
                     f"({self.rmse_V * self.cells_series * 1000:.1f} mV pack)")
        lines += [f"  note: {m}" for m in self.notes]
        lines += [f"  warning: {m}" for m in self.warnings]
        advice = self.next_test
        if advice is not None:
            lines.append(f"  {advice['text']}")
        return "\n".join(lines)

    def plot(self, ax=None, **kwargs):
        """Measured vs fitted voltage with residuals; returns the main Axes."""
        from ..plot import plot_fit

        return plot_fit(self, ax=ax, **kwargs)
