"""Fit and predict
===============

Fit a cell from one measured discharge and predict other currents and a constant power,
with the building blocks under ``dl.fit`` (readers, the fit, simulations, plots).

Uses the Samsung 30Q 1C discharge of the example set shipped with dischargelab
(``dischargelab examples DIR`` copies it); change DATA and the
column mapping for your own file.

Usage: python examples/fit_and_predict.py [--out DIR]
"""

import argparse
from pathlib import Path

from dischargelab.examples import EXAMPLE_COLUMNS, example_files
from dischargelab.fit import Curve, fit_battery
from dischargelab.io import read_discharge
from dischargelab.plot import plot_family, save
from dischargelab.simulate import curve_family, simulate_power

DATA = example_files()["bench/Q30_S001_1C.csv"]
CUTOFF_CELL_V = 2.5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="fit-out", help="folder for the plots and battery file")
    out = Path(parser.parse_args().out)

    data, meta = read_discharge(DATA, columns=EXAMPLE_COLUMNS)
    print(meta["summary"])
    # one rate with its logged temperature: the thermal family (what dl.fit picks here)
    result = fit_battery(Curve.from_frame(data, meta, name="1C"), model="shepherd-thermal",
                         bootstrap=50)
    print(result.report())
    battery = result.battery
    battery.save(out / "battery.json")
    save(result.plot(), out / "fit.png")

    family = curve_family(battery, [1.5, 3.0, 6.0], cutoff_cell_V=CUTOFF_CELL_V)
    for run in family:
        print(f"{run.steps[0].value:4.1f} A: {run.time_to_cutoff_s / 60:6.1f} min, "
              f"{run.capacity_Ah:.3f} Ah, {run.energy_Wh_total:.2f} Wh")
    save(plot_family(family), out / "curves.png")
    hold = simulate_power(battery, 10.0, cutoff_cell_V=CUTOFF_CELL_V)
    print(f"10 W: {hold.time_to_cutoff_s / 60:.1f} min ({hold.ended_by})")


if __name__ == "__main__":
    main()
