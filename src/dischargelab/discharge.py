"""A measured discharge, :class:`Discharge`, and the fitter's view of it, :class:`Curve`.

Every reader's output becomes a ``Discharge`` (time, voltage, current,
temperature, per-cell voltages, the rest voltage before the load, where it came
from); fitting and validation take it directly.

Sign convention: discharge current positive; times from the load start [s].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .cell import charge_from_current
from .errors import DataError


def measured_time_to_cutoff(time_s, voltage_V, cutoff_V: float, hold_s: float = 0.0) -> float:
    """Time [s] at which ``voltage_V`` goes to or below ``cutoff_V`` and stays there
    ``hold_s`` [s] (NaN if it never does); ``hold_s = 0``: the first crossing.

    The crossing is interpolated linearly between the sample above and the one
    below; a stretch under the cutoff lasts until the next sample above it. A
    stretch that lasts to the last sample counts however short it is: the
    measurement (a test stopped at the cutoff, a flight landed on the alarm) or
    the simulation ended there.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_V, dtype=float)
    below = v <= cutoff_V
    if not below.any():
        return float("nan")
    edges = np.diff(np.r_[0, below.astype(np.int8), 0])
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if a == 0:
            crossing = float(t[0])
        else:
            v0, v1 = v[a - 1], v[a]
            frac = (v0 - cutoff_V) / (v0 - v1) if v0 != v1 else 1.0
            crossing = float(t[a - 1] + frac * (t[a] - t[a - 1]))
        if b >= t.size or t[b] - crossing >= hold_s:
            return crossing
    return float("nan")


@dataclass(frozen=True, eq=False)
class Discharge:
    """One measured discharge at pack level.

    Attributes
    ----------
    time_s, voltage_V, current_A : numpy.ndarray
        Samples [s] (0 at load start), pack voltage [V], pack current [A]
        (discharge positive).
    temperature_C : numpy.ndarray or None
        Logged cell temperature [degC], when the source has one.
    rest_voltage_V : float or None
        Pack voltage at rest just before the load step [V].
    name : str
        Label for tables and plots (file name by default).
    meta : dict
        What the reader found and inferred (``source``, ``format``, ``notes``,
        ``summary``, ...).
    extra : dict
        Other logged columns by canonical name (``cell1_V``, ``soc_pct``, ...).
    """

    time_s: np.ndarray
    voltage_V: np.ndarray
    current_A: np.ndarray
    temperature_C: np.ndarray | None = None
    rest_voltage_V: float | None = None
    name: str = ""
    meta: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    @classmethod
    def from_frame(cls, frame, meta: dict | None = None, name: str = "") -> Discharge:
        """Build from a reader's canonical DataFrame and meta dict."""
        meta = dict(meta or {})
        missing = [c for c in ("time_s", "voltage_V", "current_A") if c not in frame]
        if missing:
            raise DataError(f"data has no {', '.join(missing)} column; files without a current "
                            "column need a constant current (current_A=...)")
        rest = (meta.get("rest_sample") or {}).get("voltage_V")
        temp = frame["temperature_C"].to_numpy(float) if "temperature_C" in frame else None
        if temp is not None and not np.all(np.isfinite(temp)):
            temp = None
        known = {"time_s", "voltage_V", "current_A", "temperature_C"}
        extra = {c: frame[c].to_numpy() for c in frame.columns if c not in known}
        label = name or str(meta.get("name") or "")
        if not label and meta.get("source"):
            from pathlib import Path

            label = Path(str(meta["source"])).name
        return cls(frame["time_s"].to_numpy(float), frame["voltage_V"].to_numpy(float),
                   frame["current_A"].to_numpy(float), temp,
                   None if rest is None else float(rest), label, meta, extra)

    @property
    def duration_s(self) -> float:
        """Time from the load start to the last sample [s]."""
        return float(self.time_s[-1] - self.time_s[0]) if self.time_s.size else 0.0

    @property
    def charge_Ah(self) -> float:
        """Charge delivered [Ah] (trapezoid over the samples)."""
        if self.time_s.size < 2:
            return 0.0
        return float(np.sum(0.5 * (self.current_A[1:] + self.current_A[:-1])
                            * np.diff(self.time_s)) / 3600.0)

    @property
    def mean_current_A(self) -> float:
        """Time-averaged current [A]."""
        return self.charge_Ah * 3600.0 / self.duration_s if self.duration_s > 0 else 0.0

    def to_curve(self):
        """The fitter's input (:class:`Curve`)."""
        return Curve(self.time_s, self.voltage_V, self.current_A, name=self.name,
                     rest_voltage_V=self.rest_voltage_V, meta=dict(self.meta),
                     temperature_C=self.temperature_C)

    def to_pandas(self):
        """Samples as a DataFrame with canonical column names."""
        import pandas as pd

        cols = {"time_s": self.time_s, "voltage_V": self.voltage_V, "current_A": self.current_A}
        if self.temperature_C is not None:
            cols["temperature_C"] = self.temperature_C
        cols.update(self.extra)
        return pd.DataFrame(cols)

    def to_dict(self) -> dict:
        """Summary: name, source, samples, duration, charge, mean current, notes."""
        return {"name": self.name, "source": self.meta.get("source"),
                "format": self.meta.get("format"), "samples": int(self.time_s.size),
                "duration_s": self.duration_s, "charge_Ah": self.charge_Ah,
                "mean_current_A": self.mean_current_A,
                "rest_voltage_V": self.rest_voltage_V,
                "has_temperature": self.temperature_C is not None,
                "summary": self.meta.get("summary"), "notes": list(self.meta.get("notes", []))}

    def plot(self, ax=None):
        """Voltage (and current on a second axis) against time; returns the Axes."""
        from .plot import plot_discharge

        return plot_discharge(self, ax=ax)


@dataclass
class Curve:
    """One measured discharge at pack level (discharge current positive).

    Parameters
    ----------
    time_s, voltage_V, current_A : array_like
        Samples [s], [V], [A] from load start.
    name : str
        Label used in plots and tables (file name, rate).
    temperature_C : array_like or None
        Logged cell temperature [degC] at the same samples, when measured.
    initial_charge_Ah : float
        Pack charge already removed before the first sample [Ah] (0 = the curve
        starts full; a flight that starts part-discharged has more).
    rest_voltage_V : float or None
        Pack voltage at rest (i = 0) just before the load step, at full charge of
        this curve; separates E0 from R when present.
    meta : dict
        Source metadata (file, format, ...).
    """

    time_s: np.ndarray
    voltage_V: np.ndarray
    current_A: np.ndarray
    name: str = ""
    rest_voltage_V: float | None = None
    meta: dict = field(default_factory=dict)
    temperature_C: np.ndarray | None = None
    initial_charge_Ah: float = 0.0

    def __post_init__(self):
        self.time_s = np.asarray(self.time_s, dtype=float)
        self.voltage_V = np.asarray(self.voltage_V, dtype=float)
        current = np.asarray(self.current_A, dtype=float)
        if current.ndim == 0:
            current = np.full(self.time_s.shape, float(current))
        self.current_A = current
        label = f"curve {self.name!r}" if self.name else "curve"
        if not (self.time_s.shape == self.voltage_V.shape == self.current_A.shape):
            raise DataError(f"{label}: time, voltage and current lengths differ "
                            f"({self.time_s.size}, {self.voltage_V.size}, {self.current_A.size})")
        if self.time_s.size < 10:
            raise DataError(f"{label}: only {self.time_s.size} samples; a fit needs at least 10")
        for column, values in (("time_s", self.time_s), ("voltage_V", self.voltage_V),
                               ("current_A", self.current_A)):
            bad = ~np.isfinite(values)
            if bad.any():
                raise DataError(f"{label}: {bad.sum()} NaN/inf values in {column} (first at "
                                f"sample {int(np.argmax(bad))}); clean the file or let the "
                                f"reader drop them")
        back = np.flatnonzero(np.diff(self.time_s) <= 0)
        if back.size:
            k = int(back[0]) + 1
            raise DataError(f"{label}: time does not increase at sample {k} "
                            f"({self.time_s[k - 1]:g} s -> {self.time_s[k]:g} s)")
        if np.median(self.current_A) <= 0:
            raise DataError(f"{label}: the current is not a discharge (median "
                            f"{np.median(self.current_A):g} A); discharge must be positive "
                            f"(use --sign to flip it, or --current A for files without one)")
        if self.rest_voltage_V is not None and not np.isfinite(self.rest_voltage_V):
            self.rest_voltage_V = None
        if self.temperature_C is not None:
            temp = np.asarray(self.temperature_C, dtype=float)
            ok = temp.shape == self.time_s.shape and np.all(np.isfinite(temp)) and \
                np.all((temp > -60) & (temp < 150))
            self.temperature_C = temp if ok else None

    @classmethod
    def from_frame(cls, data, meta: dict | None = None, name: str = "") -> Curve:
        """Build from a canonical DataFrame (``time_s``, ``voltage_V``, ``current_A``)
        and the reader's meta (see :meth:`dischargelab.Discharge.from_frame`)."""
        meta = dict(meta or {})
        label = name or str(meta.get("name") or meta.get("source", ""))
        return Discharge.from_frame(data, meta, name=label).to_curve()

    @property
    def mean_current_A(self) -> float:
        """Time-averaged current [A]."""
        duration = self.time_s[-1] - self.time_s[0]
        return float(np.trapezoid(self.current_A, self.time_s) / duration)

    @property
    def ambient_C(self) -> float | None:
        """Cell temperature at the start [degC] (the ambient of a test from rest)."""
        return None if self.temperature_C is None else float(self.temperature_C[0])

    @property
    def charge_Ah(self) -> np.ndarray:
        """Discharged charge from the first sample [Ah] (computed once)."""
        if getattr(self, "_charge", None) is None:
            self._charge = charge_from_current(self.time_s, self.current_A)
        return self._charge
