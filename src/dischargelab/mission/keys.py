"""Every key of a mission file (TOML), with its unit and default: the parser's own table.

The parser (:mod:`.spec`) takes its allowed keys from :data:`KEYS`, and the reference
page ``docs/mission-format.md`` is :func:`markdown` of it, so the page cannot drift
from what the parser accepts (a test compares them).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Key:
    """One key of a mission file.

    Attributes
    ----------
    table : str
        ``""`` (top level), ``"battery"``, ``"aircraft"``, ``"aircraft fixed-wing"``,
        ``"aircraft multirotor"`` or ``"phase"``.
    name : str
    unit : str
        Unit or value type (``"V"``, ``"whole number"``, ``"text"`` ...).
    default : str
        What applies when the key is left out (``"required"`` when it must be given).
    meaning : str
    """

    table: str
    name: str
    unit: str
    default: str
    meaning: str


KEYS: tuple[Key, ...] = (
    Key("", "name", "text", "the file's name", "Title of the mission."),
    Key("", "description", "text", "none", "Free text, not used by the calculation."),
    Key("", "ambient_C", "degC", "the battery's (that of its fitted data)",
        "Air temperature the cells start at and cool to (thermal model families)."),
    Key("", "battery", "table", "none", "The `[battery]` table below."),
    Key("", "aircraft", "table", "none",
        "The `[aircraft]` table below (needed by flight-condition phases only)."),
    Key("", "phase", "array of tables", "required", "The `[[phase]]` tables, in flight order."),
    Key("battery", "source", "path or preset", "none (give BATTERY on the command line)",
        "Battery file (a path relative to the mission file) or a preset name; a battery "
        "given on the command line or with --pack wins, and flies as a pack like this one "
        "(its cells, strings and chemistry are the defaults of the keys below)."),
    Key("battery", "series", "whole number", "the source's, else the battery's",
        "Cells in series, for a battery of one cell; a pack keeps its own (a warning when "
        "they differ)."),
    Key("battery", "parallel", "whole number", "the source's, else the battery's",
        "Strings in parallel, for a battery of one cell; a pack keeps its own."),
    Key("battery", "chemistry", "lipo, li-ion or lifepo4", "the battery's",
        "Chemistry the mission was written for, for a battery of unknown chemistry; a known "
        "one keeps its own, and a cutoff written for another chemistry is replaced by its "
        "chemistry's."),
    Key("battery", "initial_soc_pct", "%", "100", "State of charge at take-off."),
    Key("battery", "cutoff_cell_V", "V per cell",
        "the battery's own, else its chemistry's (LiPo 3.0, Li-ion 2.5, LiFePO4 2.5)",
        "Voltage the flight must never reach; a battery file's own cutoff wins."),
    Key("battery", "reserve_pct", "%", "20", "State of charge to land with (0 = to the cutoff)."),
    Key("aircraft", "type", "fixed-wing or multirotor", "required", "The kind of aircraft."),
    Key("aircraft", "mass_kg", "kg", "required", "Take-off mass."),
    Key("aircraft", "altitude_m", "m", "sea level",
        "Field altitude: the air density of the standard atmosphere (ISO 2533)."),
    Key("aircraft", "air_density_kg_m3", "kg/m^3", "1.225",
        "Air density (instead of altitude_m)."),
    Key("aircraft fixed-wing", "wing_area_m2", "m^2", "required", "Wing area."),
    Key("aircraft fixed-wing", "cd0", "-", "required", "Zero-lift drag coefficient."),
    Key("aircraft fixed-wing", "span_m", "m", "required unless aspect_ratio",
        "Wing span (aspect ratio = span^2 / area)."),
    Key("aircraft fixed-wing", "aspect_ratio", "-", "required unless span_m", "Aspect ratio."),
    Key("aircraft fixed-wing", "span_efficiency", "0-1", "required", "Oswald factor."),
    Key("aircraft fixed-wing", "propulsion_efficiency", "0-1", "required",
        "Propeller x motor x controller efficiency."),
    Key("aircraft multirotor", "rotor_count", "whole number",
        "required unless rotor_disc_area_m2", "Number of rotors."),
    Key("aircraft multirotor", "rotor_diameter_m", "m", "required unless rotor_disc_area_m2",
        "Rotor diameter."),
    Key("aircraft multirotor", "rotor_disc_area_m2", "m^2",
        "rotor_count x pi x rotor_diameter_m^2 / 4", "Disc area of all rotors."),
    Key("aircraft multirotor", "figure_of_merit", "0-1", "required",
        "Hover figure of merit (small fixed-pitch rotors: 0.5-0.7)."),
    Key("aircraft multirotor", "motor_efficiency", "0-1", "required",
        "Motor x controller efficiency."),
    Key("phase", "name", "text", "required", "Name of the phase (every phase needs one)."),
    Key("phase", "current_A", "A", "one load is required",
        "Pack current, discharge positive (0 = motors off)."),
    Key("phase", "power_W", "W", "one load is required", "Electric power drawn from the pack."),
    Key("phase", "speed_m_s", "m/s", "one load is required",
        "Fixed-wing level flight at this airspeed (drag polar; needs [aircraft])."),
    Key("phase", "hover", "true", "one load is required",
        "Multirotor hover (momentum theory; needs [aircraft])."),
    Key("phase", "climb_rate_m_s", "m/s", "0",
        "Climb rate added to speed_m_s or hover (negative: descent, fixed wing only)."),
    Key("phase", "duration_s", "s", "one duration is required", "Planned duration."),
    Key("phase", "duration_min", "min", "one duration is required",
        "Planned duration (instead of duration_s)."),
    Key("phase", "until", "cutoff or reserve", "one duration is required",
        "Fly until the cutoff or the reserve (the last phase only)."),
    Key("phase", "stretch", "true or false", "false",
        "Search the longest duration of this phase that still lands at the reserve (one "
        "phase at most)."),
    Key("phase", "repeat", "whole number, 'until cutoff' or 'until reserve'", "none",
        "Makes the phase a repeat block of `phases` (the last item only for 'until ...')."),
    Key("phase", "phases", "array of phase tables", "none",
        "The phases of a repeat block (each with a fixed duration)."),
    Key("phase", "note", "text", "none", "Free text, not used by the calculation."),
)


def keys_of(*tables: str) -> set[str]:
    """Key names of the given tables."""
    return {k.name for k in KEYS if k.table in tables}


TITLES = {"": "Top level", "battery": "`[battery]`", "aircraft": "`[aircraft]` (both types)",
          "aircraft fixed-wing": "`[aircraft]` with `type = \"fixed-wing\"`",
          "aircraft multirotor": "`[aircraft]` with `type = \"multirotor\"`",
          "phase": "`[[phase]]`"}


def markdown() -> str:
    """The reference page of the mission format (``docs/mission-format.md``)."""
    lines = [
        "# Mission file format",
        "",
        "<!-- Generated from dischargelab.mission.keys by "
        "`python -m dischargelab.mission.keys`; do not edit by hand. -->",
        "",
        "A mission is a TOML file: a title, the battery's defaults, an optional aircraft, "
        "and the flight phases in order. Every key the parser accepts is listed here with "
        "its unit and what applies when it is left out; any other key is refused with a "
        "suggestion. `dischargelab missions list` shows the bundled missions, "
        "`dischargelab missions copy NAME FILE` copies one to edit.",
        "",
        "A pack keeps what it is: a battery file of a pack, a preset or a logbook pack "
        "(`--pack`) flies with its own cells, strings, chemistry and cutoff. The "
        "`[battery]` table is a default for a battery that does not say (a single cell "
        "fitted on the bench); when it disagrees with a pack, a warning names both values "
        "and the pack's are used.",
        "",
    ]
    for table, title in TITLES.items():
        lines += [f"## {title}", "", "| key | unit | default | meaning |",
                  "|---|---|---|---|"]
        for k in KEYS:
            if k.table == table:
                lines.append(f"| `{k.name}` | {k.unit} | {k.default} | {k.meaning} |")
        lines.append("")
    lines += [
        "## Example",
        "",
        "```toml",
        'name = "survey"',
        "",
        "[battery]",
        'source = "battery.json"     # beside this file, or a preset name',
        'chemistry = "lipo"',
        "series = 4",
        "reserve_pct = 20",
        "",
        "[[phase]]",
        'name = "takeoff"',
        "current_A = 50",
        "duration_s = 10",
        "",
        "[[phase]]",
        'name = "cruise"',
        "current_A = 22",
        "duration_min = 5",
        "stretch = true",
        "",
        "[[phase]]",
        'name = "laps"',
        "repeat = 3",
        'phases = [{ name = "leg", power_W = 180, duration_s = 60 },',
        '          { name = "turn", power_W = 260, duration_s = 8 }]',
        "```",
        "",
        "Run it with `dischargelab endurance survey.toml` (the battery named by `source`), "
        "or `dischargelab endurance BATTERY survey.toml`.",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover - writes the page for the docs
    print(markdown(), end="")
