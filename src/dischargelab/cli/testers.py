"""Battery testers' files: steps (what a Neware, BioLogic, Arbin or Maccor file holds)."""

from __future__ import annotations

import click

from ..formatting import duration
from .common import err, force_option, guard_outputs, json_option, out, print_json, table


@click.command("steps")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--sign", type=click.Choice(["auto", "positive", "negative"]), default="auto",
              show_default=True,
              help="Sign of the DISCHARGE current in the file; auto reads it from the file "
                   "(state column, the tester's counters, else the voltage trend).")
@click.option("-o", "--output", "plot_path", type=click.Path(dir_okay=False),
              help="Save voltage and current over the test, steps shaded (PNG, SVG or PDF).")
@force_option
@json_option
def steps_cmd(file, sign, plot_path, force, as_json):
    """The steps of a battery tester's file: charge, rest and discharge, as numbered.

    Reads Neware .nda/.ndax, BioLogic .mpr, Arbin .res/.csv/.xlsx, and text
    exports (Maccor, EC-Lab .mpt, BaSyTec, PEC, Novonix and others whose columns name time,
    voltage, current and a step or cycle), found from the content. Each step gets
    a number (1, 2, ... in the file) that --step takes in fit and validate; the
    tester's own cycle and step numbers, the kind and control mode, the charge
    moved by the current and by the tester's counter. "full" marks a discharge
    from a charge to the lower voltage limit: fit takes the first one at each
    rate by default.

    \b
    Examples:
      dischargelab steps TestFile.nda
      dischargelab steps maccor_001.txt -o steps.png
      dischargelab fit maccor_001.txt --step 7,22 -o cell.json
      dischargelab validate cell.json maccor_001.txt --step 12,17 --cutoff 2.5
    """
    from ..io.cyclers import read_tester

    guard_outputs([plot_path], [file], force, figures=[plot_path])
    with err.status("reading", spinner="dots"):
        tester = read_tester(file, sign=sign)
    if plot_path:
        from ..plot import save

        save(tester.plot()[0], plot_path)
    summary = tester.to_dict()
    if as_json:
        if plot_path:
            summary["plot"] = str(plot_path)
        print_json(summary)
        return
    fit = set(summary["fit_steps"])

    def number(value, spec, scale=1.0):
        return "-" if value is None else format(value * scale, spec)

    rows = []
    for s in tester.steps:
        flag = ("fit" if s["number"] in fit else "full") if s.get("after_charge") and \
            s.get("to_limit") else ""
        rows.append([s["number"], s["cycle"], s["step"], s["kind"], s["mode"], s["rows"],
                     duration(s["duration_s"]), number(s["mean_current_A"], ".4g"),
                     f"{s['start_voltage_V']:.4g} -> {s['end_voltage_V']:.4g}",
                     number(s["charge_Ah"] if s["kind"] != "rest" else None, ".5g", 1e3),
                     number(s["tester_Ah"], ".5g", 1e3), flag])
    out.print(table(f"{file}: {summary['format']} read by {summary['reader']}, "
                    f"{summary['records']} records, {len(tester.steps)} steps",
                    ["step", "cycle", "tester step", "kind", "mode", "records", "duration",
                     "current [A]", "voltage [V]", "charge [mAh]", "tester [mAh]", ""], rows))
    out.print(f"current sign from {summary['sign_source']}", markup=False)
    for note in summary["notes"]:
        out.print(f"note: {note}", markup=False)
    out.print(f"fit takes steps {', '.join(map(str, summary['fit_steps'])) or '-'} by default: "
              f"{summary['fit_steps_reason']}", markup=False)
    if plot_path:
        out.print(f"plot: {plot_path}", markup=False)


COMMANDS = [steps_cmd]
