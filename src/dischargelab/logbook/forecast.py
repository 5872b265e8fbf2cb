"""End of life: a capacity trend that may bend, and a finite, calibrated 95 % interval.

**The trend seen so far.** The capacity estimates (outliers left out) against
equivalent full cycles ``x`` (EFC) are fitted with four families, each linear in its
coefficients once its shape parameters are fixed on a grid (``X = x / x_now``,
``x_now`` the last estimate's EFC, capacities as shares of their median):

* ``line``: ``a - b X`` (fade proportional to charge throughput, Wang et al. 2014);
* ``early``: ``a - b X - A (1 - exp(-X / tau))``, the fast early fade while the SEI
  forms (or an early rise, ``A < 0``), then a line;
* ``knee``: ``a - b X - c w softplus((X - k) / w)`` with ``c >= 0``: two lines joined
  smoothly; they meet at the knee ``k`` (the Bacon-Watts knee point, Fermin-Cueto
  et al. 2020);
* ``early+knee``: both.

Each grid point is weighted by its evidence (Schwarz's criterion of the weighted
least-squares fit, whose error variance is each estimate's own from its interval plus
a fitted nugget, times a prior shared evenly within a family, :data:`FAMILY_PRIOR`).
The residuals' lag-1 autocorrelation ``rho`` tempers the likelihood and widens the
coefficients' covariance by ``(1 + rho) / (1 - rho)`` (fewer independent estimates
than logged). The trend *bends* when the other families hold more of the evidence
than the line; :attr:`FadeFit.bend_odds` is their Bayes factor against it.

**The future.** :data:`PATHS` simulated futures start from the trend at the last
estimate (a grid point drawn by its weight, coefficients from their covariance). The
logarithm of the capacity falls (so that no future goes below zero) at the trend's
relative rate there, and that rate

* wanders as ``exp(SIGMA_RATE B(ln(x / x_now)))``, ``B`` a Brownian motion (fade
  rates drift as the mechanisms shift; a power law ``x^p`` is a straight line in
  these coordinates), and
* meets a knee with probability :data:`KNEE_PROBABILITY`, conditioned on none having
  started above today's capacity: onset at a capacity drawn evenly between
  :data:`KNEE_ONSET` of the reference, after which the rate is multiplied by a
  factor drawn log-uniformly from :data:`KNEE_FACTOR`. Knees are the rule for
  lithium-ion cells cycled to their end of life, and mark the turn to the fast fade
  that ends it (Attia et al. 2022; Diao et al. 2019), whose rate is several times the
  one before (Severson et al. 2019).

The end of life is where a future first reaches the threshold: the median, and the
2.5 and 97.5 percentiles as the 95 % interval; the band is the futures' percentiles.
The constants were chosen on seeded synthetic lives with and without knees
(``benchmarks/forecast.py`` prints the coverage), never on a measured cell.

References
----------
.. [1] P. M. Attia, A. Bills, F. Brosa Planella, et al., "Review - 'Knees' in
   lithium-ion battery aging trajectories", J. Electrochem. Soc. 169 (2022) 060517.
.. [2] K. A. Severson, P. M. Attia, N. Jin, et al., "Data-driven prediction of battery
   cycle life before capacity degradation", Nature Energy 4 (2019) 383-391.
.. [3] P. Fermin-Cueto, E. McTurk, M. Allerhand, et al., "Identification and machine
   learning prediction of knee-point and knee-onset in capacity degradation curves of
   lithium-ion cells", Energy and AI 1 (2020) 100006.
.. [4] J. Wang, J. Purewal, P. Liu, et al., "Degradation of lithium ion batteries
   employing graphite negatives and nickel-cobalt-manganese oxide + spinel manganese
   oxide positives: Part 1, aging mechanisms and life estimation", J. Power Sources
   269 (2014) 937-948.
.. [5] G. Schwarz, "Estimating the dimension of a model", Ann. Stat. 6 (1978) 461-464.
.. [6] W. Diao, S. Saxena, B. Han, M. Pecht, "Algorithm to determine the knee point on
   capacity fade curves of lithium-ion cells", Energies 12 (2019) 2910.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Families of the trend and their prior probabilities.
FAMILY_PRIOR = {"line": 0.4, "early": 0.2, "knee": 0.2, "early+knee": 0.2}

#: Shapes on the grid: early-fade time constants and knee positions and widths, as
#: shares of the last estimate's EFC.
EARLY_TAU = np.geomspace(0.02, 0.6, 9)
KNEE_AT = np.linspace(0.25, 0.95, 15)
KNEE_WIDTH = (0.02, 0.06, 0.15)

#: Spread of the future fade rate's logarithm per unit of ln(EFC) [-].
SIGMA_RATE = 0.25

#: Probability that a trend without a knee meets one before end of life.
KNEE_PROBABILITY = 0.85

#: Capacities (shares of the reference) between which a knee may start.
KNEE_ONSET = (0.80, 0.97)

#: Range of the factor on the fade rate after a knee (drawn log-uniformly).
KNEE_FACTOR = (2.0, 12.0)

#: Simulated futures and their steps in ln(EFC) up to :data:`HORIZON_FACTOR` x today.
PATHS = 4000
STEPS = 400
HORIZON_FACTOR = 30.0

#: Estimates needed for a forecast.
MIN_ESTIMATES = 3


@dataclass
class FadeFit:
    """The log-capacity trend over the grid of shapes (see the module docstring).

    Attributes
    ----------
    x_now : float
        EFC of the last estimate (the unit of ``X``).
    scale : float
        Capacity [Ah] the trend is expressed in (the estimates' median).
    points : list of (family, tau, knee, width)
        The grid's shapes (None where a family has no such parameter).
    weights : numpy.ndarray
        Posterior weight of each point.
    coef, cov : list of numpy.ndarray
        Each point's coefficients and their covariance.
    nugget : float
        Scatter beyond the intervals at the best point [share of ``scale``].
    rho : float
        Lag-1 autocorrelation of the best point's residuals (0-0.9).
    n : int
        Estimates used.
    """

    x_now: float
    scale: float
    points: list
    weights: np.ndarray
    coef: list
    cov: list
    nugget: float
    rho: float
    n: int

    def family_probability(self) -> dict[str, float]:
        """Posterior probability of each family."""
        out = dict.fromkeys(FAMILY_PRIOR, 0.0)
        for (fam, *_), w in zip(self.points, self.weights):
            out[fam] += float(w)
        return out

    @property
    def family(self) -> str:
        """The most probable family."""
        probs = self.family_probability()
        return max(probs, key=probs.get)

    @property
    def bend_odds(self) -> float:
        """Bayes factor of a bent trend (any other family) against the straight line."""
        p = self.family_probability()
        prior = FAMILY_PRIOR["line"] / (1 - FAMILY_PRIOR["line"])
        line = max(p["line"], 1e-300)
        return float((1 - p["line"]) / line * prior)

    @property
    def knee_probability(self) -> float:
        """Posterior probability that a knee is already in the data."""
        p = self.family_probability()
        return p["knee"] + p["early+knee"]

    @property
    def knee_efc(self) -> float | None:
        """EFC of the knee (weighted median over the knee shapes) when a knee is more
        probable than not, else None."""
        if self.knee_probability <= 0.5:
            return None
        ks = np.array([p[2] for p in self.points if p[2] is not None])
        ws = np.array([w for p, w in zip(self.points, self.weights) if p[2] is not None])
        order = np.argsort(ks)
        cum = np.cumsum(ws[order]) / ws.sum()
        return float(ks[order][np.searchsorted(cum, 0.5)] * self.x_now)

    def best(self) -> int:
        return int(np.argmax(self.weights))

    def mean(self, efc) -> np.ndarray:
        """Capacity [Ah] of the most probable shape at ``efc`` (its coefficients' best)."""
        k = self.best()
        X = np.asarray(efc, dtype=float) / self.x_now
        return self.scale * (_design(X, *self.points[k][1:], family=self.points[k][0])
                             @ self.coef[k])


def _softplus(z):
    return np.logaddexp(0.0, z)


def _design(X, tau, knee, width, *, family: str) -> np.ndarray:
    """Columns of a family's trend at ``X`` (shares of x_now)."""
    cols = [np.ones_like(X), -X]
    if "early" in family:
        cols.append(-(1 - np.exp(-X / tau)))
    if "knee" in family:
        cols.append(-width * (_softplus((X - knee) / width) - _softplus(-knee / width)))
    return np.stack(cols, axis=-1)


def _slope(X, tau, knee, width, *, family: str) -> np.ndarray:
    """d/dX of the columns of :func:`_design`."""
    cols = [np.zeros_like(X), -np.ones_like(X)]
    if "early" in family:
        cols.append(-np.exp(-X / tau) / tau)
    if "knee" in family:
        cols.append(-1.0 / (1.0 + np.exp(-(X - knee) / width)))
    return np.stack(cols, axis=-1)


def _grid() -> list:
    points = [("line", None, None, None)]
    points += [("early", t, None, None) for t in EARLY_TAU]
    points += [("knee", None, k, w) for k in KNEE_AT for w in KNEE_WIDTH]
    points += [("early+knee", t, k, w) for t in EARLY_TAU for k in KNEE_AT for w in KNEE_WIDTH]
    return points


def _wls(design, y, s2, nugget2):
    """Weighted least squares with variances ``s2 + nugget2``: (coef, cov, resid, var)."""
    var = s2 + nugget2
    w = 1.0 / var
    a = design.T @ (design * w[:, None])
    try:
        cov = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return None
    coef = cov @ (design.T @ (w * y))
    return coef, cov, y - design @ coef, var


def _fit_point(design, y, s2, weights):
    """Coefficients with the nugget profiled (a few fixed-point steps of its likelihood)."""
    nugget2 = max(float(np.var(y)) * 1e-4, 1e-14)
    out = None
    for _ in range(4):
        out = _wls(design, y, s2 / weights, nugget2 / weights)
        if out is None:
            return None
        _, _, resid, var = out
        u = 1.0 / (weights * var) ** 2
        nugget2 = max(float(np.sum(u * (resid ** 2 * weights - s2)) / np.sum(u)), 1e-14)
    coef, cov, resid, var = out
    ll = -0.5 * float(np.sum(np.log(2 * np.pi * var) + resid ** 2 / var))
    return coef, cov, resid / np.sqrt(var), ll, nugget2


def fit_fade(efc, capacity_Ah, low95=None, high95=None, weights=None) -> FadeFit | None:
    """The log-capacity trend over the grid of shapes, weighted by evidence.

    Parameters
    ----------
    efc, capacity_Ah : array_like
        Estimates (outliers already left out) [EFC], [Ah].
    low95, high95 : array_like, optional
        Their 95 % intervals [Ah].
    weights : array_like, optional
        Robust weights (0-1) of the estimates (:attr:`.trend.Smoothed.weights`).

    Returns
    -------
    FadeFit or None
        None for fewer than :data:`MIN_ESTIMATES` estimates or no spread in EFC.
    """
    from .trend import sd_from_interval

    x = np.asarray(efc, dtype=float)
    q = np.asarray(capacity_Ah, dtype=float)
    sd = np.zeros_like(q) if low95 is None else sd_from_interval(low95, high95)
    w = np.ones_like(q) if weights is None else np.clip(np.asarray(weights, float), 0.05, 1)
    ok = np.isfinite(x) & np.isfinite(q) & (q > 0)
    x, q, sd, w = x[ok], q[ok], sd[ok], w[ok]
    if x.size < MIN_ESTIMATES or np.ptp(x) <= 0 or x.max() <= 0:
        return None
    order = np.argsort(x, kind="stable")
    x, q, sd, w = x[order], q[order], sd[order], w[order]
    x_now = float(x[-1])
    scale = float(np.median(q))
    X, y, s2 = x / x_now, q / scale, (sd / scale) ** 2
    points = _grid()
    counts = {f: sum(1 for p in points if p[0] == f) for f in FAMILY_PRIOR}
    fits = []
    for fam, tau, knee, width in points:
        design = _design(X, tau, knee, width, family=fam)
        fit = None if design.shape[1] >= x.size else _fit_point(design, y, s2, w)
        if fit is not None and "knee" in fam and fit[0][-1] < 0:
            fit = None  # a knee only ever speeds the fade up
        fits.append(fit)
    scores = np.array([-np.inf if f is None else f[3] for f in fits])
    if not np.isfinite(scores).any():
        return None
    best = int(np.argmax(scores))
    z = fits[best][2]
    rho = float(np.clip(np.corrcoef(z[:-1], z[1:])[0, 1], 0.0, 0.9)) \
        if z.size >= 6 and np.std(z) > 0 else 0.0
    factor = (1 + rho) / (1 - rho)
    log_post = np.full(len(points), -np.inf)
    for k, ((fam, *_), fit) in enumerate(zip(points, fits)):
        if fit is None:
            continue
        n_par = fit[0].size + 1
        log_post[k] = (fit[3] - 0.5 * n_par * np.log(x.size)) / factor \
            + np.log(FAMILY_PRIOR[fam] / counts[fam])
    post = np.exp(log_post - log_post.max())
    post /= post.sum()
    return FadeFit(x_now=x_now, scale=scale, points=points, weights=post,
                   coef=[None if f is None else f[0] for f in fits],
                   cov=[None if f is None else f[1] * factor for f in fits],
                   nugget=float(np.sqrt(fits[best][4])), rho=rho, n=int(x.size))


@dataclass
class EolForecast:
    """Simulated futures of the capacity and where they reach the threshold.

    Attributes
    ----------
    threshold_Ah : float
        End-of-life capacity [Ah].
    eol_efc : float or None
        Median EFC of the crossing (None when fewer than half the futures cross
        within :data:`HORIZON_FACTOR` times today's EFC).
    interval95 : list
        ``[2.5 %, 97.5 %]`` of the crossing; an end is None when beyond the horizon.
    efc, low, median, high : numpy.ndarray
        The futures' 2.5, 50 and 97.5 percentiles of the capacity [Ah] on their grid.
    crossed : float
        Share of the futures that cross within the horizon.
    """

    threshold_Ah: float
    eol_efc: float | None
    interval95: list
    efc: np.ndarray
    low: np.ndarray
    median: np.ndarray
    high: np.ndarray
    crossed: float


def _normal_draws(rng, mean, cov, size: int) -> np.ndarray:
    """``size`` draws of a normal vector; the covariance symmetrised and its negative
    eigenvalues (round-off of a nearly singular fit) set to zero."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    scale = np.sqrt(np.clip(vals, 0.0, None))
    return mean + (rng.standard_normal((size, mean.size)) * scale) @ vecs.T


def simulate(fit: FadeFit, reference_Ah: float, paths: int = PATHS, steps: int = STEPS,
             seed: int = 0, horizon: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Simulated futures of the log-capacity from today (module docstring).

    Returns
    -------
    efc : numpy.ndarray
        ``steps + 1`` EFC from today to ``horizon`` times today.
    log_capacity : numpy.ndarray
        ``(paths, steps + 1)`` ln(capacity [Ah]).
    """
    rng = np.random.default_rng(seed)
    x_now = fit.x_now
    horizon = HORIZON_FACTOR if horizon is None else horizon
    s = np.linspace(0.0, np.log(horizon), steps + 1)
    efc = x_now * np.exp(s)
    pick = rng.choice(len(fit.points), size=paths, p=fit.weights)
    level = np.empty(paths)
    rate = np.empty(paths)  # fade of ln(capacity) per EFC
    knee_seen = np.zeros(paths, dtype=bool)
    one = np.ones(1)
    for k in np.unique(pick):
        rows = np.flatnonzero(pick == k)
        fam, tau, knee, width = fit.points[k]
        coef = _normal_draws(rng, fit.coef[k], fit.cov[k], rows.size)
        if "knee" in fam:
            coef[:, -1] = np.abs(coef[:, -1])
        now = np.clip(coef @ _design(one, tau, knee, width, family=fam)[0], 1e-3, None)
        level[rows] = np.log(fit.scale * now)
        rate[rows] = -(coef @ _slope(one, tau, knee, width, family=fam)[0]) / x_now / now
        knee_seen[rows] = "knee" in fam
    # a trend that does not fall today still fades: at least a tenth of the life's mean
    floor = 0.1 * max(float(np.median(np.log(reference_Ah) - level)), 0.0) / x_now
    rate = np.maximum(rate, max(floor, 1e-12))
    ds = np.diff(s)
    walk = np.cumsum(SIGMA_RATE * np.sqrt(ds) * rng.standard_normal((paths, steps)), axis=1)
    factor = np.exp(np.hstack([np.zeros((paths, 1)), walk]))
    # a knee ahead for trends without one: onset capacity uniform in KNEE_ONSET,
    # conditioned on lying below today's capacity
    share_now = np.exp(level) / reference_Ah
    lo, hi = KNEE_ONSET
    below = np.clip((np.minimum(share_now, hi) - lo) / (hi - lo), 0.0, 1.0)
    p_ahead = KNEE_PROBABILITY * below / (1 - KNEE_PROBABILITY * (1 - below))
    has_knee = rng.random(paths) < p_ahead
    onset = np.log(reference_Ah * (lo + rng.random(paths) * (np.minimum(share_now, hi) - lo)))
    jump = np.exp(rng.uniform(*np.log(KNEE_FACTOR), size=paths))
    dx = np.diff(efc)
    out = np.empty((paths, steps + 1))
    out[:, 0] = level
    current = level.copy()
    for j in range(steps):
        r = rate * factor[:, j]
        r = np.where(has_knee & (current <= onset), r * jump, r)
        current = current - r * dx[j]
        out[:, j + 1] = current
    return efc, out


def forecast_eol(fit: FadeFit, reference_Ah: float, threshold_Ah: float, *,
                 seed: int = 0, paths: int = PATHS) -> EolForecast:
    """EFC at which the capacity reaches ``threshold_Ah``: median and 95 % interval.

    Parameters
    ----------
    fit : FadeFit
        From :func:`fit_fade`.
    reference_Ah : float
        The pack's reference capacity [Ah] (where knees start is a share of it).
    threshold_Ah : float
        End of life [Ah], e.g. 0.8 x the reference.
    """
    efc, logq = simulate(fit, reference_Ah, paths=paths, seed=seed)
    level = np.log(threshold_Ah)
    below = logq <= level
    crossed = below.any(axis=1)
    k = np.argmax(below, axis=1)
    prev = np.clip(k - 1, 0, None)
    rows = np.arange(logq.shape[0])
    a, b = logq[rows, prev], logq[rows, k]
    frac = np.where(a > b, (a - level) / np.where(a > b, a - b, 1.0), 0.0)
    never = 2.0 * efc[-1]  # stands for "not within the horizon"
    when = np.where(crossed, efc[prev] + frac * (efc[k] - efc[prev]), never)
    when = np.where(crossed & (k == 0), efc[0], when)
    lo, mid, hi = np.percentile(when, [2.5, 50.0, 97.5])
    band = np.exp(np.percentile(logq, [2.5, 50.0, 97.5], axis=0))

    def finite(v):
        return float(v) if v <= efc[-1] else None

    return EolForecast(threshold_Ah=float(threshold_Ah), eol_efc=finite(mid),
                       interval95=[finite(lo), finite(hi)], efc=efc, low=band[0],
                       median=band[1], high=band[2], crossed=float(crossed.mean()))


def forecast_capacity(efc, capacity_Ah, low95, high95, reference_Ah: float,
                      threshold_Ah: float, weights=None, seed: int = 0):
    """:func:`fit_fade` then :func:`forecast_eol`: what a pack's health does with its
    capacity estimates (outliers left out) [EFC], [Ah].

    Returns
    -------
    (FadeFit, EolForecast) or None
        None when the estimates cannot carry a trend (:func:`fit_fade`).
    """
    fit = fit_fade(efc, capacity_Ah, low95, high95, weights=weights)
    if fit is None:
        return None
    return fit, forecast_eol(fit, reference_Ah, threshold_Ah, seed=seed)


__all__ = ["FadeFit", "EolForecast", "fit_fade", "forecast_eol", "forecast_capacity",
           "simulate", "PATHS",
           "HORIZON_FACTOR", "KNEE_PROBABILITY", "KNEE_ONSET", "KNEE_FACTOR", "SIGMA_RATE",
           "FAMILY_PRIOR"]
