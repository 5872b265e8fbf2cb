"""Flight missions: phases with loads, endurance, maximum cruise time and margin.

A mission is a sequence of flight phases flown on one battery. Each phase draws
a constant pack current [A] or a constant electric power [W]; the power may be
computed from a flight condition (fixed-wing drag polar or multirotor hover by
momentum theory). A phase lasts a given time, or runs ``until`` the cutoff
voltage or the reserve; a block of phases may be repeated a number of times or
until the end. One phase may be marked ``stretch``: the tool then finds the
longest duration of that phase (the cruise or loiter) that still lets the
remaining phases end at the reserve without reaching the cutoff.

Every flight is flown by the one engine (:func:`dischargelab.engine.run`), for
any model family and for many parameter draws at once; nothing here integrates
the battery model on its own. The longest stretch is found per draw by a
bracketed secant (regula falsi with a bisection safeguard, bounded rounds) on the
pack charge at the end of the stretch phase, each round one engine run. Thermal
families fly from the mission's ambient temperature (``ambient_C``; default the
battery's, i.e. that of its fitted data).

State of charge is counted on the model capacity: ``SOC = 1 - q / (C * p)``
(``q`` pack charge removed, ``C`` cell capacity, ``p`` strings in parallel); the
reserve is a state of charge (e.g. land with 20 % left).

Mission files are TOML (see :func:`load_mission`); bundled examples are listed by
:func:`bundled_missions` and can be given by name, e.g. ``paper-table5``.

References
----------
.. [1] paper section 4.3, Table 5 and Fig. 11 (per-phase currents summed into a
   flight-time estimate), see ``../shared/paper``.
.. [2] J. D. Anderson, "Introduction to Flight", 8th ed., McGraw-Hill (2016),
   sections 6.3-6.8: drag polar ``C_D = C_D0 + C_L^2 / (pi e AR)``, power required
   ``P = D V``, rate of climb ``R/C = (P_available - P_required) / W``.
.. [3] J. G. Leishman, "Principles of Helicopter Aerodynamics", 2nd ed., Cambridge
   University Press (2006), chapter 2: hover power from momentum theory
   ``P = T^1.5 / sqrt(2 rho A)``, figure of merit, axial climb.
.. [4] ISO 2533:1975 / ICAO Doc 7488, Standard Atmosphere (troposphere).
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from . import engine
from .engine import Step
from .errors import DataError, SimulationError
from .model import CUTOFF_CELL_VOLTAGE_V, Battery, load_battery
from .simulate import SimulationResult

#: Standard acceleration of gravity [m/s^2] (ISO 80000-3).
STANDARD_GRAVITY_M_S2 = 9.80665

#: ISA sea-level air density [kg/m^3].
SEA_LEVEL_AIR_DENSITY_KG_M3 = 1.225

#: Engine time steps per phase of a flown mission (also its output samples per phase).
#: Constant-power phases are integrated with Heun's method: 25 steps keep the
#: endurance of the bundled missions within 1e-6 of a 1e-9-tolerance ODE solution.
POINTS_PER_PHASE = 25

#: Engine time steps per phase in searches and draws when the result does not depend
#: on the step (constant-current phases of a family whose only state is the charge).
EXACT_POINTS_PER_PHASE = 2

#: Tolerance of the longest stretch, as a fraction of the pack capacity in charge [-].
STRETCH_TOLERANCE = 1e-9

#: Bound on the rounds of the longest-stretch search.
STRETCH_MAX_ROUNDS = 40

#: Rungs of the candidate ladder per side in a round of the longest-stretch search
#: (offsets of 1, 10, ..., 10**(n-1) times half the tolerance).
STRETCH_LADDER = 10

#: Passes of a repeat-until block per engine run, at most.
MAX_PASSES_PER_RUN = 500

#: Engine runs of a repeat-until block before it is declared endless.
MAX_REPEAT_RUNS = 8

#: Range of ambient temperatures accepted for a mission [degC].
AMBIENT_RANGE_C = (-60.0, 90.0)

UNTIL_CHOICES = ("cutoff", "reserve")


# ---------------------------------------------------------------------------------------------
# Atmosphere and aircraft power (vectorised physics)
# ---------------------------------------------------------------------------------------------

def isa_air_density_kg_m3(altitude_m):
    """Air density of the ISA troposphere [kg/m^3] at geopotential altitude [m].

    ``T = 288.15 - 0.0065 h`` [K], ``p = 101325 (T / 288.15)^(g0 / (L R))`` [Pa],
    ``rho = p / (R T)`` with ``R = 287.05287 J/(kg K)``; valid from -500 m to 11 km.

    References
    ----------
    .. [1] ISO 2533:1975 / ICAO Doc 7488 Standard Atmosphere.
    """
    h = np.asarray(altitude_m, dtype=float)
    if np.any(h < -500.0) or np.any(h > 11000.0):
        raise DataError(f"altitude must be between -500 and 11000 m (ISA troposphere), got "
                        f"{altitude_m}")
    lapse, t0, p0, r_air = 0.0065, 288.15, 101325.0, 287.05287
    temperature = t0 - lapse * h
    pressure = p0 * (temperature / t0) ** (STANDARD_GRAVITY_M_S2 / (lapse * r_air))
    rho = pressure / (r_air * temperature)
    return float(rho) if rho.ndim == 0 else rho


def fixed_wing_power_W(speed_m_s, mass_kg, wing_area_m2, cd0, aspect_ratio, span_efficiency,
                       propulsion_efficiency, air_density_kg_m3=SEA_LEVEL_AIR_DENSITY_KG_M3,
                       climb_rate_m_s=0.0):
    """Electric power [W] of a fixed-wing aircraft in steady flight (parabolic drag polar).

    Lift equals weight (level flight; in a shallow climb ``cos(gamma) ~ 1``)::

        q   = rho V^2 / 2                      dynamic pressure [Pa]
        C_L = m g / (q S)
        C_D = C_D0 + C_L^2 / (pi e AR)
        D   = q S C_D                          drag [N]
        P   = (D V + m g V_climb) / eta        electric power [W]

    Parameters
    ----------
    speed_m_s : airspeed V [m/s]
    mass_kg : take-off mass m [kg]
    wing_area_m2 : wing reference area S [m^2]
    cd0 : zero-lift drag coefficient C_D0 [-]
    aspect_ratio : wing aspect ratio AR = b^2 / S [-]
    span_efficiency : Oswald span efficiency e [-]
    propulsion_efficiency : propeller x motor x controller efficiency eta [-]
    air_density_kg_m3 : air density rho [kg/m^3]
    climb_rate_m_s : rate of climb [m/s]; negative in a descent (power floored at 0 W, a glide)

    Returns
    -------
    float or numpy.ndarray
        Electric power drawn from the battery [W].

    References
    ----------
    .. [1] Anderson, Introduction to Flight, 8th ed., eqs. (6.1c), (6.26), (6.50).
    """
    v = np.asarray(speed_m_s, dtype=float)
    weight = np.asarray(mass_kg, dtype=float) * STANDARD_GRAVITY_M_S2
    dynamic_pressure = 0.5 * np.asarray(air_density_kg_m3, dtype=float) * v**2
    cl = weight / (dynamic_pressure * wing_area_m2)
    cd = cd0 + cl**2 / (math.pi * span_efficiency * aspect_ratio)
    drag = dynamic_pressure * wing_area_m2 * cd
    power = np.maximum((drag * v + weight * climb_rate_m_s) / propulsion_efficiency, 0.0)
    return float(power) if power.ndim == 0 else power


def hover_power_W(mass_kg, rotor_disc_area_m2, figure_of_merit, motor_efficiency,
                  air_density_kg_m3=SEA_LEVEL_AIR_DENSITY_KG_M3, climb_rate_m_s=0.0):
    """Electric power [W] of a multirotor in hover or axial climb (momentum theory).

    Thrust ``T = m g`` shared by all rotors of total disc area ``A``::

        P_ideal = T^1.5 / sqrt(2 rho A)            ideal induced power in hover
        P_hover = P_ideal / (FM * eta_motor)        electric power

    In a climb at ``V_c`` the ideal power grows by
    ``V_c / (2 v_h) + sqrt((V_c / (2 v_h))^2 + 1)`` with ``v_h = sqrt(T / (2 rho A))``
    (the same figure of merit is assumed).

    Parameters
    ----------
    mass_kg : mass m [kg]
    rotor_disc_area_m2 : total disc area of all rotors A [m^2]
    figure_of_merit : rotor figure of merit FM [-] (0.5-0.75 for small rotors)
    motor_efficiency : motor x controller efficiency [-]
    air_density_kg_m3 : air density rho [kg/m^3]
    climb_rate_m_s : axial climb rate V_c >= 0 [m/s]

    Returns
    -------
    float or numpy.ndarray
        Electric power [W].

    References
    ----------
    .. [1] Leishman, Principles of Helicopter Aerodynamics, 2nd ed., eqs. (2.14),
       (2.43) (figure of merit) and section 2.6 (axial climb).
    """
    thrust = np.asarray(mass_kg, dtype=float) * STANDARD_GRAVITY_M_S2
    rho = np.asarray(air_density_kg_m3, dtype=float)
    induced_hover = np.sqrt(thrust / (2.0 * rho * rotor_disc_area_m2))
    ideal = thrust * induced_hover  # = T^1.5 / sqrt(2 rho A)
    ratio_c = np.asarray(climb_rate_m_s, dtype=float) / (2.0 * induced_hover)
    climb_factor = ratio_c + np.sqrt(ratio_c**2 + 1.0)
    power = ideal * climb_factor / (figure_of_merit * motor_efficiency)
    return float(power) if power.ndim == 0 else power


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
        Title and mission file path.
    aircraft : dict or None
        The ``[aircraft]`` table used for flight-condition phases.
    ambient_C : float or None
        Ambient temperature [degC] the cells start at and cool to (thermal
        families); None = the battery's ``ambient_C`` (that of its fitted data).
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

TOP_KEYS = {"name", "description", "ambient_C", "battery", "aircraft", "phase"}
BATTERY_KEYS = {"source", "series", "parallel", "initial_soc_pct", "cutoff_cell_V", "reserve_pct"}
ATMOSPHERE_KEYS = {"altitude_m", "air_density_kg_m3"}
FIXED_WING_KEYS = {"mass_kg", "wing_area_m2", "cd0", "aspect_ratio", "span_m",
                   "span_efficiency", "propulsion_efficiency"} | ATMOSPHERE_KEYS
MULTIROTOR_KEYS = {"mass_kg", "rotor_disc_area_m2", "rotor_count", "rotor_diameter_m",
                   "figure_of_merit", "motor_efficiency"} | ATMOSPHERE_KEYS
AIRCRAFT_TYPES = ("fixed-wing", "multirotor")
LOAD_KEYS = ("current_A", "power_W", "speed_m_s", "hover")
PHASE_KEYS = {"name", "duration_s", "duration_min", "until", "stretch", "current_A", "power_W",
              "speed_m_s", "climb_rate_m_s", "hover", "repeat", "phases", "note"}


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


def parse_mission(data: dict, *, battery=None, base_dir=None, source: str = "",
                  cutoff_cell_V: float | None = None, reserve_pct: float | None = None,
                  ambient_C: float | None = None) -> Mission:
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
    """
    ctx = _Context(source)
    _check_keys(ctx, "", data, TOP_KEYS)
    name = data.get("name", Path(source).stem if source else "mission")
    if not isinstance(name, str):
        raise ctx.error("", "name must be a string")
    bat_table = data.get("battery", {})
    _check_keys(ctx, "[battery]", bat_table, BATTERY_KEYS)
    if battery is None:
        src = bat_table.get("source")
        if src is None:
            raise ctx.error("[battery]", "no battery: pass a battery file or preset, or set "
                                         "source = 'battery.json' | preset name")
        if not isinstance(src, str):
            raise ctx.error("[battery]", "source must be a battery file path or a preset name")
        candidate = Path(base_dir or ".") / src
        battery = load_battery(candidate if candidate.exists() else src)
    else:
        battery = load_battery(battery)
    series = _integer(ctx, "[battery]", bat_table, "series")
    parallel = _integer(ctx, "[battery]", bat_table, "parallel")
    battery = battery.with_pack(series, parallel)
    soc0 = _number(ctx, "[battery]", bat_table, "initial_soc_pct", positive=True, maximum=100,
                   default=100.0)
    reserve = reserve_pct if reserve_pct is not None else _number(
        ctx, "[battery]", bat_table, "reserve_pct", minimum=0, maximum=99.9, default=20.0)
    cutoff = cutoff_cell_V if cutoff_cell_V is not None else _number(
        ctx, "[battery]", bat_table, "cutoff_cell_V", positive=True)
    if cutoff is None:
        cutoff = CUTOFF_CELL_VOLTAGE_V.get(battery.chemistry or "")
        if cutoff is None:
            raise ctx.error("[battery]", "battery chemistry unknown: give cutoff_cell_V "
                                         "(or --cutoff V)")
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
                       ambient_C=None if ambient_C is None else float(ambient_C))
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
                 reserve_pct: float | None = None, ambient_C: float | None = None) -> Mission:
    """Read a mission TOML file.

    Format (all keys with units in their names)::

        name = "survey"
        ambient_C = 35             # optional: air temperature [degC] for thermal models
                                   # (default: the battery file's, that of its fitted data)
        [battery]                  # all optional
        source = "battery.json"    # or a preset name; the command-line battery wins
        series = 4                 # override the battery file's pack configuration
        parallel = 1
        initial_soc_pct = 100
        cutoff_cell_V = 3.3        # default by chemistry
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
    path = mission_path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML ({exc})") from None
    except UnicodeDecodeError:
        raise DataError(f"{path}: not a UTF-8 text file") from None
    return parse_mission(data, battery=battery, base_dir=path.parent, source=str(path),
                         cutoff_cell_V=cutoff_cell_V, reserve_pct=reserve_pct,
                         ambient_C=ambient_C)


# ---------------------------------------------------------------------------------------------
# Flying a mission through the engine
# ---------------------------------------------------------------------------------------------

@dataclass
class _Leg:
    """Flights in progress: one entry per flight, arrays of shape (entries,).

    ``rows`` maps each entry to its parameter draw (the stretch search flies
    several candidate flights per draw). ``steps``, ``labels`` and ``series`` are
    only kept for a recorded flight (one draw).
    """

    rows: np.ndarray
    end_s: np.ndarray              # time since take-off [s]
    charge_Ah: np.ndarray          # pack charge removed [Ah]
    ended_by: np.ndarray           # "end" while the flight goes on
    energy_Wh: np.ndarray          # energy delivered [Wh]
    min_voltage_V: np.ndarray      # lowest pack voltage so far [V]
    peak_temperature_C: np.ndarray
    state: dict                    # cell states of the engine
    steps: list = field(default_factory=list)
    labels: list = field(default_factory=list)   # (phase name, item index, repetition)
    series: list = field(default_factory=list)   # engine series, time from take-off

    @property
    def going(self) -> np.ndarray:
        """Entries still flying."""
        return self.ended_by == "end"

    def take(self, index) -> _Leg:
        """A copy of the entries ``index`` (nothing recorded)."""
        def pick(values):
            return np.array(values[index], copy=True)

        return _Leg(pick(self.rows), pick(self.end_s), pick(self.charge_Ah), pick(self.ended_by),
                    pick(self.energy_Wh), pick(self.min_voltage_V), pick(self.peak_temperature_C),
                    {k: pick(v) for k, v in self.state.items()})


class _Flyer:
    """Flies mission steps for one or many parameter draws through :func:`engine.run`.

    Parameters
    ----------
    mission : Mission
    params : mapping, optional
        ``{name: value or array of draws}``; default the battery's parameters.
    points : int
        Engine time steps per phase (``steps_per_discharge`` of the engine).
    record : bool
        Keep the time series (one draw only).
    """

    def __init__(self, mission: Mission, params=None, *, points: int, record: bool = False):
        battery = mission.battery
        values = dict(battery.parameters if params is None else params)
        arrays = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in values.items()}
        self.m = max(v.size for v in arrays.values())
        self.params = {k: np.broadcast_to(v, (self.m,)) for k, v in arrays.items()}
        self.mission = mission
        self.points = max(int(points), 1)
        self.record = record
        self.capacity = self.params["C_Ah"] * battery.strings_parallel
        self.q_start = (1.0 - mission.initial_soc_pct / 100.0) * self.capacity
        self.q_reserve = (1.0 - mission.reserve_pct / 100.0) * self.capacity

    def start(self) -> _Leg:
        """Every draw on the ground, charged to the take-off state of charge."""
        fam = self.mission.battery.family
        ambient = self.mission.resolved_ambient_C
        state = fam.initial_state(self.params, temperature_C=ambient,
                                  charge_Ah=self.q_start / self.mission.battery.strings_parallel)
        m = self.m
        return _Leg(np.arange(m), np.zeros(m), self.q_start.copy(), np.full(m, "end", object),
                    np.zeros(m), np.full(m, np.inf),
                    np.broadcast_to(np.asarray(fam.temperature_C(state, ambient), float),
                                    (m,)).copy(), state)

    def run(self, leg: _Leg, steps, labels=(), *, reserve=None, only=None) -> _Leg:
        """Continue the flights of ``leg`` through ``steps``.

        Parameters
        ----------
        leg : _Leg
        steps : sequence of Step
        labels : sequence
            Phase label of each step (recorded flight).
        reserve : numpy.ndarray, optional
            Per entry: stop ("reserve") when the pack charge removed reaches it [Ah].
        only : numpy.ndarray of bool, optional
            Fly only these entries (the others keep their state).
        """
        steps = list(steps)
        out = leg.take(slice(None))
        if self.record:
            out.steps, out.labels = leg.steps + steps, leg.labels + list(labels)
            out.series = list(leg.series)
        fly = leg.going if only is None else leg.going & only
        idx = np.flatnonzero(fly)
        if not steps or idx.size == 0:
            return out
        bat = self.mission.battery
        try:
            res = engine.run(
                bat.family, {k: v[leg.rows[idx]] for k, v in self.params.items()}, steps,
                cutoff_pack_V=self.mission.cutoff_pack_V, cells_series=bat.cells_series,
                strings_parallel=bat.strings_parallel, ambient_C=self.mission.resolved_ambient_C,
                initial_state={k: v[idx] for k, v in leg.state.items()},
                reserve_charge_Ah=None if reserve is None else np.asarray(reserve)[idx],
                record=self.record, steps_per_discharge=self.points)
        except SimulationError as exc:
            raise SimulationError(f"mission {self.mission.name!r}: {exc}") from None
        out.end_s[idx] += res.end_s
        out.charge_Ah[idx] = res.charge_end_Ah
        out.ended_by[idx] = res.ended_by
        out.energy_Wh[idx] += res.energy_Wh
        lowest = np.min([s.min_voltage_V for s in res.steps], axis=0)
        out.min_voltage_V[idx] = np.minimum(out.min_voltage_V[idx], lowest)
        out.peak_temperature_C[idx] = np.maximum(out.peak_temperature_C[idx],
                                                 res.peak_temperature_C)
        for name in out.state:
            out.state[name][idx] = res.final_state[name]
        if self.record and res.series["time_s"].size:
            series = dict(res.series)
            series["time_s"] = series["time_s"] + leg.end_s[0]
            series["step"] = series["step"] + len(leg.steps)
            out.series.append(series)
        return out


def _expand(items, first_index: int = 0, stretch_s: float | None = None):
    """Steps and labels of fixed items (repeat-until blocks are flown by _repeat_until)."""
    steps, labels = [], []
    for k, item in enumerate(items, start=first_index):
        if isinstance(item, RepeatBlock):
            for r in range(item.count or 0):
                for ph in item.phases:
                    steps.append(ph.to_step(ph.duration_s))
                    labels.append((ph.name, k, r + 1))
        else:
            steps.append(item.to_step(stretch_s if item.stretch else item.duration_s))
            labels.append((item.name, k, None))
    return steps, labels


def _pass_charge_estimate_Ah(mission: Mission, block: RepeatBlock) -> float:
    """Charge of one block pass at the pack's rest voltage when full (only to size a batch)."""
    nominal_V = max(float(mission.battery.voltage(0.0, 0.0)), 0.1 * mission.battery.cells_series)
    charge = 0.0
    for ph in block.phases:
        current = ph.value if ph.kind == "current" else ph.value / nominal_V
        charge += current * ph.duration_s / 3600.0
    return max(charge, 1e-12)


def _repeat_until(fl: _Flyer, leg: _Leg, block: RepeatBlock, index: int, reserve) -> _Leg:
    """Fly a final repeat-until block in batches of passes until every flight ended.

    Bounded: at most :data:`MAX_REPEAT_RUNS` engine runs of at most
    :data:`MAX_PASSES_PER_RUN` passes each.
    """
    per_pass = _pass_charge_estimate_Ah(fl.mission, block)
    done = 0
    for _ in range(MAX_REPEAT_RUNS):
        going = leg.going
        if not going.any():
            return leg
        left = float(np.max(fl.capacity[leg.rows[going]] - leg.charge_Ah[going]))
        passes = int(min(MAX_PASSES_PER_RUN, math.ceil(1.3 * left / per_pass) + 1))
        steps, labels = [], []
        for r in range(done + 1, done + passes + 1):
            for ph in block.phases:
                steps.append(ph.to_step(ph.duration_s))
                labels.append((ph.name, index, r))
        leg = fl.run(leg, steps, labels, reserve=reserve)
        done += passes
    if leg.going.any():
        raise SimulationError(
            f"mission {fl.mission.name!r}: repeat block {block.name!r} did not reach the "
            f"{block.until} within {done} passes: the model never reaches the {block.until} "
            f"under this load (check the loads and the battery's capacity)")
    return leg


def _fly(fl: _Flyer, stretch_s: float | None = None) -> _Leg:
    """Fly the whole mission (the stretch phase for ``stretch_s``); the reserve only
    stops a final 'until reserve' item."""
    items = fl.mission.items
    last = items[-1]
    head = items[:-1] if last.until is not None else items
    steps, labels = _expand(head, 0, stretch_s)
    leg = fl.run(fl.start(), steps, labels)
    if last.until is None:
        return leg
    k = len(items) - 1
    reserve = fl.q_reserve[leg.rows] if last.until == "reserve" else None
    if isinstance(last, RepeatBlock):
        return _repeat_until(fl, leg, last, k, reserve)
    return fl.run(leg, [last.to_step(None)], [(last.name, k, None)], reserve=reserve)


def _exact_in_time(mission: Mission) -> bool:
    """True when the engine's answer does not depend on its step size (constant-current
    phases, a family whose only state is the charge: exact integration)."""
    fam = mission.battery.family
    return all(st.kind == "charge" for st in fam.states) and \
        all(ph.kind == "current" for ph in mission.phases())


def _search_points(mission: Mission, points: int) -> int:
    return EXACT_POINTS_PER_PHASE if _exact_in_time(mission) else points


# ---------------------------------------------------------------------------------------------
# The longest stretch: bracketed secant per draw over the engine
# ---------------------------------------------------------------------------------------------

def _try_stretch(fl: _Flyer, pre: _Leg, phase: Phase, suffix, target) -> dict:
    """Fly the stretch phase until the pack charge ``target`` [Ah], then the rest.

    Returns per entry the feasibility margin ``g`` (>= 0 feasible: the rest ends
    at or above the reserve without reaching the cutoff), the stretch duration
    and the flight's end. ``g`` falls monotonically through 0 at the longest
    stretch: ``min(SOC gap, voltage gap)`` when completed, minus the fraction of
    the remaining phases not flown when the cutoff came first, below -1 when the
    stretch phase itself reached the cutoff before ``target``.
    """
    rows = pre.rows
    need = target > pre.charge_Ah
    flown = fl.run(pre, [phase.to_step(None)], reserve=target, only=need)
    reached = np.where(need, flown.ended_by == "reserve", pre.going)
    stop_q = flown.charge_Ah.copy()
    flown.ended_by = np.where(reached, "end", flown.ended_by).astype(object)
    after = fl.run(flown, suffix)
    cap = fl.capacity[rows]
    soc_gap = (fl.q_reserve[rows] - after.charge_Ah) / cap
    cutoff = fl.mission.cutoff_pack_V
    volt_gap = (after.min_voltage_V - cutoff) / cutoff
    planned = float(sum(st.duration_s for st in suffix))
    if planned > 0:
        left = np.maximum(planned - (after.end_s - flown.end_s), 0.0) / planned
    else:
        left = np.zeros(rows.size)
    completed = after.going
    g = np.where(completed, np.minimum(soc_gap, volt_gap), -left - 1e-12)
    short = -(1.0 if planned > 0 else 0.0) - np.maximum(target - stop_q, 0.0) / cap - 1e-12
    g = np.where(reached, g, short)
    return {"g": g, "stretch_s": flown.end_s - pre.end_s,
            "end_s": after.end_s, "charge_Ah": after.charge_Ah, "completed": completed,
            "soc_gap": np.where(completed, soc_gap, g),
            "volt_gap": np.where(completed, volt_gap, g)}


def _crossing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Fraction of the bracket where a line from ``a`` (>= 0) to ``b`` (< 0) crosses 0;
    NaN where it does not."""
    cross = (a >= 0) & (b < 0)
    return np.where(cross, a / np.where(cross, a - b, 1.0), np.nan)


def _secant_fraction(lo: dict, hi: dict) -> np.ndarray:
    """Where in the bracket the margin crosses 0: linear interpolation of the state of
    charge gap and of the voltage gap, the first crossing wins (each is nearly linear
    in the charge, their minimum is not); the margin itself when neither crosses."""
    both = np.fmin(_crossing(lo["soc_gap"], hi["soc_gap"]),
                   _crossing(lo["volt_gap"], hi["volt_gap"]))
    return np.where(np.isfinite(both), both, _crossing(lo["g"], hi["g"]))


def _search_stretch(fl: _Flyer) -> dict:
    """Longest stretch per draw (arrays): ``max_s``, ``feasible``, ``binding`` and the
    flight at the longest stretch (``end_s``, ``charge_Ah``, ``completed``).

    The unknown is the pack charge at the end of the stretch phase, between its
    start and the reserve. Each round flies, for every unfinished draw at once, a
    ladder of candidates around the regula-falsi point (Illinois variant; the
    bracket's middle when three rounds did not halve it): offsets of +-1, 10,
    100, ... times half the tolerance, so the next bracket is at most one rung
    wide and a nearly linear margin is bracketed to the tolerance in one or two
    rounds. At most :data:`STRETCH_MAX_ROUNDS` rounds.
    """
    mission = fl.mission
    k = mission.stretch_index
    phase = mission.items[k]
    pre_steps, _ = _expand(mission.items[:k])
    suffix, _ = _expand(mission.items[k + 1:], k + 1)
    pre = fl.run(fl.start(), pre_steps)
    m = fl.m
    lo = pre.charge_Ah.copy()
    hi = np.maximum(fl.q_reserve, lo)
    both = np.r_[np.arange(m), np.arange(m)]
    ends = _try_stretch(fl, pre.take(both), phase, suffix, np.r_[lo, hi])
    best = {key: value[:m].copy() for key, value in ends.items()}
    upper = {key: value[m:].copy() for key, value in ends.items()}
    feasible = best["g"] >= 0
    top_ok = feasible & (upper["g"] >= 0)
    for key in best:
        best[key] = np.where(top_ok, upper[key], best[key])
    lo = np.where(top_ok, hi, lo)
    tol = STRETCH_TOLERANCE * fl.capacity
    active = feasible & ~top_ok & (hi - lo > tol)
    kept = np.zeros((2, m))           # rounds each side of the bracket was kept in a row
    width = [np.full(m, np.inf)] * 2 + [hi - lo]     # bracket widths of the last rounds
    rungs = 10.0 ** np.arange(STRETCH_LADDER)
    for _ in range(STRETCH_MAX_ROUNDS):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        span = hi[idx] - lo[idx]
        weight = 0.5 ** np.maximum(kept[:, idx] - 1.0, 0.0)    # Illinois
        frac = _secant_fraction({k: v[idx] * weight[0] for k, v in best.items()},
                                {k: v[idx] * weight[1] for k, v in upper.items()})
        stuck = span > 0.5 * width[0][idx]          # no halving in three rounds: bisect
        x = lo[idx] + span * np.where(stuck, 0.5, frac)
        d = 0.45 * tol[idx]
        offsets = d[:, None] * np.r_[-rungs[::-1], rungs][None, :]
        cands = np.clip(x[:, None] + offsets, (lo[idx] + 0.5 * d)[:, None],
                        (hi[idx] - 0.5 * d)[:, None])
        n, width_c = cands.shape
        ev = _try_stretch(fl, pre.take(np.repeat(idx, width_c)), phase, suffix, cands.ravel())
        g = ev["g"].reshape(n, width_c)
        rows = np.arange(n)
        top = np.argmax(np.where(g >= 0, cands, -np.inf), axis=1)     # highest feasible
        bottom = np.argmin(np.where(g < 0, cands, np.inf), axis=1)     # lowest infeasible
        up = (g[rows, top] >= 0) & (cands[rows, top] > lo[idx])
        down = (g[rows, bottom] < 0) & (cands[rows, bottom] < hi[idx])
        lo[idx[up]] = cands[rows, top][up]
        hi[idx[down]] = cands[rows, bottom][down]
        for key in best:
            values = ev[key].reshape(n, width_c)
            best[key][idx[up]] = values[rows, top][up]
            upper[key][idx[down]] = values[rows, bottom][down]
        kept[:, idx] = np.where(np.vstack([up, down]), 0.0, kept[:, idx] + 1.0)
        width = width[1:] + [hi - lo]
        active &= hi - lo > tol
    binding = np.where(~feasible, "infeasible",
                       np.where(best["soc_gap"] <= best["volt_gap"], "reserve", "cutoff"))
    return {"max_s": np.where(feasible, best["stretch_s"], 0.0), "feasible": feasible,
            "binding": binding, "end_s": best["end_s"], "charge_Ah": best["charge_Ah"],
            "completed": best["completed"]}


def mission_outcomes(mission: Mission, params=None, *,
                     points_per_step: int | None = None) -> dict:
    """Scalar outcomes of a mission for one or many parameter sets, flown at once.

    Parameters
    ----------
    mission : Mission
    params : mapping, optional
        ``{name: value or array of draws}`` per cell; default the battery's.
    points_per_step : int, optional
        Engine time steps per phase (default :data:`POINTS_PER_PHASE`).

    Returns
    -------
    dict
        Arrays per draw: ``endurance_s``, ``flight_time_s``, ``soc_end_pct``,
        ``completed`` and, with a stretch phase, ``max_stretch_s`` and ``binding``.
    """
    points = _search_points(mission, POINTS_PER_PHASE if points_per_step is None
                            else points_per_step)
    fl = _Flyer(mission, params, points=points)
    k = mission.stretch_index
    out = {}
    if k is None:
        leg = _fly(fl)
        flight, charge = leg.end_s, leg.charge_Ah
        completed = (leg.ended_by == "end") | (leg.ended_by == "reserve")
        endurance = flight.copy()
    else:
        found = _search_stretch(fl)
        planned = mission.items[k].duration_s
        if planned is None:
            flight, charge, completed = found["end_s"], found["charge_Ah"], found["completed"]
            flown = found["max_s"]
        else:
            leg = _fly(fl, planned)
            flight, charge = leg.end_s, leg.charge_Ah
            completed = (leg.ended_by == "end") | (leg.ended_by == "reserve")
            flown = planned
        endurance = np.where(found["feasible"], flight - flown + found["max_s"], flight)
        out.update(max_stretch_s=found["max_s"], binding=found["binding"])
    out.update(flight_time_s=flight, endurance_s=endurance, completed=completed.astype(bool),
               soc_end_pct=100.0 * (1.0 - charge / fl.capacity))
    return out


def max_stretch_s(mission: Mission, *, points: int | None = None) -> dict:
    """Longest duration of the stretch phase that still completes the mission.

    The remaining phases must end at or above the reserve and never reach the
    cutoff; found per draw by a bracketed secant over the engine (see
    :func:`_search_stretch`), to :data:`STRETCH_TOLERANCE` of the capacity in charge.

    Parameters
    ----------
    mission : Mission
    points : int, optional
        Engine time steps per phase (default :data:`POINTS_PER_PHASE`).

    Returns
    -------
    dict
        ``phase`` (name), ``planned_s`` (None when not given), ``max_s`` [s],
        ``margin_s`` (max - planned, None without a plan) and ``binding``:
        "reserve" (the mission ends exactly at the reserve), "cutoff" (a later
        phase would reach the cutoff) or "infeasible" (even a zero-length stretch
        does not complete the mission; ``max_s`` is 0).
    """
    k = mission.stretch_index
    if k is None:
        raise DataError("the mission has no phase with stretch = true")
    phase = mission.items[k]
    fl = _Flyer(mission, points=_search_points(mission, POINTS_PER_PHASE if points is None
                                               else points))
    found = _search_stretch(fl)
    max_s = float(found["max_s"][0])
    binding = str(found["binding"][0])
    if binding == "infeasible":
        margin = None if phase.duration_s is None else -phase.duration_s
    else:
        margin = None if phase.duration_s is None else max_s - phase.duration_s
    return {"phase": phase.name, "planned_s": phase.duration_s, "max_s": max_s,
            "binding": binding, "margin_s": margin}


def _simulation(mission: Mission, leg: _Leg) -> SimulationResult:
    """The recorded flight (one draw) as a SimulationResult."""
    keys = ("time_s", "current_A", "voltage_V", "charge_Ah", "temperature_C", "step")
    if leg.series:
        ser = {key: np.concatenate([s[key] for s in leg.series]) for key in keys}
    else:  # nothing flown (every phase of zero length): the pack at take-off
        q0 = mission.initial_charge_Ah
        ser = {"time_s": np.zeros(1), "current_A": np.zeros(1),
               "voltage_V": np.atleast_1d(mission.battery.voltage(0.0, q0)).astype(float),
               "charge_Ah": np.full(1, q0), "step": np.zeros(1, dtype=int),
               "temperature_C": np.full(1, mission.resolved_ambient_C)}
    if str(leg.ended_by[0]) == "cutoff":
        # a load step that starts below the cutoff ends the flight as its load rises
        # through the cutoff: the flight ends at the cutoff voltage
        ser["voltage_V"] = ser["voltage_V"].copy()
        ser["voltage_V"][-1] = mission.cutoff_pack_V
    power = ser["current_A"] * ser["voltage_V"]
    t = ser["time_s"]
    energy = np.zeros_like(t)
    if t.size > 1:
        np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t), out=energy[1:])
    return SimulationResult(
        time_s=t, current_A=ser["current_A"], voltage_V=ser["voltage_V"], power_W=power,
        charge_Ah=ser["charge_Ah"], energy_Wh=energy / 3600.0, step=ser["step"].astype(int),
        steps=list(leg.steps) or [Step("rest", 0.0, 0.0)], cutoff_pack_V=mission.cutoff_pack_V,
        ended_by=str(leg.ended_by[0]), battery=mission.battery,
        initial_charge_Ah=mission.initial_charge_Ah, temperature_C=ser["temperature_C"],
        ambient_C=mission.resolved_ambient_C)


@dataclass
class MissionResult:
    """A flown mission: time series, per-phase table, endurance, margins, warnings.

    Attributes
    ----------
    mission : Mission
    simulation : SimulationResult
        Pack-level time series of the flight as flown.
    phases : list of dict
        Per flown phase: name, repetition, start/end [s], charge [Ah], energy [Wh],
        mean current [A] and power [W], end voltage [V], end state of charge [%].
    completed : bool
        All phases flown without reaching the cutoff (or power limit).
    ended_by : {"end", "cutoff", "power limit", "reserve"}
    flight_time_s : float
        Duration of the flight as flown [s].
    endurance_s : float
        Headline flight time [s]: with a stretch phase, the flight with the longest
        stretch (landing at the reserve); otherwise the flight as flown.
    cutoff_time_s, reserve_time_s : float
        When the cutoff / reserve was reached during the flight (NaN if not).
    stretch : dict or None
        See :func:`max_stretch_s`.
    uncertainty : dict or None
        See :func:`dischargelab.uncertainty.mission_uncertainty`.
    warnings : list of str
    """

    mission: Mission
    simulation: SimulationResult
    labels: list
    phases: list
    completed: bool
    ended_by: str
    flight_time_s: float
    endurance_s: float
    cutoff_time_s: float
    reserve_time_s: float
    soc_end_pct: float
    min_voltage_V: float
    stretch: dict | None
    warnings: list
    uncertainty: dict | None = None

    @property
    def soc_pct(self) -> np.ndarray:
        """State of charge through the flight [%]."""
        return 100.0 * (1.0 - self.simulation.charge_Ah / self.mission.capacity_Ah)

    @property
    def voltage_margin_V(self) -> float:
        """Lowest pack voltage in flight minus the pack cutoff [V]."""
        return self.min_voltage_V - self.mission.cutoff_pack_V

    def to_pandas(self):
        """Time series: time_s, voltage_V, current_A, power_W, charge_Ah, soc_pct, phase."""
        df = self.simulation.to_pandas()
        df["soc_pct"] = self.soc_pct
        df["phase"] = [_label_text(self.labels[k]) for k in self.simulation.step]
        return df.drop(columns=["step"])

    def to_dict(self) -> dict:
        """Summary for JSON output (keys are only ever added, never renamed)."""
        m = self.mission
        out = {
            "mission": m.name,
            "source": m.source,
            "battery": m.battery.name,
            "cells_series": m.battery.cells_series,
            "strings_parallel": m.battery.strings_parallel,
            "capacity_Ah": m.capacity_Ah,
            "cutoff_cell_V": m.cutoff_cell_V,
            "cutoff_pack_V": m.cutoff_pack_V,
            "reserve_pct": m.reserve_pct,
            "initial_soc_pct": m.initial_soc_pct,
            "completed": self.completed,
            "ended_by": self.ended_by,
            "flight_time_s": self.flight_time_s,
            "endurance_s": self.endurance_s,
            "cutoff_time_s": self.cutoff_time_s,
            "reserve_time_s": self.reserve_time_s,
            "soc_end_pct": self.soc_end_pct,
            "soc_margin_pct": self.soc_end_pct - m.reserve_pct,
            "min_voltage_V": self.min_voltage_V,
            "voltage_margin_V": self.voltage_margin_V,
            "charge_used_Ah": self.simulation.capacity_Ah,
            "energy_used_Wh": self.simulation.energy_Wh_total,
            "stretch": self.stretch,
            "model": m.battery.model,
            "ambient_C": m.resolved_ambient_C,
            "peak_temperature_C": self.simulation.peak_temperature_C,
            "phases": self.phases,
            "uncertainty": self.uncertainty,
            "warnings": list(self.warnings),
        }
        return out

    def plot(self, ax=None, **kwargs):
        """Voltage through the flight with the phases shaded (paper Fig. 11); returns the Axes."""
        from .plot import plot_mission

        return plot_mission(self, ax=ax, **kwargs)


def _label_text(label) -> str:
    name, _, rep = label
    return name if rep is None else f"{name} #{rep}"


def _phase_detail(mission: Mission, label) -> dict:
    name, index, _ = label
    item = mission.items[index]
    phases = item.phases if isinstance(item, RepeatBlock) else (item,)
    return next((dict(ph.detail) for ph in phases if ph.name == name), {})


def _phase_table(mission: Mission, sim: SimulationResult, labels: list) -> list[dict]:
    rows = []
    for k, label in enumerate(labels):
        sel = np.flatnonzero(sim.step == k)
        if sel.size == 0:
            continue
        a, b = sel[0], sel[-1]
        # each step starts where the previous ended
        t0 = sim.time_s[a - 1] if a > 0 else sim.time_s[a]
        q0 = sim.charge_Ah[a - 1] if a > 0 else sim.charge_Ah[a]
        e0 = sim.energy_Wh[a - 1] if a > 0 else sim.energy_Wh[a]
        duration = float(sim.time_s[b] - t0)
        charge = float(sim.charge_Ah[b] - q0)
        energy = float(sim.energy_Wh[b] - e0)
        st = sim.steps[k]
        rows.append({
            "phase": label[0],
            "repetition": label[2],
            "load": f"{st.value:g} A" if st.kind == "current" else f"{st.value:.4g} W",
            "start_s": float(t0),
            "end_s": float(sim.time_s[b]),
            "duration_s": duration,
            "charge_Ah": charge,
            "energy_Wh": energy,
            "mean_current_A": charge * 3600.0 / duration if duration > 0 else
            float(sim.current_A[b]),
            "max_current_A": float(np.max(sim.current_A[sel])),
            "mean_power_W": energy * 3600.0 / duration if duration > 0 else
            float(sim.power_W[b]),
            "end_voltage_V": float(sim.voltage_V[b]),
            "end_soc_pct": float(100.0 * (1.0 - sim.charge_Ah[b] / mission.capacity_Ah)),
        })
        detail = _phase_detail(mission, label)
        if detail:
            rows[-1]["flight_condition"] = detail
    return rows


def _crossing_time(sim: SimulationResult, q_target: float) -> float:
    """First time the charge reaches ``q_target`` (NaN if never)."""
    idx = np.flatnonzero(sim.charge_Ah >= q_target * (1.0 - 1e-9))
    if idx.size == 0:
        return float("nan")
    k = int(idx[0])
    if k == 0:
        return float(sim.time_s[0])
    return float(np.interp(q_target, sim.charge_Ah[k - 1:k + 1], sim.time_s[k - 1:k + 1]))


def extrapolation_warnings(battery: Battery, phase_rows: list[dict]) -> list[str]:
    """Warn when phase cell currents lie far outside the currents the battery was fitted at.

    See :meth:`dischargelab.model.Battery.extrapolation` (more than 2x above the
    highest or below half the lowest fitted cell current).
    """
    fitted = [abs(x) for x in battery.fit_currents_A if x]
    if not fitted:
        return ["the battery file lists no fit currents; cannot check whether the mission "
                "currents lie inside the fitted range"]
    p = battery.strings_parallel
    found = {"above": {}, "below": {}}
    for row in phase_rows:
        cell = row["mean_current_A"] / p
        side = battery.extrapolation(cell)
        if side:
            found[side].setdefault(row["phase"], cell)
    from .predict import extrapolation_warning

    out = []
    for side, phases in found.items():
        if phases:
            # the phase furthest out speaks for the group, in the one wording of predict/curves
            worst = max(phases.values(), key=battery.extrapolation_ratio)
            names = ", ".join(f"{n} ({c:.3g} A)" for n, c in phases.items())
            out.append(f"{extrapolation_warning(battery, worst, side)} [phases: {names}]")
    return out


def run_mission(mission: Mission, *, draws: int = 0, seed: int = 0,
                points_per_step: int = POINTS_PER_PHASE, progress=None) -> MissionResult:
    """Fly a mission: time series, endurance, maximum stretch, margins and warnings.

    Parameters
    ----------
    mission : Mission
    draws : int
        Parameter draws for the 95 % interval of the endurance (0 = no interval); see
        :func:`dischargelab.uncertainty.mission_uncertainty` (a battery without draws
        gets the model error alone).
    seed : int
        Seed of the draws.
    points_per_step : int
        Engine time steps (output samples) per phase.
    progress : callable, optional
        ``progress(done, total)`` during the uncertainty draws.

    Returns
    -------
    MissionResult

    Raises
    ------
    SimulationError
        One line when the model never reaches the cutoff (or a repeat block its end).
    """
    stretch = max_stretch_s(mission, points=points_per_step) \
        if mission.stretch_index is not None else None
    stretch_flown = None
    if stretch is not None:
        planned = stretch["planned_s"]
        stretch_flown = stretch["max_s"] if planned is None else planned
    leg = _fly(_Flyer(mission, points=points_per_step, record=True), stretch_flown)
    sim = _simulation(mission, leg)
    ended_by = sim.ended_by
    completed = ended_by in ("end", "reserve")
    cutoff_time = sim.duration_s if ended_by in ("cutoff", "power limit") else float("nan")
    reserve_time = _crossing_time(sim, mission.reserve_charge_Ah)
    flight_time = sim.duration_s
    endurance = flight_time
    if stretch is not None and stretch["binding"] != "infeasible":
        endurance = flight_time - stretch_flown + stretch["max_s"]
    labels = leg.labels[:int(sim.step.max()) + 1]
    rows = _phase_table(mission, sim, labels)
    soc_end = float(100.0 * (1.0 - sim.charge_Ah[-1] / mission.capacity_Ah))
    warnings = []
    if not completed:
        where = _label_text(labels[-1])
        warnings.append(f"the mission does not complete: the {ended_by} is reached "
                        f"after {flight_time:.0f} s, during '{where}'")
    elif soc_end < mission.reserve_pct - 1e-6:
        warnings.append(f"the flight ends at {soc_end:.1f} % state of charge, below the "
                        f"{mission.reserve_pct:g} % reserve (reached at {reserve_time:.0f} s)")
    if stretch is not None:
        if stretch["binding"] == "infeasible":
            warnings.append(f"even without '{stretch['phase']}' the mission cannot be completed "
                            f"within the reserve and cutoff")
        elif stretch["margin_s"] is not None and stretch["margin_s"] < 0:
            warnings.append(f"planned '{stretch['phase']}' of {stretch['planned_s']:.0f} s is "
                            f"{-stretch['margin_s']:.0f} s longer than the maximum "
                            f"{stretch['max_s']:.0f} s")
    warnings += extrapolation_warnings(mission.battery, rows)
    result = MissionResult(
        mission=mission, simulation=sim, labels=labels, phases=rows,
        completed=completed, ended_by=ended_by, flight_time_s=flight_time,
        endurance_s=float(endurance), cutoff_time_s=cutoff_time, reserve_time_s=reserve_time,
        soc_end_pct=soc_end, min_voltage_V=float(np.min(sim.voltage_V)), stretch=stretch,
        warnings=warnings,
    )
    if draws:
        from .uncertainty import mission_uncertainty

        result.uncertainty = mission_uncertainty(mission, draws=draws, seed=seed,
                                                 progress=progress, nominal=result,
                                                 points_per_step=points_per_step)
        result.warnings += result.uncertainty.get("warnings", [])
    return result


def mission_summary(mission: Mission, *, points_per_step: int = POINTS_PER_PHASE) -> dict:
    """Scalar outcomes of a mission with the battery's own parameters (no time series).

    Returns ``endurance_s``, ``flight_time_s``, ``soc_end_pct``, ``completed`` and,
    with a stretch phase, ``max_stretch_s`` (see :func:`mission_outcomes`).
    """
    found = mission_outcomes(mission, points_per_step=points_per_step)
    out = {key: (bool(value[0]) if key == "completed" else
                 str(value[0]) if key == "binding" else float(value[0]))
           for key, value in found.items()}
    out.pop("binding", None)
    return out


__all__ = [
    "Phase", "RepeatBlock", "Mission", "MissionResult", "load_mission", "parse_mission",
    "run_mission", "max_stretch_s", "mission_summary", "mission_outcomes",
    "extrapolation_warnings",
    "fixed_wing_power_W", "hover_power_W", "isa_air_density_kg_m3",
    "STANDARD_GRAVITY_M_S2", "SEA_LEVEL_AIR_DENSITY_KG_M3",
]
