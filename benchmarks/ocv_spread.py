"""How far other Li-ion cells' open-circuit curves lie from the generic Li-ion curve, and
the spread the logbook carries for it (:data:`dischargelab.ocv.GENERIC_OCV_SPREAD_V`).

A pack of unknown cells told "li-ion" reads its rests through the generic curve (a
Samsung 30Q's C/10 discharge plus its ohmic drop). Other NMC and NCA cells rest tens of
millivolts away from it, most of all below 40 %, where a flight ends. Their curves, each
against its own state of charge (the charge a near-open-circuit discharge from a 4.2 V
full rest delivers to the generic curve's cutoff, 2.5 V; 3.0 V for LiCoO2):

* **measured**: the Sony-Murata VTC6 of the CMU eVTOL lives (``../shared/data/cmu_evtol``):
  the first C/5 capacity test of VAH27 and VAH30 from a full rest, plus the drop to the
  first loaded sample (the smaller of the two: 36 mOhm) times the current, averaged;
* **published electrode curves** (PyBaMM's parameter sets; an SPM cell at C/50 and 25
  degC, which leaves a few millivolts of polarisation): the LG M50 21700 (NMC811 /
  graphite-SiOx, Chen et al. 2020), an NMC532 pouch (Mohtat et al. 2020), a Kokam NMC
  pouch (Ecker et al. 2015), an NCA / graphite cell (Kim et al. 2011). The method is
  checked on the Enertech LiCoO2 cell, whose measured C/10 curve is the generic LiPo
  one (Ai et al. 2020); a Sony LiCoO2 18650 (Ramadass et al. 2004) is set beside that
  curve too (one cell: no spread is drawn from it).

Printed: each cell's deviation from the generic curve at every 5 % of charge; the spread
chosen (the root mean square of the cells' deviations at each state of charge); **leave
one cell out**: the spread from the other cells, with the 15 mV every generic curve
carries, against the held-out cell's deviation (how many of its points 0.05-0.95 lie
within 1.96 standard deviations); and what it does for a user: an LG M50 flown from full
to 30 % at 2.25C, its log running 36-3600 s after landing, through the logbook told
"li-ion" (capacity against the cell's C/10 capacity, and whether the band holds it).

Needs PyBaMM (the ``virtual`` extra) for the published curves; without it only the
measured cell is printed.

References: C.-H. Chen et al., J. Electrochem. Soc. 167, 080534 (2020); P. Mohtat et
al., J. Electrochem. Soc. 167, 110561 (2020); M. Ecker et al., J. Electrochem. Soc. 162,
A1849 (2015); G.-H. Kim et al., J. Electrochem. Soc. 158, A955 (2011); Y. Ai et al.,
J. Electrochem. Soc. 167, 013512 (2020); P. Ramadass et al., J. Power Sources 126, 110
(2004); A. Bills et al., Sci. Data 10, 344 (2023).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line, shared_data  # noqa: E402
from dischargelab.logbook.estimates import PRIOR_CURVE_SD_CELL_V  # noqa: E402
from dischargelab.ocv import GENERIC_OCV_SPREAD_V, OCV_SOC, generic_ocv  # noqa: E402

#: PyBaMM parameter set -> (cell, chemistry of the generic curve it is compared with).
PUBLISHED = {"Chen2020": ("LG M50 (NMC811)", "li-ion"),
             "Mohtat2020": ("NMC532 pouch", "li-ion"),
             "Ecker2015": ("Kokam NMC pouch", "li-ion"),
             "NCA_Kim2011": ("NCA cell", "li-ion"),
             "Ai2020": ("Enertech LCO (the LiPo curve's own cell: the method's check)", "lipo"),
             "Ramadass2004": ("Sony 18650 LCO", "lipo")}

#: The eVTOL lives' capacity tests: current [A] and shortest length [s].
TEST_A, TEST_MIN_S = 0.6, 3 * 3600.0


def _on_grid(soc: np.ndarray, cell_V: np.ndarray) -> np.ndarray:
    """A curve sampled at :data:`OCV_SOC` (``soc`` descending from 1)."""
    return np.interp(OCV_SOC, soc[::-1], cell_V[::-1])


def evtol_test(path: Path) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """The cell's first capacity test from a full rest: state of charge and voltage (the
    rest first), the test's current [A] and the drop to its first loaded sample [ohm]."""
    frame = pd.read_csv(path)
    t, i, v = (frame[c].to_numpy(float) for c in ("time_s", "current_A", "voltage_V"))
    on = np.r_[0, (np.abs(i - TEST_A) < 0.1).astype(int), 0]
    for a, b in zip(np.flatnonzero(np.diff(on) == 1), np.flatnonzero(np.diff(on) == -1)):
        if t[b - 1] - t[a] < TEST_MIN_S or v[a - 1] < 4.15:
            continue
        q = np.cumsum(i[a:b] * np.diff(t[a - 1:b])) / 3600.0
        return (np.r_[1.0, 1.0 - q / q[-1]], np.r_[v[a - 1], v[a:b]], np.r_[0.0, i[a:b]],
                float((v[a - 1] - v[a]) / i[a]))
    raise SystemExit(f"{path.name}: no capacity test from a full rest")


def vtc6_curve(folder: Path) -> np.ndarray:
    """The VTC6's curve at :data:`OCV_SOC`: the two lives' first tests, each loaded voltage
    plus the smaller of their drops to the first loaded sample times the current (the
    samples are minutes apart: the smaller drop, 36 mOhm, holds the least polarisation,
    and is the 30Q's load-step drop), averaged."""
    tests = [evtol_test(folder / f"{name}.csv") for name in ("VAH27", "VAH30")]
    ohm = min(test[3] for test in tests)
    return np.mean([_on_grid(soc, v + ohm * i) for soc, v, i, _ in tests], axis=0)


#: Each generic curve's empty end [V] (its cell's cutoff).
CUTOFF_V = {"li-ion": 2.5, "lipo": 3.0}


def published_curve(name: str, cutoff_V: float = CUTOFF_V["li-ion"]) -> np.ndarray:
    """The set's cell at C/50, 25 degC, from a 4.2 V rest to ``cutoff_V``, at
    :data:`OCV_SOC`."""
    import pybamm

    values = pybamm.ParameterValues(name)
    values.update({"Lower voltage cut-off [V]": 2.0, "Upper voltage cut-off [V]": 4.4,
                   "Ambient temperature [K]": 298.15, "Initial temperature [K]": 298.15},
                  check_already_exists=False)
    experiment = pybamm.Experiment([(f"Discharge at C/50 until {cutoff_V} V",)],
                                   period="20 s")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = pybamm.Simulation(pybamm.lithium_ion.SPM(), parameter_values=values,
                                experiment=experiment).solve(initial_soc=1.0)
    q = sol["Discharge capacity [A.h]"].entries
    return _on_grid(1.0 - q / q[-1], sol["Voltage [V]"].entries)


#: The hover: C-rate, share of the capacity flown, and how long the log runs on after it [s].
HOVER_C, HOVER_SHARE = 2.25, 0.7
HOVER_TAILS_S = (36, 100, 300, 600, 1200, 1800, 3600)


def lg_m50_hover_rows() -> list[str]:
    """PyBaMM's LG M50 (Chen2020, SPMe with lumped heating) flown from a full rest to 30 %
    at 2.25C, its log cut at each of :data:`HOVER_TAILS_S` after landing, added to a fresh
    logbook told "li-ion": the capacity and its band against the cell's C/10 capacity."""
    import tempfile

    import pybamm

    from dischargelab.logbook import Logbook

    values = pybamm.ParameterValues("Chen2020")
    model = pybamm.lithium_ion.SPMe({"thermal": "lumped"})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        slow = pybamm.Simulation(model, parameter_values=values, experiment=pybamm.Experiment(
            ["Discharge at C/10 until 2.5 V"])).solve(initial_soc=1.0)
        truth = float(slow["Discharge capacity [A.h]"].entries[-1])
        amps = HOVER_C * float(values["Nominal cell capacity [A.h]"])
        seconds = HOVER_SHARE * truth * 3600.0 / amps
        sol = pybamm.Simulation(model, parameter_values=values, experiment=pybamm.Experiment(
            [("Rest for 60 s", f"Discharge at {amps} A for {seconds:.0f} s",
              f"Rest for {max(HOVER_TAILS_S)} s")], period="1 s")).solve(initial_soc=1.0)
    t = sol["Time [s]"].entries
    frame = pd.DataFrame({"time_s": t, "voltage_V": sol["Voltage [V]"].entries,
                          "current_A": sol["Current [A]"].entries})
    rows = []
    for tail in HOVER_TAILS_S:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "hover.csv"
            frame[t <= 60.0 + seconds + tail].to_csv(path, index=False)
            with Logbook(Path(tmp) / "lb.sqlite") as lb:
                lb.set_pack("m50", cells=1, chemistry="li-ion")
                lb.add(path, pack="m50")
                got = [e for e in lb.health("m50").events if e.capacity_Ah is not None]
        if not got:
            rows.append(f"| {tail} | - | - | no estimate |")
            continue
        low, high = got[0].capacity_interval95
        rows.append(f"| {tail} | {100 * (got[0].capacity_Ah / truth - 1):+.1f} % | "
                    f"[{low / truth:.2f}, {high / truth:.2f}] | "
                    f"{'yes' if low <= truth <= high else 'NO'} |")
    return rows


def _row(label: str, values_V, fmt="{:+.0f}") -> str:
    return "| " + label + " | " + " | ".join(fmt.format(1000 * x) for x in values_V) + " |"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-published", action="store_true",
                        help="the measured cell only (no PyBaMM)")
    args = parser.parse_args(argv)
    os.environ.setdefault("PYBAMM_DISABLE_TELEMETRY", "true")
    start = time.perf_counter()
    generic = {c: generic_ocv(c)[0] for c in ("li-ion", "lipo")}
    cmu = shared_data() / "cmu_evtol"
    vtc6 = vtc6_curve(cmu)
    deviation = {"Sony VTC6 (measured)": vtc6 - generic["li-ion"]}
    check = {}
    if not args.no_published and importlib.util.find_spec("pybamm") is None:
        print("published curves skipped: pybamm not installed (the `virtual` extra)\n")
    elif not args.no_published:
        for name, (cell, chemistry) in PUBLISHED.items():
            curve = published_curve(name, CUTOFF_V[chemistry]) - generic[chemistry]
            (deviation if chemistry == "li-ion" else check)[f"{cell} ({name})"] = curve

    head = "| cell | " + " | ".join(f"{s:.2f}" for s in OCV_SOC) + " |"
    rule = "|---|" + "---|" * OCV_SOC.size
    print("# Deviation from the generic Li-ion curve [mV] at each state of charge\n")
    print(head + "\n" + rule)
    for label, dev in deviation.items():
        print(_row(label, dev))
    rms = np.sqrt(np.mean(np.square(list(deviation.values())), axis=0))
    print(_row("root mean square", rms, "{:.0f}"))
    print(_row("carried (`GENERIC_OCV_SPREAD_V`)", GENERIC_OCV_SPREAD_V["li-ion"], "{:.0f}"))
    if check:
        print("\n# LiCoO2 cells against the generic LiPo curve [mV]\n")
        print(head + "\n" + rule)
        for label, dev in check.items():
            print(_row(label, dev))

    if len(deviation) > 2:
        print("\n# Leave one cell out: the spread from the others against the held-out "
              "cell\n")
        print("| held-out cell | points within 1.96 sd (0.05-0.95) | largest |z| | "
              "at 0.30: deviation, sd [mV] |")
        print("|---|---|---|---|")
        inner = slice(1, -1)
        k30 = int(np.argmin(np.abs(OCV_SOC - 0.30)))
        total = within = 0
        for label, dev in deviation.items():
            others = [d for other, d in deviation.items() if other != label]
            sd = np.hypot(PRIOR_CURVE_SD_CELL_V,
                          np.sqrt(np.mean(np.square(others), axis=0)))
            z = np.abs(dev[inner]) / sd[inner]
            total, within = total + z.size, within + int((z <= 1.96).sum())
            print(f"| {label} | {(z <= 1.96).sum()} of {z.size} | {z.max():.2f} | "
                  f"{1000 * dev[k30]:+.0f}, {1000 * sd[k30]:.0f} |")
        print(f"| all | {within} of {total} ({100 * within / total:.0f} %) | | |")
    if len(deviation) > 2:
        print(f"\n# An LG M50 (PyBaMM) hovered from full to 30 % at {HOVER_C}C, read as "
              "Li-ion\n")
        print("| log after landing [s] | capacity error | 95 % band / truth | band holds |")
        print("|---|---|---|---|")
        print("\n".join(lg_m50_hover_rows()))
    print(f"\n{machine_line()}; {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
