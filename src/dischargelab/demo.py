"""The demo: the whole method on the bundled Samsung 30Q measurements.

Data: Samsung INR18650-30Q cell S001 discharged at C/10 (0.3 A), 1C (3 A) and
4C (12 A) to 2.5 V, from ARTS-Laboratory, "dataset-electrothermal-deformation-
characterization-for-samsung-30Q-cell", CC BY-SA 4.0 (see NOTICE).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from .formatting import duration

#: Bundled files and their nominal rates.
DEMO_FILES = {"C/10": "Q30_S001_C10.csv", "1C": "Q30_S001_1C.csv", "4C": "Q30_S001_4C.csv"}
DEMO_RATES = tuple(DEMO_FILES)
#: The rates the pack model (battery.json, the survey mission's) is fitted on, and the one
#: held out to validate it in the report.
PACK_FIT_RATES = ("C/10", "4C")
VALIDATION_RATES = ("1C",)
#: Column layout of the bundled files (no header).
DEMO_COLUMNS = {"time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4}
DEMO_CUTOFF_V = 2.5
#: The survey mission flies a 4S2P pack of the fitted cells down to 3.0 V per cell.
PACK = (4, 2)
SURVEY_CUTOFF_V = 3.0
#: Bootstrap refits per fit; they are the draws of the mission's 95 % interval.
BOOTSTRAP = 100
DRAWS = BOOTSTRAP


def demo_data_dir() -> Path:
    """Folder holding the bundled Samsung 30Q files."""
    return Path(str(resources.files("dischargelab") / "data" / "samsung30q"))


def load_demo_curves():
    """The bundled discharges as (frames, curves, metas) in DEMO_FILES order."""
    from .fit import Curve
    from .io import read_discharge

    frames, curves, metas = [], [], []
    for rate, name in DEMO_FILES.items():
        data, meta = read_discharge(demo_data_dir() / name, columns=DEMO_COLUMNS)
        frames.append(data)
        curves.append(Curve.from_frame(data, meta, name=rate))
        metas.append(meta)
    return frames, curves, metas


#: Files :func:`run_demo` writes into its folder.
DEMO_OUTPUTS = ("battery-1C.json", "fit-battery-1C.png", "battery.json", "fit-battery.png",
                "curves.png", "paper-table5.png", "survey.png", "report.html", "flight.png",
                "battery.param")

#: The flight-log example: a PX4 multirotor log (6S pack, 27-74 A in flight), bundled under
#: its MIT licence (see NOTICE), and the label capacity assumed for it [Ah].
FLIGHT_LOG = "esc_status_log.ulg"
FLIGHT_LOG_CAPACITY_AH = 10.0


def check_demo(out_dir, force: bool = False) -> None:
    """Everything :func:`run_demo` needs, checked before any work.

    Raises
    ------
    MissingExtraError
        matplotlib (extra ``plot``) or pyulog (extra ``logs``) is not installed.
    OutputError
        A demo file exists in ``out_dir`` and ``force`` is false, or ``out_dir`` is a file.
    """
    from .atomic import OutputError, check_outputs
    from .errors import require

    require("matplotlib", "plot")
    require("pyulog", "logs")
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputError(f"{out_dir} is a file; give a folder for the demo's files")
    check_outputs([out_dir / name for name in DEMO_OUTPUTS], force=force)


def run_demo(out_dir: Path, console=None, force: bool = False) -> dict:
    """Fit, predict, fly two missions, plot and report into ``out_dir``.

    Two models: one fitted on 1C alone, one on C/10 + 4C (:data:`PACK_FIT_RATES`); each
    predicts every measured rate, and the report validates the second on 1C, which its
    fit did not see.

    Checks first (:func:`check_demo`) that matplotlib is installed and that no
    demo file would be replaced unless ``force``. Returns a summary dict;
    ``summary["missions"]`` holds the MissionResult objects (paper Table 5 on
    its preset, and a survey flight on a pack of the fitted cells).
    """
    from dataclasses import replace

    from .atomic import atomic_path
    from .fit import fit_battery
    from .mission import load_mission, run_mission
    from .plot import plot_family, save
    from .report import write_report
    from .simulate import curve_family
    from .validate import compare_discharge, validate_discharge

    out_dir = Path(out_dir)
    check_demo(out_dir, force)
    out_dir.mkdir(parents=True, exist_ok=True)
    say = console.print if console is not None else (lambda *a, **k: None)
    status = console.status if console is not None else _no_status

    with status("reading the bundled Samsung 30Q discharges"):
        frames, curves, metas = load_demo_curves()
    for curve, meta in zip(curves, metas):
        say(f"[bold]{curve.name}[/]: {meta.get('summary', '')}")

    # 1C alone, and C/10 + 4C: each model then predicts rates it never saw, and the
    # report's validation (1C) is held out from the pack model's fit
    fitted = [curves[DEMO_RATES.index(r)] for r in PACK_FIT_RATES]
    with status("fitting"):
        one = fit_battery(curves[DEMO_RATES.index("1C")], bootstrap=BOOTSTRAP, model="auto")
        two_rates = fit_battery(fitted, bootstrap=BOOTSTRAP, model="auto")
    pack_label = " + ".join(PACK_FIT_RATES)
    models = {"fit on 1C": one, f"fit on {pack_label}": two_rates}
    files = {}
    for label, res, stem in (("1C", one, "battery-1C"), (pack_label, two_rates, "battery")):
        bat = replace(res.battery, name=f"Samsung 30Q cell S001, fitted on {label}",
                      chemistry="li-ion")
        files[stem + ".json"] = bat.save(out_dir / f"{stem}.json")
        files[f"fit-{stem}.png"] = save(res.plot(), out_dir / f"fit-{stem}.png")

    with status("predicting each measured rate"):
        rows = []
        for curve, meta, data in zip(curves, metas, frames):
            row = {"rate": curve.name, "current_A": curve.mean_current_A,
                   "max_temperature_C": float(data["temperature_C"].max())}
            for label, res in models.items():
                v = validate_discharge(res.battery, data, meta, cutoff_cell_V=DEMO_CUTOFF_V)
                row["measured_s"] = v["endurance_measured_s"]
                row[label] = v
            rows.append(row)
    family = curve_family(two_rates.battery, [0.3, 3.0, 6.0, 9.0, 12.0],
                          cutoff_cell_V=DEMO_CUTOFF_V)
    files["curves.png"] = save(plot_family(family), out_dir / "curves.png")

    with status("flying the paper's Table 5 mission"):
        table5 = run_mission(load_mission("paper-table5"))
        files["paper-table5.png"] = save(table5.plot(), out_dir / "paper-table5.png")
    with status(f"flying a survey mission on a {PACK[0]}S{PACK[1]}P pack of the fitted cells "
                f"({DRAWS} bootstrap parameter sets)"):
        pack_file = files["battery.json"]
        survey = load_mission("fixed-wing-survey", battery=pack_file,
                              cutoff_cell_V=SURVEY_CUTOFF_V)
        survey = survey.with_battery(survey.battery.with_pack(*PACK))
        survey_result = run_mission(survey, draws=DRAWS, seed=0)
        files["survey.png"] = save(survey_result.plot(), out_dir / "survey.png")
    with status("writing the report"):
        cases = [compare_discharge(pack_file, data, meta, DEMO_CUTOFF_V)
                 for rate, data, meta in zip(DEMO_RATES, frames, metas)
                 if rate in VALIDATION_RATES]
        with atomic_path(out_dir / "report.html") as tmp:
            write_report(tmp, pack_file, mission_result=survey_result, validation=cases,
                         title=f"Samsung 30Q: model, validation and a {PACK[0]}S{PACK[1]}P "
                               f"survey mission")
        files["report.html"] = out_dir / "report.html"
    with status("reading a PX4 flight log and deriving autopilot settings"):
        flight, params = _flight_example(pack_file)
        files["flight.png"] = save(flight.plot()[0], out_dir / "flight.png")
        files["battery.param"] = params.write(out_dir / "battery.param", force=True)
    say(f"\n[bold]Flight log[/] {FLIGHT_LOG}: " + _flight_text(flight))
    say(f"ArduPilot settings for a {PACK[0]}S{PACK[1]}P pack of the fitted cells "
        f"(written to battery.param):")
    for setting in params.settings:
        say(f"  {setting.name},{setting.text()}  # {setting.comment}", markup=False)

    if console is not None:
        _print_summary(console, models, rows, files)
    return {
        "missions": {"paper-table5": table5, "fixed-wing-survey": survey_result},
        "out_dir": str(out_dir),
        "files": sorted(str(p) for p in files.values()),
        "fits": {label: res.to_dict() for label, res in models.items()},
        "validation": [{"rate": r["rate"], "current_A": r["current_A"],
                        "max_temperature_C": r["max_temperature_C"],
                        **{label: r[label] for label in models}} for r in rows],
    }


def _flight_example(battery_file):
    """The bundled PX4 log analysed, and ArduPilot settings for a pack of the fitted cells."""
    from .autopilot import autopilot_params
    from .flight import analyse_flight

    log = Path(str(resources.files("dischargelab") / "data" / "flightlogs" / FLIGHT_LOG))
    flight = analyse_flight(log, capacity_Ah=FLIGHT_LOG_CAPACITY_AH)
    params = autopilot_params(battery_file, firmware="ardupilot", cells=PACK[0],
                              parallel=PACK[1], load_current_A=6.0, cutoff=SURVEY_CUTOFF_V)
    return flight, params


def _flight_text(report) -> str:
    """One line per flight: duration, charge, peak current and sag, resistance."""
    def part(label, value, scale=1.0, spec=".0f", unit=""):
        return None if value is None else f"{label}{value * scale:{spec}}{unit}"

    out = []
    for a in report.flights:
        s = a.summary
        items = [None if s.get("duration_s") is None else duration(s["duration_s"]),
                 part("", s.get("charge_Ah"), 1000, unit=" mAh"),
                 part("peak ", s.get("peak_current_A"), unit=" A"),
                 part("sag ", s.get("sag_V"), spec=".2f", unit=" V"),
                 part("resistance ", s.get("resistance_ohm"), 1000, unit=" mOhm")]
        out.append(f"flight {a.number}: " + ", ".join(x for x in items if x))
    return "; ".join(out)


def _print_summary(console, models, rows, files):
    from rich.table import Table
    from rich.text import Text

    for label, res in models.items():
        console.print(f"\n[bold]{label}[/]")
        console.print(res.report(), markup=False)
    t = Table(title=f"\nTime to {DEMO_CUTOFF_V} V: measured vs predicted", title_justify="left")
    t.add_column("rate")
    t.add_column(Text("current [A]"), justify="right")
    t.add_column(Text("measured"), justify="right")
    for label in models:
        t.add_column(Text(label), justify="right")
        t.add_column("error", justify="right")
    for r in rows:
        cells = [r["rate"], f"{r['current_A']:.2f}", duration(r["measured_s"])]
        for label in models:
            v = r[label]
            cells += [duration(v["endurance_predicted_s"]),
                      f"{v['endurance_error_pct']:+.1f} %"]
        t.add_row(*cells)
    console.print(t)
    labels = list(models)
    top = rows[-1]
    held_out = [r for r in rows if r["rate"] in VALIDATION_RATES]
    one, pair = (models[label] for label in labels)
    heat = (f"the {one.model} model simulates the self-heating to "
            f"{top['max_temperature_C']:.0f} degC (measured) from the 1C log, which lowers the "
            "resistance" if one.family.thermal else
            f"at {top['rate']} the cell heats itself to {top['max_temperature_C']:.0f} degC "
            "(measured), which the isothermal model ignores (paper 2.1)")
    console.print(
        f"The 1C-only model predicts {top['rate']} within "
        f"{top[labels[0]]['endurance_error_pct']:+.1f} %: {heat}. Fitted on "
        f"{' + '.join(PACK_FIT_RATES)} ({pair.model}), the model predicts "
        + ", ".join(f"{r['rate']}, which it did not see, within "
                    f"{r[labels[1]]['endurance_error_pct']:+.1f} %" for r in held_out) + ".",
        markup=False)
    console.print("\nFiles written:")
    for path in sorted(files.values()):
        console.print(f"  {path}")


class _no_status:
    def __init__(self, *_a, **_k):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *_exc):
        return False
