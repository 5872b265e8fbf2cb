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

import numpy as np
from scipy.special import stdtrit

from ..cell import CellParameters
from ..discharge import Curve
from ..errors import DataError, FitError
from ..identifiability import Identifiability, analyse, equilibrated_svd, plausibility, undetermined
from ..models import Family, Samples, get_family
from ..models.base import HELD_AT_AMBIENT_HEAT_CAPACITY, MIN_HEATING_K, fit_lumped_thermal
from .problem import (
    COARSE_FTOL,
    CURRENT_SCALE,
    MAX_SAMPLES_PER_CURVE,
    SEARCH_SAMPLES_PER_CURVE,
    _bootstrap,
    _covariance,
    _defined_start,
    _Model,
    _polish,
    _resolve_e0_r,
    _spec,
    _stack,
    _thin,
    _varpro_solve,
)
from .result import FitResult


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
    from ..models import FAMILIES

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

    from ..uncertainty import extrapolation_growth, held_out_posterior

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
    from ..errors import SimulationError
    from ..simulate import simulate_current

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


__all__ = ["Curve", "FitResult", "fit_battery", "guess_parameters", "held_out_error",
           "choose_model", "selection_score", "AUTO", "CURRENT_SCALE", "HELD_OUT_TAIL"]
