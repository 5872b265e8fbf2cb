"""A pack's health per event: capacity, resistance, equivalent full cycles, cells, outliers.

Works on the stored event summaries (plain dicts, see
:mod:`dischargelab.logbook.summarise` and :mod:`dischargelab.logbook.events`), never on
the database.

* **Order** (:func:`order_events`). Events of a file with a clock time are placed at
  their time. A file without one is placed by the order in which it was added: after
  everything the pack held when it came (never before the pack's first event); files
  without a clock time added one after the other keep that order, or the order of the
  cycle numbers in their names when they all carry one, placed among the dated events
  by those numbers when the dated ones carry numbers too. Files sharing one clock time
  are ordered by the cycle number in their names. Within a file, its own order.
* **Full discharge.** A discharge that reaches the steep end of its voltage curve
  (``reaches_knee``) from a rest voltage at or above :data:`FULL_SOC` of the
  chemistry's generic open-circuit voltage (or, for a bench discharge without a rest
  sample, from its start) down to :data:`EMPTY_SOC` or below (its end voltage plus
  the resistive drop). Its capacity is the charge it delivered (coulomb counting);
  the 95 % interval covers where between its last two samples the cutoff was crossed
  (not the current sensor's gain error, which shifts every capacity of the pack alike).
  Not full after all (:func:`demote_part_charged`): the charge before its rest stopped
  short of full, or, no charge logged, it delivered clearly less than a full discharge
  later in the pack's life (a storage charge a generic curve reads at 90 %); it is read
  as a run to empty.
* **Between two rests** (discharges, flights, missions and charges with a rest on
  either side). Capacity = charge counted between the two rest readings / the change
  in state of charge they read through the pack's open-circuit voltage
  (:func:`dischargelab.logbook.estimates.capacity_between_rests`). The curve is the
  pack's own, learned from its slow full discharge nearest in its life
  (:meth:`~dischargelab.logbook.estimates.OcvCurve.from_discharge`, the drop added back
  measured :data:`SETTLE_S` into the load, or at rests a load from full leaves when the
  two disagree), else the chemistry's generic curve (read from a full discharge, else
  from its loads, for a pack of no given chemistry).
  A charge that ends in a constant-voltage taper at the chemistry's charge voltage
  ends full (``FULL_SOC`` of :mod:`.estimates`), as a charger and a fuel gauge define
  it; one that stops lower (a charger set to 4.0 V, a storage charge) is read through
  the curve like any other rest.
* **Partial discharges without a rest after them** (a bench discharge stopped under
  load). The charge drawn divided by the share of the capacity it used, read from the
  pack's full discharges whose voltage curves over the same charge match it best
  (:data:`MATCH_REFERENCES`, weighted by the match): the reference with the same
  stage of life, wherever the event sits in the order. Each end of the event is
  placed on that curve: a rest voltage on its open-circuit voltage, a loaded voltage
  on its loaded voltage, scaled to the event's current and resistance (the pack's
  fitted model when it has one, else its step resistance). The 95 % interval comes
  from :data:`VOLTAGE_SD_CELL_V` at each end through the curve's slope there.
* **Flights without a full discharge or a rest after them**: the end read through the
  open-circuit voltage from the last loaded voltage plus the resistive drop, with the
  drop's size as its uncertainty (``"loaded end"``).
* **Resistance** from the load steps of each event, else from how the voltage follows
  the current (sparse logs), moved to reference conditions
  (:func:`~dischargelab.logbook.estimates.resistance_at_reference`).
* **EFC** = cumulative charge moved / the reference capacity (the label capacity if
  given, else the first full discharge, else the median of the first
  :data:`FIRST_ESTIMATES` capacity estimates). The charge moved is the discharged
  charge (discharges, flights, missions, capacity tests), or the charged charge when
  the pack has only charges logged. Cycles between two logged cycle numbers are
  counted with the mean of their neighbours' charge (an unnumbered event between them
  is one of them, counted as itself).
* **Cells** (:mod:`.cells`): per-cell figures, the weakest cell's share of the
  capacity between two rests, and a drift flag over the pack's events.
* **Outliers.** An over- or undercharged cycle shows as a capacity off the local
  trend (:func:`.outliers.flag_outliers`): residual from a robust line through the
  events on each side, modified z-score ``0.6745 r / MAD`` (Iglewicz & Hoaglin 1993),
  among the estimates made the same way from the same kind of event (charges apart from
  discharges). Outliers are flagged and left out of the trend.

References
----------
.. [1] B. Iglewicz, D. C. Hoaglin, "How to Detect and Handle Outliers", ASQC (1993).
.. [2] G. L. Plett, "Battery Management Systems, Vol. 1", Artech House (2015), ch. 2
   (state of charge from a rested voltage; coulomb counting).
.. [3] Texas Instruments, SLUA364B and SLUA450 (capacity learned from two relaxed
   open-circuit voltages and the charge passed between them).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .chemistry import infer_chemistry
from .estimates import (
    FULL_SOC_SD,
    MIN_SWING,
    OCV_AGEING_SD,
    OcvCurve,
    branch_sd_V,
    capacity_between_rests,
    cells_share,
    charge_start_corrections,
    drop_resistance,
    resistance_at_reference,
    soc_reading,
    systematic_share,
    widen,
)
from .order import later_in_life, order_events, source_of
from .outliers import flag_outliers
from .references import (
    FULL_START_SHARE,
    RELAXED_S,
    SETTLE_S,
    VOLTAGE_SD_CELL_V,
    ReferenceCurve,
    checked_drop,
    comparable_runs,
    curve_match,
    is_slow,
    learned_curve,
    matched_capacity,
    partial_capacity,
    rate_kinds,
    run_to_empty_capacity,
)
from .relaxation import SHORT_REST_METHOD, shorter_than_load

#: Said of a discharge from a rest near full that was not full after all.
NOT_FULL_NOTE = "not full: started part-charged"

#: Said of an estimate whose rest after the load was shorter than the load.
SHORT_REST_NOTE = "the relaxation still to come is carried in the interval"

#: A discharge starts full when its rest voltage reads at least this state of charge.
FULL_SOC = 0.9

#: ... and ends empty when its end voltage plus the resistive drop reads at most this.
EMPTY_SOC = 0.05

#: A rest read sooner than :data:`SETTLE_S` after a load is widened by what the load's
#: polarisation may still hold, fading after this long [s] (:func:`_soon_after`).
SOON_S = 30.0

#: Capacity estimates whose median sets the EFC scale when the pack has neither a label
#: capacity nor a full discharge.
FIRST_ESTIMATES = 5

#: A charge ends full when its highest voltage per cell is within this of the chemistry's
#: charge voltage (:func:`dischargelab.ocv.charge_cell_V`): a charger's regulation and the
#: leads' drop at the taper's end current, not a lower stop voltage.
FULL_VOLTAGE_MARGIN_CELL_V = 0.03

#: Standard deviation of a loaded end voltage read through the open-circuit voltage, as a
#: share of the resistive drop added back: the polarisation a flight builds beyond a
#: one-second step's drop can be as large again. A resistance from how the voltage
#: follows the current over samples seconds apart (``"regression"``) holds most of it:
#: a quarter (DJI Matrice 100, 19-11-28 flight 1: its last loaded voltage plus that drop
#: lay within 0.05 V (8 mV per cell) of the rest 100 s after landing).
LOADED_END_SHARE = 1.0
LOADED_END_SHARE_REGRESSION = 0.25


@dataclass
class EventHealth:
    """Health figures of one event (pack values)."""

    event_id: int
    source: str
    start: str | None
    kind: str
    cycle: int | None
    discharged_Ah: float
    full: bool
    capacity_Ah: float | None = None
    capacity_interval95: list | None = None
    capacity_method: str | None = None
    capacity_note: str | None = None
    resistance_ohm: float | None = None
    resistance_interval95: list | None = None
    resistance_method: str | None = None
    resistance_ref_ohm: float | None = None
    resistance_ref_interval95: list | None = None
    charged_Ah: float | None = None
    soc_start: float | None = None
    soc_end: float | None = None
    cells: dict | None = None
    efc: float | None = None
    outlier: bool = False
    notes: list[str] = field(default_factory=list)
    capacity_systematic: float | None = None
    capacity_own_interval95: list | None = None

    @property
    def own_interval95(self) -> list | None:
        """The capacity's 95 % interval without what the pack's estimates share alike
        (real cells' spread about a generic curve: :func:`.estimates.cells_share`), for
        comparing one estimate with another; else :attr:`capacity_interval95`."""
        return self.capacity_own_interval95 or self.capacity_interval95

    @property
    def health_kind(self) -> str:
        """``"full"`` (a full discharge), ``"partial"`` (another discharge), ``"flight"``,
        or the event's own kind (``"charge"``, ``"rest"``, ``"gap"``)."""
        if self.kind == "flight":
            return "flight"
        if self.kind == "discharge":
            return "full" if self.full else "partial"
        return self.kind

    def to_dict(self) -> dict:
        """The keys of ``logbook health --json`` (``kind``: :attr:`health_kind`;
        ``event_kind``: the stored event's)."""
        return {"source": self.source, "start": self.start, "kind": self.health_kind,
                "discharged_Ah": self.discharged_Ah, "capacity_Ah": self.capacity_Ah,
                "capacity_interval95": self.capacity_interval95,
                "resistance_ohm": self.resistance_ohm, "efc": self.efc,
                "outlier": self.outlier, "event_id": self.event_id,
                "event_kind": self.kind, "cycle": self.cycle, "full": self.full,
                "capacity_method": self.capacity_method,
                "capacity_note": self.capacity_note,
                "resistance_interval95": self.resistance_interval95,
                "resistance_method": self.resistance_method,
                "resistance_ref_ohm": self.resistance_ref_ohm,
                "resistance_ref_interval95": self.resistance_ref_interval95,
                "charged_Ah": self.charged_Ah, "soc_start": self.soc_start,
                "soc_end": self.soc_end, "cells": self.cells, "notes": list(self.notes),
                "capacity_systematic": self.capacity_systematic,
                "capacity_own_interval95": self.capacity_own_interval95}

    @classmethod
    def from_dict(cls, data: dict) -> EventHealth:
        """The event :meth:`to_dict` describes."""
        return cls(event_id=data["event_id"], source=data["source"], start=data["start"],
                   kind=data["event_kind"], cycle=data["cycle"],
                   discharged_Ah=data["discharged_Ah"], full=data["full"],
                   capacity_Ah=data["capacity_Ah"],
                   capacity_interval95=data["capacity_interval95"],
                   capacity_method=data["capacity_method"],
                   capacity_note=data.get("capacity_note"),
                   resistance_ohm=data["resistance_ohm"],
                   resistance_interval95=data["resistance_interval95"],
                   resistance_method=data.get("resistance_method"),
                   resistance_ref_ohm=data.get("resistance_ref_ohm"),
                   resistance_ref_interval95=data.get("resistance_ref_interval95"),
                   charged_Ah=data.get("charged_Ah"), soc_start=data.get("soc_start"),
                   soc_end=data.get("soc_end"), cells=data.get("cells"), efc=data["efc"],
                   outlier=data["outlier"], notes=list(data["notes"]),
                   capacity_systematic=data.get("capacity_systematic"),
                   capacity_own_interval95=data.get("capacity_own_interval95"))


# --------------------------------------------------------------------------- classification

def pack_cells(event: dict, cells: int | None, chemistry: str | None) -> int:
    """Cells in series: the pack's, the log's, else inferred from the highest voltage."""
    from ..flight import infer_cells

    if cells:
        return int(cells)
    if event.get("cells"):
        return int(event["cells"])
    curve = (event.get("curve") or {}).get("voltage_V") or [0]
    top = [x for x in (event.get("rest_voltage_V"), max(curve), event.get("end_voltage_V"))
           if x]
    return infer_cells(np.array(top or [1.0]), chemistry)


def _cell_counts(ordered: list[dict], cells: int | None, chemistry: str | None) -> list[int]:
    """:func:`pack_cells` of every event; inferred once per source from all its events."""
    if cells:
        return [int(cells)] * len(ordered)
    by_source: dict = {}
    for e in ordered:
        if not e.get("cells"):
            by_source.setdefault(source_of(e), []).append(e)
    inferred = {}
    for sid, evs in by_source.items():
        top = max((max((e.get("curve") or {}).get("voltage_V") or [0.0]),
                   e.get("rest_voltage_V") or 0.0, e.get("end_voltage_V") or 0.0) for e in evs)
        inferred[sid] = pack_cells({"rest_voltage_V": top}, None, chemistry)
    return [int(e["cells"]) if e.get("cells") else inferred[source_of(e)] for e in ordered]


def starts_full(event: dict, cells: int, chemistry: str | None) -> bool:
    """Whether the event starts from a full charge (see the module docstring)."""
    from ..ocv import soc_from_rest_voltage

    rest = event.get("rest_voltage_V")
    if rest is None:
        return event.get("kind") == "discharge"
    return bool(soc_from_rest_voltage(rest / cells, chemistry) >= FULL_SOC)


def ends_empty(event: dict, cells: int, chemistry: str | None) -> bool:
    """Whether a discharge ends empty: its end voltage plus the resistive drop reads at most
    :data:`EMPTY_SOC` (a mission whose landing makes its voltage fall fast does not)."""
    from ..ocv import soc_from_rest_voltage

    end = event.get("end_voltage_V")
    if end is None:
        return False
    drop = float(event.get("resistance_ohm") or 0.0) * float(event.get("end_current_A") or 0.0)
    return bool(soc_from_rest_voltage((end + drop) / cells, chemistry) <= EMPTY_SOC)


def is_full(event: dict, cells: int, chemistry: str | None) -> bool:
    """A full discharge (see the module docstring)."""
    return (event.get("kind") in ("discharge", "flight") and bool(event.get("reaches_knee"))
            and starts_full(event, cells, chemistry) and ends_empty(event, cells, chemistry))


def full_capacity(event: dict) -> tuple[float, list]:
    """Coulomb-counted capacity [Ah] of a full discharge and its 95 % interval."""
    q = float(event["discharged_Ah"])
    samples = max(int(event.get("samples") or 2), 2)
    step_Ah = float(event["end_current_A"]) * float(event["duration_s"]) / (samples - 1) / 3600
    half = 1.96 * abs(step_Ah) / np.sqrt(12.0)
    return q, [q - half, q + half]


# --------------------------------------------------------------------------- EFC, outliers

def moved_charge(event: dict, charges: bool) -> float:
    """Charge an event moved [Ah]: discharged (discharges, flights), or charged when the
    pack's charges are counted instead (``charges``)."""
    if charges:
        return float(((event.get("details") or {}).get("charge") or {}).get("charged_Ah")
                     or 0.0) if event.get("kind") == "charge" else 0.0
    if event.get("kind") in ("discharge", "flight"):
        return float(event.get("discharged_Ah") or 0.0)
    return 0.0


def equivalent_full_cycles(ordered: list[dict], reference_Ah: float) -> np.ndarray:
    """Cumulative charge moved / reference capacity after each event [-].

    The discharged charge counts (discharges and flights); when the pack has no discharge
    logged, the charged charge does.
    """
    charges = not any(e.get("kind", "discharge") in ("discharge", "flight") for e in ordered)
    total, out, prev, between = 0.0, [], None, 0
    for e in ordered:
        q = moved_charge(dict(e, kind=e.get("kind", "discharge")), charges)
        cycle = e.get("cycle")
        if cycle is not None:
            if prev is None and cycle > 1:
                total += max(cycle - 1 - between, 0) * q
            elif prev is not None and cycle > prev[0] + 1:
                # an unnumbered event between two numbered ones (a storage run, a flight)
                # is one of the cycles between them, counted as itself
                total += max(cycle - prev[0] - 1 - between, 0) * 0.5 * (q + prev[1])
            prev, between = (cycle, q), 0
        elif q > 0:
            between += 1
        total += q
        out.append(total / reference_Ah)
    return np.array(out, dtype=float)


# --------------------------------------------------------------------------- per event

@dataclass
class PackContext:
    """What every event of one pack is read against."""

    cells: int | None
    chemistry: str | None
    model: object | None
    fulls: list[tuple[int, dict, float]]          # (position, event, capacity)
    curves: list[tuple[int, OcvCurve]]            # (position, learned curve)
    prior: OcvCurve
    full_cell_V: float
    label_Ah: float | None = None
    start_added_Ah: dict = field(default_factory=dict)   # position -> charge [Ah]

    def curve_at(self, position: int) -> OcvCurve:
        """The learned curve nearest in the pack's life (before preferred), else the prior."""
        if not self.curves:
            return self.prior
        before = [c for p, c in self.curves if p <= position]
        return before[-1] if before else self.curves[0][1]


def _set_capacity(h: EventHealth, cap: float, own95: list, curve: OcvCurve,
                  soc_read: list[float], swing: float) -> None:
    """A capacity read through ``curve``: its interval widened by real cells' spread about
    a generic curve (:func:`.estimates.cells_share`), the one without it kept for comparing
    estimates (:attr:`EventHealth.own_interval95`)."""
    share = cells_share(curve, soc_read, swing)
    h.capacity_Ah, h.capacity_interval95 = cap, widen(cap, own95, share) if share else own95
    h.capacity_own_interval95 = own95 if share else None


def _rest_capacity(e: dict, h: EventHealth, ctx: PackContext, n_cells: int, position: int
                   ) -> str | None:
    """Capacity between the rests around a load (sets ``h``); returns why not, or None."""
    details = e.get("details") or {}
    before, after = details.get("rest_before"), details.get("rest_after")
    ends_full = _full_after(details.get("charge"), n_cells, ctx.full_cell_V)
    if before is None:
        return "no rest before it"
    if after is None and not ends_full:
        return "no rest after it"
    curve = ctx.curve_at(position)
    r = e.get("resistance_ohm")
    begins_full = _full_after(before.get("after_charge"), n_cells, ctx.full_cell_V)
    if begins_full:
        soc_a, sd_a = 1.0, FULL_SOC_SD
    else:
        soc_a, sd_a = soc_reading(curve, before, n_cells, resistance_ohm=r, cells_alike=False)
    read_after = None
    if ends_full:
        soc_b, sd_b = 1.0, FULL_SOC_SD
    else:
        read_after = _soon_after(after, e)
        soc_b, sd_b = soc_reading(curve, read_after, n_cells, resistance_ohm=r,
                                  cells_alike=False)
        if read_after.get("method") == SHORT_REST_METHOD:
            h.notes.append(f"the log ends {read_after['since_load_s']:.0f} s after a "
                           f"{float(e['duration_s']) / 60:.0f}-minute load: {SHORT_REST_NOTE}"
                           " (a log that runs on after landing for as long as the flight "
                           "measures it)")
    h.soc_start, h.soc_end = soc_a, soc_b
    q = float(details.get("counted_Ah") or 0.0)
    q_sd = float(details.get("counted_sd_Ah") or 0.0)
    added = ctx.start_added_Ah.get(position)
    if added is not None:
        q -= added       # a charge's counted charge is negative (into the pack)
    cap, interval, how = capacity_between_rests(q, q_sd, soc_a, sd_a, soc_b, sd_b)
    if cap is None:
        return how
    sampling = details.get("sampling") or {}
    fade = _fade_since(curve, cap, ctx)
    read = [(s, r) for s, r in ((soc_a, None if begins_full else before), (soc_b, read_after))
            if r is not None]
    # the curve's ageing after the last full discharge is the trend's (over_life.DRIFT_SHARE)
    h.capacity_systematic = systematic_share(curve, [s for s, _ in read], soc_a - soc_b, None,
                                             [branch_sd_V(r) for _, r in read])
    if fade:
        interval = widen(cap, interval, OCV_AGEING_SD * fade)
    _set_capacity(h, cap, interval, curve, [s for s, _ in read], soc_a - soc_b)
    h.capacity_method = "rests before and after" + (" (charge ends full)" if ends_full else "")
    if not sampling.get("resolved", True):
        h.notes.append(f"the samples ({sampling.get('period_s') or 0:.0f} s apart) do not "
                       f"follow the current: its charge is counted to +-{100 * q_sd / abs(q):.0f}"
                       " % (1 sd), and the interval widened")
    if added is not None:
        h.notes.append(f"its start placed between two samples by the first one's voltage "
                       f"({added:+.3f} Ah to the trapezoids)")
    h.notes.append(f"state of charge through {curve.source}")
    return None


def _fade_since(curve: OcvCurve, capacity_Ah: float, ctx: PackContext) -> float | None:
    """Capacity lost since ``curve`` was learned, as a share of the capacity its state of
    charge is scaled to (a generic curve: the label capacity), or None."""
    scale = curve.capacity_Ah or ctx.label_Ah
    return None if not scale else max(0.0, 1.0 - abs(capacity_Ah) / scale)


def _full_after(charge: dict | None, n_cells: int, full_cell_V: float) -> bool:
    """A charge (its figures) that ends full: in a taper at the pack's full voltage."""
    if not charge or not charge.get("taper") or charge.get("max_voltage_V") is None:
        return False
    return charge["max_voltage_V"] / n_cells >= full_cell_V - FULL_VOLTAGE_MARGIN_CELL_V


def _soon_after(reading: dict, e: dict) -> dict:
    """A rest reading taken soon after a load: a fitted one shorter than the load carries
    what its relaxation may still hold (:func:`~.relaxation.shorter_than_load`); one too
    short to fit has its interval widened by the polarisation the load may still hold:
    :data:`LOADED_END_SHARE` of the resistive drop at the load's mean current, fading as
    ``sqrt(SOON_S / t)`` after :data:`SOON_S`."""
    since = reading.get("since_load_s")
    r = e.get("resistance_ohm")
    if reading.get("method") == "fit":
        direction = -1 if e.get("kind") == "charge" else 1   # discharges and flights: +1
        return shorter_than_load(reading, float(e.get("duration_s") or 0.0),
                                 e.get("end_voltage_V"), direction)
    if since is None or r is None:
        return reading
    load = abs(float(e.get("mean_current_A") or 0.0))
    extra = 1.96 * LOADED_END_SHARE * float(r) * load * np.sqrt(SOON_S / max(since, SOON_S))
    if since >= SETTLE_S:
        return reading
    return dict(reading, half95_V=float(np.hypot(reading.get("half95_V") or 0.0, extra)))


def _loaded_end_capacity(e: dict, h: EventHealth, ctx: PackContext, n_cells: int,
                         position: int) -> str | None:
    """Capacity of a load from its rest before to its loaded end (no rest after, no full
    discharge of the pack to compare with)."""
    details = e.get("details") or {}
    before = details.get("rest_before")
    if before is None:
        return "no rest before it (the log starts under load)"
    r = e.get("resistance_ohm")
    if r is None:
        return "no rest after it and no resistance to read its loaded end"
    curve = ctx.curve_at(position)
    soc_a, sd_a = soc_reading(curve, before, n_cells, resistance_ohm=r, cells_alike=False)
    drop = float(r) * float(e.get("end_current_A") or 0.0)
    # the polarisation left at the end follows the flight's load, not its last sample
    load = max(abs(float(e.get("end_current_A") or 0.0)), abs(float(e.get("mean_current_A")
                                                                      or 0.0)))
    share = LOADED_END_SHARE_REGRESSION if details.get("resistance_method") == "regression" \
        else LOADED_END_SHARE
    end = {"relaxed_V": float(e["end_voltage_V"]) + drop,
           "half95_V": 1.96 * share * float(r) * load, "current_A": 0.0,
           "temperature_C": e.get("temperature_max_C")}
    soc_b, sd_b = soc_reading(curve, end, n_cells, cells_alike=False)
    h.soc_start, h.soc_end = soc_a, soc_b
    q = float(details.get("counted_Ah") or e.get("discharged_Ah") or 0.0)
    cap, interval, how = capacity_between_rests(q, float(details.get("counted_sd_Ah") or 0.0),
                                                soc_a, sd_a, soc_b, sd_b)
    if cap is None:
        return how + " (read from its loaded end: no rest after it)"
    h.capacity_systematic = systematic_share(curve, [soc_a, soc_b], soc_a - soc_b, None,
                                             [branch_sd_V(before), 0.0])
    _set_capacity(h, cap, interval, curve, [soc_a, soc_b], soc_a - soc_b)
    h.capacity_method = "rest before, loaded end"
    h.notes.append(f"no rest after it: its end is the last loaded voltage plus the resistive "
                   f"drop ({drop:.2f} V), read through {curve.source}")
    return None


#: Standard deviation of the state of charge a discharge run to its cutoff ends at, on
#: the scale of the pack's curve (a full discharge at another rate or temperature ends a
#: little above or below its empty).
EMPTY_SOC_SD = 0.02


def _empty_end_capacity(e: dict, h: EventHealth, ctx: PackContext, n_cells: int,
                        position: int) -> str | None:
    """Capacity of a load from a rest to its cutoff (a discharge from a storage or part
    charge run to empty): laid on the pack's full discharges at its rate when it has
    some (:func:`~.references.run_to_empty_capacity`), else its start read through the
    curve and its end empty."""
    details = e.get("details") or {}
    before = details.get("rest_before")
    if before is None and e.get("rest_voltage_V") is not None:   # a bench file's rest sample
        before = {"relaxed_V": float(e["rest_voltage_V"]), "current_A": 0.0,
                  "temperature_C": e.get("temperature_start_C")}
    if before is None or not e.get("reaches_knee") or h.full or \
            not ends_empty(e, n_cells, ctx.chemistry):
        return "not run to empty from a rest"
    cap, interval, how = run_to_empty_capacity(e, [(f, c) for _, f, c in ctx.fulls], n_cells)
    if cap is not None:
        h.capacity_Ah, h.capacity_interval95, h.capacity_method = cap, interval, how
        h.soc_start, h.soc_end = float(e.get("discharged_Ah") or 0.0) / cap, 0.0
        return None
    curve = ctx.curve_at(position)
    soc_a, sd_a = soc_reading(curve, before, n_cells, resistance_ohm=e.get("resistance_ohm"),
                              cells_alike=False)
    q = float(details.get("counted_Ah") or e.get("discharged_Ah") or 0.0)
    cap, interval, how = capacity_between_rests(q, float(details.get("counted_sd_Ah") or 0.0),
                                                soc_a, sd_a, 0.0, EMPTY_SOC_SD)
    if cap is None:
        return how
    h.soc_start, h.soc_end = soc_a, 0.0
    h.capacity_systematic = systematic_share(curve, [soc_a], soc_a, None, [branch_sd_V(before)])
    _set_capacity(h, cap, interval, curve, [soc_a], soc_a)
    h.capacity_method = "rest before, run to empty"
    h.notes.append(f"from a rest at {soc_a:.0%} to the cutoff, read through {curve.source}")
    return None


def _capacity(e: dict, h: EventHealth, ctx: PackContext, n_cells: int, position: int) -> None:
    """The event's capacity by the first method that applies (module docstring)."""
    if h.kind not in ("discharge", "flight", "charge"):
        return
    why = _rest_capacity(e, h, ctx, n_cells, position)
    if why is None:
        return
    if h.kind != "charge" and _empty_end_capacity(e, h, ctx, n_cells, position) is None:
        return
    if h.kind != "charge" and ctx.fulls and \
            not ((e.get("details") or {}).get("rest_after") and
                 (e.get("rest_after_s") or 0) >= RELAXED_S):
        cap, interval, how = matched_capacity(e, [(f, c) for _, f, c in ctx.fulls], n_cells,
                                              ctx.model)
        if cap is not None:
            h.capacity_Ah, h.capacity_interval95, h.capacity_method = cap, interval, how
            return
        why = how
    elif h.kind != "charge" and not ctx.fulls and "no rest after" in why:
        why = _loaded_end_capacity(e, h, ctx, n_cells, position) or why
        if h.capacity_Ah is not None:
            return
    h.capacity_note = why


def _resistance(e: dict, h: EventHealth, ctx: PackContext) -> None:
    temp = e.get("temperature_start_C")
    if temp is None:
        temp = e.get("ambient_C")
    r, interval, how = resistance_at_reference(
        h.resistance_ohm, h.resistance_interval95, temp, soc=h.soc_start, model=ctx.model,
        current_A=e.get("mean_current_A"))
    h.resistance_ref_ohm, h.resistance_ref_interval95 = r, interval
    if r is not None:
        h.notes.append(f"resistance from {h.resistance_method}; at reference conditions {how}")


#: How a resistance from :func:`drop_resistance` is named.
DROP_METHOD = "open-circuit drop"


def _drop_resistance(e: dict, h: EventHealth, ctx: PackContext, n_cells: int,
                     position: int) -> None:
    """The resistance of an event whose samples gave none, from its loaded voltage's
    distance to the open-circuit curve between its two rest readings (sets ``h``)."""
    if h.soc_start is None or h.soc_end is None or h.full or not e.get("curve"):
        return
    direction = -1 if h.kind == "charge" else 1
    r, interval = drop_resistance(e["curve"], h.soc_start, h.soc_end,
                                  ctx.curve_at(position), n_cells, direction)
    if r is not None:
        h.resistance_ohm, h.resistance_interval95 = r, interval
        h.resistance_method = DROP_METHOD


def _cells(e: dict, h: EventHealth, ctx: PackContext, position: int) -> None:
    from .cells import weakest_share

    figures = (e.get("details") or {}).get("cells")
    if not figures:
        return
    out = dict(figures)
    details = e.get("details") or {}
    share, weakest = weakest_share(ctx.curve_at(position), figures,
                                   float(details.get("counted_Ah") or 0.0),
                                   float(details.get("counted_sd_Ah") or 0.0))
    out.update(weakest_share=share, weakest=weakest, drift=False)
    h.cells = out


def _context(ordered: list[dict], health: list[EventHealth], cells, chemistry, model,
             label_Ah: float | None = None, read_from_loads: tuple | None = None
             ) -> PackContext:
    fulls = [(k, e, health[k].capacity_Ah) for k, e in enumerate(ordered) if health[k].full]
    if chemistry is None and fulls:
        e = fulls[0][1]
        n = pack_cells(e, cells, chemistry)
        top = e.get("rest_voltage_V") or e["curve"]["voltage_V"][0]
        chemistry = infer_chemistry(top / n, float(e["end_voltage_V"]) / n)
    from ..ocv import charge_cell_V, is_lihv

    top = highest_rest_cell_V(ordered, cells, chemistry)
    read = ""
    if chemistry is None and not is_lihv(None, top):
        chemistry, read = read_from_loads or _chemistry_from_loads(ordered, cells)
    # a 4.2 V pack of no known chemistry reads through both generic curves' mean, their
    # difference carried in the interval (a LiPo curve read on an NMC cell: -27 %)
    prior = OcvCurve.unknown() if chemistry is None and not is_lihv(None, top) else \
        OcvCurve.prior(chemistry, top)
    if read:
        prior.source = f"{prior.source} (chemistry {read})"
    # full is the chemistry's charge voltage: a constant-voltage end lower (a charger set
    # to 4.0 or 4.1 V, a storage charge) leaves the pack part-charged, whatever the pack's
    # first full discharge started from
    full_cell = charge_cell_V(chemistry, top)
    curves = []
    first_drop = None
    for k, e, cap in fulls:
        if not is_slow(e, cap):
            continue
        n = pack_cells(e, cells, chemistry)
        if first_drop is None:
            first_drop = checked_drop(ordered, k, e, n,
                                      lambda c, n=n: _full_after(c, n, full_cell))
        curves.append((k, learned_curve(dict(e, source=e.get("source")), cap, n, chemistry,
                                        resistance_ohm=first_drop)))
    return PackContext(cells=cells, chemistry=chemistry, model=model, fulls=fulls,
                       curves=curves, prior=prior, full_cell_V=full_cell, label_Ah=label_Ah)


def demote_part_charged(ordered: list[dict], out: list[EventHealth], counts: list[int],
                        ctx: PackContext) -> int:
    """Take back "full" from the discharges that started part-charged (a rest at 90 % or
    more of a generic curve is only a candidate; a 30Q cell's storage charge at 4.08 V
    reads 91 %, and a cell 300 cycles older rests there full): the charge before the rest
    ended short of full (no taper at the full voltage), or, no charge logged, it delivered
    more than :data:`~.references.FULL_START_SHARE` less than the next full discharge in
    the pack's life at its rate and temperature (a capacity does not grow with age), by
    their clock times, else their cycle numbers (:func:`.order.later_in_life`); or, wherever
    it sits in the life (an undated, unnumbered file is placed only by when it was added),
    it lies on the others by its curve counted back from its end
    (:func:`~.references.run_to_empty_capacity`): the low end of that capacity's 95 %
    interval more than ``FULL_START_SHARE`` above what it delivered (cell C's full
    discharges: at most 1.8 % above; its runs from 10 % down: 5.8 % or more), its curve
    lying on one of them within :data:`~.references.VOLTAGE_SD_CELL_V` rms (a full discharge
    300 cycles older than every other lies 25 mV off them, its resistance taken for a later
    start; a run laid on one of its age: 1.5-2.6 mV). They are read again as runs to
    empty. Returns how many were taken back."""
    taken = 0
    fulls = [k for k, h in enumerate(out) if h.full]
    for k in reversed(fulls):
        e, h = ordered[k], out[k]
        after = ((e.get("details") or {}).get("rest_before") or {}).get("after_charge")
        if after is not None:
            if not _full_after(after, counts[k], ctx.full_cell_V):
                _not_full(h, "the charge before it stopped short of full")
                taken += 1
            continue
        comparable = [j for j in fulls if j != k and out[j].full
                      and comparable_runs(e, ordered[j])]
        gaps = [(gap, j) for j in comparable
                if (gap := later_in_life(e, ordered[j])) is not None]
        why = None
        if gaps:
            later = min(gaps)[1]
            mine, theirs = float(h.capacity_Ah or 0.0), float(out[later].capacity_Ah or 0.0)
            if mine < (1.0 - FULL_START_SHARE) * theirs:
                why = (f"it delivered {1.0 - mine / theirs:.0%} less than {out[later].source}, "
                       "a full discharge later in the pack's life (a capacity does not grow "
                       "with age)")
        why = why or _short_by_its_tail(e, h, [(ordered[j], float(out[j].capacity_Ah))
                                               for j in comparable], counts[k])
        if why:
            _not_full(h, why)
            taken += 1
    return taken


def _short_by_its_tail(e: dict, h: EventHealth, refs: list[tuple[dict, float]], cells: int
                       ) -> str | None:
    """Why a discharge taken for full started part-charged, by its curve laid on the
    pack's other full discharges from its end (:func:`demote_part_charged`), or None."""
    if not refs:
        return None
    cap, interval, _ = run_to_empty_capacity(e, refs, cells, max_rms_V=VOLTAGE_SD_CELL_V)
    mine = float(h.capacity_Ah or 0.0)
    if cap is None or mine <= 0 or interval[0] <= (1.0 + FULL_START_SHARE) * mine:
        return None
    return (f"its curve, counted back from its end, lies on the pack's full discharges as "
            f"{1.0 - mine / cap:.0%} of the charge down at its start")


def _not_full(h: EventHealth, why: str) -> None:
    h.full = False
    h.capacity_Ah = h.capacity_interval95 = h.capacity_method = None
    h.soc_start = h.soc_end = None
    h.notes.append(f"{NOT_FULL_NOTE}: {why}")


def highest_rest_cell_V(ordered: list[dict], cells: int | None, chemistry: str | None
                        ) -> float | None:
    """The highest rest voltage per cell the pack's events show [V] (the rest before each
    load, read at its end), or None: what says a LiPo pack is a high-voltage one."""
    counts = _cell_counts(ordered, cells, chemistry)
    tops = [float(e["rest_voltage_V"]) / n for e, n in zip(ordered, counts)
            if e.get("rest_voltage_V") and e.get("kind") in ("discharge", "flight")]
    return max(tops) if tops else None


def _classify(ordered: list[dict], counts: list[int], chemistry: str | None
              ) -> list[EventHealth]:
    """Each event's figures as logged, its full discharges measured (module docstring)."""
    out: list[EventHealth] = []
    for k, e in enumerate(ordered):
        kind = e.get("kind", "discharge")
        n_cells = counts[k]
        full = is_full(dict(e, kind=kind), n_cells, chemistry)
        charge = (e.get("details") or {}).get("charge") or {}
        h = EventHealth(event_id=e.get("id") or k, source=e.get("source", ""),
                        start=e.get("start_time"), kind=kind, cycle=e.get("cycle"),
                        discharged_Ah=float(e.get("discharged_Ah") or 0.0), full=full,
                        resistance_ohm=e.get("resistance_ohm"),
                        charged_Ah=charge.get("charged_Ah"))
        if h.resistance_ohm is not None:
            h.resistance_method = (e.get("details") or {}).get("resistance_method") \
                or "load steps"
        if e.get("resistance_low_ohm") is not None:
            h.resistance_interval95 = [e["resistance_low_ohm"], e["resistance_high_ohm"]]
        if full:
            h.capacity_Ah, h.capacity_interval95 = full_capacity(e)
            # a full discharge at a high rate (a mission run to its cutoff) delivers less
            # than a slow one: a kind of estimate of its own
            h.capacity_method = "coulomb count"
            h.soc_start, h.soc_end = 1.0, 0.0
        out.append(h)
    return out


def _chemistry_from_loads(ordered: list[dict], cells: int | None) -> tuple[str | None, str]:
    """The chemistry the pack's loads from a rest read (:mod:`.chemistry`), with why."""
    from .chemistry import chemistry_from_loads

    return chemistry_from_loads([(e, pack_cells(e, cells, None)) for e in ordered
                                 if e.get("kind") in ("discharge", "flight")])


def pack_health(events: list[dict], *, label_capacity_Ah: float | None = None,
                cells: int | None = None, chemistry: str | None = None, model=None
                ) -> tuple[list[EventHealth], float | None, str]:
    """Health of every event of one pack.

    Parameters
    ----------
    events : list of dict
        Stored events (with ``id``, ``source`` and the summary keys).
    label_capacity_Ah, cells, chemistry
        The pack's label capacity [Ah], cells in series and chemistry, when known.
    model : Battery, optional
        The pack's fitted model (voltage drop at a current for partial events, the
        resistance's state of charge).

    Returns
    -------
    (list of EventHealth in order, reference capacity [Ah] or None, how it was chosen)
    """
    from .cells import drift_flags

    ordered = order_events(events)
    counted_as = chemistry       # the chemistry the cells of each event are counted for
    counts = _cell_counts(ordered, cells, counted_as)
    out = _classify(ordered, counts, chemistry)
    read = None
    if chemistry is None and not any(h.full for h in out):
        # no full discharge on a 4.2 V curve: the loads read the chemistry (a LiFePO4
        # pack's full rest is empty there), and a LiFePO4 pack's events are classified again
        read = _chemistry_from_loads(ordered, cells)
        if read[0] == "lifepo4":
            counted_as = read[0]
            counts = _cell_counts(ordered, cells, counted_as)
            out = _classify(ordered, counts, read[0])
    rate_kinds(ordered, out)
    ctx = _context(ordered, out, cells, chemistry, model, label_capacity_Ah, read)
    if ctx.chemistry != counted_as:
        counts, counted_as = _cell_counts(ordered, cells, ctx.chemistry), ctx.chemistry
    if demote_part_charged(ordered, out, counts, ctx):
        rate_kinds(ordered, out)
        ctx = _context(ordered, out, cells, chemistry, model, label_capacity_Ah, read)
        # a full discharge taken back may have been what read the chemistry
        if ctx.chemistry != counted_as:
            counts = _cell_counts(ordered, cells, ctx.chemistry)
    charges = [k for k, e in enumerate(ordered) if e.get("kind") == "charge"]
    added = charge_start_corrections([((ordered[k].get("details") or {}).get("charge") or {})
                                      .get("start") for k in charges])
    ctx.start_added_Ah = {k: a for k, a in zip(charges, added) if a is not None}
    for k, (e, h) in enumerate(zip(ordered, out)):
        n_cells = counts[k]
        if not h.full:
            _capacity(e, h, ctx, n_cells, k)
        if h.resistance_ohm is None:
            _drop_resistance(e, h, ctx, n_cells, k)
        if h.resistance_ohm is not None:
            _resistance(e, h, ctx)
        _cells(e, h, ctx, k)
    with_cells = [h for h in out if h.cells is not None]
    for h, drift in zip(with_cells, drift_flags([h.cells.get("off") for h in with_cells],
                                                [h.cells.get("rest_spread_V")
                                                 for h in with_cells])):
        h.cells["drift"] = drift
    estimates = [h.capacity_Ah for h in out if h.capacity_Ah is not None]
    if label_capacity_Ah:
        reference, why = float(label_capacity_Ah), "label capacity"
    elif ctx.fulls:
        reference, why = ctx.fulls[0][2], "first full discharge"
    elif estimates:
        reference = float(np.median(estimates[:FIRST_ESTIMATES]))
        why = f"median of the first {min(len(estimates), FIRST_ESTIMATES)} capacity estimates"
    else:
        reference, why = None, "no label capacity, full discharge or capacity estimate"
    if reference:
        for h, efc in zip(out, equivalent_full_cycles(ordered, reference)):
            h.efc = float(efc)
    # an estimate is compared with the others made the same way from the same kind of
    # event: a local median over neighbours of unlike precision (a charge counted to 2 %,
    # a mission seen by a few samples to 30 %) is not a trend the precise one sits off
    groups: dict = {}
    for k, h in enumerate(out):
        if h.capacity_Ah is not None:
            groups.setdefault(((h.capacity_method or "").split(" (")[0].split(",")[0],
                               h.kind == "charge"), []).append(k)
    for with_cap in groups.values():
        axis = [out[k].efc if out[k].efc is not None else k for k in with_cap]
        flags = flag_outliers(axis, [out[k].capacity_Ah for k in with_cap],
                              half95=[0.5 * (out[k].own_interval95[1]
                                             - out[k].own_interval95[0])
                                      for k in with_cap])
        for k, flag in zip(with_cap, flags):
            out[k].outlier = bool(flag)
    return out, reference, why


__all__ = ["EventHealth", "pack_health", "infer_chemistry",
           "order_events", "equivalent_full_cycles",
           "partial_capacity", "matched_capacity", "curve_match", "learned_curve", "full_capacity",
           "ReferenceCurve", "starts_full", "ends_empty", "is_full", "FULL_SOC", "EMPTY_SOC",
           "NOT_FULL_NOTE", "demote_part_charged",
           "VOLTAGE_SD_CELL_V", "MIN_SWING"]
