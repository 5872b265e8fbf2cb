"""The automatic choice of a model family: every candidate is fitted and scored by
its held-out error (:func:`dischargelab.fit.family.held_out_error`)."""

from __future__ import annotations

import time

import numpy as np

from ..errors import FitError
from ..models import get_family
from .family import _several_rates, fit_family
from .result import FitResult

AUTO = "auto"

#: A physically plausible family is preferred when its held-out error is within this
#: much (absolute, as a fraction) of the best one's.
PHYSICAL_PREFERENCE = 0.01


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
        res = fit_family(curves, model=best, model_error=False, **kw)
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
