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

**Only with evidence** (:func:`measure_fade`). No end of life is dated until the fade
is told apart from zero: a straight line with one intercept per kind of estimate (full
discharge, partial, charge, flight: a difference between kinds is an offset, never a
fade) and one common slope, weighted least squares with each estimate's variance from
its interval plus a nugget (profiled from the residuals with four or more degrees of
freedom, else :data:`~.trend.DEFAULT_NUGGET_SHARE` assumed; never below the capacity
trend's own nugget, so the trend's band counts), the slope's variance
widened by the residuals' autocorrelation ``(1 + rho) / (1 - rho)`` and by the trend's
shared error (the part of its band that does not average out, ``s``) as an error of the
level at each end of the span: ``var(r) += 2 s^2 / span^2``. The fade is measured when
``r / sd(r) >= Z_MEASURED`` (its two-sided 95 % interval excludes zero). An end of life
whose 95 % interval reaches inside :data:`SOON_FACTOR` times today's EFC also needs
``r / sd(r) >= Z_SOON`` over a span of at least :data:`SPAN_SOON` EFC.

Until a fade is measured the forecast says so and when it could be: with ``rho_e``
estimates per EFC so far, each with a relative scatter ``sigma`` (median of interval and
nugget), a slope fitted over a span ``S`` of evenly spread estimates has
``var(r) = 12 sigma^2 / (rho_e S^3) + 2 s^2 / S^2`` (``sum (x - mean)^2 = n S^2 / 12``
for ``n = rho_e S`` estimates); the EFC needed is the first estimate's EFC plus the
smallest ``S`` at which a typical fade of the chemistry (:data:`TYPICAL_LIFE_EFC`) is
``Z_MEASURED`` standard deviations.

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
.. [7] Y. Preger, H. M. Barkholtz, A. Fresquez, et al., "Degradation of commercial
   lithium-ion cells as a function of chemistry and cycling conditions",
   J. Electrochem. Soc. 167 (2020) 120532.
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

#: z of a fade told apart from zero: its two-sided 95 % interval excludes zero.
Z_MEASURED = 1.959963984540054

#: An end of life whose 95 % interval reaches inside this many times today's EFC ...
SOON_FACTOR = 5.0
#: ... needs a fade of at least this many standard deviations ...
Z_SOON = 3.0
#: ... measured over estimates spanning at least this many EFC (``benchmarks/fade_span.py``).
SPAN_SOON = 20.0

#: Typical EFC to 80 % of the capacity new, per chemistry, for the EFC a fade needs to
#: show (not for dating): LiCoO2/LiPo a few hundred cycles, NMC/NCA 18650 several
#: hundred to a thousand, LiFePO4 thousands (Preger et al. 2020).
TYPICAL_LIFE_EFC = {"lipo": 400.0, "li-ion": 800.0, "lifepo4": 3000.0}

#: Relative scatter floor of the fade fit's nugget (below the 0.2-0.3 % of repeated
#: capacity tests of a real cell).
NUGGET_FLOOR = 1e-3


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
class FadeEvidence:
    """How well the capacity estimates measure a fade (module docstring).

    Attributes
    ----------
    rate, rate_sd : float or None
        Fade per EFC as a share of the capacity (positive: losing) and its standard
        deviation; None when no kind of estimate has two at different EFC.
    z : float
        ``rate / rate_sd`` (0 when not measurable).
    span_efc : float
        EFC spanned by the estimates that carry the slope.
    estimates : int
        Estimates that carry the slope.
    kinds : list of str
        Kinds of estimate that carry it.
    efc_now : float
        EFC of the last estimate.
    typical_rate : float
        A typical fade of the chemistry [share per EFC].
    efc_needed : float or None
        EFC at which the present noise would let the typical fade be measured (None
        when it never would: the shared error is larger than any span can beat).
    sigma, per_efc, shared, first_efc : float
        The present noise: each estimate's relative scatter, estimates per EFC, the
        shared error [share], and the first estimate's EFC (:func:`efc_to_measure`).
    chemistry : str
        The chemistry of the typical fade.
    """

    rate: float | None
    rate_sd: float | None
    z: float
    span_efc: float
    estimates: int
    kinds: list
    efc_now: float
    typical_rate: float
    efc_needed: float | None
    sigma: float = 0.0
    per_efc: float = 0.0
    shared: float = 0.0
    first_efc: float = 0.0
    chemistry: str = ""

    def efc_for(self, rate: float, z: float, min_span: float = 0.0) -> float | None:
        """EFC at which a fade ``rate`` would be ``z`` standard deviations with the present
        noise, over at least ``min_span`` EFC (None: never)."""
        span = efc_to_measure(rate, self.sigma, self.per_efc, self.shared, z=z)
        return None if span is None else self.first_efc + max(span, min_span)

    @property
    def measured(self) -> bool:
        """The fade's two-sided 95 % interval excludes zero (a loss)."""
        return self.z >= Z_MEASURED

    @property
    def strong(self) -> bool:
        """Measured well outside the noise: :data:`Z_SOON` over :data:`SPAN_SOON` EFC."""
        return self.z >= Z_SOON and self.span_efc >= SPAN_SOON

    def interval95(self) -> list:
        """95 % interval of the fade [share per EFC] ([None, None] when not measurable)."""
        if self.rate is None:
            return [None, None]
        return [self.rate - Z_MEASURED * self.rate_sd, self.rate + Z_MEASURED * self.rate_sd]

    def to_dict(self) -> dict:
        lo, hi = self.interval95()
        return {"rate_per_efc": self.rate, "rate_sd": self.rate_sd,
                "rate_interval95": [lo, hi], "z": self.z, "measured": self.measured,
                "strong": self.strong, "span_efc": self.span_efc,
                "estimates": self.estimates, "kinds": list(self.kinds),
                "typical_rate_per_efc": self.typical_rate, "efc_needed": self.efc_needed}


def typical_rate(chemistry: str | None) -> float:
    """A typical fade [share of the capacity per EFC]: 20 % over :data:`TYPICAL_LIFE_EFC`."""
    return 0.2 / typical_life(chemistry)


def typical_life(chemistry: str | None) -> float:
    """:data:`TYPICAL_LIFE_EFC` of ``chemistry`` (the default chemistry's when unknown)."""
    from ..ocv import DEFAULT_CHEMISTRY

    return TYPICAL_LIFE_EFC.get(chemistry or DEFAULT_CHEMISTRY,
                                TYPICAL_LIFE_EFC[DEFAULT_CHEMISTRY])


def efc_to_measure(rate: float, sigma: float, per_efc: float, shared: float,
                   z: float = Z_MEASURED) -> float | None:
    """Smallest span ``S`` [EFC] of evenly spread estimates over which a fade ``rate``
    [share per EFC] is ``z`` standard deviations, with ``var = 12 sigma^2 / (per_efc
    S^3) + 2 shared^2 / S^2`` (module docstring); None when no span up to 1e6 EFC does."""
    if rate <= 0 or per_efc <= 0:
        return None

    def enough(span):
        var = 12 * sigma ** 2 / (per_efc * span ** 3) + 2 * shared ** 2 / span ** 2
        return rate >= z * np.sqrt(var)

    lo, hi = 1e-3, 1e6
    if not enough(hi):
        return None
    if enough(lo):
        return lo
    for _ in range(80):  # bisection in ln(S), bounded
        mid = np.sqrt(lo * hi)
        lo, hi = (lo, mid) if enough(mid) else (mid, hi)
    return float(hi)


def measure_fade(efc, capacity_Ah, low95, high95, kinds, *, weights=None,
                 shared_Ah: float = 0.0, nugget_Ah: float = 0.0,
                 chemistry: str | None = None) -> FadeEvidence:
    """The fade so far, one intercept per kind of estimate and one slope (module
    docstring), and the EFC a typical fade needs to show with the present noise.

    Parameters
    ----------
    efc, capacity_Ah, low95, high95 : array_like
        Estimates (outliers left out) and their 95 % intervals [EFC], [Ah].
    kinds : sequence of str
        Each estimate's kind (``"full"``, ``"partial"``, ``"charge"``, ``"flight"``...).
    weights : array_like, optional
        Robust weights (0-1) of the estimates (:attr:`.trend.Smoothed.weights`).
    shared_Ah : float
        The trend's shared error today (:attr:`.trend.Smoothed.systematic`) [Ah].
    nugget_Ah : float
        The trend's scatter between estimates beyond their intervals
        (:attr:`.trend.Smoothed.nugget`) [Ah]: the fade fit's nugget is at least this.
    chemistry : str, optional
        For the typical fade (:data:`TYPICAL_LIFE_EFC`).
    """
    from .trend import DEFAULT_NUGGET_SHARE, sd_from_interval

    x = np.asarray(efc, dtype=float)
    q = np.asarray(capacity_Ah, dtype=float)
    sd = sd_from_interval(low95, high95)
    w = np.ones_like(q) if weights is None else \
        np.clip(np.nan_to_num(np.asarray(weights, float), nan=1.0), 0.05, 1)
    k = np.asarray([str(v) for v in kinds], dtype=object)
    ok = np.isfinite(x) & np.isfinite(q) & (q > 0)
    x, q, sd, w, k = x[ok], q[ok], sd[ok], w[ok], k[ok]
    typical = typical_rate(chemistry)
    efc_now = float(x.max()) if x.size else 0.0
    if x.size == 0:
        return FadeEvidence(None, None, 0.0, 0.0, 0, [], efc_now, typical, None,
                            chemistry=chemistry or "")
    level = float(np.median(q))
    y, s2 = q / level, (sd / level) ** 2
    shared = float(shared_Ah) / level
    carry = [kind for kind in dict.fromkeys(k) if np.ptp(x[k == kind]) > 0]
    use = np.isin(k, carry)
    rate = rate_sd = None
    z, span, nugget2, factor = 0.0, 0.0, DEFAULT_NUGGET_SHARE ** 2, 1.0
    if carry:
        xs, ys, ss, ws, ks = x[use], y[use], s2[use], w[use], k[use]
        order = np.argsort(xs, kind="stable")
        xs, ys, ss, ws, ks = xs[order], ys[order], ss[order], ws[order], ks[order]
        design = np.column_stack([(ks == kind).astype(float) for kind in carry]
                                 + [-(xs - xs.mean())])
        if xs.size - design.shape[1] >= 4:
            fit = _fit_point(design, ys, ss, ws)
            nugget2 = max(fit[4], NUGGET_FLOOR ** 2) if fit is not None else nugget2
        nugget2 = max(nugget2, (float(nugget_Ah) / level) ** 2)
        out = _wls(design, ys, ss / ws, nugget2 / ws)
        if out is not None:
            coef, cov, resid, var = out
            zres = resid / np.sqrt(var)
            rho = float(np.clip(np.corrcoef(zres[:-1], zres[1:])[0, 1], 0.0, 0.9)) \
                if zres.size >= 6 and np.std(zres) > 0 else 0.0
            factor = (1 + rho) / (1 - rho)
            span = float(np.ptp(xs))
            rate = float(coef[-1])
            rate_sd = float(np.sqrt(cov[-1, -1] * factor + 2 * shared ** 2 / span ** 2))
            z = rate / rate_sd if rate_sd > 0 else 0.0
    sigma = float(np.sqrt(np.median(s2 + nugget2) * factor))
    per_efc = x.size / max(efc_now - float(x.min()), efc_now, 1.0)
    need = efc_to_measure(typical, sigma, per_efc, shared)
    return FadeEvidence(rate=rate, rate_sd=rate_sd, z=float(max(z, 0.0)), span_efc=span,
                        estimates=int(use.sum()), kinds=list(carry), efc_now=efc_now,
                        typical_rate=typical,
                        efc_needed=None if need is None else float(x.min()) + need,
                        sigma=sigma, per_efc=per_efc, shared=shared, first_efc=float(x.min()),
                        chemistry=chemistry or "")


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
             seed: int = 0, horizon: float | None = None,
             start: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Simulated futures of the log-capacity from today (module docstring).

    ``start``: the capacity trend's value and standard deviation at the last estimate
    [Ah] (:mod:`.trend`, what the health today shows); the futures start there, drawn
    from it, so that they never contradict it. Without it they start on the fitted shape.

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
    if start is not None and start[0] > 0:
        mean, sd = float(start[0]), max(float(start[1]), 0.0)
        level = np.log(mean) + (sd / mean) * rng.standard_normal(paths)
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
                 seed: int = 0, paths: int = PATHS,
                 start: tuple[float, float] | None = None) -> EolForecast:
    """EFC at which the capacity reaches ``threshold_Ah``: median and 95 % interval.

    Parameters
    ----------
    fit : FadeFit
        From :func:`fit_fade`.
    reference_Ah : float
        The pack's reference capacity [Ah] (where knees start is a share of it).
    threshold_Ah : float
        End of life [Ah], e.g. 0.8 x the reference.
    start : (float, float), optional
        Where the futures start (:func:`simulate`).
    """
    efc, logq = simulate(fit, reference_Ah, paths=paths, seed=seed, start=start)
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
                      threshold_Ah: float, weights=None, seed: int = 0,
                      start: tuple[float, float] | None = None):
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
    return fit, forecast_eol(fit, reference_Ah, threshold_Ah, seed=seed, start=start)


def dating(evidence: FadeEvidence, ahead: EolForecast | None, efc_now: float) -> str:
    """Whether an end of life may be given: ``"dated"``, ``"no fade"`` (the fade is not
    told apart from zero) or ``"uncertain"`` (measured, but its 95 % interval reaches inside
    :data:`SOON_FACTOR` times ``efc_now`` without a :attr:`FadeEvidence.strong` fade)."""
    if not evidence.measured:
        return "no fade"
    if ahead is None:
        return "uncertain"
    low = ahead.interval95[0] if ahead.interval95[0] is not None else ahead.eol_efc
    if low is not None and low < SOON_FACTOR * efc_now and not evidence.strong:
        return "uncertain"
    return "dated"


def _pct(rate: float | None) -> str:
    """A fade per EFC as per cent per 100 EFC."""
    if rate is None:
        return "-"
    v = 1e4 * rate
    return f"{v:.0f} %" if abs(v) >= 10 else f"{v:.1f} %" if abs(v) >= 1 else f"{v:.2f} %"


def evidence_words(evidence: FadeEvidence, status: str, efc_now: float) -> str:
    """The forecast in words when no end of life is given (``status`` of :func:`dating`)."""
    from ..ocv import DEFAULT_CHEMISTRY

    chem = evidence.chemistry or DEFAULT_CHEMISTRY
    life = 0.2 / evidence.typical_rate
    unset = "" if evidence.chemistry else ", chemistry not set"
    typical = f"a typical {chem} fade (20 % in {life:.0f} EFC{unset})"
    if status == "uncertain":
        need = evidence.efc_for(evidence.rate, Z_SOON, SPAN_SOON)
        when = "" if need is None else f": about {max(need, efc_now):.0f} EFC"
        return (f"fade measured ({_pct(evidence.rate)} per 100 EFC, {evidence.z:.1f} sigma over "
                f"{evidence.span_efc:.0f} EFC) but not yet enough to date an end of life "
                f"before {SOON_FACTOR * efc_now:.0f} EFC (needs {Z_SOON:g} sigma over "
                f"{SPAN_SOON:g} EFC{when})")
    if evidence.rate is None:
        seen = "one estimate of each kind so far"
    else:
        lo, hi = evidence.interval95()
        seen = (f"fade {_pct(evidence.rate)} per 100 EFC, 95 %: {_pct(lo)} to {_pct(hi)}, "
                f"over {evidence.span_efc:.1f} EFC")
    need = evidence.efc_needed
    if need is None:
        ahead = (f"{typical} stays hidden in the estimates' shared error at any span: a "
                 "full discharge from full (a capacity test) now and then would measure it")
    elif need <= efc_now:
        ahead = f"the fade is slower than {typical}, which would show by now"
    else:
        ahead = f"{typical} would show at about {need:.0f} EFC with the present noise"
    return f"no fade measured yet ({seen}); {ahead}"


__all__ = ["FadeFit", "EolForecast", "FadeEvidence", "fit_fade", "forecast_eol",
           "forecast_capacity", "measure_fade", "dating", "evidence_words", "efc_to_measure",
           "typical_rate", "simulate",
           "PATHS", "Z_MEASURED", "Z_SOON", "SPAN_SOON", "SOON_FACTOR", "TYPICAL_LIFE_EFC",
           "HORIZON_FACTOR", "KNEE_PROBABILITY", "KNEE_ONSET", "KNEE_FACTOR", "SIGMA_RATE",
           "FAMILY_PRIOR"]
