"""Capacity and resistance against equivalent full cycles: trend, 95 % band, end of life.

The trend is a straight line in equivalent full cycles (EFC): the capacity a
Li-ion cell loses to cycling is commonly modelled as proportional to the charge it
has passed (e.g. Wang et al. 2014, whose cycling term is linear in Ah throughput),
and a pack's logbook counts exactly that. A straight line is not the whole story:
fade is fast while the SEI forms, slows in the middle of life, and speeds up again
after a "knee" (Attia et al. 2022), which no trend fitted before the knee can see.
The 95 % band therefore has three parts:

* the uncertainty of the line's two coefficients (least squares, inflated by the
  lag-1 autocorrelation of the residuals, whose effective sample size is smaller);
* a drifting fade rate: the rate is allowed to wander as an integrated random walk
  (the local linear trend of structural time-series models, Harvey 1989), whose
  variance ``q`` is estimated by maximum likelihood from how much the pack's own
  rate has changed so far; ``h`` EFC ahead of the last event this adds
  ``q h^3 / 3`` to the variance of the trend;
* Student's t quantile for the few-event case.

The end of life is the EFC at which the trend crosses ``eol`` times the reference
capacity; its 95 % interval is where the band's edges cross it (open at the top when
the upper edge does not cross within :data:`HORIZON_FACTOR` times the EFC logged).

References
----------
.. [1] J. Wang, J. Purewal, P. Liu, et al., "Degradation of lithium ion batteries
   employing graphite negatives and nickel-cobalt-manganese oxide + spinel manganese
   oxide positives: Part 1, aging mechanisms and life estimation", J. Power Sources
   269 (2014) 937-948.
.. [2] P. M. Attia, A. Bills, F. Brosa Planella, et al., "Review - 'Knees' in
   lithium-ion battery aging trajectories", J. Electrochem. Soc. 169 (2022) 060517.
.. [3] A. C. Harvey, "Forecasting, Structural Time Series Models and the Kalman
   Filter", Cambridge University Press (1989), ch. 2 (local linear trend).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

#: The upper end of the end-of-life interval is searched up to this many times the
#: EFC logged (beyond it the interval is reported open).
HORIZON_FACTOR = 10.0

#: Points of the band returned for plots.
BAND_POINTS = 200


@dataclass
class Trend:
    """A straight-line trend ``y = intercept + slope * efc`` with its 95 % band.

    Attributes
    ----------
    intercept, slope : float
        [unit of y], [unit of y per EFC].
    covariance : numpy.ndarray
        2x2 covariance of (intercept, slope), autocorrelation-inflated.
    rate_drift : float
        Variance rate ``q`` of the fade-rate random walk [unit^2 per EFC^3].
    residual_sd : float
        Scatter of the events about the line [unit of y].
    last_efc : float
        EFC of the last event used.
    dof : int
        Residual degrees of freedom.
    n : int
        Events used.
    """

    intercept: float
    slope: float
    covariance: np.ndarray
    rate_drift: float
    residual_sd: float
    last_efc: float
    dof: int
    n: int

    def mean(self, efc) -> np.ndarray:
        """Trend value at ``efc``."""
        return self.intercept + self.slope * np.asarray(efc, dtype=float)

    def sd(self, efc) -> np.ndarray:
        """Standard deviation of the trend at ``efc`` (coefficients and rate drift)."""
        x = np.asarray(efc, dtype=float)
        c = self.covariance
        var = c[0, 0] + 2 * x * c[0, 1] + x * x * c[1, 1]
        ahead = np.clip(x - self.last_efc, 0.0, None)
        return np.sqrt(np.clip(var, 0.0, None) + self.rate_drift * ahead ** 3 / 3.0)

    @property
    def quantile(self) -> float:
        """Two-sided 95 % quantile (Student's t with the residual degrees of freedom)."""
        return float(stats.t.ppf(0.975, self.dof)) if self.dof > 0 else float("inf")

    def band(self, efc) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper 95 % band at ``efc``."""
        m, s = self.mean(efc), self.sd(efc)
        return m - self.quantile * s, m + self.quantile * s

    def to_dict(self) -> dict:
        return {"intercept": self.intercept, "slope_per_efc": self.slope,
                "rate_drift": self.rate_drift, "residual_sd": self.residual_sd,
                "events": self.n}


def _local_trend_loglik(x: np.ndarray, y: np.ndarray, q: float, r: float) -> float:
    """Diffuse log-likelihood of a local linear trend with an integrated random-walk rate.

    State (level, rate); between events ``d`` EFC apart the level moves by
    ``rate * d`` and the pair gets the integrated-Wiener covariance
    ``q [[d^3/3, d^2/2], [d^2/2, d]]``; each event observes the level with variance ``r``.
    The first two events initialise the state (their terms are left out).
    """
    m = np.array([y[0], 0.0])
    p = np.diag([1e6 * (r + 1.0), 1e6 * (r + 1.0)])
    ll = 0.0
    prev = x[0]
    for k in range(x.size):
        d = x[k] - prev
        prev = x[k]
        f = np.array([[1.0, d], [0.0, 1.0]])
        m = f @ m
        p = f @ p @ f.T + q * np.array([[d ** 3 / 3, d ** 2 / 2], [d ** 2 / 2, d]])
        s = p[0, 0] + r
        v = y[k] - m[0]
        if k >= 2:
            ll -= 0.5 * (np.log(2 * np.pi * s) + v * v / s)
        gain = p[:, 0] / s
        m = m + gain * v
        p = p - np.outer(gain, p[0, :])
    return float(ll)


def rate_drift(x, y) -> float:
    """Maximum-likelihood variance rate of the fade-rate random walk (0 for < 5 events)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.size < 5 or np.ptp(x) <= 0:
        return 0.0
    scale = float(np.std(np.diff(y))) or 1e-9
    span = float(np.ptp(x))

    def cost(p):
        q = np.exp(p[0]) * scale ** 2 / span ** 3
        r = np.exp(p[1]) * scale ** 2
        return -_local_trend_loglik(x, y, q, r)

    best = None
    for start in (-4.0, 0.0, 4.0):
        res = optimize.minimize(cost, [start, 0.0], method="Nelder-Mead",
                                options={"maxiter": 400, "xatol": 1e-3, "fatol": 1e-6})
        if best is None or res.fun < best.fun:
            best = res
    return float(np.exp(best.x[0]) * scale ** 2 / span ** 3)


def fit_trend(efc, values, sd=None) -> Trend | None:
    """Straight-line trend of ``values`` against ``efc`` with its band (None for < 2 events).

    Parameters
    ----------
    efc, values : array_like
        Events in EFC order (outliers already left out).
    sd : array_like, optional
        Standard deviation of each value (from its 95 % interval); sets the scatter
        when two events leave no residual degrees of freedom.
    """
    x = np.asarray(efc, dtype=float)
    y = np.asarray(values, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 2 or np.ptp(x) <= 0:
        return None
    design = np.vstack([np.ones_like(x), x]).T
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    resid = y - design @ coef
    dof = x.size - 2
    if dof > 0:
        s2 = float(resid @ resid / dof)
    else:
        given = np.asarray(sd if sd is not None else [], dtype=float)
        given = given[np.isfinite(given)] if given.size else given
        s2 = float(np.mean(given ** 2)) if given.size else 0.0
        dof = 1
    rho = 0.0
    if resid.size >= 4 and np.std(resid) > 0:
        rho = float(np.clip(np.corrcoef(resid[:-1], resid[1:])[0, 1], 0.0, 0.9))
    cov = s2 * np.linalg.inv(design.T @ design) * (1 + rho) / (1 - rho)
    return Trend(float(coef[0]), float(coef[1]), cov, rate_drift(x, y), float(np.sqrt(s2)),
                 float(x.max()), int(dof), int(x.size))


#: Simulated futures of the fade (Monte Carlo) and their EFC steps.
PATHS = 2000
PATH_STEPS = 400


def fade_paths(trend: Trend, horizon: float, paths: int = PATHS, steps: int = PATH_STEPS,
               seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Simulated futures of a falling trend from its last event to ``horizon`` EFC.

    The fade rate stays a fade: its logarithm ``u`` does the random walk, with the
    variance rate ``q / slope^2`` that gives the same spread of the rate as the
    additive drift of :class:`Trend` near today's rate; the level and ``u`` start
    from the line's estimate and covariance at the last event.

    Returns
    -------
    efc : numpy.ndarray
        ``steps + 1`` EFC values from the last event to ``horizon``.
    values : numpy.ndarray
        ``(paths, steps + 1)`` simulated trend values.
    """
    rng = np.random.default_rng(seed)
    x0 = trend.last_efc
    grid = np.linspace(x0, max(horizon, x0 + 1e-9), steps + 1)
    c = trend.covariance
    level_sd = float(np.sqrt(max(c[0, 0] + 2 * x0 * c[0, 1] + x0 * x0 * c[1, 1], 0.0)))
    rate = -trend.slope
    u_sd = float(np.sqrt(max(c[1, 1], 0.0))) / rate
    sigma_u = float(np.sqrt(trend.rate_drift)) / rate
    # level and rate estimates are correlated through the line's covariance
    cov_lu = (c[0, 1] + x0 * c[1, 1]) / (-rate)
    joint = np.array([[level_sd ** 2, cov_lu], [cov_lu, u_sd ** 2]])
    start = rng.multivariate_normal([trend.mean(x0), np.log(rate)], joint, size=paths,
                                    method="eigh")
    dx = np.diff(grid)
    u = start[:, 1:2] + np.cumsum(sigma_u * np.sqrt(dx) * rng.standard_normal((paths, steps)),
                                  axis=1)
    drop = np.cumsum(np.exp(u) * dx, axis=1)
    values = np.hstack([start[:, :1], start[:, :1] - drop])
    return grid, values


def crossing(trend: Trend, threshold: float, first_efc: float = 0.0, seed: int = 0
             ) -> tuple[float | None, list, tuple | None]:
    """EFC at which a falling trend reaches ``threshold``, with its 95 % interval.

    Before the last event the band is the line's; after it, the simulated futures of
    :func:`fade_paths` give the median crossing and its 2.5 and 97.5 percentiles.

    Returns
    -------
    (efc or None, [low or None, high or None], band or None)
        None when the trend does not fall (no fade seen); ``high`` None when more
        than 2.5 % of the futures do not cross within :data:`HORIZON_FACTOR` times
        the EFC logged. ``band`` is ``(efc, low, high)`` of the simulated futures.
    """
    if trend.slope >= 0:
        return None, [None, None], None
    lo_now, hi_now = trend.band(trend.last_efc)
    horizon = max(trend.last_efc * HORIZON_FACTOR, trend.last_efc + 1.0)
    grid, values = fade_paths(trend, horizon, seed=seed)
    below = values <= threshold
    crossed = below.any(axis=1)
    k = np.argmax(below, axis=1)
    prev = np.clip(k - 1, 0, None)
    rows = np.arange(values.shape[0])
    a, b = values[rows, prev], values[rows, k]
    frac = np.where(a > b, (a - threshold) / np.where(a > b, a - b, 1.0), 0.0)
    never = 2.0 * horizon  # stands for "not within the horizon"
    when = np.where(crossed, grid[prev] + frac * (grid[k] - grid[prev]), never)
    when = np.where(crossed & (k == 0), grid[0], when)
    low, mid, high = (float(v) if v <= horizon else np.inf
                      for v in np.percentile(when, [2.5, 50.0, 97.5]))
    band = (grid, *np.percentile(values, [2.5, 97.5], axis=0))
    if hi_now <= threshold:  # already below at the last event: the line tells when
        central = max(float((threshold - trend.intercept) / trend.slope), first_efc)
        lo_edge, hi_edge = trend.band(np.linspace(first_efc, trend.last_efc, 2001))
        xs = np.linspace(first_efc, trend.last_efc, 2001)
        first = lambda v: float(xs[np.argmax(v <= threshold)]) if (v <= threshold).any() \
            else None  # noqa: E731
        return central, [first(lo_edge), first(hi_edge)], band
    low_value = float(low) if np.isfinite(low) else None
    if lo_now <= threshold:  # the band reaches it already: the low end lies in the past
        xs = np.linspace(first_efc, trend.last_efc, 2001)
        lo_edge, _ = trend.band(xs)
        low_value = float(xs[np.argmax(lo_edge <= threshold)])
    return (float(mid) if np.isfinite(mid) else None,
            [low_value, float(high) if np.isfinite(high) else None], band)


__all__ = ["Trend", "fit_trend", "crossing", "fade_paths", "rate_drift", "HORIZON_FACTOR",
           "BAND_POINTS", "PATHS"]
