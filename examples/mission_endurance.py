"""Mission endurance
=================

The paper's Table 5 flight, a fixed-wing survey and a multirotor hover.

Flies the three bundled example missions on the Hacker 4S LiFePO4
preset (paper Table 4), then flies the fixed-wing survey on a 4S2P pack of Samsung 30Q
cells fitted from the bundled measurements, with a 95 % interval from the fit covariance.

Usage: python examples/mission_endurance.py [--out DIR]
"""

import argparse
from pathlib import Path

import dischargelab as dl
from dischargelab.examples import example_files
from dischargelab.mission import load_mission, run_mission
from dischargelab.plot import save

EXAMPLES = example_files()          # the example set (dischargelab examples DIR)
COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"


def minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="mission-out", help="folder for the plots")
    out = Path(parser.parse_args().out)
    out.mkdir(parents=True, exist_ok=True)

    for name in ("paper-table5", "fixed-wing-survey", "multirotor-hover"):
        mission = load_mission(name)
        result = run_mission(mission)
        line = (f"{mission.name}: flight {minutes(result.flight_time_s)}, endurance "
                f"{minutes(result.endurance_s)}, lands at {result.soc_end_pct:.0f} %")
        if result.stretch:
            line += (f", max {result.stretch['phase']} {minutes(result.stretch['max_s'])} "
                     f"(margin {minutes(result.stretch['margin_s'])})")
        print(line)
        save(result.plot(), out / f"{name}.png")

    # a fitted battery carries a covariance: the endurance gets a 95 % interval
    runs = [dl.read(EXAMPLES[f"bench/Q30_S001_{rate}.csv"], columns=COLUMNS)
            for rate in ("1C", "4C")]
    battery = dl.fit(runs).battery                     # model picked by evidence
    mission = load_mission("fixed-wing-survey", battery=battery, cutoff_cell_V=3.0)
    mission = mission.with_battery(battery.with_pack(4, 2))
    result = run_mission(mission, draws=300, seed=0)
    e = result.uncertainty["endurance_s"]
    print(f"fixed-wing survey on a fitted 4S2P Samsung 30Q pack: endurance "
          f"{minutes(result.endurance_s)} (95 % interval {minutes(e['low'])} to "
          f"{minutes(e['high'])}, {result.uncertainty['accepted']} draws)")
    for warning in result.warnings:
        print(f"  warning: {warning}")
    save(result.plot(), out / "fixed_wing_samsung30q.png")
    print(f"plots in {out}/")


if __name__ == "__main__":
    main()
