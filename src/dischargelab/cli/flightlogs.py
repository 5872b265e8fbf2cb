"""Flight logs in, autopilot settings out: convert, flight, autopilot-params,
autopilot-script, and the flight-log side of fit."""

from __future__ import annotations

import math
from pathlib import Path

import click

from ..errors import DischargelabError
from ..formatting import duration
from .common import (
    battery_input,
    cutoff_option,
    err,
    force_option,
    guard_outputs,
    json_option,
    load_battery_arg,
    number_list,
    out,
    pack_options,
    print_json,
    table,
)


def flight_numbers_option(values) -> list[int] | None:
    """``--flight 1 --flight 2,3`` as [1, 2, 3]; None when not given."""
    return number_list(values, "--flight", "flight")


def flight_fit_wanted(paths, flights, battery_index, capacity) -> bool:
    """True when DATA are flight logs (fitted from their flights); errors on a mix."""
    from ..io.flightlog import detect_flight_log

    logs = [detect_flight_log(p) is not None for p in paths]
    if any(logs) and not all(logs):
        raise DischargelabError("give either flight logs or discharge files to fit, not both")
    if not all(logs) and (flights or battery_index is not None or capacity is not None):
        raise DischargelabError("--flight, --battery and --capacity apply to flight logs "
                                "(ArduPilot, PX4 ULog, blackbox, telemetry .tlog, in-flight "
                                "logger CSV)")
    return all(logs)


def fit_flight_logs(paths, flights, battery_index, capacity, chemistry, cells, parallel,
                     model_name, fixed, bounds, bootstrap, use_rest):
    """Fit the flights of flight logs together; returns (FlightCurves, FitResult)."""
    from ..flight import FlightCurves, fit_flights, flight_curves

    parts = [flight_curves(p, flights, battery_index, capacity, chemistry, cells=cells)
             for p in paths]
    flights_all = parts[0]
    for part in parts[1:]:
        if part.cells_series != flights_all.cells_series:
            raise DischargelabError(f"{part.source} has {part.cells_series} cells in series, "
                                    f"{flights_all.source} {flights_all.cells_series}: fit "
                                    "flights of one pack together")
        flights_all = FlightCurves(flights_all.curves + part.curves, flights_all.cells_series,
                                   flights_all.capacity_Ah, flights_all.capacity_source,
                                   flights_all.chemistry, flights_all.flights + part.flights,
                                   flights_all.notes + part.notes, flights_all.source)
    result = fit_flights(flights_all, model=model_name, strings_parallel=parallel, cells=cells,
                         fixed=fixed, bounds=bounds, bootstrap=bootstrap, use_rest=use_rest)
    return flights_all, result




def _battery_or_pack(battery, pack_name, db, cells, output, force, load_current=None):
    """The model of BATTERY (a battery file or preset) or of the logbook pack --pack NAME at
    today's capacity and resistance (read without writing to the logbook), after the checks
    both autopilot commands share; with the load current [A] and what it is: the one given,
    else with --pack the typical current of the pack's logged flights, else None (1C)."""
    if battery is not None and pack_name is not None:
        raise DischargelabError("give a BATTERY or --pack NAME, not both")
    if battery is None and pack_name is None:
        raise DischargelabError("give a BATTERY (battery file or preset) or --pack NAME")
    if battery is not None and cells is None:
        raise DischargelabError("give the flight pack's cells in series: --cells N")
    guard_outputs([output], battery_input(battery or ""), force)
    if pack_name is not None:
        from ..logbook import Logbook

        with Logbook(db, create=False) as lb:
            battery = lb.model_today(pack_name)
            typical = lb.flight_current(pack_name) if load_current is None else None
        if typical is not None:
            amps, flights = typical
            return battery, amps, (f"the median mean current of the pack's {flights} logged "
                                   f"flight{'s' if flights != 1 else ''}")
    source = None if load_current is None else "given with --load"
    return load_battery_arg(battery), load_current, source


def pack_model_options(func):
    """BATTERY or --pack NAME (with --db), --cells and --parallel: the flight pack an
    autopilot file is made for (the same in every autopilot command)."""
    for option in reversed((
            click.argument("battery", required=False),
            pack_options("A logbook pack: its model at today's capacity and resistance "
                         "(then give no BATTERY)."),
            click.option("--cells", type=click.IntRange(1), default=None,
                         help="Cells in series of the flight pack (required with a BATTERY; "
                              "default with --pack: the pack's)."),
            click.option("--parallel", type=click.IntRange(1), default=None,
                         help="Strings in parallel (default: as in the battery file)."))):
        func = option(func)
    return func


def _written(result, output, force: bool, as_json: bool) -> bool:
    """Write an autopilot file when asked (-o) and print its JSON when asked (--json; then
    True: nothing more to print)."""
    if output:
        result.write(output, force=force)
    if as_json:
        doc = result.to_dict()
        if output:
            doc["file"] = str(output)
        print_json(doc)
    return bool(as_json)


@click.command("autopilot-params")
@pack_model_options
@click.option("--firmware", required=True, type=click.Choice(["ardupilot", "px4"]),
              help="Autopilot firmware: ardupilot writes a .param file, px4 a QGroundControl "
                   ".params file.")
@click.option("--load", "load_current", type=float, metavar="A", default=None,
              help="Pack current of normal flight (hover/cruise) at which the reserve is "
                   "computed [A]; default with --pack the median mean current of its logged "
                   "flights, else 1C of the pack.")
@click.option("--reserve-s", default=120.0, show_default=True, type=float, metavar="S",
              help="Flight time left at that load when the low-voltage warning fires [s].")
@click.option("--critical-reserve-s", type=float, metavar="S", default=None,
              help="Flight time left at the critical level [s] (default: a third of the reserve).")
@cutoff_option("at which the loaded pack is empty")
@click.option("--ambient", type=float, metavar="C", default=None,
              help="Ambient temperature [degC] for thermal models.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Parameter file to write (.param for ArduPilot, .params for PX4).")
@force_option
@json_option
def autopilot_params_cmd(battery, pack_name, db, firmware, cells, parallel, load_current,
                         reserve_s, critical_reserve_s, cutoff, ambient, output, force, as_json):
    """Battery failsafe and scaling settings for ArduPilot or PX4 from the model.

    The model is flown at the stated load; the low and critical voltages are the
    resting pack voltages at which --reserve-s and --critical-reserve-s of flight
    remain. Every value in the file carries a comment saying how it was derived.
    With --pack the model is the logbook pack's at its capacity and resistance
    today (its fitted model scaled, or for a pack that only flies the chemistry's
    prior built to them), and a note names the events those come from.

    \b
    Examples:
      dischargelab autopilot-params cell.json --firmware ardupilot --cells 4 --load 25 \\
          -o battery.param
      dischargelab autopilot-params cell.json --firmware px4 --cells 6 --reserve-s 90 \\
          -o battery.params
      dischargelab autopilot-params --pack zippy-a --firmware ardupilot --load 20 \\
          -o zippy-a.param
    """
    from ..autopilot import autopilot_params

    battery, load_current, load_source = _battery_or_pack(battery, pack_name, db, cells,
                                                          output, force, load_current)
    result = autopilot_params(battery, firmware=firmware, cells=cells,
                              parallel=parallel, load_current_A=load_current,
                              load_source=load_source,
                              reserve_s=reserve_s, critical_reserve_s=critical_reserve_s,
                              cutoff=cutoff, ambient=ambient)
    if _written(result, output, force, as_json):
        return
    out.print(table(f"{firmware} battery settings", ["parameter", "value", "unit", "derivation"],
                    [[s.name, s.text(), s.unit, s.comment] for s in result.settings]))
    for note in result.notes:
        out.print(f"note: {note}", markup=False)
    if output:
        out.print(f"parameter file written to {output}")
    else:
        out.print("(not saved: add -o FILE to write the parameter file)")




@click.command("autopilot-script")
@pack_model_options
@click.option("--firmware", default="ardupilot", show_default=True,
              type=click.Choice(["ardupilot"]), help="Autopilot firmware of the script.")
@click.option("--load", "load_current", type=float, metavar="A", default=None,
              help="Pack current the script assumes without a current sensor [A]; default "
                   "with --pack the typical current of its logged flights, else 1C.")
@click.option("--reserve-s", default=120.0, show_default=True, type=float, metavar="S",
              help="Time left at which the script warns (and again at a third of it) [s].")
@cutoff_option("at which the loaded pack is empty")
@click.option("--ambient", type=float, metavar="C", default=None,
              help="Ambient temperature [degC] of the tables for thermal models.")
@click.option("--instance", type=click.IntRange(0), default=0, show_default=True,
              help="ArduPilot battery monitor instance (0 = the first).")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Lua script to write (copy it to APM/scripts/ on the SD card).")
@force_option
@json_option
def autopilot_script_cmd(battery, pack_name, db, firmware, cells, parallel, load_current,
                         reserve_s, cutoff, ambient, instance, output, force, as_json):
    """An ArduPilot Lua script that sends the model's flight time left in flight.

    The model is flown on the ground into small tables (charge left to the
    cutoff against charge taken out and current, loaded voltage, open-circuit
    curve); the script reads the state of charge from the rest voltage before
    take-off, counts charge in flight and sends DL_TREM (seconds to the cutoff at
    the last 30 s mean current) and DL_SOC (%) once a second, and warns at the
    reserve and at a third of it. Install: copy to APM/scripts/, SCR_ENABLE = 1.

    \b
    Examples:
      dischargelab autopilot-script cell.json --cells 4 --cutoff 3.3 -o battery.lua
      dischargelab autopilot-script --pack zippy-a --reserve-s 90 -o zippy-a.lua
    """
    from ..onboard import autopilot_script

    battery, load_current, _ = _battery_or_pack(battery, pack_name, db, cells, output, force,
                                                load_current)
    result = autopilot_script(battery, firmware=firmware, cells=cells, parallel=parallel,
                              cutoff=cutoff, reserve_s=reserve_s, load_current_A=load_current,
                              ambient=ambient, instance=instance)
    if _written(result, output, force, as_json):
        return
    for line in result.header:
        out.print(line, markup=False)
    for note in result.notes[1:]:
        out.print(f"note: {note}", markup=False)
    if output:
        out.print(f"script written to {output}", markup=False)
    else:
        out.print("(not saved: add -o FILE.lua to write the script)")


@click.command("convert")
@click.argument("log", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="CSV file to write [default: LOG name with .discharge.csv].")
@click.option("--flight", type=click.IntRange(1), metavar="N",
              help="Only flight N (counting from 1) [default: every sample, with a flight "
                   "column].")
@click.option("--battery", type=click.IntRange(0), metavar="N",
              help="Battery instance N [default: the first with data].")
@click.option("--topic", metavar="NAME",
              help="ULog topic or DataFlash message with the battery data, when not the "
                   "standard one (battery_status; BAT/CURR).")
@click.option("--fields", metavar="SPEC",
              help="With --topic: voltage_V=FIELD,current_A=FIELD (values in V and A).")
@force_option
@json_option
def convert_cmd(log, output, flight, battery, topic, fields, force, as_json):
    """Convert a flight log's battery data to a canonical CSV.

    Reads ArduPilot .bin/.log, PX4 .ulg, Betaflight/INAV blackbox, MAVLink
    telemetry logs (.tlog, as Mission Planner and QGroundControl save them) and
    in-flight logger CSV (found from the content) and writes time_s, voltage_V,
    current_A (discharge positive), measured temperature and cell voltages,
    the log's own counters and a flight column. The summary names the flights,
    the charge drawn, the current-sensor offset and every dropped record.

    \b
    Examples:
      dischargelab convert flight.bin -o flight.csv
      dischargelab convert log.ulg --battery 1 --flight 2 -o pack2.csv
      dischargelab convert btfl_001.bbl --json
      dischargelab convert 2021-12-02_13-26-14.tlog -o flight.csv
    """
    from ..io.flightlog import convert_flight_log

    output = output or str(Path(Path(log).name).with_suffix(".discharge.csv"))
    result = convert_flight_log(log, output, flight=flight, battery=battery, force=force,
                                topic=topic, fields=fields)
    if as_json:
        print_json(result)
        return
    out.print(result["summary"], markup=False)
    for note in result["notes"]:
        out.print(f"note: {note}", markup=False)
    out.print(f"{result['rows']} rows of {result['battery_label']} written to "
              f"{result['output']}", markup=False)


@click.command("flight")
@click.argument("log", type=click.Path(dir_okay=False))
@click.option("--battery-model", "battery_model", metavar="FILE",
              help="Battery file (or preset) to fly the logged current through: predicted "
                   "voltage and the remaining-time replay by the model.")
@click.option("--flight", "flights", multiple=True, metavar="N[,N...]",
              help="Flights to analyse (repeatable or a comma list) [default: all].")
@click.option("--battery", "battery_index", type=click.IntRange(0), metavar="N",
              help="Battery instance N [default: the first with data].")
@click.option("--capacity", type=float, metavar="AH",
              help="Label capacity of the pack [Ah] [default: the log's, else the model's].")
@click.option("--chemistry", type=click.Choice(["lipo", "li-ion", "lifepo4"]),
              help="Chemistry of the generic OCV curve and the default cutoff "
                   "[default: the model's, else lipo].")
@cutoff_option("of the replay and its truth")
@click.option("--cells", type=click.IntRange(1), default=None,
              help="Cells in series [default: the log's count, else from the highest voltage].")
@click.option("--parallel", type=click.IntRange(1), default=1, show_default=True,
              help="Strings in parallel of the flight pack.")
@click.option("--low-timer", type=click.FloatRange(0), default=10.0, show_default=True,
              metavar="S",
              help="The pack has reached the cutoff when its voltage stays under it this long "
                   "(ArduPilot BATT_LOW_TIMER); shorter dips are sags. 0 = the first sample.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Save the three-panel plot (PNG, SVG or PDF).")
@force_option
@json_option
def flight_cmd(log, battery_model, flights, battery_index, capacity, chemistry, cutoff, cells,
               parallel, low_timer, output, force, as_json):
    """What each flight of a flight log did to the pack, and how long it had left.

    Per flight: duration, charge and energy used, loaded and resting voltages,
    sag at the peak current, internal resistance (regression over 8 s windows,
    beside the log's own estimate) and charge left at landing. With a battery
    model: the voltage predicted from the logged current, and every 5 s the
    remaining flight time by the model at the recent load next to the PX4 and
    ArduPilot methods and, where the logged voltage stayed under the cutoff for the
    low-voltage timer (not a sag at a current peak), the truth.

    \b
    Examples:
      dischargelab flight 29.csv
      dischargelab flight 29.csv --battery-model pack.json --cutoff 3.3 -o flight.png
      dischargelab flight btfl_001.bbl --flight 2 --capacity 1.3 --json
      dischargelab flight sample_log_small.ulg --battery 1
    """
    from ..flight import analyse_flight

    numbers = flight_numbers_option(flights)
    inputs = [log] + battery_input(battery_model)
    guard_outputs([output], inputs, force, figures=[output])
    model = load_battery_arg(battery_model) if battery_model else None
    with err.status("analysing the flights", spinner="dots"):
        report = analyse_flight(log, model, flights=numbers, battery=battery_index,
                                capacity_Ah=capacity, chemistry=chemistry, cutoff=cutoff,
                                cells=cells, parallel=parallel, low_timer_s=low_timer)
    if output:
        from ..plot import save

        save(report.plot()[0], output)
    if as_json:
        doc = report.to_dict()
        if output:
            doc["plot"] = str(output)
        print_json(doc)
        return
    _print_flight_report(report)
    if output:
        out.print(f"plot: {output}", markup=False)


def _print_flight_report(report) -> None:
    def f(value, spec, scale=1.0):
        if value is None or (isinstance(value, float) and not math.isfinite(value)):
            return "-"
        return format(value * scale, spec)

    def cells(values):
        return "-" if not values else " / ".join("-" if x is None else f"{x:.2f}"
                                                 for x in values)

    def rest(r):
        return "-" if r is None else f"{r['voltage_V']:.2f} V at {r['current_A']:.2f} A"

    rows = [("duration", lambda s: duration(s["duration_s"])),
            ("charge used [mAh]", lambda s: f(s["charge_Ah"], ".0f", 1000)),
            ("energy used [Wh]", lambda s: f(s["energy_Wh"], ".2f")),
            ("mean / peak current [A]", lambda s: f"{f(s['mean_current_A'], '.1f')} / "
                                                  f"{f(s['peak_current_A'], '.1f')}"),
            ("rest before take-off", lambda s: rest(s["rest_before"])),
            ("rest after landing", lambda s: rest(s["rest_after"])),
            ("min loaded voltage [V]", lambda s: f(s["min_loaded_V"], ".2f")),
            ("min loaded cells [V]", lambda s: cells(s["min_loaded_cell_V"])),
            ("sag at peak [V]", lambda s: f(s["sag_V"], ".2f")),
            ("sag at peak, cells [V]", lambda s: cells(s["sag_cells_V"])),
            ("resistance, pack [mOhm]", lambda s: f(s["resistance_ohm"], ".1f", 1000)),
            ("resistance, log's [mOhm]", lambda s: f(s["log_resistance_ohm"], ".1f", 1000)),
            ("SOC take-off / landing [%]", lambda s: f"{f(s['soc_start'], '.0f', 100)} / "
                                                     f"{f(s['soc_landing_ocv'], '.0f', 100)}"),
            ("left at landing, OCV [mAh]", lambda s: f(s["charge_left_ocv_Ah"], ".0f", 1000)),
            ("left, label - used [mAh]", lambda s: f(s["charge_left_label_Ah"], ".0f", 1000))]
    if report.model:
        rows += [("left, model [mAh]", lambda s: f(s.get("charge_left_model_Ah"), ".0f", 1000)),
                 ("voltage RMSE, pack [mV]", lambda s: f(s.get("rmse_V"), ".0f", 1000)),
                 ("voltage RMSE, cells [mV]",
                  lambda s: "-" if not s.get("rmse_cell_V") else
                  " / ".join("-" if x is None else f"{1000 * x:.0f}"
                             for x in s["rmse_cell_V"]))]
    rows.append(("under the cutoff: first dip / for good",
                 lambda s: f"{duration(s.get('cutoff_dip_at_s'))} / "
                           f"{duration(s.get('cutoff_reached_at_s'))}"))
    rows.append(("remaining at mid-flight", _mid_flight_text))
    out.print(table(f"{Path(report.source).name}: {report.battery_label}, "
                    f"{report.cells_series} cells, capacity "
                    f"{f(report.capacity_Ah, '.3g')} Ah ({report.capacity_source}), cutoff "
                    f"{report.cutoff_cell_V:g} V/cell",
                    ["quantity"] + [f"flight {a.number}" for a in report.flights],
                    [[name] + [fn(a.summary) for a in report.flights] for name, fn in rows]))
    for note in report.notes:
        out.print(f"note: {note}", markup=False)
    for a in report.flights:
        for note in a.notes:
            out.print(f"note: flight {a.number}: {note}", markup=False)


def _mid_flight_text(summary) -> str:
    mid = summary.get("replay_mid_flight")
    if not mid:
        return "-"
    parts = []
    for key, name in (("true_s", "true"), ("model_profile_s", "model (recent load)"),
                      ("model_s", "model (mean load)"), ("px4_s", "PX4"),
                      ("ardupilot_s", "ArduPilot")):
        if mid.get(key) is not None:
            parts.append(f"{name} {duration(mid[key])}")
    return ", ".join(parts) or "-"


COMMANDS = [autopilot_params_cmd, autopilot_script_cmd, convert_cmd, flight_cmd]
