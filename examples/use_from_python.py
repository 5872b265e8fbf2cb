"""Use it from Python
===================

The demo's fit, predictions and missions in a short script with the public API.

Reads the Samsung 30Q discharges of the example set (C/10, 1C, 4C), fits a model picked by
evidence, predicts 2C and 4C, and flies the paper's Table 5 and a survey on a
4S2P pack of the fitted cells: the numbers `make demo` prints.

Usage: python examples/use_from_python.py [--out DIR]
"""

import argparse
from pathlib import Path

import dischargelab as dl
from dischargelab.examples import example_files

COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="api-out", help="folder for the battery file and plot")
    out = Path(parser.parse_args().out)
    out.mkdir(parents=True, exist_ok=True)
    runs = [dl.read(example_files()[f"bench/Q30_S001_{r}.csv"], columns=COLUMNS)
            for r in ("C10", "1C", "4C")]
    fit = dl.fit(runs, bootstrap=100)                      # model picked by evidence
    print(fit.report())
    for amps in (6.0, 12.0):                               # 2C and 4C from 23 degC
        p = fit.predict(current=amps, cutoff=2.5, ambient=23.0).to_dict()
        print(f"{amps:g} A: {p['time_to_cutoff_s'] / 60:.2f} min to 2.5 V, 95 % "
              f"{[round(x / 60, 2) for x in p['interval95']['time_to_cutoff_s']]} min")
    cell = dl.load(fit.save(out / "cell.json", chemistry="li-ion"))
    table5 = dl.endurance("hacker-4100-4s-lifepo4", "paper-table5").to_dict()
    print(f"Table 5: {table5['endurance_s'] / 60:.2f} min landing at the reserve")
    pack = cell.with_pack(4, 2)
    survey = dl.endurance(pack, "fixed-wing-survey", cutoff_cell_V=3.0)
    print(f"survey: {survey.to_dict()['endurance_s'] / 60:.1f} min")
    survey.plot().figure.savefig(out / "survey.png", dpi=130)


if __name__ == "__main__":
    main()
