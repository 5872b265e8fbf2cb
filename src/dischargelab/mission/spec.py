"""Mission files (TOML) -> :class:`Mission`: phases, repeat blocks, battery and aircraft.

See :func:`load_mission` for the format; bundled examples are listed by
:func:`bundled_missions` and can be given by name, e.g. ``paper-table5``.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..engine import Step
from ..errors import DataError
from ..identity import resolve
from ..model import Battery, load_battery
from ..plausibility import check_cutoff
from .aircraft import (
    SEA_LEVEL_AIR_DENSITY_KG_M3,
    STANDARD_GRAVITY_M_S2,
    fixed_wing_power_W,
    hover_power_W,
    isa_air_density_kg_m3,
)
from .keys import keys_of

#: Range of ambient temperatures accepted for a mission [degC].
AMBIENT_RANGE_C = (-60.0, 90.0)

UNTIL_CHOICES = ("cutoff", "reserve")



# ---------------------------------------------------------------------------------------------
# Mission description
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Phase:
    """One flight phase with a constant load.

    Parameters
    ----------
    name : str
    kind : {"current", "power"}
        Pack current [A] or electric power [W].
    value : float
        The load, discharge positive (0 = motors off).
    duration_s : float or None
        Planned duration [s]; None with ``until`` or with ``stretch`` (fly the maximum).
    until : {"cutoff", "reserve"} or None
        Run until the cutoff voltage or the reserve (last phase only).
    stretch : bool
        The phase whose maximum duration is searched (at most one per mission).
    detail : dict
        How the load was derived (flight condition, lift and drag, ...).
    """

    name: str
    kind: str
    value: float
    duration_s: float | None = None
    until: str | None = None
    stretch: bool = False
    detail: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        label = f"phase {self.name!r}"
        if self.kind not in ("current", "power"):
            raise DataError(f"{label}: load kind must be 'current' or 'power', got {self.kind!r}")
        if not (np.isfinite(self.value) and self.value >= 0):
            raise DataError(f"{label}: load must be a finite value >= 0, got {self.value}")
        if self.duration_s is not None and not (np.isfinite(self.duration_s)
                                                and self.duration_s >= 0):
            raise DataError(f"{label}: duration_s must be >= 0, got {self.duration_s}")
        if self.until is not None and self.until not in UNTIL_CHOICES:
            raise DataError(f"{label}: until must be 'cutoff' or 'reserve', got {self.until!r}")
        if self.until is not None and (self.duration_s is not None or self.stretch):
            raise DataError(f"{label}: 'until' replaces duration_s and stretch; give only one")
        if self.until is None and self.duration_s is None and not self.stretch:
            raise DataError(f"{label}: give duration_s, until = 'cutoff' | 'reserve', "
                            f"or stretch = true")
        if self.stretch and self.value == 0:
            raise DataError(f"{label}: a stretch phase must draw a load (it would last forever)")
        if self.until is not None and self.value == 0:
            raise DataError(f"{label}: a phase with no load never reaches the {self.until}")

    def describe_load(self) -> str:
        """Load as text, e.g. '22 A' or '310 W'."""
        return f"{self.value:g} A" if self.kind == "current" else f"{self.value:.4g} W"

    def to_step(self, duration_s: float | None) -> Step:
        """The simulation step of this phase with the given duration (None = until cutoff)."""
        return Step(self.kind, float(self.value), duration_s, self.name)


@dataclass(frozen=True)
class RepeatBlock:
    """Phases flown again and again: ``count`` times, or until the cutoff / reserve."""

    name: str
    phases: tuple[Phase, ...]
    count: int | None = None
    until: str | None = None

    def __post_init__(self):
        label = f"repeat block {self.name!r}"
        if not self.phases:
            raise DataError(f"{label}: no phases to repeat")
        if (self.count is None) == (self.until is None):
            raise DataError(f"{label}: give repeat = N (a whole number >= 1) or repeat = "
                            f"'until cutoff' / 'until reserve'")
        if self.count is not None and (int(self.count) != self.count or self.count < 1):
            raise DataError(f"{label}: repeat count must be a whole number >= 1, "
                            f"got {self.count}")
        if self.until is not None and self.until not in UNTIL_CHOICES:
            raise DataError(f"{label}: repeat must be 'until cutoff' or 'until reserve'")
        for ph in self.phases:
            if ph.duration_s is None or ph.stretch or ph.until:
                raise DataError(f"{label}: phase {ph.name!r} inside a repeat block needs a "
                                f"fixed duration_s (no until, no stretch)")
        if self.until is not None and all(ph.value == 0 for ph in self.phases):
            raise DataError(f"{label}: the repeated phases draw no load; they never end")


@dataclass(frozen=True)
class Mission:
    """A battery, its limits and the flight phases.

    Parameters
    ----------
    items : tuple of Phase or RepeatBlock
    battery : Battery
        Pack as flown (series / parallel already applied).
    cutoff_cell_V : float
        Cutoff voltage per cell [V] (the flight must never reach it).
    reserve_pct : float
        State of charge to land with [%] (0 = fly to the cutoff).
    initial_soc_pct : float
        State of charge at take-off [%].
    name, source : str
        Title, and the mission file's path (a bundled mission's name for one of those).
    aircraft : dict or None
        The ``[aircraft]`` table used for flight-condition phases.
    ambient_C : float or None
        Ambient temperature [degC] the cells start at and cool to (thermal
        families); None = the battery's ``ambient_C`` (that of its fitted data).
    warnings : tuple of str
        Where the mission's ``[battery]`` table disagreed with the battery flown
        (:func:`dischargelab.identity.resolve`), one line each.
    notes : tuple of str
        What was taken from the ``[battery]`` table for a battery that did not say.
    """

    items: tuple
    battery: Battery
    cutoff_cell_V: float
    reserve_pct: float = 20.0
    initial_soc_pct: float = 100.0
    name: str = ""
    source: str = ""
    aircraft: dict | None = field(default=None, compare=False)
    ambient_C: float | None = None
    warnings: tuple = field(default=(), compare=False)
    notes: tuple = field(default=(), compare=False)

    def __post_init__(self):
        if not self.items:
            raise DataError("mission has no phases")
        if not (np.isfinite(self.cutoff_cell_V) and self.cutoff_cell_V > 0):
            raise DataError(f"cutoff_cell_V must be > 0 V, got {self.cutoff_cell_V}")
        if not 0 <= self.reserve_pct < 100:
            raise DataError(f"reserve_pct must be in [0, 100), got {self.reserve_pct}")
        if not 0 < self.initial_soc_pct <= 100:
            raise DataError(f"initial_soc_pct must be in (0, 100], got {self.initial_soc_pct}")
        if self.ambient_C is not None and not (
                np.isfinite(self.ambient_C)
                and AMBIENT_RANGE_C[0] <= self.ambient_C <= AMBIENT_RANGE_C[1]):
            raise DataError(f"ambient_C must be between {AMBIENT_RANGE_C[0]:g} and "
                            f"{AMBIENT_RANGE_C[1]:g} degC, got {self.ambient_C}")
        if self.initial_soc_pct <= self.reserve_pct:
            raise DataError(f"initial state of charge {self.initial_soc_pct:g} % is not above "
                            f"the reserve {self.reserve_pct:g} %")
        stretch = [ph.name for ph in self.items if isinstance(ph, Phase) and ph.stretch]
        if len(stretch) > 1:
            raise DataError(f"only one phase may have stretch = true, found {len(stretch)}: "
                            f"{', '.join(stretch)}")
        for k, item in enumerate(self.items):
            if item.until is not None and k != len(self.items) - 1:
                raise DataError(f"{_item_label(item)} runs until the {item.until}, so nothing "
                                f"can follow it; '{_item_label(self.items[k + 1])}' comes after")
        if stretch and self.items[-1].until is not None:
            raise DataError(f"phase {stretch[0]!r} has stretch = true but the mission ends "
                            f"'until {self.items[-1].until}'; use one or the other")

    # -- derived quantities ----------------------------------------------------------------------
    @property
    def cutoff_pack_V(self) -> float:
        """Pack cutoff voltage [V]."""
        return self.cutoff_cell_V * self.battery.cells_series

    @property
    def capacity_Ah(self) -> float:
        """Pack model capacity [Ah]."""
        return self.battery.capacity_Ah

    @property
    def resolved_ambient_C(self) -> float:
        """Ambient temperature flown [degC]: ``ambient_C``, else the battery's."""
        return self.battery.ambient_C if self.ambient_C is None else float(self.ambient_C)

    @property
    def initial_charge_Ah(self) -> float:
        """Pack charge already removed at take-off [Ah]."""
        return (1.0 - self.initial_soc_pct / 100.0) * self.capacity_Ah

    @property
    def reserve_charge_Ah(self) -> float:
        """Pack charge removed when the reserve is reached [Ah]."""
        return (1.0 - self.reserve_pct / 100.0) * self.capacity_Ah

    @property
    def stretch_index(self) -> int | None:
        """Index of the stretch phase in ``items`` (None when there is none)."""
        for k, item in enumerate(self.items):
            if isinstance(item, Phase) and item.stretch:
                return k
        return None

    def phases(self) -> list[Phase]:
        """All phases in flight order, blocks listed once."""
        out = []
        for item in self.items:
            out.extend(item.phases if isinstance(item, RepeatBlock) else [item])
        return out

    def with_battery(self, battery: Battery) -> Mission:
        """Same mission on another battery (pack configuration kept from ``battery``)."""
        return replace(self, battery=battery)


def _item_label(item) -> str:
    if isinstance(item, RepeatBlock):
        return f"repeat block {item.name!r}"
    return f"phase {item.name!r}"


# ---------------------------------------------------------------------------------------------
# TOML mission files
# ---------------------------------------------------------------------------------------------

TOP_KEYS = keys_of("")
BATTERY_KEYS = keys_of("battery")
ATMOSPHERE_KEYS = {"altitude_m", "air_density_kg_m3"}
FIXED_WING_KEYS = keys_of("aircraft", "aircraft fixed-wing") - {"type"}
MULTIROTOR_KEYS = keys_of("aircraft", "aircraft multirotor") - {"type"}
AIRCRAFT_TYPES = ("fixed-wing", "multirotor")
LOAD_KEYS = ("current_A", "power_W", "speed_m_s", "hover")
PHASE_KEYS = keys_of("phase")


class _Context:
    """Where we are in the file, for one-line error messages."""

    def __init__(self, source: str):
        self.source = source

    def error(self, where: str, message: str) -> DataError:
        prefix = f"{self.source}: " if self.source else ""
        return DataError(f"{prefix}{where}{': ' if where else ''}{message}")


def _check_keys(ctx: _Context, where: str, table: dict, allowed: set):
    if not isinstance(table, dict):
        raise ctx.error(where, f"expected a table, got {type(table).__name__}")
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(key, sorted(allowed), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else \
                f" (allowed: {', '.join(sorted(allowed))})"
            raise ctx.error(where, f"unknown key {key!r}{hint}")


def _number(ctx, where, table, key, *, positive=False, minimum=None, maximum=None,
            default=None, required=False):
    if key not in table:
        if required:
            raise ctx.error(where, f"missing {key}")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ctx.error(where, f"{key} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ctx.error(where, f"{key} must be finite, got {value}")
    if positive and value <= 0:
        raise ctx.error(where, f"{key} must be > 0, got {value:g}")
    if minimum is not None and value < minimum:
        raise ctx.error(where, f"{key} must be >= {minimum:g}, got {value:g}")
    if maximum is not None and value > maximum:
        raise ctx.error(where, f"{key} must be <= {maximum:g}, got {value:g}")
    return value


def _integer(ctx, where, table, key, default=None):
    if key not in table:
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ctx.error(where, f"{key} must be a whole number >= 1, got {value!r}")
    return int(value)


def _air_density(ctx, where, table, fallback):
    if "altitude_m" in table and "air_density_kg_m3" in table:
        raise ctx.error(where, "give altitude_m or air_density_kg_m3, not both")
    if "air_density_kg_m3" in table:
        return _number(ctx, where, table, "air_density_kg_m3", positive=True)
    if "altitude_m" in table:
        h = _number(ctx, where, table, "altitude_m", minimum=-500, maximum=11000)
        return isa_air_density_kg_m3(h)
    return fallback


def _parse_aircraft(ctx: _Context, table: dict) -> dict:
    where = "[aircraft]"
    if not isinstance(table, dict):
        raise ctx.error(where, "expected a table")
    kind = table.get("type")
    if kind not in AIRCRAFT_TYPES:
        raise ctx.error(where, f"type must be one of {', '.join(AIRCRAFT_TYPES)}, got {kind!r}")
    body = {k: v for k, v in table.items() if k != "type"}
    allowed = FIXED_WING_KEYS if kind == "fixed-wing" else MULTIROTOR_KEYS
    _check_keys(ctx, where, body, allowed)
    ac = {"type": kind}
    ac["mass_kg"] = _number(ctx, where, body, "mass_kg", positive=True, required=True)
    ac["air_density_kg_m3"] = _air_density(ctx, where, body, SEA_LEVEL_AIR_DENSITY_KG_M3)
    if kind == "fixed-wing":
        ac["wing_area_m2"] = _number(ctx, where, body, "wing_area_m2", positive=True,
                                     required=True)
        ac["cd0"] = _number(ctx, where, body, "cd0", positive=True, required=True)
        if ("aspect_ratio" in body) == ("span_m" in body):
            raise ctx.error(where, "give exactly one of aspect_ratio or span_m")
        if "span_m" in body:
            span = _number(ctx, where, body, "span_m", positive=True)
            ac["aspect_ratio"] = span**2 / ac["wing_area_m2"]
        else:
            ac["aspect_ratio"] = _number(ctx, where, body, "aspect_ratio", positive=True)
        ac["span_efficiency"] = _number(ctx, where, body, "span_efficiency", positive=True,
                                        maximum=1.0, required=True)
        ac["propulsion_efficiency"] = _number(ctx, where, body, "propulsion_efficiency",
                                              positive=True, maximum=1.0, required=True)
    else:
        if "rotor_disc_area_m2" in body and ("rotor_count" in body or "rotor_diameter_m" in body):
            raise ctx.error(where, "give rotor_disc_area_m2 or rotor_count + rotor_diameter_m, "
                                   "not both")
        if "rotor_disc_area_m2" in body:
            ac["rotor_disc_area_m2"] = _number(ctx, where, body, "rotor_disc_area_m2",
                                               positive=True)
        else:
            count = _integer(ctx, where, body, "rotor_count")
            diameter = _number(ctx, where, body, "rotor_diameter_m", positive=True)
            if count is None or diameter is None:
                raise ctx.error(where, "give rotor_disc_area_m2 (all rotors) or rotor_count "
                                       "and rotor_diameter_m")
            ac["rotor_disc_area_m2"] = count * math.pi * diameter**2 / 4.0
        ac["figure_of_merit"] = _number(ctx, where, body, "figure_of_merit", positive=True,
                                        maximum=1.0, required=True)
        ac["motor_efficiency"] = _number(ctx, where, body, "motor_efficiency", positive=True,
                                         maximum=1.0, required=True)
    return ac


def _phase_load(ctx, where, table, aircraft):
    """Return (kind, value, detail) of a phase table."""
    loads = [k for k in LOAD_KEYS if k in table]
    if not loads:
        raise ctx.error(where, "missing load: give current_A, power_W, speed_m_s (fixed wing, "
                               "needs [aircraft]) or hover = true (multirotor)")
    if len(loads) > 1:
        raise ctx.error(where, f"give one load, found {', '.join(loads)}")
    load = loads[0]
    if "climb_rate_m_s" in table and load in ("current_A", "power_W"):
        raise ctx.error(where, "climb_rate_m_s applies to flight conditions (speed_m_s or hover)")
    if load == "current_A":
        return "current", _number(ctx, where, table, "current_A", minimum=0), {}
    if load == "power_W":
        return "power", _number(ctx, where, table, "power_W", minimum=0), {}
    climb = _number(ctx, where, table, "climb_rate_m_s", default=0.0)
    if aircraft is None:
        raise ctx.error(where, f"{load} needs an [aircraft] table describing the aircraft")
    rho = aircraft["air_density_kg_m3"]
    if load == "speed_m_s":
        if aircraft["type"] != "fixed-wing":
            raise ctx.error(where, "speed_m_s needs a fixed-wing [aircraft]; a multirotor "
                                   "phase uses hover = true")
        speed = _number(ctx, where, table, "speed_m_s", positive=True)
        ac = aircraft
        power = fixed_wing_power_W(speed, ac["mass_kg"], ac["wing_area_m2"], ac["cd0"],
                                   ac["aspect_ratio"], ac["span_efficiency"],
                                   ac["propulsion_efficiency"], rho, climb)
        q_dyn = 0.5 * rho * speed**2
        cl = ac["mass_kg"] * STANDARD_GRAVITY_M_S2 / (q_dyn * ac["wing_area_m2"])
        cd = ac["cd0"] + cl**2 / (math.pi * ac["span_efficiency"] * ac["aspect_ratio"])
        detail = {"model": "fixed-wing drag polar", "speed_m_s": speed,
                  "climb_rate_m_s": climb, "air_density_kg_m3": rho, "lift_coefficient": cl,
                  "drag_coefficient": cd, "drag_N": q_dyn * ac["wing_area_m2"] * cd,
                  "lift_to_drag": cl / cd}
        if power == 0:
            detail["note"] = "glide: the descent supplies the drag power; 0 W drawn"
        return "power", power, detail
    if table["hover"] is not True:
        raise ctx.error(where, "hover must be true (or leave it out)")
    if aircraft["type"] != "multirotor":
        raise ctx.error(where, "hover = true needs a multirotor [aircraft]")
    if climb < 0:
        raise ctx.error(where, "multirotor descent is not modelled by momentum theory; give "
                               "the descent as current_A or power_W")
    ac = aircraft
    power = hover_power_W(ac["mass_kg"], ac["rotor_disc_area_m2"], ac["figure_of_merit"],
                          ac["motor_efficiency"], rho, climb)
    thrust = ac["mass_kg"] * STANDARD_GRAVITY_M_S2
    detail = {"model": "multirotor momentum theory", "climb_rate_m_s": climb,
              "air_density_kg_m3": rho, "thrust_N": thrust,
              "disc_loading_N_m2": thrust / ac["rotor_disc_area_m2"],
              "induced_velocity_m_s": math.sqrt(thrust / (2 * rho * ac["rotor_disc_area_m2"]))}
    return "power", power, detail


def _parse_duration(ctx, where, table):
    has = [k for k in ("duration_s", "duration_min", "until") if k in table]
    if len(has) > 1:
        raise ctx.error(where, f"give one of duration_s, duration_min or until, found "
                               f"{', '.join(has)}")
    if "duration_s" in table:
        return _number(ctx, where, table, "duration_s", minimum=0), None
    if "duration_min" in table:
        return 60.0 * _number(ctx, where, table, "duration_min", minimum=0), None
    if "until" in table:
        until = table["until"]
        if until not in UNTIL_CHOICES:
            raise ctx.error(where, f"until must be 'cutoff' or 'reserve', got {until!r}")
        return None, until
    return None, None


def _parse_phase(ctx, where, table, aircraft, allow_block=True):
    _check_keys(ctx, where, table, PHASE_KEYS)
    name = table.get("name", "")
    if not isinstance(name, str) or not name.strip():
        raise ctx.error(where, "every phase needs a name (a non-empty string)")
    where = f"{where} ({name!r})"
    if "repeat" in table or "phases" in table:
        if not allow_block:
            raise ctx.error(where, "repeat blocks cannot be nested")
        if "repeat" not in table or "phases" not in table:
            raise ctx.error(where, "a repeat block needs both repeat and phases")
        extra = [k for k in table if k not in ("name", "repeat", "phases", "note")]
        if extra:
            raise ctx.error(where, f"a repeat block takes name, repeat and phases only; "
                                   f"move {', '.join(extra)} into its phases")
        rep = table["repeat"]
        count = until = None
        if isinstance(rep, bool):
            raise ctx.error(where, "repeat must be a whole number or 'until cutoff' / "
                                   "'until reserve'")
        if isinstance(rep, int):
            if rep < 1:
                raise ctx.error(where, f"repeat must be >= 1, got {rep}")
            count = rep
        elif isinstance(rep, str) and rep.replace("_", " ").strip() in ("until cutoff",
                                                                        "until reserve"):
            until = rep.replace("_", " ").split()[-1]
        else:
            raise ctx.error(where, f"repeat must be a whole number or 'until cutoff' / "
                                   f"'until reserve', got {rep!r}")
        subs = table["phases"]
        if not isinstance(subs, list) or not subs:
            raise ctx.error(where, "phases must be a non-empty list of phase tables")
        phases = tuple(_parse_phase(ctx, f"{where} phase {k + 1}", sub, aircraft, False)
                       for k, sub in enumerate(subs))
        try:
            return RepeatBlock(name, phases, count, until)
        except DataError as exc:
            raise ctx.error("", str(exc)) from None
    kind, value, detail = _phase_load(ctx, where, table, aircraft)
    duration, until = _parse_duration(ctx, where, table)
    stretch = table.get("stretch", False)
    if not isinstance(stretch, bool):
        raise ctx.error(where, f"stretch must be true or false, got {stretch!r}")
    if stretch and until:
        raise ctx.error(where, "stretch = true and until cannot be combined")
    if duration is None and until is None and not stretch:
        raise ctx.error(where, "missing duration: give duration_s (or duration_min), "
                               "until = 'cutoff' | 'reserve', or stretch = true")
    try:
        return Phase(name, kind, value, duration, until, stretch, detail)
    except DataError as exc:
        raise ctx.error("", str(exc)) from None


def _battery(ctx, bat_table, battery, base_dir) -> Battery:
    """The battery given, else the one ``[battery] source`` names (a path relative to the
    mission file, or a preset)."""
    if battery is not None:
        return load_battery(battery)
    src = bat_table.get("source")
    if src is None:
        raise ctx.error("[battery]", "no battery: give BATTERY (a battery file or preset) or "
                                     "set source = 'battery.json' | preset name")
    if not isinstance(src, str) or not src:
        raise ctx.error("[battery]", "source must be a battery file path or a preset name")
    from ..model import PRESETS

    candidate = Path(base_dir or ".") / src
    if candidate.exists() or src not in PRESETS:
        if not candidate.exists():
            raise ctx.error("[battery]", f"source {src!r}: no such battery file beside the "
                                         f"mission ({candidate}) and not a preset "
                                         f"({', '.join(sorted(PRESETS))})")
        return load_battery(candidate)
    return load_battery(src)


def _source_battery(ctx, bat_table, base_dir):
    """The battery ``[battery] source`` names, found as :func:`_battery` finds it, or None
    without a readable one (a battery given instead flies; the source lends its layout)."""
    if not isinstance(bat_table.get("source"), str):
        return None
    try:
        return _battery(ctx, bat_table, None, base_dir)
    except DataError:
        return None


def parse_mission(data: dict, *, battery=None, base_dir=None, source: str = "",
                  cutoff_cell_V: float | None = None, reserve_pct: float | None = None,
                  ambient_C: float | None = None, cells_series: int | None = None,
                  strings_parallel: int | None = None) -> Mission:
    """Build a :class:`Mission` from a parsed TOML document.

    Parameters
    ----------
    data : dict
        The TOML document (see :func:`load_mission` for the format).
    battery : Battery, preset name or path, optional
        Overrides ``[battery] source``.
    base_dir : path, optional
        Folder for a relative ``[battery] source`` path.
    source : str
        File name used in error messages.
    cutoff_cell_V, reserve_pct, ambient_C : float, optional
        Override the file's values.
    cells_series, strings_parallel : int, optional
        The pack layout asked for explicitly (``--cells``, ``--parallel``); a logbook
        pack's measured layout cannot be changed (see :mod:`dischargelab.identity`).
    """
    ctx = _Context(source)
    _check_keys(ctx, "", data, TOP_KEYS)
    name = data.get("name", Path(source).stem if source else "mission")
    if not isinstance(name, str):
        raise ctx.error("", "name must be a string")
    bat_table = data.get("battery", {})
    _check_keys(ctx, "[battery]", bat_table, BATTERY_KEYS)
    given, battery = battery, _battery(ctx, bat_table, battery, base_dir)
    where = f"{name if not source else Path(source).name} [battery]"
    chem = bat_table.get("chemistry")
    series = _integer(ctx, "[battery]", bat_table, "series")
    parallel = _integer(ctx, "[battery]", bat_table, "parallel")
    planned = battery if given is None else _source_battery(ctx, bat_table, base_dir)
    if planned is not None:  # the pack the mission was planned for: defaults, as its table
        chem = chem or planned.chemistry
        if series is None and parallel is None and \
                planned.cells_series * planned.strings_parallel > 1:
            series, parallel = planned.cells_series, planned.strings_parallel
    try:
        flown = resolve(
            battery, where=where, series=series, parallel=parallel, chemistry=chem,
            cutoff_cell_V=_number(ctx, "[battery]", bat_table, "cutoff_cell_V", positive=True),
            cells_given=cells_series, parallel_given=strings_parallel,
            cutoff_given=cutoff_cell_V)
    except DataError as exc:
        raise ctx.error("", str(exc)) from None
    battery, cutoff = flown.battery, flown.cutoff_cell_V
    soc0 = _number(ctx, "[battery]", bat_table, "initial_soc_pct", positive=True, maximum=100,
                   default=100.0)
    reserve = reserve_pct if reserve_pct is not None else _number(
        ctx, "[battery]", bat_table, "reserve_pct", minimum=0, maximum=99.9, default=20.0)
    if cutoff is None:
        raise ctx.error("[battery]", "battery chemistry unknown: give cutoff_cell_V or "
                                     "chemistry (or --cutoff V)")
    warnings = list(flown.warnings) + [f.text({"cutoff_cell_V": "--cutoff"}) for f in
                                       check_cutoff(cutoff, battery.chemistry)]
    if ambient_C is None:
        ambient_C = _number(ctx, "", data, "ambient_C", minimum=AMBIENT_RANGE_C[0],
                            maximum=AMBIENT_RANGE_C[1])
    aircraft = _parse_aircraft(ctx, data["aircraft"]) if "aircraft" in data else None
    phases = data.get("phase")
    if not isinstance(phases, list) or not phases:
        raise ctx.error("", "no phases: add [[phase]] tables (name, a load, a duration)")
    items = tuple(_parse_phase(ctx, f"phase {k + 1}", table, aircraft)
                  for k, table in enumerate(phases))
    try:
        return Mission(items=items, battery=battery, cutoff_cell_V=float(cutoff),
                       reserve_pct=float(reserve), initial_soc_pct=float(soc0), name=name,
                       source=source, aircraft=aircraft,
                       ambient_C=None if ambient_C is None else float(ambient_C),
                       warnings=tuple(warnings), notes=tuple(flown.notes))
    except DataError as exc:
        raise ctx.error("", str(exc)) from None


def bundled_missions() -> dict[str, Path]:
    """Example missions shipped with dischargelab, by name (e.g. "paper-table5")."""
    from importlib import resources

    folder = Path(str(resources.files("dischargelab") / "data" / "missions"))
    return {p.stem: p for p in sorted(folder.glob("*.toml"))}


def mission_path(name_or_path) -> Path:
    """A mission file path, or the path of a bundled example mission by name."""
    path = Path(name_or_path)
    if path.exists():
        return path
    bundled = bundled_missions()
    if str(name_or_path) in bundled:
        return bundled[str(name_or_path)]
    raise DataError(f"mission file {str(name_or_path)!r} not found (bundled examples: "
                    f"{', '.join(bundled)})")


def load_mission(path, *, battery=None, cutoff_cell_V: float | None = None,
                 reserve_pct: float | None = None, ambient_C: float | None = None,
                 cells_series: int | None = None, strings_parallel: int | None = None
                 ) -> Mission:
    """Read a mission TOML file.

    Format (all keys with units in their names; every key with its unit and default:
    :data:`dischargelab.mission.keys.KEYS`, the page ``docs/mission-format.md``)::

        name = "survey"
        ambient_C = 35             # optional: air temperature [degC] for thermal models
                                   # (default: the battery file's, that of its fitted data)
        [battery]                  # all optional
        source = "battery.json"    # beside this file, or a preset name; the command-line
                                   # battery wins
        series = 4                 # defaults for a battery that does not say: a cell is
        parallel = 1               # placed in this pack, a pack keeps its own (a warning)
        chemistry = "lipo"         # what the cutoff below was written for
        initial_soc_pct = 100
        cutoff_cell_V = 3.3        # default: the battery's own, else its chemistry's
        reserve_pct = 20           # land with 20 % left

        [aircraft]                 # only for flight-condition phases
        type = "fixed-wing"        # mass_kg, wing_area_m2, cd0, aspect_ratio | span_m,
                                   # span_efficiency, propulsion_efficiency,
                                   # altitude_m | air_density_kg_m3
        # type = "multirotor"      # mass_kg, rotor_disc_area_m2 | rotor_count +
                                   # rotor_diameter_m, figure_of_merit, motor_efficiency

        [[phase]]
        name = "takeoff"
        current_A = 50             # or power_W, speed_m_s (+ climb_rate_m_s), hover = true
        duration_s = 10            # or duration_min, until = "cutoff" | "reserve"

        [[phase]]
        name = "cruise"
        speed_m_s = 16
        duration_s = 300
        stretch = true             # search the longest cruise that still lands at the reserve

        [[phase]]
        name = "laps"
        repeat = 3                 # or "until cutoff" / "until reserve" (last only)
        phases = [{ name = "leg", power_W = 180, duration_s = 60 },
                  { name = "turn", power_W = 260, duration_s = 8 }]

    Raises
    ------
    DataError
        One line naming the file, the phase and the problem.
    """
    given = str(path)
    path = mission_path(path)
    # a bundled mission is named by its name, not by where the package lies
    source = given if not Path(given).exists() else str(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML ({exc})") from None
    except UnicodeDecodeError:
        raise DataError(f"{path}: not a UTF-8 text file") from None
    return parse_mission(data, battery=battery, base_dir=path.parent, source=source,
                         cutoff_cell_V=cutoff_cell_V, reserve_pct=reserve_pct,
                         ambient_C=ambient_C, cells_series=cells_series,
                         strings_parallel=strings_parallel)


def mission_catalogue() -> list[dict]:
    """The bundled missions: ``{"name", "title", "battery", "phases", "path"}`` each."""
    rows = []
    for key, path in bundled_missions().items():
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        bat = data.get("battery") or {}
        rows.append({"name": key, "title": str(data.get("name", key)),
                     "battery": bat.get("source"), "phases": len(data.get("phase") or []),
                     "path": str(path)})
    return rows


def bundled_mission_text(name: str) -> str:
    """The TOML text of a bundled mission (a :class:`DataError` naming the bundled ones
    for another name)."""
    bundled = bundled_missions()
    if name not in bundled:
        raise DataError(f"no bundled mission {name!r}; choose one of {', '.join(bundled)} "
                        f"(dischargelab missions list)")
    return bundled[name].read_text(encoding="utf-8")


def copy_mission(name: str, destination, *, force: bool = False) -> Path:
    """Copy a bundled mission to ``destination`` to edit (atomic; an existing file is kept
    unless ``force``). Returns the path written."""
    from ..atomic import check_outputs, write_text

    text = bundled_mission_text(name)
    (path,) = check_outputs([destination], [], force)
    return write_text(path, text)
