"""Fit the modified Shepherd model to one or several measured discharges.

Method
------
Bounded nonlinear least squares on the cell voltage, eq. (8) of the paper,
solved by **variable projection**: for fixed nonlinear parameters (B, C and, in
paper mode, a current scale) the model is linear in E0, R, K and A, which are
eliminated by a linear least-squares solve; the reduced problem in (B, C) is
solved with scipy's ``least_squares`` and Kaufman's analytic Jacobian from a
small grid of starts. A final bounded ``least_squares`` polish over all free
parameters (analytic Jacobian) enforces the bounds on the linear parameters when
the projected solution violates them.

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
from scipy.special import stdtrit
from scipy.optimize import least_squares

from .errors import DataError, FitError
from .identifiability import Identifiability, analyse, equilibrated_svd
from .model import (
    PARAMETER_NAMES, Battery, CellParameters, charge_from_current, cell_voltage,
)

#: Name of the current-scale parameter fitted in paper mode.
CURRENT_SCALE = "current_scale"

#: Default bounds per cell. C is also bounded below by the largest discharged
#: charge in the data (the model is undefined for q >= C).
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "E0_V": (0.5, 6.0),
    "R_ohm": (0.0, 2.0),
    "K_V_per_Ah": (0.0, 20.0),
    "A_V": (0.0, 3.0),
    "B_per_Ah": (1e-3, 1e4),
    "C_Ah": (1e-3, 1e4),
    CURRENT_SCALE: (1.0, 1.0),
}

#: Default upper bound of C as a multiple of the largest discharged charge.
C_UPPER_FACTOR = 20.0

#: Bounds of the fitted/measured current ratio in paper mode (the paper's fits
#: came within 2.5-5 % of the measured current). C is bounded below by the
#: largest charge times the upper bound.
PAPER_CURRENT_SCALE_BOUNDS = (0.9, 1.1)

_LINEAR = ("E0_V", "R_ohm", "K_V_per_Ah", "A_V")
_NONLINEAR = ("B_per_Ah", "C_Ah", CURRENT_SCALE)


@dataclass
class Curve:
    """One measured discharge at pack level (discharge current positive).

    Parameters
    ----------
    time_s, voltage_V, current_A : array_like
        Samples [s], [V], [A] from load start.
    name : str
        Label used in plots and tables (file name, rate).
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

    @classmethod
    def from_frame(cls, data, meta: dict | None = None, name: str = "") -> "Curve":
        """Build from a canonical DataFrame (``time_s``, ``voltage_V``, ``current_A``)."""
        meta = dict(meta or {})
        missing = [c for c in ("time_s", "voltage_V", "current_A") if c not in data]
        if missing:
            raise DataError(f"data has no {', '.join(missing)} column; "
                            f"files without a current column need --current A")
        rest = (meta.get("rest_sample") or {}).get("voltage_V")
        return cls(data["time_s"].to_numpy(float), data["voltage_V"].to_numpy(float),
                   data["current_A"].to_numpy(float),
                   name=name or str(meta.get("name") or meta.get("source", "")),
                   rest_voltage_V=None if rest is None else float(rest), meta=meta)

    @property
    def mean_current_A(self) -> float:
        """Time-averaged current [A]."""
        duration = self.time_s[-1] - self.time_s[0]
        return float(np.trapezoid(self.current_A, self.time_s) / duration)

    @property
    def charge_Ah(self) -> np.ndarray:
        """Discharged charge from the first sample [Ah] (computed once)."""
        if getattr(self, "_charge", None) is None:
            self._charge = charge_from_current(self.time_s, self.current_A)
        return self._charge


@dataclass
class _Stack:
    """Cell-level samples of all curves, rest points appended as i = 0, q = 0 samples."""

    voltage: np.ndarray
    current: np.ndarray
    charge: np.ndarray
    weight: np.ndarray  # sqrt weights per sample
    curve: np.ndarray   # curve index per sample
    is_rest: np.ndarray
    n_curves: int

    @property
    def q_max(self) -> float:
        return float(self.charge.max())


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
           max_samples=MAX_SAMPLES_PER_CURVE) -> _Stack:
    parts = []
    for k, c in enumerate(curves):
        keep = _thin(c.time_s.size, max_samples)
        v = c.voltage_V[keep] / cells_series
        i = c.current_A[keep] / strings_parallel
        q = c.charge_Ah[keep] / strings_parallel
        w = np.full(v.size, 1.0 / np.sqrt(v.size) if weighting == "equal" else 1.0)
        rest = np.zeros(v.size, bool)
        if use_rest and c.rest_voltage_V is not None:
            v = np.append(v, c.rest_voltage_V / cells_series)
            i, q = np.append(i, 0.0), np.append(q, 0.0)
            w, rest = np.append(w, w[0]), np.append(rest, True)
        parts.append((v, i, q, w, np.full(v.size, k), rest))
    cols = [np.concatenate([p[j] for p in parts]) for j in range(6)]
    if weighting == "equal":
        cols[3] = cols[3] / cols[3].mean()
    return _Stack(*cols, n_curves=len(curves))


def _spec(fixed, bounds, stack: _Stack, paper_mode: bool):
    """Resolve fixed values and bounds; returns (fixed dict, bounds dict)."""
    fixed = {k: float(v) for k, v in (fixed or {}).items()}
    bounds = {k: tuple(map(float, v)) for k, v in (bounds or {}).items()}
    allowed = set(PARAMETER_NAMES) | {CURRENT_SCALE}
    for name in list(fixed) + list(bounds):
        if name not in allowed:
            raise FitError(f"unknown parameter {name!r}; use one of {', '.join(PARAMETER_NAMES)}")
    b = dict(DEFAULT_BOUNDS)
    if paper_mode:
        b[CURRENT_SCALE] = PAPER_CURRENT_SCALE_BOUNDS
    b.update(bounds)
    # the model is undefined for q >= C: C must stay above the largest charge
    # (in paper mode the charge scales with the fitted current: use its upper bound)
    scale_hi = b[CURRENT_SCALE][1] if paper_mode else 1.0
    lo_c = stack.q_max * scale_hi * (1.0 + 1e-4)
    hi_c = b["C_Ah"][1] if "C_Ah" in bounds else stack.q_max * C_UPPER_FACTOR
    b["C_Ah"] = (max(b["C_Ah"][0], lo_c), max(hi_c, lo_c * 1.01))
    if "C_Ah" in fixed and fixed["C_Ah"] <= stack.q_max:
        raise FitError(f"fixed C_Ah = {fixed['C_Ah']:g} Ah is not above the "
                       f"{stack.q_max:g} Ah already discharged in the data (q >= C)")
    for name, (lo, hi) in b.items():
        if not lo < hi and not (name == CURRENT_SCALE and not paper_mode):
            raise FitError(f"bounds for {name} are empty: {lo:g} .. {hi:g}")
        if name in fixed and not lo <= fixed[name] <= hi and name in bounds:
            raise FitError(f"fixed {name} = {fixed[name]:g} is outside its bounds {lo:g}..{hi:g}")
    if not paper_mode:
        fixed[CURRENT_SCALE] = 1.0
    return fixed, b


class _Model:
    """Cell-voltage model over the stacked samples with a given set of free parameters.

    The basis columns of the linear parameters (1, -i, -K-term, exp-term) depend
    only on the nonlinear ones; they are computed once per nonlinear point.
    """

    def __init__(self, stack: _Stack, fixed: dict):
        self.s = stack
        self.fixed = fixed
        self.linear = [n for n in _LINEAR if n not in fixed]
        self.nonlinear = [n for n in _NONLINEAR if n not in fixed]
        self.free = self.linear + self.nonlinear
        self._basis_key = None
        self._weighted = not np.all(stack.weight == 1.0)
        self._weighted_voltage = stack.voltage * stack.weight
        self._lin_idx = [_LINEAR.index(n) for n in self.linear]
        self._fixed_lin = [(_LINEAR.index(n), self.fixed[n]) for n in _LINEAR
                           if n in self.fixed and self.fixed[n] != 0]

    def full(self, values: dict) -> dict:
        out = dict(self.fixed)
        out.update(values)
        return out

    def params(self, values: dict) -> tuple[CellParameters, float]:
        full = self.full(values)
        return CellParameters(*(full[n] for n in PARAMETER_NAMES)), full[CURRENT_SCALE]

    def basis(self, full: dict):
        """Basis columns (E0, R, K, A order) and intermediates at the nonlinear point (cached)."""
        key = (full["B_per_Ah"], full["C_Ah"], full[CURRENT_SCALE])
        if key != self._basis_key:
            b, c, scale = key
            q = self.s.charge * scale
            denom = c - q
            gain = c / denom
            pol = self.s.current * scale + q
            expo = np.exp(-b * q)
            phi = np.empty((q.size, 4))
            phi[:, 0] = 1.0
            np.multiply(self.s.current, -scale, out=phi[:, 1])
            np.multiply(gain, -pol, out=phi[:, 2])
            phi[:, 3] = expo
            self._basis_key = key
            self._basis_val = (q, denom, gain, pol, expo, phi)
        return self._basis_val

    def voltage(self, values):
        full = self.full(values)
        return self.basis(full)[5] @ np.array([full[n] for n in _LINEAR])

    def jacobian(self, values, names):
        """Analytic dV/d(name) for the named parameters, shape (n, len(names))."""
        full = self.full(values)
        q, denom, gain, pol, expo, phi = self.basis(full)
        out = np.empty((q.size, len(names)))
        for k, n in enumerate(names):
            if n in _LINEAR:
                out[:, k] = phi[:, _LINEAR.index(n)]
            elif n == "B_per_Ah":
                out[:, k] = -full["A_V"] * q * expo
            elif n == "C_Ah":
                out[:, k] = full["K_V_per_Ah"] * q * pol / denom ** 2
            else:  # current scale: i, i_f and q all scale with it
                dv_di = -full["R_ohm"] - full["K_V_per_Ah"] * gain
                dv_dq = (-full["K_V_per_Ah"] * (full["C_Ah"] * pol / denom ** 2 + gain)
                         - full["A_V"] * full["B_per_Ah"] * expo)
                out[:, k] = dv_di * self.s.current + dv_dq * self.s.charge
        return out

    # --- variable projection over the nonlinear parameters -------------------------
    def project(self, theta):
        """Linear solve for the linear parameters at nonlinear values ``theta``.

        Returns (values dict, weighted residual, weighted linear basis, its
        Gram-matrix Cholesky factor). The last call is cached: least_squares asks
        for the residual and the Jacobian at the same point.
        """
        key = np.asarray(theta, dtype=float).tobytes()
        if getattr(self, "_cache_key", None) == key:
            return self._cache
        values = dict(zip(self.nonlinear, theta))
        values.update({n: 0.0 for n in self.linear})
        basis = self.basis(self.full(values))[5]
        rhs = self._weighted_voltage
        if self._fixed_lin:
            base = sum(value * basis[:, k] for k, value in self._fixed_lin)
            rhs = rhs - (base * self.s.weight if self._weighted else base)
        if self.linear:
            phi = basis if len(self._lin_idx) == 4 else basis[:, self._lin_idx]
            if self._weighted:
                phi = phi * self.s.weight[:, None]
            coef, chol = _solve_normal(phi, rhs)
            values.update(zip(self.linear, coef))
            resid = phi @ coef - rhs
        else:
            phi, chol, resid = None, None, -rhs
        self._cache_key, self._cache = key, (values, resid, phi, chol)
        return self._cache

    def grid_costs(self, starts) -> np.ndarray:
        """Projected residual sum of squares at many nonlinear points in one batch."""
        starts = np.atleast_2d(starts)
        if CURRENT_SCALE in self.nonlinear or len(self._lin_idx) == 0:
            return np.array([float(r @ r) for r in map(self.varpro_residual, starts)])
        point = {n: starts[:, [k]] for k, n in enumerate(self.nonlinear)}
        b = point.get("B_per_Ah", self.fixed.get("B_per_Ah"))
        c = point.get("C_Ah", self.fixed.get("C_Ah"))
        q, i = self.s.charge, self.s.current
        gain = c / (c - q)
        phi = np.empty((starts.shape[0], q.size, 4))
        phi[:, :, 0] = 1.0
        phi[:, :, 1] = -i
        phi[:, :, 2] = -gain * (i + q)
        phi[:, :, 3] = np.exp(-b * q)
        rhs = np.broadcast_to(self._weighted_voltage, phi.shape[:2])
        if self._fixed_lin:
            base = sum(value * phi[:, :, k] for k, value in self._fixed_lin)
            rhs = rhs - base * self.s.weight
        phi = phi[:, :, self._lin_idx] * self.s.weight[None, :, None]
        gram = np.einsum("mni,mnj->mij", phi, phi)
        norm = np.sqrt(np.einsum("mii->mi", gram))
        norm[norm == 0] = 1.0
        gram = gram / (norm[:, :, None] * norm[:, None, :])
        proj = np.einsum("mni,mn->mi", phi, rhs) / norm
        coef = np.linalg.pinv(gram, hermitian=True) @ proj[:, :, None]
        resid = np.einsum("mni,mi->mn", phi, coef[:, :, 0] / norm) - rhs
        return np.einsum("mn,mn->m", resid, resid)

    def varpro_residual(self, theta):
        return self.project(theta)[1]

    def varpro_jacobian(self, theta):
        values, _, phi, chol = self.project(theta)
        jac = self.jacobian(values, self.nonlinear) * self.s.weight[:, None]
        if phi is None:
            return jac
        # Kaufman's approximation: P_perp dV/dtheta, P_perp = I - phi (phi^T phi)^-1 phi^T
        return jac - phi @ _cho_apply(chol, phi.T @ jac)


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
        inverse = np.linalg.pinv(gram)
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

    # ---- derived ---------------------------------------------------------------
    @property
    def fit_currents_A(self) -> tuple[float, ...]:
        """Mean cell current of each fitted curve [A] (times the scale in paper mode)."""
        return tuple(c.mean_current_A / self.strings_parallel * self.current_scale
                     for c in self.curves)

    def predicted_voltage(self, curve: Curve) -> np.ndarray:
        """Model pack voltage [V] at the samples of ``curve`` (paper mode: fitted current)."""
        s, p = self.cells_series, self.strings_parallel
        i = curve.current_A / p * self.current_scale
        return s * cell_voltage(self.parameters, i, curve.charge_Ah / p * self.current_scale)

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
        if self.bootstrap is not None:
            extra["bootstrap"] = {"names": list(PARAMETER_NAMES),
                                  "samples": np.round(self.bootstrap, 12).tolist()}
        return Battery(self.parameters, self.cells_series, self.strings_parallel,
                       covariance=self.covariance, fit_currents_A=self.fit_currents_A,
                       extra=extra)

    def to_dict(self) -> dict:
        """The ``fit --json`` document (keys are only ever added, never renamed)."""
        out = {
            "model": "tremblay",
            "cells_series": self.cells_series,
            "strings_parallel": self.strings_parallel,
            "parameters": self.parameters.as_dict(),
            "stderr": {n: self.stderr[n] for n in PARAMETER_NAMES},
            "ci95": {n: list(self.ci95[n]) for n in PARAMETER_NAMES},
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
        }
        if self.paper_mode:
            out["paper_mode"] = {
                "current_scale": self.current_scale,
                "fitted_currents_A": list(self.fit_currents_A),
                "measured_currents_A": [c.mean_current_A / self.strings_parallel
                                        for c in self.curves],
            }
        return out

    def report(self) -> str:
        """Plain-text summary: parameters with 95 % intervals, RMSE, warnings."""
        lines = [f"modified Shepherd model, per cell ({self.cells_series}S{self.strings_parallel}P "
                 f"pack), {len(self.curves)} curve(s), {self.n_samples} samples"]
        for n in PARAMETER_NAMES:
            value = getattr(self.parameters, n)
            if n in self.fixed:
                lines.append(f"  {n:12s} {value:12.6g}   (fixed)")
            else:
                lo, hi = self.ci95[n]
                lines.append(f"  {n:12s} {value:12.6g}   +/- {self.stderr[n]:.3g}   "
                             f"95% [{lo:.6g}, {hi:.6g}]")
        if self.paper_mode:
            lines.append(f"  fitted current scale {self.current_scale:.4f} "
                         f"(fitted/measured current)")
        lines.append(f"  RMSE {self.rmse_V * 1000:.2f} mV per cell "
                     f"({self.rmse_V * self.cells_series * 1000:.1f} mV pack)")
        lines += [f"  note: {m}" for m in self.notes]
        lines += [f"  warning: {m}" for m in self.warnings]
        return "\n".join(lines)

    def plot(self, ax=None, **kwargs):
        """Measured vs fitted voltage with residuals; returns the main Axes."""
        from .plot import plot_fit

        return plot_fit(self, ax=ax, **kwargs)


def guess_parameters(curves, cells_series: int = 1, strings_parallel: int = 1) -> dict:
    """Starting values from the data (per cell).

    C from the integrated Ah (a little above the largest discharged charge),
    E0 + A from the rest voltage when present (else the first sample), R + K from
    the voltage step at load start when a rest sample exists, B from the length of
    the initial exponential drop.
    """
    curves = [curves] if isinstance(curves, Curve) else list(curves)
    q_max = max(float(c.charge_Ah[-1]) for c in curves) / strings_parallel
    c0 = curves[0]
    v_first = c0.voltage_V[0] / cells_series
    i_first = c0.current_A[0] / strings_parallel
    rest = None if c0.rest_voltage_V is None else c0.rest_voltage_V / cells_series
    r_step = (rest - v_first) / i_first if rest is not None and i_first > 0 else 0.01
    return {"E0_V": (rest if rest is not None else v_first) - 0.05,
            "R_ohm": max(r_step, 0.0), "K_V_per_Ah": 0.01, "A_V": 0.05,
            "B_per_Ah": 10.0 / q_max, "C_Ah": q_max * 1.05}


def _starts(model: _Model, q_max: float, bounds: dict, guess: dict | None):
    """Grid of starting points for the nonlinear parameters (clipped into bounds)."""
    grid = {
        "B_per_Ah": [x / q_max for x in (2.0, 8.0, 30.0, 100.0)],
        "C_Ah": [q_max * f for f in (1.003, 1.03, 1.15)],
        CURRENT_SCALE: [1.0],
    }
    if guess:
        for n in model.nonlinear:
            if n in guess:
                grid[n] = [guess[n]] + grid[n]
    axes = [grid[n] for n in model.nonlinear]
    mesh = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(axes), -1).T if axes else \
        np.empty((1, 0))
    lo = np.array([bounds[n][0] for n in model.nonlinear])
    hi = np.array([bounds[n][1] for n in model.nonlinear])
    span = hi - lo
    return np.clip(mesh, lo + 1e-9 * span, hi - 1e-9 * span), lo, hi


def fit_battery(curves, *, cells_series: int = 1, strings_parallel: int = 1,
                fixed: dict | None = None, bounds: dict | None = None,
                guess: dict | None = None, paper_mode: bool = False, use_rest: bool = True,
                weighting: str = "equal", n_best: int = 1, bootstrap: int = 0,
                seed: int = 0) -> FitResult:
    """Fit the cell model to one or several discharges with shared parameters.

    Parameters
    ----------
    curves : Curve or sequence of Curve
        Pack-level measurements, each with its own (logged or commanded) current.
    cells_series, strings_parallel : int
        Pack configuration; the fit is per cell.
    fixed : dict, optional
        ``{name: value}`` parameters held fixed (e.g. ``{"E0_V": 4.1}``).
    bounds : dict, optional
        ``{name: (lower, upper)}`` overriding :data:`DEFAULT_BOUNDS`.
    guess : dict, optional
        Starting values for B_per_Ah / C_Ah tried before the built-in grid.
    paper_mode : bool
        Reproduce the paper's setup: E0 must be fixed, the current is scaled by a
        fitted factor (bounds ``current_scale``) together with R, K, A, B, C.
        The result is degenerate by construction and says so.
    use_rest : bool
        Use each curve's rest voltage (i = 0) as a data point.
    weighting : {"equal", "samples"}
        "equal" gives each curve the same total weight whatever its length.
    n_best : int
        Number of best grid starts refined by the variable-projection solver.
    bootstrap : int
        Number of moving-block bootstrap refits stored with the result (0 = none);
        they carry the parameter uncertainty into simulations without assuming
        the linearised covariance holds far from the optimum.
    seed : int
        Seed of the bootstrap.

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
    if cells_series < 1 or strings_parallel < 1:
        raise FitError("cells in series and strings in parallel must be at least 1")
    if weighting not in ("equal", "samples"):
        raise FitError(f"weighting must be 'equal' or 'samples', got {weighting!r}")
    stack = _stack(curves, cells_series, strings_parallel, use_rest, weighting)
    requested_fixed = dict(fixed or {})
    if paper_mode:
        if "E0_V" not in requested_fixed:
            raise FitError("paper mode needs E0 (the paper's only input): give --e0 V")
        if len(curves) != 1:
            raise FitError("paper mode fits one curve (the paper's setup); give one file")
    fixed, bnds = _spec(requested_fixed, bounds, stack, paper_mode)
    notes, warnings = [], []
    _resolve_e0_r(stack, fixed, notes, warnings)
    for c in curves:
        used = _thin(c.time_s.size, MAX_SAMPLES_PER_CURVE).size
        if used < c.time_s.size:
            notes.append(f"curve {c.name or '?'}: {used} of {c.time_s.size} samples used "
                         f"(evenly thinned in time)")
    model = _Model(stack, fixed)
    if not model.free:
        raise FitError("every parameter is fixed; nothing to fit")

    q_max = stack.q_max
    starts, lo, hi = _starts(model, q_max, bnds, guess)
    nfev = 0
    theta = np.empty(0)
    if model.nonlinear:
        # coarse to fine: search on a thinned copy of the data, refine on all of it
        coarse = _Model(_stack(curves, cells_series, strings_parallel, use_rest, weighting,
                               max_samples=SEARCH_SAMPLES_PER_CURVE), fixed)
        cost = coarse.grid_costs(starts)
        nfev += len(starts)
        best = None
        for k in np.argsort(cost)[:max(1, n_best)]:
            sol = _varpro_solve(coarse, starts[k], lo, hi)
            nfev += sol.nfev
            if best is None or sol.cost < best.cost:
                best = sol
        sol = _varpro_solve(model, best.x, lo, hi)
        nfev += sol.nfev
        theta = sol.x
    values = dict(model.project(theta)[0])
    values = _polish(model, values, bnds)
    nfev += 1

    params, scale = model.params(values)
    residual = model.voltage(values) - stack.voltage
    if not np.all(np.isfinite(residual)):
        raise FitError("the fit reached a region where the model is undefined (q >= C); "
                       "check the data and the bounds on C_Ah")
    w = stack.weight
    jac = model.jacobian(values, model.free) * w[:, None]
    svd = equilibrated_svd(jac)
    cov_free, dof_eff = _covariance(svd, residual * w, stack)
    names_all = list(PARAMETER_NAMES)
    cov = np.zeros((6, 6))
    idx = [names_all.index(n) for n in model.free if n in names_all]
    sub = [k for k, n in enumerate(model.free) if n in names_all]
    cov[np.ix_(idx, idx)] = cov_free[np.ix_(sub, sub)]
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    corr[~np.isfinite(corr)] = 0.0
    np.fill_diagonal(corr, 1.0)
    t_crit = float(stdtrit(max(dof_eff, 1.0), 0.975))  # Student t quantile
    stderr, ci95 = {}, {}
    for k, n in enumerate(PARAMETER_NAMES):
        v = float(getattr(params, n))
        if n in fixed:
            stderr[n], ci95[n] = 0.0, (v, v)
        else:
            e = float(sd[k]) if np.isfinite(sd[k]) else float("nan")
            stderr[n], ci95[n] = e, (v - t_crit * e, v + t_crit * e)

    ident = analyse(jac, model.free, values, bnds, paper_mode=paper_mode, svd=svd)
    warnings += ident.warnings
    measured = ~stack.is_rest
    rmse = float(np.sqrt(np.mean(residual[measured] ** 2)))
    samples = None
    if bootstrap:
        samples = _bootstrap(model, values, residual, bnds, int(bootstrap), seed)
    return FitResult(
        parameters=params, stderr=stderr, ci95=ci95, covariance=cov, correlation=corr,
        free=list(model.free), fixed={n: v for n, v in fixed.items()}, bounds=bnds,
        rmse_V=rmse, n_samples=int(measured.sum()), warnings=warnings, notes=notes,
        identifiability=ident, curves=curves, cells_series=int(cells_series),
        strings_parallel=int(strings_parallel), current_scale=float(scale),
        paper_mode=paper_mode, elapsed_s=time.perf_counter() - t_start, nfev=nfev,
        n_starts=len(starts), bootstrap=samples,
    )


def _lag1_correlation(residual, stack: _Stack) -> float:
    """Lag-1 autocorrelation of the residuals within each curve, pooled, in [0, 0.999]."""
    num = den = 0.0
    for k in range(stack.n_curves):
        r = residual[(stack.curve == k) & ~stack.is_rest]
        if r.size > 2:
            num += float(np.dot(r[1:], r[:-1]))
            den += float(np.dot(r, r))
    return min(max(num / den if den > 0 else 0.0, 0.0), 0.999)


def _block_length(residual, stack: _Stack) -> int:
    """Block length of the moving-block bootstrap: the residuals' correlation length."""
    rho = _lag1_correlation(residual, stack)
    return max(1, int(np.ceil((1 + rho) / (1 - rho))))


def _bootstrap(model: _Model, values: dict, residual, bounds: dict, n: int, seed: int):
    """Parameter sets refitted to the fit plus block-resampled residuals.

    Circular moving-block bootstrap of the residuals within each curve (blocks as
    long as the residuals' correlation length, so the smooth model-misfit pattern
    is resampled, not only the noise); each replica is refitted from the optimum.
    Returns an array (n, 6) in PARAMETER_NAMES order; fixed parameters constant.
    """
    from dataclasses import replace as _replace

    rng = np.random.default_rng(seed)
    stack = model.s
    fitted = stack.voltage + residual
    block = _block_length(residual, stack)
    theta0 = np.array([values[k] for k in model.nonlinear])
    lo = np.array([bounds[k][0] for k in model.nonlinear])
    hi = np.array([bounds[k][1] for k in model.nonlinear])
    out = np.empty((n, 6))
    for b in range(n):
        voltage = fitted.copy()
        for k in range(stack.n_curves):
            idx = np.flatnonzero((stack.curve == k) & ~stack.is_rest)
            m = idx.size
            length = min(block, max(1, m // 4))
            starts = rng.integers(0, m, int(np.ceil(m / length)))
            pick = ((starts[:, None] + np.arange(length)[None, :]) % m).ravel()[:m]
            voltage[idx] = fitted[idx] - residual[idx][pick]
        replica = _Model(_replace(stack, voltage=voltage), model.fixed)
        theta = _varpro_solve(replica, theta0, lo, hi).x if model.nonlinear else theta0
        vals = _polish(replica, dict(replica.project(theta)[0]), bounds)
        params, _ = replica.params(vals)
        out[b] = params.as_array()
    return out


@dataclass
class _Solution:
    x: np.ndarray
    cost: float
    nfev: int


def _varpro_solve(model: _Model, theta0, lo, hi, max_iter: int = 200) -> _Solution:
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
        if decrease <= 1e-12 * cost or np.all(moved <= 1e-10 * (np.abs(x) + 1e-10)):
            break
    model.varpro_residual(x)  # leave the cache at the solution
    return _Solution(x=x, cost=cost, nfev=nfev)


def _resolve_e0_r(stack: _Stack, fixed: dict, notes: list, warnings: list):
    """Apply the documented resolution of the E0/R collinearity (see module docstring)."""
    if "E0_V" in fixed or "R_ohm" in fixed:
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
        "other currents miss the ohmic drop. Fix: give --e0 V (e.g. from a low-rate curve), "
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

    sol = least_squares(resid, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac",
                        ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=500)
    if not np.isfinite(sol.cost):
        raise FitError("bounded least squares did not converge; check the data and bounds")
    out = dict(values)
    out.update(zip(model.free, sol.x))
    return out


def _covariance(svd, resid: np.ndarray, stack: _Stack):
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
