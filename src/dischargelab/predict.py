"""Predict a constant-current or constant-power discharge with its 95 % interval.

:func:`predict` is what ``dischargelab predict`` and ``Battery.predict`` run: the
simulation (any model family, one engine), the interval from the stored
parameter draws plus the model's own error (:mod:`dischargelab.uncertainty`), and
the extrapolation warning — the same everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .cell import CUTOFF_CELL_VOLTAGE_V
from .errors import SimulationError
from .formatting import duration
from .simulate import require_battery

if TYPE_CHECKING:
    from .model import Battery


@dataclass
class Prediction:
    """A predicted discharge: the simulation, its interval and warnings.

    ``to_dict()`` is exactly the ``predict --json`` document (``time_to_cutoff_s``,
    ``capacity_Ah``, ``energy_Wh``, ``interval95``, ``warnings``, ...).
    """

    simulation: object
    interval: dict | None
    warnings: list = field(default_factory=list)
    sensitivity: dict | None = None
    #: The one extra run that would narrow the interval most
    #: (:func:`dischargelab.nexttest.next_test`), or None.
    next_test: dict | None = None

    @property
    def time_to_cutoff_s(self) -> float:
        """Time to the cutoff [s]."""
        return self.simulation.time_to_cutoff_s

    def to_dict(self) -> dict:
        out = self.simulation.to_dict()
        if self.interval is not None:
            out["interval95"] = {key: list(self.interval[key]) for key in
                                 ("time_to_cutoff_s", "capacity_Ah", "energy_Wh")
                                 if key in self.interval}
            for key, value in self.interval.items():
                if key not in ("time_to_cutoff_s", "capacity_Ah", "energy_Wh"):
                    out["interval95"][key] = value
            if "draws" in self.interval and "failed" in self.interval:
                out["interval95"]["bootstrap_draws"] = (self.interval["draws"]
                                                        - self.interval["failed"])
        if self.sensitivity is not None:
            out["beta_sensitivity"] = dict(self.sensitivity)
        if self.next_test is not None:
            out["next_test"] = dict(self.next_test)
        out["warnings"] = list(self.warnings)
        return out

    def to_pandas(self):
        """Time series of the predicted discharge."""
        return self.simulation.to_pandas()

    def plot(self, ax=None, **kwargs):
        """Voltage against time with the cutoff line; returns the Axes."""
        ax = self.simulation.plot(ax=ax, **kwargs)
        sim = self.simulation
        ax.axhline(sim.cutoff_pack_V, color="0.4", ls="--", lw=0.8)
        ax.set_title(f"{sim.steps[0].describe()}: {duration(sim.time_to_cutoff_s)} to "
                     f"{sim.cutoff_pack_V:.2f} V", fontsize=10)
        if sim.peak_temperature_C is not None:
            self._plot_temperature(ax, kwargs.get("x", "time"))
        return ax

    def _plot_temperature(self, ax, x: str):
        """Predicted cell temperature on a second axis, its peak with the 95 % interval."""
        import numpy as np

        from .plot import _xvalues

        sim = self.simulation
        xs = _xvalues(sim.charge_Ah, sim.time_s, x)
        twin = ax.twinx()
        temp = np.asarray(sim.temperature_C, dtype=float)
        twin.plot(xs, temp, color="tab:red", lw=1.0, label="cell temperature")
        k = int(np.nanargmax(temp))
        band = (self.interval or {}).get("peak_temperature_C")
        if band is not None:
            twin.errorbar([xs[k]], [temp[k]], yerr=[[temp[k] - band[0]], [band[1] - temp[k]]],
                          color="tab:red", capsize=4, fmt="o", ms=3,
                          label=f"peak {temp[k]:.1f} degC [95 %: {band[0]:.1f} to "
                                f"{band[1]:.1f}]")
        twin.set_ylabel("cell temperature [degC]", color="tab:red")
        twin.legend(fontsize=8, loc="upper right")
        return twin


def predict(battery: Battery, *, current: float | None = None, c_rate: float | None = None,
            power: float | None = None, cutoff: float | None = None,
            cutoff_pack: float | None = None, soc: float = 100.0, ambient: float | None = None,
            interval: bool = True) -> Prediction:
    """Constant-current or constant-power discharge until the cutoff.

    Parameters
    ----------
    battery : Battery
        From :func:`dischargelab.load` (:func:`dischargelab.api.predict` also takes a
        battery file or a preset name).
    current : float, optional
        Constant pack current [A].
    c_rate : float, optional
        Current as a multiple of the rated pack capacity [1/h].
    power : float, optional
        Constant pack power [W]. Give exactly one of current, c_rate, power.
    cutoff, cutoff_pack : float, optional
        Cutoff per cell or per pack [V]; default the chemistry's usual cutoff.
    soc : float
        State of charge at the start [%] (100 = full).
    ambient : float, optional
        Ambient temperature [degC] (thermal families; default the fitted data's).
    interval : bool
        Add the 95 % interval (parameter draws plus model error).

    Returns
    -------
    Prediction
    """
    from .nexttest import next_test
    from .simulate import simulate_current, simulate_power
    from .uncertainty import simulation_interval

    require_battery(battery)
    bat: Battery = battery
    chosen = [x is not None for x in (current, c_rate, power)]
    if sum(chosen) != 1:
        raise SimulationError("give exactly one load: current (A), c_rate or power (W)")
    cut = default_cutoff(bat, cutoff, cutoff_pack)
    if not 0 < soc <= 100:
        raise SimulationError(f"soc must be in (0, 100] %, got {soc}")
    q0 = (1.0 - soc / 100.0) * bat.capacity_Ah
    if power is not None:
        def run(b):
            return simulate_power(b, power, initial_charge_Ah=q0, ambient_C=ambient, **cut)
    else:
        amps = current if current is not None else c_rate * bat.rated_capacity_Ah

        def run(b):
            return simulate_current(b, amps, initial_charge_Ah=q0, ambient_C=ambient, **cut)
    sim = run(bat)
    spread = simulation_interval(bat, run) if interval else None
    sensitivity = beta_sensitivity(bat, run, sim.time_to_cutoff_s)
    warnings = []
    cell_current = float(sim.current_A[0]) / bat.strings_parallel
    side = bat.extrapolation(cell_current)
    if side:
        warnings.append(extrapolation_warning(bat, cell_current, side))
    advice = None
    if spread is not None and spread.get("time_to_cutoff_s") and sim.time_to_cutoff_s > 0:
        lo, hi = spread["time_to_cutoff_s"]
        now = 100.0 * (hi - lo) / 2.0 / sim.time_to_cutoff_s
        mean_cell = sim.capacity_Ah * 3600.0 / sim.duration_s / bat.strings_parallel \
            if sim.duration_s > 0 else cell_current
        advice = next_test(bat, mean_cell, now)
    return Prediction(sim, spread, warnings, sensitivity, advice)


#: Arrhenius coefficients [K] tried when the fit held beta at its prior (E_a ~ 12-33 kJ/mol).
BETA_ALTERNATIVES_K = (1500.0, 4000.0)


def beta_sensitivity(battery: Battery, run, time_s: float) -> dict | None:
    """Time to cutoff [s] with other Arrhenius coefficients, when the fit held beta at a prior.

    From one rate the temperature dependence of R and K is not identifiable, so
    the prediction's dependence on that prior is reported next to it.
    """
    from dataclasses import replace

    fixed = battery.extra.get("fixed") if isinstance(battery.extra, dict) else None
    if "beta_K" not in battery.parameter_names or not isinstance(fixed, dict) or \
            "beta_K" not in fixed:
        return None
    out = {"prior_beta_K": float(battery.parameters["beta_K"])}
    for beta in BETA_ALTERNATIVES_K:
        other = replace(battery, parameters=battery.parameters.replace(beta_K=beta))
        try:
            t = run(other).time_to_cutoff_s
        except SimulationError:
            t = float("nan")
        out[f"time_to_cutoff_s_beta_{beta:.0f}K"] = t
        out[f"change_pct_beta_{beta:.0f}K"] = 100.0 * (t - time_s) / time_s
    return out


def extrapolation_warning(battery: Battery, cell_current_A: float, side: str,
                          interval_ratio: float | None = None) -> str:
    """The one wording of the extrapolation warning (predict, curves, endurance).

    ``interval_ratio``: the ratio the interval was widened with when it is not this
    current's own (a mission's, weighted over its phases), so that the warning and the
    interval name the same number.
    """
    from .formatting import ratio

    fitted = ", ".join(f"{x:.3g}" for x in battery.fit_currents_A)
    if interval_ratio is None:
        widens = (f"the interval widens with the extrapolation ratio "
                  f"({ratio(battery.extrapolation_ratio(cell_current_A))})")
    else:
        widens = (f"the interval widens with the mission's extrapolation ratio "
                  f"({ratio(interval_ratio)}, its phases' ratios weighted by the charge they "
                  f"draw)")
    return (f"extrapolation: {cell_current_A:.3g} A per cell is far {side} the fitted currents "
            f"({fitted} A); {widens}; check with validate")


def default_cutoff(battery: Battery, cutoff=None, cutoff_pack=None) -> dict:
    """Cutoff keywords for the simulators: the given one, else the chemistry's usual one."""

    if cutoff is not None and cutoff_pack is not None:
        raise SimulationError("give one cutoff: per cell (cutoff) or per pack (cutoff_pack)")
    if cutoff_pack is not None:
        return {"cutoff_pack_V": float(cutoff_pack)}
    if cutoff is not None:
        return {"cutoff_cell_V": float(cutoff)}
    if battery.chemistry in CUTOFF_CELL_VOLTAGE_V:
        return {"cutoff_cell_V": CUTOFF_CELL_VOLTAGE_V[battery.chemistry]}
    tested = tested_cutoff(battery)
    if tested is not None:
        return {"cutoff_cell_V": tested}
    raise SimulationError("give a cutoff voltage (per cell, e.g. 3.0 for LiPo, 2.5 for Li-ion); "
                          "the battery's chemistry is not known and its fitted runs did not "
                          "all stop at one voltage")


def tested_cutoff(battery: Battery) -> float | None:
    """The voltage per cell [V] every fitted run stopped at, as its battery file records it
    (``tested_cutoff_cell_V``), or None."""
    value = (battery.extra or {}).get("tested_cutoff_cell_V")
    try:
        return float(value) if value is not None and float(value) > 0 else None
    except (TypeError, ValueError):
        return None
