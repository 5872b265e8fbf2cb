"""Missions and the pilot's report: endurance, report, demo."""

from __future__ import annotations

from pathlib import Path

import click

from ..errors import DischargelabError
from ..formatting import duration, number
from .common import (
    battery_input,
    cutoff_option,
    data_options,
    err,
    expand_paths,
    force_option,
    guard_outputs,
    json_option,
    load_battery_arg,
    out,
    pack_options,
    print_json,
    progress_callback,
    table,
    validation_cases,
    write_csv,
)


@click.command("demo")
@click.option("--out", "out_dir", default="demo-out", show_default=True,
              type=click.Path(file_okay=False), help="Folder for the plots and battery files.")
@force_option
@json_option
def demo_cmd(out_dir, force, as_json):
    """Run the whole method on the bundled Samsung 30Q data (C/10, 1C, 4C).

    Fits the cell on 1C alone and on C/10 + 4C, predicts each measured rate (1C
    held out from the second fit: the report's validation), flies the paper's
    Table 5 mission and a survey mission on a 4S2P pack of the fitted cells, and
    writes battery files, plots and an HTML report to --out.

    \b
    Example:
      dischargelab demo --out demo-out
    """
    from ..demo import check_demo, run_demo

    check_demo(out_dir, force)  # the plot extra and the output files, before any work
    summary = run_demo(Path(out_dir), console=None if as_json else out, force=force)
    missions = summary.pop("missions")
    if as_json:
        summary["missions"] = {name: {k: v for k, v in m.to_dict().items() if k != "phases"}
                               for name, m in missions.items()}
        print_json(summary)
        return
    for result in missions.values():
        out.print()
        print_mission(result)
    out.print(f"\nOpen {Path(out_dir) / 'report.html'} in a browser for the full report.")





def print_mission(result) -> None:
    m = result.mission
    unc = result.uncertainty
    st = result.stretch
    text = result.to_dict()["text"]       # the durations as the JSON and the report write them
    head = text["endurance_s"]
    if unc and unc.get("available"):
        head += (f"  (95 % interval {text['endurance_interval95']}: "
                 + " + ".join(unc.get("interval_includes", ["parameters"]))
                 + (f", {unc['accepted']} draws)" if unc.get("accepted") else ")"))
    else:
        head += "  (95 % interval unavailable: " + (
            unc["reason"] if unc else "no uncertainty requested (--draws 0)") + ")"
    label = "endurance, landing at the reserve" if st else "flight time"
    out.print(f"{m.name}: {label} {head}", markup=False)
    if result.cannot_deliver:
        out.print(f"cannot fly: {result.cannot_deliver['message']}", markup=False)
    rows = [["battery", f"{m.battery.name or '-'} ({m.battery.cells_series}S"
                        f"{m.battery.strings_parallel}P, {m.capacity_Ah:.3f} Ah)"],
            ["model", f"{m.battery.family.title} ({m.battery.model})"],
            ["interval method", (unc.get("method") or "-") if unc and unc.get("available")
             else "none"],
            ["cutoff / reserve", f"{m.cutoff_cell_V:g} V/cell ({m.cutoff_pack_V:.2f} V pack) / "
                                 f"{m.reserve_pct:g} %"],
            ["flight as planned", text["flight_time_s"]
                                  + ("" if result.completed else
                                     f" (NOT completed: {result.ended_by})")],
            ["state of charge at landing", f"{result.soc_end_pct:.1f} %"],
            ["reserve reached at", text["reserve_time_s"]],
            ["cutoff reached at", text["cutoff_time_s"]],
            ["lowest pack voltage", f"{number(result.min_voltage_V)} V "
                                    f"(margin {number(result.voltage_margin_V)} V)"],
            ["charge / energy used", f"{result.simulation.capacity_Ah:.3f} Ah / "
                                     f"{result.simulation.energy_Wh_total:.1f} Wh"]]
    if st:
        limit = ("the mission cannot complete even without it"
                 if st["binding"] == "infeasible" else f"limited by the {st['binding']}")
        rows.append([f"max {st['phase']}", f"{text['stretch_max_s']} ({limit})"])
        if st["margin_s"] is not None:
            rows.append([f"margin on {st['phase']}", text["stretch_margin_s"]])
    out.print(table("Endurance", ["quantity", "value"], rows))
    phase_rows = [[r["phase"] + (f" #{r['repetition']}" if r["repetition"] else ""), r["load"],
                   duration(r["start_s"]), duration(r["duration_s"]),
                   number(r["mean_current_A"], 2), number(r["charge_Ah"]),
                   number(r["end_voltage_V"]), number(r["end_soc_pct"], 1)]
                  for r in result.phases]
    if len(phase_rows) > 30:
        phase_rows = phase_rows[:12] + [["...", "", "", "", "", "", "", ""]] + phase_rows[-12:]
    out.print(table("Phases", ["phase", "load", "start", "duration", "current [A]",
                               "charge [Ah]", "end V", "end SOC [%]"], phase_rows))
    for w in result.warnings:
        if not (result.cannot_deliver and w == result.cannot_deliver["message"]):
            out.print(f"warning: {w}", markup=False)
    for n in result.notes:
        out.print(f"note: {n}", markup=False)


@click.command("endurance")
@click.argument("battery", required=False)
@click.argument("mission", required=False, type=click.Path(dir_okay=False))
@pack_options("Fly a logbook pack: its model scaled to today's capacity and resistance "
              "(then give MISSION alone).")
@cutoff_option(default="the mission file's")
@click.option("--reserve", type=click.FloatRange(0, 100, max_open=True), metavar="PCT",
              help="State of charge to land with [%] (overrides the mission file).")
@click.option("--cells", type=click.IntRange(1), default=None,
              help="Cells in series (overrides the mission and battery files).")
@click.option("--parallel", type=click.IntRange(1), default=None,
              help="Strings in parallel (overrides the mission and battery files).")
@click.option("--ambient", type=float, metavar="C", default=None,
              help="Ambient temperature [degC] for thermal models (overrides the mission file; "
                   "default: the battery's, that of its fitted data).")
@click.option("--draws", default=300, show_default=True, type=click.IntRange(0),
              help="Parameter draws for the 95 % interval (0 = no interval; without draws in "
                   "the battery file the interval is the model error alone).")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the draws.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Save the flight profile plot (PNG, SVG or PDF).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False),
              help="Save voltage, current, power and state of charge through the flight (CSV).")
@force_option
@json_option
def endurance_cmd(battery, mission, pack_name, db, cutoff, reserve, cells, parallel, ambient,
                  draws, seed, plot_path, csv_path, force, as_json):
    """Fly a mission (TOML) on a battery: flight time, max cruise, margin and its interval.

    BATTERY is a battery file from `fit` or a preset name (leave it out when the
    mission's [battery] source names one); MISSION a TOML file of
    phases (current, power or flight condition; duration, until cutoff/reserve,
    repeat blocks; one phase may be `stretch = true`). Bundled examples by name:
    paper-table5, fixed-wing-survey, multirotor-hover.

    \b
    Examples:
      dischargelab endurance hacker-4100-4s-lifepo4 paper-table5
      dischargelab endurance battery.json mission.toml --reserve 25 --plot flight.png
      dischargelab endurance quad.toml      # [battery] source = "lco.json" beside it
      dischargelab endurance cell.json mission.toml --cells 4 --parallel 2 --cutoff 3.0
      dischargelab endurance battery.json mission.toml --draws 500 --json
      dischargelab endurance --pack zippy-a paper-table5     # a logbook pack, today
    """
    from ..mission import load_mission, run_mission

    if pack_name is not None:
        if mission is not None:
            raise DischargelabError("with --pack NAME give the MISSION alone, not a battery")
        battery, mission = None, battery
    elif mission is None and battery is not None:
        battery, mission = None, battery  # the mission's [battery] source names the battery
    if mission is None:
        raise DischargelabError("give MISSION (its [battery] source names the battery), "
                                "BATTERY and MISSION, or --pack NAME and MISSION")
    guard_outputs([plot_path, csv_path], battery_input(battery or "") + [mission], force,
                  figures=[plot_path])
    if pack_name is not None:
        from ..logbook import Logbook

        with Logbook(db, create=False) as lb:
            loaded = lb.model_today(pack_name)  # a read: nothing stored
    else:
        loaded = None if battery is None else load_battery_arg(battery)
    plan = load_mission(mission, battery=loaded, cutoff_cell_V=cutoff,
                        reserve_pct=reserve, ambient_C=ambient, cells_series=cells,
                        strings_parallel=parallel)
    with err.status("flying the mission", spinner="dots") as status:
        result = run_mission(plan, draws=draws, seed=seed,
                             progress=progress_callback(status, "parameter draws"))
    if plot_path:
        from ..plot import save

        save(result.plot(), plot_path)
    if csv_path:
        write_csv(result.to_pandas(), csv_path)
    if as_json:
        print_json(result.to_dict())
        return
    print_mission(result)
    if plot_path:
        out.print(f"plot: {plot_path}", markup=False)




@click.command("report")
@click.argument("battery", required=False)
@pack_options("Report a logbook pack: its model as of today (its fitted model, or one fitted "
              "in memory to its latest full discharge, scaled to today's capacity and "
              "resistance; a pack that only flies: its chemistry's model at today's figures), "
              "read without writing to the logbook (then give no BATTERY).")
@click.option("--mission", "mission_path", type=click.Path(dir_okay=False),
              help="Mission TOML or bundled mission name to fly and report (a --pack "
                   "keeps its cells, strings, chemistry and cutoff).")
@click.option("--validate", "validate_paths", multiple=True, metavar="DATA",
              help="Measured discharge to validate against (repeat, or a quoted pattern "
                   "such as 'runs/*.csv').")
@cutoff_option("for validation and curves",
               "the mission's, else the battery's own, else its chemistry's")
@data_options
@click.option("--cells", type=click.IntRange(1), default=None,
              help="Cells in series of the mission pack (overrides the mission file).")
@click.option("--parallel", type=click.IntRange(1), default=None,
              help="Strings in parallel of the mission pack (overrides the mission file).")
@click.option("--draws", default=300, show_default=True, type=click.IntRange(0),
              help="Parameter draws for the mission's 95 % interval (0 = none).")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the draws.")
@click.option("--title", default=None, help="Page title.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), required=True,
              help="HTML file to write (one self-contained page).")
@force_option
@json_option
def report_cmd(battery, pack_name, db, mission_path, validate_paths, cutoff, columns, current,
               sign, segment, units, steps, cells, parallel, draws, seed, title, output, force,
               as_json):
    """Write one self-contained HTML report for the pilot: model, fit, mission, validation.

    BATTERY is a battery file or a preset name; or, with --pack NAME, a logbook
    pack's model as of today (nothing is written to the logbook).

    \b
    Examples:
      dischargelab report battery.json -o report.html
      dischargelab report battery.json --mission mission.toml --validate 'runs/*.csv' \\
          --cutoff 3.0 --columns time_s=0,current_A=1,voltage_V=2 -o report.html
      dischargelab report hacker-4100-4s-lifepo4 \\
          --mission paper-table5 -o table5.html
      dischargelab report --pack zippy-a --mission multirotor-hover -o zippy-a.html
    """
    from ..identity import battery_identity
    from ..mission import load_mission, run_mission
    from ..model import CUTOFF_CELL_VOLTAGE_V
    from ..report import write_report
    from ..validate import summarise

    if not output.lower().endswith((".html", ".htm")):
        raise DischargelabError(f"-o must name an .html file, got {output!r}")
    if (battery is None) == (pack_name is None):
        raise DischargelabError("give a BATTERY (battery file or preset) or --pack NAME"
                                + (", not both" if battery is not None else ""))
    validate_paths = expand_paths(validate_paths)
    guard_outputs([output], battery_input(battery or "") + [mission_path] + validate_paths,
                  force)
    from ..errors import require

    require("matplotlib", "plot")  # the report's figures; checked before any work
    if pack_name is not None:
        from ..logbook import Logbook

        with err.status(f"reading pack {pack_name}", spinner="dots"), \
                Logbook(db, create=False) as lb:
            bat = lb.model_today(pack_name)
    else:
        bat = load_battery_arg(battery)
    result = None
    cases = []
    with err.status("building the report", spinner="dots") as status:
        if mission_path:
            status.update("flying the mission")
            plan = load_mission(mission_path, battery=bat, cutoff_cell_V=cutoff,
                                cells_series=cells, strings_parallel=parallel)
            result = run_mission(plan, draws=draws, seed=seed,
                                 progress=progress_callback(status, "parameter draws"))
        if validate_paths:
            cut = cutoff
            if cut is None and result is not None:
                cut = result.mission.cutoff_cell_V
            if cut is None:   # the battery's own cutoff, else its chemistry's
                cut = battery_identity(bat).cutoff_cell_V or \
                    CUTOFF_CELL_VOLTAGE_V.get(bat.chemistry or "")
            if cut is None:
                raise DischargelabError("give --cutoff V (per cell) for the validation: the "
                                        "battery's chemistry is unknown")
            cases = validation_cases(bat, validate_paths, cut, columns, current, sign, segment,
                                      units, status, steps=steps)
        status.update("drawing plots")
        label = battery if isinstance(battery, str) else None
        from ..atomic import atomic_path

        with atomic_path(output) as tmp:
            write_report(tmp, bat if bat.name else label, mission_result=result,
                         validation=cases, title=title, cutoff_cell_V=cutoff)
        path = Path(output)
    from ..report import model_statement

    summary = {"report": str(path), "bytes": path.stat().st_size, "pack": pack_name,
               "model_statement": model_statement(bat),
               "mission": None if result is None else result.to_dict(),
               "validation": [c.summary for c in cases],
               "validation_summary": summarise([c.summary for c in cases]) if cases else None}
    if as_json:
        summary["mission"] = None if result is None else {
            k: v for k, v in result.to_dict().items() if k != "phases"}
        print_json(summary)
        return
    out.print(f"report written: {path} ({summary['bytes'] / 1024:.0f} KiB)", markup=False)
    out.print(summary["model_statement"], markup=False)
    if pack_name is not None and bat.extra.get("note"):
        out.print(f"pack: {bat.extra['note']}", markup=False)
    if result is not None:
        print_mission(result)


@click.group("missions")
def missions_group():
    """The bundled missions: list them, show one, copy one to a file to edit.

    \b
    Examples:
      dischargelab missions list
      dischargelab missions show paper-table5
      dischargelab missions copy multirotor-hover quad.toml
    The keys of a mission file, with units and defaults: docs/mission-format.md.
    """


@missions_group.command("list")
@json_option
def missions_list_cmd(as_json):
    """List the bundled missions (name, title, battery, phases)."""
    from ..mission import mission_catalogue

    rows = mission_catalogue()
    if as_json:
        print_json({"missions": [{k: v for k, v in r.items() if k != "path"} for r in rows]})
        return
    out.print(table("Bundled missions", ["name", "title", "battery", "phases"],
                    [[r["name"], r["title"], r["battery"] or "-", str(r["phases"])]
                     for r in rows]))
    out.print("Show one: dischargelab missions show NAME; copy one to edit: "
              "dischargelab missions copy NAME FILE", markup=False)


@missions_group.command("show")
@click.argument("name")
def missions_show_cmd(name):
    """Print a bundled mission's TOML text."""
    from ..mission import bundled_mission_text

    click.echo(bundled_mission_text(name), nl=False)


@missions_group.command("copy")
@click.argument("name")
@click.argument("file", type=click.Path(dir_okay=False))
@force_option
def missions_copy_cmd(name, file, force):
    """Copy a bundled mission to FILE to edit (an existing FILE is kept without --force)."""
    from ..mission import copy_mission

    path = copy_mission(name, file, force=force)
    out.print(f"copied {name} to {path}; fly it with: dischargelab endurance {path}",
              markup=False)


COMMANDS = [demo_cmd, endurance_cmd, report_cmd, missions_group]
