"""Pilot's report
==============

Fit a battery, check it on rates it did not see, fly a mission and write one HTML page.

Uses the Samsung 30Q discharges of the example set shipped with dischargelab (1C and 4C
to fit, C/10 to validate; ``dischargelab examples DIR`` copies them). The mission is the
bundled fixed-wing survey on a 4S2P pack of the fitted cells.

Usage: python examples/endurance_report.py [--out DIR]
"""

import argparse
from pathlib import Path

import dischargelab as dl
from dischargelab.examples import EXAMPLE_COLUMNS as COLUMNS
from dischargelab.examples import example_files
from dischargelab.report import write_report

EXAMPLES = example_files()          # {"bench/Q30_S001_1C.csv": path, ...}
CUTOFF_CELL_V = 3.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="report-out", help="folder for the battery and report")
    out = Path(parser.parse_args().out)
    out.mkdir(parents=True, exist_ok=True)

    runs = [dl.read(EXAMPLES[f"bench/Q30_S001_{rate}.csv"], columns=COLUMNS)
            for rate in ("1C", "4C")]
    fit = dl.fit(runs)                                     # model picked by evidence
    print(fit.report())
    cell = fit.save(out / "samsung30q.json", chemistry="li-ion")

    unseen = [EXAMPLES["bench/Q30_S001_C10.csv"]]
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
