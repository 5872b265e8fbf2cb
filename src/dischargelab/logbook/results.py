"""Result objects of the logbook: packs, events, health with its forecast, a pack's model."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from ..errors import LogbookError
from .forecast import Trend
from .health import EventHealth

#: Default end of life: this share of the reference capacity.
DEFAULT_EOL = 0.8


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
    """End of life of one pack.

    Attributes
    ----------
    eol : float
        End of life as a share of the reference capacity.
    threshold_Ah : float
        ``eol`` times the reference capacity [Ah].
    eol_efc : float or None
        EFC at which the capacity trend reaches the threshold (median of the
        simulated futures; None when no fade is seen).
    eol_efc_interval95 : list
        ``[low, high]``; an end is None when the band does not bound it.
    capacity : Trend
        Capacity trend [Ah] against EFC (outliers left out).
    resistance : Trend or None
        Resistance trend [ohm] against EFC.
    band : tuple or None
        ``(efc, low, high)`` of the capacity's simulated futures past the last event.
    observed : bool
        The logged capacities already fell below the threshold: ``eol_efc`` is where
        (interpolated), the interval the two events around it.
    """

    eol: float
    threshold_Ah: float
    eol_efc: float | None
    eol_efc_interval95: list
    capacity: Trend
    resistance: Trend | None = None
    band: tuple | None = None
    first_efc: float = 0.0
    observed: bool = False

    def band_points(self, points: int = 120) -> dict:
        """The capacity trend and its 95 % band from the first event to the forecast's end:
        ``{"efc", "capacity_Ah", "lo", "hi"}`` (lists; for plots and pages)."""
        trend = self.capacity
        past = np.linspace(self.first_efc, trend.last_efc, points // 2)
        lo_p, hi_p = trend.band(past)
        efc, lo, hi = list(past), list(lo_p), list(hi_p)
        mean = list(trend.mean(past))
        if self.band is not None:
            grid, blo, bhi = self.band
            end = self.eol_efc_interval95[1] or self.eol_efc or grid[-1]
            stop = max(int(np.searchsorted(grid, 1.1 * end)), 2)
            idx = np.unique(np.linspace(1, min(stop, grid.size - 1), points // 2).astype(int))
            efc += list(grid[idx])
            lo += list(blo[idx])
            hi += list(bhi[idx])
            mean += list(trend.mean(grid[idx]))
        return _clean({"efc": efc, "capacity_Ah": mean, "lo": lo, "hi": hi})

    def to_dict(self) -> dict:
        """The forecast for pages and JSON (``band``: :meth:`band_points`) with what
        :meth:`from_dict` needs to rebuild it (the trends' coefficients, the simulated
        band)."""
        future = None if self.band is None else {
            k: np.asarray(v, dtype=float).tolist() for k, v in zip(("efc", "lo", "hi"), self.band)}
        return _clean({"eol": self.eol, "threshold_Ah": self.threshold_Ah,
                       "eol_efc": self.eol_efc,
                       "eol_efc_interval95": list(self.eol_efc_interval95),
                       "observed": self.observed, "first_efc": self.first_efc,
                       "band": self.band_points(),
                       "capacity_trend": _trend_state(self.capacity),
                       "resistance_trend": _trend_state(self.resistance),
                       "future_band": future})

    @classmethod
    def from_dict(cls, data: dict) -> Forecast:
        """The forecast :meth:`to_dict` describes."""
        future = data.get("future_band")
        band = None if future is None else tuple(
            np.asarray(future[k], dtype=float) for k in ("efc", "lo", "hi"))
        return cls(eol=data["eol"], threshold_Ah=data["threshold_Ah"], eol_efc=data["eol_efc"],
                   eol_efc_interval95=list(data["eol_efc_interval95"]),
                   capacity=_trend_from(data["capacity_trend"]),
                   resistance=_trend_from(data.get("resistance_trend")), band=band,
                   first_efc=data["first_efc"], observed=data["observed"])


def _trend_state(trend: Trend | None) -> dict | None:
    """Every field of a trend (what :func:`_trend_from` rebuilds it from)."""
    if trend is None:
        return None
    return {f.name: np.asarray(getattr(trend, f.name)).tolist() for f in fields(trend)}


def _trend_from(state: dict | None) -> Trend | None:
    if state is None:
        return None
    values = {f.name: state[f.name] for f in fields(Trend)}
    values["covariance"] = np.asarray(values["covariance"], dtype=float)
    return Trend(**values)


@dataclass
class Health:
    """A pack's health over its life: one row per event, and the forecast.

    ``to_dict()`` is the JSON of ``dischargelab logbook health NAME --json``.
    """

    pack: str
    events: list[EventHealth]
    reference_capacity_Ah: float | None
    reference: str
    forecast: Forecast | None
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return _clean({"pack": self.pack, "reference_capacity_Ah": self.reference_capacity_Ah,
                       "reference": self.reference, "notes": list(self.notes),
                       "events": [e.to_dict() for e in self.events],
                       "forecast": None if self.forecast is None else self.forecast.to_dict()})

    @classmethod
    def from_dict(cls, data: dict) -> Health:
        """The health :meth:`to_dict` describes (how the logbook's stored figures are read)."""
        forecast = data.get("forecast")
        return cls(pack=data["pack"], events=[EventHealth.from_dict(e) for e in data["events"]],
                   reference_capacity_Ah=data.get("reference_capacity_Ah"),
                   reference=data.get("reference", ""),
                   forecast=None if forecast is None else Forecast.from_dict(forecast),
                   notes=list(data.get("notes", [])))

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
            row.pop("resistance_interval95")
            rows.append(_clean(row))
        return pd.DataFrame(rows)

    @property
    def capacity_now_Ah(self) -> float | None:
        """Capacity today [Ah]: robust line through the latest capacities (outliers left
        out), at the last one (:func:`~dischargelab.logbook.health.value_today`)."""
        from .health import value_today

        sel = [e for e in self.events if e.capacity_Ah is not None and not e.outlier]
        return value_today([e.efc if e.efc is not None else k for k, e in enumerate(sel)],
                           [e.capacity_Ah for e in sel])

    @property
    def resistance_now_ohm(self) -> float | None:
        """Resistance today [ohm], read like :attr:`capacity_now_Ah`."""
        from .health import value_today

        sel = [e for e in self.events if e.resistance_ohm is not None and not e.outlier]
        return value_today([e.efc if e.efc is not None else k for k, e in enumerate(sel)],
                           [e.resistance_ohm for e in sel])

    @property
    def efc_now(self) -> float | None:
        values = [e.efc for e in self.events if e.efc is not None]
        return values[-1] if values else None

    def plot(self, axes=None):
        """Capacity and resistance against EFC, trend, 95 % band, forecast, outliers.

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
    _model: Any = None
    _fit: Any = None

    @property
    def fitted(self) -> bool:
        """A fitted model of the pack is stored (without one, :meth:`battery` fits and
        stores one first: a write)."""
        return self._model is not None

    def battery(self):
        """The pack's fitted model scaled to today's capacity and resistance.

        Capacity: every charge parameter times ``capacity today / capacity at the
        fit``; resistance: the series resistance plus the change of the measured step
        resistance since the fit (per cell). The returned Battery's
        ``extra["note"]`` says so; ``dl.endurance`` repeats it in its result's notes.

        Raises
        ------
        LogbookError
            No model can be fitted (no full discharge) or no capacity today.
        """
        from ..model import Battery

        model = self._model
        if model is None and self._fit is not None:
            model = self._fit()
        if model is None:
            raise LogbookError(f"pack {self.name!r} has no fitted model; it needs a full "
                               "discharge in the logbook (Logbook.fit)")
        bat = Battery.from_dict(model["battery"])
        if self.capacity_Ah is None or not model.get("capacity_Ah"):
            raise LogbookError(f"pack {self.name!r} has no capacity estimate yet")
        factor = float(self.capacity_Ah) / float(model["capacity_Ah"])
        shift = 0.0
        if self.resistance_ohm is not None and model.get("resistance_ohm") is not None:
            shift = (self.resistance_ohm - model["resistance_ohm"]) * bat.strings_parallel \
                / bat.cells_series
        fam = bat.family
        units = {p.name: p.unit for p in fam.parameters}
        params = scale_parameters({n: float(bat.parameters[n]) for n in fam.names}, units,
                                  factor, shift)
        extra = dict(bat.extra)
        boot = extra.get("bootstrap")
        if isinstance(boot, dict) and boot.get("samples"):
            names = list(boot["names"])
            scaled = [[scale_parameters(dict(zip(names, row)), units, factor, shift)[n]
                       for n in names] for row in boot["samples"]]
            extra["bootstrap"] = dict(boot, samples=scaled)
        jac = np.array([factor if units.get(n) in ("Ah", "Ah/K") else
                        1.0 / factor if units.get(n, "").endswith("/Ah") else 1.0
                        for n in fam.names])
        cov = None if bat.covariance is None else \
            np.asarray(bat.covariance) * np.outer(jac, jac)
        note = (f"battery model of logbook pack {self.name!r} scaled to its health today "
                f"(EFC {self.efc:.0f}): capacity x{factor:.3f} ({self.capacity_Ah:.3g} Ah), "
                f"series resistance {shift * 1000:+.1f} mOhm per cell")
        extra["logbook"] = {"pack": self.name, "capacity_factor": factor,
                            "resistance_shift_cell_ohm": shift}
        extra["note"] = note
        for key in ("measured_capacity_Ah", "nominal_capacity_Ah"):
            if extra.get(key):
                extra[key] = float(extra[key]) * factor
        from ..cell import CellParameters

        return replace(bat, parameters=CellParameters.from_dict(params, fam.names),
                       covariance=cov, extra=extra, name=f"{self.name} (today)")

    def to_battery(self):
        """:meth:`battery` (what ``dl.load``, ``dl.endurance`` and ``dl.predict`` call)."""
        return self.battery()

    def to_dict(self) -> dict:
        return _clean({"name": self.name, "label_capacity_Ah": self.label_capacity_Ah,
                       "reference_capacity_Ah": self.reference_capacity_Ah,
                       "chemistry": self.chemistry, "cells": self.cells, "events": self.events,
                       "efc": self.efc, "capacity_Ah": self.capacity_Ah,
                       "resistance_ohm": self.resistance_ohm})


def build_health(row: dict, events: list[dict], model: dict | None, eol: float) -> Health:
    """Health of one pack from its stored rows ``(pack row, event rows, model row or None)``
    (pure; see :mod:`.health` and :mod:`.forecast`)."""
    import numpy as np

    from ..model import Battery
    from .forecast import crossing, fit_trend
    from .health import observed_crossing, pack_health

    battery = Battery.from_dict(model["battery"]) if model else None
    per_event, reference, how = pack_health(
        events, label_capacity_Ah=row["label_capacity_Ah"], cells=row["cells"],
        chemistry=row["chemistry"], model=battery)
    notes = [f"reference capacity: {how}"]
    usable = [e for e in per_event if e.capacity_Ah is not None and not e.outlier
              and e.efc is not None]
    forecast = None
    if reference and len(usable) >= 2:
        efc = np.array([e.efc for e in usable])
        cap = np.array([e.capacity_Ah for e in usable])
        sd = np.array([(e.capacity_interval95[1] - e.capacity_interval95[0]) / 3.92
                       for e in usable])
        trend = fit_trend(efc, cap, sd)
        if trend is not None:
            threshold = eol * reference
            central, interval, band = crossing(trend, threshold, first_efc=float(efc.min()))
            seen = observed_crossing(efc, cap, threshold)
            if seen is not None:
                central, interval = seen
                notes.append(f"end of life observed: the capacity fell below {threshold:.3g} Ah "
                             f"between {interval[0]:.0f} and {interval[1]:.0f} EFC")
            with_r = [e for e in per_event if e.resistance_ohm is not None and not e.outlier
                      and e.efc is not None]
            r_trend = fit_trend([e.efc for e in with_r], [e.resistance_ohm for e in with_r]) \
                if len(with_r) >= 2 else None
            forecast = Forecast(eol=eol, threshold_Ah=threshold, eol_efc=central,
                                eol_efc_interval95=interval, capacity=trend,
                                resistance=r_trend, band=band, first_efc=float(efc.min()),
                                observed=seen is not None)
    return Health(pack=row["name"], events=per_event, reference_capacity_Ah=reference,
                  reference=how, forecast=forecast, notes=notes)


__all__ = ["Health", "Forecast", "PackTable", "EventTable", "Pack", "scale_parameters",
           "build_health", "DEFAULT_EOL"]
