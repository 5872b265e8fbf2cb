"""Fit, predict and compare: fit, predict, curves, validate, presets, models."""

from __future__ import annotations

import math
from pathlib import Path

import click

from ..errors import DischargelabError
from ..formatting import duration, duration_interval, runs_label
from .common import (
    OPTION_OF_ARGUMENT,
    PARAMETER_HELP,
    battery_and_cutoff,
    battery_input,
    cell_cutoff,
    cutoff_option,
    cutoff_options,
    data_options,
    err,
    expand_paths,
    force_option,
    guard_outputs,
    json_option,
    load_battery_arg,
    load_curves,
    out,
    parse_assignments,
    parse_number_list,
    print_data_warnings,
    print_json,
    progress_callback,
    table,
    validation_cases,
    write_csv,
)
from .flightlogs import fit_flight_logs, flight_fit_wanted, flight_numbers_option


def _parse_bounds(items) -> dict:
    bounds = {}
    for name, text in parse_assignments(items, "--bound").items():
        lo, sep, hi = text.partition(":")
        try:
            bounds[name] = (float(lo), float(hi))
        except ValueError:
            raise DischargelabError(f"--bound expects NAME=LOW:HIGH, e.g. C_Ah=2.5:3.5; "
                                    f"got {name}={text}") from None
        if not sep:
            raise DischargelabError(f"--bound expects NAME=LOW:HIGH, got {name}={text}")
    return bounds


def _parse_fixed(items, e0) -> dict:
    fixed = {}
    for name, text in parse_assignments(items, "--fix").items():
        try:
            fixed[name] = float(text)
        except ValueError:
            raise DischargelabError(f"--fix {name} needs a number, got {text!r}") from None
    if e0 is not None:
        fixed["E0_V"] = float(e0)
    return fixed


def _fmt(value, digits=4):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}g}"


def _print_fit(result, battery_path=None):
    rows = []
    for n in result.family.names:
        v = result.parameters.as_dict()[n]
        if n in result.fixed:
            rows.append([n, _fmt(v, 6), "fixed", ""])
        else:
            lo, hi = result.ci95[n]
            rows.append([n, _fmt(v, 6), _fmt(result.stderr[n], 3), f"[{_fmt(lo)}, {_fmt(hi)}]"])
    out.print(table(f"Cell model {result.model!r} ({result.cells_series}S"
                    f"{result.strings_parallel}P pack, "
                    f"{len(result.curves)} curve(s), {result.n_samples} samples, "
                    f"{result.elapsed_s * 1000:.0f} ms)",
                    ["parameter", "value", "std. error", "95 % interval"], rows))
    out.print(f"RMSE {result.rmse_V * 1000:.2f} mV per cell "
              f"({result.rmse_V * result.cells_series * 1000:.1f} mV pack)")
    from ..report import model_statement

    out.print(model_statement(result.battery), markup=False)
    if result.model_error:
        from ..uncertainty import held_out_summary

        out.print(f"held-out error of the time to cutoff: "
                  f"{held_out_summary(result.model_error)}")
    if result.paper_mode:
        for c, fitted in zip(result.curves, result.fit_currents_A):
            out.print(f"paper mode: fitted current {fitted:.4g} A vs measured "
                      f"{c.mean_current_A / result.strings_parallel:.4g} A (not a validation)")
    for note in result.notes:
        out.print(f"note: {note}", markup=False)
    for warning in result.warnings:
        out.print(f"[bold yellow]warning:[/] {warning}")
    advice = result.next_test
    if advice is not None:
        out.print(advice["text"], markup=False)
    if battery_path:
        out.print(f"battery file written to {battery_path}")


@click.command("fit")
@click.argument("data", nargs=-1, required=True, type=click.Path(dir_okay=False))
@data_options
@click.option("--cells", default=None, type=click.IntRange(1),
              help="Cells in series in the measured pack (the model is per cell) "
                   "[default: 1, or a flight log's own count].")
@click.option("--parallel", default=1, show_default=True, type=click.IntRange(1),
              help="Strings in parallel in the measured pack.")
@click.option("--flight", "flights", multiple=True, metavar="N[,N...]",
              help="Flight logs: the flights to fit together (repeatable or a comma list; "
                   "default every flight).")
@click.option("--battery", "battery_index", type=click.IntRange(0), metavar="N",
              help="Flight logs: battery instance N [default: the first with data].")
@click.option("--capacity", type=float, metavar="AH",
              help="Flight logs: label capacity of the pack [Ah] (needed when the log does not "
                   "state it); the initial charge of each flight is (1 - SOC) x capacity.")
@click.option("--e0", type=float, metavar="V",
              help="Fix E0 [V per cell] (e.g. read from a low-rate curve).")
@click.option("--fix", "fix", multiple=True, metavar="NAME=VALUE",
              help=f"Fix a parameter (repeatable). Names: {PARAMETER_HELP}.")
@click.option("--bound", "bound", multiple=True, metavar="NAME=LOW:HIGH",
              help="Override a parameter's bounds (repeatable).")
@click.option("--model", "model_name", default="auto", show_default=True, metavar="NAME",
              help="Model family (see `dischargelab models`): shepherd, shepherd-thermal, "
                   "shepherd-dynamic, ecm, or auto (one curve: shepherd-dynamic, the series "
                   "and polarisation resistances from its load step, its self-heating from "
                   "the logged cell temperature or else the thermal prior of --cooling; "
                   "several rates: the family with the smallest error on curve ends left out "
                   "and on the rate-capacity check between the currents).")
@click.option("--paper-mode", is_flag=True,
              help="Reproduce the paper: E0 given (--e0), current fitted with R, K, A, B, C. "
                   "Degenerate by construction; prints why.")
@click.option("--bootstrap", default=100, show_default=True, type=click.IntRange(0),
              help="Bootstrap refits stored in the battery file; they give missions and "
                   "predictions their 95 % interval (0 = covariance only).")
@click.option("--no-rest", is_flag=True,
              help="Ignore the rest voltage logged before the load step.")
@click.option("--nominal-capacity", type=float, metavar="AH",
              help="Nominal cell capacity [Ah] from the datasheet; defines C-rates later "
                   "(default: the capacity measured in the lowest-rate file).")
@click.option("--name", default="", help="Label stored in the battery file.")
@click.option("--chemistry", type=click.Choice(["lipo", "li-ion", "lifepo4"]),
              help="Chemistry stored in the battery file (sets default cutoffs later).")
@click.option("--cooling", type=click.Choice(["still-air", "airflow", "none"]),
              default="still-air", show_default=True,
              help="Without a logged temperature, thermal models simulate the cells' "
                   "self-heating with a prior from capacity, chemistry and pack size: cooled "
                   "by still air (a bench) or the airflow of flight (flight logs always); "
                   "none holds the cell at the ambient.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Write the battery file (JSON) here.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Save the data-vs-model plot (PNG, SVG or PDF).")
@force_option
@click.option("--strict", is_flag=True,
              help="Treat data plausibility warnings (units, cell count, flat voltage) as "
                   "errors.")
@click.option("--quiet", is_flag=True,
              help="Print only the result (warnings that change it are always shown).")
@json_option
def fit_cmd(data, columns, current, sign, units, segment, steps, cells, parallel, flights,
            battery_index, capacity, e0, fix, bound, model_name, paper_mode, bootstrap,
            no_rest, nominal_capacity, name, chemistry, cooling, output, plot_path, force,
            strict, quiet, as_json):
    """Fit the battery model to one or more discharge files.

    Several files (at different currents) are fitted together with shared
    parameters: the cure for the E0/R ambiguity of a single constant current.

    \b
    Examples:
      dischargelab fit run.csv --cells 4 -o battery.json --plot fit.png
      dischargelab fit Q30_1C.csv --columns time_s=0,current_A=1,voltage_V=2 -o cell.json
      dischargelab fit c10.csv c1.csv c4.csv --columns time_s=0,current_A=1,voltage_V=2
      dischargelab fit 1C_discharge_U.txt --current 2.28 --e0 3.9
      dischargelab fit zippy.csv --cells 2 --e0 3.85 --paper-mode
      dischargelab fit c10.csv c1.csv c4.csv --model ecm -o cell.json
      dischargelab fit 29.csv --capacity 1.6 --model ecm -o pack.json
      dischargelab fit btfl_001.bbl --flight 1,2,3 --capacity 1.3 --model ecm
      dischargelab fit TestFile.nda -o cell.json          # a tester's file: its full discharges
      dischargelab fit maccor_001.txt --step 7,22 -o cell.json
    """
    from ..fit import AUTO, fit_battery
    from ..models import get_family

    if model_name != AUTO:
        get_family(model_name)  # option errors first

    fixed, bounds = _parse_fixed(fix, e0), _parse_bounds(bound)  # option errors first
    if nominal_capacity is not None and not nominal_capacity > 0:
        raise DischargelabError("--nominal-capacity must be a positive number of Ah")
    paths = expand_paths(data)
    guard_outputs([output, plot_path], paths, force, figures=[plot_path])
    if flight_fit_wanted(paths, flights, battery_index, capacity):
        if columns or current or units or paper_mode:
            raise DischargelabError("--columns, --current, --units and --paper-mode do not "
                                    "apply to flight logs")
        with err.status("fitting flights", spinner="dots"):
            flown, result = fit_flight_logs(
                paths, flight_numbers_option(flights), battery_index, capacity, chemistry,
                cells, parallel, model_name, fixed, bounds, bootstrap, not no_rest)
        curves, chemistry = flown.curves, chemistry or flown.chemistry
        metas, data_warnings = [], []
        if nominal_capacity is None:
            nominal_capacity = flown.capacity_Ah / parallel
    else:
        cells = cells or 1
        pack = {"cells_series": cells, "strings_parallel": parallel, "chemistry": chemistry,
                "e0_V": e0}
        from ..fit.workers import fold_workers

        # the held-out folds' workers start before the spinner's thread
        with fold_workers(), \
                err.status("reading", spinner="dots") as status:
            curves, metas, data_warnings = load_curves(paths, columns, current, sign, segment,
                                                       units, pack, strict, status=status,
                                                       steps=steps)
            status.update(f"fitting {len(curves)} curve(s), model {model_name}")
            result = fit_battery(curves, cells_series=cells, strings_parallel=parallel,
                                 fixed=fixed, bounds=bounds, paper_mode=paper_mode,
                                 model=model_name, use_rest=not no_rest, bootstrap=bootstrap,
                                 progress=progress_callback(status, "bootstrap refits"),
                                 cooling=None if cooling == "none" else cooling,
                                 chemistry=chemistry)
    battery = result.battery
    label = name or runs_label([c.name for c in curves])
    from dataclasses import replace as _replace

    extra = dict(battery.extra)
    if nominal_capacity is not None:
        extra["nominal_capacity_Ah"] = float(nominal_capacity)
    battery = _replace(battery, name=label, chemistry=chemistry, extra=extra)
    if plot_path:
        from ..plot import save

        save(result.plot(), plot_path)
    if output:
        battery.save(output)
    print_data_warnings(data_warnings)
    from ..io.cyclers import used_steps_note

    steps_used = used_steps_note(metas)
    if as_json:
        doc = result.to_dict()
        doc["name"] = label
        doc["tester_steps"] = steps_used
        doc["data_warnings"] = [f.text(OPTION_OF_ARGUMENT) for f in data_warnings]
        if output:
            doc["battery_file"] = str(output)
        print_json(doc)
        return
    if not quiet:
        for meta in metas:
            summary = meta.get("summary")
            if summary:
                out.print(f"{meta.get('source', '')}: {summary}", markup=False)
    for line in steps_used:
        out.print(line, markup=False)
    _print_fit(result, output)
    if not output and not quiet:
        out.print("(not saved: add -o battery.json to keep this model)")




@click.command("predict")
@click.argument("battery")
@click.option("--current", type=float, metavar="A", help="Constant pack current [A].")
@click.option("--c-rate", type=float, metavar="X",
              help="Constant current as a C-rate of the rated capacity (nominal, or measured "
                   "in the lowest-rate fitted curve).")
@click.option("--power", type=float, metavar="W", help="Constant pack power [W].")
@cutoff_options
@click.option("--ambient", type=float, metavar="C", default=None,
              help="Ambient temperature [degC] for thermal models (default: the fitted data's, "
                   "else 25); the cell temperature is simulated from it.")
@click.option("--soc", type=click.FloatRange(0, 100, min_open=True), default=100.0,
              show_default=True, help="Initial state of charge [%] of the model capacity.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Save the voltage curve (PNG, SVG or PDF).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False),
              help="Save the simulated time series as CSV.")
@force_option
@json_option
def predict_cmd(battery, current, c_rate, power, cells, parallel, cutoff, cutoff_pack, ambient,
                soc, plot_path, csv_path, force, as_json):
    """Predict a constant-current or constant-power discharge until the cutoff.

    BATTERY is a battery file from `fit` or a preset name (see `presets`).

    \b
    Examples:
      dischargelab predict battery.json --current 20 --cutoff 3.0
      dischargelab predict battery.json --c-rate 2 --cutoff 2.5 --json
      dischargelab predict battery.json --power 250 --cells 4 --cutoff 3.3 --plot p.png
      dischargelab predict hacker-4100-4s-lifepo4 --current 50 --cutoff-pack 10
    """
    from ..predict import predict

    chosen = [x is not None for x in (current, c_rate, power)]
    if sum(chosen) != 1:
        raise DischargelabError("give exactly one load: --current A, --c-rate X or --power W")
    guard_outputs([plot_path, csv_path], battery_input(battery), force, figures=[plot_path])
    bat, cut = battery_and_cutoff(battery, cells, parallel, cutoff, cutoff_pack)
    prediction = predict(bat, current=current, c_rate=c_rate, power=power,
                         cutoff=cut.get("cutoff_cell_V"), cutoff_pack=cut.get("cutoff_pack_V"),
                         soc=soc, ambient=ambient)
    if plot_path:
        from ..plot import save

        save(prediction.plot(), plot_path)
    if csv_path:
        write_csv(prediction.to_pandas(), csv_path)
    summary = prediction.to_dict()
    warnings = summary["warnings"]
    spread = summary.get("interval95")
    if as_json:
        print_json(summary)
        return

    def with_interval(text, key, scale=1.0, spec=".4g"):
        if not spread or key not in spread:
            return text
        lo, hi = spread[key]
        return f"{text}  [95 %: {lo * scale:{spec}} to {hi * scale:{spec}}]"

    load = (f"{summary['current_A']:.4g} A" if "current_A" in summary
            else f"{summary['power_W']:.4g} W")
    rows = [["load", load],
            ["cutoff", f"{summary['cutoff_V']:.3f} V/cell ({summary['cutoff_pack_V']:.2f} V pack)"],
            ["time to cutoff", duration(summary["time_to_cutoff_s"])
             + (f"  [95 %: {duration_interval(spread['time_to_cutoff_s'])}]"
                if spread and "time_to_cutoff_s" in spread else "")],
            ["charge delivered", with_interval(f"{summary['capacity_Ah']:.4g} Ah",
                                               "capacity_Ah")],
            ["energy delivered", with_interval(f"{summary['energy_Wh']:.4g} Wh", "energy_Wh")],
            ["ended by", summary["ended_by"]]]
    if summary.get("peak_temperature_C") is not None:
        rows.append(["peak cell temperature", with_interval(
            f"{summary['peak_temperature_C']:.1f} degC (ambient {summary['ambient_C']:.1f} degC)",
            "peak_temperature_C", spec=".1f")])
    sens = summary.get("beta_sensitivity")
    if sens:
        alt = ", ".join(f"{key.rsplit('_', 1)[-1]}: {value:+.1f} %" for key, value in sens.items()
                        if key.startswith("change_pct"))
        rows.append([f"if beta were not {sens['prior_beta_K']:.0f} K", f"time {alt}"])
    out.print(table(f"Prediction ({bat.cells_series}S{bat.strings_parallel}P, {bat.model})",
                    ["quantity", "value"], rows))
    if spread and spread.get("interval_includes"):
        out.print("95 % interval includes: " + ", ".join(spread["interval_includes"]),
                  markup=False)
    for warning in warnings + list((spread or {}).get("warnings", [])):
        out.print(f"warning: {warning}", markup=False)
    if summary.get("next_test"):
        out.print(summary["next_test"]["text"], markup=False)


@click.command("curves")
@click.argument("battery")
@click.option("--currents", metavar="A,A,...", help="Pack currents [A], e.g. 1,5,10.")
@click.option("--c-rates", metavar="X,X,...", help="C-rates, e.g. 0.5,1,2,4.")
@click.option("--powers", metavar="W,W,...", help="Pack powers [W], e.g. 50,100,200.")
@cutoff_options
@click.option("--ambient", type=float, metavar="C", default=None,
              help="Ambient temperature [degC] for thermal models (default: the fitted data's).")
@click.option("--x", "x_axis", type=click.Choice(["charge", "time"]), default="charge",
              show_default=True, help="Horizontal axis.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Save the plot (PNG, SVG or PDF).")
@force_option
@json_option
def curves_cmd(battery, currents, c_rates, powers, cells, parallel, cutoff, cutoff_pack, ambient,
               x_axis, output, force, as_json):
    """Simulate a family of discharges (like the paper's Figs 5, 7 and 10).

    \b
    Examples:
      dischargelab curves battery.json --currents 1,5,10 --cutoff 3.0 -o curves.png
      dischargelab curves battery.json --c-rates 0.5,1,2,4 --cutoff 2.5 --x time -o c.png
      dischargelab curves battery.json --powers 100,200,400 --cutoff 3.3 --json
    """
    from ..predict import extrapolation_warning
    from ..simulate import curve_family

    given = [x for x in (currents, c_rates, powers) if x]
    if len(given) != 1:
        raise DischargelabError("give exactly one of --currents, --c-rates or --powers")
    guard_outputs([output], battery_input(battery), force, figures=[output])
    bat, cut = battery_and_cutoff(battery, cells, parallel, cutoff, cutoff_pack)
    if powers:
        results = curve_family(bat, powers_W=parse_number_list(powers, "--powers"),
                               ambient_C=ambient, **cut)
    else:
        values = parse_number_list(currents or c_rates, "--currents" if currents else "--c-rates")
        if c_rates:
            values = [x * bat.rated_capacity_Ah for x in values]
        results = curve_family(bat, values, ambient_C=ambient, **cut)
    if output:
        from ..plot import plot_family, save

        save(plot_family(results, x=x_axis), output)
    rows = [r.to_dict() for r in results]
    for row, res in zip(rows, results):
        cell = float(res.current_A[0]) / bat.strings_parallel
        side = bat.extrapolation(cell)
        row["warnings"] = [extrapolation_warning(bat, cell, side)] if side else []
    if as_json:
        print_json(rows)
        return
    unit = "W" if powers else "A"
    key = "power_W" if powers else "current_A"
    out.print(table(f"Discharges to {rows[0]['cutoff_V']:.3f} V/cell "
                    f"({bat.cells_series}S{bat.strings_parallel}P)",
                    [f"load [{unit}]", "time to cutoff", "charge [Ah]", "energy [Wh]", "ended by"],
                    [[f"{r[key]:.4g}", duration(r["time_to_cutoff_s"]),
                      f"{r['capacity_Ah']:.4g}", f"{r['energy_Wh']:.4g}", r["ended_by"]]
                     for r in rows]))
    for row in rows:
        for warning in row["warnings"]:
            out.print(f"warning: {warning}", markup=False)
    if output:
        out.print(f"plot written to {output}")


@click.command("presets")
@json_option
def presets_cmd(as_json):
    """List the built-in battery presets (the paper's Tables 2-4, E0 assumed).

    \b
    Example:
      dischargelab predict zippy-1100-2s --current 1.1 --cutoff 3.0
    """
    from ..model import preset_table

    rows = preset_table()
    if as_json:
        print_json(rows)
        return
    out.print(table("Presets (per-cell coefficients; E0 assumed = nominal cell voltage)",
                    ["preset", "pack", "E0 [V]", "R [ohm]", "K [V/Ah]", "A [V]", "B [1/Ah]",
                     "C [Ah]"],
                    [[r["preset"], f"{r['cells_series']}S {r['chemistry']}", r["E0_V"],
                      r["R_ohm"], r["K_V_per_Ah"], r["A_V"], r["B_per_Ah"], r["C_Ah"]]
                     for r in rows]))




@click.command("models")
@json_option
def models_cmd(as_json):
    """List the model families `fit --model NAME` can fit, with their parameters.

    
    Examples:
      dischargelab models
      dischargelab fit c10.csv c1.csv c4.csv --model shepherd-thermal -o cell.json
    """
    from ..models import family_table

    rows = family_table()
    if as_json:
        print_json(rows)
        return
    for fam in rows:
        out.print(f"[bold]{fam['name']}[/] (version {fam['version']}): {fam['title']}")
        out.print(f"  {fam['description']}", markup=False)
        params = ", ".join(f"{p['name']} [{p['unit']}]" for p in fam["parameters"])
        out.print(f"  parameters: {params}", markup=False)
        states = ", ".join(f"{s['name']} ({s['kind']})" for s in fam["states"])
        out.print(f"  states: {states}", markup=False)




@click.command("validate")
@click.argument("battery")
@click.argument("data", nargs=-1, required=True)
@cutoff_option("at which endurance is measured")
@data_options
@click.option("--cells", type=click.IntRange(1), default=None,
              help="Cells in series of the measured pack (default: as in the battery file).")
@click.option("--parallel", type=click.IntRange(1), default=None,
              help="Strings in parallel of the measured pack (default: as in the battery file).")
@click.option("--flight", type=click.IntRange(1), metavar="N",
              help="Flight logs: flight N (counting from 1) [default: the longest].")
@click.option("--low-timer", type=click.FloatRange(0), default=None, metavar="S",
              help="The cutoff is reached when the voltage stays under it S seconds, for the "
                   "measurement and the model alike [default: 10 under a varying current, "
                   "where peaks dip under it early (ArduPilot BATT_LOW_TIMER); 0 under a "
                   "constant one].")
@click.option("--battery", "battery_index", type=click.IntRange(0), metavar="N",
              help="Flight logs: battery instance N [default: the first with data].")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Save measured vs predicted curves (PNG, SVG or PDF).")
@force_option
@json_option
def validate_cmd(battery, data, cutoff, columns, current, sign, segment, units, steps, cells,
                 parallel, flight, low_timer, battery_index, plot_path, force, as_json):
    """Compare the model with measured discharges: endurance and voltage errors.

    Each DATA file is predicted with its own measured current (constant or the
    measured profile) and compared to the cutoff (paper section 4.4).

    \b
    Examples:
      dischargelab validate battery.json run_2C.csv run_3C.csv --cutoff 3.0
      dischargelab validate battery.json 'data/*.csv' --cutoff 2.5 --columns \\
          time_s=0,current_A=1,voltage_V=2 --plot validation.png
      dischargelab validate battery.json log.txt --current 2.28 --cutoff 3.0 --json
      dischargelab validate pack.json btfl_001.bbl --flight 2 --cutoff 3.3
      dischargelab validate cell.json maccor_001.txt --step 12,17 --cutoff 2.6
    """
    from ..validate import summarise

    paths = expand_paths(data)
    guard_outputs([plot_path], battery_input(battery) + paths, force, figures=[plot_path])
    bat = load_battery_arg(battery).with_pack(cells, parallel)
    cutoff = cell_cutoff(bat, cutoff)
    chosen = {k: v for k, v in (("flight", flight), ("battery", battery_index)) if v is not None}
    with err.status("validating", spinner="dots") as status:
        cases = validation_cases(bat, paths, cutoff, columns, current, sign, segment, units,
                                  status, flight_options=chosen, low_timer_s=low_timer,
                                  steps=steps)
    if plot_path:
        from ..plot import plot_validation, save

        save(plot_validation(cases), plot_path)
    rows = [c.summary for c in cases]
    summary = summarise(rows)
    if as_json:
        print_json({"battery": str(battery), "cutoff_cell_V": cutoff, "files": rows,
                    "summary": summary})
        return

    def f(value, spec):
        return "-" if value is None or not math.isfinite(value) else format(value, spec)

    body = [[Path(r["file"]).name, f(r["current_A"], ".3g") + ("" if r["profile"] == "constant"
                                                               else " (profile)"),
             duration(r["endurance_measured_s"]), duration(r["endurance_predicted_s"]),
             duration_interval(r.get("interval_s")),
             {True: "yes", False: "NO", None: "-"}[r.get("covered")],
             duration(r["endurance_error_s"], signed=True), f(r["endurance_error_pct"], "+.2f"),
             f(r["voltage_rmse_pct"], ".2f"), f(r["voltage_max_error_pct"], ".2f"),
             f(r["voltage_max_error_operational_pct"], ".2f"),
             {True: "yes", False: "no", None: "?"}[r["in_fit"]]] for r in rows]
    seen = [r for r in rows if r["in_fit"] is True]
    held = [r for r in rows if r["in_fit"] is False]
    what = "Validation" if held and not seen and len(held) == len(rows) else \
        "Measured against predicted"
    out.print(table(f"{what} to {cutoff:g} V/cell ({bat.cells_series}S{bat.strings_parallel}P)",
                    ["file", "current [A]", "measured", "predicted", "95 % interval",
                     "covered", "error", "error [%]", "V RMS [%]", "V max [%]",
                     "V max >20% SOC [%]", "in fit"], body))
    from ..report import model_statement

    out.print(model_statement(bat), markup=False)
    groups = [(held, "on files the fit did not see (validation)"),
              (seen, "on files the fit saw (a fit check, not a validation)"),
              ([r for r in rows if r["in_fit"] is None],
               "(the battery file does not record the data its fit saw)")]
    for group, label in groups:
        if group:
            part = summarise(group)
            out.print(f"mean |endurance error| {label}: "
                      f"{f(part['mean_abs_endurance_error_pct'], '.2f')} %, worst "
                      f"{f(part['max_abs_endurance_error_pct'], '.2f')} %", markup=False)
    cov = summary["coverage"]
    if cov["runs"]:
        parts = (["parameters"] if any("parameters" in r["interval_includes"] for r in rows)
                 else []) + ["model error"]
        out.print(f"95 % interval coverage: {cov['covered']}/{cov['runs']} runs "
                  f"({100 * cov['fraction']:.0f} %; the intervals include "
                  f"{' + '.join(parts)})", markup=False)
    for r in rows:
        for w in r["warnings"]:
            out.print(f"warning: {Path(r['file']).name}: {w}", markup=False)
    if plot_path:
        out.print(f"plot: {plot_path}", markup=False)


COMMANDS = [fit_cmd, predict_cmd, curves_cmd, presets_cmd, models_cmd, validate_cmd]
