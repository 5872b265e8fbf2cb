"""Simulate a battery under a load: constant current, constant power, or a profile of steps.

Loads are given as data (PyBaMM-style experiment steps)::

    simulate(battery, [Step("current", 20.0, 60.0, "climb"), Step("power", 250.0, None, "cruise")],
             cutoff_cell_V=3.0)

Sign convention: current and power are positive on discharge; all arrays are
pack-level (pack current, pack voltage, pack charge). A step without a duration
runs until the cutoff. The time to cutoff is found by root finding on the
one engine (:mod:`dischargelab.engine`) for every model family: the stop is
located by bisection inside the last time step, never by scanning a grid.
Thermal families simulate the cell temperature from ``ambient_C``.

References
----------
.. [1] paper eq. (6) and Figs 5, 7, 10 (see ``../shared/paper``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from . import engine
from .engine import Step
from .errors import SimulationError

if TYPE_CHECKING:
    from .model import Battery

def require_battery(battery) -> None:
    """Raise a clear error unless ``battery`` is a loaded battery model.

    The simulation layer takes :class:`dischargelab.model.Battery` objects only;
    :func:`dischargelab.load` turns a battery file or a preset name into one.
    """
    if not (hasattr(battery, "family") and hasattr(battery, "parameters")
            and hasattr(battery, "cells_series")):
        raise SimulationError(f"battery must be a Battery (dischargelab.load(path_or_preset)), "
                              f"not {type(battery).__name__}")


#: Points per simulated step on the output curve.
POINTS_PER_STEP = 100


@dataclass
class SimulationResult:
    """Pack-level time series of a simulation and its summary numbers.

    Arrays: ``time_s``, ``current_A``, ``voltage_V``, ``power_W``, ``charge_Ah``,
    ``energy_Wh`` (cumulative), ``step`` (index into ``steps``).
    Scalars: ``time_to_cutoff_s`` (NaN when the profile ended first),
    ``capacity_Ah`` and ``energy_Wh_total`` delivered, ``ended_by`` in
    {"cutoff", "power limit", "end"}.
    """

    time_s: np.ndarray
    current_A: np.ndarray
    voltage_V: np.ndarray
    power_W: np.ndarray
    charge_Ah: np.ndarray
    energy_Wh: np.ndarray
    step: np.ndarray
    steps: list[Step]
    cutoff_pack_V: float
    ended_by: str
    battery: Battery = field(repr=False)
    initial_charge_Ah: float = 0.0
    temperature_C: np.ndarray | None = None
    ambient_C: float | None = None

    @property
    def peak_temperature_C(self) -> float | None:
        """Highest simulated cell temperature [degC] (None for isothermal families)."""
        if self.temperature_C is None or not self.battery.family.thermal:
            return None
        return float(np.max(self.temperature_C))

    @property
    def duration_s(self) -> float:
        """Simulated time [s]."""
        return float(self.time_s[-1])

    @property
    def time_to_cutoff_s(self) -> float:
        """Time at which the cutoff (or power limit) was reached [s]; NaN if never."""
        return self.duration_s if self.ended_by != "end" else float("nan")

    @property
    def capacity_Ah(self) -> float:
        """Charge delivered during the simulation [Ah]."""
        return float(self.charge_Ah[-1] - self.initial_charge_Ah)

    @property
    def energy_Wh_total(self) -> float:
        """Energy delivered during the simulation [Wh]."""
        return float(self.energy_Wh[-1])

    def to_pandas(self):
        """Time series as a DataFrame with canonical column names."""
        import pandas as pd

        names = [s.name or s.kind for s in self.steps]
        frame = pd.DataFrame({
            "time_s": self.time_s, "current_A": self.current_A, "voltage_V": self.voltage_V,
            "power_W": self.power_W, "charge_Ah": self.charge_Ah, "energy_Wh": self.energy_Wh,
            "step": [names[k] for k in self.step],
        })
        if self.peak_temperature_C is not None:
            frame["temperature_C"] = self.temperature_C
        return frame

    def to_dict(self) -> dict:
        """Summary for JSON output (the ``predict --json`` keys plus ``ended_by``)."""
        out = {}
        if len(self.steps) == 1 and self.steps[0].kind == "current":
            out["current_A"] = self.steps[0].value
        elif len(self.steps) == 1 and self.steps[0].kind == "power":
            out["power_W"] = self.steps[0].value
        out.update({
            "cutoff_V": self.cutoff_pack_V / self.battery.cells_series,
            "cutoff_pack_V": self.cutoff_pack_V,
            "time_to_cutoff_s": self.time_to_cutoff_s,
            "capacity_Ah": self.capacity_Ah,
            "energy_Wh": self.energy_Wh_total,
            "ended_by": self.ended_by,
            "cells_series": self.battery.cells_series,
            "strings_parallel": self.battery.strings_parallel,
            "model": self.battery.model,
        })
        if self.peak_temperature_C is not None:
            out["ambient_C"] = self.ambient_C
            out["peak_temperature_C"] = self.peak_temperature_C
        return out

    def plot(self, ax=None, x: str = "time", **kwargs):
        """Voltage against time (``x="time"``) or charge (``x="charge"``); returns the Axes."""
        from .plot import plot_simulation

        return plot_simulation(self, ax=ax, x=x, **kwargs)


def _cutoff_pack(battery: Battery, cutoff_cell_V, cutoff_pack_V) -> float:
    if (cutoff_cell_V is None) == (cutoff_pack_V is None):
        raise SimulationError("give exactly one cutoff: per cell (cutoff_cell_V / --cutoff) "
                              "or per pack (cutoff_pack_V / --cutoff-pack)")
    value = cutoff_pack_V if cutoff_pack_V is not None else cutoff_cell_V * battery.cells_series
    if not np.isfinite(value) or value <= 0:
        raise SimulationError(f"cutoff voltage must be a positive number, got {value}")
    return float(value)


def simulate(battery, steps, *, cutoff_cell_V: float | None = None,
             cutoff_pack_V: float | None = None, initial_charge_Ah: float = 0.0,
             points_per_step: int = POINTS_PER_STEP, ambient_C: float | None = None,
             reserve_charge_Ah: float | None = None,
             max_step_s: float = engine.MAX_DT_S) -> SimulationResult:
    """Run load steps one after another until the profile ends or the cutoff is reached.

    Parameters
    ----------
    battery : Battery
        From :func:`dischargelab.load` (a battery file or a preset name).
    steps : sequence of Step
    cutoff_cell_V, cutoff_pack_V : float
        Cutoff voltage per cell or per pack [V]; give exactly one.
    initial_charge_Ah : float
        Pack charge already removed at the start [Ah] (0 = full).
    points_per_step : int
        Engine time steps for a step that runs to the cutoff (the time to cutoff
        does not depend on it for isothermal families).
    ambient_C : float, optional
        Ambient temperature [degC] for thermal families (default: the fitted data's).
    reserve_charge_Ah : float, optional
        Stop when this pack charge has been removed [Ah].
    max_step_s : float
        Longest engine time step [s] (see :func:`dischargelab.engine.run`).

    Returns
    -------
    SimulationResult

    Raises
    ------
    SimulationError
        Cutoff at or above the starting voltage, charge beyond the capacity, bad steps.
    """
    require_battery(battery)
    steps = list(steps)
    if not steps:
        raise SimulationError("no load steps to simulate")
    for st in steps:
        if not isinstance(st, Step):
            raise SimulationError(f"steps must be Step objects, got {type(st).__name__}")
    cutoff = _cutoff_pack(battery, cutoff_cell_V, cutoff_pack_V)
    q_max = battery.capacity_Ah
    if not 0 <= initial_charge_Ah < q_max:
        raise SimulationError(f"initial charge removed {initial_charge_Ah:g} Ah must be in "
                              f"[0, {q_max:g}) Ah (the model capacity C x parallel strings)")
    ambient = battery.ambient_C if ambient_C is None else float(ambient_C)
    first_load = next((st for st in steps if st.kind != "rest"), None)
    if first_load is not None:
        v0 = _start_voltage(battery, first_load, initial_charge_Ah, ambient)
        if not v0 > cutoff:
            raise SimulationError(
                f"cutoff {cutoff / battery.cells_series:.3f} V/cell ({cutoff:.3f} V pack) is not "
                f"below the starting voltage {v0 / battery.cells_series:.3f} V/cell under "
                f"'{first_load.describe()}'; lower the cutoff or check the cell count")
    res = engine.run(battery.family, dict(battery.parameters), steps, cutoff_pack_V=cutoff,
                     cells_series=battery.cells_series,
                     strings_parallel=battery.strings_parallel, ambient_C=ambient,
                     initial_charge_Ah=initial_charge_Ah, reserve_charge_Ah=reserve_charge_Ah,
                     record=True, steps_per_discharge=max(int(points_per_step), 50),
                     max_dt_s=max_step_s)
    ser = res.series
    t, i, v = ser["time_s"], ser["current_A"], ser["voltage_V"]
    power = i * v
    return SimulationResult(
        time_s=t, current_A=i, voltage_V=v, power_W=power, charge_Ah=ser["charge_Ah"],
        energy_Wh=_cumulative_energy(t, power), step=ser["step"], steps=steps,
        cutoff_pack_V=cutoff, ended_by=str(res.ended_by[0]), battery=battery,
        initial_charge_Ah=float(initial_charge_Ah), temperature_C=ser["temperature_C"],
        ambient_C=ambient,
    )


def _start_voltage(battery: Battery, step: Step, q0: float, ambient_C: float) -> float:
    """Pack voltage [V] as ``step`` starts from rest with ``q0`` [Ah] removed.

    Raises
    ------
    SimulationError
        The power cannot be delivered at the start.
    """
    current, voltage, max_power = engine.start_load(
        battery.family, dict(battery.parameters), step, charge_Ah=q0, ambient_C=ambient_C,
        cells_series=battery.cells_series, strings_parallel=battery.strings_parallel)
    if not np.isfinite(current):
        raise SimulationError(f"the battery cannot deliver {step.value:g} W: its maximum power "
                              f"at the start is {max_power:.1f} W; lower the power")
    return voltage


def _cumulative_energy(t, p):
    e = np.zeros_like(t)
    if t.size > 1:
        np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(t), out=e[1:])
    return e / 3600.0


def simulate_current(battery, current_A: float, *, cutoff_cell_V: float | None = None,
                     cutoff_pack_V: float | None = None, initial_charge_Ah: float = 0.0,
                     points: int = POINTS_PER_STEP,
                     ambient_C: float | None = None,
                     max_step_s: float = engine.MAX_DT_S) -> SimulationResult:
    """Constant-current discharge [A, pack] until the cutoff (paper Figs 5, 7, 10)."""
    if not current_A > 0:
        raise SimulationError(f"discharge current must be > 0 A, got {current_A}")
    return simulate(battery, [Step("current", float(current_A))], cutoff_cell_V=cutoff_cell_V,
                    cutoff_pack_V=cutoff_pack_V, initial_charge_Ah=initial_charge_Ah,
                    points_per_step=points, ambient_C=ambient_C, max_step_s=max_step_s)


def simulate_power(battery, power_W: float, *, cutoff_cell_V: float | None = None,
                   cutoff_pack_V: float | None = None, initial_charge_Ah: float = 0.0,
                   points: int = POINTS_PER_STEP,
                   ambient_C: float | None = None) -> SimulationResult:
    """Constant-power discharge [W, pack] until the cutoff or the power limit."""
    if not power_W > 0:
        raise SimulationError(f"discharge power must be > 0 W, got {power_W}")
    return simulate(battery, [Step("power", float(power_W))], cutoff_cell_V=cutoff_cell_V,
                    cutoff_pack_V=cutoff_pack_V, initial_charge_Ah=initial_charge_Ah,
                    points_per_step=points, ambient_C=ambient_C)


def curve_family(battery, currents_A=None, *, powers_W=None, cutoff_cell_V=None,
                 cutoff_pack_V=None, ambient_C=None) -> list[SimulationResult]:
    """Constant-current (or constant-power) discharges at several loads (paper Figs 5, 7, 10)."""
    require_battery(battery)
    if (currents_A is None) == (powers_W is None):
        raise SimulationError("give either currents or powers for a curve family")
    kw = dict(cutoff_cell_V=cutoff_cell_V, cutoff_pack_V=cutoff_pack_V, ambient_C=ambient_C)
    if currents_A is not None:
        return [simulate_current(battery, i, **kw) for i in currents_A]
    return [simulate_power(battery, p, **kw) for p in powers_W]
