"""Fit any model family to one or several measured discharges.

Method
------
Bounded nonlinear least squares on the cell voltage, eq. (8) of the paper,
solved by **variable projection** over the family's parameters: for fixed
nonlinear parameters (for ``shepherd`` B, C and, in paper mode, a current scale)
the voltage is linear in the family's linear parameters (E0, R, K, A), which are
eliminated by a linear least-squares solve (bounded where a bound binds); the
reduced problem is solved by projected Levenberg-Marquardt with Kaufman's
analytic Jacobian from a small grid of starts. A final bounded ``least_squares``
polish over all free parameters (analytic Jacobian) enforces the bounds on the
linear parameters when the projected solution violates them. Families with a
thermal state get their heat capacity and thermal resistance from the logged
cell temperature afterwards (a linear regression, see
:func:`dischargelab.models.base.fit_lumped_thermal`).

Identifiability (see DESIGN.md and :mod:`dischargelab.identifiability`):

* one constant current: only ``E0 - R*i`` is determined. A rest sample before
  the load (i = 0) separates them: the fit then uses it as a data point
  (``V_rest = E0 + A``, so the load step gives ``R + K``). Without a rest sample,
  a given E0 or a second current, R is fixed to 0 and a warning says so.
* with the current free (paper mode) R, K, B, C and i scale together: the fit
  still runs (to reproduce the paper) and the warning says the curve alone
  cannot determine C.

Standard errors come from the Jacobian at the optimum, ``cov = s^2 (J^T J)^-1``,
with ``s^2`` the residual variance inflated for the serial correlation of the
residuals (AR(1) effective sample size ``n (1 - rho) / (1 + rho)``): residuals of
a model fit to a smooth curve are far from independent, and ignoring that would
give error bars that are too small.

References
----------
.. [1] paper eq. (6), (8), section 3.4 (see ``../shared/paper``).
.. [2] G. Golub, V. Pereyra, "Separable nonlinear least squares: the variable
   projection method and its applications", Inverse Problems 19 (2003) R1.
.. [3] L. Kaufman, "A variable projection method for solving separable nonlinear
   least squares problems", BIT 15 (1975) 49-57.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.special import stdtrit

from .errors import DataError, FitError
from .identifiability import Identifiability, analyse, equilibrated_svd, plausibility, undetermined
from .model import Battery, CellParameters, charge_from_current
from .models import Family, Samples, get_family
from .models.base import HELD_AT_AMBIENT_HEAT_CAPACITY, MIN_HEATING_K, fit_lumped_thermal

#: Name of the current-scale parameter fitted in paper mode.
CURRENT_SCALE = "current_scale"

#: Bounds of the fitted/measured current ratio in paper mode (the paper's fits
#: came within 2.5-5 % of the measured current). C is bounded below by the
#: largest charge times the upper bound.
PAPER_CURRENT_SCALE_BOUNDS = (0.9, 1.1)


@dataclass
class Curve:
    """One measured discharge at pack level (discharge current positive).

    Parameters
    ----------
    time_s, voltage_V, current_A : array_like
        Samples [s], [V], [A] from load start.
    name : str
        Label used in plots and tables (file name, rate).
    temperature_C : array_like or None
        Logged cell temperature [degC] at the same samples, when measured.
    initial_charge_Ah : float
        Pack charge already removed before the first sample [Ah] (0 = the curve
        starts full; a flight that starts part-discharged has more).
    rest_voltage_V : float or None
        Pack voltage at rest (i = 0) just before the load step, at full charge of
        this curve; separates E0 from R when present.
    meta : dict
        Source metadata (file, format, ...).
    """

    time_s: np.ndarray
    voltage_V: np.ndarray
    current_A: np.ndarray
    name: str = ""
    rest_voltage_V: float | None = None
    meta: dict = field(default_factory=dict)
    temperature_C: np.ndarray | None = None
    initial_charge_Ah: float = 0.0

    def __post_init__(self):
        self.time_s = np.asarray(self.time_s, dtype=float)
        self.voltage_V = np.asarray(self.voltage_V, dtype=float)
        current = np.asarray(self.current_A, dtype=float)
        if current.ndim == 0:
            current = np.full(self.time_s.shape, float(current))
        self.current_A = current
        label = f"curve {self.name!r}" if self.name else "curve"
        if not (self.time_s.shape == self.voltage_V.shape == self.current_A.shape):
            raise DataError(f"{label}: time, voltage and current lengths differ "
                            f"({self.time_s.size}, {self.voltage_V.size}, {self.current_A.size})")
        if self.time_s.size < 10:
            raise DataError(f"{label}: only {self.time_s.size} samples; a fit needs at least 10")
        for column, values in (("time_s", self.time_s), ("voltage_V", self.voltage_V),
                               ("current_A", self.current_A)):
            bad = ~np.isfinite(values)
            if bad.any():
                raise DataError(f"{label}: {bad.sum()} NaN/inf values in {column} (first at "
                                f"sample {int(np.argmax(bad))}); clean the file or let the "
                                f"reader drop them")
        back = np.flatnonzero(np.diff(self.time_s) <= 0)
        if back.size:
            k = int(back[0]) + 1
            raise DataError(f"{label}: time does not increase at sample {k} "
                            f"({self.time_s[k - 1]:g} s -> {self.time_s[k]:g} s)")
        if np.median(self.current_A) <= 0:
            raise DataError(f"{label}: the current is not a discharge (median "
                            f"{np.median(self.current_A):g} A); discharge must be positive "
                            f"(use --sign to flip it, or --current A for files without one)")
        if self.rest_voltage_V is not None and not np.isfinite(self.rest_voltage_V):
            self.rest_voltage_V = None
        if self.temperature_C is not None:
            temp = np.asarray(self.temperature_C, dtype=float)
            ok = temp.shape == self.time_s.shape and np.all(np.isfinite(temp)) and \
                np.all((temp > -60) & (temp < 150))
            self.temperature_C = temp if ok else None

    @classmethod
    def from_frame(cls, data, meta: dict | None = None, name: str = "") -> Curve:
        """Build from a canonical DataFrame (``time_s``, ``voltage_V``, ``current_A``)
        and the reader's meta (see :meth:`dischargelab.Discharge.from_frame`)."""
        from .discharge import Discharge

        meta = dict(meta or {})
        label = name or str(meta.get("name") or meta.get("source", ""))
        return Discharge.from_frame(data, meta, name=label).to_curve()

    @property
    def mean_current_A(self) -> float:
        """Time-averaged current [A]."""
        duration = self.time_s[-1] - self.time_s[0]
        return float(np.trapezoid(self.current_A, self.time_s) / duration)

    @property
    def ambient_C(self) -> float | None:
        """Cell temperature at the start [degC] (the ambient of a test from rest)."""
        return None if self.temperature_C is None else float(self.temperature_C[0])

    @property
    def charge_Ah(self) -> np.ndarray:
        """Discharged charge from the first sample [Ah] (computed once)."""
        if getattr(self, "_charge", None) is None:
            self._charge = charge_from_current(self.time_s, self.current_A)
        return self._charge


#: The multi-start search runs on curves thinned to this many samples; the
#: best solution is then refined on all samples.
SEARCH_SAMPLES_PER_CURVE = 400

#: Longer curves are thinned (evenly in time, last sample kept) before fitting:
#: a 1 s log of a 10-hour discharge carries no more shape than every 9th sample.
MAX_SAMPLES_PER_CURVE = 4000


def _thin(n: int, limit: int) -> np.ndarray:
    """Indices of at most about ``limit`` evenly spaced samples, first and last kept."""
    if n <= limit:
        return np.arange(n)
    stride = int(np.ceil(n / limit))
    return np.unique(np.r_[np.arange(0, n, stride), n - 1])


def _stack(curves, cells_series, strings_parallel, use_rest, weighting,
           max_samples=MAX_SAMPLES_PER_CURVE) -> Samples:
    """Cell-level samples of all curves (thinned), rest points appended as i = 0, q = 0."""
    parts = []
    has_temp = all(c.temperature_C is not None for c in curves)
    ambients = [c.ambient_C for c in curves if c.ambient_C is not None]
    ambient = float(np.median(ambients)) if ambients else 25.0
    for k, c in enumerate(curves):
        keep = _thin(c.time_s.size, max_samples)
        v = c.voltage_V[keep] / cells_series
        i = c.current_A[keep] / strings_parallel
        q0 = float(c.initial_charge_Ah) / strings_parallel
        q = c.charge_Ah[keep] / strings_parallel + q0
        t = c.time_s[keep] - c.time_s[0]
        temp = c.temperature_C[keep] if has_temp else np.full(v.size, ambient)
        w = np.full(v.size, 1.0 / np.sqrt(v.size) if weighting == "equal" else 1.0)
        rest = np.zeros(v.size, bool)
        if use_rest and c.rest_voltage_V is not None:
            v = np.append(v, c.rest_voltage_V / cells_series)
            i, q, t = np.append(i, 0.0), np.append(q, q0), np.append(t, 0.0)
            temp = np.append(temp, temp[0])
            w, rest = np.append(w, w[0]), np.append(rest, True)
        parts.append((v, i, q, t, temp, w, np.full(v.size, k), rest))
    cols = [np.concatenate([p[j] for p in parts]) for j in range(8)]
    if weighting == "equal":
        cols[5] = cols[5] / cols[5].mean()
    return Samples(voltage=cols[0], current=cols[1], charge=cols[2], time=cols[3],
                   temperature=cols[4], weight=cols[5], curve=cols[6], is_rest=cols[7],
                   n_curves=len(curves), has_temperature=has_temp, ambient_C=ambient)


def _spec(family: Family, fixed, bounds, stack: Samples, paper_mode: bool):
    """Resolve fixed values and bounds; returns (fixed dict, bounds dict)."""
    fixed = {k: float(v) for k, v in (fixed or {}).items()}
    bounds = {k: tuple(map(float, v)) for k, v in (bounds or {}).items()}
    allowed = set(family.names) | ({CURRENT_SCALE} if paper_mode else set())
    for name in list(fixed) + list(bounds):
        if name not in allowed:
            raise FitError(f"unknown parameter {name!r} for model {family.name!r}; use one of "
                           f"{', '.join(family.names)}")
    b = {p.name: (p.lower, p.upper) for p in family.parameters}
    b.update(family.fit_bounds(stack))
    b[CURRENT_SCALE] = PAPER_CURRENT_SCALE_BOUNDS if paper_mode else (1.0, 1.0)
    if paper_mode:
        # the charge scales with the fitted current: C must stay above the scaled charge
        lo_c = stack.q_max * PAPER_CURRENT_SCALE_BOUNDS[1] * (1.0 + 1e-4)
        b["C_Ah"] = (max(b["C_Ah"][0], lo_c), max(b["C_Ah"][1], lo_c * 1.01))
    if "C_Ah" in bounds:
        lo_c = b["C_Ah"][0]
        b["C_Ah"] = (max(bounds["C_Ah"][0], lo_c), max(bounds["C_Ah"][1], lo_c * 1.01))
    b.update({k: v for k, v in bounds.items() if k != "C_Ah"})
    if "C_Ah" in fixed and fixed["C_Ah"] <= stack.q_max:
        raise FitError(f"fixed C_Ah = {fixed['C_Ah']:g} Ah is not above the "
                       f"{stack.q_max:g} Ah already discharged in the data (q >= C)")
    for name, (lo, hi) in b.items():
        if not lo < hi and not (name == CURRENT_SCALE and not paper_mode):
            raise FitError(f"bounds for {name} are empty: {lo:g} .. {hi:g}")
        if name in fixed and not lo <= fixed[name] <= hi and name in bounds:
            raise FitError(f"fixed {name} = {fixed[name]:g} is outside its bounds {lo:g}..{hi:g}")
    for name, value in family.fit_fixed(stack).items():
        fixed.setdefault(name, value)
    if not paper_mode:
        fixed[CURRENT_SCALE] = 1.0
    elif not hasattr(family, "input_derivatives"):
        raise FitError(f"paper mode fits the paper's model; model {family.name!r} has no "
                       "fitted current scale")
    return fixed, b


class _Model:
    """A family's cell voltage over the stacked samples with a given set of free parameters."""

    def __init__(self, family: Family, stack: Samples, fixed: dict, bounds: dict | None = None):
        self.family = family
        self.s = stack
        self.fixed = fixed
        names = family.names
        self.linear = [n for n in names if family.parameter(n).linear and n not in fixed]
        self.nonlinear = [n for n in names if not family.parameter(n).linear and n not in fixed]
        if CURRENT_SCALE not in fixed:
            self.nonlinear.append(CURRENT_SCALE)
        self.free = self.linear + self.nonlinear
        self.bounds = bounds or {}
        self._weighted = not np.all(stack.weight == 1.0)
        self._weighted_voltage = stack.voltage * stack.weight
        self._scaled = (1.0, stack)

    def full(self, values: dict) -> dict:
        out = dict(self.fixed)
        out.update(values)
        return out

    def params(self, values: dict) -> tuple[CellParameters, float]:
        full = self.full(values)
        return CellParameters({n: full[n] for n in self.family.names}), full[CURRENT_SCALE]

    def data(self, scale: float) -> Samples:
        """The samples with current and charge times the paper-mode current scale."""
        if scale == 1.0:
            return self.s
        if self._scaled[0] != scale:
            from dataclasses import replace

            self._scaled = (scale, replace(self.s, current=self.s.current * scale,
                                           charge=self.s.charge * scale, _cache={}))
        return self._scaled[1]

    def voltage(self, values):
        full = self.full(values)
        with np.errstate(invalid="ignore", over="ignore"):
            return self.family.fit_voltage(full, self.data(full[CURRENT_SCALE]))

    def jacobian(self, values, names):
        """Analytic dV/d(name) for the named parameters, shape (n, len(names))."""
        full = self.full(values)
        scale = full[CURRENT_SCALE]
        data = self.data(scale)
        own = [n for n in names if n != CURRENT_SCALE]
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            jac = self.family.jacobian(full, data, own)
        if CURRENT_SCALE not in names:
            return jac
        dv_di, dv_dq = self.family.input_derivatives(full, data)
        col = dv_di * self.s.current + dv_dq * self.s.charge
        out = np.empty((col.size, len(names)))
        out[:, [k for k, n in enumerate(names) if n != CURRENT_SCALE]] = jac
        out[:, names.index(CURRENT_SCALE)] = col
        return out

    # --- variable projection over the nonlinear parameters -------------------------
    def project(self, theta):
        """Linear solve for the free linear parameters at nonlinear values ``theta``.

        Returns (values dict, weighted residual, weighted basis of the linear
        parameters not held at a bound, its inverse-Gram solver). The last call is
        cached: the solver asks for the residual and the Jacobian at one point.
        """
        key = np.asarray(theta, dtype=float).tobytes()
        if getattr(self, "_cache_key", None) == key:
            return self._cache
        values = dict(zip(self.nonlinear, theta))
        values.update(dict.fromkeys(self.linear, 0.0))
        w = self.s.weight
        offset = self.voltage(values)
        rhs = self._weighted_voltage - (offset * w if self._weighted else offset)
        if self.linear:
            phi = self.jacobian(values, self.linear)
            if self._weighted:
                phi = phi * w[:, None]
            if not np.all(np.isfinite(phi)) or not np.all(np.isfinite(rhs)):
                resid = np.full(rhs.size, np.inf)
                self._cache_key, self._cache = key, (values, resid, None, None)
                return self._cache
            coef, chol = _solve_normal(phi, rhs)
            held = self._violations(coef)
            if held.any():
                coef = _bounded_linear(phi, rhs, self._linear_bounds())
                held = self._at_bound(coef)
                keep = ~held
                fixed_part = phi[:, held] @ coef[held]
                if keep.any():
                    sub, chol = _solve_normal(phi[:, keep], rhs - fixed_part)
                    coef[keep] = sub
                    phi_free = phi[:, keep]
                else:
                    phi_free, chol = None, None
            else:
                phi_free = phi
            values.update(zip(self.linear, coef))
            resid = phi @ coef - rhs
        else:
            phi_free, chol, resid = None, None, -rhs
        self._cache_key, self._cache = key, (values, resid, phi_free, chol)
        return self._cache

    def _linear_bounds(self):
        lo = np.array([self.bounds.get(n, (-np.inf, np.inf))[0] for n in self.linear])
        hi = np.array([self.bounds.get(n, (-np.inf, np.inf))[1] for n in self.linear])
        return lo, hi

    def _violations(self, coef):
        lo, hi = self._linear_bounds()
        return (coef < lo) | (coef > hi)

    def _at_bound(self, coef):
        lo, hi = self._linear_bounds()
        span = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
        return (coef <= lo + 1e-12 * span) | (coef >= hi - 1e-12 * span)

    def grid_costs(self, starts) -> np.ndarray:
        """Projected residual sum of squares at each nonlinear starting point."""
        out = np.empty(len(starts))
        for k, theta in enumerate(np.atleast_2d(starts)):
            r = self.varpro_residual(theta)
            out[k] = float(r @ r) if np.all(np.isfinite(r)) else np.inf
        return out

    def varpro_residual(self, theta):
        return self.project(theta)[1]

    def varpro_jacobian(self, theta):
        values, _, phi, chol = self.project(theta)
        jac = self.jacobian(values, self.nonlinear) * self.s.weight[:, None]
        if phi is None:
            return jac
        # Kaufman's approximation: P_perp dV/dtheta, P_perp = I - phi (phi^T phi)^-1 phi^T
        return jac - phi @ _cho_apply(chol, phi.T @ jac)


def _bounded_linear(phi, rhs, bounds):
    """Bounded linear least squares (BVLS) for the linear parameters.

    Solved on the square Cholesky form of the normal equations
    (``min |L^T c - L^-1 phi^T rhs|``, the same minimiser) with equilibrated
    columns, so each solve costs a few columns squared, not the samples.
    """
    from scipy.linalg import cho_factor, solve_triangular
    from scipy.optimize import lsq_linear

    lo, hi = bounds
    norm = np.sqrt(np.einsum("ij,ij->j", phi, phi))
    norm[norm == 0] = 1.0
    scaled = phi / norm
    gram = scaled.T @ scaled
    gram[np.diag_indices_from(gram)] += 1e-12
    factor, _ = cho_factor(gram, lower=True)
    lower = np.tril(factor)
    target = solve_triangular(lower, scaled.T @ rhs, lower=True)
    sol = lsq_linear(lower.T, target, bounds=(lo * norm, hi * norm), method="bvls", tol=1e-12)
    return np.clip(sol.x / norm, lo, hi)


def _solve_normal(phi, rhs):
    """Least squares by equilibrated normal equations (a few columns, many rows).

    Returns (coefficients, solver) where ``solver`` applies the inverse Gram
    matrix again (for the Kaufman Jacobian). Falls back to a pseudo-inverse when
    the Gram matrix is ill-conditioned (cond > ~1e12).
    """
    gram = phi.T @ phi
    norm = np.sqrt(np.diag(gram))
    norm[norm == 0] = 1.0
    gram = gram / np.outer(norm, norm)
    # unit diagonal: det(gram) = prod(eigenvalues) < 1e-12 flags near-collinear columns
    sign, logdet = np.linalg.slogdet(gram)
    if sign > 0 and logdet > -27.6:
        inverse = np.linalg.inv(gram)
    else:
        inverse = np.linalg.pinv(gram, hermitian=True)
    solver = (inverse, norm)
    return _cho_apply(solver, phi.T @ rhs), solver


def _cho_apply(solver, b):
    """Solve (phi^T phi) x = b with the solver from :func:`_solve_normal`."""
    inverse, norm = solver
    if b.ndim == 2:
        return (inverse @ (b / norm[:, None])) / norm[:, None]
    return (inverse @ (b / norm)) / norm


@dataclass
class FitResult:
    """Outcome of :func:`fit_battery` (values, errors, diagnostics, data)."""

    parameters: CellParameters
    stderr: dict
    ci95: dict
    covariance: np.ndarray
    correlation: np.ndarray
    free: list
    fixed: dict
    bounds: dict
    rmse_V: float
    n_samples: int
    warnings: list
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
    model: str = "shepherd"
    ambient_C: float = 25.0
    thermal: dict | None = None
    model_error: dict | None = None
    implausible: list = field(default_factory=list)

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
        extra = {k: v for k, v in self.to_dict().items()
                 if k not in ("parameters", "cells_series", "strings_parallel",
                              "fit_currents_A", "model")}
        extra["source"] = [dict(c.meta, name=c.name) for c in self.curves]
        capacities = [float(c.charge_Ah[-1]) / self.strings_parallel for c in self.curves]
        lowest = int(np.argmin([abs(x) for x in self.fit_currents_A]))
        extra["measured_capacity_Ah"] = capacities[lowest]
        extra["ambient_C"] = self.ambient_C
        rises = [float(np.max(c.temperature_C) - c.temperature_C[0]) for c in self.curves
                 if c.temperature_C is not None]
        if rises:
            extra["fit_temperature_rise_K"] = max(rises)
        if self.bootstrap is not None:
            extra["bootstrap"] = {"names": list(self.family.names),
                                  "samples": np.round(self.bootstrap, 12).tolist()}
        return Battery(self.parameters, self.cells_series, self.strings_parallel,
                       covariance=self.covariance, fit_currents_A=self.fit_currents_A,
                       extra=extra, model=self.model)

    def to_dict(self) -> dict:
        """The ``fit --json`` document (keys are only ever added, never renamed)."""
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
        return "\n".join(lines)

    def plot(self, ax=None, **kwargs):
        """Measured vs fitted voltage with residuals; returns the main Axes."""
        from .plot import plot_fit

        return plot_fit(self, ax=ax, **kwargs)


def guess_parameters(curves, cells_series: int = 1, strings_parallel: int = 1,
                     model="shepherd") -> dict:
    """Starting values from the data (per cell), from the family's own ``guess``.

    For ``shepherd``: C from the integrated Ah (a little above the largest
    discharged charge), E0 + A from the rest voltage when present (else the first
    sample), R + K from the voltage step at load start when a rest sample exists,
    B from the length of the initial exponential drop.
    """
    curves = [curves] if isinstance(curves, Curve) else list(curves)
    stack = _stack(curves, cells_series, strings_parallel, True, "equal")
    return get_family(model).guess(stack)


def _starts(model: _Model, bounds: dict, guess: dict | None):
    """Grid of starting points for the nonlinear parameters (clipped into bounds)."""
    grid = model.family.start_grid(model.s, model.nonlinear)
    base = model.family.guess(model.s)
    axes = []
    for n in model.nonlinear:
        values = list(grid.get(n, [1.0 if n == CURRENT_SCALE else base[n]]))
        if guess and n in guess:
            values = [guess[n]] + values
        axes.append(values)
    mesh = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(axes), -1).T if axes else \
        np.empty((1, 0))
    lo = np.array([bounds[n][0] for n in model.nonlinear])
    hi = np.array([bounds[n][1] for n in model.nonlinear])
    span = hi - lo
    return np.clip(mesh, lo + 1e-9 * span, hi - 1e-9 * span), lo, hi


def fit_battery(curves, *, cells_series: int = 1, strings_parallel: int = 1,
                fixed: dict | None = None, bounds: dict | None = None,
                guess: dict | None = None, paper_mode: bool = False, use_rest: bool = True,
                weighting: str = "equal", n_best: int | None = None, bootstrap: int = 0,
                seed: int = 0, model="shepherd", model_error: bool = True,
                progress=None) -> FitResult:
    """Fit a model family to one or several discharges with shared parameters.

    Parameters
    ----------
    curves : Curve or sequence of Curve
        Pack-level measurements, each with its own (logged or commanded) current.
    cells_series, strings_parallel : int
        Pack configuration; the fit is per cell.
    fixed : dict, optional
        ``{name: value}`` parameters held fixed (e.g. ``{"E0_V": 4.1}``).
    bounds : dict, optional
        ``{name: (lower, upper)}`` overriding the family's default bounds.
    guess : dict, optional
        Starting values of nonlinear parameters tried before the built-in grid.
    paper_mode : bool
        Reproduce the paper's setup (``shepherd`` only): E0 must be fixed, the
        current is scaled by a fitted factor together with R, K, A, B, C. The
        result is degenerate by construction and says so.
    use_rest : bool
        Use each curve's rest voltage (i = 0) as a data point.
    weighting : {"equal", "samples"}
        "equal" gives each curve the same total weight whatever its length.
    n_best : int, optional
        Number of best grid starts refined by the variable-projection solver
        (default: the family's ``n_best``).
    bootstrap : int
        Number of moving-block bootstrap refits stored with the result (0 = none);
        they carry the parameter uncertainty into simulations.
    seed : int
        Seed of the bootstrap.
    model : str or Family
        Model family name (``dischargelab.models.FAMILIES``), or ``"auto"``: pick
        by evidence (see :func:`choose_model`).
    model_error : bool
        With two or more curves at different currents, estimate the model's own
        error from leave-one-curve-out predictions (stored in ``model_error``).
    progress : callable, optional
        Called as ``progress(done, total)`` during the bootstrap refits.

    Returns
    -------
    FitResult

    Raises
    ------
    FitError
        Bad fixed/bounds specification or no convergence.
    """
    t_start = time.perf_counter()
    curves = [curves] if isinstance(curves, Curve) else list(curves)
    if not curves:
        raise FitError("no discharge curves to fit")
    if model == AUTO:
        return _fit_auto(curves, t_start, cells_series=cells_series,
                         strings_parallel=strings_parallel, fixed=fixed, bounds=bounds,
                         guess=guess, paper_mode=paper_mode, use_rest=use_rest,
                         weighting=weighting, n_best=n_best, bootstrap=bootstrap, seed=seed,
                         progress=progress)
    family = get_family(model)
    if cells_series < 1 or strings_parallel < 1:
        raise FitError("cells in series and strings in parallel must be at least 1")
    if weighting not in ("equal", "samples"):
        raise FitError(f"weighting must be 'equal' or 'samples', got {weighting!r}")
    stack = _stack(curves, cells_series, strings_parallel, use_rest, weighting)
    requested_fixed = dict(fixed or {})
    if paper_mode:
        if "E0_V" not in requested_fixed:
            raise FitError("paper mode needs E0 (the paper's only input): give E0_V in fixed")
        if len(curves) != 1:
            raise FitError("paper mode fits one curve (the paper's setup); give one curve")
    fixed, bnds = _spec(family, requested_fixed, bounds, stack, paper_mode)
    notes, warnings = [], []
    _resolve_e0_r(family, stack, fixed, notes, warnings)
    for c in curves:
        used = _thin(c.time_s.size, MAX_SAMPLES_PER_CURVE).size
        if used < c.time_s.size:
            notes.append(f"curve {c.name or '?'}: {used} of {c.time_s.size} samples used "
                         f"(evenly thinned in time)")
    mdl = _Model(family, stack, fixed, bnds)
    if not mdl.free:
        raise FitError("every parameter is fixed; nothing to fit")

    starts, lo, hi = _starts(mdl, bnds, guess)
    nfev = 0
    theta = np.empty(0)
    if mdl.nonlinear:
        # coarse to fine: search on a thinned copy of the data, refine on all of it
        coarse = _Model(family, _stack(curves, cells_series, strings_parallel, use_rest,
                                       weighting, max_samples=SEARCH_SAMPLES_PER_CURVE),
                        fixed, bnds)
        cost = coarse.grid_costs(starts)
        nfev += len(starts)
        if not np.any(np.isfinite(cost)):
            raise FitError("the model cannot be evaluated on these data at any starting point; "
                           "check the data (current sign, units) and the bounds")
        best = None
        refine = family.n_best if n_best is None else n_best
        for k in np.argsort(cost)[:max(1, refine)]:
            sol = _varpro_solve(coarse, starts[k], lo, hi, ftol=COARSE_FTOL)
            nfev += sol.nfev
            if best is None or sol.cost < best.cost:
                best = sol
        sol = _varpro_solve(mdl, _defined_start(mdl, best.x, hi), lo, hi)
        nfev += sol.nfev
        theta = sol.x
    values = dict(mdl.project(theta)[0])
    values = _polish(mdl, values, bnds)
    nfev += 1

    params, scale = mdl.params(values)
    residual = mdl.voltage(values) - stack.voltage
    if not np.all(np.isfinite(residual)):
        raise FitError("the fit reached a region where the model is undefined (q >= C); "
                       "check the data and the bounds on C_Ah")
    w = stack.weight
    jac = mdl.jacobian(values, mdl.free) * w[:, None]
    svd = equilibrated_svd(jac)
    cov_free, dof_eff = _covariance(svd, residual * w, stack)
    names_all = list(family.names)
    n_all = len(names_all)
    cov = np.zeros((n_all, n_all))
    idx = [names_all.index(n) for n in mdl.free if n in names_all]
    sub = [k for k, n in enumerate(mdl.free) if n in names_all]
    cov[np.ix_(idx, idx)] = cov_free[np.ix_(sub, sub)]
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    corr[~np.isfinite(corr)] = 0.0
    np.fill_diagonal(corr, 1.0)
    t_crit = float(stdtrit(max(dof_eff, 1.0), 0.975))  # Student t quantile
    stderr, ci95 = {}, {}
    for k, n in enumerate(names_all):
        v = float(params[n])
        if n in fixed:
            stderr[n], ci95[n] = 0.0, (v, v)
        else:
            e = float(sd[k]) if np.isfinite(sd[k]) else float("nan")
            stderr[n], ci95[n] = e, (v - t_crit * e, v + t_crit * e)

    thermal = None
    if family.thermal:
        params, thermal = _thermal(family, params, stack, notes)
    ident = analyse(jac, mdl.free, values, bnds, paper_mode=paper_mode, svd=svd)
    _physical_limits(family, ident, notes)
    warnings += ident.warnings
    measured = ~stack.is_rest
    rmse = float(np.sqrt(np.mean(residual[measured] ** 2)))
    implausible = plausibility(family, params, ci95, fixed, stack, rmse)
    warnings += implausible + undetermined(family, params, ci95, fixed)
    samples = None
    if bootstrap:
        samples = _bootstrap(mdl, values, residual, bnds, int(bootstrap), seed, progress)
        if thermal is not None:
            for name in ("Cth_J_per_K", "Rth_K_per_W"):
                samples[:, names_all.index(name)] = params[name]
    result = FitResult(
        parameters=params, stderr=stderr, ci95=ci95, covariance=cov, correlation=corr,
        free=list(mdl.free), fixed=dict(fixed), bounds=bnds,
        rmse_V=rmse, n_samples=int(measured.sum()), warnings=warnings, notes=notes,
        identifiability=ident, curves=curves, cells_series=int(cells_series),
        strings_parallel=int(strings_parallel), current_scale=float(scale),
        paper_mode=paper_mode, elapsed_s=0.0, nfev=nfev,
        n_starts=len(starts), bootstrap=samples, model=family.name,
        ambient_C=float(stack.ambient_C), thermal=thermal, implausible=implausible,
    )
    if model_error and not paper_mode:
        result.model_error = held_out_error(
            curves, model=family.name, cells_series=cells_series,
            strings_parallel=strings_parallel, fixed=requested_fixed, bounds=bounds,
            use_rest=use_rest, weighting=weighting)
    result.elapsed_s = time.perf_counter() - t_start
    return result


#: ``model`` value that picks the family by evidence.
AUTO = "auto"

#: A physically plausible family is preferred when its held-out error is within this
#: much (absolute, as a fraction) of the best one's.
PHYSICAL_PREFERENCE = 0.01


def _several_rates(curves) -> bool:
    """Two or more curves whose mean currents differ by 20 % or more."""
    currents = [c.mean_current_A for c in curves]
    return len(curves) >= 2 and max(currents) >= 1.2 * min(currents)


def selection_score(curve_rms: float | None, end_rms: float | None) -> float:
    """Score of a family for ``model="auto"`` [-]: the geometric mean of its two
    held-out errors of the time to cutoff (:func:`held_out_error`), whole curves
    left out (how capacity and overpotentials change with rate) and curve ends left
    out (the knee at every fitted rate). A family must predict both; with two
    curves, leaving one out leaves a one-rate fit, which scores priors more than
    the family. ``inf`` when either could not be computed."""
    if curve_rms is None or end_rms is None:
        return float("inf")
    return float(np.sqrt(max(curve_rms, 1e-6) * max(end_rms, 1e-6)))


def _pct(value) -> str:
    return "n/a" if value is None or not np.isfinite(value) else f"{100 * value:.2f} %"


def choose_model(curves) -> tuple[list[str], str]:
    """Candidate families for ``model="auto"`` and why.

    One curve without temperature: ``shepherd`` (nothing can tell a richer model
    apart). One curve with a logged temperature: ``shepherd-thermal`` (its
    temperature dependence comes from physics priors, the self-heating from the
    log). Two or more curves at different currents: every family that the data
    can feed, compared by leave-one-curve-out prediction error.
    """
    from .models import FAMILIES

    has_temp = all(c.temperature_C is not None for c in curves)
    if not _several_rates(curves):
        if has_temp:
            return ["shepherd-thermal"], ("one rate with a logged temperature: shepherd-thermal "
                                          "(self-heating from the log, Arrhenius prior)")
        return ["shepherd"], "one rate without temperature: the paper's shepherd model"
    names = [n for n in FAMILIES if has_temp or not get_family(n).thermal]
    return names, "several rates: the family with the smallest held-out error"


def _fit_auto(curves, t_start, **kw) -> FitResult:
    """Fit every candidate of :func:`choose_model`; keep the best held-out error."""
    names, why = choose_model(curves)
    if kw.get("paper_mode"):
        names, why = ["shepherd"], "paper mode: the paper's model"
    if len(names) == 1:
        res = fit_battery(curves, model=names[0], **kw)
        res.notes.insert(0, f"model {names[0]!r} chosen automatically: {why}")
        return res
    fits, scores = {}, {}
    for name in names:
        try:
            fits[name] = fit_battery(curves, model=name, **dict(kw, bootstrap=0, progress=None))
        except FitError:
            continue
        err = fits[name].model_error or {}
        scores[name] = selection_score(err.get("held_out_rms"), err.get("end_rms"))
    if not fits:
        raise FitError("no model family could be fitted to these data")
    order = sorted(fits, key=lambda n: (scores[n], list(fits).index(n)))
    best = order[0]
    physical = [n for n in order if fits[n].physical]
    if physical and physical[0] != best and \
            scores[physical[0]] <= scores[best] + PHYSICAL_PREFERENCE:
        best = physical[0]
        why += (f", preferring physically plausible parameters within "
                f"{100 * PHYSICAL_PREFERENCE:g} points of the best")
    res = fits[best]
    if kw.get("bootstrap"):  # refit with the bootstrap; the held-out error is already known
        res = fit_battery(curves, model=best, model_error=False, **kw)
        res.model_error = fits[best].model_error
    def row(n):
        err = fits[n].model_error or {}
        return (f"{n} {_pct(scores[n])} (curves {_pct(err.get('held_out_rms'))}, "
                f"ends {_pct(err.get('end_rms'))})"
                + ("" if fits[n].physical else " implausible parameters"))

    table = ", ".join(row(n) for n in fits)
    res.notes.insert(0, f"model {best!r} chosen automatically: {why} (held-out time-to-cutoff "
                        f"error, geometric mean of whole curves and curve ends left out: "
                        f"{table})")
    res.elapsed_s = time.perf_counter() - t_start
    return res


def _physical_limits(family: Family, ident: Identifiability, notes: list) -> None:
    """Parameters at a bound that marks an absent effect become notes, not bound problems."""
    keep = []
    for name, side, bound in ident.at_bounds:
        par = family.parameter(name) if name in family.names else None
        if par is not None and par.limit_note:
            notes.append(f"{name} = {bound:g} at its {side} bound: {par.limit_note}")
            ident.warnings = [w for w in ident.warnings if not w.startswith(f"{name} = ")]
        else:
            keep.append((name, side, bound))
    ident.at_bounds = keep


def _thermal(family: Family, params: CellParameters, stack: Samples, notes: list):
    """Heat capacity and thermal resistance from the logged temperature (else defaults)."""
    if not stack.has_temperature:
        # the fit took the cell at the ambient, so its resistances already hold whatever
        # heating the runs had: predictions keep the cell at the ambient too
        params = params.replace(Cth_J_per_K=HELD_AT_AMBIENT_HEAT_CAPACITY)
        notes.append("thermal model: no temperature logged, so the cell is held at the "
                     "ambient in predictions (its resistances are those of the fitted runs, "
                     "heating included); give the ambient with --ambient")
        return params, {"Cth_J_per_K": float(params["Cth_J_per_K"]),
                        "Rth_K_per_W": float(params["Rth_K_per_W"]),
                        "source": "held at the ambient (no logged temperature)"}
    fitted = fit_lumped_thermal(family, params, stack)
    if fitted is None:
        source = "default (the logged temperature could not be used)"
        notes.append(f"thermal model: {source}; heat capacity {params['Cth_J_per_K']:.3g} J/K, "
                     f"thermal resistance {params['Rth_K_per_W']:.3g} K/W")
        return params, {"Cth_J_per_K": float(params["Cth_J_per_K"]),
                        "Rth_K_per_W": float(params["Rth_K_per_W"]), "source": source}
    params = params.replace(Cth_J_per_K=fitted["Cth_J_per_K"],
                            Rth_K_per_W=fitted["Rth_K_per_W"])
    if fitted["heat_capacity_fitted"]:
        source = "logged temperature"
        how = "heat capacity {:.3g} J/K, thermal resistance {:.3g} K/W"
    else:
        source = (f"logged temperature (less than {MIN_HEATING_K:g} K of self-heating: "
                  f"heat capacity kept at its default)")
        how = ("heat capacity {:.3g} J/K (default: the log shows less than "
               f"{MIN_HEATING_K:g} K of self-heating), thermal resistance {{:.3g}} K/W")
    notes.append("thermal model fitted to the logged cell temperature: "
                 + how.format(fitted["Cth_J_per_K"], fitted["Rth_K_per_W"])
                 + f" (RMSE {fitted['rmse_K']:.2f} K)")
    return params, dict(fitted, source=source)


#: Fraction of a curve's duration left out at its end by :func:`held_out_error`.
HELD_OUT_TAIL = 0.2


def held_out_error(curves, *, model, cells_series=1, strings_parallel=1, fixed=None,
                   bounds=None, use_rest=True, weighting="equal") -> dict | None:
    """The model's own error of the time to cutoff, from data left out of the fit.

    Two kinds of folds, each predicting the time to the left-out curve's last
    voltage at its mean current (thermal families from its starting temperature):

    * **whole curves**: each curve in turn is left out and the model fitted to the
      others. The prediction is an extrapolation by the current ratio ``r_k``
      between the left-out curve and the fitted ones, so its error is brought back
      to the fitted currents by dividing it by ``1 + g_k ln r_k``, ``g_k`` being
      the growth :func:`dischargelab.uncertainty.extrapolation_growth` of that
      smaller fit (one rate: the prior's; several: the held-out one);
    * **curve ends**: each curve in turn loses its last :data:`HELD_OUT_TAIL` of
      duration (the knee and the cutoff) and the model is fitted to that and every
      other curve. Every rate stays in the fit, so this is an error at the fitted
      currents, the one a two-curve fit is used for (leaving one of two curves out
      leaves a one-rate fit).

    Needs two or more curves whose currents differ by 20 % or more.

    Returns
    -------
    dict or None
        ``relative_sd`` and ``dof``: the model error inside the fitted currents,
        every normalised error pooled with the prior
        (:func:`dischargelab.uncertainty.held_out_posterior`); ``held_out_rms`` /
        ``end_rms``: RMS of the raw errors of each kind [-] (None when none could
        be computed); ``errors_pct``, ``extrapolation_ratios``, ``curves``
        (whole curves left out) and ``end_errors_pct``; ``source = "held-out"``.
    """
    from dataclasses import replace as _replace

    from .uncertainty import extrapolation_growth, held_out_posterior

    if not _several_rates(curves):
        return None
    common = dict(cells_series=cells_series, strings_parallel=strings_parallel, fixed=fixed,
                  bounds=bounds, use_rest=use_rest, weighting=weighting, model=model)
    errors, ratios, normalised, names, ends = [], [], [], [], []
    for k, left in enumerate(curves):
        rest = [c for j, c in enumerate(curves) if j != k]
        fold = _held_out_fold(rest, left, common)
        if fold is not None:
            error, battery = fold
            ratio = battery.extrapolation_ratio(left.mean_current_A / strings_parallel)
            growth = extrapolation_growth(
                battery, "held-out" if _several_rates(rest) else "prior")
            errors.append(100.0 * error)
            ratios.append(float(ratio))
            normalised.append(error / (1.0 + growth * np.log(ratio)))
            names.append(left.name)
        t = left.time_s
        keep = t <= t[0] + (1.0 - HELD_OUT_TAIL) * (t[-1] - t[0])
        cut = {"time_s": t[keep], "voltage_V": left.voltage_V[keep],
               "current_A": left.current_A[keep]}
        if left.temperature_C is not None:
            cut["temperature_C"] = left.temperature_C[keep]
        try:
            shortened = _replace(left, **cut)
        except DataError:
            continue
        fold = _held_out_fold([shortened if j == k else c for j, c in enumerate(curves)],
                              left, common)
        if fold is not None:
            ends.append(fold[0])
    if not errors and not ends:
        return None
    sd, dof = held_out_posterior(normalised + ends)

    def rms(values):
        return float(np.sqrt(np.mean(np.square(values)))) if values else None

    return {"relative_sd": sd, "dof": dof,
            "held_out_rms": None if not errors else rms(errors) / 100.0,
            "end_rms": rms(ends), "errors_pct": errors, "extrapolation_ratios": ratios,
            "curves": names, "end_errors_pct": [100.0 * e for e in ends],
            "source": "held-out"}


def _held_out_fold(fitted, left, common):
    """(relative error of the predicted time to ``left``'s last voltage, battery) of a
    fit to ``fitted``; None when the fit or the prediction fails."""
    from .errors import SimulationError
    from .simulate import simulate_current

    try:
        res = fit_battery(fitted, model_error=False, **common)
        sim = simulate_current(res.battery, left.mean_current_A,
                               cutoff_pack_V=float(left.voltage_V[-1]),
                               ambient_C=left.ambient_C)
    except (FitError, SimulationError, DataError):
        return None
    measured = float(left.time_s[-1] - left.time_s[0])
    if not np.isfinite(sim.time_to_cutoff_s) or measured <= 0:
        return None
    return (sim.time_to_cutoff_s - measured) / measured, res.battery


def _lag1_correlation(residual, stack: Samples) -> float:
    """Lag-1 autocorrelation of the residuals within each curve, pooled, in [0, 0.999]."""
    num = den = 0.0
    for k in range(stack.n_curves):
        r = residual[(stack.curve == k) & ~stack.is_rest]
        if r.size > 2:
            num += float(np.dot(r[1:], r[:-1]))
            den += float(np.dot(r, r))
    return min(max(num / den if den > 0 else 0.0, 0.0), 0.999)


def _block_length(residual, stack: Samples) -> int:
    """Block length of the moving-block bootstrap: the residuals' correlation length."""
    rho = _lag1_correlation(residual, stack)
    return max(1, int(np.ceil((1 + rho) / (1 - rho))))


def _bootstrap(model: _Model, values: dict, residual, bounds: dict, n: int, seed: int,
               progress=None):
    """Parameter sets refitted to the fit plus block-resampled residuals.

    Circular moving-block bootstrap of the residuals within each curve (blocks as
    long as the residuals' correlation length, so the smooth model-misfit pattern
    is resampled, not only the noise); each replica is refitted from the optimum.
    Returns an array (n, parameters) in the family's order; fixed parameters constant.
    """
    from dataclasses import replace as _replace

    rng = np.random.default_rng(seed)
    stack = model.s
    fitted = stack.voltage + residual
    block = _block_length(residual, stack)
    theta0 = np.array([values[k] for k in model.nonlinear])
    lo = np.array([bounds[k][0] for k in model.nonlinear])
    hi = np.array([bounds[k][1] for k in model.nonlinear])
    out = np.empty((n, len(model.family.names)))
    for b in range(n):
        voltage = fitted.copy()
        for k in range(stack.n_curves):
            idx = np.flatnonzero((stack.curve == k) & ~stack.is_rest)
            m = idx.size
            length = min(block, max(1, m // 4))
            starts = rng.integers(0, m, int(np.ceil(m / length)))
            pick = ((starts[:, None] + np.arange(length)[None, :]) % m).ravel()[:m]
            voltage[idx] = fitted[idx] - residual[idx][pick]
        # the filtered currents in the cache depend on time and current only: shared
        replica = _Model(model.family, _replace(stack, voltage=voltage), model.fixed, bounds)
        theta = _varpro_solve(replica, theta0, lo, hi).x if model.nonlinear else theta0
        vals = _polish(replica, dict(replica.project(theta)[0]), bounds)
        params, _ = replica.params(vals)
        out[b] = params.as_array(model.family.names)
        if progress is not None:
            progress(b + 1, n)
    return out


#: Capacity increases tried when the coarse optimum leaves a sample past empty.
_CAPACITY_STEPS = (1.0, 1.001, 1.003, 1.01, 1.03, 1.1)


def _defined_start(model: _Model, theta, hi):
    """``theta`` with the capacity raised just enough that the model is defined on
    every sample: the coarse search sees a thinned copy of the data and can place
    the capacity just under a sample it did not see (q >= C there)."""
    theta = np.asarray(theta, dtype=float)
    if "C_Ah" not in model.nonlinear:
        return theta
    k = model.nonlinear.index("C_Ah")
    for factor in _CAPACITY_STEPS:
        trial = theta.copy()
        trial[k] = min(theta[k] * factor, hi[k])
        if np.all(np.isfinite(model.varpro_residual(trial))):
            return trial
    return theta


#: Relative cost decrease below which a start's search on the thinned data stops:
#: it only has to pick the basin that the refinement on all samples then polishes.
COARSE_FTOL = 1e-6


@dataclass
class _Solution:
    x: np.ndarray
    cost: float
    nfev: int


def _varpro_solve(model: _Model, theta0, lo, hi, max_iter: int = 200,
                  ftol: float = 1e-12) -> _Solution:
    """Projected Levenberg-Marquardt on the reduced (variable-projection) problem.

    The reduced problem has at most three parameters, so each iteration is a
    2x2 or 3x3 solve; the cost is in the residual and Kaufman Jacobian
    evaluations. Bounds: steps are clipped to the box and parameters held at a
    bound by the gradient are frozen for that step (Bertsekas-style projection).
    """
    span = hi - lo
    x = np.clip(np.asarray(theta0, dtype=float), lo + 1e-9 * span, hi - 1e-9 * span)
    r = model.varpro_residual(x)
    cost = 0.5 * float(r @ r)
    nfev = 1
    lam = None
    for _ in range(max_iter):
        jac = model.varpro_jacobian(x)
        grad = jac.T @ r
        hess = jac.T @ jac
        at_lo = (x <= lo) & (grad > 0)
        at_hi = (x >= hi) & (grad < 0)
        free = ~(at_lo | at_hi)
        if not free.any() or np.max(np.abs(grad[free]) * (np.abs(x[free]) + 1e-12)) <= \
                1e-12 * max(cost, 1e-300):
            break
        diag = np.diag(hess)[free].copy()
        diag[diag <= 0] = 1.0
        if lam is None:
            lam = 1e-3
        accepted = False
        while lam < 1e16:
            a = hess[np.ix_(free, free)] + lam * np.diag(diag)
            step = np.zeros_like(x)
            try:
                step[free] = np.linalg.solve(a, -grad[free])
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            x_new = np.clip(x + step, lo, hi)
            r_new = model.varpro_residual(x_new)
            nfev += 1
            cost_new = 0.5 * float(r_new @ r_new)
            if np.isfinite(cost_new) and cost_new < cost:
                accepted = True
                break
            lam *= 4.0
        if not accepted:
            break
        moved = np.abs(x_new - x)
        decrease = cost - cost_new
        x, r, cost = x_new, r_new, cost_new
        lam = max(lam / 3.0, 1e-12)
        if decrease <= ftol * cost or np.all(moved <= 1e-10 * (np.abs(x) + 1e-10)):
            break
    model.varpro_residual(x)  # leave the cache at the solution
    return _Solution(x=x, cost=cost, nfev=nfev)


def _resolve_e0_r(family: Family, stack: Samples, fixed: dict, notes: list, warnings: list):
    """Apply the documented resolution of the E0/R collinearity (see module docstring)."""
    if "E0_V" not in family.names or "E0_V" in fixed or "R_ohm" in fixed:
        return
    currents = []
    for k in range(stack.n_curves):
        sel = stack.curve == k
        currents.append(stack.current[sel & ~stack.is_rest])
    span = np.ptp(np.concatenate(currents))
    mean = np.mean(np.concatenate(currents))
    has_rest = bool(stack.is_rest.any())
    if has_rest:
        notes.append("E0 and R separated by the rest voltage before the load step "
                     "(V_rest = E0 + A; the step gives R + K)")
        return
    if span > 0.2 * mean:
        notes.append("E0 and R separated by the spread of currents in the data")
        return
    fixed["R_ohm"] = 0.0
    warnings.append(
        "E0 and R are not separable from one constant-current curve without a rest sample: "
        "only E0 - R*i is determined, so R is set to 0 and E0 absorbs R*i. Predictions at "
        "other currents miss the ohmic drop. Fix: give E0 (e.g. from a low-rate curve), "
        "log the rest voltage before the load starts, or add a curve at a second current.")


def _polish(model: _Model, values: dict, bounds: dict) -> dict:
    """Bounded full least squares from the projected solution when it violates bounds."""
    x0 = np.array([values[n] for n in model.free])
    lo = np.array([bounds[n][0] for n in model.free])
    hi = np.array([bounds[n][1] for n in model.free])
    if np.all((x0 >= lo) & (x0 <= hi)):
        return values
    span = hi - lo
    x0 = np.clip(x0, lo + 1e-9 * span, hi - 1e-9 * span)
    w = model.s.weight

    def resid(x):
        return (model.voltage(dict(zip(model.free, x))) - model.s.voltage) * w

    def jac(x):
        return model.jacobian(dict(zip(model.free, x)), model.free) * w[:, None]

    if not np.all(np.isfinite(resid(x0))):
        # clipping moved the model where it is undefined (e.g. an empty cell before the
        # last sample): keep the projected solution, clipped, if that is defined
        clipped = dict(values)
        clipped.update(zip(model.free, np.clip([values[n] for n in model.free], lo, hi)))
        if np.all(np.isfinite(model.voltage(clipped))):
            return clipped
        raise FitError("the fit cannot stay inside the parameter bounds on these data; check "
                       "the data (units, current sign) or widen the bounds")
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        sol = least_squares(resid, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac",
                            ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=500)
    if not np.isfinite(sol.cost):
        raise FitError("bounded least squares did not converge; check the data and bounds")
    out = dict(values)
    out.update(zip(model.free, sol.x))
    return out


def _covariance(svd, resid: np.ndarray, stack: Samples):
    """Parameter covariance with an AR(1) effective-sample-size correction.

    Returns (covariance of the free parameters, effective degrees of freedom).
    """
    norm, sv, vt = svd
    n, p = resid.size, norm.size
    rho = _lag1_correlation(resid, stack)
    n_eff = max(n * (1 - rho) / (1 + rho), p + 1.0)
    dof_eff = n_eff - p
    s2 = float(np.dot(resid, resid)) / max(n - p, 1) * (n / n_eff)
    # pseudo-inverse via SVD; parameters in a degenerate direction get NaN variance
    # (columns equilibrated first so the threshold is scale free)
    keep = sv > (sv.max() * 1e-8 if sv.size else 0.0)
    inv = np.where(keep, 1.0 / np.where(keep, sv, 1.0) ** 2, 0.0)
    cov = ((vt.T * inv) @ vt) / np.outer(norm, norm)
    if not keep.all():
        degenerate = np.abs(vt[~keep]).max(axis=0) > 1e-3
        cov[degenerate, :] = np.nan
        cov[:, degenerate] = np.nan
    return s2 * cov, dof_eff
