"""What every command group shares: consoles, JSON output, tables, option types
(``--columns`` and the other data options, ``--cutoff``, ``--json``, ``--force``),
reading data files, the output policy and one-line error messages."""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import click
from rich.console import Console
from rich.table import Table
from rich.text import Text

from ..errors import DischargelabError

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}



# Piped or redirected output gets wide tables instead of rich's 80-column default.
out = Console(highlight=False, soft_wrap=True,
              width=None if sys.stdout.isatty() or os.environ.get("COLUMNS") else 160)
err = Console(stderr=True, highlight=False, soft_wrap=True)

JSON_HELP = "Print the result as JSON alone on stdout (for scripts)."


def json_option(func):
    """The ``--json`` flag of every command (JSON alone on stdout)."""
    return click.option("--json", "as_json", is_flag=True, help=JSON_HELP)(func)


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
        click.option("--step", "steps", multiple=True, metavar="N[,N...]",
                     help="Battery tester files (Neware, BioLogic, Arbin, Maccor): the discharge "
                          "steps to use, numbered as `dischargelab steps FILE` lists them "
                          "(repeatable or a comma list) [default: fit takes the first full "
                          "discharge at each rate, validate every discharge step]."),
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


PACK_DB_HELP = "Logbook of --pack (default: $DISCHARGELAB_DB, else the user's logbook)."


def pack_options(pack_help: str):
    """``--pack NAME`` and ``--db URL|FILE`` of every command that reads a logbook pack's
    model as of today (endurance, report, autopilot-params, autopilot-script); the
    command's BATTERY argument is then left out."""
    def decorate(func):
        func = click.option("--db", metavar="URL|FILE", help=PACK_DB_HELP)(func)
        return click.option("--pack", "pack_name", metavar="NAME", help=pack_help)(func)
    return decorate


def guard_outputs(outputs, inputs=(), force=False, figures=()) -> None:
    """Apply the output policy before any work (:func:`dischargelab.atomic.check_outputs`).

    ``figures`` are the outputs that are plots: their suffix must name a format.
    """
    from ..atomic import check_outputs
    from ..errors import require

    check_outputs(outputs, inputs, force)
    figures = [f for f in figures if f]
    if figures:
        from ..plot import check_path

        for figure in figures:
            check_path(figure)
        require("matplotlib", "plot")


def battery_input(battery) -> list:
    """The battery argument as an input path when it names a file (not a preset)."""
    return [battery] if battery is not None and Path(str(battery)).is_file() else []


def load_battery_arg(battery):
    """Load a BATTERY argument (battery file or preset); errors name the battery file."""
    from ..errors import DataError
    from ..model import load_battery

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
    from ..atomic import write_text

    return write_text(path, frame.to_csv(index=False))


def number_list(values, option: str, what: str) -> list[int] | None:
    """``--step 7 --step 12,17`` as [7, 12, 17]; None when not given (numbers count from 1)."""
    if not values:
        return None
    numbers = []
    for value in values:
        for part in str(value).split(","):
            try:
                number = int(part)
            except ValueError:
                raise DischargelabError(f"{option} expects {what} numbers such as 1 or 1,2,3; "
                                        f"got {value!r}") from None
            if number < 1:
                raise DischargelabError(f"{option} numbers count from 1; got {number}")
            numbers.append(number)
    return numbers


def read_data_files(paths, columns=None, current=None, sign="auto", segment="auto", units=None,
                    status=None, verb="reading", flight_options=None, steps=None,
                    choose="fit"):
    """Read measured files with the shared data options; returns [(data, meta), ...].

    A battery tester's file gives several discharges: ``steps`` (``--step``), else
    ``choose`` (``"fit"`` or ``"all"``, see :func:`dischargelab.io.read_discharges`).
    Raises DischargelabError with one line on bad options or input.
    """
    from ..atomic import check_inputs
    from ..io import parse_columns, parse_units, read_discharges

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
        loaded.extend(read_discharges(path, steps=number_list(steps, "--step", "step"),
                                      choose=choose,
                                      columns=column_map, current_A=amps, sign=sign,
                                      segment=segment, units=unit_map, **(flight_options or {})))
    return loaded


def check_plausible(loaded, pack: dict, strict: bool = False) -> list:
    """Plausibility of read files for the described pack (:mod:`dischargelab.plausibility`).

    Errors (and warnings when ``strict``) raise; the warnings are returned for
    :func:`print_data_warnings`.
    """
    from ..plausibility import check_discharges, check_given_current, raise_for

    return raise_for(check_discharges(loaded, **pack) + check_given_current(loaded),
                     strict=strict)


def print_data_warnings(warnings) -> None:
    """Data warnings change the result: always on stderr, whatever --quiet or --json say."""
    for finding in warnings:
        err.print(f"warning: {finding.text(OPTION_OF_ARGUMENT)}", markup=False)


def load_curves(paths, columns=None, current=None, sign="auto", segment="auto", units=None,
                pack=None, strict=False, status=None, steps=None):
    """Read files into fit curves after the plausibility checks.

    ``pack`` holds the keyword arguments of
    :func:`dischargelab.plausibility.check_discharges` (cells_series,
    strings_parallel, chemistry, e0_V). Returns ``(curves, metas, warnings)``.
    """
    from ..fit import Curve
    from ..io import discharge_label

    loaded = read_data_files(paths, columns, current, sign, segment, units, status=status,
                             steps=steps, choose="fit")
    warnings = check_plausible(loaded, pack or {}, strict)
    curves, metas = [], []
    for data, meta in loaded:
        curves.append(Curve.from_frame(data, meta, name=discharge_label(meta)))
        metas.append(meta)
    return curves, metas, warnings




CHEMISTRY_CUTOFF = "the battery chemistry's usual one: LiPo 3.0, Li-ion and LiFePO4 2.5"


def cutoff_option(role: str = "", default: str = CHEMISTRY_CUTOFF):
    """The ``--cutoff`` option (volts per cell): what it sets and its default, in the help."""
    text = "Cutoff voltage per cell [V]" + (f" {role}" if role else "")
    return click.option("--cutoff", type=float, metavar="V", default=None,
                        help=f"{text} [default: {default}].")


def cutoff_options(func):
    func = click.option("--cutoff-pack", type=float, metavar="V",
                        help="Cutoff voltage of the whole pack [V] (instead of --cutoff).")(func)
    func = cutoff_option()(func)
    func = click.option("--parallel", type=click.IntRange(1), default=None,
                        help="Strings in parallel (default: as in the battery file).")(func)
    func = click.option("--cells", type=click.IntRange(1), default=None,
                        help="Cells in series (default: as in the battery file).")(func)
    return func


def battery_and_cutoff(battery_arg, cells, parallel, cutoff, cutoff_pack):
    from ..plausibility import check_cutoff

    battery = load_battery_arg(battery_arg).with_pack(cells, parallel)
    per_cell = cell_cutoff(battery, cutoff, cutoff_pack)
    if cutoff_pack is not None:
        per_cell_given = cutoff_pack / battery.cells_series
    else:
        per_cell_given = per_cell
    print_data_warnings(check_cutoff(per_cell_given, battery.chemistry))
    return battery, {"cutoff_cell_V": per_cell, "cutoff_pack_V": cutoff_pack}


def cell_cutoff(battery, cutoff, cutoff_pack=None):
    """The per-cell cutoff: the given one, else the battery chemistry's usual one
    (:func:`dischargelab.predict.default_cutoff`, said on stderr), else a one-line error
    naming the options."""
    from ..errors import SimulationError
    from ..predict import default_cutoff

    if cutoff is not None and cutoff_pack is not None:
        raise DischargelabError("give either --cutoff (per cell) or --cutoff-pack, not both")
    if cutoff is not None or cutoff_pack is not None:
        return cutoff
    try:
        value = default_cutoff(battery)["cutoff_cell_V"]
    except SimulationError:
        raise DischargelabError("give a cutoff: --cutoff V per cell (e.g. 3.0 LiPo, 2.5 "
                                "Li-ion) or --cutoff-pack V (the battery file names no "
                                "chemistry, and its fitted runs stopped at different "
                                "voltages)") from None
    why = (f"the usual one for {battery.chemistry}" if battery.chemistry else
           "where every fitted run stopped (the battery file names no chemistry)")
    err.print(f"cutoff {value:g} V/cell, {why} (--cutoff to change it)", markup=False)
    return value



BUG_LINE = "this is a bug in dischargelab; please report it with the command you ran"

#: Library argument names and the options that set them, for error messages.
OPTION_OF_ARGUMENT = {"force": "--force", "cells_series": "--cells", "e0_V": "--e0",
                      "units": "--units", "columns": "--columns", "chemistry": "--chemistry",
                      "current": "--current", "cutoff_cell_V": "--cutoff"}


def cli_message(exc: DischargelabError) -> str:
    """One line for a library error, with library arguments named as options."""
    from ..atomic import OutputExistsError
    from ..plausibility import PlausibilityError

    if isinstance(exc, OutputExistsError):
        text = (f"{exc.path} already exists; choose another file name, or pass --force to "
                "replace it")
    elif isinstance(exc, PlausibilityError):
        text = exc.text(OPTION_OF_ARGUMENT)
    else:
        text = str(exc)
    return " ".join(text.split())


def usage_line(exc: click.ClickException) -> str:
    text = " ".join(exc.format_message().split())
    ctx = getattr(exc, "ctx", None)
    if ctx is not None:
        text += f" (see: {ctx.command_path} --help)"
    return text



def progress_callback(status, what: str):
    def update(done, total):
        status.update(f"{what}: {done}/{total}")
    return update


def validation_cases(battery, paths, cutoff, columns, current, sign, segment, units,
                      status=None, flight_options=None, low_timer_s=None, steps=None):
    from ..validate import compare_discharge, input_warnings

    loaded = read_data_files(paths, columns, current, sign, segment, units, status=status,
                             verb="validating", flight_options=flight_options, steps=steps,
                             choose="all")
    cases = [compare_discharge(battery, data, meta, cutoff, low_timer_s=low_timer_s)
             for data, meta in loaded]
    input_warnings(battery, loaded, cases, cutoff, options=OPTION_OF_ARGUMENT)
    return cases


def executor_options(func):
    """``--workers`` and ``--scheduler``: where fleet work runs (:mod:`dischargelab.fleet`)."""
    func = click.option(
        "--scheduler", metavar="tcp://HOST:PORT",
        help="Run the work on an existing Dask cluster [default: $DISCHARGELAB_SCHEDULER]; "
             "files its workers cannot see are sent to them.")(func)
    return click.option(
        "--workers", type=click.IntRange(1), default=None, metavar="N",
        help="Run the work on N Dask worker processes on this machine (extra dask) "
             "[default: 1, in this process].")(func)


def open_executor(workers, scheduler, background: bool = False):
    """The executor for ``--workers`` / ``--scheduler``, said on stderr when it is Dask.

    ``background=True`` starts a Dask cluster in a thread and returns at once (the command
    goes on with its own work meanwhile); the line is printed when the workers are up.
    """
    from ..fleet import InProcessExecutor, executor

    def ready(chosen) -> None:
        err.print(f"running on {chosen.describe()}", markup=False)

    if background:
        return executor(workers=workers, scheduler=scheduler, background=True, on_ready=ready)
    with err.status("starting the Dask workers", spinner="dots"):
        chosen = executor(workers=workers, scheduler=scheduler)
    if not isinstance(chosen, InProcessExecutor):
        ready(chosen)
    return chosen


def progress_bar(description: str):
    """A rich progress bar on stderr and its ``progress(done, total, message)`` callback."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                   TimeRemainingColumn(), console=err, transient=True)
    task = bar.add_task(description, total=None)

    def progress(done, total, message):
        bar.update(task, completed=done, total=total, description=f"{description} {message[:40]}")
    return bar, progress
