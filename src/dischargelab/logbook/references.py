"""A pack's full discharges as the measure of its other events.

* :class:`ReferenceCurve`, :func:`partial_capacity`: a partial discharge's capacity from a
  full discharge's voltage curve (each end placed on it: a rest voltage on its
  open-circuit voltage, a loaded voltage on its loaded voltage at the event's current and
  resistance).
* :func:`curve_match`, :func:`matched_capacity`: the full discharges whose loaded curves
  match a partial one best over the charge they share (the same stage of life, wherever
  the event sits in the order), their estimates weighted by the match.
* :func:`learned_curve`: the pack's open-circuit voltage from a slow full discharge (the
  loaded curve plus the settled drop, :func:`settled_drop`, checked against the rests that
  loads from full leave at a counted state of charge, :func:`rest_drop`).

References
----------
.. [1] G. L. Plett, "Battery Management Systems, Vol. 1", Artech House (2015), ch. 2
   (open-circuit voltage from a slow discharge corrected for the resistive drop).
.. [2] M. Lewerenz, J. Muennix, J. Schmalstieg, S. Kaebitz, M. Knips, D. U. Sauer,
   "Systematic aging of commercial LiFePO4|Graphite cylindrical cells including a theory
   explaining rise of capacity during aging", J. Power Sources 345, 254-263 (2017)
   (capacity regained from the anode's overhang).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .estimates import LEARNED_CURVE_SD_CELL_V, OcvCurve, robust_sd

#: Standard deviation of a voltage placed on the reference curve, per cell [V]:
#: relaxation left after a rest, temperature and ageing since the reference.
VOLTAGE_SD_CELL_V = 0.010

#: A rest after the load counts as relaxed after this long [s]; sooner the loaded curve
#: is used at the last loaded sample.
RELAXED_S = 60.0

#: Partial events using less than this share of the capacity get no capacity.
MIN_SHARE = 0.2

#: Full discharges whose curves match a partial one best, used as its references.
MATCH_REFERENCES = 3

#: A full discharge at this C-rate or slower teaches the pack's open-circuit voltage.
SLOW_C_RATE = 0.5

#: The resistive drop of a slow discharge is measured this long after its start [s] (the
#: polarisation has built up): its loaded curve from there on, extrapolated back to the
#: start, lies that drop below the rest voltage.
SETTLE_S = 300.0


@dataclass
class ReferenceCurve:
    """A full discharge of the pack as the measure of its partial ones.

    ``share`` is the share of the capacity drawn (0 full, 1 empty) at each curve
    point; ``loaded(current, resistance)`` and ``ocv`` give the voltage there.
    """

    event: dict
    capacity_Ah: float
    model: object | None = None

    def __post_init__(self):
        curve = self.event["curve"]
        q = np.asarray(curve["charge_Ah"], dtype=float)
        self.share = q / q[-1]
        self.voltage = np.asarray(curve["voltage_V"], dtype=float)
        self.current = np.asarray(curve["current_A"], dtype=float)
        self.resistance = float(self.event.get("resistance_ohm") or 0.0)
        self.drop = self._model_drop(q) if self.model is not None else \
            self.resistance * self.current
        # the drop the load settled to [ohm] (settled_drop, at least the step resistance),
        # which ocv uses; None with a pack model or without a rest before the discharge
        self.settled_ohm = None if (self.model is not None
                                    or self.event.get("rest_voltage_V") is None
                                    or float(self.event.get("mean_current_A") or 0.0) <= 0) \
            else max(settled_drop(self.event), self.resistance)

    def _model_drop(self, q: np.ndarray) -> np.ndarray:
        """The model's voltage drop at the reference current [V], at the same charge."""
        bat = self.model
        qm = np.minimum(q, 0.999 * bat.capacity_Ah)
        with np.errstate(all="ignore"):
            rest = np.asarray(bat.voltage(np.zeros_like(qm), qm), dtype=float)
            loaded = np.asarray(bat.voltage(self.current, qm), dtype=float)
        drop = rest - loaded
        return np.where(np.isfinite(drop), drop, self.resistance * self.current)

    @property
    def ocv(self) -> np.ndarray:
        """Open-circuit voltage at each point [V]: the loaded voltage plus the drop the load
        settled to (:attr:`settled_ohm`, as :func:`learned_curve` takes it; the step
        resistance misses the polarisation that builds over minutes, and a rest 45 % down
        read on it came out 0.05 of the charge too full), and over the first
        :data:`SETTLE_S`, where the polarisation is still building, the line from the rest
        voltage to there; else the loaded voltage plus the model's or the step
        resistance's drop."""
        settled = self.settled_ohm
        if settled is None:
            return self.voltage + self.drop
        ocv = self.voltage + settled * self.current
        rest = float(self.event["rest_voltage_V"])
        q = np.asarray(self.event["curve"]["charge_Ah"], dtype=float)
        q_settle = min(float(self.event["mean_current_A"]) * SETTLE_S / 3600.0, 0.1 * q[-1])
        early = q < q_settle
        ocv[early] = rest + (float(np.interp(q_settle, q, ocv)) - rest) * q[early] / q_settle
        return ocv

    @property
    def ocv_sd_V(self) -> float:
        """Standard deviation of :attr:`ocv` [V]: half the polarisation that built between
        the step and :data:`SETTLE_S` (as much may still build after it: a slow relaxation
        of 900 s read 0.027 of the charge too full 45 % down), 0 when it is not used."""
        settled = self.settled_ohm
        if settled is None:
            return 0.0
        return 0.5 * (settled - self.resistance) * float(self.event["mean_current_A"])

    def loaded(self, current_A: float, resistance_ohm: float | None) -> np.ndarray:
        """Voltage at ``current_A`` of a pack whose step resistance is now ``resistance_ohm``."""
        scale = current_A / np.where(self.current > 0, self.current, np.nan)
        drop = np.nan_to_num(self.drop * scale, nan=self.resistance * current_A)
        extra = 0.0 if resistance_ohm is None else (resistance_ohm - self.resistance) * current_A
        return self.voltage + self.drop - drop - extra

    def place(self, voltage_V: float, curve: np.ndarray, sd_V: float
              ) -> tuple[float, float] | None:
        """Share of the capacity drawn where ``curve`` reads ``voltage_V``, and its sd."""
        falling = np.minimum.accumulate(curve)
        if not np.isfinite(voltage_V) or voltage_V < falling[-1]:
            return None
        if voltage_V >= falling[0]:
            share = 0.0
        else:
            k = int(np.argmax(falling <= voltage_V))
            a, b = falling[k - 1], falling[k]
            share = float(self.share[k - 1] + (a - voltage_V) / (a - b)
                          * (self.share[k] - self.share[k - 1])) if a > b else float(self.share[k])
        lo = float(np.interp(share - 0.05, self.share, curve))
        hi = float(np.interp(min(share + 0.05, 1.0), self.share, curve))
        slope = abs(lo - hi) / (min(share + 0.05, 1.0) - max(share - 0.05, 0.0))
        return share, (sd_V / slope if slope > 0 else 1.0)


def partial_capacity(event: dict, ref: ReferenceCurve, cells: int
                     ) -> tuple[float | None, list | None, str]:
    """Capacity [Ah] of a partial discharge or flight from the reference curve."""
    sd = VOLTAGE_SD_CELL_V * cells
    r_now = event.get("resistance_ohm")
    rest, top = event.get("rest_voltage_V"), ref.event.get("rest_voltage_V")
    if r_now is not None and rest is not None and top is not None and rest > top + sd:
        # a rest above the full discharge's own: a charge still relaxing, whose excess the
        # first load step would count as resistance (and move the end: +8 % at 40 mV)
        r_now = None
    curve = event["curve"]
    ocv_sd = float(np.hypot(sd, ref.ocv_sd_V))
    if event.get("rest_voltage_V") is not None:
        start = ref.place(event["rest_voltage_V"], ref.ocv, ocv_sd)
        how_start = "rest voltage before"
    else:
        start = ref.place(curve["voltage_V"][0], ref.loaded(curve["current_A"][0], r_now),
                          2 * sd)
        how_start = "first loaded voltage"
    if event.get("rest_after_V") is not None and (event.get("rest_after_s") or 0) >= RELAXED_S:
        end = ref.place(event["rest_after_V"], ref.ocv, ocv_sd)
        how_end = "rest voltage after"
    else:
        end = ref.place(event["end_voltage_V"], ref.loaded(event["end_current_A"], r_now), sd)
        how_end = "last loaded voltage"
    if start is None or end is None:
        return None, None, "a voltage lies below the reference curve"
    share = end[0] - start[0]
    if share < MIN_SHARE:
        return None, None, f"uses {100 * max(share, 0):.0f} % of the capacity (too little)"
    cap = float(event["discharged_Ah"]) / share
    half = 1.96 * cap * float(np.hypot(start[1], end[1])) / share
    rate = ""
    if how_end == "last loaded voltage" and end[0] > 1.0 - NEAR_CUTOFF_SHARE and \
            faster(event.get("mean_current_A"), ref.event.get("mean_current_A")):
        rate = " at a high rate"
    return cap, [cap - half, cap + half], f"reference curve{rate} ({how_start}, {how_end})"


#: A load read under load within this share of the reference's end, at a current above
#: the reference's, ran to where the rate moves the cutoff most: the reference scaled by
#: its resistance does not hold the rate-capacity effect there (a late VAH30 mission read
#: at 60 s: -24 % inside +-1.2 %), so it is an estimate at a high rate
#: (:data:`.over_life.HIGH_RATE_KIND`), whose offset is learned, not taken as the scale.
NEAR_CUTOFF_SHARE = 0.2


def curve_match(event: dict, reference: dict) -> float:
    """RMS difference [V] between an event's loaded voltage and a full discharge's over the
    charge they share (from 5 % of the event's charge on); inf without overlap."""
    ce, cr = event.get("curve") or {}, reference.get("curve") or {}
    if not ce.get("charge_Ah") or not cr.get("charge_Ah"):
        return float("inf")
    qe, ve = np.asarray(ce["charge_Ah"], float), np.asarray(ce["voltage_V"], float)
    qr, vr = np.asarray(cr["charge_Ah"], float), np.asarray(cr["voltage_V"], float)
    use = (qe >= 0.05 * qe[-1]) & (qe <= qr[-1])
    if use.sum() < 3:
        return float("inf")
    return float(np.sqrt(np.mean((ve[use] - np.interp(qe[use], qr, vr)) ** 2)))


def matched_capacity(event: dict, refs: list[tuple[dict, float]], cells: int, model=None
                     ) -> tuple[float | None, list | None, str]:
    """Capacity of a partial discharge from its best-matching full discharges
    (:data:`MATCH_REFERENCES`, weighted by ``1 / rms^2`` of :func:`curve_match`)."""
    scored = sorted(((curve_match(event, e), e, cap) for e, cap in refs),
                    key=lambda item: item[0])
    scored = [s for s in scored if np.isfinite(s[0])][:MATCH_REFERENCES] or \
        [(1.0, e, cap) for e, cap in refs[-1:]]
    caps, lows, highs, weights, hows = [], [], [], [], []
    for rms, e, cap in scored:
        value, interval, how = partial_capacity(event, ReferenceCurve(e, cap, model=model), cells)
        if value is None:
            hows.append(how)
            continue
        caps.append(value)
        lows.append(interval[0])
        highs.append(interval[1])
        weights.append(1.0 / max(rms, 1e-4) ** 2)
        hows.append(how)
    if not caps:
        return None, None, hows[0] if hows else "no reference curve"
    w = np.asarray(weights) / np.sum(weights)
    cap = float(np.sum(w * caps))
    spread = float(np.sqrt(np.sum(w * (np.asarray(caps) - cap) ** 2)))
    half = max(float(np.sum(w * (np.asarray(highs) - np.asarray(lows)))) / 2.0, 1.96 * spread)
    return cap, [cap - half, cap + half], f"{hows[0]}, {len(caps)} matched full discharge(s)"


def is_slow(event: dict, capacity_Ah: float) -> bool:
    """A full discharge slow enough to teach the open-circuit voltage, with a rest before."""
    mean_i = float(event.get("mean_current_A") or 0.0)
    return (len((event.get("curve") or {}).get("charge_Ah") or []) >= 10
            and event.get("rest_voltage_V") is not None
            and 0 < mean_i <= SLOW_C_RATE * capacity_Ah)


def settled_drop(event: dict) -> float:
    """Resistance [ohm] a slow discharge's load showed once settled: its loaded curve from
    :data:`SETTLE_S` on, extrapolated back to the start, lies this times the current below
    the rest voltage (series resistance and polarisation; the open-circuit voltage's own
    fall left out by the extrapolation)."""
    curve = event["curve"]
    q = np.asarray(curve["charge_Ah"], dtype=float)
    v = np.asarray(curve["voltage_V"], dtype=float)
    mean_i = float(event["mean_current_A"])
    q_settle = min(mean_i * SETTLE_S / 3600.0, 0.1 * q[-1])
    v1, v2 = float(np.interp(q_settle, q, v)), float(np.interp(2 * q_settle, q, v))
    return max(0.0, float(event["rest_voltage_V"]) - (v1 + (v1 - v2))) / mean_i


#: Loads from full read by :func:`rest_drop` at most (the nearest after the discharge),
#: and at least (fewer give no scatter to judge the reading by).
REST_DROP_LOADS = 5
REST_DROP_MIN = 3


def rest_drop(event: dict, rests: list[tuple[float, float]]) -> tuple[float, float] | None:
    """Resistance [ohm] a slow full discharge's load showed, read where its open-circuit
    voltage is known, and the scatter of that reading between rests [ohm]: a load that
    starts from full and leaves a relaxed rest after ``counted_Ah`` has the open-circuit
    voltage ``relaxed_V`` there, and the slow discharge's loaded voltage at the same charge
    drawn lies the drop below it (Plett 2015, ch. 2). ``rests`` holds ``(counted_Ah,
    relaxed_V)`` pack pairs; the median over the first :data:`REST_DROP_LOADS` inside the
    discharge's charge and their scatter (1.4826 x their median absolute deviation), None
    with fewer than :data:`REST_DROP_MIN` (a scatter needs them).

    Unlike :func:`settled_drop` it needs no open-circuit voltage near full: a curve that
    falls steeply from full (LiFePO4 over its last per cent) puts that fall in the
    settled drop's extrapolation, not here."""
    curve = event["curve"]
    q = np.asarray(curve["charge_Ah"], dtype=float)
    v = np.asarray(curve["voltage_V"], dtype=float)
    mean_i = float(event["mean_current_A"])
    drops = np.array([(relaxed - float(np.interp(counted, q, v))) / mean_i
                      for counted, relaxed in rests[:REST_DROP_LOADS]
                      if 0.1 * q[-1] < counted < 0.9 * q[-1]]) if mean_i > 0 else np.array([])
    if drops.size < REST_DROP_MIN:
        return None
    mid = float(np.median(drops))
    return max(mid, 0.0), robust_sd(drops, mid)


def checked_drop(ordered: list[dict], position: int, event: dict, cells: int,
                 ends_full) -> float:
    """The slow full discharge ``event`` (at ``position`` in ``ordered``)'s settled drop
    [ohm], or its drop read at the rests the next loads from full leave
    (:func:`rest_drop`; ``ends_full(charge figures)`` says which charges end full) when the
    two differ by more than the learned curve's error per cell and more than the rests'
    own scatter: the settled drop's extrapolation takes a steep fall from full (LiFePO4)
    for resistance, while rests that disagree among themselves (relaxation left, ageing
    since) read nothing better."""
    rests = []
    for later in ordered[position + 1:]:
        if len(rests) >= REST_DROP_LOADS:
            break
        d = later.get("details") or {}
        before, after = d.get("rest_before") or {}, d.get("rest_after")
        if later.get("kind") in ("discharge", "flight") and after and \
                (later.get("rest_after_s") or 0) >= RELAXED_S and \
                ends_full(before.get("after_charge")):
            rests.append((float(d.get("counted_Ah") or 0.0), float(after["relaxed_V"])))
    drop = settled_drop(event)
    check = rest_drop(event, rests)
    if check is None:
        return drop
    limit = max(LEARNED_CURVE_SD_CELL_V * cells / float(event["mean_current_A"]), check[1])
    return check[0] if abs(check[0] - drop) > limit else drop


def learned_curve(event: dict, capacity_Ah: float, cells: int, chemistry: str | None,
                  resistance_ohm: float | None = None) -> OcvCurve | None:
    """The pack's open-circuit voltage from one slow full discharge (see the module
    docstring), or None when it is not slow or has no rest before it.

    ``resistance_ohm`` (default: :func:`settled_drop` of this discharge) is added back at
    its current. The pack's first slow full discharge gives it for all of them: an aged
    cell's open-circuit voltage falls faster near full, which the extrapolation from the
    settled curve then takes for resistance (the CMU eVTOL cells' C/5 tests: 0.08 ohm fresh,
    0.16 ohm at 17 % fade, while the step resistance grows far less)."""
    if not is_slow(event, capacity_Ah):
        return None
    curve = event["curve"]
    q = np.asarray(curve["charge_Ah"], dtype=float)
    v = np.asarray(curve["voltage_V"], dtype=float)
    i = np.asarray(curve["current_A"], dtype=float)
    resistance = settled_drop(event) if resistance_ohm is None else resistance_ohm
    rest = event["rest_voltage_V"]
    return OcvCurve.from_discharge(q, v, i, cells=cells, resistance_ohm=resistance,
                                   rest_before_V=float(rest),
                                   temperature_C=event.get("temperature_start_C"),
                                   source=f"the pack's slow full discharge ({event.get('source')})")


def rate_kinds(ordered: list[dict], out: list) -> None:
    """Mark the full discharges of ``out`` (the events' EventHealth; ``ordered``: their
    stored summaries) much faster than the pack's slowest ones (a mission run to its
    cutoff beside C/5 capacity tests): they deliver less by the rate-capacity effect, and
    their coulomb count is a kind of estimate of its own. Their currents are compared (a
    test at the same current on an aged pack is the same test, however much less it
    delivers). The others are a plain coulomb count (marked again when the pack's set of
    full discharges changes)."""
    rates = {k: float(ordered[k].get("mean_current_A") or 0.0)
             for k, h in enumerate(out) if h.full and h.capacity_Ah}
    if not rates:
        return
    slowest = min(rates.values())
    for k, rate in rates.items():
        out[k].capacity_method = ("coulomb count at a high rate" if faster(rate, slowest)
                                  else "coulomb count")


__all__ = ["ReferenceCurve", "partial_capacity", "rate_kinds", "curve_match",
           "comparable_runs", "FULL_START_SHARE", "FULL_START_SPAN_K",
           "matched_capacity", "learned_curve", "is_slow", "settled_drop", "rest_drop",
           "checked_drop", "REST_DROP_MIN", "VOLTAGE_SD_CELL_V", "RELAXED_S", "MIN_SHARE",
           "MATCH_REFERENCES", "SLOW_C_RATE", "SETTLE_S"]


#: A full discharge is laid on a run to empty when their mean currents agree within this
#: share (the rate moves where a discharge ends).
SAME_RATE_SHARE = 0.25


def faster(current_A, than_A) -> bool:
    """Whether a mean current [A] is above another by more than :data:`SAME_RATE_SHARE`
    (False when either is not known)."""
    if current_A is None or than_A is None:
        return False
    return float(current_A) > (1.0 + SAME_RATE_SHARE) * float(than_A)

#: Capacities tried when laying a run to empty on a full discharge, as shares of the
#: charge the run delivered (from a start at full to one at 10 % charge).
_SCALES = 1.0 / np.linspace(1.0, 0.1, 361)


def _tail_fit(q, v, total, ref: dict, ref_cap: float, cells: int) -> tuple[float, float]:
    """The capacity [Ah] at which a run to empty's loaded curve, counted back from its
    end, lies best on a full discharge's (both at one rate, by state of charge), and the
    rms [V per cell] left."""
    rc = ref.get("curve") or {}
    rq = np.asarray(rc.get("charge_Ah") or [], dtype=float)
    rv = np.asarray(rc.get("voltage_V") or [], dtype=float) / cells
    soc_ref = 1.0 - rq / ref_cap
    order = np.argsort(soc_ref)
    soc_ref, rv = soc_ref[order], rv[order]
    caps = total * _SCALES
    soc = (total - q)[None, :] / caps[:, None]            # one row per capacity tried
    ok = soc <= soc_ref[-1]
    counted = ok.sum(axis=1)
    if not (counted >= 5).any():
        return np.nan, np.inf
    off = np.where(ok, v[None, :] - np.interp(soc, soc_ref, rv), 0.0)
    rms = np.where(counted >= 5, np.sqrt((off ** 2).sum(axis=1) / np.maximum(counted, 1)),
                   np.inf)
    best = int(np.argmin(rms))
    return float(caps[best]), float(rms[best])


#: A discharge taken for full that delivered more than this share less than a full
#: discharge later in the pack's life, at its rate and temperature, started part-charged:
#: a capacity does not grow with age, except for what a long rest gives back (lithium
#: returning from the anode's overhang: cell C's cycle 300 delivered 2.3 % more than
#: cycle 290 after a 2.5-day pause; Lewerenz et al. 2017), so twice that.
FULL_START_SHARE = 0.05

#: ... at its temperature: within this [K] (a colder run delivers less).
FULL_START_SPAN_K = 5.0


def comparable_runs(a: dict, b: dict) -> bool:
    """Whether two full discharges ran at one rate (:data:`SAME_RATE_SHARE`) and one
    temperature (:data:`FULL_START_SPAN_K`, when both log one), so that the later one
    delivers no more than the earlier."""
    ia, ib = float(a.get("mean_current_A") or 0.0), float(b.get("mean_current_A") or 0.0)
    if abs(ia - ib) > SAME_RATE_SHARE * max(ia, ib):
        return False
    ta, tb = a.get("temperature_start_C"), b.get("temperature_start_C")
    return ta is None or tb is None or abs(float(ta) - float(tb)) <= FULL_START_SPAN_K


def run_to_empty_capacity(event: dict, refs: list[tuple[dict, float]], cells: int,
                          max_rms_V: float | None = None
                          ) -> tuple[float | None, list | None, str]:
    """Capacity of a discharge run from part charge to its cutoff: its loaded curve,
    counted back from its end (empty at that rate), laid on the full discharges at the
    same rate (:data:`SAME_RATE_SHARE`) by state of charge; the capacity that fits best
    over its curve after :data:`SETTLE_S` (the start's polarisation left out), weighted
    ``1 / rms^2`` over the :data:`MATCH_REFERENCES` that fit best. The 95 % interval: the
    spread between them and the fit of the curve moved by +-2 :data:`VOLTAGE_SD_CELL_V`.
    ``max_rms_V`` (per cell): no capacity unless the best fit leaves at most that (the
    curve lies on a full discharge at its stage of life)."""
    c = event.get("curve") or {}
    q = np.asarray(c.get("charge_Ah") or [], dtype=float)
    v = np.asarray(c.get("voltage_V") or [], dtype=float) / cells
    total = float(event.get("discharged_Ah") or (q[-1] if q.size else 0.0))
    current = float(event.get("mean_current_A") or 0.0)
    same = [(e, cap) for e, cap in refs
            if abs(float(e.get("mean_current_A") or 0.0) - current) <= SAME_RATE_SHARE * current]
    if q.size < 10 or total <= 0 or not same:
        return None, None, "no full discharge at its rate to lay it on"
    keep = q >= current * SETTLE_S / 3600.0
    if keep.sum() < 5:
        return None, None, "too short to lay on a full discharge"
    fits = sorted((_tail_fit(q[keep], v[keep], total, e, cap, cells) + (e, cap)
                   for e, cap in same), key=lambda f: f[1])[:MATCH_REFERENCES]
    fits = [f for f in fits if np.isfinite(f[0])]
    if not fits or (max_rms_V is not None and fits[0][1] > max_rms_V):
        return None, None, "its curve lies on no full discharge"
    w = np.array([1.0 / max(f[1], 1e-4) ** 2 for f in fits])
    caps = np.array([f[0] for f in fits])
    value = float(w @ caps / w.sum())
    moved = [_tail_fit(q[keep], v[keep] + s * 2 * VOLTAGE_SD_CELL_V, total, e, cap, cells)[0]
             for s in (-1.0, 1.0) for _, _, e, cap in fits[:1]]
    low = min(float(caps.min()), *moved)
    high = max(float(caps.max()), *moved)
    return value, [low, high], (f"run to empty, laid on {len(fits)} full discharge(s) at its "
                                "rate")
