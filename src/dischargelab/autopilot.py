"""Battery settings for ArduPilot and PX4 derived from a fitted battery model.

:func:`autopilot_params` flies the model at a stated load (the pack current the
vehicle draws in normal flight, e.g. hover) and reads off the voltages at which
a given reserve of flight time remains; every value carries a comment saying
how it was derived. :meth:`AutopilotParams.write` writes the firmware's own
parameter-file format: ArduPilot ``.param`` (``NAME,VALUE`` lines, ``#``
comments, as Mission Planner and MAVProxy load them) or PX4/QGroundControl
``.params`` (tab-separated ``vehicle component name value type`` lines, type 6
for INT32 and 9 for REAL32).

Voltages that the firmware compares with a *resting* (load-compensated)
voltage are model rest voltages (zero current, every other state at rest):
ArduPilot with ``BATT_FS_VOLTSRC = 1`` (sag compensated) and PX4 with
``BAT1_R_INTERNAL`` set (the voltage plus internal resistance times current).

References
----------
.. [1] ArduPilot parameter reference: BATT_CAPACITY [mAh], BATT_LOW_VOLT,
   BATT_CRT_VOLT, BATT_ARM_VOLT [V], BATT_FS_VOLTSRC, MOT_BAT_VOLT_MAX,
   MOT_BAT_VOLT_MIN [V] ("recommend 4.2 x cells" / "3.3 x cells").
.. [2] PX4 parameter reference: BAT1_N_CELLS, BAT1_V_EMPTY, BAT1_V_CHARGED
   [V per cell], BAT1_R_INTERNAL [ohm per cell], BAT1_CAPACITY [mAh].
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import SimulationError
from .formatting import duration
from .model import Battery, load_battery

FIRMWARES = ("ardupilot", "px4")

#: Default flight-time reserve at the low-voltage warning [s].
DEFAULT_RESERVE_S = 120.0


def wrap_comment(text: str, width: int = 96) -> list[str]:
    """``text`` cut at spaces into lines of at most ``width`` characters (comment lines)."""
    import textwrap

    return textwrap.wrap(text, width, break_long_words=False, break_on_hyphens=False) or [""]


@dataclass(frozen=True)
class Setting:
    """One parameter: name, value, unit, firmware type and how it was derived."""

    name: str
    value: float
    unit: str
    comment: str
    integer: bool = False

    def text(self) -> str:
        """The value as the parameter file shows it."""
        return str(int(round(self.value))) if self.integer else f"{self.value:.3f}".rstrip(
            "0").rstrip(".")


@dataclass
class AutopilotParams:
    """Derived settings for one firmware; ``write(path)`` writes its parameter file."""

    firmware: str
    settings: list[Setting]
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"firmware": self.firmware,
                "parameters": {s.name: (int(round(s.value)) if s.integer else s.value)
                               for s in self.settings},
                "units": {s.name: s.unit for s in self.settings},
                "derivation": {s.name: s.comment for s in self.settings},
                "notes": list(self.notes)}

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame([{"name": s.name, "value": s.value, "unit": s.unit,
                              "derivation": s.comment} for s in self.settings])

    def text(self) -> str:
        """The parameter file's content (comment lines of at most 100 characters)."""
        def comment(text: str) -> list[str]:
            wrapped = wrap_comment(text, 96)
            return [f"# {wrapped[0]}"] + [f"#   {line}" for line in wrapped[1:]]

        lines = [f"# Battery settings for {self.firmware} derived by dischargelab"]
        for n in self.notes:
            lines += comment(n)
        if self.firmware == "px4":
            lines += ["#", "# Vehicle-Id Component-Id Name Value Type"]
            for s in self.settings:
                lines += comment(f"{s.name}: {s.comment}")
                lines.append(f"1\t1\t{s.name}\t{s.text()}\t{6 if s.integer else 9}")
        else:
            for s in self.settings:
                unit = f" [{s.unit}]" if s.unit else ""
                lines += comment(f"{s.name}{unit}: {s.comment}")
                lines.append(f"{s.name},{s.text()}")
        return "\n".join(lines) + "\n"

    def write(self, path, *, force: bool = False) -> Path:
        """Write the parameter file atomically; refuses to replace a file unless ``force``."""
        from .atomic import check_outputs, write_text

        check_outputs([path], force=force)
        return write_text(path, self.text())


def checked_pack(battery, cells: int | None, reserve_s: float):
    """The battery (loaded) and the flight pack's cells in series, after the checks every
    autopilot file shares: at least one cell, a positive reserve time [s]."""
    battery = load_battery(battery)
    cells = battery.cells_series if cells is None else int(cells)
    if cells < 1:
        raise SimulationError(f"cells must be at least 1, got {cells}")
    if not reserve_s > 0:
        raise SimulationError(f"reserve_s must be a positive time [s], got {reserve_s}")
    return battery, cells


def autopilot_params(battery, *, firmware: str, cells: int | None = None,
                     parallel: int | None = None,
                     load_current_A: float | None = None, reserve_s: float = DEFAULT_RESERVE_S,
                     critical_reserve_s: float | None = None, cutoff: float | None = None,
                     ambient: float | None = None, load_source: str | None = None,
                     instance: int = 0) -> AutopilotParams:
    """Battery settings for ``firmware`` from the battery model.

    Parameters
    ----------
    battery : Battery, preset name, battery-file path or logbook pack
        The cell model (its pack configuration is replaced by ``cells``/``parallel``);
        a logbook pack (:meth:`dischargelab.Logbook.pack`) gives its model at today's
        capacity and resistance, and the notes say which events those come from.
    firmware : {"ardupilot", "px4"}
    cells : int, optional
        Cells in series of the flight pack (default: the battery's).
    parallel : int, optional
        Strings in parallel (default: as in the battery file).
    load_current_A : float, optional
        Pack current [A] of normal flight (hover/cruise) at which the reserve is
        computed; default 1C of the pack's rated capacity.
    reserve_s : float
        Flight time [s] left at that load when the low-voltage warning fires.
    critical_reserve_s : float, optional
        Flight time [s] left at the critical level (default a third of ``reserve_s``).
    cutoff : float, optional
        Loaded cell voltage [V] at which the pack counts as empty (default by chemistry).
    ambient : float, optional
        Ambient temperature [degC] for thermal models.
    load_source : str, optional
        What ``load_current_A`` is (e.g. "the median mean current of the pack's 12 logged
        flights"), said in the notes.
    instance : int
        ArduPilot battery instance (0 = the first monitor); ``BATT_SOC1_IDX`` is
        ``instance + 1``, as the applet counts monitors from 1 (0 switches it off).

    Returns
    -------
    AutopilotParams

    Notes
    -----
    For ArduPilot the settings include ``BATT_SOC1_C1..C4`` (with ``BATT_SOC_COUNT``,
    ``BATT_SOC1_IDX``, ``BATT_SOC1_NCELL``) of ArduPilot's ``BattEstimate.lua`` applet,
    fitted to the model's open-circuit curve (:func:`battestimate_coefficients`).
    """
    from .predict import default_cutoff
    from .simulate import simulate_current

    if firmware not in FIRMWARES:
        raise SimulationError(f"firmware must be one of {', '.join(FIRMWARES)}, got {firmware!r}")
    battery, cells = checked_pack(battery, cells, reserve_s)
    critical = reserve_s / 3.0 if critical_reserve_s is None else float(critical_reserve_s)
    if not 0 < critical < reserve_s:
        raise SimulationError("critical_reserve_s must be between 0 and reserve_s")
    bat: Battery = battery.with_pack(cells, parallel)
    cut = default_cutoff(bat, cutoff)["cutoff_cell_V"]
    capacity_mAh = bat.rated_capacity_Ah * 1000.0
    load = bat.rated_capacity_Ah if load_current_A is None else float(load_current_A)
    if not load > 0:
        raise SimulationError(f"load_current_A must be a positive pack current, got {load}")
    sim = simulate_current(bat, load, cutoff_cell_V=cut, ambient_C=ambient)
    total = sim.time_to_cutoff_s
    if not total > reserve_s:
        raise SimulationError(f"at {load:g} A the pack reaches {cut:g} V/cell after {total:.0f} s, "
                              f"less than the {reserve_s:g} s reserve; lower the load or reserve")

    def rest_at(t_s):
        q = float(np.interp(t_s, sim.time_s, sim.charge_Ah))
        return float(bat.voltage(0.0, q, temperature_C=ambient))

    def loaded_at(t_s):
        return float(np.interp(t_s, sim.time_s, sim.voltage_V))

    full_rest = float(bat.voltage(0.0, 0.0, temperature_C=ambient))
    empty_rest = rest_at(total)
    low_rest, crit_rest = rest_at(total - reserve_s), rest_at(total - critical)
    # resistance per series element at half charge: DC drop at the load / load
    q_half = 0.5 * float(sim.charge_Ah[-1])
    r_pack = (float(bat.voltage(0.0, q_half, temperature_C=ambient))
              - float(bat.voltage(load, q_half, temperature_C=ambient))) / load
    r_cell = r_pack / cells
    amps = f"{load:.3g} A"
    how = (f"{bat.model} model, {cells}S{bat.strings_parallel}P, at {amps} "
           f"({load / bat.rated_capacity_Ah:.2g}C): {duration(total)} to {cut:g} V/cell")
    today = bool(bat.extra.get("logbook"))
    basis = "today's capacity estimate of the logbook pack" if today else bat.capacity_basis
    source = load_source or (f"1C of {basis}" if load_current_A is None
                             else "the given load")
    notes = [how, f"load {amps}: {source}",
             f"reserve {reserve_s:g} s at the low level, {critical:.0f} s at the critical level"]
    if today and bat.extra.get("note"):  # a logbook pack, today
        notes.append(str(bat.extra["note"]))
    if firmware == "ardupilot":
        capacity_how = basis
        coefficients, worst = battestimate_coefficients(bat, ambient)
        settings = [
            Setting("BATT_CAPACITY", capacity_mAh, "mAh", capacity_how, True),
            Setting("BATT_FS_VOLTSRC", 1, "", "compare failsafe voltages with the sag-compensated "
                    "(resting) voltage, so load peaks do not trigger false failsafes", True),
            Setting("BATT_LOW_VOLT", low_rest, "V", f"resting pack voltage when {reserve_s:g} s "
                    f"of flight at {amps} remain"),
            Setting("BATT_CRT_VOLT", crit_rest, "V", f"resting pack voltage when {critical:.0f} s "
                    f"of flight at {amps} remain"),
            Setting("BATT_ARM_VOLT", rest_at(max(total - 3.0 * reserve_s, 0.0)), "V",
                    f"resting pack voltage with three reserves ({3 * reserve_s:g} s) of flight "
                    "left: refuse to arm below it"),
            Setting("MOT_BAT_VOLT_MAX", full_rest, "V", "resting pack voltage when full (thrust "
                    "scaling upper limit)"),
            Setting("MOT_BAT_VOLT_MIN", cut * cells, "V", f"loaded pack voltage when empty "
                    f"({cut:g} V/cell x {cells}; thrust scaling lower limit)"),
            Setting("BATT_SOC_COUNT", 1, "", "one BattEstimate.lua estimator (ArduPilot's "
                    "applet: state of charge from the resting voltage before take-off)", True),
            Setting("BATT_SOC1_IDX", instance + 1, "", "battery monitor of the estimator, "
                    "counted from 1 (1 = the first; 0 switches it off)", True),
            Setting("BATT_SOC1_NCELL", cells, "", "cells in series", True),
        ]
        fit_how = (f"soc = C1*(1 - 1/(1 + (V/C2)^C4)^C3) fitted to the model's open-circuit "
                   f"curve: worst difference {worst:.1f} % of charge")
        settings += [Setting(f"BATT_SOC1_C{k + 1}", c, "", fit_how if k == 0 else
                             f"see BATT_SOC1_C1 (bounds {lo:g} to {hi:g})")
                     for k, (c, (lo, hi)) in enumerate(zip(coefficients, SOC_BOUNDS))]
    else:
        settings = [
            Setting("BAT1_N_CELLS", cells, "", "cells in series", True),
            Setting("BAT1_CAPACITY", capacity_mAh, "mAh",
                    basis),
            Setting("BAT1_V_CHARGED", full_rest / cells, "V", "resting cell voltage when full"),
            Setting("BAT1_V_EMPTY", empty_rest / cells, "V", f"resting cell voltage when the "
                    f"pack reaches {cut:g} V/cell under {amps} (load-compensated with "
                    "BAT1_R_INTERNAL)"),
            Setting("BAT1_R_INTERNAL", r_cell, "ohm", f"DC resistance per series cell at half "
                    f"charge and {amps} ({r_pack * 1000:.1f} mOhm for the pack)"),
        ]
        notes.append(f"low/critical thresholds (BAT_LOW_THR/BAT_CRIT_THR) as charge fractions: "
                     f"{reserve_s * load / 3600 / (bat.rated_capacity_Ah):.3f} / "
                     f"{critical * load / 3600 / (bat.rated_capacity_Ah):.3f}")
    return AutopilotParams(firmware, settings, notes)


#: Bounds of BattEstimate.lua's coefficients C1..C4 (ArduPilot's parameter ranges).
SOC_BOUNDS = ((100.0, 200.0), (2.0, 5.0), (0.01, 0.5), (5.0, 100.0))


def _soc_formula(coefficients, cell_V):
    c1, c2, c3, c4 = coefficients
    with np.errstate(over="ignore", invalid="ignore"):
        return c1 * (1.0 - 1.0 / (1.0 + (cell_V / c2) ** c4) ** c3)


def battestimate_coefficients(battery: Battery, ambient: float | None = None):
    """``BATT_SOC1_C1..C4`` of ArduPilot's ``BattEstimate.lua`` for the model's own
    open-circuit curve, and the worst difference [% of charge] over it.

    The applet's state of charge [%] from the resting cell voltage ``V`` is
    ``C1*(1 - 1/(1 + (V/C2)^C4)^C3)`` (ArduPilot ``libraries/AP_Scripting/applets/
    BattEstimate.lua``, coefficients from ``Tools/scripts/battery_fit.py``); it is fitted
    here by bounded least squares (scipy ``least_squares``, trust-region reflective) to the
    model's rest voltage per cell against its state of charge ``1 - q / capacity``, from
    full to 2 % left, within ArduPilot's parameter ranges.
    """
    from scipy.optimize import least_squares

    cap = battery.capacity_Ah
    q = np.linspace(0.0, 0.98 * cap, 60)
    with np.errstate(invalid="ignore", over="ignore"):
        cell = np.asarray(battery.voltage(np.zeros_like(q), q, temperature_C=ambient),
                          dtype=float) / battery.cells_series
    soc = 100.0 * (1.0 - q / cap)
    ok = np.isfinite(cell)
    cell, soc = cell[ok], soc[ok]
    if cell.size < 5:
        raise SimulationError("the model's open-circuit curve cannot be evaluated")
    lower = np.array([b[0] for b in SOC_BOUNDS])
    upper = np.array([b[1] for b in SOC_BOUNDS])

    def residual(c):
        r = _soc_formula(c, cell) - soc
        return np.where(np.isfinite(r), r, 1e3)

    best = None
    for c2 in (0.85 * float(np.median(cell)), 0.95 * float(np.median(cell))):
        for c4 in (20.0, 60.0):   # a few starts: the formula has flat directions
            start = np.clip([105.0, c2, 0.1, c4], lower, upper)
            sol = least_squares(residual, start, bounds=(lower, upper), max_nfev=2000)
            if best is None or sol.cost < best.cost:
                best = sol
    worst = float(np.max(np.abs(residual(best.x))))
    return [float(c) for c in best.x], worst


__all__ = ["autopilot_params", "AutopilotParams", "Setting", "FIRMWARES",
           "battestimate_coefficients", "wrap_comment"]
