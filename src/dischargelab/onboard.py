"""The pack's model on board: an ArduPilot Lua script with the model flown into tables.

:func:`autopilot_script` flies the battery model on the ground, at generation,
through the one engine (:mod:`dischargelab.simulate`): one constant-current
discharge to the cutoff per table current. From those runs it keeps small
tables: the charge left to the cutoff against the charge taken out and the
pack current, the loaded pack voltage on the same grid, and the open-circuit
curve. The script (package data ``data/onboard.lua``) only interpolates them:

* disarmed at rest, the charge taken out from the rest voltage through the
  model's open-circuit curve;
* armed, the charge counted from ``battery:consumed_mah`` (or the integrated
  ``battery:current_amps``), and the time left until the loaded voltage reaches
  the cutoff at the recent load (``DL_TREM`` [s]) with the state of charge
  (``DL_SOC`` [%]), sent with ``gcs:send_named_float`` every second. The recent
  load is the mean current of the last 30 s; the pack is empty when its voltage
  at the window's highest 1 s current reaches the cutoff (steps of a stepped
  flight), and the mean current is let grow as the voltage falls, ``I ~ V^-g``,
  with ``g`` measured in flight from the mean current and voltage against those
  of the first full window (0 for a constant current, 1 for a constant-power
  hover; filtered, within [0, 1.2]);
* one ``gcs:send_text`` warning at the reserve and one at a third of it;
* without a current sensor, the charge from the filtered loaded voltage at the
  reference current, said once.

The charge left to the cutoff at a constant current depends on the charge
taken out and the current only (the model's voltage at settled filtered
states), so the constant-current runs give it exactly on their grid; between
grid points the script interpolates linearly. Thermal families are tabulated
at the ambient temperature (the listed bindings give no temperature).

References
----------
.. [1] ArduPilot Lua scripting: bindings ``battery:voltage``, ``current_amps``,
   ``consumed_mah``, ``num_instances``; ``gcs:send_text``,
   ``gcs:send_named_float``; ``arming:is_armed``; ``millis``; parameters
   ``SCR_ENABLE``, ``SCR_HEAP_SIZE``, ``SCR_VM_I_COUNT`` (ardupilot.org,
   "Lua Scripts").
.. [2] Plett, G. L. (2015). Battery Management Systems, Vol. I, ch. 2 (open-circuit
   voltage and coulomb counting); PX4 ``BAT1_*`` / ArduPilot ``BATT_*`` parameter
   references for the firmware's own estimates.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from .autopilot import DEFAULT_RESERVE_S, checked_pack
from .errors import SimulationError
from .formatting import duration
from .model import Battery

#: Charge grid points of the tables (charge taken out, full to the lowest-rate cutoff).
CHARGE_POINTS = 21

#: Table currents as multiples of the pack's rated capacity [1/h] (C-rates).
TABLE_C_RATES = (0.1, 0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0)

#: How often ArduPilot calls the script's update [ms], and how often it sends [ms].
INTERVAL_MS = 200
SEND_MS = 1000

#: The recent load of the time left: mean current over this many seconds [s].
RECENT_LOAD_S = 30

#: Pack current [A] below which a disarmed pack reads as resting (a fraction of 1C).
REST_C_RATE = 0.05

#: Time constant of the voltage filter of the no-current fallback [s].
VOLTAGE_FILTER_S = 5.0

#: Key of the script's parameter table (DL_BATT_IDX, DL_RESERVE); unique among the
#: scripts on one autopilot.
PARAM_KEY = 73

TEMPLATE = "onboard.lua"


@dataclass
class AutopilotScript:
    """The generated script: ``text`` (Lua), its ``tables`` and how it was made."""

    text: str
    tables: dict
    header: list[str]
    firmware: str = "ardupilot"
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"firmware": self.firmware, "header": list(self.header),
                "tables": {k: (np.asarray(v).tolist() if isinstance(v, (list, np.ndarray))
                               else v) for k, v in self.tables.items()},
                "notes": list(self.notes), "lines": self.text.count("\n")}

    def write(self, path, *, force: bool = False) -> Path:
        """Write the script atomically; refuses to replace a file unless ``force``."""
        from .atomic import check_outputs, write_text

        check_outputs([path], force=force)
        return write_text(path, self.text)


def _lua_list(values, digits: int, indent: str = "") -> str:
    """A Lua table constructor of numbers, cut into lines of at most 100 characters."""
    text = "{" + ", ".join(_num(v, digits) for v in values) + "}"
    if len(text) + len(indent) + 12 <= 100:
        return text
    import textwrap

    lines = textwrap.wrap(", ".join(_num(v, digits) for v in values), 96 - len(indent))
    return "{\n" + "\n".join(indent + "  " + line for line in lines) + "\n" + indent + "}"


def _num(value: float, digits: int) -> str:
    text = f"{float(value):.{digits}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _tables(bat: Battery, cut: float, ambient: float | None) -> dict:
    """Constant-current runs at the table currents, and the grids kept from them."""
    from .simulate import simulate_current

    rated = bat.rated_capacity_Ah
    currents = [c * rated for c in TABLE_C_RATES]
    q_cut = []
    for current in currents:
        try:
            sim = simulate_current(bat, current, cutoff_cell_V=cut, ambient_C=ambient)
        except SimulationError:  # at this load the pack starts below the cutoff
            q_cut.append(0.0)
            continue
        q_cut.append(float(sim.charge_Ah[-1]) if sim.ended_by != "end" else float("nan"))
    q_cut = np.asarray(q_cut)
    if not np.isfinite(q_cut).all() or not q_cut[0] > 0:
        raise SimulationError(f"the model does not reach {cut:g} V/cell at "
                              f"{currents[0]:.3g} A; check the cutoff")
    q_cut = np.minimum.accumulate(q_cut)   # more current never gives more charge
    charge = np.linspace(0.0, float(q_cut[0]), CHARGE_POINTS)
    # charge left to the cutoff, negative past it (linear in the charge: exact between rows)
    remaining = q_cut[None, :] - charge[:, None]
    with np.errstate(invalid="ignore", over="ignore"):
        ocv = np.asarray(bat.voltage(np.zeros_like(charge), charge, temperature_C=ambient))
        loaded = np.array([[float(bat.voltage(i, q, temperature_C=ambient)) for i in currents]
                           for q in charge])
    cutoff_pack = cut * bat.cells_series
    loaded = np.where(np.isfinite(loaded), loaded, 0.0)
    # past the cutoff the loaded voltage only matters as "below it": keep it falling
    loaded = np.minimum.accumulate(np.maximum(loaded, 0.5 * cutoff_pack), axis=0)
    return {"charge_Ah": charge, "current_A": np.asarray(currents), "ocv_V": ocv,
            "remaining_Ah": remaining, "loaded_V": loaded, "charge_to_cutoff_Ah": q_cut}


def autopilot_script(battery, *, firmware: str = "ardupilot", cells: int | None = None,
                     parallel: int | None = None, cutoff: float | None = None,
                     reserve_s: float = DEFAULT_RESERVE_S, load_current_A: float | None = None,
                     ambient: float | None = None, instance: int = 0,
                     generated: str | None = None) -> AutopilotScript:
    """A Lua script for ArduPilot that sends the model's time left and state of charge.

    Parameters
    ----------
    battery : Battery, preset name, battery-file path or logbook pack
        The cell model (its pack configuration replaced by ``cells``/``parallel``).
    firmware : {"ardupilot"}
    cells, parallel : int, optional
        Cells in series and strings in parallel of the flight pack.
    cutoff : float, optional
        Loaded cell voltage [V] at which the pack counts as empty (default by chemistry).
    reserve_s : float
        Time left [s] at which the script warns (and again at a third of it).
    load_current_A : float, optional
        Reference pack current [A] of the no-current fallback (default 1C).
    ambient : float, optional
        Ambient temperature [degC] of the tables for thermal models.
    instance : int
        ArduPilot battery instance (0 = the first monitor).
    generated : str, optional
        Time stamp of the header (default now, UTC).

    Returns
    -------
    AutopilotScript
    """
    from .predict import default_cutoff

    if firmware != "ardupilot":
        raise SimulationError(f"autopilot scripts are written for ardupilot, got {firmware!r}")
    battery, cells = checked_pack(battery, cells, reserve_s)
    if int(instance) < 0:
        raise SimulationError(f"the battery instance counts from 0, got {instance}")
    bat = battery.with_pack(cells, parallel)
    cut = default_cutoff(bat, cutoff)["cutoff_cell_V"]
    ref = bat.rated_capacity_Ah if load_current_A is None else float(load_current_A)
    if not ref > 0:
        raise SimulationError(f"load_current_A must be a positive pack current, got {ref}")
    tables = _tables(bat, cut, ambient)
    tables["reference_current_A"] = ref
    tables["capacity_Ah"] = bat.capacity_Ah
    tables["cutoff_pack_V"] = cut * cells
    t_ref = float(np.interp(ref, tables["current_A"], tables["charge_to_cutoff_Ah"])) \
        * 3600.0 / ref
    if not t_ref > reserve_s:
        raise SimulationError(f"at {ref:.3g} A the pack reaches {cut:g} V/cell after "
                              f"{t_ref:.0f} s, less than the {reserve_s:g} s reserve; lower "
                              "the load or reserve")
    stamp = generated or _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    header = _header(bat, cells, cut, ref, t_ref, reserve_s, stamp, ambient)
    text = _render(tables, header, reserve_s, int(instance), bat)
    notes = [f"{bat.model} model, {cells}S{bat.strings_parallel}P, cutoff {cut:g} V/cell: "
             f"{duration(t_ref)} at {ref:.3g} A"]
    if bat.extra.get("logbook") and bat.extra.get("note"):
        notes.append(str(bat.extra["note"]))
    return AutopilotScript(text=text, tables=tables, header=header, notes=notes)


def _header(bat: Battery, cells: int, cut: float, ref: float, t_ref: float, reserve_s: float,
            stamp: str, ambient: float | None) -> list[str]:
    from .autopilot import wrap_comment

    health = "health: the model as fitted"
    lb = bat.extra.get("logbook")
    if isinstance(lb, dict) and "capacity_factor" in lb:
        health = (f"health today: capacity x{lb['capacity_factor']:.3f} of the fitted model, "
                  f"series resistance {1000 * lb['resistance_shift_cell_ohm']:+.1f} mOhm/cell")
    elif lb:
        health = "health today: the chemistry's prior at the logbook's figures"
    amb = f", tables at {bat.ambient_C if ambient is None else ambient:.0f} degC" \
        if bat.family.thermal else ""
    lines = [f"dischargelab on-board flight time for {bat.name or 'a battery model'}",
             f"pack: {cells}S{bat.strings_parallel}P, {bat.rated_capacity_Ah:.3g} Ah rated, "
             f"cutoff {cut:g} V/cell ({cut * cells:.2f} V pack) at load",
             f"generated {stamp} from the {bat.model} model{amb}",
             health,
             f"at {ref:.3g} A the model reaches the cutoff after {duration(t_ref)}",
             "sends DL_TREM (s to the cutoff at the last 30 s load) and DL_SOC (%)",
             f"warns at {reserve_s:g} s and at {reserve_s / 3:.0f} s left",
             "settings: DL_BATT_IDX (battery instance) and DL_RESERVE (s), after a reboot",
             "install: copy to APM/scripts/ on the SD card, set SCR_ENABLE = 1 and reboot;",
             "  it needs about 32 KB of scripting heap (SCR_HEAP_SIZE; 43 KB on F4 boards)"]
    out = []
    for line in lines:
        out += wrap_comment(line, 96)
    return out


def _render(tables: dict, header: list[str], reserve_s: float, instance: int,
            bat: Battery) -> str:
    template = resources.files("dischargelab").joinpath("data", TEMPLATE).read_text("utf-8")
    rows = lambda grid, d: "{\n" + ",\n".join(  # noqa: E731
        "  " + _lua_list(r, d) for r in grid) + "\n}"
    values = {
        "HEADER": "\n".join(f"-- {line}".rstrip() for line in header),
        "INSTANCE": str(instance),
        "PARAM_KEY": str(PARAM_KEY),
        "RESERVE_S": _num(reserve_s, 1),
        "INTERVAL_MS": str(INTERVAL_MS),
        "SEND_MS": str(SEND_MS),
        "WINDOW_S": str(RECENT_LOAD_S),
        "CAPACITY_AH": _num(tables["capacity_Ah"], 5),
        "REF_A": _num(tables["reference_current_A"], 4),
        "REST_A": _num(REST_C_RATE * bat.rated_capacity_Ah, 4),
        "FILTER_S": _num(VOLTAGE_FILTER_S, 1),
        "Q": _lua_list(tables["charge_Ah"], 5),
        "I": _lua_list(tables["current_A"], 4),
        "OCV": _lua_list(tables["ocv_V"], 4),
        "REM": rows(tables["remaining_Ah"], 5),
        "VL": rows(tables["loaded_V"], 4),
    }
    text = template
    for key, value in values.items():
        text = text.replace(f"@{key}@", value)
    return text


def flight_samples(sim, *, rest_s: float = 5.0, interval_ms: int = INTERVAL_MS,
                   current_sensor: bool = True) -> list[tuple]:
    """What ArduPilot's battery monitor would read at each call of the script during a
    simulated run (:class:`dischargelab.simulate.SimulationResult`): ``(time_ms, armed,
    voltage_V, current_A or None, consumed_mAh or None)``, after ``rest_s`` disarmed at
    the start's rest voltage. Returns the rows and the flight's time to cutoff [s]."""
    bat = sim.battery
    dt = interval_ms / 1000.0
    t_end = float(sim.time_s[-1])
    rest_v = float(bat.voltage(0.0, sim.initial_charge_Ah, temperature_C=sim.ambient_C))
    rows = []
    n_rest = int(round(rest_s / dt))
    for k in range(n_rest):
        rows.append((int(round(k * interval_ms)), False, rest_v, 0.0 if current_sensor else None,
                     0.0 if current_sensor else None))
    times = np.arange(dt, t_end, dt)
    volts = np.interp(times, sim.time_s, sim.voltage_V)
    amps = np.interp(times, sim.time_s, sim.current_A)
    used = (np.interp(times, sim.time_s, sim.charge_Ah) - sim.initial_charge_Ah) * 1000.0
    for t, v, i, q in zip(times, volts, amps, used):
        rows.append((int(round((rest_s + t) * 1000)), True, float(v),
                     float(i) if current_sensor else None, float(q) if current_sensor else None))
    return rows


__all__ = ["autopilot_script", "AutopilotScript", "flight_samples"]
