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

Kinds of estimate: estimates made differently (a charge, a load between two rests, a full
discharge) may each sit off the values' scale by an offset of their own kind. Each kind
given an ``offset_sd`` is one more state, constant over the life, with that prior standard
deviation: ``estimate_k = level(x_k) + offset_kind(k) + e_k``. Where kinds overlap the
offsets are learned from the data; where the scale's own kind is missing they stay at their
prior, and the level's variance carries it (a difference between kinds is never a trend).
Estimates at one EFC are each an observation.

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

from dataclasses import dataclass, field

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
    offsets: dict = field(default_factory=dict)

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
                "nugget": self.nugget, "estimates": self.n, "systematic": self.systematic,
                "offsets": dict(self.offsets)}

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
                   systematic=float(d.get("systematic") or 0.0),
                   offsets=dict(d.get("offsets") or {}))


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


def _design(kinds, n: int) -> np.ndarray:
    """Observation rows ``h`` (n x D): the level, the rate (never observed) and one offset
    per kind other than the reference (index 0 of ``kinds``' codes)."""
    codes = np.zeros(n, dtype=int) if kinds is None else np.asarray(kinds, dtype=int)
    k = int(codes.max()) if codes.size else 0
    h = np.zeros((n, 2 + k))
    h[:, 0] = 1.0
    for j in range(1, k + 1):
        h[codes == j, 1 + j] = 1.0
    return h


def _start(x, y, r, h, offset_var):
    """Start mean and covariance: a diffuse level and rate, each offset its prior."""
    big, big_rate = _diffuse(x, y, r)
    d = h.shape[1]
    m = np.zeros(d)
    m[0] = y[0]
    p = np.zeros((d, d))
    p[0, 0], p[1, 1] = big, big_rate
    for j in range(2, d):
        p[j, j] = offset_var[j - 2]
    return m, p


def _filter_loglik(x, y, r, w, q, nugget2, h, offset_var):
    """Log-likelihood of the local linear trend for arrays of ``q`` and ``nugget2``
    (vectorised over them); ``r`` holds each estimate's own variance, ``w`` its weight
    (its error variance is ``(r + nugget2) / w``), ``h`` its observation row."""
    q = np.asarray(q, dtype=float)
    nugget2 = np.asarray(nugget2, dtype=float)
    g = q.size
    m0, p0 = _start(x, y, r, h, offset_var)
    m = np.tile(m0, (g, 1))
    p = np.tile(p0, (g, 1, 1))
    ll = np.zeros(g)
    floor2, span = _floor2(x, y), max(float(np.ptp(x)), 1e-9)
    prev = x[0]
    for k in range(x.size):
        d = x[k] - prev
        prev = x[k]
        if d > 0:
            qk = q * (m[:, 1] ** 2 + floor2) / span
            m[:, 0] += d * m[:, 1]
            # F P F' with F = [[1, d], [0, 1]] on the level and rate, identity on offsets
            p[:, 0, :] += d * p[:, 1, :]
            p[:, :, 0] += d * p[:, :, 1]
            p[:, 0, 0] += qk * d ** 3 / 3
            p[:, 0, 1] += qk * d * d / 2
            p[:, 1, 0] += qk * d * d / 2
            p[:, 1, 1] += qk * d
        hk = h[k]
        ph = p @ hk                                   # (g, D)
        s = ph @ hk + (r[k] + nugget2) / w[k]
        v = y[k] - m @ hk
        if k >= 2:
            ll -= 0.5 * (np.log(2 * np.pi * s) + v * v / s)
        gain = ph / s[:, None]
        m += gain * v[:, None]
        p -= gain[:, :, None] * ph[:, None, :]
    return ll, (m, p)


def _smooth(x, y, r, w, q, nugget2, grid, h, offset_var):
    """Kalman filter and RTS smoother at the union of ``x`` (observed; several estimates
    may share one EFC) and ``grid``.

    Returns the points, the smoothed means and covariances, the weight of each estimate
    in the last point's level (the filter is linear in the estimates once its gains are
    set: ``level_last = influence @ y``) and each estimate's squared standardised
    one-step-ahead error."""
    pts = np.union1d(x, grid)
    at = np.searchsorted(pts, x)
    n, dim = pts.size, h.shape[1]
    m, p = _start(x, y, r, h, offset_var)
    c = np.zeros((dim, x.size))       # the state as weights of the y's
    c[0, 0] = 1.0
    surprise = np.zeros(x.size)
    mf, pf, mp, pp = (np.empty((n, dim)), np.empty((n, dim, dim)), np.empty((n, dim)),
                      np.empty((n, dim, dim)))
    floor2, span = _floor2(x, y), max(float(np.ptp(x)), 1e-9)
    prev = pts[0]
    j = 0
    for k in range(n):
        d = pts[k] - prev
        prev = pts[k]
        f = np.eye(dim)
        f[0, 1] = d
        qk = q * (m[1] * m[1] + floor2) / span
        m = f @ m
        c = f @ c
        p = f @ p @ f.T
        p[:2, :2] += qk * np.array([[d ** 3 / 3, d * d / 2], [d * d / 2, d]])
        mp[k], pp[k] = m, p
        while j < x.size and at[j] == k:
            hj = h[j]
            ph = p @ hj
            s = ph @ hj + (r[j] + nugget2) / w[j]
            v = y[j] - m @ hj
            surprise[j] = w[j] * v * v / (w[j] * (ph @ hj) + r[j] + nugget2)
            gain = ph / s
            m = m + gain * v
            innovation = -(hj @ c)
            innovation[j] += 1.0
            c = c + np.outer(gain, innovation)
            p = p - np.outer(gain, ph)
            j += 1
        mf[k], pf[k] = m, p
    ms, ps = mf.copy(), pf.copy()
    for k in range(n - 2, -1, -1):
        f = np.eye(dim)
        f[0, 1] = pts[k + 1] - pts[k]
        g = pf[k] @ f.T @ np.linalg.pinv(pp[k + 1])
        ms[k] = mf[k] + g @ (ms[k + 1] - mp[k + 1])
        ps[k] = pf[k] + g @ (ps[k + 1] - pp[k + 1]) @ g.T
    return pts, ms, ps, c[0], surprise


#: Grid of the hyperparameters: log of q and of nugget^2 / scale^2 (``scale`` the spread
#: of successive estimates' differences).
LOG_DRIFT = np.arange(-6.0, 6.01, 0.75)
LOG_NUGGET = np.arange(-12.0, 2.01, 0.5)


def _hyper_grid(x, y, r, w, scale, h, offset_var):
    """Likelihood over the (q, nugget^2) grid and the filtered state at the last point."""
    aa, bb = np.meshgrid(LOG_DRIFT, LOG_NUGGET, indexing="ij")
    q = np.exp(aa.ravel())
    n2 = np.exp(bb.ravel()) * scale ** 2
    ll, last = _filter_loglik(x, y, r, w, q, n2, h, offset_var)
    ll = np.where(np.isfinite(ll), ll, -np.inf)
    return q, n2, ll, last


def _mixture(ll, last):
    """Posterior mixture (flat prior on the log grid) of the last point's level and rate:
    their mean and 2x2 covariance."""
    p = np.exp(ll - ll.max())
    p /= p.sum()
    m, cov = last[0][:, :2], last[1][:, :2, :2]
    mean = p @ m
    second = np.einsum("g,gij->ij", p, cov + m[:, :, None] * m[:, None, :])
    return mean, second - np.outer(mean, mean)


def _codes(kinds, offset_sd) -> tuple[np.ndarray | None, np.ndarray, list]:
    """Each estimate's offset code (0: the reference scale), the offsets' prior variances
    [unit^2] and their labels."""
    if kinds is None or not offset_sd:
        return None, np.zeros(0), []
    labels = [k for k in dict.fromkeys(kinds) if (offset_sd.get(k) or 0.0) > 0]
    codes = np.array([labels.index(k) + 1 if k in labels else 0 for k in kinds], dtype=int)
    var = np.array([float(offset_sd[k]) ** 2 for k in labels])
    return codes, var, labels


def smooth(efc, values, low95=None, high95=None, *, robust: bool = True,
           grid_points: int = GRID_POINTS, nugget_share: float = DEFAULT_NUGGET_SHARE,
           systematic=None, kinds=None, offset_sd: dict | None = None) -> Smoothed | None:
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
    kinds : sequence, optional
        Each estimate's kind (how it was made: a label).
    offset_sd : dict, optional
        Prior standard deviation [unit] of each kind's offset from the values' scale;
        kinds missing or at 0 are on that scale (module docstring: kinds).

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
    codes, offset_var, labels = _codes(None if kinds is None else [kinds[k] for k in order],
                                       offset_sd)
    h = _design(codes, x.size)
    n = x.size
    level_scale = float(np.median(np.abs(y))) or 1.0
    if n < MIN_FOR_NUGGET or np.ptp(x) <= 0:
        out, offsets = _few(x, y, sd, nugget_share * level_scale, n, h, offset_var), ()
    else:
        out, offsets = _smooth_many(x, y, sd, level_scale, robust, grid_points, h, offset_var)
    out.offsets = {label: float(v) for label, v in zip(labels, offsets)}

    def per_given(values):  # back to the order given
        full = np.full(ok.size, np.nan)
        full[order] = values
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


def _smooth_many(x, y, sd, level_scale, robust, grid_points, h, offset_var
                 ) -> tuple[Smoothed, np.ndarray]:
    """:func:`smooth` of at least :data:`MIN_FOR_NUGGET` estimates, with the kinds' offsets
    at the last point."""
    n = x.size
    r0 = sd ** 2
    span = float(np.ptp(x))
    scale = float(np.std(np.diff(y))) or 1e-6 * level_scale
    weights = np.ones(n)
    grid = np.linspace(x[0], x[-1], grid_points)
    for _ in range(ROBUST_PASSES if robust else 1):
        q_all, n2_all, ll, last = _hyper_grid(x, y, r0, weights, scale, h, offset_var)
        best = int(np.argmax(ll))
        q, nugget2 = float(q_all[best]), float(n2_all[best])
        pts, ms, ps, influence, surprise = _smooth(x, y, r0, weights, q, nugget2, grid, h,
                                                   offset_var)
        if not robust:
            break
        at_obs = np.searchsorted(pts, x)
        fitted = np.einsum("ij,ij->i", h, ms[at_obs])
        var = np.einsum("ij,ijk,ik->i", h, ps[at_obs], h)
        resid2 = (y - fitted) ** 2 / (r0 + nugget2 + var)
        new = (T_DOF + 1.0) / (T_DOF + resid2)
        if np.allclose(new, weights, atol=1e-3):
            break
        weights = new
    mean, cov = _mixture(ll, last)
    recent = surprise[2:][-RECENT_EVENTS:]
    cov = cov * max(1.0, float(np.mean(recent))) if recent.size else cov
    level, level_var = ms[:, 0].copy(), ps[:, 0, 0].copy()
    level[-1], level_var[-1] = mean[0], cov[0, 0]
    rate = ms[:, 1].copy()
    rate[-1] = mean[1]
    drift = q * (mean[1] ** 2 + _floor2(x, y)) / span
    return Smoothed(efc=pts, level=level, level_sd=np.sqrt(np.clip(level_var, 0, None)),
                    rate=rate, rate_sd=np.sqrt(np.clip(ps[:, 1, 1], 0, None)),
                    last_cov=cov, drift=float(drift), nugget=float(np.sqrt(nugget2)),
                    weights=weights, influence=influence, n=n,
                    quantile=float(stats.t.ppf(0.975, n - 2))), ms[-1, 2:]


def _few(x, y, sd, nugget, n, h, offset_var) -> Smoothed:
    """Fewer than :data:`MIN_FOR_NUGGET` estimates: a weighted straight line (one
    estimate, or all at one EFC: their mean), with an assumed ``nugget`` [unit]; an
    estimate off the reference scale carries its kind's offset as error of its own."""
    extra = np.zeros(n)
    if h.shape[1] > 2:
        extra = h[:, 2:] @ offset_var
    var = sd ** 2 + nugget ** 2 + extra
    w = 1 / var
    if n == 1 or np.ptp(x) <= 0:
        mean = float(np.sum(w * y) / np.sum(w))
        v = float(1 / np.sum(w))
        return Smoothed(efc=x[-1:], level=np.array([mean]), level_sd=np.array([np.sqrt(v)]),
                        rate=np.zeros(1), rate_sd=np.zeros(1),
                        last_cov=np.array([[v, 0.0], [0.0, 0.0]]), drift=0.0, nugget=nugget,
                        weights=np.ones(n), influence=w / np.sum(w), n=n)
    design = np.vstack([np.ones_like(x), x - x[-1]]).T
    cov = np.linalg.inv(design.T @ (design * w[:, None]))
    coef = cov @ design.T @ (w * y)
    if n > 2:  # estimates further off the line than their errors: the line is less sure
        # (the reduced chi-square scales the covariance when above 1, the Birge ratio)
        cov = cov * max(1.0, float(np.sum(w * (y - design @ coef) ** 2)) / (n - 2))
    pts = np.union1d(np.linspace(x[0], x[-1], GRID_POINTS), x)
    d = pts - x[-1]
    level = coef[0] + coef[1] * d
    lsd = np.sqrt(np.clip(cov[0, 0] + 2 * d * cov[0, 1] + d * d * cov[1, 1], 0, None))
    influence = (cov @ (design * w[:, None]).T)[0]  # the intercept at the last point
    return Smoothed(efc=pts, level=level, level_sd=lsd, rate=np.full(pts.size, coef[1]),
                    rate_sd=np.full(pts.size, np.sqrt(cov[1, 1])), last_cov=cov, drift=0.0,
                    nugget=nugget, weights=np.ones(n), influence=influence, n=n)


__all__ = ["Smoothed", "smooth", "sd_from_interval", "Z95", "T_DOF", "DEFAULT_NUGGET_SHARE"]
