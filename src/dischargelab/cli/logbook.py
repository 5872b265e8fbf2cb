"""``dischargelab logbook``: add tests and flights to a pack, its health, events, export.

A thin layer over :class:`dischargelab.Logbook`: parse, call, print a table or JSON.
"""

from __future__ import annotations

import click

from ..errors import DischargelabError
from ..formatting import duration, interval, number, pack_text, quantity
from .common import (
    CONTEXT,
    err,
    executor_options,
    force_option,
    guard_outputs,
    json_option,
    open_executor,
    out,
    print_json,
    progress_bar,
    table,
)

DB_HELP = ("Logbook database: a SQLite file or a postgresql+psycopg://user@host/db URL "
           "(default: $DISCHARGELAB_DB, else logbook.sqlite in the user data folder).")


def db_option(func):
    return click.option("--db", metavar="URL|FILE", help=DB_HELP)(func)


def eol_option(func):
    return click.option("--eol", type=click.FloatRange(0, 1, min_open=True, max_open=True),
                        default=0.8, show_default=True,
                        help="End of life: this share of the reference capacity.")(func)


def open_logbook(db, create: bool = False):
    """The logbook at ``db``; only commands that add to it create a new one."""
    from ..logbook import Logbook

    return Logbook(db, create=create)


def refresh_stale(lb, names=None) -> None:
    """Recompute, with a progress bar, the stored figures that are older than their packs
    (after an upgrade, an interrupted add); a logbook that cannot be written is read as it
    is (the figures are then computed in memory)."""
    from ..errors import LogbookStorageError

    stale = lb.stale(names)
    if not stale:
        return
    bar, progress = progress_bar("recomputing figures")
    try:
        with bar:
            lb.refresh(stale, progress=progress)
    except LogbookStorageError as exc:
        if exc.reason not in ("read-only", "full"):
            raise


_num = number          # one rounding and one open interval for every view (formatting.py)
_interval = interval


@click.group("logbook", context_settings=CONTEXT)
def logbook_group() -> None:
    """Every pack's tests and flights in one database: health, end of life, flight time today.

    \b
    Examples:
      dischargelab logbook add runs/ --pack zippy-a --recursive
      dischargelab logbook add logs/*/ --pack-from parent
      dischargelab logbook packs
      dischargelab logbook health zippy-a --plot zippy-a.png
      dischargelab logbook events zippy-a --json
      dischargelab logbook export all.csv
      dischargelab logbook fit --all --workers 4
      dischargelab logbook report --fleet -o fleet.html
      dischargelab endurance --pack zippy-a paper-table5
    """


@logbook_group.command("add", context_settings=CONTEXT)
@click.argument("paths", nargs=-1, required=True, metavar="FILE|DIR...")
@click.option("--pack", metavar="NAME", help="The pack every file belongs to.")
@click.option("--pack-from", type=click.Choice(["parent"]),
              help="Take each file's pack from the name of its folder.")
@click.option("-r", "--recursive", is_flag=True, help="Descend into sub-folders.")
@click.option("--columns", metavar="SPEC",
              help="Column mapping for files whose header does not say, e.g. "
                   "time_s=0,current_A=1,voltage_V=2,temperature_C=4.")
@click.option("--current", "current_A", type=float, metavar="A",
              help="Constant discharge current [A] for files without a current column.")
@click.option("--sign", type=click.Choice(["auto", "positive", "negative"]), default="auto",
              show_default=True, help="Sign of the DISCHARGE current in the files.")
@click.option("--units", metavar="SPEC", help="Source units, e.g. voltage_V=mV,current_A=mA.")
@click.option("--capacity", "label_capacity_Ah", type=click.FloatRange(min=0, min_open=True),
              metavar="AH", help="The pack's label capacity [Ah] (reference of its EFC).")
@click.option("--chemistry", type=click.Choice(["lipo", "li-ion", "lifepo4"]),
              help="The pack's chemistry (for rest-voltage states of charge).")
@click.option("--cells", type=click.IntRange(1), help="The pack's cells in series.")
@click.option("--keep-raw/--no-keep-raw", default=True, show_default=True,
              help="Keep each file's bytes (compressed) in the logbook, or record only its "
                   "path and SHA-256 (a smaller database; the files must stay where they are).")
@executor_options
@db_option
@json_option
def add_cmd(paths, pack, pack_from, recursive, columns, current_A, sign, units,
            label_capacity_Ah, chemistry, cells, keep_raw, workers, scheduler, db, as_json):
    """Add test files, logger files and flight logs to a pack.

    Each file is kept by its SHA-256 (adding it again adds nothing and says so);
    each discharge or flight in it becomes an event. A file that cannot be read
    is rejected with one line and the others go in. Folders give their data files
    (.csv .txt .tsv .lvm .log .bin .ulg .bbl .bfl .tlog .dat, and testers' .nda
    .ndax .mpr .mpt .res .xlsx and Maccor's .001, .002...). Exit status 2 when
    every file was rejected.

    With --workers N or --scheduler the files are read on Dask workers; this
    process alone writes the database, in batches. Ctrl-C keeps what is done:
    run the same command again and only what is missing is read.

    \b
    Examples:
      dischargelab logbook add DischargeCycle*.txt --pack cell-C
      dischargelab logbook add flights/ --pack zippy-a --capacity 5.0 --cells 6
      dischargelab logbook add bench/ --pack-from parent --recursive
      dischargelab logbook add fleet-logs/ --pack-from parent -r --workers 8
      dischargelab logbook add fleet-logs/ --pack-from parent -r --scheduler tcp://10.0.0.5:8786
    """
    options = {"columns": columns, "current_A": current_A, "units": units,
               "sign": None if sign == "auto" else sign}
    settings = {"label_capacity_Ah": label_capacity_Ah, "chemistry": chemistry, "cells": cells}
    if any(v is not None for v in settings.values()) and not pack:
        raise DischargelabError("--capacity, --chemistry and --cells need --pack NAME")
    bar, progress = progress_bar("adding")
    # the workers come up while the logbook is opened and the files are listed and hashed
    with open_executor(workers, scheduler, background=True) as executor, \
            open_logbook(db, create=True) as lb:
        if any(v is not None for v in settings.values()):
            lb.set_pack(pack, refresh=False, **settings)   # refreshed with the add
        with bar:
            result = lb.add(list(paths), pack=pack, pack_from=pack_from, recursive=recursive,
                            executor=executor, progress=progress, keep_raw=keep_raw,
                            **{k: v for k, v in options.items() if v})
            if pack and pack not in result.changed:
                lb.refresh([pack], executor=executor, progress=progress)
    if as_json:
        print_json(result.to_dict())
    else:
        out.print(result.summary(), markup=False)
        for line in result.lines():
            (err if "rejected" in line else out).print(line, markup=False)
    if result.rejected and not result.added and not result.skipped:
        raise SystemExit(2)


@logbook_group.command("packs", context_settings=CONTEXT)
@eol_option
@db_option
@json_option
def packs_cmd(eol, db, as_json):
    """List the packs: events, EFC, capacity (95 % interval) and resistance today, end of life.

    \b
    Examples:
      dischargelab logbook packs
      dischargelab logbook packs --db team.sqlite --json
    """
    with open_logbook(db) as lb:
        refresh_stale(lb)
        result = lb.packs(eol=eol)
    if as_json:
        data = result.to_dict()
        data["rows"] = [dict(r, text=pack_text(r)) for r in data["rows"]]
        print_json(data)
        return
    rows = []
    for r in result.rows:
        text = pack_text(r)
        rows.append([r["name"], r["events"], text["efc"], text["capacity_Ah"],
                     text["capacity_interval95"], text["capacity_fraction"].removesuffix(" %"),
                     text["resistance_ohm"], text["eol_efc"], text["eol_efc_interval95"]])
    out.print(table("Packs", ["pack", "events", "EFC", "capacity today [Ah]", "95 % interval",
                              "of reference [%]", "resistance [mOhm]", "end of life [EFC]",
                              "95 % interval"], rows))


@logbook_group.command("health", context_settings=CONTEXT)
@click.argument("name")
@eol_option
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Save capacity and resistance against EFC with the forecast (PNG, SVG, PDF).")
@force_option
@db_option
@json_option
def health_cmd(name, eol, plot_path, force, db, as_json):
    """A pack's capacity and resistance per event, over its life, today, and its end of life.

    \b
    Per event: capacity with its 95 % interval (a full discharge: the charge it
    delivered; a partial event or a flight: the charge moved over the share of the
    capacity it used), resistance from its load steps (a sparse log: from how the
    voltage follows the current, or its distance to the open-circuit curve), EFC.
    Outliers (over- or undercharged cycles) are flagged and left out of the trends.
    Over the life: the estimates combined by their intervals (a smoother over EFC)
    into the capacity today with its 95 % interval, and the events it comes from; since
    the last full discharge, capacity today is taken below the estimates by a tenth of
    the resistance's relative rise (a 50 % rise: 5 %; lithium lost below the charge they
    swing through, where they cannot see it), its interval widened for it.
    Ahead: a trend that may bend (fast early fade, a knee) chosen by evidence
    against a straight line, and the EFC of end of life with a 95 % interval from
    simulated futures (knees that have not shown yet included). No end of life until
    the fade is told apart from zero ("no fade measured yet", with the EFC a typical
    fade needs to show), and none inside 5x today's EFC without a fade of 3 sigma
    over 20 EFC.

    \b
    Examples:
      dischargelab logbook health cell-C
      dischargelab logbook health cell-C --eol 0.7 --plot cell-C.png
      dischargelab logbook health cell-C --json
    """
    guard_outputs([plot_path], [], force, figures=[plot_path])
    with open_logbook(db) as lb:
        refresh_stale(lb, [name])
        health = lb.health(name, eol=eol)
    if plot_path:
        from ..plot import save

        save(health.plot()[0], plot_path)
    if as_json:
        print_json(health.to_dict())
        return
    rows = [_health_row(e) for e in health.events]
    head = ["source", "start", "kind", "discharged [Ah]", "capacity [Ah]", "95 % interval",
            "R [mOhm]", "R ref [mOhm]", "EFC", "note"]
    if any(r[-1] for r in rows):
        head.append("cells")
    else:
        rows = [r[:-1] for r in rows]
    out.print(table(f"Health of {name}", head, rows))
    for line in health_lines(health, name):
        out.print(line, markup=False)
    if plot_path:
        out.print(f"plot: {plot_path}", markup=False)


def _health_row(e) -> list:
    from ..logbook.health import NOT_FULL_NOTE

    d = e.to_dict()
    not_full = NOT_FULL_NOTE if any(n.startswith(NOT_FULL_NOTE) for n in e.notes) else ""
    note = "outlier" if e.outlier else (d.get("capacity_note") or not_full)
    return [e.source, (e.start or "-").replace("T", " "), d.get("kind") or "-",
            _num(e.discharged_Ah), _num(e.capacity_Ah), _interval(e.capacity_interval95, 3),
            _num(e.resistance_ohm, 1, 1000), _num(d.get("resistance_ref_ohm"), 1, 1000),
            _num(e.efc, 1), note, _cells(d.get("cells"))]


def _cells(cells) -> str:
    """An event's per-cell figures in a few words: rest spread, weakest cell, drift."""
    if not isinstance(cells, dict):
        return ""
    from ..plot import cell_figures

    spread, share = cell_figures({"cells": cells})
    parts = [] if spread is None else [f"spread {1000 * spread:.0f} mV"]
    if share is not None:
        parts.append(f"weakest {100 * share:.0f} %")
    if cells.get("drift"):
        parts.append("a cell drifts")
    return ", ".join(parts)


def _from(sources) -> str:
    if not sources:
        return ""
    names = [s["source"] for s in sources]
    kinds = "/".join(sorted({str(s.get("kind")) for s in sources}))
    shown = ", ".join(names) if len(names) <= 3 else f"{names[0]} ... {names[-1]}"
    return f" from {len(names)} {kinds} event(s): {shown}"


def health_lines(health, name: str) -> list[str]:
    """The lines under the health table: reference, today, trend, end of life, notes."""
    ref, fc, t = health.reference_capacity_Ah, health.forecast, health.today
    lines = [f"reference capacity: {_num(ref)} Ah ({health.reference})"]
    if ref is None:
        lines.append(f"  give its label capacity to count cycles: dischargelab logbook add FILE "
                     f"--pack {name!r} --capacity AH (a file already there is skipped)")
    if t.get("capacity_Ah") is not None:
        lines.append(f"capacity today (EFC {quantity('efc', t.get('efc'))}): "
                     f"{_num(t['capacity_Ah'])} Ah "
                     f"(95 %: {_interval(t.get('capacity_interval95'), 3)})"
                     f"{_from(t.get('capacity_from'))}")
    if t.get("resistance_ohm") is not None:
        lines.append(f"resistance today ({t.get('resistance_basis')}): "
                     f"{_num(t['resistance_ohm'], 1, 1000)} mOhm (95 %: "
                     f"{_num(t['resistance_interval95'][0], 1, 1000)} - "
                     f"{_num(t['resistance_interval95'][1], 1, 1000)})"
                     f"{_from(t.get('resistance_from'))}")
    if fc is None:
        lines.append("end of life: no fade measured yet (no capacity estimate with a "
                     "reference capacity)")
        return lines + [f"note: {n}" for n in health.notes[1:]]
    shape = {"line": "a straight line", "early": "a fast early fade, then a straight line",
             "knee": "a knee", "early+knee": "a fast early fade and a knee"}.get(fc.shape)
    knee = (f"knee at {fc.knee_efc:.0f} EFC" if fc.knee_efc is not None
            else "no knee in the data yet (the forecast allows one ahead)")
    if shape is not None and fc.status in ("dated", "observed"):
        lines.append(f"trend: {shape} (odds of a bend against a straight line "
                     f"{fc.bend_odds:.3g}); {knee}")
    head = f"end of life ({100 * fc.eol:.0f} % = {fc.threshold_Ah:.3f} Ah): "
    if fc.status in ("no fade", "uncertain"):
        lines.append(head + fc.message)
    elif fc.reached:
        lines.append(head + f"reached: the capacity trend is below it today (EFC "
                            f"{quantity('efc', fc.last_efc)})")
    else:
        how, span = ("observed at", "between events") if fc.observed else ("forecast at",
                                                                           "95 %")
        lines.append(head + f"{how} {_num(fc.eol_efc, 0)} EFC ({span}: "
                            f"{_interval(fc.eol_efc_interval95)})")
    return lines + [f"note: {n}" for n in health.notes[1:]]


@logbook_group.command("events", context_settings=CONTEXT)
@click.argument("name")
@db_option
@json_option
def events_cmd(name, db, as_json):
    """The events of a pack as stored (one per discharge or flight).

    \b
    Examples:
      dischargelab logbook events cell-C
      dischargelab logbook events cell-C --json
    """
    with open_logbook(db) as lb:
        result = lb.events(name)
    if as_json:
        print_json(result.to_dict())
        return
    rows = [[r["source"], (r["start_time"] or "-").replace("T", " "), r["kind"],
             "-" if r["cycle"] is None else r["cycle"], duration(r["duration_s"]),
             _num(r["discharged_Ah"]), _num(r["discharged_Wh"], 2), _num(r["mean_current_A"], 2),
             _num(r["rest_voltage_V"]), _num(r["min_voltage_V"]),
             _num(r["resistance_ohm"], 1, 1000), _num(r["temperature_max_C"], 1),
             _num(r["cell_spread_V"], 0, 1000)]
            for r in result.rows]
    out.print(table(f"Events of {name}", ["source", "start", "kind", "cycle", "duration",
                                          "Ah", "Wh", "mean A", "rest V", "min V", "R [mOhm]",
                                          "max T [degC]", "cell spread [mV]"], rows))


@logbook_group.command("export", context_settings=CONTEXT)
@click.argument("output", type=click.Path(dir_okay=False))
@click.option("--format", "fmt", type=click.Choice(["csv", "parquet"]), default=None,
              help="File format (default: from the suffix, else csv).")
@force_option
@db_option
def export_cmd(output, fmt, force, db):
    """Write every pack's events with their health figures (CSV or Parquet).

    \b
    Examples:
      dischargelab logbook export logbook.csv
      dischargelab logbook export logbook.parquet
    """
    if fmt is None:
        fmt = "parquet" if str(output).lower().endswith(".parquet") else "csv"
    with open_logbook(db) as lb:
        path = lb.export(output, format=fmt, force=force)
    out.print(f"wrote {path}", markup=False)


@logbook_group.command("fit", context_settings=CONTEXT)
@click.argument("name", required=False)
@click.option("--all", "every", is_flag=True, help="Refit every pack (on the executor).")
@click.option("--bootstrap", default=100, show_default=True, type=click.IntRange(0),
              help="Bootstrap refits kept for the intervals of later predictions.")
@executor_options
@db_option
@json_option
def fit_cmd(name, every, bootstrap, workers, scheduler, db, as_json):
    """Fit a pack's model to its latest full discharge (what `endurance --pack` scales).

    With --all every pack is refitted from its latest data, on Dask workers with
    --workers N or --scheduler; packs without a full discharge are listed with why.

    \b
    Examples:
      dischargelab logbook fit cell-C
      dischargelab logbook fit --all --workers 4
    """
    if every == (name is not None):
        raise DischargelabError("give a pack NAME or --all")
    if not every:
        with open_logbook(db) as lb, err.status(f"fitting {name}", spinner="dots"):
            battery = lb.fit(name, bootstrap=bootstrap)
        if as_json:
            print_json(battery.to_dict())
            return
        ref = battery.extra["logbook_fit"]
        out.print(f"{name}: {battery.model} model fitted to a full discharge of "
                  f"{_num(ref['capacity_Ah'])} Ah", markup=False)
        return
    bar, progress = progress_bar("fitting")
    # the workers come up while the logbook is opened; the first fits run here meanwhile
    with open_executor(workers, scheduler, background=True) as executor, \
            open_logbook(db) as lb, bar:
        results = lb.fit_all(executor=executor, progress=progress, bootstrap=bootstrap)
    fitted = {k: v for k, v in results.items() if not isinstance(v, str)}
    if as_json:
        print_json({"fitted": {k: v.to_dict() for k, v in fitted.items()},
                    "not_fitted": {k: v for k, v in results.items() if isinstance(v, str)}})
        return
    rows = [[k, v.model, _num(v.extra["logbook_fit"]["capacity_Ah"])]
            if not isinstance(v, str) else [k, "-", v] for k, v in results.items()]
    out.print(table(f"Refitted {len(fitted)} of {len(results)} pack(s)",
                    ["pack", "model", "full discharge [Ah] / why not"], rows))


@logbook_group.command("report", context_settings=CONTEXT)
@click.option("--fleet", "fleet", is_flag=True, required=True,
              help="Every pack, soonest end of life first (the only report so far).")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default="fleet.html",
              show_default=True, help="HTML page to write.")
@click.option("--within", type=click.FloatRange(0), default=50.0, show_default=True,
              metavar="EFC", help="List packs with at most this many EFC left as due.")
@eol_option
@force_option
@executor_options
@db_option
@json_option
def report_cmd(fleet, output, within, eol, force, workers, scheduler, db, as_json):
    """The fleet at a glance: packs sorted by end of life, with their trends (HTML).

    Each pack's health is computed on the executor (--workers / --scheduler); the
    page holds capacity and resistance against EFC per pack and opens offline.

    \b
    Examples:
      dischargelab logbook report --fleet -o fleet.html
      dischargelab logbook report --fleet --workers 4 --within 100 --json
    """
    bar, progress = progress_bar("packs")
    with open_logbook(db) as lb:
        guard_outputs([output], lb.own_files(), force)   # never the logbook, even with --force
        if (workers or scheduler) and not lb.stale():
            err.print("every pack's figures are stored and current: no workers needed",
                      markup=False)
            workers = scheduler = None
        with open_executor(workers, scheduler, background=True) as executor, bar:
            report = lb.fleet(eol=eol, executor=executor, progress=progress)
    path = report.save(output, force=force, within_efc=within)
    due = report.retire_soon(within)
    if as_json:
        doc = report.to_dict()
        doc.update(report=str(path), retire_soon=due)
        print_json(doc)
        return
    out.print(f"fleet report: {path} ({len(report.rows)} pack(s))", markup=False)
    if due:
        out.print(f"retire soon (end of life logged or within {within:g} EFC): "
                  f"{', '.join(due)}", markup=False)
    for pack, reason in report.failed:
        err.print(f"{pack}: {reason}", markup=False)


COMMANDS = [logbook_group]
