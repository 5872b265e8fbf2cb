"""The model's own error from data the fit did not see: curves and curve ends left out,
and the rate-capacity check between the fitted currents.

Used by ``model="auto"`` to choose a family (:mod:`dischargelab.fit.auto`) and by the
intervals (:func:`dischargelab.uncertainty.model_error_sd`).
"""

from __future__ import annotations

from dataclasses import replace as _replace

import numpy as np

from ..discharge import measured_time_to_cutoff
from ..errors import DataError, FitError, SimulationError
from .family import fit_family, several_rates
from .workers import fold_workers, submit

#: Fraction of a curve's duration left out at its end by :func:`held_out_error`.
HELD_OUT_TAIL = 0.2

#: Samples per curve of the held-out folds' fits (the full fit uses up to
#: :data:`~dischargelab.fit.problem.MAX_SAMPLES_PER_CURVE`): a fold only has to
#: predict one time to cutoff, which a smooth curve sampled 500 times sets as well.
FOLD_SAMPLES_PER_CURVE = 500

#: A fold's warm-started fit stops when a step lowers its cost by less than this
#: fraction (the full fit: 1e-12). On the benchmark cells its predicted times move by
#: less than 0.01 percentage point against a fit converged to round-off.
FOLD_FTOL = 1e-9


def held_out_error(curves, *, model, battery=None, cells_series=1, strings_parallel=1,
                   fixed=None, bounds=None, use_rest=True, weighting="equal",
                   cooling="still-air", chemistry=None) -> dict | None:
    """The model's own error of the time to cutoff, from data left out of the fit.

    Each fold predicts the time to a left-out curve's last voltage at its mean current
    (thermal families from its starting temperature):

    * **curve ends**: each curve in turn loses its last :data:`HELD_OUT_TAIL` of
      duration (the knee and the cutoff) and the model is fitted to that and every
      other curve. The knee at that curve's current is then predicted from the knees
      at the other currents, an extrapolation by the same ratio ``r_k`` as the curve
      left out whole (1 for a curve between two others), so its error too is brought
      back to the fitted currents by dividing it by ``1 + g ln r_k``;
    * **whole curves**: each curve in turn is left out and the model fitted to the
      others. The prediction is an extrapolation by the current ratio ``r_k``; when
      the curves left in still span several rates, its error is brought back to the
      fitted currents by dividing it by ``1 + g ln r_k`` (``g`` =
      :data:`dischargelab.uncertainty.EXTRAPOLATION_GROWTH`). With two curves every
      such fold is a one-rate fit, whose error says how far one rate extrapolates,
      not how well the two-rate fit interpolates: it is reported, not pooled;
    * **between the fitted currents** (with ``battery``, the full fit): the
      rate-capacity check of :func:`rate_capacity_error` at currents between the
      fitted ones.

    The folds' fits are thinned to :data:`FOLD_SAMPLES_PER_CURVE` samples per curve
    and, given ``battery``, start from its parameters instead of the multi-start
    search (a fold leaves out a curve or a curve's end: its optimum lies near the
    full fit's, and the solver still converges to it).

    The errors at and between the fitted currents are pooled with the prior
    (:func:`dischargelab.uncertainty.held_out_posterior`) into the model error
    inside the fitted currents, which is never below the RMS error of the fitted
    curves' own times to the rate-capacity check's voltage (``fitted_pct``: an error
    on data the fit saw, so a lower bound of the error elsewhere). Needs two or more
    curves whose currents differ by 20 % or more.

    Returns
    -------
    dict or None
        ``relative_sd`` and ``dof``: the model error inside the fitted currents;
        ``pooled`` (how many errors went in); ``held_out_rms`` / ``end_rms`` /
        ``rate_rms``: RMS of each kind [-] (as measured, before any ratio; None when
        none could be computed); ``errors_pct``, ``extrapolation_ratios``, ``curves``
        (whole curves left out), ``end_errors_pct`` and ``end_ratios``,
        ``rate_capacity``, ``fitted_floor`` (the lower bound, [-] or None);
        ``source = "held-out"``.
    """
    with fold_workers():
        return start_held_out(curves, model=model, battery=battery,
                              cells_series=cells_series, strings_parallel=strings_parallel,
                              fixed=fixed, bounds=bounds, use_rest=use_rest,
                              weighting=weighting, cooling=cooling, chemistry=chemistry)()


def start_held_out(curves, *, model, battery=None, cells_series=1, strings_parallel=1,
                   fixed=None, bounds=None, use_rest=True, weighting="equal",
                   cooling="still-air", chemistry=None):
    """:func:`held_out_error` in two halves: the folds are handed to the workers of an
    active :func:`~dischargelab.fit.workers.fold_workers` (else fitted here and now) and the
    rate-capacity check is run; the function returned gathers them into the same dict (a
    caller fits the next candidate in between)."""

    if not several_rates(curves):
        return lambda: None
    common = dict(cells_series=cells_series, strings_parallel=strings_parallel, fixed=fixed,
                  bounds=bounds, use_rest=use_rest, weighting=weighting, model=model,
                  max_samples=FOLD_SAMPLES_PER_CURVE, cooling=cooling, chemistry=chemistry,
                  warm_ftol=FOLD_FTOL)
    if battery is not None:  # warm start from the full fit
        common["start"] = battery.parameters.as_dict()
    folds = []  # (k, ratio, whole-curve fold, curve-end fold or None), in curve order
    for k, left in enumerate(curves):
        rest = [c for j, c in enumerate(curves) if j != k]
        whole = submit(_held_out_fold, rest, left, common)
        t = left.time_s
        keep = t <= t[0] + (1.0 - HELD_OUT_TAIL) * (t[-1] - t[0])
        cut = {"time_s": t[keep], "voltage_V": left.voltage_V[keep],
               "current_A": left.current_A[keep]}
        if left.temperature_C is not None:
            cut["temperature_C"] = left.temperature_C[keep]
        try:
            shortened = _replace(left, **cut)
        except DataError:
            end = None
        else:
            end = submit(_held_out_fold,
                         [shortened if j == k else c for j, c in enumerate(curves)],
                         left, common)
        folds.append((k, current_ratio(left, rest), whole, end))
    # the full fit's own check, a task like the folds
    rate = None if battery is None else submit(rate_capacity_error, battery, curves)
    return lambda: _gathered(curves, folds, None if rate is None else rate.result())


def _gathered(curves, folds, rate) -> dict | None:
    """:func:`held_out_error`'s dict from the folds started by :func:`start_held_out` and
    the rate-capacity check ``rate``."""
    from ..uncertainty import EXTRAPOLATION_GROWTH, held_out_posterior

    errors, ratios, names, ends, end_ratios, pooled = [], [], [], [], [], []
    for k, ratio, whole, end in folds:
        error = whole.result()
        if error is not None:
            errors.append(100.0 * error)
            ratios.append(ratio)
            names.append(curves[k].name)
            if several_rates([c for j, c in enumerate(curves) if j != k]):
                pooled.append(error / (1.0 + EXTRAPOLATION_GROWTH * np.log(ratio)))
        error = None if end is None else end.result()
        if error is not None:
            ends.append(error)
            end_ratios.append(ratio)
    between = [] if rate is None else [e / 100.0 for e in rate["between_pct"]
                                       if np.isfinite(e)]
    if not errors and not ends and not between:
        return None

    def rms(values):
        return float(np.sqrt(np.mean(np.square(values)))) if values else None

    ends_back = [e / (1.0 + EXTRAPOLATION_GROWTH * np.log(r)) for e, r in zip(ends, end_ratios)]
    sd, dof = held_out_posterior(pooled + ends_back + between)
    floor = None if rate is None else rms([e / 100.0 for e in rate["fitted_pct"]
                                           if np.isfinite(e)])
    if floor is not None:
        sd = max(sd, floor)
    return {"relative_sd": sd, "dof": dof, "pooled": len(pooled) + len(ends) + len(between),
            "held_out_rms": None if not errors else rms(errors) / 100.0,
            "end_rms": rms(ends), "rate_rms": None if rate is None else rate["rms"],
            "errors_pct": errors, "extrapolation_ratios": ratios,
            "curves": names, "end_errors_pct": [100.0 * e for e in ends],
            "end_ratios": end_ratios, "fitted_floor": floor,
            "rate_capacity": rate, "source": "held-out"}


def current_ratio(curve, others) -> float:
    """How far ``curve``'s mean current lies outside the others' (>= 1; 1 between them):
    the extrapolation ratio of a fit to ``others`` predicting ``curve``."""
    cell = abs(float(curve.mean_current_A))
    fitted = [abs(float(c.mean_current_A)) for c in others if c.mean_current_A]
    if not fitted or cell == 0:
        return 1.0
    return float(max(1.0, cell / max(fitted), min(fitted) / cell))


def _held_out_fold(fitted, left, common):
    """Relative error of the predicted time to ``left``'s last voltage of a fit to
    ``fitted``; None when the fit or the prediction fails."""
    from ..simulate import simulate_current

    try:
        res = fit_family(fitted, **common)
        sim = simulate_current(res.battery, left.mean_current_A,
                               cutoff_pack_V=float(left.voltage_V[-1]),
                               ambient_C=left.ambient_C, points=CHECK_POINTS,
                               max_step_s=CHECK_MAX_STEP_S)
    except (FitError, SimulationError, DataError):
        return None
    measured = float(left.time_s[-1] - left.time_s[0])
    if not np.isfinite(sim.time_to_cutoff_s) or measured <= 0:
        return None
    return (sim.time_to_cutoff_s - measured) / measured


#: Currents between the fitted ones at which :func:`rate_capacity_error` scores a
#: family (log-spaced, shared out over the gaps, at least one per gap), and the ratio
#: beyond the lowest and highest fitted current.
BETWEEN_POINTS = 3
BEYOND_RATIO = 1.5

#: Engine points per discharge of the held-out and rate-capacity predictions, and their
#: longest step [s] (only their time to cutoff is used: charge and filtered currents are
#: advanced exactly, the cutoff is located by bisection; 50 instead of 100 points moves a
#: 4C time by less than 0.01 %, and a C/10 discharge in 50 steps instead of the engine's
#: 60 s ones moves its time by less than 0.01 %).
CHECK_POINTS = 50
CHECK_MAX_STEP_S = float("inf")


def rate_capacity_error(battery, curves) -> dict | None:
    """How well a fitted family reproduces the rate-capacity relation of the data.

    All curves are cut at one voltage, the highest last voltage among them (each
    reached it), and the family predicts the time to that voltage at:

    * **the fitted currents**, each from its curve's initial charge and ambient. This
      is where a flat plateau (LiFePO4) is evidence: there a few millivolts of misfit
      along the plateau move the knee, and with it the time to cutoff, by many per
      cent, so a family that cannot shape the plateau and the knee at every rate
      misses here although its voltage RMSE looks small;
    * **between the fitted currents** (:data:`BETWEEN_POINTS` log-spaced currents
      shared out over the gaps) and **below them** (the lowest current divided by
      :data:`BEYOND_RATIO`), against the delivered charge interpolated (extrapolated
      from the lowest two) linearly in current. To first order the
      charge lost before the cutoff grows linearly with the current: the ohmic drop
      ``R i`` and the solid-diffusion lead of the surface concentration (``i R_p^2 /
      (15 D)`` at pseudo-steady state, Subramanian et al., J. Electrochem. Soc. 152
      (2005) A2002) are both linear in ``i``, and each shifts the knee by the charge
      over which the open-circuit voltage falls by that much;
    * **above them** (the highest current times :data:`BEYOND_RATIO`): there the loss
      may grow faster than linearly (electrolyte depletion) or slower (a discharge
      too short for the diffusion lead to build up, self-heating), so only the
      physical bound counts: the excess of the predicted charge over the charge
      delivered at the highest fitted current.

    Between and beyond, only curves that start from the same charge are compared.

    Returns
    -------
    dict or None
        ``rms`` over every point (relative, [-]; ``inf`` where a prediction failed);
        the relative errors of the time [%] at the fitted currents (``fitted_pct``),
        between them (``between_pct``), below (``below_pct``) and the excess above
        (``above_pct``); ``cutoff_pack_V``. None with fewer than two rates.
    """
    from ..simulate import simulate_current

    cutoff = max(float(c.voltage_V[-1]) for c in curves)
    rows = []
    for c in curves:
        t = measured_time_to_cutoff(c.time_s - c.time_s[0], c.voltage_V, cutoff)
        if not np.isfinite(t) or t <= 0:
            continue
        keep = c.time_s - c.time_s[0] <= t
        q = float(np.trapezoid(c.current_A[keep], c.time_s[keep]) / 3600.0)
        rows.append((c.mean_current_A, t, q, float(c.initial_charge_Ah), c.ambient_C))
    if len({round(r[0], 9) for r in rows}) < 2:
        return None
    rows.sort(key=lambda r: r[0])

    def predicted(current, charge0, ambient):
        try:
            sim = simulate_current(battery, current, cutoff_pack_V=cutoff,
                                   initial_charge_Ah=charge0, ambient_C=ambient,
                                   points=CHECK_POINTS, max_step_s=CHECK_MAX_STEP_S)
        except SimulationError:
            return float("nan")
        return float(sim.time_to_cutoff_s)

    fitted = [predicted(i, q0, amb) / t - 1.0 for i, t, _, q0, amb in rows]
    between = []
    if len({round(r[3], 6) for r in rows}) == 1:
        ambients = [r[4] for r in rows if r[4] is not None]
        ambient = float(np.median(ambients)) if ambients else None
        cur = np.array([r[0] for r in rows])
        charge = np.array([r[2] for r in rows])
        points = []
        per_gap = max(1, BETWEEN_POINTS // (cur.size - 1))
        for a, b in zip(cur[:-1], cur[1:]):
            points += list(np.geomspace(a, b, per_gap + 2)[1:-1])
        for i in points + [cur[0] / BEYOND_RATIO]:
            k = int(np.clip(np.searchsorted(cur, i) - 1, 0, cur.size - 2))
            slope = (charge[k + 1] - charge[k]) / (cur[k + 1] - cur[k])
            ref = charge[k] + slope * (i - cur[k])
            between.append(predicted(i, rows[0][3], ambient) / (3600.0 * ref / i) - 1.0)
        below = [between.pop()]
        # beyond the highest current the loss grows faster than linearly (or, for a short
        # discharge, slower: the diffusion lead has no time to build up), so only the
        # physical bound is scored: no more charge than at the highest fitted current
        i = cur[-1] * BEYOND_RATIO
        excess = predicted(i, rows[0][3], ambient) * i / 3600.0 / charge[-1] - 1.0
        above = [max(excess, 0.0) if np.isfinite(excess) else excess]
    else:
        below, above = [], []
    errors = np.array(fitted + between + below + above)
    out = {"fitted_pct": [100.0 * e for e in fitted],
           "between_pct": [100.0 * e for e in between],
           "below_pct": [100.0 * e for e in below], "above_pct": [100.0 * e for e in above],
           "cutoff_pack_V": cutoff}
    out["rms"] = float(np.sqrt(np.mean(errors ** 2))) if np.all(np.isfinite(errors)) \
        else float("inf")
    return out
