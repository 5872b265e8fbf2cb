"""A pack's capacity and resistance over its life, and capacity today with its band.

* Kinds of estimate on one scale (:func:`estimate_kind`, :func:`capacity_over_life`): each
  kind's offset from the slow full discharges' scale is learned where the pack has both,
  and carried in the band until then.
* The drift band (:func:`drift_unit`, :data:`DRIFT_SHARE`): the curves every estimate is
  read through age after the last slow full discharge.
* A fade the estimates cannot show (:func:`hidden_fade`, :data:`HIDDEN_FADE_PER_RISE`): the
  lithium lost below the charge the loads swing through, in proportion to the resistance's
  rise (the same SEI makes both): taken off the estimates, part of it in the band.
* :func:`capacity_now`: capacity today with the parts of its spread (what the benchmarks
  calibrate the constants on).

The pack's figures (:func:`dischargelab.logbook.results.build_health`) are made from these.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .estimates import Z95, log_sd
from .health import DROP_METHOD, SHORT_REST_NOTE, EventHealth
from .trend import Smoothed


def resistance_over_life(per_event: list[EventHealth]) -> Smoothed | None:
    """The resistance trend over the pack's life (at reference conditions when the events
    give it, else as measured)."""
    r_values, r_intervals, _, with_r = _resistances(per_event)
    return _trend(with_r, r_values, r_intervals, nugget_share=RESISTANCE_SCATTER_SHARE)


def _resistances(per_event: list[EventHealth]):
    """Each event's resistance at reference conditions when the events give it, else as
    measured: (values, intervals, basis, events). Resistances read from the open-circuit
    drop (minutes of polarisation in them) only when the events give no other."""
    rows = [e for e in per_event if not e.outlier and e.efc is not None]
    if any(e.resistance_ohm is not None and e.resistance_method != DROP_METHOD for e in rows):
        rows = [e for e in rows if e.resistance_method != DROP_METHOD]
    ref = [e for e in rows if e.resistance_ref_ohm is not None]
    if ref:
        return ([e.resistance_ref_ohm for e in ref],
                [e.resistance_ref_interval95 for e in ref], "reference conditions", ref)
    got = [e for e in rows if e.resistance_ohm is not None]
    return ([e.resistance_ohm for e in got], [e.resistance_interval95 for e in got],
            "as measured", got)


#: Scatter of a pack's resistance between events beyond their intervals, as a share,
#: assumed while fewer than five events can measure it: temperature and state of charge
#: move a load-step resistance by tens of per cent (Plett 2015, ch. 2), so 10 %.
RESISTANCE_SCATTER_SHARE = 0.1


def _trend(chosen: list[EventHealth], values: list, intervals: list,
           **options) -> Smoothed | None:
    from .trend import smooth

    if not chosen:
        return None
    lo = [np.nan if iv is None or iv[0] is None else iv[0] for iv in intervals]
    hi = [np.nan if iv is None or iv[1] is None else iv[1] for iv in intervals]
    return smooth([e.efc for e in chosen], values, lo, hi, **options)


def capacity_over_life(with_cap: list[EventHealth], drift_share: float | None = None,
                       per_event: list[EventHealth] | None = None) -> Smoothed | None:
    """The capacity trend over the pack's life from its events' estimates (the one place
    it is made: the pack's figures and the benchmarks read it). Each kind of estimate
    (:func:`estimate_kind`) has an offset from the full discharges' scale, learned where
    the pack has both and carried in the band until then (:mod:`.trend`). After the last
    full discharge the band widens by ``drift_share`` (:data:`DRIFT_SHARE`) times the
    fade since then (:func:`drift_unit`): the curves every estimate is read through age
    with the pack, and no later full discharge checks them. The fade the resistance of
    ``per_event`` (all the pack's events) says the estimates do not show
    (:func:`hidden_fade`) is taken off the level, :data:`HIDDEN_FADE_SD_SHARE` of it in
    the band; without a slow full discharge, in the band only (:attr:`CapacityNow.tested`)."""
    if not with_cap:
        return None
    kinds = [estimate_kind(e) for e in with_cap]
    scale = float(np.median([e.capacity_Ah for e in with_cap]))
    offset_sd = {k: (RATE_OFFSET_SHARE if k == HIGH_RATE_KIND else KIND_OFFSET_SHARE) * scale
                 for k in set(kinds) if k != REFERENCE_KIND}
    trend = _trend(with_cap, [e.capacity_Ah for e in with_cap],
                   [e.own_interval95 for e in with_cap],
                   systematic=shared_errors(with_cap), kinds=kinds, offset_sd=offset_sd)
    if trend is not None:
        share = DRIFT_SHARE if drift_share is None else drift_share
        anchor = _anchor(with_cap)
        extra = share * drift_unit(trend, anchor, trend.efc)
        trend.level_sd = np.sqrt(trend.level_sd ** 2 + extra ** 2)
        trend.last_cov = trend.last_cov + np.array([[extra[-1] ** 2, 0.0], [0.0, 0.0]])
        taken, sd = hidden_parts(hidden_fade(per_event, anchor, trend.efc),
                                 _tested(with_cap))
        if sd.any():
            spread = sd * trend.level
            trend.level = trend.level * (1.0 - taken)
            trend.level_sd = np.hypot(trend.level_sd, spread)
            trend.last_cov = trend.last_cov + np.array([[spread[-1] ** 2, 0.0], [0.0, 0.0]])
    return trend


#: Standard deviation of the drift of every estimate's scale after the last full
#: discharge, as a share of the fade since then (:func:`capacity_over_life`; chosen on
#: the synthetic conditions of benchmarks/health_matrix.py, leaving each out in turn,
#: and checked on the real eVTOL lives).
DRIFT_SHARE = 0.3

#: The fade the drift is taken on at least [share per EFC] when the estimates show less:
#: 20 % over 1,000 EFC, the slow end of Li-ion cycle lives (estimates read through an
#: aged curve can hide the fade they should show).
FADE_FLOOR_PER_EFC = 2e-4


#: Capacity fade the estimates do not show per unit of the pack's relative resistance
#: rise [share of the capacity]: a cell losing lithium below the charge its loads swing
#: through (SEI growth and plating) keeps its curve over that charge, so every estimate
#: reads the capacity of the part it swings through, while the same SEI raises its
#: resistance (Birkl et al. 2017). Taken off capacity today (:func:`capacity_over_life`).
#: The median over the conditions of benchmarks/health_matrix.py whose resistance rose (the
#: PyBaMM lives: 0.06-0.21; the eVTOL cells as logged and resampled: 0.05-0.09) of the
#: value that fits each best; leaving out any one condition, or one real cell, gives
#: 0.09-0.10 (benchmarks/unseen_fade.py: the eVTOL cells' charges miss 8.3 and 11.9 % per
#: unit of rise).
HIDDEN_FADE_PER_RISE = 0.1

#: Standard deviation of that fade as a share of itself, in capacity today's band on both
#: sides: the largest any PyBaMM life needs for its band to hold 90 % of its tests (they
#: need 0-0.7; the eVTOL cells' bands hold without it).
HIDDEN_FADE_SD_SHARE = 0.7

#: The rise compares the median of the first resistance estimates of one kind of event
#: after the last slow full discharge with the median of as many at the end: a quarter of
#: the estimates, at least :data:`RISE_EVENTS` and at most :data:`RISE_WINDOW`.
RISE_EVENTS = 3
RISE_WINDOW = 25

#: A rise smaller than this is not taken for ageing: temperature and state of charge move
#: a pack's resistance by 10-20 % between events (Plett 2015, ch. 2), more than the rise
#: of a fresh pack's first EFC (the DJI M100 flights: 8 %); the rises the hidden fade was
#: chosen on are 40-150 %.
RISE_MIN = 0.2


def resistance_rise(per_event: list[EventHealth] | None, anchor_efc: float, efc
                    ) -> np.ndarray:
    """The relative rise of the pack's resistance at each ``efc`` since ``anchor_efc``.

    Read within one group of estimates (one kind of event, one way of measuring, at
    reference conditions or not; full discharges left out, measured at another current),
    so that each way's own offset cancels: the group whose estimates scatter least from one
    event to the next (median absolute difference over the median; the charges' constant
    current gives the most repeatable one, where a regression over samples interpolated
    between loads scatters by 20 %). The median of its last ``n`` estimates up to ``efc``
    over the median of its first ``n``, less 1 (:data:`RISE_EVENTS` <= ``n`` <=
    :data:`RISE_WINDOW`; linear between events, 0 before the first that can say, flat
    after the last; 0 when it fell)."""
    x = np.atleast_1d(np.asarray(efc, dtype=float))
    out = np.zeros_like(x)
    groups: dict[tuple, list[tuple[float, float]]] = {}
    for e in per_event or []:
        ref = e.resistance_ref_ohm is not None
        r = e.resistance_ref_ohm if ref else e.resistance_ohm
        if e.outlier or e.efc is None or not r or e.efc <= anchor_efc \
                or estimate_kind(e) == REFERENCE_KIND:
            continue
        groups.setdefault((e.kind, e.resistance_method, ref), []).append((float(e.efc), float(r)))
    usable = [np.array(g) for g in groups.values() if len(g) >= 2 * RISE_EVENTS]
    if not usable:
        return out
    got = min(usable, key=lambda g: float(np.median(np.abs(np.diff(g[:, 1])))
                                          / np.median(g[:, 1])))
    n = int(np.clip(len(got) // 4, RISE_EVENTS, RISE_WINDOW))
    start = float(np.median(got[:n, 1]))
    ends = np.arange(2 * n, len(got) + 1)
    rise = np.array([max(0.0, float(np.median(got[k - n:k, 1])) / start - 1.0) for k in ends])
    at = got[ends - 1, 0]
    return np.where(x >= at[0], np.interp(x, at, rise), 0.0)


def hidden_fade(per_event: list[EventHealth] | None, anchor_efc: float, efc,
                per_rise: float = HIDDEN_FADE_PER_RISE) -> np.ndarray:
    """The fade the estimates do not show [share of the capacity] at each ``efc``:
    ``per_rise`` times the resistance's rise since ``anchor_efc`` (:func:`resistance_rise`
    of ``per_event``; 0 where the rise is less than :data:`RISE_MIN`)."""
    return hidden_share(resistance_rise(per_event, anchor_efc, efc), per_rise)


def hidden_share(rise, per_rise: float = HIDDEN_FADE_PER_RISE):
    """``per_rise`` times the resistance's ``rise`` (0 where it is less than
    :data:`RISE_MIN`): the rule of :func:`hidden_fade`, on numbers or arrays."""
    rise = np.asarray(rise, dtype=float)
    return np.where(rise >= RISE_MIN, per_rise * rise, 0.0)


def hidden_parts(share, tested: bool, sd_share: float = HIDDEN_FADE_SD_SHARE
                 ) -> tuple[np.ndarray, np.ndarray]:
    """What of a hidden fade ``share`` (:func:`hidden_share`) capacity today takes off the
    estimates' level, and its standard deviation, both as shares of that level: all of it
    and ``sd_share`` of it when a slow full discharge sets the scale (``tested``), else
    nothing and the same spread (:meth:`CapacityNow.estimate` says why)."""
    share = np.asarray(share, dtype=float)
    return np.where(tested, share, 0.0), sd_share * share


def seen_fade(trend: Smoothed, anchor_efc: float, efc) -> tuple[np.ndarray, np.ndarray]:
    """The trend's level at ``efc`` [unit] and its fade since ``anchor_efc`` (a share, 0
    where it rose)."""
    level = trend.at(np.asarray(efc, dtype=float))[0]
    start = float(trend.at(anchor_efc)[0][0])
    return level, np.clip((start - level) / start, 0.0, None)


def _short_rest_notes(with_cap: list[EventHealth]) -> list[str]:
    """A line when estimates read a rest the log cut short of the load's length."""
    short = [e for e in with_cap if any(SHORT_REST_NOTE in n for n in e.notes)]
    if not short:
        return []
    return [f"capacity today: {len(short)} of its {len(with_cap)} estimate(s) end on a rest "
            "shorter than the flight before it (the log stops soon after landing); the "
            "relaxation still to come widens them (a log that runs on for as long as the "
            "flight after landing narrows it)"]


def _scale_notes(with_cap: list[EventHealth], trend: Smoothed,
                 per_event: list[EventHealth] | None = None) -> list[str]:
    """Lines on what capacity today's scale rests on, when it is not a recent slow full
    discharge, on the charge it has not seen, and on a fade the resistance says it may
    not show."""
    last = max(e.efc for e in with_cap)
    anchor = _anchor(with_cap)
    tested = _tested(with_cap)
    notes = (_generic_curve_notes(with_cap) + _unseen_depth_notes(with_cap, anchor, tested)
             + _short_rest_notes(with_cap))
    rise = float(resistance_rise(per_event, anchor, [last])[0])
    hidden = float(hidden_share(rise))
    if hidden > 0.0025:
        band = f"+-{1.96 * float(hidden_parts(hidden, tested)[1]):.1%}"
        notes.insert(0, f"capacity today: the resistance rose {rise:.0%} since the last slow "
                     f"full discharge; taken {hidden:.1%} below the estimates for the lithium "
                     "such a rise goes with, lost below the charge they swing through (band "
                     f"{band} for it; a full discharge from full to empty measures it)"
                     if tested else
                     f"capacity today: the resistance rose {rise:.0%} since the first "
                     f"estimate; its band carries {band} for the lithium such a rise goes "
                     "with, lost below the charge the estimates swing through (not taken off "
                     "while no full discharge sets their scale; one from full to empty "
                     "measures it)")
    if not tested:
        return ["capacity today: no slow full discharge yet; its scale rests on "
                f"{len({estimate_kind(e) for e in with_cap})} kind(s) of estimate whose "
                "offsets are not measured, and the band carries them (a full discharge "
                "from full to empty measures them)"] + notes
    extra = DRIFT_SHARE * float(drift_unit(trend, anchor, [last])[0])
    value = float(trend.at(last)[0][0])
    if extra <= 0.005 * value:
        return notes
    return [f"capacity today: {last - anchor:.0f} EFC since the last slow full discharge; "
            f"its band includes +-{1.96 * extra / value:.1%} for the curves' ageing since "
            "(another full discharge resets it)"] + notes


def _generic_curve_notes(with_cap: list[EventHealth]) -> list[str]:
    """A note when estimates were read through a generic curve whose real cells scatter
    about it (their interval wider than their own: :attr:`EventHealth.own_interval95`):
    by how much, at the median estimate."""
    shares = [Z95 * np.sqrt(max(log_sd(e.capacity_interval95) ** 2
                                - log_sd(e.own_interval95) ** 2, 0.0))
              for e in with_cap if e.capacity_own_interval95]
    if not shares:
        return []
    return [f"capacity today: read through a generic curve; where these estimates read it, "
            f"real cells' curves scatter about it by +-{float(np.median(shares)):.0%} of the "
            "capacity (95 %), carried in the band (a slow full discharge of the pack reads "
            "its own curve)"]


#: Lowest state of charge [-] the estimates since the last slow full discharge must reach
#: for capacity today to see the bottom of the charge; above it a note says what is unseen
#: (PyBaMM lives of benchmarks/health_matrix.py lose lithium below missions that stop at
#: 50-60 %: capacity today read 7-8 % high with no sign of it in the estimates).
UNSEEN_BELOW_SOC = 0.3


def _unseen_depth_notes(with_cap: list[EventHealth], anchor: float, tested: bool
                        ) -> list[str]:
    """A note when every estimate since ``anchor`` [EFC] (the last slow full discharge, when
    ``tested``; all of them without one) stopped above :data:`UNSEEN_BELOW_SOC`: the charge
    below is extrapolated, not measured."""
    ends = [e.soc_end for e in with_cap if e.efc is not None and e.soc_end is not None
            and (e.efc > anchor or not tested) and estimate_kind(e) != REFERENCE_KIND]
    if not ends or min(ends) <= UNSEEN_BELOW_SOC:
        return []
    since = "since the last slow full discharge" if tested else "so far"
    return [f"capacity today: {since} every estimate stopped "
            f"above {min(ends):.0%} state of charge; charge lost below that (lithium lost as "
            "the pack ages empties it first) does not show until a deeper discharge or a "
            "capacity test"]


def _tested(with_cap: list[EventHealth]) -> bool:
    """Whether a slow full discharge sets the scale of ``with_cap``'s estimates."""
    return any(estimate_kind(e) == REFERENCE_KIND for e in with_cap)


def _anchor(with_cap: list[EventHealth]) -> float:
    """EFC of the last full discharge, else of the first estimate."""
    fulls = [e.efc for e in with_cap if estimate_kind(e) == REFERENCE_KIND]
    return float(fulls[-1]) if fulls else float(min(e.efc for e in with_cap))


def drift_unit(trend: Smoothed, anchor_efc: float, efc) -> np.ndarray:
    """The fade since ``anchor_efc`` times the capacity at ``efc`` [Ah] (0 before it): the
    trend's own fade, or :data:`FADE_FLOOR_PER_EFC` per EFC when that is more."""
    x = np.asarray(efc, dtype=float)
    level, fade = seen_fade(trend, anchor_efc, x)
    since = np.clip(x - anchor_efc, 0.0, None)
    fade = np.maximum(fade, FADE_FLOOR_PER_EFC * since)
    return np.where(since > 0, fade * level, 0.0)


@dataclass
class CapacityNow:
    """Capacity today with the parts of its spread: the estimates' trend ``value_Ah``
    [Ah], the drift and the resistance's ``rise`` (0 below :data:`RISE_MIN`) apart, so a
    benchmark can choose :data:`DRIFT_SHARE` and :data:`HIDDEN_FADE_PER_RISE` (numbers,
    or arrays of many blocks), and whether a slow full discharge sets the scale
    (``tested``). :meth:`estimate` is capacity today."""

    value_Ah: float
    trend_sd_Ah: float
    drift_unit_Ah: float
    quantile: float
    rise: float = 0.0
    seen_fade: float = 0.0
    tested: bool = True

    def estimate(self, per_rise: float = HIDDEN_FADE_PER_RISE):
        """Capacity today [Ah]: the trend's value less the hidden fade
        (:func:`hidden_share`) when a slow full discharge sets the scale (``tested``).
        Without one the estimates are read through a generic curve, whose error over their
        swing is larger than the lithium lost below it and moves with age either way (the
        eVTOL cells given their label only: the fade they show is within 0.6 points of the
        tests' on VAH27, 5 points over on VAH30); the hidden fade, fitted on lives with a
        full discharge, is then in the band only."""
        taken, _ = hidden_parts(hidden_share(self.rise, per_rise), self.tested)
        return self.value_Ah * (1.0 - taken)

    def interval95(self, drift_share: float = DRIFT_SHARE,
                   per_rise: float = HIDDEN_FADE_PER_RISE,
                   hidden_sd_share: float = HIDDEN_FADE_SD_SHARE) -> list:
        """``[low, high]`` around :meth:`estimate`: the trend's spread, the drift's and
        ``hidden_sd_share`` of the hidden fade."""
        _, hidden = hidden_parts(hidden_share(self.rise, per_rise), self.tested,
                                 hidden_sd_share)
        sd = np.hypot(np.hypot(self.trend_sd_Ah, drift_share * self.drift_unit_Ah),
                      hidden * self.value_Ah)
        centre = self.estimate(per_rise)
        return [centre - self.quantile * sd, centre + self.quantile * sd]


def capacity_now(with_cap: list[EventHealth], per_event: list[EventHealth] | None = None
                 ) -> CapacityNow | None:
    """Capacity today from ``with_cap`` (events with an estimate, no outliers, in order),
    read at the last one's EFC (the trend's value and spread, the hidden fade apart), with
    the resistance of ``per_event`` (all the pack's events, for :func:`hidden_fade`); None
    without any."""
    trend = capacity_over_life(with_cap, drift_share=0.0)
    if trend is None:
        return None
    x = max(e.efc for e in with_cap)
    anchor = _anchor(with_cap)
    mean, sd = trend.at(x)
    rise = float(resistance_rise(per_event, anchor, [x])[0])
    return CapacityNow(value_Ah=float(mean[0]), trend_sd_Ah=float(sd[0]),
                       drift_unit_Ah=float(drift_unit(trend, anchor, [x])[0]),
                       quantile=trend.quantile, rise=rise if rise >= RISE_MIN else 0.0,
                       seen_fade=float(seen_fade(trend, anchor, [x])[1][0]),
                       tested=_tested(with_cap))


#: The kind of estimate whose scale capacity is given on: a slow full discharge's coulomb
#: count (what a capacity test measures).
REFERENCE_KIND = "full discharge"

#: Prior standard deviation of another kind's offset from that scale, as a share of the
#: capacity, until events of both kinds measure it: a charge counts its constant-voltage
#: overshoot and coulombic losses, a load between rests reads both ends through a curve
#: (chosen on the synthetic half of benchmarks/health_matrix.py, checked on the rest).
KIND_OFFSET_SHARE = 0.02


#: A full discharge at a high rate (a mission run to its cutoff), or a load read under load
#: near the cutoff at a current above the reference's (``references.NEAR_CUTOFF_SHARE``):
#: it delivers less than a slow one by the rate-capacity effect, up to ~20 % at 5C for a
#: power cell (Doyle & Newman 1997; CMU VAH30's late missions run to cutoff: -15 %), its
#: offset's prior sd.
HIGH_RATE_KIND = "load: coulomb count at a high rate"
RATE_OFFSET_SHARE = 0.2


def estimate_kind(e: EventHealth) -> str:
    """How an event's capacity was estimated, as one label per kind of estimate (the
    kinds measure capacity differently: :func:`capacity_over_life`)."""
    method = (e.capacity_method or "").split(" (")[0].split(",")[0]
    if method == "coulomb count":
        return REFERENCE_KIND
    if method.endswith(" at a high rate") and e.kind != "charge":
        return HIGH_RATE_KIND
    return f"{'charge' if e.kind == 'charge' else 'load'}: {method}"


def shared_errors(events: list[EventHealth]) -> list[float]:
    """The part of each capacity estimate's error [Ah] that every estimate read through the
    same open-circuit voltage curve shares (``capacity_systematic``; 0 when none)."""
    return [float(e.capacity_systematic or 0.0) * float(e.capacity_Ah) for e in events]
