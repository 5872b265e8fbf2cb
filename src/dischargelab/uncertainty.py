"""95 % intervals of predictions and missions: parameter draws plus the model's own error.

Two parts go into every interval (and ``interval_includes`` says which did):

* **Parameters.** When the fit stored bootstrap refits (``fit --bootstrap N``, the
  command-line default) those parameter sets are flown: each is a real fit of the
  data with resampled residuals. Otherwise the fit covariance
  (``Battery.covariance``, in the model family's parameter order, zeros for
  fixed parameters) is sampled: multivariate normal draws (seeded), draws
  outside the family's parameter bounds or with a capacity not above the charge
  measured during the fit rejected. All draws are flown at once through the one
  engine (:func:`dischargelab.engine.run`, vectorised over the draws), so every
  model family works and no model equation is evaluated here.
* **Model error.** The model itself is not exact, and less so away from the
  currents it was fitted at. Its relative standard deviation of a time to cutoff
  (or endurance) is :func:`model_error_sd`: from held-out-curve residuals when
  the fit had several rates, else from the one-rate errors measured on other cells
  (:func:`one_rate_law`; a documented prior for presets and flights); both grow
  with the extrapolation ratio. Each draw's time is multiplied by ``exp(sigma z)``,
  ``z ~ N(0, 1)`` (seeded, :data:`MODEL_ERROR_SAMPLES` values shared out over the
  draws) and the central percentile interval is taken. Without parameter draws
  (presets, hand-written files) the interval is the model error alone around the
  point value, ``t exp(+-z_(1+level)/2 sigma)``.

A draw that cannot reach the cutoff (the cutoff at or above its starting
voltage, or a power it cannot deliver) is a result, not a failure: its time is
0 s, it is counted (``draws_not_reaching_cutoff``) and reported.

References
----------
.. [1] JCGM 101:2008, "Evaluation of measurement data - Supplement 1: Propagation
   of distributions using a Monte Carlo method".
.. [2] B. Efron, R. Tibshirani, "An Introduction to the Bootstrap", Chapman & Hall
   (1993), chapter 13 (percentile intervals).
.. [3] A. Gelman et al., "Bayesian Data Analysis", 3rd ed., CRC Press (2013),
   section 3.3 (normal model, conjugate scaled-inverse-chi-square prior on the
   variance; the predictive distribution is Student's t).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from . import engine
from .cell import CellParameters
from .errors import DataError, SimulationError
from .formatting import ratio as format_ratio
from .onerate import FLAT_PLATEAU_RATIO, one_rate_law

if TYPE_CHECKING:
    from .model import Battery

#: Default number of covariance draws.
DEFAULT_DRAWS = 300

#: Prior relative standard deviation of a time to cutoff inside the fitted currents [-]
#: (the paper reports endurance errors of 1-6 % on unseen rates; 1.5 % is one sigma of
#: the better half).
PRIOR_RELATIVE_SD = 0.015

#: Smallest relative standard deviation taken from held-out curves [-] (a handful of
#: curves cannot show an error below this).
MIN_HELD_OUT_SD = 0.005

#: Weight of the prior :data:`PRIOR_RELATIVE_SD` against held-out curves, in curves:
#: the model error's variance is the scaled-inverse-chi-square posterior
#: ``(nu0 s_prior^2 + sum e_k^2) / (nu0 + n)`` with ``nu0 + n`` degrees of freedom, and
#: intervals use Student's t with those degrees of freedom (two or three held-out
#: curves cannot pin a standard deviation down) [3].
PRIOR_WEIGHT_CURVES = 2

#: Growth of the model error with the logarithm of the extrapolation ratio [-].
EXTRAPOLATION_GROWTH = 0.8

#: Growth of the prior (one fitted rate) with ln(extrapolation ratio): one rate
#: cannot show how the capacity and the overpotentials change with rate. This is
#: the value of a sloped discharge curve; each family may declare its own
#: (``Family.one_rate_growth``), and a flat curve multiplies it (see
#: :data:`SLOPED_PLATEAU_RATIO`).
PRIOR_EXTRAPOLATION_GROWTH = 2.0

#: Plateau ratio (:func:`dischargelab.fit.result.plateau_ratio`: the voltage drop over
#: the middle 60 % of the charge over the whole drop) of a sloped discharge curve [-].
#: A flatter curve multiplies the one-rate growth by ``SLOPED_PLATEAU_RATIO / ratio``
#: (at most :data:`MAX_PLATEAU_FACTOR`): a model error ``dV`` in the voltage moves the
#: time to cutoff by ``dV / |dV/dt|``, so the time error of one error in the
#: overpotential grows as the curve flattens. A flat curve (plateau ratio below
#: :data:`dischargelab.onerate.FLAT_PLATEAU_RATIO`: LiFePO4) takes the whole
#: :data:`MAX_PLATEAU_FACTOR`: there the end is a steep knee (a 0.05 V shift of the
#: cutoff moves it by 0.2-2 %), so the slope argument no longer sets the error; the
#: time to cutoff is where the knee falls, which moves with the rate-dependent accessible
#: capacity (solid diffusion, the two-phase front) that one rate cannot show. The two
#: flat cells measured by ``benchmarks/one_rate_errors.py`` (a LiFePO4 and a flat LCO)
#: grew by 13-14 % per ln r (95th percentile at the interval's edge); ``1.5 % x (1 + 8
#: ln r)`` is 12 % per ln r.
SLOPED_PLATEAU_RATIO = 1.0 / 3.0
MAX_PLATEAU_FACTOR = 4.0

#: Growth of the prior for an isothermal family fitted to data that logged a
#: self-heating rise of at least :data:`SELF_HEATING_K`: the model ignores heat
#: that the data show, and the error grows with the rate (I^2 R heating).
ISOTHERMAL_EXTRAPOLATION_GROWTH = 4.0
SELF_HEATING_K = 5.0

#: Relative standard deviation of a predicted temperature rise (peak - ambient) inside
#: the fitted currents [-], and its growth with ln(extrapolation ratio). A lumped
#: model's heat capacity and thermal resistance come from the fitted runs only: on
#: the Samsung 30Q and PyBaMM NMC/LFP cells of ``benchmarks/accuracy.py`` the
#: logged rise was exp(-0.6) to exp(+0.15) times the predicted one (RMS of the
#: logarithm about 0.3), and a 1C fit predicting 4C can under-predict the rise by a
#: quarter.
THERMAL_RISE_SD = 0.25
THERMAL_RISE_GROWTH = 0.3

#: Absolute standard deviation [K] added to a predicted peak temperature: a
#: thermocouple's tolerance (IEC 60584-1 class 1: +-1.5 K) and a lumped model's
#: single temperature for a cell whose surface and core differ.
THERMAL_ABSOLUTE_SD_K = 1.0

#: Model-error samples per interval (shared out over the parameter draws).
MODEL_ERROR_SAMPLES = 4000

#: Engine time steps per discharge when flying the draws.
DRAW_STEPS_PER_DISCHARGE = 100

#: Keys of a prediction that scale with the model error.
PREDICTION_KEYS = ("time_to_cutoff_s", "capacity_Ah", "energy_Wh")


# ---------------------------------------------------------------------------------------------
# Parameter draws
# ---------------------------------------------------------------------------------------------

def _physical(values: np.ndarray, battery: Battery, min_capacity_Ah: float) -> np.ndarray:
    """Rows of parameter draws (family order) that describe a physical cell.

    Each parameter must stay at or above the family's lower bound (no negative
    resistance, polarisation, exponential term, heat capacity, ...; the upper
    bounds only limit the fit's search and are not applied), except where the
    battery's own value is already below it; the capacity must exceed the charge
    measured during the fit.
    """
    ok = np.ones(len(values), dtype=bool)
    for k, par in enumerate(battery.family.parameters):
        if float(battery.parameters[par.name]) >= par.lower:
            ok &= values[:, k] >= par.lower
        if par.name == "C_Ah":
            ok &= values[:, k] > min_capacity_Ah
    return ok


def bootstrap_parameters(battery: Battery) -> dict | None:
    """Bootstrap parameter sets stored in the battery file, ``{name: array}``, or None.

    Parameters the file does not list (held fixed during the refits) take the
    battery's value.

    Raises
    ------
    DataError
        The stored bootstrap is malformed.
    """
    boot = battery.extra.get("bootstrap") if isinstance(battery.extra, dict) else None
    if not boot:
        return None
    names = list(boot.get("names", [])) if isinstance(boot, dict) else []
    family_names = battery.family.names
    if not names or any(n not in family_names for n in names):
        raise DataError(f"battery file bootstrap names must be parameters of the "
                        f"{battery.model!r} model ({', '.join(family_names)})")
    try:
        samples = np.asarray(boot.get("samples", []), dtype=float)
    except (TypeError, ValueError):
        raise DataError("battery file bootstrap samples must be numbers") from None
    if samples.ndim != 2 or samples.shape[1] != len(names) or len(samples) < 2 or \
            not np.all(np.isfinite(samples)):
        raise DataError(f"battery file bootstrap must be a list of at least 2 rows of "
                        f"{len(names)} numbers")
    out = {n: np.full(len(samples), float(battery.parameters[n])) for n in family_names}
    out.update({n: samples[:, k] for k, n in enumerate(names)})
    return out


def sample_parameters(battery: Battery, draws: int = DEFAULT_DRAWS, *, seed: int = 0,
                      max_rounds: int = 50):
    """Parameter draws of the battery: its bootstrap refits, else covariance samples.

    Parameters
    ----------
    battery : Battery
        Must carry bootstrap refits or a covariance (family order, n x n).
    draws : int
        Number of accepted covariance draws wanted (bootstrap refits are all used).
    seed : int
        Seed of ``numpy.random.default_rng``.
    max_rounds : int
        Batches of covariance draws tried before giving up.

    Returns
    -------
    params : CellParameters
        Each parameter an array of shape ``(n,)``.
    info : dict
        ``requested``, ``accepted``, ``tried``, ``rejected``, ``rejected_fraction``,
        ``warnings``, ``method``, ``bootstrap`` (True for stored refits).

    Raises
    ------
    DataError
        No bootstrap and no covariance, or fewer than half the covariance draws
        physical after ``max_rounds``.
    """
    boot = bootstrap_parameters(battery)
    if boot is not None:
        n = len(next(iter(boot.values())))
        return CellParameters(boot), {
            "requested": n, "accepted": n, "tried": n, "rejected": 0,
            "rejected_fraction": 0.0, "warnings": [], "bootstrap": True,
            "method": f"bootstrap refits stored by the fit ({n} moving-block replicas)"}
    if battery.covariance is None:
        raise DataError("the battery has no covariance (presets and hand-written files); "
                        "fit it from a measured discharge to get an uncertainty")
    if draws < 2:
        raise DataError(f"need at least 2 draws, got {draws}")
    names = battery.family.names
    cov = np.asarray(battery.covariance, dtype=float)
    if cov.shape != (len(names), len(names)) or not np.all(np.isfinite(cov)):
        raise DataError(f"battery covariance must be a finite {len(names)}x{len(names)} "
                        f"matrix")
    factor, warnings = _covariance_factor(cov)
    mean = battery.parameters.as_array(names)
    min_capacity = float(battery.extra.get("measured_capacity_Ah", 0.0) or 0.0)
    if not _physical(mean[None, :], battery, min_capacity)[0]:
        min_capacity = 0.0
    rng = np.random.default_rng(seed)
    accepted, tried = [], 0
    for _ in range(max_rounds):
        need = draws - sum(len(x) for x in accepted)
        if need <= 0:
            break
        batch = mean + rng.standard_normal((max(2 * need, 16), len(names))) @ factor.T
        tried += len(batch)
        accepted.append(batch[_physical(batch, battery, min_capacity)])
    sample = np.concatenate(accepted)[:draws] if accepted else np.empty((0, len(names)))
    if len(sample) < draws:
        raise DataError(f"only {len(sample)} of {tried} parameter draws are physical; the fit "
                        f"covariance is too wide to sample (check the fit warnings)")
    rejected = tried - sum(len(x) for x in accepted)
    fraction = rejected / max(tried, 1)
    if fraction > 0.1:
        warnings.append(f"{100 * fraction:.0f} % of the parameter draws were unphysical and "
                        f"rejected: the interval is a truncated-normal estimate")
    params = CellParameters({n: sample[:, k] for k, n in enumerate(names)})
    info = {"requested": int(draws), "accepted": int(len(sample)), "tried": int(tried),
            "rejected": int(rejected), "rejected_fraction": float(fraction),
            "warnings": warnings, "bootstrap": False,
            "method": "covariance sampling (multivariate normal, unphysical draws rejected)"}
    return params, info


def _covariance_factor(cov: np.ndarray):
    """Square-root factor of a symmetric covariance (negative eigenvalues set to 0)."""
    cov = 0.5 * (cov + cov.T)
    values, vectors = np.linalg.eigh(cov)
    warnings = []
    scale = max(float(values.max()), 0.0)
    if values.min() < -1e-8 * max(scale, 1e-300):
        warnings.append("the stored covariance is not positive semi-definite; negative "
                        "eigenvalues were set to zero")
    return vectors * np.sqrt(np.clip(values, 0.0, None)), warnings


def hasparameter_draws(battery: Battery) -> bool:
    """True when the battery carries bootstrap refits or a non-zero covariance."""
    if bootstrap_parameters(battery) is not None:
        return True
    return battery.covariance is not None and bool(np.any(np.asarray(battery.covariance)))


def interval(values, level: float = 0.95) -> tuple[float, float]:
    """Central percentile interval of the finite ``values``."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan")
    tail = 100.0 * (1.0 - level) / 2.0
    lo, hi = np.percentile(v, [tail, 100.0 - tail])
    return float(lo), float(hi)


# ---------------------------------------------------------------------------------------------
# Model error
# ---------------------------------------------------------------------------------------------

def held_out_posterior(normalised_errors) -> tuple[float, int]:
    """``(relative sd, degrees of freedom)`` of the model error from held-out curves.

    ``normalised_errors`` are relative time-to-cutoff errors [-] of leave-one-out
    predictions, each already brought back to the fitted currents. The prior
    :data:`PRIOR_RELATIVE_SD` counts as :data:`PRIOR_WEIGHT_CURVES` curves [3].
    """
    e = np.asarray(normalised_errors, dtype=float)
    dof = PRIOR_WEIGHT_CURVES + e.size
    var = (PRIOR_WEIGHT_CURVES * PRIOR_RELATIVE_SD ** 2 + float(np.sum(e * e))) / dof
    return math.sqrt(var), int(dof)


def held_out_summary(model_error: dict) -> str:
    """One line on a stored held-out model error (``FitResult.model_error``)."""
    parts = []
    for key, what in (("held_out_rms", "whole curves left out"),
                      ("end_rms", "curve ends left out"),
                      ("rate_rms", "the rate-capacity check")):
        value = model_error.get(key)
        if isinstance(value, (int, float)):
            parts.append(f"{100 * value:.2f} % RMS with {what}")
    parts.append(f"{100 * float(model_error['relative_sd']):.2f} % inside the fitted currents "
                 f"(the interval's model error)")
    return "; ".join(parts)


def model_error_base(battery: Battery) -> tuple[float, str, float | None]:
    """(relative sd inside the fitted currents, "held-out" | "prior", Student-t degrees
    of freedom or None for a normal)."""
    stored = battery.extra.get("model_error") if isinstance(battery.extra, dict) else None
    if not isinstance(stored, dict) or stored.get("source") != "held-out":
        return PRIOR_RELATIVE_SD, "prior", None
    value = stored.get("relative_sd")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(value) or value < 0:
        raise DataError(f"battery file model_error.relative_sd must be a number >= 0, "
                        f"got {value!r}")
    dof = stored.get("dof")
    if dof is not None and (isinstance(dof, bool) or not isinstance(dof, (int, float))
                            or not dof >= 1):
        raise DataError(f"battery file model_error.dof must be a number >= 1, got {dof!r}")
    return max(float(value), MIN_HELD_OUT_SD), "held-out", \
        None if dof is None else float(dof)


def extrapolation_side(battery: Battery, cell_current_A: float) -> str | None:
    """``"up"`` above the fitted currents, ``"down"`` below them, None inside or unknown."""
    fitted = [abs(x) for x in battery.fit_currents_A if x]
    cell = abs(float(cell_current_A))
    if not fitted or cell == 0:
        return None
    return "up" if cell > max(fitted) else "down" if cell < min(fitted) else None


def model_error_sd(battery: Battery, cell_current_A: float) -> float:
    """Relative standard deviation of a time to cutoff or endurance from the model's error.

    ``sigma = s0 (1 + g ln r)`` with ``r = battery.extrapolation_ratio(cell_current_A)``
    (>= 1; 1 inside the fitted currents) and

    * ``s0 = max(s_held_out, 0.005)``, ``g = 0.8`` when the battery file holds
      ``model_error = {"relative_sd": s_held_out, "source": "held-out"}`` (stored by
      the fit when >= 2 rates were fitted: the errors of curve ends left out and, from
      three curves, of whole curves left out, each brought back to the fitted currents
      by ``1 + 0.8 ln r_k``, and of the rate-capacity check between the fitted currents,
      pooled with the prior, and at least the fitted curves' own error of the time to
      cutoff; :func:`dischargelab.fit.heldout.held_out_error`);
    * for one constant-current rate, the law measured on other cells
      (:func:`dischargelab.onerate.one_rate_law`): ``sigma = base + growth |ln r|`` with
      the growth of the side (above or below the fitted current) of the family, curve
      shape and logged temperature of the fit; intervals then use Student's t with one
      degree of freedom fewer than the cells the law was measured on (the spread between
      cells is measured on a few of them);
    * ``s0 = 0.015`` otherwise (prior: the paper's endurance errors on unseen rates
      were 1-6 %), ``g`` the family's ``one_rate_growth`` (2: one rate cannot show how
      capacity and overpotentials change with rate) times
      ``SLOPED_PLATEAU_RATIO / plateau ratio`` for a flatter curve (at most x4; x4 on a
      flat one, plateau ratio below ``FLAT_PLATEAU_RATIO``), and at
      least 4 for an isothermal family fitted to data that logged 5 K or more of
      self-heating (heat the model ignores grows as I^2 R).

    Parameters
    ----------
    battery : Battery
    cell_current_A : float
        Cell current of the prediction [A] (pack current / strings in parallel).

    Returns
    -------
    float
        Relative standard deviation [-] (e.g. 0.015 = 1.5 %).
    """
    return model_error_info(battery, battery.extrapolation_ratio(cell_current_A),
                            extrapolation_side(battery, cell_current_A))["relative_sd"]


def extrapolation_growth(battery: Battery, source: str) -> float:
    """How fast the model error grows with ln(extrapolation ratio) (see model_error_sd).

    ``source`` is ``"held-out"`` (several rates fitted) or ``"prior"`` (one rate).
    """
    if source == "held-out":
        return EXTRAPOLATION_GROWTH
    extra = battery.extra if isinstance(battery.extra, dict) else {}
    growth = float(getattr(battery.family, "one_rate_growth", PRIOR_EXTRAPOLATION_GROWTH))
    plateau = extra.get("fit_plateau_ratio")
    if isinstance(plateau, (int, float)) and not isinstance(plateau, bool) and plateau >= 0:
        growth *= MAX_PLATEAU_FACTOR if plateau < FLAT_PLATEAU_RATIO else \
            min(MAX_PLATEAU_FACTOR, max(1.0, SLOPED_PLATEAU_RATIO / plateau))
    rise = extra.get("fit_temperature_rise_K")
    if not battery.family.thermal and isinstance(rise, (int, float)) and rise >= SELF_HEATING_K:
        growth = max(growth, ISOTHERMAL_EXTRAPOLATION_GROWTH)
    return growth


def model_error_info(battery: Battery, ratio: float, side: str | None = None) -> dict:
    """Model error for an (effective) extrapolation ratio: sd, source, label.

    ``side`` is ``"up"`` (above the fitted currents) or ``"down"``; None takes the wider
    of the two where they differ (the measured one-rate law)."""
    base, source, dof = model_error_base(battery)
    log_ratio = math.log(max(ratio, 1.0))
    law = one_rate_law(battery) if source == "prior" else None
    if law is not None:
        growths = [law.get(k) for k in ((side,) if side in ("up", "down") else ())
                   + ("up", "down")]
        growth = next(g for g in growths if g is not None) if side else \
            max(g for g in growths if g is not None)
        base = float(law["base"])
        sd = base + float(growth) * log_ratio
        source = "one-rate, measured"
        # the spread between cells is measured on a few of them: Student's t
        dof = float(max(len(law.get("cells", [])) - 1, 1))
        return {"relative_sd": sd, "base_relative_sd": base, "source": source, "dof": dof,
                "extrapolation_ratio": float(ratio), "growth_per_log_ratio": float(growth),
                "one_rate_class": law["name"], "measured_cells": len(law.get("cells", [])),
                "label": f"model error ({source} on {len(law.get('cells', []))} other cells, "
                         f"extrapolation {format_ratio(ratio)})"}
    sd = base * (1.0 + extrapolation_growth(battery, source) * log_ratio)
    return {"relative_sd": sd, "base_relative_sd": base, "source": source, "dof": dof,
            "extrapolation_ratio": float(ratio),
            "label": f"model error ({source}, extrapolation {format_ratio(ratio)})"}


def half_width_pct(sd: float, level: float = 0.95, dof: float | None = None) -> float:
    """Half-width [% of the median] of the interval ``exp(+-z sd)`` of a relative sd."""
    return 100.0 * math.sinh(z_level(level, dof) * sd)


def z_level(level: float, dof: float | None = None) -> float:
    """Two-sided quantile of a normal (``dof`` None) or of Student's t."""
    from scipy.stats import norm, t

    q = 0.5 + level / 2.0
    return float(norm.ppf(q) if dof is None else t.ppf(q, dof))


def error_factors(n: int, sd: float, seed: int, dof: float | None = None):
    """``(rows, factor)``: each of ``n`` draws repeated, times ``exp(sd z)`` (seeded;
    ``z`` normal, or Student's t with ``dof`` degrees of freedom)."""
    copies = max(1, math.ceil(MODEL_ERROR_SAMPLES / max(n, 1)))
    rng = np.random.default_rng([int(seed), 1])
    rows = np.repeat(np.arange(n), copies)
    z = rng.standard_normal(rows.size) if dof is None else rng.standard_t(dof, rows.size)
    return rows, np.exp(sd * z)


def spread(samples: np.ndarray, nominal: float, level: float) -> dict:
    lo, hi = interval(samples, level)
    finite = samples[np.isfinite(samples)]
    return {"nominal": float(nominal),
            "median": float(np.median(finite)) if finite.size else float("nan"),
            "low": lo, "high": hi,
            "std": float(np.std(finite, ddof=1)) if finite.size > 1 else float("nan")}


def lognormal_spread(nominal: float, sd: float, level: float,
                      dof: float | None = None) -> dict:
    z = z_level(level, dof)
    return {"nominal": float(nominal), "median": float(nominal),
            "low": float(nominal * math.exp(-z * sd)), "high": float(nominal * math.exp(z * sd)),
            "std": float(abs(nominal) * math.sqrt(math.expm1(sd * sd)) * math.exp(sd * sd / 2))}


# ---------------------------------------------------------------------------------------------
# Predictions (predict, validate)
# ---------------------------------------------------------------------------------------------

def parameter_draws(battery: Battery, draws: int, seed: int):
    """(params, info) of the battery's draws, or (None, reason) when it has none."""
    if not hasparameter_draws(battery):
        return None, ("the battery file holds no parameter draws or covariance (a preset or "
                      "a hand-written file)")
    try:
        return sample_parameters(battery, draws, seed=seed)
    except DataError as exc:
        return None, str(exc)


def fly_draws(battery: Battery, params, steps, *, cutoff_pack_V: float,
              initial_charge_Ah: float = 0.0, ambient_C: float | None = None,
              steps_per_discharge: int = DRAW_STEPS_PER_DISCHARGE) -> dict:
    """Time to cutoff, charge and energy of load steps for every parameter draw at once.

    Parameters
    ----------
    battery : Battery
    params : mapping
        ``{name: array of draws}`` (e.g. from :func:`sample_parameters`).
    steps : sequence of dischargelab.engine.Step
    cutoff_pack_V : float
        Pack cutoff [V].
    initial_charge_Ah : float
        Pack charge removed at the start [Ah].
    ambient_C : float, optional
        Ambient temperature [degC] (default the battery's).
    steps_per_discharge : int
        Engine time steps per step that runs to the cutoff.

    Returns
    -------
    dict
        Arrays per draw: ``time_to_cutoff_s`` (0 where the draw cannot start, NaN
        where the steps ended first), ``capacity_Ah``, ``energy_Wh``,
        ``peak_temperature_C``, ``ended_by`` and ``not_reaching`` (bool).

    Raises
    ------
    SimulationError
        The engine's step limit (one clear line).
    """
    res = engine.run(battery.family, dict(params), list(steps), cutoff_pack_V=cutoff_pack_V,
                     cells_series=battery.cells_series,
                     strings_parallel=battery.strings_parallel,
                     ambient_C=battery.ambient_C if ambient_C is None else float(ambient_C),
                     initial_charge_Ah=initial_charge_Ah,
                     steps_per_discharge=steps_per_discharge)
    ended = np.asarray(res.ended_by)
    time = np.where(ended == "end", np.nan, res.end_s)
    return {"time_to_cutoff_s": time, "capacity_Ah": res.charge_end_Ah - initial_charge_Ah,
            "energy_Wh": res.energy_Wh, "ended_by": ended,
            "peak_temperature_C": np.asarray(res.peak_temperature_C, dtype=float),
            "not_reaching": (ended == "end") | (res.end_s <= 0.0)}


def prediction_interval(battery: Battery, steps, *, nominal: dict, cutoff_pack_V: float,
                        cell_current_A: float, initial_charge_Ah: float = 0.0,
                        ambient_C: float | None = None, draws: int = DEFAULT_DRAWS,
                        seed: int = 0, level: float = 0.95) -> dict:
    """95 % interval of a simulated discharge: parameter draws times the model error.

    Parameters
    ----------
    battery : Battery
    steps : sequence of dischargelab.engine.Step
        The load (the same steps as the point prediction).
    nominal : dict
        Point values ``time_to_cutoff_s`` [s], ``capacity_Ah`` [Ah], ``energy_Wh`` [Wh]
        (and ``peak_temperature_C`` [degC], used when no draws can be flown).
    cutoff_pack_V : float
        Pack cutoff [V].
    cell_current_A : float
        Mean cell current of the prediction [A] (sets the extrapolation ratio).
    initial_charge_Ah, ambient_C
        As for :func:`fly_draws`.
    draws : int
        Covariance draws when the battery has no bootstrap refits.
    seed : int
        Seed of the covariance draws and of the model-error samples.
    level : float
        Coverage of the central interval.

    Returns
    -------
    dict
        ``level``, ``time_to_cutoff_s`` / ``capacity_Ah`` / ``energy_Wh`` as
        ``[low, high]`` (and ``peak_temperature_C`` for thermal families, see
        :func:`peak_temperature_interval`), ``interval_includes`` (list of str), ``model_error``
        (``relative_sd``, ``source``, ``extrapolation_ratio``), ``draws``,
        ``bootstrap_draws``, ``draws_not_reaching_cutoff``, ``method``, ``warnings``.
        Draws that cannot reach the cutoff count with 0 s (see the module docstring).
    """
    error = model_error_info(battery, battery.extrapolation_ratio(cell_current_A),
                             extrapolation_side(battery, cell_current_A))
    params, info = parameter_draws(battery, draws, seed)
    out = {"level": level, "model_error": {k: v for k, v in error.items() if k != "label"},
           "draws": 0, "bootstrap_draws": 0, "draws_not_reaching_cutoff": 0, "warnings": []}
    ambient = battery.ambient_C if ambient_C is None else float(ambient_C)

    def peak_interval(peaks):
        if battery.family.thermal and peaks is not None:
            out["peak_temperature_C"] = peak_temperature_interval(
                peaks, ambient, error["extrapolation_ratio"], level, seed)

    if params is None:
        out.update(_model_error_only(nominal, error, level, info))
        peak_interval(nominal.get("peak_temperature_C"))
        return out
    try:
        flown = fly_draws(battery, params, steps, cutoff_pack_V=cutoff_pack_V,
                          initial_charge_Ah=initial_charge_Ah, ambient_C=ambient_C)
    except SimulationError as exc:
        out.update(_model_error_only(nominal, error, level, f"the parameter draws could not "
                                                            f"be flown: {exc}"))
        peak_interval(nominal.get("peak_temperature_C"))
        return out
    n = len(flown["time_to_cutoff_s"])
    rows, factor = error_factors(n, error["relative_sd"], seed, error["dof"])
    for key in PREDICTION_KEYS:
        out[key] = list(interval(flown[key][rows] * factor, level))
    peak_interval(flown["peak_temperature_C"])
    missing = int(np.count_nonzero(flown["not_reaching"]))
    out.update({"draws": n, "bootstrap_draws": n if info["bootstrap"] else 0,
                "draws_not_reaching_cutoff": missing, "method": info["method"],
                "interval_includes": ["parameters", error["label"]],
                "warnings": list(info["warnings"])})
    if missing:
        out["warnings"].append(f"{missing} of {n} parameter draws cannot reach the cutoff "
                               f"under this load (they start at or below it, or cannot "
                               f"deliver the power); they count as 0 s in the interval")
    return out


def peak_temperature_interval(peaks_C, ambient_C: float, ratio: float, level: float = 0.95,
                              seed: int = 0) -> list[float]:
    """Interval [degC] of the peak cell temperature from the draws' peaks.

    Each draw's rise above the ambient is multiplied by ``exp(s z1)`` with
    ``s = THERMAL_RISE_SD (1 + THERMAL_RISE_GROWTH ln r)`` and
    ``THERMAL_ABSOLUTE_SD_K z2`` is added (``z1``, ``z2`` standard normal, seeded).

    Parameters
    ----------
    peaks_C : array_like
        Peak temperature of each parameter draw [degC] (one value: the point prediction).
    ambient_C : float
        Ambient temperature [degC].
    ratio : float
        Extrapolation ratio of the load (>= 1).
    level : float
        Coverage of the central interval.
    seed : int
    """
    peaks = np.atleast_1d(np.asarray(peaks_C, dtype=float))
    sd = THERMAL_RISE_SD * (1.0 + THERMAL_RISE_GROWTH * math.log(max(float(ratio), 1.0)))
    copies = max(1, math.ceil(MODEL_ERROR_SAMPLES / peaks.size))
    rng = np.random.default_rng([int(seed), 2])
    rise = np.repeat(np.maximum(peaks - ambient_C, 0.0), copies)
    z = rng.standard_normal((2, rise.size))
    samples = ambient_C + rise * np.exp(sd * z[0]) + THERMAL_ABSOLUTE_SD_K * z[1]
    return list(interval(samples, level))


def _model_error_only(nominal: dict, error: dict, level: float, reason: str) -> dict:
    z = z_level(level, error["dof"])
    sd = error["relative_sd"]
    out = {key: [float(nominal[key]) * math.exp(-z * sd), float(nominal[key]) * math.exp(z * sd)]
           for key in PREDICTION_KEYS if key in nominal}
    out.update({"interval_includes": [error["label"]],
                "method": f"model error only: {reason}"})
    return out


def simulation_interval(battery: Battery, simulate_one, *, level: float = 0.95,
                        draws: int = DEFAULT_DRAWS, seed: int = 0) -> dict:
    """Interval of a simulation's summary numbers (``predict``).

    Parameters
    ----------
    battery : Battery
    simulate_one : SimulationResult or callable
        The point prediction, or ``simulate_one(battery) -> SimulationResult``
        (called once, for the point prediction). Its steps, cutoff, initial
        charge and ambient temperature are flown for every parameter draw at once.
    level, draws, seed
        See :func:`prediction_interval`.

    Returns
    -------
    dict
        See :func:`prediction_interval`.
    """
    sim = simulate_one(battery) if callable(simulate_one) else simulate_one
    duration = sim.duration_s
    mean_current = sim.capacity_Ah * 3600.0 / duration if duration > 0 else \
        float(sim.current_A[0])
    nominal = {"time_to_cutoff_s": sim.time_to_cutoff_s, "capacity_Ah": sim.capacity_Ah,
               "energy_Wh": sim.energy_Wh_total, "peak_temperature_C": sim.peak_temperature_C}
    return prediction_interval(
        battery, sim.steps, nominal=nominal, cutoff_pack_V=sim.cutoff_pack_V,
        cell_current_A=mean_current / battery.strings_parallel,
        initial_charge_Ah=sim.initial_charge_Ah, ambient_C=sim.ambient_C, draws=draws,
        seed=seed, level=level)


__all__ = ["sample_parameters", "bootstrap_parameters", "hasparameter_draws", "interval",
           "model_error_sd", "fly_draws", "prediction_interval", "simulation_interval",
           "DEFAULT_DRAWS",
           "PRIOR_RELATIVE_SD", "MIN_HELD_OUT_SD", "EXTRAPOLATION_GROWTH", "held_out_posterior",
           "extrapolation_growth", "peak_temperature_interval", "held_out_summary",
           "half_width_pct", "model_error_info", "extrapolation_side"]
