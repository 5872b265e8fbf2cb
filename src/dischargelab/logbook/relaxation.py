"""What a rest after a load has still to relax when the log stops, and the voltage it
relaxes to.

A flight log ends 30-100 s after landing; a cycler rests 10-15 min. What is left
follows from the rate at which the voltage still moves at the rest's end
(:func:`relaxation`): ``RELAX_TAIL t dV/dt``, between what an RC pair and a diffusion
tail leave, and the 95 % interval spans both. A rest too short to fit takes a share of
the recovery seen (the prior); a fitted rest shorter than the load before it takes at
least that (:func:`shorter_than_load`).

References
----------
.. [1] V. Pop, H. J. Bergveld, P. H. L. Notten, P. P. L. Regtien, "State-of-the-art
   of battery state-of-charge determination", Meas. Sci. Technol. 16 (2005)
   R93-R110 (EMF from relaxation, extrapolated).
.. [2] Texas Instruments, SLUA364B (the rate test of an OCV reading).
.. [3] W. Weppner, R. A. Huggins, "Determination of the kinetic parameters of mixed-
   conducting electrodes", J. Electrochem. Soc. 124 (1977) 1569-1578 (the relaxation
   after a current pulse of length ``T`` goes as ``sqrt(t + T) - sqrt(t)``).
.. [4] G. L. Plett, "Battery Management Systems, Vol. 1", Artech House (2015), ch. 2.
"""

from __future__ import annotations

import numpy as np

from .estimates import Z95

#: Rest samples earlier than this after the load [s] are left out of the relaxation fit
#: (the fast RC part, which the diffusion tail does not describe).
RELAX_SKIP_S = 5.0

#: The tail is fitted only to a rest seen at least this long after the load [s] (a few
#: seconds after a hard flight say little about the minutes of relaxation to come).
RELAX_FIT_MIN_S = 20.0

#: What is left to relax is ``RELAX_TAIL t dV/dt`` at the rest's end (``t`` since the
#: load): an RC pair whose time constant is the rest's length leaves ``1 t dV/dt``, a
#: diffusion tail ``V_inf - c / sqrt(t)`` leaves ``2 t dV/dt`` (the rate test of a fuel
#: gauge's OCV reading, TI SLUA364B, made a measure). Checked on the 10,000 s rest of the
#: CMU eVTOL cell VAH27 after a mission: its first 833 s say 18 mV left (+-12 mV); it rose
#: 17 mV more by 10,000 s, and still rose there (a tail slower than diffusion: a power law
#: fitted to it gives ``t^-0.23`` to ``t^-0.43``; from 749 s it needs 1.7-2.2 ``t dV/dt``,
#: and about 3 would take the early offset out of both CMU cells' charges, docs/logbook.md).
#: A rest of minutes does not show that tail (a power law fitted to its first 749 s decays
#: as ``t^-1``), and the engine's relaxation is RC pairs (1): 2 reads the synthetic lives'
#: capacities 1.2 % high. Kept between the two until a pack's own long rests can set it.
RELAX_TAIL = 1.5

#: ... give or take this many ``t dV/dt`` (95 %): a time constant of half the rest to a
#: tail slower than diffusion.
RELAX_TAIL_HALF95 = 1.0

#: Without enough rest samples to fit, what is left is taken as this share of the
#: recovery seen so far (which holds the instant resistive part too), scaled by
#: ``sqrt(RELAX_PRIOR_T_S / t)``, and twice as uncertain.
RELAX_PRIOR_SHARE = 0.15
RELAX_PRIOR_T_S = 60.0


def relaxation(time_since_s, voltage_V, direction: int, *, loaded_V: float | None = None
               ) -> dict:
    """How far a rest has relaxed, and the voltage it relaxes to [V].

    Parameters
    ----------
    time_since_s : array_like
        Time of each rest sample since the load ended [s] (> 0); None entries or an
        empty array when the rest starts the log.
    voltage_V : array_like
        Pack voltage of each rest sample [V].
    direction : {1, -1, 0}
        +1 after a discharge (the voltage recovers upwards), -1 after a charge, 0 when
        no load came before.
    loaded_V : float, optional
        Last loaded voltage before the rest [V] (the recovery seen so far, for the
        prior when the rest has too few samples to fit).

    Returns
    -------
    dict
        ``voltage_V`` (last reading, median of the last up-to-3 samples), ``relaxed_V``
        (extrapolated), ``left_V`` (signed: what the fitted tail says is left),
        ``half95_V`` (95 % half-width of ``relaxed_V`` from the extrapolation) and
        ``method`` (``"fit"``, ``"prior"``, ``"unloaded"`` (no load before: not
        extrapolated, its last third's wander as the uncertainty) or ``"one sample"``).

    References
    ----------
    Pop et al. (2005); Plett (2015), ch. 2.
    """
    v = np.asarray(voltage_V, dtype=float)
    last = float(np.median(v[-3:]))
    out = {"voltage_V": last, "relaxed_V": last, "left_V": 0.0, "half95_V": 0.0,
           "method": "one sample"}
    t = None if time_since_s is None else np.asarray(time_since_s, dtype=float)
    if direction == 0 or t is None or t.size != v.size:
        # no load before it: nothing to extrapolate; the rest's own wander is its uncertainty
        if v.size >= 3:
            out.update(half95_V=float(np.ptp(v[-max(3, v.size // 3):])), method="unloaded")
        return out
    use = t >= RELAX_SKIP_S
    if use.sum() < 2:
        use = t > 0
    tu, vu = t[use], v[use]
    if tu.size >= 3 and tu[-1] >= 2.0 * tu[0] and tu[-1] >= RELAX_FIT_MIN_S:
        slope, slope_se, t_mid = _end_slope(tu, vu)
        if direction * slope < 0:      # still moving the other way (an idle draw): relaxed
            slope = 0.0
        # left at the middle of the fitted stretch, less what relaxed from there to the end
        moved = slope * (float(tu[-1]) - t_mid)
        left = RELAX_TAIL * t_mid * slope - moved
        if direction * left < 0:
            left = 0.0
        half = RELAX_TAIL_HALF95 * t_mid * abs(slope) + Z95 * RELAX_TAIL * t_mid * slope_se
        out.update(relaxed_V=last + left, left_V=float(left), half95_V=float(half),
                   method="fit")
        return out
    if loaded_V is not None and t.size and t[-1] > 0:
        left = direction * prior_left_V(last, float(loaded_V), float(t[-1]), direction)
        out.update(relaxed_V=last + left, left_V=float(left), half95_V=2.0 * abs(left),
                   method="prior")
    return out


def prior_left_V(last_V: float, loaded_V: float, since_s: float, direction: int) -> float:
    """What the prior says is left to relax [V, unsigned]: :data:`RELAX_PRIOR_SHARE` of the
    recovery from the last loaded voltage to the last rest reading, scaled by
    ``sqrt(RELAX_PRIOR_T_S / t)``."""
    recovery = max(0.0, direction * (last_V - loaded_V))
    return RELAX_PRIOR_SHARE * recovery * float(np.sqrt(RELAX_PRIOR_T_S / max(since_s, 1.0)))


#: The ``method`` of a reading :func:`shorter_than_load` changed.
SHORT_REST_METHOD = "fit, shorter than the load"


def shorter_than_load(reading: dict, load_s: float, loaded_V: float | None,
                      direction: int) -> dict:
    """A fitted rest reading taken sooner after a load than the load lasted, with at least
    what :func:`relaxation`'s prior leaves (:func:`prior_left_V`), twice that as its 95 %
    half width.

    A rest shorter than the load shows only the fast part of the relaxation: after a load
    of ``T`` the diffusion overpotential still relaxes as ``sqrt(t + T) - sqrt(t)``
    (Weppner and Huggins 1977), over the load's own time scale, and the ``t dV/dt`` of a
    fit over ``t << T`` (or a slope that self-heating's cooling turns flat) says little
    of it. Readings that are not fits, or rests longer than the load, are returned as
    they are.
    """
    t = reading.get("since_load_s")
    if (reading.get("method") != "fit" or t is None or loaded_V is None or direction == 0
            or not t < load_s):
        return reading
    last = float(reading["voltage_V"])
    prior = prior_left_V(last, float(loaded_V), float(t), direction)
    left = float(reading.get("left_V") or 0.0)
    half = float(reading.get("half95_V") or 0.0)
    if abs(left) >= prior and half >= 2.0 * prior:
        return reading
    left = direction * max(abs(left), prior)
    return dict(reading, relaxed_V=last + left, left_V=left, half95_V=max(half, 2.0 * prior),
                method=SHORT_REST_METHOD)


def _end_slope(t: np.ndarray, v: np.ndarray) -> tuple[float, float, float]:
    """Slope of the voltage over the last third of a rest [V/s], its standard error, and
    the time it holds at (the stretch's mean time) [s] (least squares, >= 3 samples)."""
    k = max(3, t.size // 3)
    tt, vv = t[-k:] - t[-k], v[-k:]
    slope, intercept = np.polyfit(tt, vv, 1)
    resid = vv - (intercept + slope * tt)
    var_t = float(np.sum((tt - tt.mean()) ** 2))
    se = float(np.sqrt(np.sum(resid ** 2) / max(k - 2, 1) / var_t)) if var_t > 0 else 0.0
    return float(slope), se, float(np.mean(t[-k:]))


__all__ = ["relaxation", "shorter_than_load", "SHORT_REST_METHOD", "RELAX_TAIL",
           "RELAX_PRIOR_SHARE"]
