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

from .aircraft import (
    SEA_LEVEL_AIR_DENSITY_KG_M3,
    STANDARD_GRAVITY_M_S2,
    fixed_wing_power_W,
    hover_power_W,
    isa_air_density_kg_m3,
)
from .fly import (
    EXACT_POINTS_PER_PHASE,
    MAX_PASSES_PER_RUN,
    MAX_REPEAT_RUNS,
    POINTS_PER_PHASE,
    max_stretch_s,
    mission_outcomes,
)
from .result import (
    MissionResult,
    extrapolation_warnings,
    mission_extrapolation_ratio,
    mission_summary,
    mission_uncertainty,
    run_mission,
)
from .spec import (
    Mission,
    Phase,
    RepeatBlock,
    bundled_mission_text,
    bundled_missions,
    copy_mission,
    load_mission,
    mission_catalogue,
    mission_path,
    parse_mission,
)

__all__ = [
    "Phase", "RepeatBlock", "Mission", "MissionResult", "load_mission", "parse_mission",
    "run_mission", "max_stretch_s", "mission_summary", "mission_outcomes",
    "extrapolation_warnings", "mission_uncertainty", "mission_extrapolation_ratio",
    "bundled_missions", "mission_path", "mission_catalogue", "bundled_mission_text",
    "copy_mission", "POINTS_PER_PHASE", "EXACT_POINTS_PER_PHASE",
    "MAX_PASSES_PER_RUN", "MAX_REPEAT_RUNS",
    "fixed_wing_power_W", "hover_power_W", "isa_air_density_kg_m3",
    "STANDARD_GRAVITY_M_S2", "SEA_LEVEL_AIR_DENSITY_KG_M3",
]
