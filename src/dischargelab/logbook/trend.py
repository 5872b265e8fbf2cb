"""A quantity over a pack's life from its per-event estimates: a smoother with a 95 % band.

Each event's estimate (a capacity [Ah], a resistance [ohm]...) at ``x`` equivalent full
cycles (EFC) is the pack's true value plus an error whose standard deviation is read
from the estimate's 95 % interval. The true value follows a **local linear trend**
whose rate is an integrated random walk (Harvey 1989, ch. 2; Durbin & Koopman 2012,
sec. 3.2), the state-space form of a cubic smoothing spline (Wecker & Ansley 1983):

    level(x + d) = level(x) + d rate(x) + w1,   rate(x + d) = rate(x) + w2,
    cov(w1, w2) = q_x [[d^3/3, d^2/2], [d^2/2, d]],
    estimate_k = level(x_k) + e_k,   var(e_k) = sd_k^2 + nugget^2.

The rate's drift is taken in proportion to the rate itself,
``q_x = q (rate(x)^2 + floor^2) / span`` (``floor`` the mean rate over the estimates,
``span`` their EFC range; the filtered rate stands in for ``rate(x)``): a fade that
speeds up after a knee is followed as fast as it happens, and ``q`` has no unit. ``q``
and the ``nugget`` (the scatter between events that their own intervals do not hold: a
capacity test's interval is its coulomb count's sampling step, not the cycle-to-cycle
spread of a real cell) are read from the likelihood over a grid (diffuse start, the first
two events left out); the smoother runs at the most likely pair, and the value at the
last estimate mixes all pairs by their likelihood, so an uncertain drift widens today's
interval. A Kalman filter and the Rauch-Tung-Striebel smoother give the level and its
variance at every EFC, weighting each event by its interval; the band is Student's t
with ``n - 2`` degrees of freedom (the nugget is measured from the estimates).
Today's variance is scaled up when the latest estimates surprise the filter more than it
expected (their mean squared standardised one-step-ahead error above 1, the covariance
matching of adaptive Kalman filters, Mehra 1972): a knee that has just started.

Errors the estimates share (the open-circuit voltage curve every state of charge was
read through, and its drift as the pack ages) do not average out over many estimates:
given as each estimate's ``systematic`` standard deviation, they are taken as one error
common to the estimates a point stands on and added to the band at the end: at the last
point the mean of the estimates' systematic errors weighted by their (positive) share in
today's value, elsewhere the running mean over the :data:`SYSTEMATIC_WINDOW` nearest
estimates on each side. Without it ~1,000 estimates read through one
curve make a band of +-1 % that misses the truth by 4 % (the CMU eVTOL cells).

Outliers: the errors are taken as Student's t with :data:`T_DOF` degrees of freedom,
fitted by iteratively reweighting each event's variance (the EM algorithm of the
t model: weight ``(nu + 1) / (nu + r^2)`` for a standardised residual ``r``), so an
over- or undercharged cycle pulls the trend little.

References
----------
.. [1] A. C. Harvey, "Forecasting, Structural Time Series Models and the Kalman
   Filter", Cambridge University Press (1989), ch. 2 and 3.
.. [2] J. Durbin, S. J. Koopman, "Time Series Analysis by State Space Methods",
   2nd ed., Oxford University Press (2012), sec. 3.2, 4.4 (smoothing), 7.2 (likelihood).
.. [3] W. E. Wecker, C. F. Ansley, "The signal extraction approach to nonlinear
   regression and spline smoothing", J. Am. Stat. Assoc. 78 (1983) 81-89.
.. [4] K. L. Lange, R. J. A. Little, J. M. G. Taylor, "Robust statistical modeling
   using the t distribution", J. Am. Stat. Assoc. 84 (1989) 881-896.
.. [5] R. K. Mehra, "Approaches to adaptive filtering", IEEE Trans. Automatic Control
   17 (1972) 693-698.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Degrees of freedom of the Student's t errors (robust to a few outliers).
T_DOF = 4.0

#: Reweighting passes of the t errors.
ROBUST_PASSES = 4

#: z of a two-sided 95 % interval.
Z95 = 1.959963984540054

#: Scatter between repeated estimates, as a share of the value, assumed when too few
#: estimates (< :data:`MIN_FOR_NUGGET`) exist to measure it: 0.5 %, about twice the
#: cycle-to-cycle spread of Samsung 30Q cell C's capacity tests (0.2-0.3 %).
DEFAULT_NUGGET_SHARE = 0.005

#: Estimates needed to measure the nugget and the rate drift from the data.
MIN_FOR_NUGGET = 5

#: Latest estimates whose one-step-ahead errors scale today's variance when they are
#: larger than the filter expected (a knee starting: innovation-based adaptive estimation).
RECENT_EVENTS = 6

#: Estimates on each side whose systematic errors make the band's shared part away from
#: the last point (a running mean).
SYSTEMATIC_WINDOW = 10

#: Points of the smoothed curve between the first and the last estimate.
GRID_POINTS = 120


@dataclass
class Smoothed:
    """A quantity over EFC: the smoothed level with its standard deviation.

    Attributes
    ----------
    efc : numpy.ndarray
        EFC of the points (the estimates' and a grid between them), increasing.
    level, level_sd : numpy.ndarray
        Smoothed value and its standard deviation there [unit of the estimates].
    rate, rate_sd : numpy.ndarray
        Its rate of change [unit per EFC] and standard deviation.
    last_cov : numpy.ndarray
        2x2 covariance of (level, rate) at the last point (for extrapolation).
    drift : float
        Variance rate of the rate's random walk at the last point,
        ``q (rate^2 + floor^2) / span`` [unit^2 per EFC^3] (carries the band ahead).
    nugget : float
        Scatter between estimates beyond their intervals [unit].
    weights : numpy.ndarray
        Robust weight of each estimate given, in the order given (1: as its interval
        says, near 0: an outlier; NaN where the estimate was not finite).
    influence : numpy.ndarray
        Share of each estimate given in the last point's level (sums to 1; NaN where
        not used): which events today's value comes from.
    n : int
        Estimates used.
    quantile : float
        Two-sided 95 % quantile of the band: Student's t with ``n - 2`` degrees of
        freedom when the nugget was measured from the estimates, else normal.
    systematic : float
        Standard deviation of the error the estimates share, at the last point [unit]
        (included in ``level_sd``).
    """

    efc: np.ndarray
    level: np.ndarray
    level_sd: np.ndarray
    rate: np.ndarray
    rate_sd: np.ndarray
    last_cov: np.ndarray
    drift: float
    nugget: float
    weights: np.ndarray
    influence: np.ndarray
    n: int
    quantile: float = Z95
    systematic: float = 0.0

    def band(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper 95 % band at :attr:`efc`."""
        return (self.level - self.quantile * self.level_sd,
                self.level + self.quantile * self.level_sd)

    def at(self, efc) -> tuple[np.ndarray, np.ndarray]:
        """Mean and standard deviation at ``efc`` (interpolated between points, carried
        forward with the trend's rate past the last one)."""
        x = np.atleast_1d(np.asarray(efc, dtype=float))
        mean = np.interp(x, self.efc, self.level)
        sd = np.interp(x, self.efc, self.level_sd)
        h = np.clip(x - self.efc[-1], 0.0, None)
        ahead = h > 0
        if ahead.any():
            c = self.last_cov
            mean[ahead] = self.level[-1] + self.rate[-1] * h[ahead]
            var = c[0, 0] + 2 * h * c[0, 1] + h * h * c[1, 1] + self.drift * h ** 3 / 3
            sd[ahead] = np.sqrt(np.clip(var[ahead], 0.0, None))
        return mean, sd

    def interval95(self, efc: float) -> tuple[float, list[float]]:
        """Value at ``efc`` with its 95 % interval ``[low, high]``."""
        mean, sd = self.at(efc)
        m, s = float(mean[0]), float(sd[0])
        return m, [m - self.quantile * s, m + self.quantile * s]

    def to_dict(self, points: int | None = None) -> dict:
        """``{"efc", "value", "sd", "lo", "hi"}`` lists (value, its standard deviation and
        the 95 % band), thinned to ``points``, with ``drift``, ``nugget`` and ``estimates``."""
        idx = np.arange(self.efc.size)
        if points is not None and self.efc.size > points:
            idx = np.unique(np.linspace(0, self.efc.size - 1, points).round().astype(int))
        lo, hi = self.band()
        return {"efc": self.efc[idx].tolist(), "value": self.level[idx].tolist(),
                "sd": self.level_sd[idx].tolist(), "lo": lo[idx].tolist(),
                "hi": hi[idx].tolist(), "quantile": self.quantile, "drift": self.drift,
                "nugget": self.nugget, "estimates": self.n, "systematic": self.systematic}

    @classmethod
    def from_dict(cls, d: dict) -> Smoothed:
        """The band of :meth:`to_dict` back (its rate is not kept: carried past its last
        point, a stored band keeps its last level and spread)."""
        efc = np.asarray(d["efc"], dtype=float)
        level = np.asarray(d["value"], dtype=float)
        sd = np.asarray(d["sd"], dtype=float)
        var = float(sd[-1] ** 2) if sd.size else 0.0
        return cls(efc=efc, level=level, level_sd=sd, rate=np.zeros_like(efc),
                   rate_sd=np.zeros_like(efc), last_cov=np.array([[var, 0.0], [0.0, 0.0]]),
                   drift=float(d.get("drift") or 0.0), nugget=float(d.get("nugget") or 0.0),
                   weights=np.ones(0), influence=np.ones(0), n=int(d.get("estimates") or 0),
                   quantile=float(d.get("quantile") or Z95),
                   systematic=float(d.get("systematic") or 0.0))


def sd_from_interval(low95, high95) -> np.ndarray:
    """Standard deviation [unit] of a normal estimate from its 95 % interval (0 when missing)."""
    lo = np.asarray(low95, dtype=float)
    hi = np.asarray(high95, dtype=float)
    sd = (hi - lo) / (2 * Z95)
    return np.where(np.isfinite(sd) & (sd > 0), sd, 0.0)


def _diffuse(x, y, r) -> tuple[float, float]:
    """Start variances of the level and the rate: wide against the data's own spread
    (a diffuse start; the first two events are left out of the likelihood)."""
    spread = float(np.var(y) + np.max(r)) + 1e-12 * (1.0 + float(np.mean(y * y)))
    return 1e4 * spread, 1e4 * spread / max(float(np.ptp(x)), 1e-9) ** 2


def _floor2(x, y) -> float:
    """Square of the rate [unit/EFC] below which the rate's drift does not shrink further:
    the mean rate over the estimates, or their spread over their span when flat."""
    span = max(float(np.ptp(x)), 1e-9)
    return (max(abs(float(y[-1] - y[0])), float(np.std(y))) / span) ** 2


def _filter_loglik(x, y, r, w, q, nugget2):
    """Log-likelihood of the local linear trend for arrays of ``q`` and ``nugget2``
    (vectorised over them); ``r`` holds each estimate's own variance, ``w`` its weight
    (its error variance is ``(r + nugget2) / w``)."""
    q = np.asarray(q, dtype=float)
    nugget2 = np.asarray(nugget2, dtype=float)
    big, big_rate = _diffuse(x, y, r)
    m0 = np.full(q.shape, y[0])
    m1 = np.zeros(q.shape)
    p00 = np.full(q.shape, big)
    p01 = np.zeros(q.shape)
    p11 = np.full(q.shape, big_rate)
    ll = np.zeros(q.shape)
    floor2, span = _floor2(x, y), max(float(np.ptp(x)), 1e-9)
    prev = x[0]
    for k in range(x.size):
        d = x[k] - prev
        prev = x[k]
        if d > 0:
            qk = q * (m1 * m1 + floor2) / span
            m0 = m0 + d * m1
            p00, p01 = (p00 + 2 * d * p01 + d * d * p11 + qk * d ** 3 / 3,
                        p01 + d * p11 + qk * d * d / 2)
            p11 = p11 + qk * d
        s = p00 + (r[k] + nugget2) / w[k]
        v = y[k] - m0
        if k >= 2:
            ll -= 0.5 * (np.log(2 * np.pi * s) + v * v / s)
        g0, g1 = p00 / s, p01 / s
        m0, m1 = m0 + g0 * v, m1 + g1 * v
        p00, p01, p11 = p00 - g0 * p00, p01 - g0 * p01, p11 - g1 * p01
    return ll, (m0, m1, p00, p01, p11)


def _smooth(x, y, r, w, q, nugget2, grid):
    """Kalman filter and RTS smoother at the union of ``x`` (observed) and ``grid``.

    Returns the points, the smoothed means and covariances, and the weight of each
    estimate in the last point's level (the filter is linear in the estimates once its
    gains are set: ``level_last = influence @ y``)."""
    pts = np.union1d(x, grid)
    obs = {float(v): k for k, v in enumerate(x)}
    n = pts.size
    big, big_rate = _diffuse(x, y, r)
    m = np.array([y[0], 0.0])
    p = np.diag([big, big_rate])
    c0, c1 = np.zeros(x.size), np.zeros(x.size)  # level and rate as weights of the y's
    c0[0] = 1.0
    surprise = np.zeros(x.size)  # squared standardised one-step-ahead errors
    mf, pf, mp, pp = (np.empty((n, 2)), np.empty((n, 2, 2)), np.empty((n, 2)),
                      np.empty((n, 2, 2)))
    floor2, span = _floor2(x, y), max(float(np.ptp(x)), 1e-9)
    prev = pts[0]
    for k in range(n):
        d = pts[k] - prev
        prev = pts[k]
        f = np.array([[1.0, d], [0.0, 1.0]])
        qk = q * (m[1] * m[1] + floor2) / span
        m = f @ m
        c0 = c0 + d * c1
        p = f @ p @ f.T + qk * np.array([[d ** 3 / 3, d * d / 2], [d * d / 2, d]])
        mp[k], pp[k] = m, p
        j = obs.get(float(pts[k]))
        if j is not None:
            s = p[0, 0] + (r[j] + nugget2) / w[j]
            surprise[j] = w[j] * (y[j] - m[0]) ** 2 / (p[0, 0] * w[j] + r[j] + nugget2)
            gain = p[:, 0] / s
            m = m + gain * (y[j] - m[0])
            innovation = -c0
            innovation[j] += 1.0
            c0, c1 = c0 + gain[0] * innovation, c1 + gain[1] * innovation
            p = p - np.outer(gain, p[0, :])
        mf[k], pf[k] = m, p
    ms, ps = mf.copy(), pf.copy()
    for k in range(n - 2, -1, -1):
        d = pts[k + 1] - pts[k]
        f = np.array([[1.0, d], [0.0, 1.0]])
        c = pf[k] @ f.T @ np.linalg.pinv(pp[k + 1])
        ms[k] = mf[k] + c @ (ms[k + 1] - mp[k + 1])
        ps[k] = pf[k] + c @ (ps[k + 1] - pp[k + 1]) @ c.T
    return pts, ms, ps, c0, surprise


#: Grid of the hyperparameters: log of q and of nugget^2 / scale^2 (``scale`` the spread
#: of successive estimates' differences).
LOG_DRIFT = np.arange(-6.0, 6.01, 0.75)
LOG_NUGGET = np.arange(-12.0, 2.01, 0.5)


def _hyper_grid(x, y, r, w, scale, span):
    """Likelihood over the (q, nugget^2) grid and the filtered state at the last point."""
    aa, bb = np.meshgrid(LOG_DRIFT, LOG_NUGGET, indexing="ij")
    q = np.exp(aa.ravel())
    n2 = np.exp(bb.ravel()) * scale ** 2
    ll, last = _filter_loglik(x, y, r, w, q, n2)
    ll = np.where(np.isfinite(ll), ll, -np.inf)
    return q, n2, ll, last


def _mixture(ll, last):
    """Posterior mixture (flat prior on the log grid) of the last point's level: mean,
    variance and the (level, rate) covariance."""
    p = np.exp(ll - ll.max())
    p /= p.sum()
    m0, m1, p00, p01, p11 = last
    mean = np.array([p @ m0, p @ m1])
    cov = np.array([[p @ (p00 + m0 * m0), p @ (p01 + m0 * m1)],
                    [p @ (p01 + m0 * m1), p @ (p11 + m1 * m1)]]) - np.outer(mean, mean)
    return mean, cov


def smooth(efc, values, low95=None, high95=None, *, robust: bool = True,
           grid_points: int = GRID_POINTS,
           nugget_share: float = DEFAULT_NUGGET_SHARE, systematic=None) -> Smoothed | None:
    """The smoothed value over EFC with its 95 % band (module docstring).

    Parameters
    ----------
    efc : array_like
        EFC of each estimate [-].
    values : array_like
        The estimates [any unit, e.g. Ah].
    low95, high95 : array_like, optional
        Their 95 % intervals [same unit]; missing or zero-width intervals count as
        the nugget alone.
    robust : bool
        Student's t errors (outliers pull little) instead of normal ones.
    grid_points : int
        Points of the curve between the first and the last estimate, besides the
        estimates' own.
    nugget_share : float
        Scatter between estimates beyond their intervals, as a share of the value,
        assumed when fewer than :data:`MIN_FOR_NUGGET` estimates cannot measure it.
    systematic : array_like, optional
        Standard deviation of the part of each estimate's error that all estimates share
        [same unit] (NaN or missing: none); added to the band (module docstring).

    Returns
    -------
    Smoothed or None
        None without a finite estimate.
    """
    x = np.asarray(efc, dtype=float)
    y = np.asarray(values, dtype=float)
    sd = np.zeros_like(y) if low95 is None else sd_from_interval(low95, high95)
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        return None
    given = np.flatnonzero(ok)
    order = given[np.argsort(x[ok], kind="stable")]
    x, y, sd = x[order], y[order], sd[order]
    shared = np.zeros(ok.size) if systematic is None else \
        np.nan_to_num(np.asarray(systematic, dtype=float), nan=0.0)
    shared = shared[order]
    # estimates at the same EFC are merged into one, weighted by their variances
    ux, inv = np.unique(x, return_inverse=True)
    share = np.ones(x.size)
    if ux.size < x.size:
        w = 1.0 / np.maximum(sd ** 2, 1e-12 * (1 + y * y))
        share = w / np.bincount(inv, w)[inv]
        shared = np.bincount(inv, w * shared) / np.bincount(inv, w)
        y = np.bincount(inv, w * y) / np.bincount(inv, w)
        has = np.bincount(inv, sd > 0) > 0
        sd = np.where(has, np.sqrt(1.0 / np.bincount(inv, w)), 0.0)
        x = ux
    n = x.size
    level_scale = float(np.median(np.abs(y))) or 1.0
    if n < MIN_FOR_NUGGET or np.ptp(x) <= 0:
        out = _few(x, y, sd, nugget_share * level_scale, n)
    else:
        out = _smooth_many(x, y, sd, level_scale, robust, grid_points)

    def per_given(values):  # back to the order given (merged estimates share)
        full = np.full(ok.size, np.nan)
        full[order] = values[inv] * (share if values is out.influence else 1.0)
        return full

    if np.any(shared > 0):
        _add_systematic(out, x, shared)
    out.weights, out.influence = per_given(out.weights), per_given(out.influence)
    return out


def _add_systematic(out: Smoothed, x: np.ndarray, shared: np.ndarray) -> None:
    """Add the estimates' shared error (``shared`` [unit] at ``x``) to the band of ``out``
    (module docstring)."""
    k = SYSTEMATIC_WINDOW
    padded = np.concatenate((np.full(k, shared[0]), shared, np.full(k, shared[-1])))
    running = np.convolve(padded, np.ones(2 * k + 1) / (2 * k + 1), mode="valid")
    along = np.interp(out.efc, x, running)
    last = float(running[-1])
    if out.influence.size == x.size:
        carry = np.clip(np.nan_to_num(out.influence), 0.0, None)
        last = float(carry @ shared / carry.sum()) if carry.sum() > 0 else last
    along[-1] = last
    out.level_sd = np.sqrt(out.level_sd ** 2 + along ** 2)
    out.last_cov = out.last_cov + np.array([[last ** 2, 0.0], [0.0, 0.0]])
    out.systematic = last


def _smooth_many(x, y, sd, level_scale, robust, grid_points) -> Smoothed:
    """:func:`smooth` of at least :data:`MIN_FOR_NUGGET` estimates at distinct EFC."""
    n = x.size
    r0 = sd ** 2
    span = float(np.ptp(x))
    scale = float(np.std(np.diff(y))) or 1e-6 * level_scale
    weights = np.ones(n)
    grid = np.linspace(x[0], x[-1], grid_points)
    for _ in range(ROBUST_PASSES if robust else 1):
        q_all, n2_all, ll, last = _hyper_grid(x, y, r0, weights, scale, span)
        best = int(np.argmax(ll))
        q, nugget2 = float(q_all[best]), float(n2_all[best])
        pts, ms, ps, influence, surprise = _smooth(x, y, r0, weights, q, nugget2, grid)
        if not robust:
            break
        at_obs = np.searchsorted(pts, x)
        resid2 = (y - ms[at_obs, 0]) ** 2 / (r0 + nugget2 + ps[at_obs, 0, 0])
        new = (T_DOF + 1.0) / (T_DOF + resid2)
        if np.allclose(new, weights, atol=1e-3):
            break
        weights = new
    mean, cov = _mixture(ll, last)
    recent = surprise[2:][-RECENT_EVENTS:]
    cov = cov * max(1.0, float(np.mean(recent))) if recent.size else cov
    ms[-1], ps[-1] = mean, cov
    level_sd = np.sqrt(np.clip(ps[:, 0, 0], 0, None))
    drift = q * (mean[1] ** 2 + _floor2(x, y)) / span
    return Smoothed(efc=pts, level=ms[:, 0], level_sd=level_sd,
                    rate=ms[:, 1], rate_sd=np.sqrt(np.clip(ps[:, 1, 1], 0, None)),
                    last_cov=ps[-1], drift=float(drift), nugget=float(np.sqrt(nugget2)),
                    weights=weights, influence=influence, n=n,
                    quantile=float(stats.t.ppf(0.975, n - 2)))


def _few(x, y, sd, nugget, n) -> Smoothed:
    """Fewer than :data:`MIN_FOR_NUGGET` estimates: a weighted straight line (one
    estimate: itself), with an assumed ``nugget`` [unit]."""
    var = sd ** 2 + nugget ** 2
    if n == 1 or np.ptp(x) <= 0:
        w = 1 / var
        mean = float(np.sum(w * y) / np.sum(w))
        v = float(1 / np.sum(w))
        return Smoothed(efc=x[-1:], level=np.array([mean]), level_sd=np.array([np.sqrt(v)]),
                        rate=np.zeros(1), rate_sd=np.zeros(1),
                        last_cov=np.array([[v, 0.0], [0.0, 0.0]]), drift=0.0, nugget=nugget,
                        weights=np.ones(n), influence=w / np.sum(w), n=n)
    design = np.vstack([np.ones_like(x), x - x[-1]]).T
    w = 1 / var
    cov = np.linalg.inv(design.T @ (design * w[:, None]))
    coef = cov @ design.T @ (w * y)
    pts = np.linspace(x[0], x[-1], GRID_POINTS)
    pts = np.union1d(pts, x)
    h = pts - x[-1]
    level = coef[0] + coef[1] * h
    lsd = np.sqrt(np.clip(cov[0, 0] + 2 * h * cov[0, 1] + h * h * cov[1, 1], 0, None))
    influence = (cov @ (design * w[:, None]).T)[0]  # the intercept at the last point
    return Smoothed(efc=pts, level=level, level_sd=lsd, rate=np.full(pts.size, coef[1]),
                    rate_sd=np.full(pts.size, np.sqrt(cov[1, 1])), last_cov=cov, drift=0.0,
                    nugget=nugget, weights=np.ones(n), influence=influence, n=n)


__all__ = ["Smoothed", "smooth", "sd_from_interval", "Z95", "T_DOF", "DEFAULT_NUGGET_SHARE"]
