"""Robust figures of a quantity over a pack's life: its outliers, its value today, and
where it fell through a threshold.

* :func:`flag_outliers`: a capacity far from its neighbours' local line (the modified
  z-score of Iglewicz and Hoaglin 1993 on the residuals of a Theil-Sen line).
* :func:`value_today`: the local line through the last events, read at the last one.
* :func:`observed_crossing`: where the logged values fell through a threshold for good.
"""

from __future__ import annotations

import numpy as np

#: Neighbours on each side for the outlier test's local median.
OUTLIER_NEIGHBOURS = 3

#: Modified z-score above which a capacity is an outlier.
OUTLIER_Z = 3.5

def theil_sen(x, y) -> tuple[float, float]:
    """Theil-Sen line through points: the median of the pairwise slopes, and the intercept
    ``median(y) - slope median(x)`` (Sen 1968; as ``scipy.stats.theilslopes``)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    a, b = np.triu_indices(x.size, 1)
    dx = x[b] - x[a]
    ok = dx != 0
    slope = _median((y[b] - y[a])[ok] / dx[ok]) if ok.any() else 0.0
    return slope, _median(y) - slope * _median(x)


def _median(values: np.ndarray) -> float:
    """Median of a small 1-D array (what ``np.median`` gives, without its overhead)."""
    v = np.sort(values)
    n = v.size
    return float(v[n // 2]) if n % 2 else float(0.5 * (v[n // 2 - 1] + v[n // 2]))


def flag_outliers(efc, values, neighbours: int = OUTLIER_NEIGHBOURS,
                  threshold: float = OUTLIER_Z, half95=None) -> np.ndarray:
    """True where a value sits off the local trend of its neighbours (module docstring).

    With ``half95`` (each value's 95 % half-width), a value is an outlier only when its
    interval does not reach the trend either: a precise estimate slightly off a scattered
    one's trend is not.

    The local trend at each event is the Theil-Sen line (median of pairwise slopes)
    through the :data:`OUTLIER_NEIGHBOURS` nearest events on each side (more on one
    side at the ends), the event itself left out. Events already flagged are left out
    of their neighbours' lines and the test repeated (at most three passes), so one
    odd cycle does not drag its neighbours out with it.
    """
    x = np.asarray(efc, dtype=float)
    y = np.asarray(values, dtype=float)
    n = y.size
    flags = np.zeros(n, dtype=bool)
    if n < 2 * neighbours + 1:
        return flags
    for _ in range(3):
        good = np.flatnonzero(~flags)
        if good.size < 2 * neighbours + 1:
            break
        resid = np.empty(n)
        for k in range(n):
            others = good[good != k]
            pos = int(np.searchsorted(others, k))
            lo = min(max(0, pos - neighbours), others.size - 2 * neighbours)
            idx = others[lo:lo + 2 * neighbours]
            if np.ptp(x[idx]) > 0:
                slope, intercept = theil_sen(x[idx], y[idx])
                resid[k] = y[k] - (intercept + slope * x[k])
            else:
                resid[k] = y[k] - np.median(y[idx])
        centre = np.median(resid[~flags])
        mad = float(np.median(np.abs(resid[~flags] - centre)))
        if mad <= 0:
            break
        new = 0.6745 * np.abs(resid - centre) / mad > threshold
        if half95 is not None:
            new &= np.abs(resid - centre) > np.asarray(half95, dtype=float)
        if np.array_equal(new, flags):
            break
        flags = new
    return flags


#: Events in the local line that gives a pack's capacity and resistance today.
TODAY_EVENTS = 7


def value_today(efc, values, events: int = TODAY_EVENTS) -> float | None:
    """A quantity today: the Theil-Sen line through the last ``events`` values, at the last EFC.

    Robust to one odd event, and local: the fade rate changes over a life, so the
    capacity today is read from the latest events, not from the whole-life trend.
    """
    x = np.asarray(efc, dtype=float)[-events:]
    y = np.asarray(values, dtype=float)[-events:]
    if y.size == 0:
        return None
    if y.size < 3 or np.ptp(x) <= 0:
        return float(np.median(y))
    slope, intercept = theil_sen(x, y)
    return float(intercept + slope * x[-1])


def observed_crossing(efc, values, threshold: float) -> tuple[float, list] | None:
    """Where logged values fell through ``threshold`` for good, when the last two are below it.

    Returns ``(efc, [efc of the last value above, efc of the first below])`` with the
    crossing interpolated between them, or None.
    """
    x = np.asarray(efc, dtype=float)
    y = np.asarray(values, dtype=float)
    if y.size < 3 or not np.all(y[-2:] <= threshold):
        return None
    above = np.flatnonzero(y > threshold)
    if above.size == 0:
        return None
    k = int(above[-1])
    a, b = y[k], y[k + 1]
    at = float(x[k] + (a - threshold) / (a - b) * (x[k + 1] - x[k]))
    return at, [float(x[k]), float(x[k + 1])]
