"""The numerical core of a fit: stacked samples, the variable-projection problem of
any model family, its bounded solver, polishing, covariance and block bootstrap.

See :mod:`dischargelab.fit` for the method and its references.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..cell import CellParameters
from ..errors import FitError
from ..models import Family, Samples

#: Name of the current-scale parameter fitted in paper mode.
CURRENT_SCALE = "current_scale"

#: Bounds of the fitted/measured current ratio in paper mode (the paper's fits
#: came within 2.5-5 % of the measured current). C is bounded below by the
#: largest charge times the upper bound.
PAPER_CURRENT_SCALE_BOUNDS = (0.9, 1.1)


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
           max_samples=MAX_SAMPLES_PER_CURVE, virtual_temperature=None) -> Samples:
    """Cell-level samples of all curves (thinned), rest points appended as i = 0, q = 0.

    ``virtual_temperature``: per curve, a simulated cell temperature at its samples
    [degC] used where no temperature was logged (``has_temperature`` stays False)."""
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
        if has_temp:
            temp = c.temperature_C[keep]
        elif virtual_temperature is not None:
            temp = np.asarray(virtual_temperature[k], dtype=float)[keep]
        else:
            temp = np.full(v.size, ambient)
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


#: Bootstrap methods: ``"linearised"`` moves each replica by one Gauss-Newton step from
#: the optimum (exact for the linear parameters, the delta method for the others);
#: ``"refit"`` refits every replica from the optimum.
BOOTSTRAP_METHODS = ("linearised", "refit")


def _resampled_residuals(residual, stack: Samples, n: int, seed: int):
    """``n`` circular moving-block resamples of the residuals within each curve (0 at
    the rest samples), as an (n, samples) array."""
    rng = np.random.default_rng(seed)
    block = _block_length(residual, stack)
    out = np.zeros((n, residual.size))  # rest samples: the replica keeps the model's value
    curves = [np.flatnonzero((stack.curve == k) & ~stack.is_rest) for k in range(stack.n_curves)]
    for b in range(n):
        for idx in curves:
            m = idx.size
            length = min(block, max(1, m // 4))
            starts = rng.integers(0, m, int(np.ceil(m / length)))
            pick = ((starts[:, None] + np.arange(length)[None, :]) % m).ravel()[:m]
            out[b, idx] = residual[idx][pick]
    return out


def _bootstrap(model: _Model, values: dict, residual, bounds: dict, n: int, seed: int,
               progress=None, method: str = "linearised"):
    """Parameter sets fitted to the fit plus block-resampled residuals.

    Circular moving-block bootstrap of the residuals within each curve (blocks as
    long as the residuals' correlation length, so the smooth model-misfit pattern
    is resampled, not only the noise) [Efron & Tibshirani 1993, ch. 8.6]. Each
    replica's data are the fitted voltage minus a resampled residual series.

    * ``"linearised"`` (default): each replica's parameters are the optimum plus one
      Gauss-Newton step, ``-(W J)^+ W r_b`` with the Jacobian ``J`` of the free
      parameters at the optimum (parameters at a bound held there, others clipped
      into their bounds). Exact for the linear parameters (E0, R, K, A; ecm's OCV
      and resistances) and first-order for the others: the spread of small
      perturbations, at the cost of one pseudo-inverse.
    * ``"refit"``: each replica is refitted from the optimum (variable projection),
      about one fit per replica.

    Returns an array (n, parameters) in the family's order; fixed parameters constant.
    """
    from dataclasses import replace as _replace

    if method not in BOOTSTRAP_METHODS:
        raise FitError(f"bootstrap method must be one of {', '.join(BOOTSTRAP_METHODS)}, "
                       f"got {method!r}")
    stack = model.s
    fitted = stack.voltage + residual
    resampled = _resampled_residuals(residual, stack, n, seed)
    out = np.empty((n, len(model.family.names)))
    if method == "linearised":
        free = list(model.free)
        x0 = np.array([values[k] for k in free])
        lo = np.array([bounds[k][0] for k in free])
        hi = np.array([bounds[k][1] for k in free])
        span = np.where(np.isfinite(hi - lo), hi - lo, np.abs(x0) + 1.0)
        moving = (x0 > lo + 1e-9 * span) & (x0 < hi - 1e-9 * span)
        w = stack.weight
        jac = model.jacobian(values, [k for k, m in zip(free, moving) if m]) * w[:, None]
        norm = np.linalg.norm(jac, axis=0)
        norm[norm == 0] = 1.0
        step = -np.linalg.pinv(jac / norm, rcond=1e-10) @ (resampled * w).T / norm[:, None]
        for b in range(n):
            x = x0.copy()
            x[moving] += step[:, b]
            x = np.clip(x, lo, hi)
            params, _ = model.params(dict(values, **dict(zip(free, x))))
            out[b] = params.as_array(model.family.names)
            if progress is not None:
                progress(b + 1, n)
        return out
    theta0 = np.array([values[k] for k in model.nonlinear])
    lo = np.array([bounds[k][0] for k in model.nonlinear])
    hi = np.array([bounds[k][1] for k in model.nonlinear])
    for b in range(n):
        voltage = fitted - resampled[b]
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
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            jac = model.varpro_jacobian(x)
            grad = jac.T @ r
            hess = jac.T @ jac
        if not (np.all(np.isfinite(grad)) and np.all(np.isfinite(hess))):
            break  # a sample at the empty cell: the last defined point is the solution
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
