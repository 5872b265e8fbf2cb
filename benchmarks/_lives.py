"""Seeded synthetic capacity lives with a known truth, for the trend and the forecast.

A life is the capacity of one pack against equivalent full cycles (EFC), relative to
its capacity new, ``q(x) = Q(x) / Q0``, built from the shapes the literature reports:

* an early fade while the SEI forms, ``A (1 - exp(-x / tau))`` (a few per cent);
  sometimes an early rise instead (LFP cells, Severson et al. 2019);
* the main fade, linear in charge throughput or slightly sub-linear,
  ``b x^p`` with ``0.75 <= p <= 1`` (Wang et al. 2014: cycling fade linear in Ah
  throughput; calendar-like fade goes as a power below 1);
* in "knee" lives an acceleration that starts at a capacity between 97 % and 83 %
  of new and multiplies the fade rate by 2 to 12 afterwards, either bent (two lines
  joined smoothly, the Bacon-Watts shape used to find knees) or exponential
  (a runaway such as lithium plating): Attia et al. 2022 review both.

The logged estimates scatter about the truth with white noise, a slowly wandering
(AR(1)) part that a capacity test repeated after a rest or a different charge shows
(cell C's residuals are autocorrelated), and a few over- or undercharged outliers.
Each estimate carries a 95 % interval: tight for capacity tests (the coulomb count's
sampling step, which says nothing about the scatter between cycles) or about the
error of a partial event's estimate.

References
----------
.. [1] P. M. Attia, A. Bills, F. Brosa Planella, et al., "Review - 'Knees' in
   lithium-ion battery aging trajectories", J. Electrochem. Soc. 169 (2022) 060517.
.. [2] K. A. Severson, P. M. Attia, N. Jin, et al., "Data-driven prediction of battery
   cycle life before capacity degradation", Nature Energy 4 (2019) 383-391.
.. [3] J. Wang, J. Purewal, P. Liu, et al., J. Power Sources 269 (2014) 937-948.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: End of life used by the calibration: this share of the capacity new.
EOL = 0.8


@dataclass
class Life:
    """One synthetic life: the truth and what a logbook would hold of it.

    Attributes
    ----------
    q0_Ah : float
        Capacity new [Ah] (the reference of EOL).
    params : dict
        The shape's parameters (``knee_efc`` None for lives without a knee).
    efc, capacity_Ah, low95, high95 : numpy.ndarray
        The logged estimates [EFC], [Ah] and their 95 % intervals [Ah].
    outlier : numpy.ndarray of bool
        Estimates made outliers on purpose.
    eol_efc : float
        EFC where the true capacity first reaches ``EOL * q0_Ah``.
    """

    q0_Ah: float
    params: dict
    efc: np.ndarray
    capacity_Ah: np.ndarray
    low95: np.ndarray
    high95: np.ndarray
    outlier: np.ndarray
    eol_efc: float

    @property
    def knee(self) -> bool:
        return self.params["knee_efc"] is not None

    def truth(self, efc) -> np.ndarray:
        """True capacity [Ah] at ``efc``."""
        return self.q0_Ah * relative_capacity(np.asarray(efc, dtype=float), **self.params)

    def crossing(self, threshold_Ah: float) -> float:
        """EFC where the true capacity first reaches ``threshold_Ah``."""
        return _crossing(self.params, threshold_Ah / self.q0_Ah, 4 * self.eol_efc)

    def upto(self, efc: float):
        """The estimates logged up to ``efc`` (efc, capacity, low95, high95)."""
        k = self.efc <= efc
        return self.efc[k], self.capacity_Ah[k], self.low95[k], self.high95[k]


def _softplus(z):
    return np.logaddexp(0.0, z)


def relative_capacity(x, *, early, tau, rise, tau_rise, b, p, knee_efc, knee_rate,
                      knee_width, knee_shape) -> np.ndarray:
    """``q(x)``: capacity relative to new at ``x`` EFC (see the module docstring)."""
    x = np.asarray(x, dtype=float)
    q = 1.0 - early * (1 - np.exp(-x / tau)) + rise * (1 - np.exp(-x / tau_rise)) - b * x ** p
    if knee_efc is not None:
        z = (x - knee_efc) / knee_width
        if knee_shape == "bent":
            q = q - knee_rate * knee_width * (_softplus(z) - _softplus(-knee_efc / knee_width))
        else:  # exponential runaway from the onset on
            q = q - knee_rate * knee_width * np.where(z > 0, np.expm1(np.minimum(z, 50)), 0.0)
    return q


def _crossing(params: dict, level: float, top: float) -> float:
    grid = np.linspace(0.0, top, 200001)
    q = relative_capacity(grid, **params)
    below = np.flatnonzero(q <= level)
    if below.size == 0:
        return np.inf
    k = int(below[0])
    a, c = q[k - 1], q[k]
    return float(grid[k - 1] + (a - level) / (a - c) * (grid[k] - grid[k - 1]))


def make_life(seed: int, knee: bool, *, partial_share: float = 0.0, wander: bool = True) -> Life:
    """One seeded life (``knee``: with an acceleration before end of life).

    ``partial_share`` of the estimates come from partial events (intervals of 1-6 %);
    the rest are capacity tests (tight intervals).
    """
    rng = np.random.default_rng(seed)
    scale = float(np.exp(rng.uniform(np.log(150), np.log(2500))))  # EFC to 20 % fade
    early = rng.uniform(0.0, 0.05)
    rise = rng.uniform(0.0, 0.01) if rng.random() < 0.2 else 0.0
    p = 1.0 if rng.random() < 0.5 else rng.uniform(0.75, 1.0)
    b = (0.2 - 0.5 * early) / scale ** p
    params = dict(early=early, tau=scale * rng.uniform(0.02, 0.15), rise=rise,
                  tau_rise=scale * rng.uniform(0.03, 0.1), b=b, p=p, knee_efc=None,
                  knee_rate=0.0, knee_width=1.0, knee_shape="bent")
    if knee:
        onset_q = rng.uniform(0.83, 0.97)
        onset = _crossing(params, onset_q, 20 * scale)
        rate = b * p * onset ** (p - 1)
        shape = "bent" if rng.random() < 0.6 else "exp"
        width = onset * (rng.uniform(0.02, 0.15) if shape == "bent" else rng.uniform(0.08, 0.4))
        params.update(knee_efc=onset, knee_rate=rate * (np.exp(rng.uniform(np.log(2), np.log(12)))
                                                        - 1), knee_width=width, knee_shape=shape)
    eol = _crossing(params, EOL, 20 * scale)
    q0 = rng.uniform(1.5, 6.0)
    n = int(rng.integers(40, 121))
    end = 1.15 * eol
    x = np.sort(rng.uniform(0.0, end, n))
    x[0] = rng.uniform(0.0, 0.01 * end)
    white = rng.uniform(0.001, 0.005)
    ar_sd, rho = rng.uniform(0.0, 0.003 if wander else 0.0), rng.uniform(0.3, 0.8)
    ar = np.empty(n)
    ar[0] = rng.normal(0, ar_sd)
    for k in range(1, n):
        ar[k] = rho * ar[k - 1] + np.sqrt(1 - rho ** 2) * rng.normal(0, ar_sd)
    partial = rng.random(n) < partial_share
    partial[0] = False
    claimed = np.where(partial, rng.uniform(0.005, 0.03, n), rng.uniform(0.0001, 0.0005, n))
    err = white * rng.standard_normal(n) + ar + np.where(partial, claimed, 0.0) \
        * rng.standard_normal(n)
    outlier = rng.random(n) < 0.03
    outlier[0] = False
    err = err + outlier * rng.choice([-1.0, 1.0], n) * rng.uniform(0.01, 0.04, n)
    q = relative_capacity(x, **params) * (1 + err)
    half = 1.96 * claimed
    return Life(q0_Ah=q0, params=params, efc=x, capacity_Ah=q0 * q, low95=q0 * q * (1 - half),
                high95=q0 * q * (1 + half), outlier=outlier, eol_efc=eol)
