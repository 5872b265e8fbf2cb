"""The automatic choice of a model family: every candidate is fitted and scored by
its held-out error (:func:`dischargelab.fit.family.held_out_error`)."""

from __future__ import annotations

import time

import numpy as np

from ..discharge import measured_time_to_cutoff
from ..errors import FitError
from ..models import get_family
from .family import _several_rates, fit_family
from .result import FitResult

AUTO = "auto"

#: A physically plausible family is preferred when its held-out error is within this
#: much (absolute, as a fraction) of the best one's.
PHYSICAL_PREFERENCE = 0.01


#: Points per gap between two fitted currents (log-spaced, ends excluded) and the ratio
#: beyond the lowest and highest fitted current at which :func:`rate_capacity_error`
#: scores a family.
BETWEEN_POINTS = 3
BEYOND_RATIO = 1.5


def selection_score(curve_rms: float | None, end_rms: float | None,
                    rate_rms: float | None = None, n_curves: int = 3) -> float:
    """Score of a family for ``model="auto"`` [-], smaller is better: the geometric
    mean of its errors of the time to cutoff on what the fit did not see.

    * ``end_rms``: each curve's last fifth left out while every rate stays in the fit
      (the knee at every fitted current; :func:`~dischargelab.fit.family.held_out_error`);
    * ``rate_rms``: the rate-capacity check of :func:`rate_capacity_error` (the knee at
      the fitted currents, and how the delivered charge changes between and beyond them);
    * ``curve_rms``: whole curves left out, only with three or more curves: with two,
      leaving one out leaves a one-rate fit, which scores a family's priors rather than
      the family.

    ``inf`` when a needed error could not be computed.
    """
    parts = [end_rms, rate_rms] + ([curve_rms] if n_curves >= 3 else [])
    if rate_rms is None and n_curves < 3:  # no rate check: the older two-error score
        parts = [curve_rms, end_rms]
    if any(p is None or not np.isfinite(p) for p in parts):
        return float("inf")
    return float(np.exp(np.mean(np.log([max(p, 1e-6) for p in parts]))))


def rate_capacity_error(battery, curves) -> dict | None:
    """How well a fitted family reproduces the rate-capacity relation of the data.

    All curves are cut at one voltage, the highest last voltage among them (each
    reached it), and the family predicts the time to that voltage at:

    * **the fitted currents**, each from its curve's initial charge and ambient. This
      is where a flat plateau (LiFePO4) is evidence: there a few millivolts of misfit
      along the plateau move the knee, and with it the time to cutoff, by many per
      cent, so a family that cannot shape the plateau and the knee at every rate
      misses here although its voltage RMSE looks small;
    * **between the fitted currents** (:data:`BETWEEN_POINTS` log-spaced currents per
      gap) and **below them** (the lowest current divided by :data:`BEYOND_RATIO`),
      against the delivered charge interpolated (extrapolated from the lowest two)
      linearly in current. To first order the
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
        ``rms`` (relative, [-]), ``fitted_pct`` and ``between_pct`` (relative errors
        of the time [%]), ``currents_A``; None with fewer than two rates or when no
        prediction could be made.
    """
    from ..errors import SimulationError
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
                                   initial_charge_Ah=charge0, ambient_C=ambient)
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
        points = [cur[0] / BEYOND_RATIO]
        for a, b in zip(cur[:-1], cur[1:]):
            points += list(np.geomspace(a, b, BETWEEN_POINTS + 2)[1:-1])
        for i in points:
            k = int(np.clip(np.searchsorted(cur, i) - 1, 0, cur.size - 2))
            slope = (charge[k + 1] - charge[k]) / (cur[k + 1] - cur[k])
            ref = charge[k] + slope * (i - cur[k])
            between.append(predicted(i, rows[0][3], ambient) / (3600.0 * ref / i) - 1.0)
        # beyond the highest current the loss grows faster than linearly (or, for a short
        # discharge, slower: the diffusion lead has no time to build up), so only the
        # physical bound is scored: no more charge than at the highest fitted current
        i = cur[-1] * BEYOND_RATIO
        excess = predicted(i, rows[0][3], ambient) * i / 3600.0 / charge[-1] - 1.0
        between.append(max(excess, 0.0) if np.isfinite(excess) else excess)
    errors = np.array(fitted + between)
    if errors.size == 0 or not np.all(np.isfinite(errors)):
        return None if errors.size == 0 else {"rms": float("inf"), "fitted_pct": [
            100 * e for e in fitted], "between_pct": [100 * e for e in between]}
    return {"rms": float(np.sqrt(np.mean(errors ** 2))),
            "fitted_pct": [100.0 * e for e in fitted],
            "between_pct": [100.0 * e for e in between],
            "cutoff_pack_V": cutoff}


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
    names = [n for n in FAMILIES if has_temp or not get_family(n).needs_temperature]
    return names, "several rates: the family with the smallest held-out error"


def fit_auto(curves, t_start, **kw) -> FitResult:
    """Fit every candidate of :func:`choose_model`; keep the best held-out error."""
    names, why = choose_model(curves)
    if kw.get("paper_mode"):
        names, why = ["shepherd"], "paper mode: the paper's model"
    if len(names) == 1:
        res = fit_family(curves, model=names[0], **kw)
        res.notes.insert(0, f"model {names[0]!r} chosen automatically: {why}")
        return res
    fits, scores = {}, {}
    for name in names:
        try:
            fits[name] = fit_family(curves, model=name, **dict(kw, bootstrap=0, progress=None))
        except FitError:
            continue
        err = fits[name].model_error or {}
        rate = rate_capacity_error(fits[name].battery, curves)
        if rate is not None:
            err["rate_rms"] = rate["rms"]
            err["rate_capacity"] = rate
        scores[name] = selection_score(err.get("held_out_rms"), err.get("end_rms"),
                                       None if rate is None else rate["rms"], len(curves))
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
        res = fit_family(curves, model=best, model_error=False, **kw)
        res.model_error = fits[best].model_error
    def row(n):
        err = fits[n].model_error or {}
        return (f"{n} {_pct(scores[n])} (ends {_pct(err.get('end_rms'))}, rate-capacity "
                f"{_pct(err.get('rate_rms'))}, curves {_pct(err.get('held_out_rms'))}"
                + ("" if len(curves) >= 3 else " not scored") + ")"
                + ("" if fits[n].physical else " implausible parameters"))

    table = ", ".join(row(n) for n in fits)
    res.notes.insert(0, f"model {best!r} chosen automatically: {why} (time-to-cutoff error "
                        f"on what the fit did not see, geometric mean of curve ends left out, "
                        f"the rate-capacity check at, between and beyond the fitted currents"
                        f" and, with three or more curves, whole curves left out: {table})")
    res.elapsed_s = time.perf_counter() - t_start
    return res
