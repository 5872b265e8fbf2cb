"""A pack's health per event: capacity, resistance, equivalent full cycles, outliers.

Works on the stored event summaries (plain dicts, see
:mod:`dischargelab.logbook.summarise`), never on the database.

* **Order.** Events are ordered by start time (when the file records a clock time),
  then cycle number, then the order they were added.
* **Full discharge.** A discharge that reaches the steep end of its voltage curve
  (``reaches_knee``) from a rest voltage at or above :data:`FULL_SOC` of the
  chemistry's generic open-circuit voltage (or, for a bench discharge without a
  rest sample, from its start). Its capacity is the charge it delivered
  (coulomb counting); the 95 % interval covers where between its last two samples
  the cutoff was crossed (not the current sensor's gain error, which shifts every
  capacity of the pack alike).
* **Partial discharges and flights.** The charge drawn divided by the share of the
  capacity it used, read from the pack's own voltage curve: the nearest full
  discharge logged before it (else after it), scaled to the event's current and
  resistance. Each end of the event is placed on that curve: a rest voltage on its
  open-circuit voltage, a loaded voltage on its loaded voltage. The open-circuit
  voltage is the reference curve plus the model's voltage drop at its current
  (the pack's fitted model when it has one, else its measured step resistance
  times the current). The 95 % interval comes from :data:`VOLTAGE_SD_CELL_V` at each
  end through the curve's slope there.
* **Resistance** from the load steps of each event (``step_resistance``).
* **EFC** = cumulative discharged charge / the reference capacity (the label
  capacity if given, else the first full discharge). Cycles between two logged
  cycle numbers are counted with the mean of their neighbours' charge.
* **Outliers.** An over- or undercharged cycle shows as a capacity off the local
  trend: residual from a robust line through the :data:`OUTLIER_NEIGHBOURS` events on
  each side, modified z-score ``0.6745 r / MAD`` above :data:`OUTLIER_Z` (Iglewicz &
  Hoaglin 1993). Outliers are flagged and left out of the trend.

References
----------
.. [1] B. Iglewicz, D. C. Hoaglin, "How to Detect and Handle Outliers", ASQC (1993).
.. [2] G. L. Plett, "Battery Management Systems, Vol. 1", Artech House (2015), ch. 2
   (state of charge from a rested voltage; coulomb counting).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: A discharge starts full when its rest voltage reads at least this state of charge.
FULL_SOC = 0.9

#: Standard deviation of a voltage placed on the reference curve, per cell [V]:
#: relaxation left after a rest, temperature and ageing since the reference.
VOLTAGE_SD_CELL_V = 0.010

#: A rest after the load counts as relaxed after this long [s]; sooner the loaded curve
#: is used at the last loaded sample.
RELAXED_S = 60.0

#: Partial events using less than this share of the capacity get no capacity.
MIN_SHARE = 0.2

#: Neighbours on each side for the outlier test's local median.
OUTLIER_NEIGHBOURS = 3

#: Modified z-score above which a capacity is an outlier.
OUTLIER_Z = 3.5


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
    resistance_ohm: float | None = None
    resistance_interval95: list | None = None
    efc: float | None = None
    outlier: bool = False
    notes: list[str] = field(default_factory=list)

    @property
    def health_kind(self) -> str:
        """``"full"`` (a full discharge), ``"partial"`` (a bench discharge) or ``"flight"``."""
        if self.kind == "flight":
            return "flight"
        return "full" if self.full else "partial"

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
                "resistance_interval95": self.resistance_interval95, "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, data: dict) -> EventHealth:
        """The event :meth:`to_dict` describes."""
        return cls(event_id=data["event_id"], source=data["source"], start=data["start"],
                   kind=data["event_kind"], cycle=data["cycle"],
                   discharged_Ah=data["discharged_Ah"], full=data["full"],
                   capacity_Ah=data["capacity_Ah"],
                   capacity_interval95=data["capacity_interval95"],
                   capacity_method=data["capacity_method"],
                   resistance_ohm=data["resistance_ohm"],
                   resistance_interval95=data["resistance_interval95"], efc=data["efc"],
                   outlier=data["outlier"], notes=list(data["notes"]))


def order_events(events: list[dict]) -> list[dict]:
    """Events by start time, then cycle number, then the order they were added."""
    return sorted(events, key=lambda e: (e.get("start_time") or "",
                                         -1 if e.get("cycle") is None else e["cycle"],
                                         e.get("id") or 0, e.get("idx") or 0))


def pack_cells(event: dict, cells: int | None, chemistry: str | None) -> int:
    """Cells in series: the pack's, the log's, else inferred from the highest voltage."""
    from ..flight import infer_cells

    if cells:
        return int(cells)
    if event.get("cells"):
        return int(event["cells"])
    top = [x for x in (event.get("rest_voltage_V"), max(event["curve"]["voltage_V"] or [0]))
           if x]
    return infer_cells(np.array(top), chemistry)


def starts_full(event: dict, cells: int, chemistry: str | None) -> bool:
    """Whether the event starts from a full charge (see the module docstring)."""
    from ..ocv import soc_from_rest_voltage

    rest = event.get("rest_voltage_V")
    if rest is None:
        return event.get("kind") == "discharge"
    return bool(soc_from_rest_voltage(rest / cells, chemistry) >= FULL_SOC)


def full_capacity(event: dict) -> tuple[float, list]:
    """Coulomb-counted capacity [Ah] of a full discharge and its 95 % interval."""
    q = float(event["discharged_Ah"])
    samples = max(int(event.get("samples") or 2), 2)
    step_Ah = float(event["end_current_A"]) * float(event["duration_s"]) / (samples - 1) / 3600
    half = 1.96 * abs(step_Ah) / np.sqrt(12.0)
    return q, [q - half, q + half]


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
        return self.voltage + self.drop

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
    curve = event["curve"]
    if event.get("rest_voltage_V") is not None:
        start = ref.place(event["rest_voltage_V"], ref.ocv, sd)
        how_start = "rest voltage before"
    else:
        start = ref.place(curve["voltage_V"][0], ref.loaded(curve["current_A"][0], r_now),
                          2 * sd)
        how_start = "first loaded voltage"
    if event.get("rest_after_V") is not None and (event.get("rest_after_s") or 0) >= RELAXED_S:
        end = ref.place(event["rest_after_V"], ref.ocv, sd)
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
    return cap, [cap - half, cap + half], f"reference curve ({how_start}, {how_end})"


def equivalent_full_cycles(ordered: list[dict], reference_Ah: float) -> np.ndarray:
    """Cumulative discharged charge / reference capacity after each event [-]."""
    total, out, prev = 0.0, [], None
    for e in ordered:
        q = float(e["discharged_Ah"])
        cycle = e.get("cycle")
        if cycle is not None:
            if prev is None and cycle > 1:
                total += (cycle - 1) * q
            elif prev is not None and prev[0] is not None and cycle > prev[0] + 1:
                total += (cycle - prev[0] - 1) * 0.5 * (q + prev[1])
        total += q
        out.append(total / reference_Ah)
        prev = (cycle, q)
    return np.array(out, dtype=float)


def flag_outliers(efc, values, neighbours: int = OUTLIER_NEIGHBOURS,
                  threshold: float = OUTLIER_Z) -> np.ndarray:
    """True where a value sits off the local trend of its neighbours (module docstring).

    The local trend at each event is the Theil-Sen line (median of pairwise slopes)
    through the :data:`OUTLIER_NEIGHBOURS` nearest events on each side (more on one
    side at the ends), the event itself left out. Events already flagged are left out
    of their neighbours' lines and the test repeated (at most three passes), so one
    odd cycle does not drag its neighbours out with it.
    """
    from scipy.stats import theilslopes

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
                slope, intercept, *_ = theilslopes(y[idx], x[idx])
                resid[k] = y[k] - (intercept + slope * x[k])
            else:
                resid[k] = y[k] - np.median(y[idx])
        centre = np.median(resid[~flags])
        mad = float(np.median(np.abs(resid[~flags] - centre)))
        if mad <= 0:
            break
        new = 0.6745 * np.abs(resid - centre) / mad > threshold
        if np.array_equal(new, flags):
            break
        flags = new
    return flags


def infer_chemistry(full_cell_V: float, end_cell_V: float) -> str:
    """The chemistry whose charge and cutoff voltages per cell lie nearest to a full
    discharge's rest (or first) voltage and end voltage [V] (tables
    :data:`dischargelab.ocv.CHARGE_CELL_V`, :data:`dischargelab.cell.CUTOFF_CELL_VOLTAGE_V`)."""
    from ..cell import CUTOFF_CELL_VOLTAGE_V
    from ..ocv import CHARGE_CELL_V

    return min(CHARGE_CELL_V, key=lambda c: abs(CHARGE_CELL_V[c] - full_cell_V)
               + abs(CUTOFF_CELL_VOLTAGE_V[c] - end_cell_V))


#: Events in the local line that gives a pack's capacity and resistance today.
TODAY_EVENTS = 7


def value_today(efc, values, events: int = TODAY_EVENTS) -> float | None:
    """A quantity today: the Theil-Sen line through the last ``events`` values, at the last EFC.

    Robust to one odd event, and local: the fade rate changes over a life, so the
    capacity today is read from the latest events, not from the whole-life trend.
    """
    from scipy.stats import theilslopes

    x = np.asarray(efc, dtype=float)[-events:]
    y = np.asarray(values, dtype=float)[-events:]
    if y.size == 0:
        return None
    if y.size < 3 or np.ptp(x) <= 0:
        return float(np.median(y))
    slope, intercept, *_ = theilslopes(y, x)
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
        The pack's fitted model (voltage drop at a current for partial events).

    Returns
    -------
    (list of EventHealth in order, reference capacity [Ah] or None, how it was chosen)
    """
    ordered = order_events(events)
    out: list[EventHealth] = []
    refs: list[int] = []
    for k, e in enumerate(ordered):
        n_cells = pack_cells(e, cells, chemistry)
        full = bool(e.get("reaches_knee")) and starts_full(e, n_cells, chemistry)
        h = EventHealth(event_id=e.get("id") or k, source=e.get("source", ""),
                        start=e.get("start_time"), kind=e["kind"], cycle=e.get("cycle"),
                        discharged_Ah=float(e["discharged_Ah"]), full=full,
                        resistance_ohm=e.get("resistance_ohm"))
        if e.get("resistance_low_ohm") is not None:
            h.resistance_interval95 = [e["resistance_low_ohm"], e["resistance_high_ohm"]]
        if full:
            h.capacity_Ah, h.capacity_interval95 = full_capacity(e)
            h.capacity_method = "coulomb count"
            refs.append(k)
        out.append(h)
    for k, (e, h) in enumerate(zip(ordered, out)):
        if h.full:
            continue
        if not refs:
            h.notes.append("no full discharge of this pack to compare with")
            continue
        before = [j for j in refs if j < k]
        j = before[-1] if before else refs[0]
        ref = ReferenceCurve(ordered[j], out[j].capacity_Ah, model=model)
        n_cells = pack_cells(e, cells, chemistry)
        cap, interval, how = partial_capacity(e, ref, n_cells)
        if cap is None:
            h.notes.append(how)
        else:
            h.capacity_Ah, h.capacity_interval95, h.capacity_method = cap, interval, how
    if label_capacity_Ah:
        reference, why = float(label_capacity_Ah), "label capacity"
    elif refs:
        reference, why = out[refs[0]].capacity_Ah, "first full discharge"
    else:
        reference, why = None, "no label capacity and no full discharge"
    if reference:
        for h, efc in zip(out, equivalent_full_cycles(ordered, reference)):
            h.efc = float(efc)
    with_cap = [k for k, h in enumerate(out) if h.capacity_Ah is not None]
    axis = [out[k].efc if out[k].efc is not None else k for k in with_cap]
    flags = flag_outliers(axis, [out[k].capacity_Ah for k in with_cap])
    for k, flag in zip(with_cap, flags):
        out[k].outlier = bool(flag)
    return out, reference, why


__all__ = ["EventHealth", "pack_health", "value_today", "infer_chemistry", "observed_crossing",
           "order_events", "equivalent_full_cycles", "flag_outliers", "partial_capacity",
           "full_capacity", "ReferenceCurve", "starts_full", "FULL_SOC", "VOLTAGE_SD_CELL_V",
           "OUTLIER_Z"]
