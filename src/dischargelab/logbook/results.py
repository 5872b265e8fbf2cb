"""Result objects of the logbook: packs, events, health with its forecast, a pack's model."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from ..errors import LogbookError
from .health import EventHealth
from .over_life import (
    _resistances,
    _scale_notes,
    capacity_now,
    capacity_over_life,
    estimate_kind,
    resistance_over_life,
)
from .trend import Smoothed, sd_from_interval

#: Default end of life: this share of the reference capacity.
DEFAULT_EOL = 0.8

#: Points of each trend kept in ``Health.to_dict()``.
TREND_POINTS = 160


def _clean(value):
    """Plain Python numbers for JSON (numpy scalars, NaN -> None)."""
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


@dataclass
class Forecast:
    """End of life of one pack (:mod:`.forecast`).

    Attributes
    ----------
    eol : float
        End of life as a share of the reference capacity.
    threshold_Ah : float
        ``eol`` times the reference capacity [Ah].
    eol_efc : float or None
        EFC at which the capacity reaches the threshold: the median of the simulated
        futures, or where the logged capacities fell through it (``observed``).
    eol_efc_interval95 : list
        ``[low, high]``; an end is None when the futures do not bound it within
        :data:`~dischargelab.logbook.forecast.HORIZON_FACTOR` times today's EFC.
    shape : str
        The most probable trend shape: ``"line"``, ``"early"`` (fast early fade,
        then a line), ``"knee"`` or ``"early+knee"``.
    bend_odds : float
        Bayes factor of a bent trend against the straight line.
    knee_efc : float or None
        EFC of the knee seen in the data (when more probable than not).
    knee_probability : float
        Posterior probability of a knee already in the data.
    band : dict
        ``{"efc", "capacity_Ah", "lo", "hi"}``: the smoothed capacity with its 95 %
        band up to the last estimate, then the futures' median and 2.5-97.5 %.
    last_efc : float
        EFC of the last capacity estimate (where the futures start).
    estimates : int
        Capacity estimates used.
    observed : bool
        The logged capacities already fell below the threshold (two in a row).
    status : str
        ``"dated"`` (an end of life forecast), ``"observed"``, ``"no fade"`` (the fade
        is not told apart from zero yet: no end of life) or ``"uncertain"`` (a fade is
        measured but not well enough for an end of life this soon), see
        :func:`~dischargelab.logbook.forecast.dating`.
    fade : dict
        The fade so far with its 95 % interval, how many sigma, over which span, and the
        EFC a typical fade needs to show (:class:`~.forecast.FadeEvidence`).
    message : str
        Why no end of life is given, in words ("no fade measured yet ...").
    """

    eol: float
    threshold_Ah: float
    eol_efc: float | None
    eol_efc_interval95: list
    shape: str
    bend_odds: float
    knee_efc: float | None
    knee_probability: float
    band: dict
    last_efc: float
    estimates: int
    observed: bool = False
    status: str = "dated"
    fade: dict = field(default_factory=dict)
    message: str = ""

    @property
    def reached(self) -> bool:
        """The capacity trend is already at or below the threshold today (the futures
        start below it), while no two logged capacities have fallen through it yet."""
        return (not self.observed and self.eol_efc is not None
                and self.eol_efc <= self.last_efc * (1 + 1e-9))

    def band_points(self, points: int = 120) -> dict:
        """:attr:`band` thinned to about ``points`` points (for plots and pages)."""
        efc = np.asarray(self.band["efc"], dtype=float)
        idx = np.arange(efc.size)
        if efc.size > points:
            idx = np.unique(np.linspace(0, efc.size - 1, points).round().astype(int))
        return _clean({k: [self.band[k][i] for i in idx] for k in ("efc", "capacity_Ah", "lo",
                                                                     "hi")})

    def to_dict(self) -> dict:
        return _clean({"eol": self.eol, "threshold_Ah": self.threshold_Ah,
                       "eol_efc": self.eol_efc,
                       "eol_efc_interval95": list(self.eol_efc_interval95),
                       "observed": self.observed, "shape": self.shape,
                       "bend_odds": self.bend_odds, "knee_efc": self.knee_efc,
                       "knee_probability": self.knee_probability, "last_efc": self.last_efc,
                       "estimates": self.estimates, "band": self.band_points(),
                       "status": self.status, "fade": self.fade, "message": self.message})

    @classmethod
    def from_dict(cls, d: dict) -> Forecast:
        band = d["band"]
        nan = float("nan")
        band = {k: [nan if v is None else v for v in band[k]]
                for k in ("efc", "capacity_Ah", "lo", "hi")}
        return cls(eol=d["eol"], threshold_Ah=d["threshold_Ah"], eol_efc=d["eol_efc"],
                   eol_efc_interval95=list(d["eol_efc_interval95"]), shape=d["shape"],
                   bend_odds=d["bend_odds"], knee_efc=d["knee_efc"],
                   knee_probability=d["knee_probability"], band=band,
                   last_efc=d["last_efc"], estimates=d["estimates"], observed=d["observed"],
                   status=d.get("status") or ("observed" if d["observed"] else "dated"),
                   fade=dict(d.get("fade") or {}), message=d.get("message") or "")


def _event_to_dict(e: EventHealth) -> dict:
    """An event's ``to_dict()`` plus every other field of it (``event_kind``: its stored
    kind), so that :meth:`Health.from_dict` rebuilds it."""
    out = e.to_dict()
    for f in fields(e):
        key = "event_kind" if f.name == "kind" else f.name
        out.setdefault(key, getattr(e, f.name))
    return out


def _event_from_dict(d: dict) -> EventHealth:
    values = {f.name: d.get("event_kind" if f.name == "kind" else f.name)
              for f in fields(EventHealth)}
    values["notes"] = list(values.get("notes") or [])
    values["outlier"] = bool(values.get("outlier"))
    return EventHealth(**values)


@dataclass
class Health:
    """A pack's health over its life: one row per event, today's figures, the trends
    and the forecast.

    ``to_dict()`` is the JSON of ``dischargelab logbook health NAME --json``;
    :meth:`from_dict` rebuilds the object from it (figures stored once per change).

    Attributes
    ----------
    today : dict
        ``efc``, ``capacity_Ah`` and ``capacity_interval95`` [Ah] (the capacity
        trend at today's EFC), ``resistance_ohm`` and ``resistance_interval95``
        [ohm], ``resistance_basis`` (``"reference conditions"`` or ``"as
        measured"``), ``capacity_from`` and ``resistance_from`` (the events that
        carry most of today's value: source, start, kind, efc, share).
    capacity_trend, resistance_trend : Smoothed or None
        The smoothed capacity [Ah] and resistance [ohm] over EFC (:mod:`.trend`).
    """

    pack: str
    events: list[EventHealth]
    reference_capacity_Ah: float | None
    reference: str
    forecast: Forecast | None
    notes: list[str] = field(default_factory=list)
    today: dict = field(default_factory=dict)
    capacity_trend: Smoothed | None = None
    resistance_trend: Smoothed | None = None

    def to_dict(self) -> dict:
        t = self.today
        return _clean({
            "pack": self.pack, "events": [_event_to_dict(e) for e in self.events],
            "forecast": None if self.forecast is None else self.forecast.to_dict(),
            "reference_capacity_Ah": self.reference_capacity_Ah, "reference": self.reference,
            "efc_now": t.get("efc"), "capacity_now_Ah": t.get("capacity_Ah"),
            "capacity_now_interval95": t.get("capacity_interval95"),
            "resistance_now_ohm": t.get("resistance_ohm"),
            "resistance_now_interval95": t.get("resistance_interval95"),
            "resistance_basis": t.get("resistance_basis"),
            "capacity_from": t.get("capacity_from", []),
            "resistance_from": t.get("resistance_from", []),
            "trend": {"capacity": None if self.capacity_trend is None
                      else self.capacity_trend.to_dict(points=TREND_POINTS),
                      "resistance": None if self.resistance_trend is None
                      else self.resistance_trend.to_dict(points=TREND_POINTS)},
            "notes": list(self.notes)})

    @classmethod
    def from_dict(cls, d: dict) -> Health:
        """The Health of :meth:`to_dict` back (trends as their stored bands)."""
        trend = d.get("trend") or {}
        today = {"efc": d.get("efc_now"), "capacity_Ah": d.get("capacity_now_Ah"),
                 "capacity_interval95": d.get("capacity_now_interval95"),
                 "resistance_ohm": d.get("resistance_now_ohm"),
                 "resistance_interval95": d.get("resistance_now_interval95"),
                 "resistance_basis": d.get("resistance_basis"),
                 "capacity_from": list(d.get("capacity_from") or []),
                 "resistance_from": list(d.get("resistance_from") or [])}
        return cls(pack=d["pack"], events=[_event_from_dict(e) for e in d["events"]],
                   reference_capacity_Ah=d.get("reference_capacity_Ah"),
                   reference=d.get("reference") or "",
                   forecast=None if d.get("forecast") is None
                   else Forecast.from_dict(d["forecast"]),
                   notes=list(d.get("notes") or []), today=today,
                   capacity_trend=None if trend.get("capacity") is None
                   else Smoothed.from_dict(trend["capacity"]),
                   resistance_trend=None if trend.get("resistance") is None
                   else Smoothed.from_dict(trend["resistance"]))

    def to_pandas(self):
        """Events with every health column (capacity method, full, cycle, notes...)."""
        import pandas as pd

        rows = []
        for e in self.events:
            row = e.to_dict()
            lo, hi = (e.capacity_interval95 or (None, None))
            rlo, rhi = (e.resistance_interval95 or (None, None))
            row.update(cycle=e.cycle, full=e.full, capacity_method=e.capacity_method,
                       capacity_low_Ah=lo, capacity_high_Ah=hi, resistance_low_ohm=rlo,
                       resistance_high_ohm=rhi, notes="; ".join(e.notes))
            row.pop("capacity_interval95")
            rows.append({k: v for k, v in _clean(row).items()
                         if not isinstance(v, (list, dict))})
        return pd.DataFrame(rows)

    @property
    def capacity_now_Ah(self) -> float | None:
        """Capacity today [Ah]: the capacity trend at today's EFC (:mod:`.trend`)."""
        return self.today.get("capacity_Ah")

    @property
    def capacity_now_interval95(self) -> list | None:
        """95 % interval of :attr:`capacity_now_Ah` [Ah]."""
        return self.today.get("capacity_interval95")

    @property
    def resistance_now_ohm(self) -> float | None:
        """Resistance today [ohm]: the resistance trend at today's EFC (at reference
        conditions when the events give it there, see ``today["resistance_basis"]``)."""
        return self.today.get("resistance_ohm")

    @property
    def efc_now(self) -> float | None:
        return self.today.get("efc")

    def plot(self, axes=None):
        """Capacity and resistance against EFC: estimates by kind with their intervals,
        the trends with their bands, the knee and the end of life.

        Returns the two Axes.
        """
        from ..plot import plot_health

        return plot_health(self, axes=axes)


@dataclass
class PackTable:
    """Every pack of the logbook, one row each (``rows``: list of dict)."""

    rows: list[dict]

    def to_dict(self) -> dict:
        return {"rows": _clean(self.rows)}

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame(_clean(self.rows))


@dataclass
class EventTable:
    """The events of one pack as stored (``rows``: list of dict, no curves)."""

    pack: str
    rows: list[dict]

    def to_dict(self) -> dict:
        return {"pack": self.pack, "events": _clean(self.rows)}

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame(_clean(self.rows))


#: Parameters of a family shifted by a resistance change (series resistance, per cell).
SERIES_RESISTANCE = ("R_ohm", "R0_ohm")


#: Relative standard deviation of a pack's capacity when only its label gives it [-]
#: (packs are sold within about +-10 % of their label, and age from it).
LABEL_CAPACITY_SD = 0.05


def capacity_draws(n: int, relative_sd: float, seed: int = 0) -> np.ndarray:
    """``n`` seeded factors around 1 with ``relative_sd`` (normal, kept within 4 sd and
    above 0.05): the capacity today's uncertainty handed to a model's parameter draws."""
    z = np.clip(np.random.default_rng(seed).standard_normal(n), -4.0, 4.0)
    return np.maximum(1.0 + relative_sd * z, 0.05)


def scale_parameters(values: dict, units: dict, factor: float, shift_cell_ohm: float) -> dict:
    """Parameters of a cell whose capacity is ``factor`` times and series resistance
    ``shift_cell_ohm`` more: charges [Ah] times ``factor``, per-charge quantities
    [x/Ah] divided by it (the curve keeps its shape in state of charge), the series
    resistance shifted (not below 0)."""
    out = dict(values)
    for name, value in values.items():
        unit = units.get(name, "")
        if unit in ("Ah", "Ah/K"):
            out[name] = value * factor
        elif unit.endswith("/Ah"):
            out[name] = value / factor
        elif name in SERIES_RESISTANCE:
            out[name] = max(0.0, value + shift_cell_ohm)
    return out


@dataclass
class Pack:
    """One pack of the logbook: its settings, health today and model.

    ``dl.endurance(logbook.pack(NAME), mission)`` flies the pack's model scaled to
    its capacity and resistance today (:meth:`battery`).
    """

    name: str
    label_capacity_Ah: float | None
    reference_capacity_Ah: float | None
    chemistry: str | None
    cells: int | None
    events: int
    efc: float | None
    capacity_Ah: float | None
    resistance_ohm: float | None
    health: Health | None = None
    capacity_interval95: list | None = None
    _model: Any = None
    _fit: Any = None
    _seen: dict = field(default_factory=dict)

    @property
    def fitted(self) -> bool:
        """A fitted model of the pack is stored (without one, :meth:`battery` fits and
        stores one first when the pack has a full discharge: a write)."""
        return self._model is not None

    @property
    def has_full_discharge(self) -> bool:
        """The pack has a full discharge (not an outlier) a model can be fitted to."""
        return self.health is not None and any(e.full and not e.outlier
                                               for e in self.health.events)

    def battery(self):
        """The pack's model at today's capacity and resistance.

        With a fitted model (stored, or fitted and stored now from the latest full
        discharge): every charge parameter times ``capacity today / capacity at the
        fit``, the series resistance plus the change of the resistance trend since
        the fit (per cell). A pack without a full discharge (flights only): the
        chemistry's prior built to today's figures (:mod:`.today`). The returned
        Battery's ``extra["note"]`` says which, and which events today's figures come
        from; ``dl.endurance`` and ``autopilot_params`` repeat it in their notes.

        Raises
        ------
        LogbookError
            No capacity today (and no label capacity for a pack that only flies).
        """
        model = self._model
        if model is None and self._fit is not None and self.has_full_discharge:
            model = self._fit()
        if model is None:
            return self._prior()
        return self._scaled(model)

    def _capacity_sd(self) -> float | None:
        """Relative standard deviation of the capacity today [-], from the wider side of
        its 95 % band (None without a band)."""
        band = self.capacity_interval95
        if not self.capacity_Ah or not band or any(b is None for b in band):
            return None
        low = [band[0], 2 * self.capacity_Ah - band[0]]
        return float(max(sd_from_interval(*band), sd_from_interval(*low))) / self.capacity_Ah

    def _note(self) -> str:
        from .today import figures_note

        if self.health is None:
            return f"logbook pack {self.name!r}"
        return figures_note(self.health, self.name)

    def _prior(self):
        from ..ocv import DEFAULT_CHEMISTRY
        from .today import prior_battery

        capacity, note = self.capacity_Ah, self._note()
        if capacity is None and self.label_capacity_Ah:
            capacity = self.label_capacity_Ah
            note += f", no capacity estimate yet: its label capacity {capacity:.3g} Ah"
        if capacity is None:
            raise LogbookError(f"pack {self.name!r} has no capacity estimate and no label "
                               "capacity; set one with --capacity AH (Logbook.set_pack)")
        chemistry = self.chemistry or self._seen.get("chemistry")
        if chemistry is None:
            chemistry = DEFAULT_CHEMISTRY
            note += f"; chemistry unknown, {chemistry} assumed (set it with --chemistry)"
        elif self.chemistry is None:
            note += f"; chemistry taken as {chemistry} from its full rest voltage"
        cells = self.cells or self._seen.get("cells") or 1
        today = {} if self.health is None else self.health.today
        return prior_battery(self.name, chemistry, int(cells), float(capacity),
                             self.resistance_ohm, note,
                             rest_cell_V=self._seen.get("rest_cell_V"),
                             capacity_sd=self._capacity_sd() if capacity == self.capacity_Ah
                             else LABEL_CAPACITY_SD,
                             resistance_interval95=today.get("resistance_interval95"))

    def _scaled(self, model: dict):
        from ..cell import CellParameters
        from ..model import Battery

        bat = Battery.from_dict(model["battery"])
        if self.capacity_Ah is None or not model.get("capacity_Ah"):
            raise LogbookError(f"pack {self.name!r} has no capacity estimate yet")
        factor = float(self.capacity_Ah) / float(model["capacity_Ah"])
        shift = 0.0
        at_fit = self._resistance_at_fit(model)
        if self.resistance_ohm is not None and at_fit is not None:
            shift = (self.resistance_ohm - at_fit) * bat.strings_parallel / bat.cells_series
        fam = bat.family
        units = {p.name: p.unit for p in fam.parameters}
        params = scale_parameters({n: float(bat.parameters[n]) for n in fam.names}, units,
                                  factor, shift)
        extra = dict(bat.extra)
        sd = self._capacity_sd() or 0.0
        boot = extra.get("bootstrap")
        if isinstance(boot, dict) and boot.get("samples"):
            # each refit also draws its own capacity today from the band around it
            names = list(boot["names"])
            draws = capacity_draws(len(boot["samples"]), sd)
            scaled = [[scale_parameters(dict(zip(names, row)), units, factor * d, shift)[n]
                       for n in names] for row, d in zip(boot["samples"], draws)]
            extra["bootstrap"] = dict(boot, samples=scaled)
        power = np.array([1.0 if units.get(n) in ("Ah", "Ah/K") else
                          -1.0 if units.get(n, "").endswith("/Ah") else 0.0
                          for n in fam.names])
        jac = factor ** power
        cov = None if bat.covariance is None else \
            np.asarray(bat.covariance) * np.outer(jac, jac)
        if cov is not None and sd > 0:  # plus the capacity today's own uncertainty
            slope = power * np.array([float(params[n]) for n in fam.names])
            cov = cov + sd ** 2 * np.outer(slope, slope)
        note = (f"{self._note()}; its fitted model scaled to its health today: capacity "
                f"x{factor:.3f}, "
                f"series resistance {shift * 1000:+.1f} mOhm per cell")
        extra["logbook"] = {"pack": self.name, "capacity_factor": factor,
                            "resistance_shift_cell_ohm": shift}
        extra["note"] = note
        for key in ("measured_capacity_Ah", "nominal_capacity_Ah"):
            if extra.get(key):
                extra[key] = float(extra[key]) * factor
        return replace(bat, parameters=CellParameters.from_dict(params, fam.names),
                       covariance=cov, extra=extra, name=f"{self.name} (today)")

    def _resistance_at_fit(self, model: dict) -> float | None:
        """The resistance trend at the EFC of the event the model was fitted to (same
        basis as today's), else the resistance measured on that event."""
        h = self.health
        trend = None if h is None else h.resistance_trend
        ref = model.get("reference_event_id")
        if trend is not None and ref is not None:
            for e in h.events:
                if e.event_id == ref and e.efc is not None:
                    return float(trend.at(e.efc)[0][0])
        return model.get("resistance_ohm")

    def to_battery(self):
        """:meth:`battery` (what ``dl.load``, ``dl.endurance`` and ``dl.predict`` call)."""
        return self.battery()

    def to_dict(self) -> dict:
        return _clean({"name": self.name, "label_capacity_Ah": self.label_capacity_Ah,
                       "reference_capacity_Ah": self.reference_capacity_Ah,
                       "chemistry": self.chemistry, "cells": self.cells, "events": self.events,
                       "efc": self.efc, "capacity_Ah": self.capacity_Ah,
                       "capacity_interval95": self.capacity_interval95,
                       "resistance_ohm": self.resistance_ohm})


def build_health(row: dict, events: list[dict], model: dict | None, eol: float) -> Health:
    """Health of one pack from its stored rows ``(pack row, event rows, model row or None)``
    (pure; per event :mod:`.health`, over the life :mod:`.trend`, ahead :mod:`.forecast`).

    This is the one place that makes a pack's figures; everything that shows them
    (``logbook health``, ``packs``, the fleet report, the pack page, ``endurance
    --pack``) reads them from the :class:`Health` it returns.
    """
    from ..model import Battery
    from .health import pack_health

    battery = Battery.from_dict(model["battery"]) if model else None
    per_event, reference, how = pack_health(
        events, label_capacity_Ah=row["label_capacity_Ah"], cells=row["cells"],
        chemistry=row["chemistry"], model=battery)
    notes = [f"reference capacity: {how}"]
    if reference is None:
        reference, fallback = _reference_from_estimates(per_event)
        if reference is not None:
            how = fallback
            notes = [f"reference capacity: {fallback}"]
    with_cap = [e for e in per_event if e.capacity_Ah is not None and not e.outlier
                and e.efc is not None]
    capacity_trend = capacity_over_life(with_cap, per_event=per_event)
    if capacity_trend is not None:
        notes += _scale_notes(with_cap, capacity_trend, per_event)
    resistance_trend = resistance_over_life(per_event)
    efcs = [e.efc for e in per_event if e.efc is not None]
    _, _, basis, with_r = _resistances(per_event)
    today: dict = {"efc": efcs[-1] if efcs else None, "resistance_basis": basis}
    if capacity_trend is not None:
        value, interval = capacity_trend.interval95(today["efc"])
        today.update(capacity_Ah=value, capacity_interval95=interval,
                     capacity_from=_sources(with_cap, capacity_trend.influence))
    if resistance_trend is not None:
        value, interval = resistance_trend.interval95(today["efc"])
        # a resistance is positive: a band from two or three events (a t with one or two
        # degrees of freedom) must not reach below zero
        interval = [max(interval[0], 0.0), interval[1]]
        today.update(resistance_ohm=value, resistance_interval95=interval,
                     resistance_from=_sources(with_r, resistance_trend.influence))
    forecast = None
    if reference and capacity_trend is not None:
        forecast = _forecast(with_cap, capacity_trend, reference, eol, notes,
                             chemistry=row["chemistry"], efc_now=today["efc"])
    return Health(pack=row["name"], events=per_event, reference_capacity_Ah=reference,
                  reference=how, forecast=forecast, notes=notes, today=today,
                  capacity_trend=capacity_trend, resistance_trend=resistance_trend)


def _reference_from_estimates(per_event: list[EventHealth]) -> tuple[float | None, str]:
    """Without a label capacity or a full discharge: the median of the pack's first three
    capacity estimates as the reference, and each event's EFC counted against it."""
    from .health import equivalent_full_cycles

    first = [e.capacity_Ah for e in per_event if e.capacity_Ah is not None and not e.outlier]
    if not first:
        return None, ""
    reference = float(np.median(first[:3]))
    rows = [{"discharged_Ah": e.discharged_Ah, "cycle": e.cycle} for e in per_event]
    for e, efc in zip(per_event, equivalent_full_cycles(rows, reference)):
        e.efc = float(efc)
    return reference, (f"median of the first {min(len(first), 3)} capacity estimate(s) (no "
                       "label capacity and no full discharge)")


#: Events listed as the source of a figure today: those carrying this share of it.
SOURCE_SHARE = 0.9
#: ... and at most this many.
SOURCE_EVENTS = 8


def _sources(chosen: list[EventHealth], influence) -> list[dict]:
    """The events that carry most of today's value (by their weight in it), in order."""
    share = np.abs(np.nan_to_num(np.asarray(influence, dtype=float)))
    if share.sum() <= 0:
        return []
    share = share / share.sum()
    top = np.argsort(-share, kind="stable")
    cut = int(np.searchsorted(np.cumsum(share[top]), SOURCE_SHARE)) + 1
    keep = sorted(top[:min(cut, SOURCE_EVENTS)])
    return [{"source": chosen[k].source, "start": chosen[k].start,
             "kind": chosen[k].to_dict().get("kind"), "efc": chosen[k].efc,
             "share": float(share[k])} for k in keep]


def _forecast(with_cap: list[EventHealth], trend: Smoothed, reference: float, eol: float,
              notes: list[str], chemistry: str | None = None,
              efc_now: float | None = None) -> Forecast | None:
    """End of life from the capacity estimates (:mod:`.forecast`), or where the logged
    capacities already fell through it; none until a fade is measured (:func:`.dating`).
    The futures start from the capacity trend that gives the health today."""
    from .forecast import dating, evidence_words, forecast_capacity, measure_fade
    from .outliers import observed_crossing

    efc = np.array([e.efc for e in with_cap])
    cap = np.array([e.capacity_Ah for e in with_cap])
    lo = [np.nan if e.own_interval95 is None else e.own_interval95[0] for e in with_cap]
    hi = [np.nan if e.own_interval95 is None else e.own_interval95[1] for e in with_cap]
    threshold = eol * reference
    evidence = measure_fade(efc, cap, lo, hi, [estimate_kind(e) for e in with_cap],
                            weights=trend.weights, shared_Ah=trend.systematic,
                            nugget_Ah=trend.nugget,
                            chemistry=chemistry)
    x_now = float(efc.max())
    today = max(x_now, efc_now or 0.0)
    made = None
    if evidence.measured:
        mean, sd = trend.at(x_now)
        made = forecast_capacity(efc, cap, lo, hi, reference, threshold,
                                 weights=trend.weights, start=(float(mean[0]), float(sd[0])))
    fit, ahead = made if made is not None else (None, None)
    status = dating(evidence, ahead, today)
    past = (trend.efc >= efc.min()) & (trend.efc <= x_now)
    lo_past, hi_past = trend.band()
    band = {"efc": [*trend.efc[past]], "capacity_Ah": [*trend.level[past]],
            "lo": [*lo_past[past]], "hi": [*hi_past[past]]}
    common = dict(eol=eol, threshold_Ah=threshold, band=band, last_efc=x_now,
                  fade=evidence.to_dict(), estimates=int(efc.size))
    if status != "dated":
        shape = {} if fit is None else dict(shape=fit.family, bend_odds=fit.bend_odds,
                                            knee_efc=fit.knee_efc,
                                            knee_probability=fit.knee_probability)
        fc = Forecast(eol_efc=None, eol_efc_interval95=[None, None],
                      **{"shape": "", "bend_odds": float("nan"), "knee_efc": None,
                         "knee_probability": float("nan"), **shape},
                      status=status, message=evidence_words(evidence, status, today),
                      **common)
        fc.band = _clean(fc.band)
        return fc
    central, interval = ahead.eol_efc, list(ahead.interval95)
    seen = observed_crossing(efc, cap, threshold)
    if seen is not None:
        central, interval = seen
        notes.append(f"end of life observed: the capacity fell below {threshold:.3g} Ah "
                     f"between {interval[0]:.0f} and {interval[1]:.0f} EFC")
    end = max(v for v in (interval[1], central, fit.x_now) if v is not None)
    future = (ahead.efc > fit.x_now) & (ahead.efc <= max(1.15 * end, 1.5 * fit.x_now))
    for key, values in (("efc", ahead.efc), ("capacity_Ah", ahead.median),
                        ("lo", ahead.low), ("hi", ahead.high)):
        band[key] = [*band[key], *values[future]]
    common["band"] = _clean(band)
    return Forecast(eol_efc=central, eol_efc_interval95=interval, shape=fit.family,
                    bend_odds=fit.bend_odds, knee_efc=fit.knee_efc,
                    knee_probability=fit.knee_probability, observed=seen is not None,
                    status="observed" if seen is not None else "dated", **common)


__all__ = ["Health", "Forecast", "PackTable", "EventTable", "Pack", "scale_parameters",
           "build_health", "capacity_now", "capacity_over_life", "DEFAULT_EOL"]
