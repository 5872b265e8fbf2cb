"""Command line interface: parse -> call the library -> print a table or JSON.

Every command accepts ``--json`` (JSON alone on stdout) and shows examples in
``--help``. Errors the user can fix (:class:`~dischargelab.errors.DischargelabError`
and usage errors) print one line on stderr and exit with status 2; any other
exception is a bug: its traceback is printed with a request to report it, and
the status is 1. ``DISCHARGELAB_DEBUG=1`` shows tracebacks for every error.
"""

from __future__ import annotations

import json
import math
import os
import sys
import traceback
from pathlib import Path

import click
from rich.console import Console
from rich.table import Table
from rich.text import Text

from .errors import DischargelabError

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


@click.group(context_settings=CONTEXT)
@click.version_option(package_name="dischargelab")
def app() -> None:
    """Turn a battery discharge test into a battery model and a UAV endurance estimate.

    \b
    Typical use:
      dischargelab fit discharge.csv --cells 4 -o battery.json
      dischargelab predict battery.json --current 20 --cutoff 3.0
      dischargelab curves battery.json --currents 5,10,20 --cutoff 3.0 -o curves.png
      dischargelab demo
    """


# Piped or redirected output gets wide tables instead of rich's 80-column default.
out = Console(highlight=False, soft_wrap=True,
              width=None if sys.stdout.isatty() or os.environ.get("COLUMNS") else 160)
err = Console(stderr=True, highlight=False, soft_wrap=True)

JSON_HELP = "Print the result as JSON alone on stdout (for scripts)."


def print_json(data) -> None:
    """Write JSON (NaN/inf as null) alone on stdout."""
    sys.stdout.write(json.dumps(_json_safe(data), indent=2) + "\n")


def print_json_line(data) -> None:
    """Write one compact JSON object on its own line of stdout (JSON Lines) and flush."""
    sys.stdout.write(json.dumps(_json_safe(data)) + "\n")
    sys.stdout.flush()


def _json_safe(value):
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def table(title: str, columns: list[str], rows: list[list]) -> Table:
    """A rich table with right-aligned numeric columns."""
    t = Table(title=Text(title), title_justify="left")
    for i, name in enumerate(columns):
        t.add_column(Text(name), justify="left" if i == 0 else "right")
    for row in rows:
        t.add_row(*[Text(str(x)) for x in row])
    return t


def parse_number_list(text: str, what: str) -> list[float]:
    """Parse ``"1,5,10"`` into floats; raises a one-line error naming the option."""
    try:
        values = [float(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        raise DischargelabError(f"{what} must be numbers separated by commas, e.g. 1,5,10; "
                                f"got {text!r}") from None
    if not values:
        raise DischargelabError(f"{what} is empty; give numbers separated by commas, e.g. 1,5,10")
    return values


def parse_assignments(items: list[str], what: str) -> dict[str, str]:
    """Parse repeated ``NAME=VALUE`` options into a dict."""
    result = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise DischargelabError(f"{what} expects NAME=VALUE, got {item!r}")
        result[name.strip()] = value.strip()
    return result


# --- core commands: fit, predict, curves, demo, presets ---

PARAMETER_HELP = "E0_V, R_ohm, K_V_per_Ah, A_V, B_per_Ah, C_Ah"


def data_options(func):
    """Options shared by every command that reads measured discharge files."""
    options = [
        click.option("--columns", metavar="SPEC",
                     help="Map columns to canonical names by header name or 0-based index, e.g. "
                          "time_s=0,current_A=1,voltage_V=2,temperature_C=4 (needed for "
                          "headerless files with more than two columns)."),
        click.option("--current", "current", metavar="A[,A...]",
                     help="Constant discharge current [A] for files without a current column "
                          "(one value for all files, or one per file)."),
        click.option("--sign", type=click.Choice(["auto", "positive", "negative"]),
                     default="auto", show_default=True,
                     help="Sign of the DISCHARGE current in the file; auto detects and "
                          "reports it."),
        click.option("--units", metavar="SPEC",
                     help="Units of the source columns when the header does not say, e.g. "
                          "voltage_V=mV,current_A=mA,time_s=ms (also h, min)."),
        click.option("--segment", default="auto", show_default=True, metavar="auto|none|N",
                     help="Which discharge to keep: auto (the main one), none (all rows) or the "
                          "N-th segment (counting from 1) of a file holding several."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def expand_paths(items) -> list[str]:
    """Paths, with quoted shell patterns such as 'runs/*.csv' expanded."""
    import glob

    paths = []
    for item in items:
        item = str(item)
        if any(c in item for c in "*?[") and not Path(item).is_file():
            matches = sorted(glob.glob(item))
            if not matches:
                raise DischargelabError(f"no file matches {item!r}")
            paths.extend(matches)
        else:
            paths.append(item)
    return paths


FORCE_HELP = "Replace output files that already exist (an input is never overwritten)."


def force_option(func):
    """The ``--force`` flag of every command that writes files."""
    return click.option("--force", is_flag=True, help=FORCE_HELP)(func)


def guard_outputs(outputs, inputs=(), force=False, figures=()) -> None:
    """Apply the output policy before any work (:func:`dischargelab.atomic.check_outputs`).

    ``figures`` are the outputs that are plots: their suffix must name a format.
    """
    from .atomic import check_outputs
    from .errors import require

    check_outputs(outputs, inputs, force)
    figures = [f for f in figures if f]
    if figures:
        from .plot import check_path

        for figure in figures:
            check_path(figure)
        require("matplotlib", "plot")


def battery_input(battery) -> list:
    """The battery argument as an input path when it names a file (not a preset)."""
    return [battery] if battery is not None and Path(str(battery)).is_file() else []


def load_battery_arg(battery):
    """Load a BATTERY argument (battery file or preset); errors name the battery file."""
    from .errors import DataError
    from .model import load_battery

    try:
        return load_battery(battery)
    except DischargelabError as exc:
        path = Path(str(battery))
        if not path.is_file():
            raise
        text = str(exc).removeprefix(f"{path}: ").removeprefix(f"{path.name}: ")
        raise DataError(f"battery file {path}: {text}") from None


def write_csv(frame, path) -> Path:
    """Write a DataFrame as CSV atomically (:mod:`dischargelab.atomic`)."""
    from .atomic import write_text

    return write_text(path, frame.to_csv(index=False))


def read_data_files(paths, columns=None, current=None, sign="auto", segment="auto", units=None,
                    status=None, verb="reading", flight_options=None):
    """Read measured files with the shared data options; returns [(data, meta), ...].

    Raises DischargelabError with one line on bad options or input.
    """
    from .atomic import check_inputs
    from .io import parse_columns, parse_units, read_discharge

    paths = expand_paths(paths)
    check_inputs(paths)
    currents = [None] * len(paths)
    if current:
        values = parse_number_list(current, "--current")
        if len(values) == 1:
            currents = values * len(paths)
        elif len(values) == len(paths):
            currents = values
        else:
            raise DischargelabError(f"--current has {len(values)} values for {len(paths)} files; "
                                    f"give one value or one per file")
    if segment not in ("auto", "none"):
        try:
            segment = int(segment)
        except ValueError:
            raise DischargelabError(f"--segment must be auto, none or an integer, "
                                    f"got {segment!r}") from None
    column_map = parse_columns(columns) if columns else None
    unit_map = parse_units(units) if units else None
    loaded = []
    for k, (path, amps) in enumerate(zip(paths, currents)):
        if status is not None:
            status.update(f"{verb} {Path(path).name} ({k + 1}/{len(paths)})")
        loaded.append(read_discharge(path, columns=column_map, current_A=amps, sign=sign,
                                     segment=segment, units=unit_map, **(flight_options or {})))
    return loaded


def check_plausible(loaded, pack: dict, strict: bool = False) -> list:
    """Plausibility of read files for the described pack (:mod:`dischargelab.plausibility`).

    Errors (and warnings when ``strict``) raise; the warnings are returned for
    :func:`print_data_warnings`.
    """
    from .plausibility import check_discharges, raise_for

    return raise_for(check_discharges(loaded, **pack), strict=strict)


def print_data_warnings(warnings) -> None:
    """Data warnings change the result: always on stderr, whatever --quiet or --json say."""
    for finding in warnings:
        err.print(f"warning: {finding.text(OPTION_OF_ARGUMENT)}", markup=False)


def load_curves(paths, columns=None, current=None, sign="auto", segment="auto", units=None,
                pack=None, strict=False, status=None):
    """Read files into fit curves after the plausibility checks.

    ``pack`` holds the keyword arguments of
    :func:`dischargelab.plausibility.check_discharges` (cells_series,
    strings_parallel, chemistry, e0_V). Returns ``(curves, metas, warnings)``.
    """
    from .fit import Curve

    loaded = read_data_files(paths, columns, current, sign, segment, units, status=status)
    warnings = check_plausible(loaded, pack or {}, strict)
    curves, metas = [], []
    for data, meta in loaded:
        curves.append(Curve.from_frame(data, meta, name=Path(meta.get("source", "")).stem))
        metas.append(meta)
    return curves, metas, warnings


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
    if result.model_error:
        from .uncertainty import held_out_summary

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
    if battery_path:
        out.print(f"battery file written to {battery_path}")


@app.command("fit")
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
              help="Model family (see `dischargelab models`): shepherd, shepherd-thermal, ecm, "
                   "or auto (one curve: shepherd, or shepherd-thermal when the file logs the "
                   "cell temperature; several rates: the family with the smallest held-out "
                   "error, whole curves and curve ends left out).")
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
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def fit_cmd(data, columns, current, sign, units, segment, cells, parallel, flights,
            battery_index, capacity, e0, fix, bound, model_name, paper_mode, bootstrap,
            no_rest, nominal_capacity, name, chemistry, output, plot_path, force, strict, quiet,
            as_json):
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
    """
    from .fit import AUTO, fit_battery
    from .models import get_family

    if model_name != AUTO:
        get_family(model_name)  # option errors first

    fixed, bounds = _parse_fixed(fix, e0), _parse_bounds(bound)  # option errors first
    if nominal_capacity is not None and not nominal_capacity > 0:
        raise DischargelabError("--nominal-capacity must be a positive number of Ah")
    paths = expand_paths(data)
    guard_outputs([output, plot_path], paths, force, figures=[plot_path])
    if _flight_fit_wanted(paths, flights, battery_index, capacity):
        if columns or current or units or paper_mode:
            raise DischargelabError("--columns, --current, --units and --paper-mode do not "
                                    "apply to flight logs")
        with err.status("fitting flights", spinner="dots"):
            flown, result = _fit_flight_logs(
                paths, _flight_numbers_option(flights), battery_index, capacity, chemistry,
                cells, parallel, model_name, fixed, bounds, bootstrap, not no_rest)
        curves, chemistry = flown.curves, chemistry or flown.chemistry
        metas, data_warnings = [], []
        if nominal_capacity is None:
            nominal_capacity = flown.capacity_Ah / parallel
    else:
        cells = cells or 1
        pack = {"cells_series": cells, "strings_parallel": parallel, "chemistry": chemistry,
                "e0_V": e0}
        with err.status("reading", spinner="dots") as status:
            curves, metas, data_warnings = load_curves(paths, columns, current, sign, segment,
                                                       units, pack, strict, status=status)
            status.update(f"fitting {len(curves)} curve(s), model {model_name}")
            result = fit_battery(curves, cells_series=cells, strings_parallel=parallel,
                                 fixed=fixed, bounds=bounds, paper_mode=paper_mode,
                                 model=model_name, use_rest=not no_rest, bootstrap=bootstrap,
                                 progress=_progress_callback(status, "bootstrap refits"))
    battery = result.battery
    label = name or ", ".join(c.name for c in curves)
    from dataclasses import replace as _replace

    extra = dict(battery.extra)
    if nominal_capacity is not None:
        extra["nominal_capacity_Ah"] = float(nominal_capacity)
    battery = _replace(battery, name=label, chemistry=chemistry, extra=extra)
    if plot_path:
        from .plot import save

        save(result.plot(), plot_path)
    if output:
        battery.save(output)
    print_data_warnings(data_warnings)
    if as_json:
        doc = result.to_dict()
        doc["name"] = label
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
    _print_fit(result, output)
    if not output and not quiet:
        out.print("(not saved: add -o battery.json to keep this model)")


def _flight_numbers_option(values) -> list[int] | None:
    """``--flight 1 --flight 2,3`` as [1, 2, 3]; None when not given."""
    if not values:
        return None
    numbers = []
    for value in values:
        for part in str(value).split(","):
            try:
                number = int(part)
            except ValueError:
                raise DischargelabError(f"--flight expects flight numbers such as 1 or 1,2,3; "
                                        f"got {value!r}") from None
            if number < 1:
                raise DischargelabError(f"--flight numbers count from 1; got {number}")
            numbers.append(number)
    return numbers


def _flight_fit_wanted(paths, flights, battery_index, capacity) -> bool:
    """True when DATA are flight logs (fitted from their flights); errors on a mix."""
    from .io.flightlog import detect_flight_log

    logs = [detect_flight_log(p) is not None for p in paths]
    if any(logs) and not all(logs):
        raise DischargelabError("give either flight logs or discharge files to fit, not both")
    if not all(logs) and (flights or battery_index is not None or capacity is not None):
        raise DischargelabError("--flight, --battery and --capacity apply to flight logs "
                                "(ArduPilot, PX4 ULog, blackbox, in-flight logger CSV)")
    return all(logs)


def _fit_flight_logs(paths, flights, battery_index, capacity, chemistry, cells, parallel,
                     model_name, fixed, bounds, bootstrap, use_rest):
    """Fit the flights of flight logs together; returns (FlightCurves, FitResult)."""
    from .flight import FlightCurves, fit_flights, flight_curves

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


def _cutoff_options(func):
    func = click.option("--cutoff-pack", type=float, metavar="V",
                        help="Cutoff voltage of the whole pack [V] (instead of --cutoff).")(func)
    func = click.option("--cutoff", type=float, metavar="V",
                        help="Cutoff voltage per cell [V] [default: the battery chemistry's "
                             "usual one: LiPo 3.0, Li-ion and LiFePO4 2.5].")(func)
    func = click.option("--parallel", type=click.IntRange(1), default=None,
                        help="Strings in parallel (default: as in the battery file).")(func)
    func = click.option("--cells", type=click.IntRange(1), default=None,
                        help="Cells in series (default: as in the battery file).")(func)
    return func


def _battery_and_cutoff(battery_arg, cells, parallel, cutoff, cutoff_pack):
    battery = load_battery_arg(battery_arg).with_pack(cells, parallel)
    return battery, {"cutoff_cell_V": _cell_cutoff(battery, cutoff, cutoff_pack),
                     "cutoff_pack_V": cutoff_pack}


def _cell_cutoff(battery, cutoff, cutoff_pack=None):
    """The per-cell cutoff: the given one, else the battery chemistry's usual one
    (:func:`dischargelab.predict.default_cutoff`, said on stderr), else a one-line error
    naming the options."""
    from .errors import SimulationError
    from .predict import default_cutoff

    if cutoff is not None and cutoff_pack is not None:
        raise DischargelabError("give either --cutoff (per cell) or --cutoff-pack, not both")
    if cutoff is not None or cutoff_pack is not None:
        return cutoff
    try:
        value = default_cutoff(battery)["cutoff_cell_V"]
    except SimulationError:
        raise DischargelabError("give a cutoff: --cutoff V per cell (e.g. 3.0 LiPo, 2.5 "
                                "Li-ion) or --cutoff-pack V (the battery file names no "
                                "chemistry)") from None
    err.print(f"cutoff {value:g} V/cell, the usual one for {battery.chemistry} "
              f"(--cutoff to change it)", markup=False)
    return value


@app.command("predict")
@click.argument("battery")
@click.option("--current", type=float, metavar="A", help="Constant pack current [A].")
@click.option("--c-rate", type=float, metavar="X",
              help="Constant current as a C-rate of the rated capacity (nominal, or measured "
                   "in the lowest-rate fitted curve).")
@click.option("--power", type=float, metavar="W", help="Constant pack power [W].")
@_cutoff_options
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
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
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
    from .predict import predict

    chosen = [x is not None for x in (current, c_rate, power)]
    if sum(chosen) != 1:
        raise DischargelabError("give exactly one load: --current A, --c-rate X or --power W")
    guard_outputs([plot_path, csv_path], battery_input(battery), force, figures=[plot_path])
    bat, cut = _battery_and_cutoff(battery, cells, parallel, cutoff, cutoff_pack)
    prediction = predict(bat, current=current, c_rate=c_rate, power=power,
                         cutoff=cut.get("cutoff_cell_V"), cutoff_pack=cut.get("cutoff_pack_V"),
                         soc=soc, ambient=ambient)
    if plot_path:
        from .plot import save

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
            ["time to cutoff", with_interval(f"{summary['time_to_cutoff_s'] / 60:.2f} min",
                                             "time_to_cutoff_s", 1 / 60, ".2f")],
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


@app.command("curves")
@click.argument("battery")
@click.option("--currents", metavar="A,A,...", help="Pack currents [A], e.g. 1,5,10.")
@click.option("--c-rates", metavar="X,X,...", help="C-rates, e.g. 0.5,1,2,4.")
@click.option("--powers", metavar="W,W,...", help="Pack powers [W], e.g. 50,100,200.")
@_cutoff_options
@click.option("--ambient", type=float, metavar="C", default=None,
              help="Ambient temperature [degC] for thermal models (default: the fitted data's).")
@click.option("--x", "x_axis", type=click.Choice(["charge", "time"]), default="charge",
              show_default=True, help="Horizontal axis.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Save the plot (PNG, SVG or PDF).")
@force_option
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def curves_cmd(battery, currents, c_rates, powers, cells, parallel, cutoff, cutoff_pack, ambient,
               x_axis, output, force, as_json):
    """Simulate a family of discharges (like the paper's Figs 5, 7 and 10).

    \b
    Examples:
      dischargelab curves battery.json --currents 1,5,10 --cutoff 3.0 -o curves.png
      dischargelab curves battery.json --c-rates 0.5,1,2,4 --cutoff 2.5 --x time -o c.png
      dischargelab curves battery.json --powers 100,200,400 --cutoff 3.3 --json
    """
    from .predict import extrapolation_warning
    from .simulate import curve_family

    given = [x for x in (currents, c_rates, powers) if x]
    if len(given) != 1:
        raise DischargelabError("give exactly one of --currents, --c-rates or --powers")
    guard_outputs([output], battery_input(battery), force, figures=[output])
    bat, cut = _battery_and_cutoff(battery, cells, parallel, cutoff, cutoff_pack)
    if powers:
        results = curve_family(bat, powers_W=parse_number_list(powers, "--powers"),
                               ambient_C=ambient, **cut)
    else:
        values = parse_number_list(currents or c_rates, "--currents" if currents else "--c-rates")
        if c_rates:
            values = [x * bat.rated_capacity_Ah for x in values]
        results = curve_family(bat, values, ambient_C=ambient, **cut)
    if output:
        from .plot import plot_family, save

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
                    [f"load [{unit}]", "time [min]", "charge [Ah]", "energy [Wh]", "ended by"],
                    [[f"{r[key]:.4g}", f"{r['time_to_cutoff_s'] / 60:.2f}",
                      f"{r['capacity_Ah']:.4g}", f"{r['energy_Wh']:.4g}", r["ended_by"]]
                     for r in rows]))
    for row in rows:
        for warning in row["warnings"]:
            out.print(f"warning: {warning}", markup=False)
    if output:
        out.print(f"plot written to {output}")


@app.command("presets")
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def presets_cmd(as_json):
    """List the built-in battery presets (the paper's Tables 2-4, E0 assumed).

    \b
    Example:
      dischargelab predict zippy-1100-2s --current 1.1 --cutoff 3.0
    """
    from .model import preset_table

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


@app.command("autopilot-params")
@click.argument("battery")
@click.option("--firmware", required=True, type=click.Choice(["ardupilot", "px4"]),
              help="Autopilot firmware: ardupilot writes a .param file, px4 a QGroundControl "
                   ".params file.")
@click.option("--cells", required=True, type=click.IntRange(1), help="Cells in series of the "
              "flight pack.")
@click.option("--parallel", type=click.IntRange(1), default=None,
              help="Strings in parallel (default: as in the battery file).")
@click.option("--load", "load_current", type=float, metavar="A", default=None,
              help="Pack current of normal flight (hover/cruise) at which the reserve is "
                   "computed [A]; default 1C of the pack.")
@click.option("--reserve-s", default=120.0, show_default=True, type=float, metavar="S",
              help="Flight time left at that load when the low-voltage warning fires [s].")
@click.option("--critical-reserve-s", type=float, metavar="S", default=None,
              help="Flight time left at the critical level [s] (default: a third of the reserve).")
@click.option("--cutoff", type=float, metavar="V", default=None,
              help="Loaded cell voltage at which the pack is empty [V] (default by chemistry).")
@click.option("--ambient", type=float, metavar="C", default=None,
              help="Ambient temperature [degC] for thermal models.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Parameter file to write (.param for ArduPilot, .params for PX4).")
@force_option
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def autopilot_params_cmd(battery, firmware, cells, parallel, load_current, reserve_s,
                         critical_reserve_s, cutoff, ambient, output, force, as_json):
    """Battery failsafe and scaling settings for ArduPilot or PX4 from the model.

    The model is flown at the stated load; the low and critical voltages are the
    resting pack voltages at which --reserve-s and --critical-reserve-s of flight
    remain. Every value in the file carries a comment saying how it was derived.

    \b
    Examples:
      dischargelab autopilot-params cell.json --firmware ardupilot --cells 4 --load 25 \\
          -o battery.param
      dischargelab autopilot-params cell.json --firmware px4 --cells 6 --reserve-s 90 \\
          -o battery.params
    """
    from .autopilot import autopilot_params

    guard_outputs([output], battery_input(battery), force)
    result = autopilot_params(load_battery_arg(battery), firmware=firmware, cells=cells,
                              parallel=parallel, load_current_A=load_current,
                              reserve_s=reserve_s, critical_reserve_s=critical_reserve_s,
                              cutoff=cutoff, ambient=ambient)
    if output:
        result.write(output, force=force)
    if as_json:
        doc = result.to_dict()
        if output:
            doc["file"] = str(output)
        print_json(doc)
        return
    out.print(table(f"{firmware} battery settings", ["parameter", "value", "unit", "derivation"],
                    [[s.name, s.text(), s.unit, s.comment] for s in result.settings]))
    for note in result.notes:
        out.print(f"note: {note}", markup=False)
    if output:
        out.print(f"parameter file written to {output}")
    else:
        out.print("(not saved: add -o FILE to write the parameter file)")


@app.command("models")
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def models_cmd(as_json):
    """List the model families `fit --model NAME` can fit, with their parameters.

    
    Examples:
      dischargelab models
      dischargelab fit c10.csv c1.csv c4.csv --model shepherd-thermal -o cell.json
    """
    from .models import family_table

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


@app.command("demo")
@click.option("--out", "out_dir", default="demo-out", show_default=True,
              type=click.Path(file_okay=False), help="Folder for the plots and battery files.")
@force_option
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def demo_cmd(out_dir, force, as_json):
    """Run the whole method on the bundled Samsung 30Q data (C/10, 1C, 4C).

    Fits the cell on 1C alone and on all three rates together, predicts each
    measured rate, flies the paper's Table 5 mission and a survey mission on a
    4S2P pack of the fitted cells, and writes battery files, plots and an HTML
    report to --out.

    \b
    Example:
      dischargelab demo --out demo-out
    """
    from .demo import check_demo, run_demo

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
        _print_mission(result)
    out.print(f"\nOpen {Path(out_dir) / 'report.html'} in a browser for the full report.")


@app.command("convert")
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
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def convert_cmd(log, output, flight, battery, topic, fields, force, as_json):
    """Convert a flight log's battery data to a canonical CSV.

    Reads ArduPilot .bin/.log, PX4 .ulg, Betaflight/INAV blackbox and in-flight
    logger CSV (found from the content) and writes time_s, voltage_V,
    current_A (discharge positive), measured temperature and cell voltages,
    the log's own counters and a flight column. The summary names the flights,
    the charge drawn, the current-sensor offset and every dropped record.

    \b
    Examples:
      dischargelab convert flight.bin -o flight.csv
      dischargelab convert log.ulg --battery 1 --flight 2 -o pack2.csv
      dischargelab convert btfl_001.bbl --json
    """
    from .io.flightlog import convert_flight_log

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


@app.command("flight")
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
@click.option("--cutoff", type=float, metavar="V",
              help="Cutoff per cell [V] of the replay and its truth [default: by chemistry].")
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
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
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
    from .flight import analyse_flight

    numbers = _flight_numbers_option(flights)
    inputs = [log] + battery_input(battery_model)
    guard_outputs([output], inputs, force, figures=[output])
    model = load_battery_arg(battery_model) if battery_model else None
    with err.status("analysing the flights", spinner="dots"):
        report = analyse_flight(log, model, flights=numbers, battery=battery_index,
                                capacity_Ah=capacity, chemistry=chemistry, cutoff=cutoff,
                                cells=cells, parallel=parallel, low_timer_s=low_timer)
    if output:
        from .plot import save

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
        return "-" if not values else " / ".join(f"{x:.2f}" for x in values)

    def rest(r):
        return "-" if r is None else f"{r['voltage_V']:.2f} V at {r['current_A']:.2f} A"

    rows = [("duration [s]", lambda s: f(s["duration_s"], ".1f")),
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
                  " / ".join(f"{1000 * x:.0f}" for x in s["rmse_cell_V"]))]
    rows.append(("under the cutoff: first dip / for good [s]",
                 lambda s: f"{f(s.get('cutoff_dip_at_s'), '.1f')} / "
                           f"{f(s.get('cutoff_reached_at_s'), '.1f')}"))
    rows.append(("remaining at mid-flight [s]", _mid_flight_text))
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
            parts.append(f"{name} {mid[key]:.0f}")
    return ", ".join(parts) or "-"


BUG_LINE = "this is a bug in dischargelab; please report it with the command you ran"

#: Library argument names and the options that set them, for error messages.
OPTION_OF_ARGUMENT = {"force": "--force", "cells_series": "--cells", "e0_V": "--e0",
                      "units": "--units", "columns": "--columns", "chemistry": "--chemistry"}


def cli_message(exc: DischargelabError) -> str:
    """One line for a library error, with library arguments named as options."""
    from .atomic import OutputExistsError
    from .plausibility import PlausibilityError

    if isinstance(exc, OutputExistsError):
        text = (f"{exc.path} already exists; choose another file name, or pass --force to "
                "replace it")
    elif isinstance(exc, PlausibilityError):
        text = exc.text(OPTION_OF_ARGUMENT)
    else:
        text = str(exc)
    return " ".join(text.split())


def _usage_line(exc: click.ClickException) -> str:
    text = " ".join(exc.format_message().split())
    ctx = getattr(exc, "ctx", None)
    if ctx is not None:
        text += f" (see: {ctx.command_path} --help)"
    return text


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``dischargelab`` command.

    Exit status: 0 success, 2 an error the user can fix (one line on stderr),
    1 a bug (traceback and a request to report it), 130 interrupted; ``acquire``
    adds its own (see its ``--help``). ``DISCHARGELAB_DEBUG=1`` re-raises every
    error with its traceback.
    """
    debug = os.environ.get("DISCHARGELAB_DEBUG") == "1"
    try:
        code = app.main(args=argv, prog_name="dischargelab", standalone_mode=False)
    except click.ClickException as exc:
        err.print(f"error: {_usage_line(exc)}", markup=False)
        sys.exit(2)
    except click.exceptions.Abort:
        err.print("aborted")
        sys.exit(130)
    except KeyboardInterrupt:
        err.print("interrupted")
        sys.exit(130)
    except BrokenPipeError:
        sys.exit(1)
    except DischargelabError as exc:
        if debug:
            raise
        err.print(f"error: {cli_message(exc)}", markup=False)
        sys.exit(2)
    except Exception:  # not a user error: show everything, never hide it
        if debug:
            raise
        traceback.print_exc()
        err.print(BUG_LINE, markup=False)
        sys.exit(1)
    sys.exit(code if isinstance(code, int) else 0)


# --- calibration and load commands ---

def _read_pairs_interactively() -> list[tuple[float, float]]:
    """Ask for REAL,MEASURED pairs on stdin until an empty line or end of input."""
    from .acquire.calibration import parse_pair

    err.print("Type one point per line as MULTIMETER_V,LOGGER_V (e.g. 11.88,2.71); "
              "an empty line ends.", markup=False)
    pairs: list[tuple[float, float]] = []
    while True:
        try:
            text = click.prompt(f"point {len(pairs) + 1}", default="", show_default=False,
                                err=True)
        except click.exceptions.Abort:
            break
        if not text.strip():
            break
        try:
            pairs.append(parse_pair(text, len(pairs) + 1))
        except DischargelabError as exc:
            err.print(f"  {exc}; try again", markup=False)
    return pairs


@app.command("calibrate")
@click.option("--pair", "pairs", multiple=True, metavar="REAL,MEASURED",
              help="Multimeter reading and logger reading of one voltage [V] (repeat).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False),
              help="CSV of points: two columns (multimeter, logger) or named real_V,measured_V.")
@click.option("--divider", default="", metavar="NAME",
              help="Name of the divider (stored; selects rows of a CSV 'divider' column).")
@click.option("--meter-percent", default=0.8, show_default=True, type=click.FloatRange(0),
              help="Multimeter accuracy, percent of reading (paper: Minipa ET-1002).")
@click.option("--meter-digits", default=5, show_default=True, type=click.IntRange(0),
              help="Multimeter accuracy, digits.")
@click.option("--meter-resolution", default=0.01, show_default=True,
              type=click.FloatRange(0, min_open=True), metavar="V",
              help="Multimeter resolution on the range used [V].")
@click.option("--adc-bits", default=10, show_default=True, type=click.IntRange(1, 32),
              help="Logger ADC bits (Arduino Uno: 10).")
@click.option("--adc-reference", default=5.0, show_default=True,
              type=click.FloatRange(0, min_open=True), metavar="V",
              help="Logger ADC reference [V].")
@click.option("--offset", type=click.Choice(["auto", "yes", "no"]), default="auto",
              show_default=True, help="Fit an offset: only if significant (auto), always, never.")
@click.option("--alpha", default=0.05, show_default=True, type=click.FloatRange(0, 1,
              min_open=True, max_open=True), help="Significance level of the offset tests.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Write the calibration file (JSON) for 'acquire --calibration'.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Save a plot of Ke per point, the fit and the linear range (PNG, PDF).")
@force_option
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def calibrate_cmd(pairs, csv_path, divider, meter_percent, meter_digits, meter_resolution,
                  adc_bits, adc_reference, offset, alpha, output, plot_path, force, as_json):
    """Find the logger's scale factor Ke = V_real / V_measured (paper eq. 7).

    Give pairs of (multimeter reading, logger reading) taken with packs at
    several voltages. The command fits Ke through the origin, adds an offset only
    if it is significant (F-test and a chi-square test against the meter's stated
    accuracy), lists the residual of every point, flags points outside the linear
    range of the front end and prints the voltage resolution (ADC step x Ke).

    \b
    Examples:
      dischargelab calibrate --pair 15.33,3.51 --pair 13.16,3.01 --pair 11.88,2.71 \\
          --pair 11.26,2.57 --pair 7.67,1.74 --divider 3.3k -o cal.json
      dischargelab calibrate --csv points.csv --divider 2.7k --plot ke.png --json
      dischargelab calibrate -o cal.json          (type the points at the prompt)
      dischargelab acquire --calibration cal.json ...
    """
    from .acquire.calibration import MeterAccuracy, fit_calibration, parse_pair, read_points_csv

    if csv_path and pairs:
        raise DischargelabError("give the points either with --pair or with --csv, not both")
    guard_outputs([output, plot_path], [csv_path], force, figures=[plot_path])
    if csv_path:
        real, measured = read_points_csv(csv_path, divider or None)
    elif pairs:
        parsed = [parse_pair(text, i) for i, text in enumerate(pairs, start=1)]
        real, measured = [p[0] for p in parsed], [p[1] for p in parsed]
    else:
        parsed = _read_pairs_interactively()
        if not parsed:
            raise DischargelabError("no calibration points given; use --pair REAL,MEASURED, "
                                    "--csv FILE or type them at the prompt")
        real, measured = [p[0] for p in parsed], [p[1] for p in parsed]
    meter = MeterAccuracy(meter_percent, meter_digits, meter_resolution)
    result = fit_calibration(real, measured, divider=divider, meter=meter, adc_bits=adc_bits,
                             adc_reference_V=adc_reference, alpha=alpha, offset=offset)
    if output:
        result.calibration.save(output)
    if plot_path:
        from .errors import require
        from .plot import save

        require("matplotlib", "plot").use("Agg")
        ax = result.plot()
        ax.figure.tight_layout()
        save(ax, plot_path, dpi=120)
    if as_json:
        data = result.to_dict()
        data["output"] = output
        data["plot"] = plot_path
        print_json(data)
        return
    rows = [[f"{p.real_V:g}", f"{p.measured_V:g}", f"{p.ke:.4f}", f"{p.predicted_V:.3f}",
             f"{p.residual_V * 1000:+.0f}",
             "" if math.isnan(p.loo_residual_V) else f"{p.loo_residual_V * 1000:+.0f}",
             f"{p.bound_V * 1000:.0f}", p.status] for p in result.points]
    title = f"Calibration points{' (' + divider + ')' if divider else ''}"
    out.print(table(title, ["meter V", "logger V", "Ke", "fit V", "resid mV", "LOO mV",
                            "bound mV", "status"], rows))
    out.print(result.report(), markup=False)
    if output:
        out.print(f"calibration written to {output}; use it with: dischargelab acquire "
                  f"--calibration {output}", markup=False)


# --- acquisition commands ---

_ACQ_STATUS_HELP = ("exit status: 0 stopped by the user or --duration, 3 cutoff reached, "
                    "4 over-temperature, 5 link lost (--give-up-after), 6 internal error, "
                    "2 bad input")


def _source_choices() -> list[str]:
    from .acquire.sources import SOURCE_KINDS

    return list(SOURCE_KINDS)


def _acquire_summary_rows(result) -> list[list]:
    s = result.summary

    def num(key, fmt):
        value = s.get(key)
        return "-" if value is None else format(value, fmt)

    rows = [["ended by", result.ended_by], ["message", result.message or "-"],
            ["samples", s.get("samples", 0)], ["rows in file", s.get("rows_written", 0)],
            ["test time (s)", num("duration_s", ".1f")],
            ["first voltage (V)", num("first_voltage_V", ".3f")],
            ["last voltage (V)", num("last_voltage_V", ".3f")],
            ["min voltage (V)", num("min_voltage_V", ".3f")],
            ["charge (Ah)", num("charge_Ah", ".4f")], ["energy (Wh)", num("energy_Wh", ".3f")]]
    for key in ("frames_ok", "frames_lost", "frames_corrupt", "reconnects"):
        if key in result.stats:
            rows.append([key.replace("_", " "), result.stats[key]])
    rows.append(["load at the end", {"switched off": "switched off by dischargelab",
                                     "not switched off": "NOT switched off (switch it off)",
                                     "not driven": "not driven by dischargelab"}
                 [result.load_state]])
    rows.append(["data file", str(result.out)])
    from rich.markup import escape

    return [[escape(str(key)), escape(str(value))] for key, value in rows]


#: What the end-of-test alarm says about the load, by ``AcquireResult.load_state``.
_LOAD_LINES = {
    "switched off": "load switched off, test stopped",
    "not switched off": "test stopped, but the load could NOT be switched off: switch it off "
                        "by hand NOW",
    "not driven": "test stopped; dischargelab does not drive this load (no --switch-load "
                  "relay): switch it off by hand NOW",
}


def _report_acquisition(result, as_json: bool) -> None:
    if result.ended_by in ("cutoff", "over-temperature", "link-lost"):
        err.print(f"\a\n*** {result.message or result.ended_by} ***\n*** "
                  f"{_LOAD_LINES[result.load_state]}; event recorded in {result.out} ***",
                  style="bold red", markup=False)
    if result.error:
        err.print(f"error during the test: {result.error}", markup=False)
    if as_json:
        print_json(result.to_dict())
    else:
        out.print(table("Acquisition summary", ["", "value"], _acquire_summary_rows(result)))


@app.command("acquire", epilog=_ACQ_STATUS_HELP)
@click.option("--port", required=True, metavar="PORT",
              help="Serial port of the logger (/dev/ttyACM0, COM3, a virtual device's path).")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Log file to create (dischargelab log CSV); never overwritten without --force.")
@click.option("--source", "source_kind", default="arduino", show_default=True,
              type=click.Choice(_source_choices()), help="Kind of instrument on --port.")
@click.option("--cells", type=click.IntRange(1, 24), metavar="N",
              help="Cells in series (default: inferred from the first voltage, with a warning).")
@click.option("--chemistry", type=click.Choice(["lipo", "li-ion", "lifepo4"]), default="lipo",
              show_default=True, help="Sets the per-cell cutoff (3.0 / 2.5 / 2.5 V).")
@click.option("--cutoff-cell", type=click.FloatRange(0.5, 4.5), metavar="V",
              help="Per-cell cutoff voltage [V], overriding the chemistry preset.")
@click.option("--max-temp", type=float, default=60.0, show_default=True, metavar="C",
              help="Over-temperature limit [degC] (needs a temperature sensor).")
@click.option("--debounce", type=click.IntRange(1, 1000), default=3, show_default=True,
              metavar="N", help="Consecutive samples beyond a limit before it trips.")
@click.option("--rate", "rate_Hz", type=click.FloatRange(min=0.0003, min_open=False),
              default=1.0, show_default=True, metavar="HZ", help="Sample rate [Hz].")
@click.option("--calibration", "calibration_path", type=click.Path(dir_okay=False),
              help="Calibration file from 'dischargelab calibrate' (Ke and offset).")
@click.option("--ke", type=click.FloatRange(min=0, min_open=True), metavar="X",
              help="Divider gain Ke = V_real / V_measured (paper eq. 7; 4.38 for its 3.3 kOhm "
                   "divider).")
@click.option("--current", "current_A", type=click.FloatRange(min=0, min_open=True),
              metavar="A", help="Known constant discharge current [A] (for Ah and Wh; the "
                                "EBC load's set current).")
@click.option("--current-sensor", metavar="NAME",
              help="Current sensor on A1: acs712-5a, acs712-20a, acs712-30a or "
                   "shunt:V_PER_A[:ZERO_V].")
@click.option("--thermistor", is_flag=True,
              help="10 kOhm NTC (B 3950) on A2 with a 10 kOhm resistor to 5 V.")
@click.option("--switch-load", is_flag=True,
              help="Close the load relay (pin D7) at start; it is opened at any end.")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0, min_open=True),
              metavar="S", help="Stop after this much test time [s].")
@click.option("--plot", is_flag=True, help="Also open a live plot window (needs a display).")
@click.option("--live/--no-live", default=True, show_default=True,
              help="Terminal panel; --no-live prints a line every --every seconds.")
@click.option("--quiet", is_flag=True, help="Same as --no-live.")
@click.option("--every", "every_s", type=click.FloatRange(min=0.1), default=10.0,
              show_default=True, metavar="S", help="Seconds between lines without the panel.")
@click.option("--force", is_flag=True, help="Overwrite an existing --out file.")
@click.option("--logview", "logview_path", type=click.Path(dir_okay=False), metavar="FILE",
              help="Also write LogView OpenFormat lines to FILE (or a serial port).")
@click.option("--baud", type=click.IntRange(1200), metavar="BAUD",
              help="Serial baud rate (default: the source's own, 115200 for the Arduino).")
@click.option("--parity", type=click.Choice(["N", "E", "O"]), default=None,
              help="Serial parity (default: the source's own; the EBC-A loads are documented "
                   "with E by most sources, O by some: try O if no status frame arrives).")
@click.option("--give-up-after", "give_up_s", type=click.FloatRange(min=0, min_open=True),
              metavar="S", help="End the test if the link stays down this long [s] "
                                "(default: keep reconnecting until stopped).")
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def acquire_cmd(port, out_path, source_kind, cells, chemistry, cutoff_cell, max_temp, debounce,
                rate_Hz, calibration_path, ke, current_A, current_sensor, thermistor,
                switch_load, duration_s, plot, live, quiet, every_s, force, logview_path, baud,
                parity, give_up_s, as_json):
    """Log a discharge test from a serial instrument, with live view and safety cutoff.

    The producer/consumer program of the paper (section 3.2): samples are
    calibrated, written to a crash-safe log file (fsync every 0.5 s), shown live
    and checked against the cutoff; on a cutoff the load is switched off (when
    dischargelab drives it: --switch-load relay or an electronic load; otherwise
    you are told to switch it off), the event is recorded and the command exits
    with status 3. Ctrl-C stops cleanly.

    \b
    Examples:
      dischargelab acquire --port /dev/ttyACM0 --out run.csv --cells 3 --ke 4.38 --current 2
      dischargelab acquire --port COM3 --out run.csv --calibration cal.json --rate 2 --plot
      dischargelab acquire --port /dev/ttyACM0 --out run.csv --ke 4.38 --current-sensor \\
          acs712-20a --thermistor --chemistry lifepo4 --cells 4 --quiet --every 30
      dischargelab acquire --source ebc-a20 --port /dev/ttyUSB0 --out run.csv --cells 2 \\
          --current 1.7
    """
    from .acquire.acquisition import AcquireSettings, prepare_acquisition
    from .acquire.sensors import Thermistor
    from .acquire.sensors import current_sensor as make_current_sensor

    if calibration_path and ke is not None:
        raise DischargelabError("give either --calibration or --ke, not both")
    if plot:
        from .acquire.live import check_display

        check_display()                    # before the port is opened or a file created
    from .acquire.logview import is_serial_target

    logview_file = logview_path if logview_path and not is_serial_target(logview_path) else None
    guard_outputs([out_path, logview_file], [calibration_path], force)
    calibration = None
    if calibration_path:
        from .acquire.calibration import load_calibration

        calibration = load_calibration(calibration_path)
    elif ke is not None:
        from .acquire.calibration import Calibration

        calibration = Calibration(gain=ke)
    settings = AcquireSettings(
        port=port, out=Path(out_path), source=source_kind, cells=cells, chemistry=chemistry,
        cutoff_cell_V=cutoff_cell, max_temperature_C=max_temp, debounce_samples=debounce,
        rate_Hz=rate_Hz, calibration=calibration, current_A=current_A,
        current_sensor=make_current_sensor(current_sensor) if current_sensor else None,
        thermistor=Thermistor() if thermistor else None, baudrate=baud, parity=parity,
        switch_load=switch_load, duration_s=duration_s, force=force, logview=logview_path,
        give_up_after_s=give_up_s)
    acquisition = prepare_acquisition(settings)
    console = err if as_json else out
    view = "live" if live and not quiet and console.is_terminal else "lines"
    result = acquisition.run(view=view, console=console, every_s=every_s, plot=plot)
    _report_acquisition(result, as_json)
    sys.exit(result.exit_status)


@app.command("virtual-device")
@click.option("--battery", default="zippy-1100-2s", show_default=True, metavar="PRESET|FILE",
              help="Battery preset or battery file driving the simulated pack.")
@click.option("--cells", type=click.IntRange(1, 24), metavar="N",
              help="Cells in series (default: the battery's).")
@click.option("--current", "current_A", type=click.FloatRange(min=0), metavar="A",
              help="Load current [A] (default 1C).")
@click.option("--rate", "rate_Hz", type=click.FloatRange(min=0.0003), default=1.0,
              show_default=True, metavar="HZ", help="Sample rate at power-up (the host sets it).")
@click.option("--speed", type=click.FloatRange(min=0, min_open=True), default=1.0,
              show_default=True, metavar="X", help="Battery seconds per wall second.")
@click.option("--ke", "divider_gain", type=click.FloatRange(min=0, min_open=True), default=4.38,
              show_default=True, metavar="X", help="Divider gain of the simulated front end.")
@click.option("--noise-mV", "noise_mV", type=click.FloatRange(min=0), default=2.0,
              show_default=True, metavar="MV", help="RMS noise at the ADC pin [mV].")
@click.option("--drop-bytes", type=click.FloatRange(0, 1, max_open=True), default=0.0,
              show_default=True, metavar="P", help="Probability of losing each sample byte.")
@click.option("--corrupt", type=click.FloatRange(0, 1), default=0.0, show_default=True,
              metavar="P", help="Probability of flipping 1-3 bits in a sample frame.")
@click.option("--disconnect-after", type=click.FloatRange(min=0), metavar="S",
              help="Simulate an unplugged cable this many seconds after START.")
@click.option("--disconnect-for", type=click.FloatRange(min=0), default=2.0, show_default=True,
              metavar="S", help="How long the disconnect lasts.")
@click.option("--disconnect-mode", type=click.Choice(["close", "silent"]), default="close",
              show_default=True, help="close: the port vanishes and returns reset; silent: the "
                                      "board stops answering.")
@click.option("--baud", type=click.IntRange(min=0), default=0, show_default=True, metavar="BAUD",
              help="Pace output like a UART at this baud rate (0 = unpaced).")
@click.option("--relay", is_flag=True, help="Model a load relay switched by the host.")
@click.option("--link", type=click.Path(dir_okay=False), metavar="PATH",
              help="Create the port symlink here (default: a temporary directory).")
@click.option("--record", type=click.Path(dir_okay=False), metavar="FILE",
              help="Write every produced frame and its fate to this CSV.")
@click.option("--seed", type=int, default=0, show_default=True, help="Noise and fault seed.")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0, min_open=True),
              metavar="S", help="Exit after this many wall seconds (default: until Ctrl-C).")
@force_option
@click.option("--json", "as_json", is_flag=True,
              help="JSON Lines on stdout: one object when the port is ready (event "
                   "'started'), one with the summary when the device stops ('stopped').")
def virtual_device_cmd(battery, cells, current_A, rate_Hz, speed, divider_gain, noise_mV,
                       drop_bytes, corrupt, disconnect_after, disconnect_for, disconnect_mode,
                       baud, relay, link, record, seed, duration_s, force, as_json):
    """Run a virtual Arduino logger on a pseudo-terminal, driven by the battery model.

    Prints the port path, then answers the host like the firmware until Ctrl-C.

    \b
    Examples:
      dischargelab virtual-device --battery zippy-1100-2s --speed 60
      dischargelab virtual-device --link /tmp/ttyDLAB --corrupt 0.01 --drop-bytes 0.001
      dischargelab virtual-device --disconnect-after 10 --disconnect-for 3 --record sent.csv
    and in another terminal:
      dischargelab acquire --port /tmp/ttyDLAB --out run.csv --ke 4.38 --current 1.1
    """
    import signal
    import time as _time

    from .acquire.virtual_device import VirtualDevice

    guard_outputs([record], battery_input(battery), force)
    device = VirtualDevice(load_battery_arg(battery), cells_series=cells, current_A=current_A,
                           rate_Hz=rate_Hz, speed=speed, divider_gain=divider_gain,
                           noise_mV=noise_mV, drop_bytes=drop_bytes, corrupt=corrupt,
                           disconnect_after_s=disconnect_after, disconnect_for_s=disconnect_for,
                           disconnect_mode=disconnect_mode, baudrate=baud or None, seed=seed,
                           link=link, record=record, relay=relay)
    port = device.start()
    info = {"event": "started", "port": port, "battery": device.battery.name, "cells_series":
            device.battery.cells_series, "current_A": device.current_A, "speed": speed,
            "divider_gain": divider_gain}
    if as_json:
        print_json_line(info)
    else:
        out.print(port, markup=False)
        err.print(f"virtual logger: {device.battery.name} ({device.battery.cells_series}S), "
                  f"{device.current_A:g} A, x{speed:g}, Ke {divider_gain:g}; "
                  f"connect with: dischargelab acquire --port {port} --ke {divider_gain:g} "
                  f"--current {device.current_A:g} --out run.csv   (Ctrl-C stops)",
                  markup=False)
    sys.stdout.flush()

    def _term(signum, frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _term)
    end = None if duration_s is None else _time.monotonic() + duration_s
    try:
        while end is None or _time.monotonic() < end:
            _time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        device.stop()
    summary = device.summary()
    if as_json:
        print_json_line({"event": "stopped", **summary})
    else:
        err.print(table("Virtual logger stopped", ["", "value"], _device_summary_rows(summary)))


def _device_summary_rows(summary: dict) -> list[list]:
    """Rows of the virtual device's summary (see ``VirtualDevice.summary``)."""
    frames = summary["frames"]
    lost = {k: v for k, v in frames.items() if k not in ("produced", "sent") and v}
    rows = [["battery", f"{summary['battery']} ({summary['cells_series']}S), "
                        f"{summary['current_A']:g} A, x{summary['speed']:g}"],
            ["battery time (s)", f"{summary['battery_time_s']:.1f}"],
            ["charge drawn (Ah)", f"{summary['charge_Ah']:.4f}"],
            ["frames produced", frames.get("produced", 0)],
            ["frames sent intact", frames.get("sent", 0)]]
    rows += [[f"frames {key.replace('-', ' ')}", value] for key, value in lost.items()]
    rows += [["disconnects", summary["disconnects"]], ["commands received", summary["commands"]]]
    return rows


@app.command("demo-acquire")
@click.option("--out", "out_dir", default="demo-out", show_default=True,
              type=click.Path(file_okay=False), help="Folder for the log, record and plot.")
@click.option("--battery", default="zippy-1100-2s", show_default=True, metavar="PRESET|FILE",
              help="Battery driving the virtual logger.")
@click.option("--seconds", "wall_seconds", type=click.FloatRange(min=5), default=45.0,
              show_default=True, metavar="S", help="Wall-clock length of the discharge.")
@click.option("--seed", type=int, default=1, show_default=True, help="Noise seed.")
@click.option("--live/--no-live", default=True, show_default=True, help="Terminal panel.")
@force_option
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def demo_acquire_cmd(out_dir, battery, wall_seconds, seed, live, force, as_json):
    """A complete simulated test: virtual logger -> acquisition -> cutoff -> fit.

    A preset pack is discharged at 1C by a virtual logger on a pseudo-terminal
    (time compressed to about --seconds), logged through the real serial path
    until the cutoff trips, and the logged curve is fitted; the fitted
    coefficients are printed next to the true ones.

    \b
    Examples:
      dischargelab demo-acquire
      dischargelab demo-acquire --battery zippy-1100-2s --seconds 30 --out /tmp/demo
    """
    from .acquire.demo import check_acquire_demo, run_acquire_demo

    check_acquire_demo(out_dir, force)
    console = err if as_json else out
    view = "live" if live and console.is_terminal else "lines"
    summary = run_acquire_demo(out_dir, battery=load_battery_arg(battery),
                               wall_seconds=wall_seconds, seed=seed, view=view,
                               console=console, force=force)
    if as_json:
        print_json(summary)
        return
    out.print(f"ended by {summary['ended_by']}: {summary['message']}", markup=False)
    rows = [[r["parameter"], f"{r['true']:.5g}", f"{r['fitted']:.5g}",
             "fixed" if r["fixed"] else ("-" if r["stderr"] is None else f"{r['stderr']:.2g}")]
            for r in summary["parameters"]]
    rows.append(["E0 - R*i (cell)", f"{summary['E0_minus_Ri_true_V']:.5g}",
                 f"{summary['E0_minus_Ri_fitted_V']:.5g}", ""])
    out.print(table(f"Fitted vs true coefficients ({summary['battery']}, per cell)",
                    ["parameter", "true", "fitted", "stderr"], rows))
    out.print(f"fit RMSE {summary['rmse_V'] * 1000:.1f} mV per cell; logged "
              f"{summary['samples']} samples, lost {summary['stats'].get('frames_lost', 0)}, "
              f"corrupt {summary['stats'].get('frames_corrupt', 0)}", markup=False)
    for w in summary["warnings"]:
        out.print(f"warning: {w}", markup=False)
    out.print(f"files: {summary['log']}, {summary['device_record']}, {summary['plot']}",
              markup=False)


# --- mission, validation and report commands ---


def _duration_text(seconds) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "-"
    sign = "-" if seconds < 0 else ""
    minutes, secs = divmod(abs(float(seconds)), 60.0)
    return f"{sign}{int(minutes)} min {secs:04.1f} s"


def _progress_callback(status, what: str):
    def update(done, total):
        status.update(f"{what}: {done}/{total}")
    return update


def _validation_cases(battery, paths, cutoff, columns, current, sign, segment, units,
                      status=None, flight_options=None, low_timer_s=None):
    from .validate import compare_discharge

    return [compare_discharge(battery, data, meta, cutoff, low_timer_s=low_timer_s)
            for data, meta in read_data_files(paths, columns, current, sign, segment, units,
                                              status=status, verb="validating",
                                              flight_options=flight_options)]


def _print_mission(result) -> None:
    m = result.mission
    unc = result.uncertainty
    st = result.stretch
    head = _duration_text(result.endurance_s)
    if unc and unc.get("available"):
        e = unc["endurance_s"]
        head += (f"  (95 % interval {_duration_text(e['low'])} to {_duration_text(e['high'])}: "
                 + " + ".join(unc.get("interval_includes", ["parameters"]))
                 + (f", {unc['accepted']} draws)" if unc.get("accepted") else ")"))
    else:
        head += "  (95 % interval unavailable: " + (
            unc["reason"] if unc else "no uncertainty requested (--draws 0)") + ")"
    label = "endurance, landing at the reserve" if st else "flight time"
    out.print(f"{m.name}: {label} {head}", markup=False)
    rows = [["battery", f"{m.battery.name or '-'} ({m.battery.cells_series}S"
                        f"{m.battery.strings_parallel}P, {m.capacity_Ah:.3f} Ah)"],
            ["cutoff / reserve", f"{m.cutoff_cell_V:g} V/cell ({m.cutoff_pack_V:.2f} V pack) / "
                                 f"{m.reserve_pct:g} %"],
            ["flight as planned", f"{_duration_text(result.flight_time_s)}"
                                  + ("" if result.completed else
                                     f" (NOT completed: {result.ended_by})")],
            ["state of charge at landing", f"{result.soc_end_pct:.1f} %"],
            ["reserve reached at", _duration_text(result.reserve_time_s)],
            ["cutoff reached at", _duration_text(result.cutoff_time_s)],
            ["lowest pack voltage", f"{result.min_voltage_V:.3f} V "
                                    f"(margin {result.voltage_margin_V:.3f} V)"],
            ["charge / energy used", f"{result.simulation.capacity_Ah:.3f} Ah / "
                                     f"{result.simulation.energy_Wh_total:.1f} Wh"]]
    if st:
        rows.append([f"max {st['phase']}", f"{_duration_text(st['max_s'])} "
                                          f"(limited by the {st['binding']})"])
        if st["margin_s"] is not None:
            rows.append([f"margin on {st['phase']}", _duration_text(st["margin_s"])])
    out.print(table("Endurance", ["quantity", "value"], rows))
    phase_rows = [[r["phase"] + (f" #{r['repetition']}" if r["repetition"] else ""), r["load"],
                   f"{r['start_s']:.0f}", f"{r['duration_s']:.1f}", f"{r['mean_current_A']:.2f}",
                   f"{r['charge_Ah']:.3f}", f"{r['end_voltage_V']:.3f}",
                   f"{r['end_soc_pct']:.1f}"] for r in result.phases]
    if len(phase_rows) > 30:
        phase_rows = phase_rows[:12] + [["...", "", "", "", "", "", "", ""]] + phase_rows[-12:]
    out.print(table("Phases", ["phase", "load", "start [s]", "duration [s]", "current [A]",
                               "charge [Ah]", "end V", "end SOC [%]"], phase_rows))
    for w in result.warnings:
        out.print(f"warning: {w}", markup=False)


@app.command("endurance")
@click.argument("battery")
@click.argument("mission", type=click.Path(dir_okay=False))
@click.option("--cutoff", type=float, metavar="V",
              help="Cutoff voltage per cell [V] (overrides the mission file).")
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
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def endurance_cmd(battery, mission, cutoff, reserve, cells, parallel, ambient, draws, seed,
                  plot_path, csv_path, force, as_json):
    """Fly a mission (TOML) on a battery: flight time, max cruise, margin and its interval.

    BATTERY is a battery file from `fit` or a preset name; MISSION a TOML file of
    phases (current, power or flight condition; duration, until cutoff/reserve,
    repeat blocks; one phase may be `stretch = true`). Bundled examples by name:
    paper-table5, fixed-wing-survey, multirotor-hover.

    \b
    Examples:
      dischargelab endurance hacker-4100-4s-lifepo4 paper-table5
      dischargelab endurance battery.json mission.toml --reserve 25 --plot flight.png
      dischargelab endurance cell.json mission.toml --cells 4 --parallel 2 --cutoff 3.0
      dischargelab endurance battery.json mission.toml --draws 500 --json
    """
    from .mission import load_mission, run_mission

    guard_outputs([plot_path, csv_path], battery_input(battery) + [mission], force,
                  figures=[plot_path])
    plan = load_mission(mission, battery=load_battery_arg(battery), cutoff_cell_V=cutoff,
                        reserve_pct=reserve, ambient_C=ambient)
    plan = plan.with_battery(plan.battery.with_pack(cells, parallel))
    with err.status("flying the mission", spinner="dots") as status:
        result = run_mission(plan, draws=draws, seed=seed,
                             progress=_progress_callback(status, "parameter draws"))
    if plot_path:
        from .plot import save

        save(result.plot(), plot_path)
    if csv_path:
        write_csv(result.to_pandas(), csv_path)
    if as_json:
        print_json(result.to_dict())
        return
    _print_mission(result)
    if plot_path:
        out.print(f"plot: {plot_path}", markup=False)


@app.command("validate")
@click.argument("battery")
@click.argument("data", nargs=-1, required=True)
@click.option("--cutoff", type=float, metavar="V", default=None,
              help="Cutoff voltage per cell [V] at which endurance is measured [default: the "
                   "battery chemistry's usual one: LiPo 3.0, Li-ion and LiFePO4 2.5].")
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
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def validate_cmd(battery, data, cutoff, columns, current, sign, segment, units, cells, parallel,
                 flight, low_timer, battery_index, plot_path, force, as_json):
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
    """
    from .validate import summarise

    paths = expand_paths(data)
    guard_outputs([plot_path], battery_input(battery) + paths, force, figures=[plot_path])
    bat = load_battery_arg(battery).with_pack(cells, parallel)
    cutoff = _cell_cutoff(bat, cutoff)
    chosen = {k: v for k, v in (("flight", flight), ("battery", battery_index)) if v is not None}
    with err.status("validating", spinner="dots") as status:
        cases = _validation_cases(bat, paths, cutoff, columns, current, sign, segment, units,
                                  status, flight_options=chosen, low_timer_s=low_timer)
    if plot_path:
        from .plot import plot_validation, save

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
             f(r["endurance_measured_s"], ".0f"), f(r["endurance_predicted_s"], ".0f"),
             "-" if r.get("interval_s") is None else
             f"{r['interval_s'][0]:.0f} to {r['interval_s'][1]:.0f}",
             {True: "yes", False: "NO", None: "-"}[r.get("covered")],
             f(r["endurance_error_s"], "+.0f"), f(r["endurance_error_pct"], "+.2f"),
             f(r["voltage_rmse_pct"], ".2f"), f(r["voltage_max_error_pct"], ".2f"),
             f(r["voltage_max_error_operational_pct"], ".2f"),
             {True: "yes", False: "no", None: "?"}[r["in_fit"]]] for r in rows]
    out.print(table(f"Validation to {cutoff:g} V/cell ({bat.cells_series}S{bat.strings_parallel}P)",
                    ["file", "current [A]", "measured [s]", "predicted [s]", "95 % interval [s]",
                     "covered", "error [s]", "error [%]", "V RMS [%]", "V max [%]",
                     "V max >20% SOC [%]", "in fit"], body))
    out.print(f"mean |endurance error| {f(summary['mean_abs_endurance_error_pct'], '.2f')} %, "
              f"worst {f(summary['max_abs_endurance_error_pct'], '.2f')} %", markup=False)
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


@app.command("report")
@click.argument("battery")
@click.option("--mission", "mission_path", type=click.Path(dir_okay=False),
              help="Mission TOML to fly and report.")
@click.option("--validate", "validate_paths", multiple=True, metavar="DATA",
              help="Measured discharge to validate against (repeat, or a quoted pattern "
                   "such as 'runs/*.csv').")
@click.option("--cutoff", type=float, metavar="V",
              help="Cutoff per cell [V] for validation and curves (default: the mission's, "
                   "else the chemistry's).")
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
@click.option("--json", "as_json", is_flag=True, help=JSON_HELP)
def report_cmd(battery, mission_path, validate_paths, cutoff, columns, current, sign, segment,
               units,
               cells, parallel, draws, seed, title, output, force, as_json):
    """Write one self-contained HTML report for the pilot: model, fit, mission, validation.

    \b
    Examples:
      dischargelab report battery.json -o report.html
      dischargelab report battery.json --mission mission.toml --validate 'runs/*.csv' \\
          --cutoff 3.0 --columns time_s=0,current_A=1,voltage_V=2 -o report.html
      dischargelab report hacker-4100-4s-lifepo4 \\
          --mission paper-table5 -o table5.html
    """
    from .mission import load_mission, run_mission
    from .model import CUTOFF_CELL_VOLTAGE_V
    from .report import write_report
    from .validate import summarise

    if not output.lower().endswith((".html", ".htm")):
        raise DischargelabError(f"-o must name an .html file, got {output!r}")
    validate_paths = expand_paths(validate_paths)
    guard_outputs([output], battery_input(battery) + [mission_path] + validate_paths, force)
    from .errors import require

    require("matplotlib", "plot")  # the report's figures; checked before any work
    bat = load_battery_arg(battery)
    result = None
    cases = []
    with err.status("building the report", spinner="dots") as status:
        if mission_path:
            status.update("flying the mission")
            plan = load_mission(mission_path, battery=bat, cutoff_cell_V=cutoff)
            plan = plan.with_battery(plan.battery.with_pack(cells, parallel))
            result = run_mission(plan, draws=draws, seed=seed,
                                 progress=_progress_callback(status, "parameter draws"))
        if validate_paths:
            cut = cutoff
            if cut is None and result is not None:
                cut = result.mission.cutoff_cell_V
            if cut is None:
                cut = CUTOFF_CELL_VOLTAGE_V.get(bat.chemistry or "")
            if cut is None:
                raise DischargelabError("give --cutoff V (per cell) for the validation: the "
                                        "battery's chemistry is unknown")
            cases = _validation_cases(bat, validate_paths, cut, columns, current, sign, segment,
                                      units, status)
        status.update("drawing plots")
        label = battery if isinstance(battery, str) else None
        from .atomic import atomic_path

        with atomic_path(output) as tmp:
            write_report(tmp, bat if bat.name else label, mission_result=result,
                         validation=cases, title=title, cutoff_cell_V=cutoff)
        path = Path(output)
    summary = {"report": str(path), "bytes": path.stat().st_size,
               "mission": None if result is None else result.to_dict(),
               "validation": [c.summary for c in cases],
               "validation_summary": summarise([c.summary for c in cases]) if cases else None}
    if as_json:
        summary["mission"] = None if result is None else {
            k: v for k, v in result.to_dict().items() if k != "phases"}
        print_json(summary)
        return
    out.print(f"report written: {path} ({summary['bytes'] / 1024:.0f} KiB)", markup=False)
    if result is not None:
        _print_mission(result)


if __name__ == "__main__":  # pragma: no cover
    main()
