"""Fitting one model family: starts, the bounded variable-projection fit, its
thermal parameters and identifiability.

See :mod:`dischargelab.fit` for the method and its references.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.special import stdtrit

from ..cell import CellParameters
from ..discharge import Curve
from ..errors import FitError
from ..identifiability import (
    Identifiability,
    analyse,
    capacity_at_delivered_charge,
    equilibrated_svd,
    plausibility,
    undetermined,
)
from ..models import Family, Samples, get_family
from ..models.base import (
    HELD_AT_AMBIENT_HEAT_CAPACITY,
    MAX_THERMAL_RESISTANCE,
    MIN_HEATING_K,
    fit_lumped_thermal,
)
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


#: Local minima of the capacity scan refined (the lowest first).
SCAN_MINIMA_REFINED = 3


def _scan_capacity(model: _Model, best, lo, hi):
    """The searched solution ``best``, or a lower one refined from the lowest local minima
    of the cost over the family's :attr:`~dischargelab.models.base.Family.capacity_scan`
    around it (the other parameters held); with the number of model evaluations spent."""
    factors = model.family.capacity_scan
    if not factors or "C_Ah" not in model.nonlinear:
        return best, 0
    k = model.nonlinear.index("C_Ah")
    trials = np.repeat(best.x[None, :], len(factors), axis=0)
    trials[:, k] = np.clip(best.x[k] * np.asarray(factors), lo[k], hi[k])
    cost = 0.5 * model.grid_costs(trials)
    nfev = len(factors)
    padded = np.r_[np.inf, cost, np.inf]
    minima = np.flatnonzero((cost < padded[:-2]) & (cost <= padded[2:]) & np.isfinite(cost))
    for j in minima[np.argsort(cost[minima])][:SCAN_MINIMA_REFINED]:
        if trials[j, k] == best.x[k]:
            continue
        sol = _varpro_solve(model, trials[j], lo, hi, ftol=COARSE_FTOL)
        nfev += sol.nfev
        if sol.cost < best.cost:
            best = sol
    return best, nfev


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


def several_rates(curves) -> bool:
    """Two or more curves whose mean currents differ by 20 % or more."""
    currents = [c.mean_current_A for c in curves]
    return len(curves) >= 2 and max(currents) >= 1.2 * min(currents)


#: A load current is steady when its coefficient of variation (over the samples above
#: half the median current) is below this [-].
STEADY_CURRENT_CV = 0.25


def steady_current(current_A) -> bool:
    """True when a load current is a near-constant drain (:data:`STEADY_CURRENT_CV`)."""
    i = np.asarray(current_A, dtype=float)
    load = i[i > 0.5 * np.median(i)] if i.size else i
    return bool(load.size > 1 and np.std(load) < STEADY_CURRENT_CV * np.mean(load))


def one_steady_rate(curves) -> bool:
    """True when the curves are near-constant drains at one rate (not :func:`several_rates`):
    data that cannot show a cell's dynamics (``Family.steady_fixed``)."""
    curves = [curves] if isinstance(curves, Curve) else list(curves)
    return bool(curves) and not several_rates(curves) and \
        all(steady_current(c.current_A) for c in curves)


def steady_dynamics(curves, model, fixed: dict | None, bounds: dict | None):
    """``(fixed, note)``: the family's ``steady_fixed`` parameters added to ``fixed`` when
    the curves are :func:`one_steady_rate` (those the caller fixes or bounds excepted),
    with the note that says so; ``(fixed, None)`` otherwise."""
    family = get_family(model)
    held = {n: v for n, v in family.steady_fixed.items()
            if n not in (fixed or {}) and n not in (bounds or {})}
    if not held or not one_steady_rate(curves):
        return fixed, None
    absent = {n: v for n, v in held.items() if n not in family.steady_prior}
    note = (f"{', '.join(absent)} held at {', '.join(f'{v:g}' for v in absent.values())} "
            f"(effect absent): one constant current cannot show the cell's dynamics (time "
            f"under load and charge drawn are proportional, so the OCV takes them up); fit two "
            f"or more rates or a varying current to fit them")
    return dict(held, **(fixed or {})), note


#: Relative decrease of the cost below which a warm-started fit stops (the solver's
#: default: converged to round-off).
WARM_FTOL = 1e-12


def fit_family(curves, *, cells_series: int = 1, strings_parallel: int = 1,
                fixed: dict | None = None, bounds: dict | None = None,
                guess: dict | None = None, paper_mode: bool = False, use_rest: bool = True,
                weighting: str = "equal", n_best: int | None = None, bootstrap: int = 0,
                seed: int = 0, model="shepherd", progress=None, start: dict | None = None,
                max_samples: int = MAX_SAMPLES_PER_CURVE,
                bootstrap_method: str = "linearised", cooling: str | None = "still-air",
                chemistry: str | None = None, warm_ftol: float = WARM_FTOL) -> FitResult:
    """Fit one model family (``model`` a family name, not ``"auto"``) without its
    held-out model error (:func:`dischargelab.fit.heldout.held_out_error`); see
    :func:`dischargelab.fit.fit_battery` for the parameters.

    ``start`` (values of the nonlinear parameters, e.g. a fit to more of the same
    data) skips the multi-start search and refines from there: a warm start, which
    stops when a step lowers the cost by less than ``warm_ftol`` of it.
    ``max_samples`` thins each curve to at most that many samples. A thermal family
    fitted without a logged temperature gets the thermal prior of ``cooling`` and
    ``chemistry`` (:func:`fit_self_heating`; ``cooling``
    None holds the cell at the ambient instead). A family's ``steady_fixed`` parameters
    are held absent on :func:`one_steady_rate` data (:func:`steady_dynamics`)."""
    chosen = set(fixed or {}) | set(bounds or {})
    fixed, steady_note = steady_dynamics(curves, model, fixed, bounds)
    if steady_note is not None:
        kw = dict(cells_series=cells_series, strings_parallel=strings_parallel, bounds=bounds,
                  guess=guess, paper_mode=paper_mode, use_rest=use_rest, weighting=weighting,
                  n_best=n_best, seed=seed, model=model, progress=progress, start=start,
                  max_samples=max_samples, bootstrap_method=bootstrap_method,
                  cooling=cooling, chemistry=chemistry, warm_ftol=warm_ftol)
        family = get_family(model)
        prior = {n: v for n, v in family.steady_prior.items() if n not in chosen}
        res = fit_family(curves, fixed=fixed, bootstrap=0 if prior else bootstrap, **kw)
        notes = [steady_note]
        if prior:
            # the parameters the steady data do determine (the load step's series
            # resistance) come from the fit without the prior, which could take their place
            carried = {n: float(res.parameters[n]) for n in family.steady_prior_carries
                       if n not in chosen}
            res = fit_family(curves, fixed={**fixed, **prior, **carried}, bootstrap=bootstrap,
                             **dict(kw, start=start or res.parameters.as_dict()))
            notes.append(family.steady_prior_note + "".join(
                f"; {n} = {v:.4g} from the fit without it" for n, v in carried.items()))
        res.notes[:0] = notes
        return res
    if needs_prior(curves, model, cooling):
        return fit_self_heating(
            curves, cooling=cooling, chemistry=chemistry, cells_series=cells_series,
            strings_parallel=strings_parallel, fixed=fixed, bounds=bounds, guess=guess,
            paper_mode=paper_mode, use_rest=use_rest, weighting=weighting, n_best=n_best,
            bootstrap=bootstrap, seed=seed, model=model, progress=progress, start=start,
            max_samples=max_samples, bootstrap_method=bootstrap_method, warm_ftol=warm_ftol)
    return fit_once(curves, cells_series=cells_series, strings_parallel=strings_parallel,
                    fixed=fixed, bounds=bounds, guess=guess, paper_mode=paper_mode,
                    use_rest=use_rest, weighting=weighting, n_best=n_best, bootstrap=bootstrap,
                    seed=seed, model=model, progress=progress, start=start,
                    max_samples=max_samples, bootstrap_method=bootstrap_method,
                    warm_ftol=warm_ftol)


def fit_once(curves, *, cells_series: int = 1, strings_parallel: int = 1,
             fixed: dict | None = None, bounds: dict | None = None,
             guess: dict | None = None, paper_mode: bool = False, use_rest: bool = True,
             weighting: str = "equal", n_best: int | None = None, bootstrap: int = 0,
             seed: int = 0, model="shepherd", progress=None, start: dict | None = None,
             max_samples: int = MAX_SAMPLES_PER_CURVE, bootstrap_method: str = "linearised",
             virtual_temperature=None, thermal_prior: dict | None = None,
             warm_ftol: float = WARM_FTOL) -> FitResult:
    """One fit of one family (see :func:`fit_family`); ``virtual_temperature`` (per
    curve, a simulated cell temperature [degC]) stands in for the unlogged temperature,
    and ``thermal_prior`` (``Cth_J_per_K``, ``Rth_K_per_W``, ``note``) gives a thermal
    family fitted without a logged temperature its heat capacity and resistance."""
    t_start = time.perf_counter()
    curves = [curves] if isinstance(curves, Curve) else list(curves)
    if not curves:
        raise FitError("no discharge curves to fit")
    family = get_family(model)
    if cells_series < 1 or strings_parallel < 1:
        raise FitError("cells in series and strings in parallel must be at least 1")
    if weighting not in ("equal", "samples"):
        raise FitError(f"weighting must be 'equal' or 'samples', got {weighting!r}")
    stack = _stack(curves, cells_series, strings_parallel, use_rest, weighting,
                   max_samples=max_samples, virtual_temperature=virtual_temperature)
    requested_fixed = dict(fixed or {})
    if paper_mode:
        if "E0_V" not in requested_fixed:
            raise FitError("paper mode needs E0 (the paper's only input): give E0_V in fixed")
        if len(curves) != 1:
            raise FitError("paper mode fits one curve (the paper's setup); give one curve")
    fixed, bnds = _spec(family, requested_fixed, bounds, stack, paper_mode)
    notes, warnings = [], []
    notes += family.fit_notes(stack, fixed)
    _resolve_e0_r(family, stack, fixed, notes, warnings)
    for c in curves:
        used = _thin(c.time_s.size, max_samples).size
        if used < c.time_s.size:
            notes.append(f"curve {c.name or '?'}: {used} of {c.time_s.size} samples used "
                         f"(evenly thinned in time)")
    mdl = _Model(family, stack, fixed, bnds)
    if not mdl.free:
        raise FitError("every parameter is fixed; nothing to fit")

    starts, lo, hi = _starts(mdl, bnds, guess)
    nfev = 0
    theta = np.empty(0)
    warm = None
    if mdl.nonlinear and start is not None and all(n in start for n in mdl.nonlinear):
        warm = _defined_start(mdl, np.clip([float(start[n]) for n in mdl.nonlinear], lo, hi),
                              hi)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            if not np.all(np.isfinite(mdl.varpro_residual(warm))):
                warm = None  # the start is undefined on these data: search instead
    if warm is not None:
        sol = _varpro_solve(mdl, warm, lo, hi, ftol=warm_ftol)
        nfev += sol.nfev
        theta = sol.x
    elif mdl.nonlinear:
        # coarse to fine: search on a thinned copy of the data, refine on all of it
        coarse = _Model(family, _stack(curves, cells_series, strings_parallel, use_rest,
                                       weighting, max_samples=SEARCH_SAMPLES_PER_CURVE,
                                       virtual_temperature=virtual_temperature),
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
        best, scanned = _scan_capacity(coarse, best, lo, hi)
        nfev += scanned
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
            positive = bnds.get(n, (-np.inf, 0.0))[0] >= 0
            stderr[n], ci95[n] = e, _interval95(v, e, t_crit, positive)

    thermal = None
    if family.thermal:
        params, thermal = _thermal(family, params, stack, notes, thermal_prior, warnings)
    ident = analyse(jac, mdl.free, values, bnds, paper_mode=paper_mode, svd=svd)
    _physical_limits(family, ident, notes, stack.q_max)
    warnings += ident.warnings
    measured = ~stack.is_rest
    rmse = float(np.sqrt(np.mean(residual[measured] ** 2)))
    implausible = plausibility(family, params, ci95, fixed, stack, rmse)
    warnings += implausible + undetermined(family, params, ci95, fixed)
    samples = None
    if bootstrap:
        samples = _bootstrap(mdl, values, residual, bnds, int(bootstrap), seed, progress,
                             method=bootstrap_method)
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
    result.elapsed_s = time.perf_counter() - t_start
    return result


def _interval95(value: float, stderr: float, t_crit: float, positive: bool) -> tuple:
    """95 % interval of a fitted parameter from its standard error.

    A parameter bounded below by zero (a resistance, a time constant, a capacity)
    gets a log-scale interval, ``value * exp(+-t * stderr / value)`` (the delta method
    on ``ln value``), which stays positive (one-sided from zero when the value sits
    on that bound); the others are symmetric.
    """
    if not np.isfinite(stderr):
        return float("nan"), float("nan")
    if positive and value > 0:
        factor = float(np.exp(min(t_crit * stderr / value, 700.0)))
        return value / factor, value * factor
    if positive and value <= 0:  # at its zero bound: one-sided
        return 0.0, t_crit * stderr
    return value - t_crit * stderr, value + t_crit * stderr


def _physical_limits(family: Family, ident: Identifiability, notes: list,
                     delivered_Ah: float | None = None) -> None:
    """Parameters at a bound that marks an absent effect become notes, not bound problems;
    a capacity at the charge the runs delivered (``delivered_Ah``, per cell) is a note that
    says so instead of a warning to widen the bound (it stays in ``at_bounds``)."""
    keep = []
    for name, side, bound in ident.at_bounds:
        par = family.parameter(name) if name in family.names else None
        if name == "C_Ah" and side == "lower" and delivered_Ah is not None and \
                bound <= delivered_Ah * (1.0 + 1e-3):  # physics: the charge delivered
            notes.append(capacity_at_delivered_charge(bound))
            ident.warnings = [w for w in ident.warnings if not w.startswith("C_Ah = ")]
            # still at a bound for the automatic choice (a family whose capacity the data
            # do not pin down above the charge drawn is not preferred as plausible)
            keep.append((name, side, bound))
        elif par is not None and par.limit_note:
            notes.append(f"{name} = {bound:g} at its {side} bound: {par.limit_note}")
            ident.warnings = [w for w in ident.warnings if not w.startswith(f"{name} = ")]
        else:
            keep.append((name, side, bound))
    ident.at_bounds = keep


def _thermal(family: Family, params: CellParameters, stack: Samples, notes: list,
             prior: dict | None = None, warnings: list | None = None):
    """Heat capacity and thermal resistance from the logged temperature, else from the
    thermal prior, else held at the ambient (else defaults); a thermal resistance at its
    limit (no cooling in the log) adds a warning that says so."""
    if not stack.has_temperature and prior is not None:
        params = params.replace(Cth_J_per_K=prior["Cth_J_per_K"],
                                Rth_K_per_W=prior["Rth_K_per_W"])
        return params, {"Cth_J_per_K": float(prior["Cth_J_per_K"]),
                        "Rth_K_per_W": float(prior["Rth_K_per_W"]),
                        "source": "prior (no temperature logged): " + prior["note"]}
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
    if fitted["Rth_K_per_W"] >= MAX_THERMAL_RESISTANCE and warnings is not None:
        warnings.append(adiabatic_warning())
    return params, dict(fitted, source=source)


def adiabatic_warning() -> str:
    """A thermal resistance at its limit: what the log showed and what it means."""
    return (f"Rth_K_per_W = {MAX_THERMAL_RESISTANCE:g} K/W is its limit, not a measurement: "
            f"the logged temperature rises as if the cell lost no heat to the ambient during "
            f"the runs (an adiabatic cell), so the model's heat (current x overpotential) is "
            f"less than what warmed the cell (heat the model lacks, such as the entropic heat, "
            f"or an ambient that warmed with the cell). Predictions of runs longer than the "
            f"fitted ones overstate the heating; log the ambient temperature, or include a "
            f"run that shows the cell cooling (a rest after the load)")


# ---- self-heating without a logged temperature ----------------------------------------

#: The prior's simulated heating is kept unless it makes the voltage fit worse than
#: this factor, and this margin [V], times / above the fit with the cell at the ambient
#: (data whose voltage does not show the heating the prior predicts).
PRIOR_RMSE_FACTOR = 1.1
PRIOR_RMSE_MARGIN_V = 0.001

#: Refits at most, and the change of the simulated temperature [K] that ends them.
VIRTUAL_ITERATIONS = 10
VIRTUAL_TOLERANCE_K = 0.2

def needs_prior(curves, model, cooling) -> bool:
    """True for a thermal family, fitted without a logged temperature, with a cooling."""
    curves = [curves] if isinstance(curves, Curve) else list(curves)
    return (cooling is not None and get_family(model).thermal
            and not all(c.temperature_C is not None for c in curves))


def prior_for(result, curves, cooling: str, chemistry: str | None) -> dict:
    """The thermal prior of the fitted cell (capacity per cell from the fit, chemistry
    given or from the full cell's voltage, the pack's cells sharing its surface)."""
    from ..thermalprior import chemistry_from_full_voltage, thermal_prior

    if chemistry is None:
        full = result.battery.voltage(0.0, 0.0) / result.cells_series
        chemistry = chemistry_from_full_voltage(float(np.asarray(full).ravel()[0]))
    capacity = float(result.parameters["C_Ah"])
    return thermal_prior(capacity, chemistry, cells=result.cells_series * result.strings_parallel,
                         cooling=cooling)


def virtual_temperature(result: FitResult, curve: Curve, prior: dict,
                        temperature) -> np.ndarray:
    """Cell temperature [degC] at the samples of ``curve`` by the lumped thermal model with
    the prior's heat capacity and resistance, heated by the fitted model's irreversible
    heat ``i (U_ocv - V)`` at the samples (its resistances read at ``temperature``, the
    previous estimate); exact over each sample interval for the interval's mean heat."""
    family, p = result.family, result.parameters
    t_all = curve.time_s - curve.time_s[0]
    data = _stack([curve], result.cells_series, result.strings_parallel, False, "samples",
                  virtual_temperature=[np.asarray(temperature, dtype=float)])
    with np.errstate(invalid="ignore", over="ignore"):
        v = family.fit_voltage(p, data)
        state = {st.name: (data.charge if st.kind == "charge" else data.temperature
                           if st.kind == "thermal" else data.current) for st in family.states}
        heat = data.current * (family.open_circuit_voltage(p, state) - v)
    heat = np.where(np.isfinite(heat), np.maximum(heat, 0.0), 0.0)
    ambient = curve.ambient_C if curve.ambient_C is not None else result.ambient_C
    rth, tau = prior["Rth_K_per_W"], prior["Rth_K_per_W"] * prior["Cth_J_per_K"]
    decay = np.exp(-np.diff(data.time) / tau)
    mean_heat = 0.5 * (heat[1:] + heat[:-1])
    out = np.empty(data.time.size)
    out[0] = ambient
    for k in range(decay.size):
        out[k + 1] = ambient + (out[k] - ambient) * decay[k] + mean_heat[k] * rth * (1 - decay[k])
    return np.interp(t_all, data.time, out)


def fit_self_heating(curves, *, cooling: str, chemistry: str | None = None, **kw):
    """Fit a thermal family to curves without a logged temperature, its self-heating
    simulated with the thermal prior; ``kw`` as :func:`fit_once`.

    Fitting a thermal family to data without a logged temperature: the self-heating the
    runs had is simulated with a thermal prior instead of ignored.

    Without a temperature log the fit used to take the cell at the ambient throughout, and
    predictions kept it there: the resistances then hold whatever heating the fitted runs
    had, and a prediction at a higher current misses the heating it adds (a slow drain
    says nothing about how warm a 3.5C drain gets, and a warm cell sags less). Here:

    1. the family is fitted with the cell at the ambient;
    2. the thermal prior (:func:`dischargelab.thermalprior.thermal_prior`: heat capacity and
       thermal resistance from the cell's capacity, its chemistry, the cells in the pack
       and the cooling) turns the fitted model's irreversible heat at every sample of a
       run into a simulated cell temperature from the ambient
       (:func:`virtual_temperature`);
    3. the family is fitted again with that temperature standing in for the unlogged one
       (its Arrhenius resistances read it), warm-started, and 2-3 repeat until the simulated
       temperature moves by less than :data:`VIRTUAL_TOLERANCE_K` (the prior's heat
       capacity and resistance become the fit's).

    Predictions then simulate the heating with the same prior. A slow drain hardly heats,
    so its fit is the cold cell's; a fast drain heats and its resistances fall with the
    family's Arrhenius prior. When the simulated heating makes the voltage fit worse
    (:data:`PRIOR_RMSE_FACTOR`, :data:`PRIOR_RMSE_MARGIN_V`), the data argue against it
    and the cell is held at the ambient, as without a prior.
    """
    curves = [curves] if isinstance(curves, Curve) else list(curves)
    held = res = fit_once(curves, **kw)
    prior = prior_for(res, curves, cooling, chemistry)
    temps = [np.full(c.time_s.size, c.ambient_C if c.ambient_C is not None else res.ambient_C,
                     dtype=float) for c in curves]
    change, rounds, worse = np.inf, 0, False
    while rounds < VIRTUAL_ITERATIONS:
        rounds += 1
        new = [virtual_temperature(res, c, prior, tc) for c, tc in zip(curves, temps)]
        change = max(float(np.max(np.abs(a - b))) for a, b in zip(new, temps))
        temps = new
        res = fit_once(curves, **dict(kw, thermal_prior=prior, virtual_temperature=temps,
                                      start=res.parameters.as_dict()))
        worse = res.rmse_V > max(PRIOR_RMSE_FACTOR * held.rmse_V,
                                 held.rmse_V + PRIOR_RMSE_MARGIN_V)
        if change < VIRTUAL_TOLERANCE_K or worse:
            break
    if worse:
        held.notes.append(
            f"no temperature logged: the self-heating the {prior['note']} predicts makes the "
            f"fit worse (RMSE {1000 * held.rmse_V:.1f} -> {1000 * res.rmse_V:.1f} mV): the "
            f"voltage does not show that heating, so the cell is held at the ambient")
        return held
    rise = max(float(np.max(tc) - tc[0]) for tc in temps)
    converged = "" if change < VIRTUAL_TOLERANCE_K else (
        f"; not settled after {rounds} refits (last change {change:.2g} K)")
    res.notes.append(f"no temperature logged: the self-heating is simulated with the "
                     f"{prior['note']}; the fitted runs heat the cell by up to {rise:.1f} K "
                     f"in that simulation, and the fit reads its resistances at that "
                     f"temperature ({rounds} refit(s){converged})")
    res.thermal_prior = dict(prior, fit_virtual_rise_K=rise)
    return res
