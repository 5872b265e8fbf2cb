"""Cutoff and over-temperature watch for a running discharge test.

A pipeline :class:`~dischargelab.acquire.pipeline.Consumer`: every sample is
compared with the limits. One noisy sample does not end a test: a limit trips
after ``debounce_samples`` CONSECUTIVE samples beyond it. It cannot be skipped
either: any sample beyond the limit starts the count, only a sample back inside
resets it, and a trip calls the ``on_trip`` callback exactly once (the
pipeline then records the event, switches the load off and stops).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from ..errors import DataError
from ..model import CUTOFF_CELL_VOLTAGE_V

#: Highest cell voltage when full [V], used to infer the cell count from the pack voltage.
FULL_CELL_VOLTAGE_V = {"lipo": 4.2, "li-ion": 4.2, "lifepo4": 3.65}

#: Default over-temperature limit [degC] (common LiPo/Li-ion discharge maximum is 60 degC).
DEFAULT_MAX_TEMPERATURE_C = 60.0


@dataclass(frozen=True)
class SafetyLimits:
    """Limits of one test.

    Attributes
    ----------
    cells_series : int
    cutoff_cell_V : float
        Per-cell cutoff voltage [V].
    max_temperature_C : float or None
        Over-temperature limit [degC]; only checked when a sensor is present.
    debounce_samples : int
        Consecutive samples beyond a limit needed to trip.
    chemistry : str or None
    """

    cells_series: int
    cutoff_cell_V: float
    max_temperature_C: float | None = DEFAULT_MAX_TEMPERATURE_C
    debounce_samples: int = 3
    chemistry: str | None = None

    def __post_init__(self):
        if self.cells_series < 1:
            raise DataError(f"cells must be >= 1, got {self.cells_series}")
        if not (math.isfinite(self.cutoff_cell_V) and 0 < self.cutoff_cell_V < 5):
            raise DataError(f"cutoff per cell must be between 0 and 5 V, got {self.cutoff_cell_V}")
        if self.debounce_samples < 1:
            raise DataError(f"debounce must be >= 1 sample, got {self.debounce_samples}")

    @property
    def cutoff_pack_V(self) -> float:
        """Pack cutoff voltage [V] = cells x per-cell cutoff."""
        return self.cells_series * self.cutoff_cell_V

    @classmethod
    def for_chemistry(cls, chemistry: str, cells_series: int, *,
                      cutoff_cell_V: float | None = None,
                      max_temperature_C: float | None = DEFAULT_MAX_TEMPERATURE_C,
                      debounce_samples: int = 3) -> SafetyLimits:
        """Limits from a chemistry preset (:data:`dischargelab.model.CUTOFF_CELL_VOLTAGE_V`),
        with an optional per-cell cutoff override."""
        key = chemistry.lower()
        if key not in CUTOFF_CELL_VOLTAGE_V:
            raise DataError(f"unknown chemistry {chemistry!r}; use one of "
                            f"{', '.join(CUTOFF_CELL_VOLTAGE_V)}")
        cutoff = CUTOFF_CELL_VOLTAGE_V[key] if cutoff_cell_V is None else float(cutoff_cell_V)
        return cls(int(cells_series), cutoff, max_temperature_C, int(debounce_samples), key)

    def to_dict(self) -> dict:
        return {"cells_series": self.cells_series, "cutoff_cell_V": self.cutoff_cell_V,
                "cutoff_pack_V": self.cutoff_pack_V, "max_temperature_C": self.max_temperature_C,
                "debounce_samples": self.debounce_samples, "chemistry": self.chemistry}


def infer_cells(pack_voltage_V: float, chemistry: str) -> int:
    """Series cell count of a pack from its voltage: ``ceil(V / full-cell voltage)``.

    Right while every cell is above ``full * (n - 1) / n`` (e.g. 3.15 V for a
    4S LiPo); pass the count explicitly to be sure.
    """
    full = FULL_CELL_VOLTAGE_V[chemistry.lower()]
    if not (math.isfinite(pack_voltage_V) and pack_voltage_V > 0.5):
        raise DataError(f"cannot infer the cell count from {pack_voltage_V:.3f} V; give --cells")
    return max(1, math.ceil(pack_voltage_V / full - 1e-9))


class SafetyMonitor:
    """Trip on a sustained cutoff or over-temperature (a pipeline Consumer).

    Parameters
    ----------
    limits : SafetyLimits
    on_trip : callable(kind, message, fields)
        Called once, from the consumer thread, with kind ``"cutoff"`` or
        ``"over-temperature"``.
    """

    def __init__(self, limits: SafetyLimits, on_trip: Callable[[str, str, dict], None]):
        self.limits = limits
        self.on_trip = on_trip
        self.below = 0
        self.hot = 0
        self.tripped: str | None = None
        self.message = ""
        self.min_voltage_V = math.inf

    @property
    def pending(self) -> str:
        """Short text while a limit is being debounced ('' otherwise)."""
        n = self.limits.debounce_samples
        if self.tripped:
            return self.tripped
        if self.below:
            return f"below cutoff {self.below}/{n}"
        if self.hot:
            return f"over temperature {self.hot}/{n}"
        return ""

    def handle(self, sample) -> None:
        if self.tripped:
            return
        lim = self.limits
        v = sample.voltage_V
        self.min_voltage_V = min(self.min_voltage_V, v)
        self.below = self.below + 1 if not v > lim.cutoff_pack_V else 0   # NaN counts as below
        t = sample.temperature_C
        if lim.max_temperature_C is not None and t is not None:
            self.hot = self.hot + 1 if t >= lim.max_temperature_C else 0
        if self.below >= lim.debounce_samples:
            self._trip("cutoff", (
                f"CUTOFF: pack {v:.3f} V below {lim.cutoff_pack_V:.3f} V "
                f"({lim.cells_series} x {lim.cutoff_cell_V:g} V/cell) for {self.below} consecutive "
                f"samples at t = {sample.time_s:.1f} s"),
                {"time_s": sample.time_s, "voltage_V": v, "cell_V": v / lim.cells_series,
                 "cutoff_pack_V": lim.cutoff_pack_V, "samples_below": self.below})
        elif lim.max_temperature_C is not None and self.hot >= lim.debounce_samples:
            self._trip("over-temperature", (
                f"OVER-TEMPERATURE: {t:.1f} degC at or above {lim.max_temperature_C:g} degC for "
                f"{self.hot} consecutive samples at t = {sample.time_s:.1f} s"),
                {"time_s": sample.time_s, "temperature_C": t, "voltage_V": v,
                 "max_temperature_C": lim.max_temperature_C})

    def _trip(self, kind: str, message: str, fields: dict) -> None:
        self.tripped = kind
        self.message = message
        self.on_trip(kind, message, fields)

    def event(self, kind: str, **fields) -> None:
        pass

    def close(self) -> None:
        pass
