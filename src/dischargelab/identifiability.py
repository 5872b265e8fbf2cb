"""What the data do and do not determine: Jacobian SVD, correlations, bounds.

Turns the Jacobian of a fit (columns = free parameters) into plain-language
warnings. Three checks:

1. **Degenerate directions**: singular values of the column-equilibrated
   Jacobian below ``DEGENERATE_RATIO`` times the largest. The right singular
   vector says which parameters move together; known patterns get a specific
   explanation and cure (E0/R collinearity for one constant current; the
   R, K, B, C, current scaling when the current is fitted).
2. **Correlations** of the parameter estimates above ``CORRELATION_LIMIT``.
3. **Parameters at a bound**: the optimum is then set by the bound, not the data.

References
----------
.. [1] paper section 4.4 (trade-off between R and K; bounds set by trial and error).
.. [2] DESIGN.md, "Facts any implementation must respect".
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Relative singular value below which a direction counts as undetermined.
DEGENERATE_RATIO = 1e-6
#: Relative singular value below which a direction counts as poorly determined.
WEAK_RATIO = 1e-3
#: Absolute correlation above which a pair of parameters is reported.
CORRELATION_LIMIT = 0.95
#: Relative distance to a bound (of the bound span) that counts as "at the bound".
AT_BOUND_TOLERANCE = 1e-6

_CURRENT = "current_scale"


@dataclass
class Identifiability:
    """Diagnostics of a fit's Jacobian (free parameters only)."""

    names: list
    singular_values: np.ndarray       # relative to the largest, descending
    directions: list                  # [{name: component}] for weak/degenerate directions
    correlation: np.ndarray           # among free parameters
    strong_pairs: list                # [(name_a, name_b, rho)]
    at_bounds: list                   # [(name, "lower"|"upper", bound)]
    warnings: list = field(default_factory=list)

    @property
    def condition_number(self) -> float:
        """Ratio of largest to smallest singular value (inf if degenerate)."""
        smallest = self.singular_values[-1] if self.singular_values.size else 1.0
        return float("inf") if smallest == 0 else float(1.0 / smallest)

    def to_dict(self) -> dict:
        return {
            "parameters": list(self.names),
            "relative_singular_values": [float(x) for x in self.singular_values],
            "condition_number": self.condition_number,
            "weak_directions": [{k: float(v) for k, v in d.items()} for d in self.directions],
            "strong_correlations": [[a, b, float(r)] for a, b, r in self.strong_pairs],
            "at_bounds": [[n, side, float(b)] for n, side, b in self.at_bounds],
        }


def equilibrated_svd(jacobian):
    """SVD of the Jacobian with unit-norm columns, via a QR factor (no n x n work).

    Returns (column norms, singular values descending, right singular vectors
    as rows); ``J = U diag(sv) Vt diag(norms)``.
    """
    jac = np.asarray(jacobian, dtype=float)
    norm = np.linalg.norm(jac, axis=0)
    norm[norm == 0] = 1.0
    r = np.linalg.qr(jac / norm, mode="r")
    _, sv, vt = np.linalg.svd(r)
    return norm, sv, vt


def analyse(jacobian, names, values: dict, bounds: dict, *, paper_mode: bool = False,
            svd=None) -> Identifiability:
    """Diagnose a fit from its (weighted) Jacobian.

    Parameters
    ----------
    jacobian : ndarray, shape (n_samples, n_free)
        dV/dparameter at the optimum, columns in ``names`` order.
    names : list of str
        Free parameter names.
    values : dict
        Parameter values at the optimum.
    bounds : dict
        ``{name: (lower, upper)}``.
    paper_mode : bool
        The current was fitted (adds the scaling-degeneracy warning even when a
        bound happens to pin it).
    svd : tuple, optional
        :func:`equilibrated_svd` of ``jacobian`` if already computed.
    """
    names = list(names)
    jac = np.asarray(jacobian, dtype=float)
    warnings: list[str] = []
    if jac.shape[1] == 0:
        return Identifiability(names, np.empty(0), [], np.empty((0, 0)), [], [], warnings)
    norm, sv, vt = equilibrated_svd(jac) if svd is None else svd
    zero_cols = [n for n, x in zip(names, np.linalg.norm(jac, axis=0)) if x == 0]
    rel = sv / sv.max() if sv.max() > 0 else sv
    directions = []
    degenerate_found = set()
    for k in np.flatnonzero(rel < WEAK_RATIO):
        vec = vt[k] / np.abs(vt[k]).max()
        involved = {n: float(c) for n, c in zip(names, vec) if abs(c) > 0.05}
        directions.append(involved)
        kind = _explain(involved, rel[k], warnings)
        degenerate_found.add(kind)
    for n in zero_cols:
        warnings.append(f"{n} has no effect on the fitted curve at all: fix it to a known value.")

    # correlations from the equilibrated normal matrix (pseudo-inverse)
    keep = rel > DEGENERATE_RATIO
    inv = np.where(keep, 1.0 / np.where(keep, sv, 1.0) ** 2, 0.0)
    cov = (vt.T * inv) @ vt
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    corr[~np.isfinite(corr)] = 0.0
    np.fill_diagonal(corr, 1.0)
    pairs = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            if abs(corr[a, b]) > CORRELATION_LIMIT:
                pairs.append((names[a], names[b], float(corr[a, b])))
    if pairs and not degenerate_found - {None}:
        text = ", ".join(f"{a}/{b} (rho = {r:+.3f})" for a, b, r in pairs)
        warnings.append(
            f"strongly correlated estimates: {text}. The data fix a combination of these, not "
            f"each one; their individual values and predictions far from the fitted currents are "
            f"uncertain. Add a curve at another current, or fix one of them.")

    at_bounds = []
    for n in names:
        lo, hi = bounds[n]
        span = hi - lo
        v = values[n]
        for side, bound in (("lower", lo), ("upper", hi)):
            if abs(v - bound) <= AT_BOUND_TOLERANCE * span + 1e-12 * abs(bound):
                at_bounds.append((n, side, bound))
                if n == "C_Ah" and side == "upper":
                    warnings.append(
                        f"C_Ah ran to its upper bound {bound:g} Ah: the data do not reach the "
                        f"end-of-discharge knee, so the capacity is not determined. Fix it with "
                        f"--fix C_Ah=<Ah> (e.g. the nominal capacity) or use a discharge that "
                        f"reaches the cutoff.")
                    continue
                warnings.append(
                    f"{n} = {v:.6g} sits at its {side} bound {bound:g}: the bound, not the data, "
                    f"sets it. Widen it with --bound {n}=LOW:HIGH or fix it to a known value.")
    if paper_mode and "scaling" not in degenerate_found:
        warnings.append(_SCALING_TEXT)
    return Identifiability(names, rel, directions, corr, pairs, at_bounds, warnings)


def capacity_at_delivered_charge(capacity_Ah: float) -> str:
    """What a capacity at its lower bound means: the charge the fitted runs delivered.

    That bound is physics, not a limit of the search: a cell cannot hold less than it
    delivered. The fit wanted a smaller capacity, so the model's capacity is the charge
    drawn by the run that drew the most (the slowest, which drained the cell furthest).
    """
    return (f"C_Ah = {capacity_Ah:.6g} Ah: the capacity equals the charge the fitted runs "
            f"delivered, its lower limit (a cell cannot hold less than it delivered). The "
            f"slowest run drained the cell to the end of what the model can hold; the capacity "
            f"is that measured charge, not a fitted extrapolation beyond it")


_SCALING_TEXT = (
    "the current and C, K, R, B scale together (i -> l*i, C -> l*C, K -> K/l, R -> R/l, "
    "B -> B/l leaves the voltage curve unchanged): one curve cannot tell the capacity C nor the "
    "current, so the 'fitted current' is set by the start and the bounds and is NOT a "
    "validation. Use the logged or commanded current (drop --paper-mode).")


def _explain(involved: dict, ratio: float, warnings: list) -> str | None:
    """Append a plain-language warning for one weak direction; return its kind."""
    keys = set(involved)
    strength = "not determined" if ratio < DEGENERATE_RATIO else "poorly determined"
    if _CURRENT in keys:
        warnings.append(_SCALING_TEXT)
        return "scaling"
    if keys <= {"E0_V", "R_ohm", "K_V_per_Ah", "A_V"} and {"E0_V", "R_ohm"} <= keys:
        warnings.append(
            f"E0 and R are {strength} separately: with one constant current only E0 - R*i is "
            f"fixed by the curve. Give --e0 V (e.g. from a low-rate curve), keep the rest voltage "
            f"before the load in the file, or add a curve at a second current.")
        return "e0_r"
    text = ", ".join(f"{n} ({c:+.2f})" for n, c in sorted(involved.items()))
    warnings.append(
        f"a combination of parameters is {strength} by the data (relative singular value "
        f"{ratio:.1e}): {text} can change together with almost no change of the curve. "
        f"Fix one of them or add a curve at another current.")
    return "other"


#: Plausible per-cell rest voltage at full charge [V] of lithium cells (any chemistry).
FULL_CELL_VOLTAGE_RANGE_V = (3.0, 4.5)

#: A fitted capacity above this multiple of the discharged charge is implausible.
CAPACITY_EXCESS_FACTOR = 1.5

#: RMSE above this fraction of the voltage span: the model does not follow the data.
RMSE_SPAN_FRACTION = 0.05


def plausibility(family, params, ci95: dict, fixed: dict, data, rmse_V: float) -> list[str]:
    """Plain-language warnings when fitted values are physically implausible.

    Checks: the rest voltage at full charge (the model at q = 0, i = 0) against
    the range of lithium cells; negative resistances; a capacity far above the
    charge the data discharged; an RMSE large against the voltage span. (Intervals
    that span zero are reported by :func:`undetermined`: a value the data do not
    fix is uncertain, not implausible.)

    Parameters
    ----------
    family : models.Family
    params : mapping
        Fitted per-cell values.
    ci95 : dict
        ``{name: (low, high)}``.
    fixed : dict
        Parameters held fixed (not checked for intervals).
    data : models.Samples
        The fitted samples (per cell).
    rmse_V : float
        Fit RMSE per cell [V].
    """
    out = []
    state = family.initial_state(dict(params), temperature_C=data.ambient_C)
    full = float(np.asarray(family.voltage(params, state, 0.0)).ravel()[0])
    lo, hi = FULL_CELL_VOLTAGE_RANGE_V
    if not lo <= full <= hi:
        out.append(f"the fitted cell rests at {full:.2f} V when full, outside the {lo:g}-{hi:g} "
                   "V of lithium cells: check the cell count (cells in series) and the voltage "
                   "units")
    if "E0_V" in params and not 2.0 <= float(params["E0_V"]) <= 5.0:
        out.append(f"E0 = {float(params['E0_V']):.3g} V is not a cell voltage: the parameters fit "
                   "the curve but mean nothing physically; try model='ecm' (a free-form "
                   "open-circuit voltage) or fit fewer rates at once")
    for p in family.parameters:
        value = float(params[p.name])
        if p.unit == "ohm" and value < 0:
            out.append(f"{p.name} = {value:.3g} ohm is a negative resistance: the data cannot "
                       "separate it; fix it or add a curve at another current")
    q_max = data.q_max
    if "C_Ah" in params and float(params["C_Ah"]) > CAPACITY_EXCESS_FACTOR * q_max:
        out.append(f"capacity C = {float(params['C_Ah']):.3g} Ah is far above the {q_max:.3g} Ah "
                   "the data discharged: the curve does not reach the knee, so the capacity is "
                   "a guess; discharge to the cutoff or fix C_Ah to the rated capacity")
    span = float(np.ptp(data.voltage[~data.is_rest])) if (~data.is_rest).any() else 0.0
    if span > 0 and rmse_V > RMSE_SPAN_FRACTION * span:
        out.append(f"the fit misses the data by {rmse_V * 1000:.0f} mV RMS, "
                   f"{100 * rmse_V / span:.0f} % of the voltage span: the model does not follow "
                   "this curve; check the data or try another model")
    return out


#: Ratio of the upper to the lower end of a positive parameter's 95 % interval beyond
#: which it is reported undetermined (``e**2``: a symmetric interval would reach zero).
UNDETERMINED_SPAN = float(np.exp(2.0))


def undetermined(family, params, ci95: dict, fixed: dict) -> list[str]:
    """Warnings for positive parameters the data do not determine.

    Their 95 % interval is on a log scale (it stays positive): a parameter whose
    interval spans more than a factor ``e**2`` (about 7.4, i.e. a relative standard
    error above ``1 / t``, where a symmetric interval would reach zero) is undetermined.
    """
    out = []
    for p in family.parameters:
        if p.name in fixed or p.lower < 0 or p.limit_note:
            continue
        low, high = ci95.get(p.name, (np.nan, np.nan))
        value = float(params[p.name])
        if not (np.isfinite(low) and np.isfinite(high) and value > 0):
            continue
        if low <= 0 or high / low > UNDETERMINED_SPAN:
            out.append(f"{p.name}'s 95 % interval [{low:.3g}, {high:.3g}] {p.unit} spans more "
                       f"than a factor {UNDETERMINED_SPAN:.1f}: the data do not determine it; "
                       "add a curve at another current (or log the rest voltage before the "
                       "load) or fix it")
    return out
