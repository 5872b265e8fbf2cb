"""Pilot's report
==============

Fit a battery, check it on rates it did not see, fly a mission and write one HTML page.

Uses the Samsung 30Q discharges bundled with dischargelab (1C and 4C to fit, C/10 to
validate) and, when the shared data folder is beside the checkout (or given with
``--more``), the 2C and 3C runs too. The mission is the bundled fixed-wing survey on a
4S2P pack of the fitted cells.

Usage: python examples/endurance_report.py [--out DIR] [--more DIR]
"""

import argparse
from pathlib import Path

import dischargelab as dl
from dischargelab.demo import demo_data_dir
from dischargelab.report import write_report

#: The other Samsung 30Q runs, relative to where the script runs (the checkout)
SHARED = Path("..") / "shared" / "data" / "samsung30q_S001"
COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
CUTOFF_CELL_V = 3.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="report-out", help="folder for the battery and report")
    parser.add_argument("--more", default=str(SHARED),
                        help="folder with Q30_S001_2C.csv and Q30_S001_3C.csv to validate on "
                             "too, if it exists (default: %(default)s)")
    args = parser.parse_args()
    out, more = Path(args.out), Path(args.more)
    out.mkdir(parents=True, exist_ok=True)

    runs = [dl.read(demo_data_dir() / f"Q30_S001_{rate}.csv", columns=COLUMNS)
            for rate in ("1C", "4C")]
    fit = dl.fit(runs)                                     # model picked by evidence
    print(fit.report())
    cell = fit.save(out / "samsung30q.json", chemistry="li-ion")

    unseen = [demo_data_dir() / "Q30_S001_C10.csv"]
    unseen += [more / f"Q30_S001_{rate}.csv" for rate in ("2C", "3C")
               if (more / f"Q30_S001_{rate}.csv").exists()]
    cases = dl.validate(cell, [dl.read(path, columns=COLUMNS) for path in unseen],
                        cutoff=CUTOFF_CELL_V)
    for case in cases:
        s = case.summary
        print(f"validation {Path(s['file']).name}: "
              f"endurance error {s['endurance_error_pct']:+.2f} %"
              f", voltage RMS {s['voltage_rmse_pct']:.2f} %")

    pack = dl.load(cell).with_pack(4, 2)
    survey = dl.endurance(pack, "fixed-wing-survey", cutoff_cell_V=CUTOFF_CELL_V)
    report = write_report(out / "report.html", cell, mission_result=survey,
                          validation=cases, title="Samsung 30Q 4S2P survey pack")
    print(f"endurance {survey.endurance_s / 60:.1f} min; report: {report}")


if __name__ == "__main__":
    main()

# the gallery's card shows the fitted model (this example writes an HTML page, no figure)
# sphinx_gallery_thumbnail_path = "_static/overview.png"
