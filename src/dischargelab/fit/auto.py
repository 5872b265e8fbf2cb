"""The automatic choice of a model family: every candidate is fitted and scored by
its error on what the fit did not see (:func:`dischargelab.fit.heldout.held_out_error`)."""

from __future__ import annotations

import time

import numpy as np

from ..errors import FitError
from .family import fit_family, several_rates
from .heldout import start_held_out
from .result import FitResult
from .workers import fold_workers

AUTO = "auto"

#: A physically plausible family is preferred when its held-out error is within this
#: much (absolute, as a fraction) of the best one's.
PHYSICAL_PREFERENCE = 0.01


def selection_score(curve_rms: float | None, end_rms: float | None,
                    rate_rms: float | None = None, n_curves: int = 3) -> float:
    """Score of a family for ``model="auto"`` [-], smaller is better: the geometric
    mean of its errors of the time to cutoff on what the fit did not see.

    * ``end_rms``: each curve's last fifth left out while every rate stays in the fit
      (the knee at every fitted current; :func:`~dischargelab.fit.heldout.held_out_error`);
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


def _pct(value) -> str:
    return "n/a" if value is None or not np.isfinite(value) else f"{100 * value:.2f} %"


#: The family ``model="auto"`` fits to one rate (with a thermal prior or a logged
#: temperature): eq. (6) whose polarisation builds after a load step, with the series and
#: polarisation resistances the step shows (``benchmarks/slow_to_fast.py``: a slow drain's
#: model flies a 27 A flight at 0.11 % voltage RMS, where shepherd-thermal, its
#: polarisation present at once and its resistance left to the curve shape, flew it at
#: 2.06 %).
ONE_RATE_FAMILY = "shepherd-dynamic"


#: What ``auto`` fits to one rate when :data:`ONE_RATE_FAMILY` finds no capacity in it (a
#: flight that ends far from the knee).
ONE_RATE_FALLBACK = "shepherd-thermal"


def _capacity_told(res: FitResult) -> bool:
    """False when the fitted capacity ran to its upper bound or far above the charge the
    curves delivered (:data:`~dischargelab.identifiability.CAPACITY_EXCESS_FACTOR`), or
    when the knee's ``K`` sits at 0: the curve shows no knee, and without one the capacity
    changes nothing in the fitted voltage (it is where the fit started, not a measurement).
    """
    from ..identifiability import CAPACITY_EXCESS_FACTOR

    if "C_Ah" not in res.free:
        return True
    if "K_V_per_Ah" in res.free and \
            float(res.parameters["K_V_per_Ah"]) <= float(res.bounds["K_V_per_Ah"][0]):
        return False
    capacity = float(res.parameters["C_Ah"])
    upper = float(res.bounds["C_Ah"][1])
    delivered = max(float(c.charge_Ah[-1]) for c in res.curves) / res.strings_parallel
    return capacity < upper * (1 - 1e-6) and capacity <= CAPACITY_EXCESS_FACTOR * delivered


def choose_model(curves, cooling: str | None = "still-air") -> tuple[list[str], str]:
    """Candidate families for ``model="auto"`` and why.

    One curve with a logged temperature: ``shepherd-dynamic`` (eq. 6 with Tremblay's
    filtered current and the load step's series and polarisation resistances; its
    temperature dependence from physics priors, the self-heating from the log). One curve
    without temperature: the same with its self-heating simulated by the thermal prior
    (:func:`dischargelab.fit.family.fit_self_heating`): a slow drain hardly heats, a
    fast one does, and a warm cell sags less (Samsung 30Q fitted on C/10 without its
    temperature: 1C-4C within -3.0 %, where eq. 6 held at the ambient misses 4C by
    -19 %); ``shepherd`` when ``cooling`` is None. Two or more curves at different
    currents: every family that the data can feed and that competes on several rates
    (``Family.several_rates_candidate``) and its simpler forms (:func:`candidate_forms`),
    compared by held-out error.
    """
    from ..models import FAMILIES

    has_temp = all(c.temperature_C is not None for c in curves)
    if not several_rates(curves):
        if has_temp:
            return [ONE_RATE_FAMILY], (f"one rate with a logged temperature: {ONE_RATE_FAMILY} "
                                       "(the load step's series resistance and the "
                                       "polarisation building after it, self-heating from "
                                       "the log, Arrhenius prior)")
        if cooling is not None:
            return [ONE_RATE_FAMILY], (
                f"one rate without temperature: {ONE_RATE_FAMILY} (the load step's series "
                "resistance and the polarisation building after it) with its self-heating "
                "simulated from a thermal prior (a fit at one current cannot show how a "
                "faster drain heats the cell)")
        return ["shepherd"], "one rate without temperature: the paper's shepherd model"
    names = [n for n, f in FAMILIES.items() if f.several_rates_candidate
             and (has_temp or not f.needs_temperature)]
    return names, "several rates: the family with the smallest held-out error"


def candidate_forms(names, fixed: dict | None = None,
                    bounds: dict | None = None) -> dict[str, tuple[str, dict]]:
    """``{label: (family name, parameters held)}``: each family of ``names`` and its
    simpler forms (``Family.several_rates_variants``, labelled ``"<family> without <term>"``)
    whose parameters the caller neither fixes nor bounds."""
    from ..models import get_family

    taken = set(fixed or {}) | set(bounds or {})
    forms = {}
    for name in names:
        forms[name] = (name, {})
        for left_out, held in get_family(name).several_rates_variants.items():
            if not taken & set(held):
                forms[f"{name} without {left_out}"] = (name, dict(held))
    return forms


def _holding(kw: dict, held: dict) -> dict:
    """Fit arguments ``kw`` with the parameters ``held`` added to its ``fixed`` (a copy)."""
    return dict(kw, fixed={**held, **(kw.get("fixed") or {})}) if held else dict(kw)


def fit_with_model_error(curves, model_error: bool = True, **kw) -> FitResult:
    """:func:`fit_family` plus, with several rates, its held-out model error."""
    with fold_workers():
        res, gather = _fit_and_start(curves, model_error, **kw)
        res.model_error = gather()
    return res


def _fit_and_start(curves, model_error: bool = True, **kw):
    """:func:`fit_family`, and its held-out folds started (:func:`start_held_out`):
    ``(result, gather)``, ``gather()`` the model error (None without one)."""
    res = fit_family(curves, **kw)
    if not model_error or kw.get("paper_mode"):
        return res, lambda: res.model_error
    common = {k: kw[k] for k in ("cells_series", "strings_parallel", "fixed", "bounds",
                                 "use_rest", "weighting", "cooling", "chemistry") if k in kw}
    return res, start_held_out(curves, model=res.model, battery=res.battery, **common)


def fit_auto(curves, t_start, **kw) -> FitResult:
    """Fit every candidate of :func:`choose_model`; keep the best held-out error."""
    names, why = choose_model(curves, kw.get("cooling", "still-air"))
    if kw.get("paper_mode"):
        names, why = ["shepherd"], "paper mode: the paper's model"
    if len(names) == 1:
        res = fit_with_model_error(curves, model=names[0], **kw)
        if names[0] == ONE_RATE_FAMILY and not _capacity_told(res):
            res = fit_with_model_error(curves, model=ONE_RATE_FALLBACK, **kw)
            names, why = [ONE_RATE_FALLBACK], (
                f"one rate that does not reach the end-of-discharge knee: {ONE_RATE_FALLBACK} "
                f"({ONE_RATE_FAMILY} found no knee (K at 0) or its capacity ran away: with "
                "its resistances held at the load step and no knee, nothing in the curve "
                "sets its capacity)")
        res.notes.insert(0, f"model {names[0]!r} chosen automatically: {why}")
        return res
    fits, scores = {}, {}
    # the linearised bootstrap costs little: every candidate gets it, no refit of the best
    linear = kw.get("bootstrap_method", "linearised") == "linearised"
    forms = candidate_forms(names, kw.get("fixed"), kw.get("bounds"))
    gathers = {}
    with fold_workers():  # one set of workers for every candidate's held-out folds
        for label, (name, held) in forms.items():
            args = _holding(kw if linear else dict(kw, bootstrap=0, progress=None), held)
            if held and name in fits and args.get("start") is None:
                # a simpler form starts from its family's fit (the same data)
                args["start"] = fits[name].parameters.as_dict()
            try:  # the next candidate is fitted while this one's folds run
                fits[label], gathers[label] = _fit_and_start(curves, model=name, **args)
            except FitError:
                continue
        for label, gather in gathers.items():
            fits[label].model_error = gather()
            err = fits[label].model_error or {}
            scores[label] = selection_score(err.get("held_out_rms"), err.get("end_rms"),
                                            err.get("rate_rms"), len(curves))
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
    name, held = forms[best]
    if kw.get("bootstrap") and not linear:  # the bootstrap; the held-out error is known
        res = fit_family(curves, model=name, **_holding(kw, held))
        res.model_error = fits[best].model_error
    if held:
        res.notes.insert(0, f"{', '.join(held)} held at "
                            f"{', '.join(f'{v:g}' for v in held.values())}: {best}, whose "
                            f"held-out error was smaller than with it")
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
