"""Virtual cells: reference discharges from physics-based PyBaMM models.

Simulates constant-current discharges (and one UAV-like variable-current
mission) of three published cell parameter sets with the Doyle-Fuller-Newman
model plus a lumped thermal model, and writes one CSV per run in the glossary
columns (``time_s,current_A,voltage_V,temperature_C``, discharge positive) with
the run's metadata in ``#`` comment lines, plus an ``index.json``. The files
are test and benchmark data for dischargelab's model families across rates and
ambient temperatures; PyBaMM is never a runtime dependency of dischargelab.

Cases
-----
* NMC  - ``Chen2020`` (LG M50, 21700, NMC811 / graphite-SiOx, 5.0 Ah):
  0.1C, 0.5C, 1C, 2C, 3C at 25 degC; 1C at 10 and 40 degC; one mission.
* LFP  - ``Prada2013`` (A123 ANR26650M1, LFP / graphite, 2.3 Ah):
  0.1C, 0.2C, 0.5C, 1C, 2C at 25 degC.
* LCO  - ``Marquis2019`` (LiCoO2 / graphite, 0.68 Ah single-layer pouch):
  0.1C, 0.5C, 1C, 2C, 3C at 25 degC.
* Every chemistry also at 0.2C, 0.5C, 1C, 2C at 15 and 35 degC (and 0.2C at 25 degC).
* The LFP plateau set: ``Prada2013`` with SPMe, 0.2C, 0.5C, 1C, 2C to 2.5 V (on the
  knee after the flat plateau), solver output every 5 s, at 25 and 15 degC.
* Cells for the measured one-rate error (:data:`PRIOR_CHEMISTRIES`): ``Ecker2015`` (NMC
  pouch), ``NCA_Kim2011``, ``Mohtat2020`` (NMC532), ``Ai2020`` (LCO pouch) and
  ``Prada2013`` again, 0.2C-3C at 25 degC and 0.5C-2C at 40 degC.

Every run: 10 s rest at 0 A from full charge (state of charge 1, i.e. the open
circuit voltage equals the set's upper cut-off), then the load until the set's
own lower voltage cut-off. Cell and ambient start at the same temperature.
Newton cooling with h = 10 W/(m^2 K) (bare cell in still air).

Mission (NMC): 60 s at 3C (take-off), then 2C cruise for 50 s and a 3.5C burst
for 10 s, repeated until the cut-off.

Usage (in an environment with PyBaMM; see ``tests/data/virtual/README.md``)::

    nice python benchmarks/virtual_cells.py --out tests/data/virtual

References
----------
Chen, C.-H. et al. (2020). Development of experimental techniques for
parameterization of multi-scale lithium-ion battery models. J. Electrochem.
Soc. 167, 080534.
Prada, E. et al. (2013). A simplified electrochemical and thermal aging model
of LiFePO4-graphite Li-ion batteries. J. Electrochem. Soc. 160, A616.
Marquis, S. G. et al. (2019). An asymptotic derivation of a single particle
model with electrolyte. J. Electrochem. Soc. 166, A3693.
Sulzer, V. et al. (2021). Python Battery Mathematical Modelling (PyBaMM).
J. Open Res. Softw. 9(1), 14.
"""

import os

os.environ.setdefault("PYBAMM_DISABLE_TELEMETRY", "true")

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

pybamm = None  # imported in main(), after the options are parsed (so --help works without it)

#: Heat transfer coefficient [W/(m^2 K)]: natural convection plus radiation
#: from a bare cell in still air.
H_STILL_AIR = 10.0
REST_S = 10.0
#: Solver tolerances (relative, absolute).
RTOL, ATOL = 1e-6, 1e-8
#: Output sample period of the rest and of the first minute under load [s].
FINE_PERIOD_S = 1.0
#: Output sample period of the mission [s] (steps are whole multiples of it).
MISSION_PERIOD_S = 2.0
#: Times after the load step [s] always kept in a thinned file (early transient).
EARLY_S = (1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0)


def _a123_26650():
    """Cell-level data PyBaMM's Prada2013 set lacks for a lumped thermal model.

    A123 ANR26650M1: 26 mm x 65 mm cylinder, 76 g (datasheet). The specific heat
    1000 J/(kg K) is an assumed typical cell-level value; current collectors are
    Cu 12 um / Al 16 um with handbook conductivities.
    """
    r, h = 0.013, 0.065
    volume = math.pi * r ** 2 * h
    return {
        "Cell volume [m3]": volume,
        "Cell cooling surface area [m2]": 2 * math.pi * r * h + 2 * math.pi * r ** 2,
        "Cell heat capacity [J.K-1.m-3]": 0.076 * 1000.0 / volume,
        "Negative current collector thickness [m]": 12e-6,
        "Positive current collector thickness [m]": 16e-6,
        "Negative current collector conductivity [S.m-1]": 5.84e7,
        "Positive current collector conductivity [S.m-1]": 3.69e7,
    }


CHEMISTRIES = {
    "nmc": {
        "parameter_set": "Chen2020",
        "cell": "LG M50 21700, NMC811 / graphite-SiOx (Chen et al. 2020)",
        "rates_C": (0.1, 0.5, 1.0, 2.0, 3.0),
        "extra": {},
        "options": {},
        "thermal_note": "geometry and layer heat capacities from the parameter set",
    },
    "lfp": {
        "parameter_set": "Prada2013",
        "cell": "A123 ANR26650M1, LFP / graphite (Prada et al. 2013)",
        "rates_C": (0.1, 0.2, 0.5, 1.0, 2.0),
        "extra": _a123_26650(),
        "options": {"use lumped thermal capacity": "true"},
        "thermal_note": ("the set has no thermal data: 26650 geometry, 76 g x 1000 J/(kg K) "
                         "cell heat capacity and Cu/Al collectors added"),
    },
    "lco": {
        "parameter_set": "Marquis2019",
        "cell": "LiCoO2 / graphite, single-layer pouch (Marquis et al. 2019)",
        "rates_C": (0.1, 0.5, 1.0, 2.0, 3.0),
        "extra": {},
        "options": {},
        "thermal_note": ("geometry from the parameter set (single-layer pouch, 7.8 cm3, "
                         "0.0569 m2 cooling area: close to isothermal)"),
    },
}

#: Further cells for the measured one-rate error (``benchmarks/one_rate_errors.py``): other
#: published parameter sets, and the LFP cell of ``lfp`` again (the same cell: its runs at
#: 3C and at 40 degC), each at :data:`PRIOR_RATES_C` at 25 degC and
#: :data:`PRIOR_WARM_RATES_C` at 40 degC. (A 5x faster LFP particle diffusivity does not
#: move these runs: the Prada2013 cell's rate loss is not set by it, so it gives no second
#: LFP cell.)
PRIOR_CHEMISTRIES = {
    "nmc-pouch": {
        "parameter_set": "Ecker2015",
        "cell": "Kokam SLPB 75106100 NMC / graphite pouch, one layer (Ecker et al. 2015)",
        "extra": {}, "options": {},
        "thermal_note": "geometry and heat capacities from the parameter set (one layer)",
    },
    "nca": {
        "parameter_set": "NCA_Kim2011",
        "cell": "NCA / graphite pouch (Kim et al. 2011)",
        "extra": {}, "options": {},
        "thermal_note": "geometry and heat capacities from the parameter set",
    },
    "nmc532": {
        "parameter_set": "Mohtat2020",
        "cell": "NMC532 / graphite pouch, 5 Ah (Mohtat et al. 2020)",
        "extra": {}, "options": {},
        "thermal_note": "geometry and heat capacities from the parameter set",
    },
    "lco-pouch": {
        "parameter_set": "Ai2020",
        "cell": "Enertech LCO / graphite pouch, 2.28 Ah (Ai et al. 2020)",
        "extra": {}, "options": {},
        "thermal_note": "geometry and heat capacities from the parameter set",
    },
    "lfp-a123": {
        "parameter_set": "Prada2013",
        "cell": "A123 ANR26650M1 LFP / graphite (Prada et al. 2013)",
        "extra": _a123_26650(),
        "options": {"use lumped thermal capacity": "true"},
        "thermal_note": ("26650 geometry, 76 g x 1000 J/(kg K) cell heat capacity and Cu/Al "
                         "collectors added"),
    },
}
PRIOR_RATES_C = (0.2, 0.5, 1.0, 2.0, 3.0)
PRIOR_WARM_RATES_C = (0.5, 1.0, 2.0)
PRIOR_WARM_C = 40.0
#: Rows per file of those cells (they only set times to cutoff and fits of 500 samples).
PRIOR_MAX_ROWS = 400

#: The NMC mission: (current as a multiple of 1C, duration [s]); the cycle repeats.
MISSION_TAKEOFF = (3.0, 60.0)
MISSION_CYCLE = ((2.0, 50.0), (3.5, 10.0))


def spec_of(chem: str) -> dict:
    """The description of a chemistry (:data:`CHEMISTRIES` or :data:`PRIOR_CHEMISTRIES`)."""
    return CHEMISTRIES[chem] if chem in CHEMISTRIES else PRIOR_CHEMISTRIES[chem]


def parameter_values(chem: str, ambient_C: float):
    """PyBaMM parameter values of a chemistry at an ambient temperature [degC]."""
    spec = spec_of(chem)
    values = pybamm.ParameterValues(spec["parameter_set"])
    kelvin = ambient_C + 273.15
    values.update({
        "Total heat transfer coefficient [W.m-2.K-1]": H_STILL_AIR,
        "Ambient temperature [K]": kelvin,
        "Initial temperature [K]": kelvin,
        **spec["extra"],
    }, check_already_exists=False)
    return values


def make_model(kind: str, chem: str):
    options = {"thermal": "lumped", **spec_of(chem)["options"]}
    if kind == "DFN":
        return pybamm.lithium_ion.DFN(options)
    return pybamm.lithium_ion.SPMe(options)


def cc_steps(current_A: float, cutoff_V: float, capacity_Ah: float,
             period_s: float | None = None):
    """Rest, then constant current until the cut-off (fine output for the first minute,
    or every ``period_s`` throughout)."""
    expected_s = 3600.0 * capacity_Ah / current_A
    until = f"{cutoff_V:g} V"
    if period_s is not None:
        return [pybamm.step.rest(REST_S, period=period_s),
                pybamm.step.current(current_A, duration=20 * expected_s, termination=until,
                                    period=period_s)]
    period = max(FINE_PERIOD_S, math.ceil(expected_s / 4000.0))
    return [
        pybamm.step.rest(REST_S, period=FINE_PERIOD_S),
        pybamm.step.current(current_A, duration=EARLY_S[-1], termination=until,
                            period=FINE_PERIOD_S),
        pybamm.step.current(current_A, duration=20 * expected_s, termination=until,
                            period=period),
    ]


def mission_steps(c_rate_A: float, cutoff_V: float, capacity_Ah: float):
    """Rest, take-off, then cruise/burst cycles, each step ending early at the cut-off."""
    until = f"{cutoff_V:g} V"
    steps = [pybamm.step.rest(REST_S, period=FINE_PERIOD_S)]
    rate, duration = MISSION_TAKEOFF
    steps.append(pybamm.step.current(rate * c_rate_A, duration=duration, termination=until,
                                     period=MISSION_PERIOD_S))
    cycle_Ah = sum(r * c_rate_A * d for r, d in MISSION_CYCLE) / 3600.0
    for _ in range(int(math.ceil(1.5 * capacity_Ah / cycle_Ah))):
        for rate, duration in MISSION_CYCLE:
            steps.append(pybamm.step.current(rate * c_rate_A, duration=duration,
                                             termination=until, period=MISSION_PERIOD_S))
    return steps


def simulate(kind: str, chem: str, ambient_C: float, steps, cutoff_V: float):
    """Solve one experiment; return arrays and the solver's termination string."""
    values = parameter_values(chem, ambient_C)
    experiment = pybamm.Experiment(steps, termination=f"{cutoff_V:g} V")
    solver = pybamm.IDAKLUSolver(rtol=RTOL, atol=ATOL)
    sim = pybamm.Simulation(make_model(kind, chem), parameter_values=values,
                            experiment=experiment, solver=solver)
    sol = sim.solve(initial_soc=1.0)
    out = {
        "t": sol["Time [s]"].entries,
        "i": sol["Current [A]"].entries,
        "v": sol["Voltage [V]"].entries,
        "T": sol["Volume-averaged cell temperature [C]"].entries,
        "q": sol["Discharge capacity [A.h]"].entries,
    }
    return out, str(sol.termination)


def drop_coincident(run: dict) -> dict:
    """At a step change PyBaMM returns two points ~1e-14 s apart; keep the later one.

    The earlier is the end of the previous step, the later is the state just
    after the change (e.g. the ohmic drop at the load step).
    """
    t = run["t"]
    keep = np.append(np.diff(t) > 1e-6, True)
    return {k: np.asarray(a)[keep] for k, a in run.items()}


def truncate_at_cutoff(run: dict, cutoff_V: float) -> dict:
    """Keep rows up to the first one at the cut-off (the last point is the event)."""
    hit = np.flatnonzero(run["v"] <= cutoff_V + 1e-6)
    if hit.size == 0:
        raise RuntimeError(f"the run ended at {run['v'][-1]:.4f} V without reaching the "
                           f"{cutoff_V:g} V cut-off")
    stop = int(hit[0]) + 1
    return {k: a[:stop] for k, a in run.items()}


def thin(run: dict, max_rows: int, uniform_from_s: float) -> np.ndarray:
    """Row indices to keep.

    Every rest row, the load step, the early-transient rows (``EARLY_S`` after
    the load step), the rows either side of every current change, every k-th
    row of the solver's evenly spaced output from ``uniform_from_s`` on (k
    chosen so that about ``max_rows`` rows remain), and the last row (cut-off).
    """
    t, i = run["t"], run["i"]
    n = t.size
    load = int(np.flatnonzero(i > 0)[0])
    special = set(range(load + 1))
    t_load = t[load]
    for dt in EARLY_S:
        special.add(int(np.argmin(np.abs(t - (t_load + dt)))))
    changes = np.flatnonzero(np.abs(np.diff(i[load:])) > 1e-9 * max(1.0, np.max(i))) + load
    for k in changes:
        special.update((int(k), int(k) + 1))
    special.add(n - 1)
    uniform = np.flatnonzero(t >= uniform_from_s - 1e-9)
    budget = max(max_rows - len(special - set(uniform.tolist())), 10)
    stride = max(1, math.ceil(uniform.size / budget))
    return np.array(sorted(special | set(uniform[::stride].tolist())))


def label(rate) -> str:
    return "mission" if rate is None else f"{rate:g}C"


def write_csv(path: Path, run: dict, rows: np.ndarray, meta: dict, notes: list[str]) -> None:
    head = ("# virtual cell, PyBaMM simulation (not a measurement): "
            f"parameter_set={meta['parameter_set']}; pybamm={meta['pybamm_version']}; "
            f"model={meta['model']}; capacity_Ah={meta['capacity_Ah']:g}; "
            f"current_A={meta['current_A_text']}; ambient_C={meta['ambient_C']:g}; "
            f"cutoff_V={meta['cutoff_V']:g}; time_to_cutoff_s={meta['time_to_cutoff_s']:.2f}")
    lines = [head] + [f"# {note}" for note in notes]
    lines.append("time_s,current_A,voltage_V,temperature_C")
    for k in rows:
        lines.append(f"{run['t'][k]:.3f},{run['i'][k]:.6g},{run['v'][k]:.6f},"
                     f"{run['T'][k]:.4f}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


@dataclass(frozen=True)
class Case:
    """One simulated run: chemistry, rate (None: the mission), ambient [degC], model
    kind, a cut-off overriding the set's own [V] and a fixed sample period [s]
    (None: fine first minute, then thinned; see :func:`thin`)."""

    chem: str
    rate: float | None
    ambient: float
    kind: str = "DFN"
    cutoff_V: float | None = None
    period_s: float | None = None

    @property
    def name(self) -> str:
        prefix = self.chem if self.kind == "DFN" else f"{self.chem}-{self.kind.lower()}"
        if self.cutoff_V is not None:
            prefix += f"-{self.cutoff_V:g}V"
        return f"{prefix}_{label(self.rate)}_{self.ambient:g}C.csv"

    @property
    def set_name(self) -> str:
        """Group of runs a benchmark fits and predicts together."""
        out = self.chem.upper()
        if self.kind != "DFN":
            out += f" {self.kind}"
        if self.cutoff_V is not None:
            out += f" {self.cutoff_V:g} V"
        return out


#: Rates simulated at the extra ambients (and at 25 degC where missing): the fit on
#: 0.2C + 2C predicts 0.5C and 1C.
AMBIENT_RATES_C = (0.2, 0.5, 1.0, 2.0)
EXTRA_AMBIENTS_C = (15.0, 35.0)

#: The LFP plateau case: PyBaMM SPMe, Prada2013, to 2.5 V, sampled every 5 s.
PLATEAU_CUTOFF_V = 2.5
PLATEAU_PERIOD_S = 5.0


def cases():
    """Every :class:`Case` in generation order."""
    for chem, spec in CHEMISTRIES.items():
        for rate in spec["rates_C"]:
            yield Case(chem, rate, 25.0)
        if chem == "nmc":
            yield Case(chem, 1.0, 10.0)
            yield Case(chem, 1.0, 40.0)
            yield Case(chem, None, 25.0)
        for rate in AMBIENT_RATES_C:
            if rate not in spec["rates_C"]:
                yield Case(chem, rate, 25.0)
        for ambient in EXTRA_AMBIENTS_C:
            for rate in AMBIENT_RATES_C:
                yield Case(chem, rate, ambient)
    for ambient in (25.0, 15.0):
        for rate in AMBIENT_RATES_C:
            yield Case("lfp", rate, ambient, kind="SPMe", cutoff_V=PLATEAU_CUTOFF_V,
                       period_s=PLATEAU_PERIOD_S)
    for chem in PRIOR_CHEMISTRIES:
        for rate in PRIOR_RATES_C:
            yield Case(chem, rate, 25.0)
        for rate in PRIOR_WARM_RATES_C:
            yield Case(chem, rate, PRIOR_WARM_C)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="tests/data/virtual", help="output folder")
    parser.add_argument("--model", choices=("DFN", "SPMe"), default="DFN")
    parser.add_argument("--max-rows", type=int, default=1000,
                        help="rows per file after thinning (about)")
    parser.add_argument("--only", default=None,
                        help="run only cases whose file name contains one of these "
                             "comma-separated texts")
    args = parser.parse_args(argv)
    global pybamm
    try:
        import pybamm
    except ImportError:  # pragma: no cover - depends on the environment
        sys.exit("virtual_cells.py needs PyBaMM: pip install 'dischargelab[virtual]' "
                 "(best in a separate virtual environment)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    version = pybamm.__version__
    model_text = (f"{args.model} (thermal=lumped), IDAKLUSolver rtol={RTOL:g} "
                  f"atol={ATOL:g}, default mesh")
    index, table = [], []
    wall_total = time.perf_counter()
    for case in cases():
        chem, rate, ambient, name = case.chem, case.rate, case.ambient, case.name
        if args.only and not any(part in name for part in args.only.split(",")):
            continue
        spec = spec_of(chem)
        values = pybamm.ParameterValues(spec["parameter_set"])
        capacity = float(values["Nominal cell capacity [A.h]"])
        cutoff = float(values["Lower voltage cut-off [V]"]) if case.cutoff_V is None \
            else case.cutoff_V
        kind = case.kind if case.kind != "DFN" else args.model
        model_text = (f"{kind} (thermal=lumped), IDAKLUSolver rtol={RTOL:g} "
                      f"atol={ATOL:g}, default mesh")
        if rate is None:
            steps = mission_steps(capacity, cutoff, capacity)
            current_text = ("variable: 60 s at 3C, then (50 s at 2C, 10 s at 3.5C) repeated; "
                            f"1C = {capacity:g} A")
        else:
            steps = cc_steps(rate * capacity, cutoff, capacity, case.period_s)
            current_text = f"{rate * capacity:.6g}"
        wall = time.perf_counter()
        raw, termination = simulate(kind, chem, ambient, steps, cutoff)
        wall = time.perf_counter() - wall
        run = truncate_at_cutoff(drop_coincident(raw), cutoff)
        if abs(run["v"][-1] - cutoff) > 1e-4 or "voltage" not in termination.lower():
            raise RuntimeError(f"{name}: did not end at the cut-off (termination "
                               f"{termination!r}, last voltage {run['v'][-1]:.4f} V)")
        load = int(np.flatnonzero(run["i"] > 0)[0])
        t_load = float(run["t"][load])
        time_to_cutoff = float(run["t"][-1] - t_load)
        delivered = float(run["q"][-1] - run["q"][load])
        # evenly spaced solver output: the mission from the load step, a constant
        # current after its first (finely sampled) minute
        uniform_from = t_load if rate is None else t_load + EARLY_S[-1]
        max_rows = args.max_rows if chem in CHEMISTRIES else min(args.max_rows, PRIOR_MAX_ROWS)
        rows = np.arange(run["t"].size) if case.period_s is not None else \
            thin(run, max_rows, uniform_from)
        meta = {
            "file": name, "chemistry": chem.upper(), "set": case.set_name,
            "parameter_set": spec["parameter_set"],
            "cell": spec["cell"], "pybamm_version": version, "model": model_text,
            "rate_C": rate, "current_A": None if rate is None else rate * capacity,
            "current_A_text": current_text, "ambient_C": ambient, "capacity_Ah": capacity,
            "cutoff_V": cutoff, "time_to_cutoff_s": round(time_to_cutoff, 3),
            "delivered_Ah": round(delivered, 5),
            "peak_temperature_C": round(float(np.max(run["T"])), 3),
            "rest_voltage_V": round(float(run["v"][load - 1]), 6),
            "load_start_s": round(t_load, 6), "rows": int(rows.size),
            "heat_transfer_W_m2K": H_STILL_AIR, "thermal": spec["thermal_note"],
            "sample_period_s": case.period_s,
            "termination": termination,
        }
        if rate is None:
            meta["profile"] = {"takeoff": {"C": MISSION_TAKEOFF[0], "s": MISSION_TAKEOFF[1]},
                               "cycle": [{"C": r, "s": d} for r, d in MISSION_CYCLE]}
            meta["mean_current_A"] = round(delivered * 3600.0 / time_to_cutoff, 4)
        notes = [
            f"cell: {spec['cell']}",
            f"from full charge (SOC 1); {REST_S:g} s rest at 0 A, load from t = {t_load:g} s; "
            "time_to_cutoff_s is measured from the load step",
            f"lumped thermal, h = {H_STILL_AIR:g} W/(m2 K), cell starts at ambient; "
            f"{spec['thermal_note']}",
            "columns: discharge current positive; temperature_C = volume-averaged cell "
            "temperature; " + ("rows thinned from the solver output" if case.period_s is None
                               else f"solver output every {case.period_s:g} s, not thinned"),
        ]
        write_csv(out / name, run, rows, meta, notes)
        index.append({k: v for k, v in meta.items() if k != "current_A_text"})
        table.append((name.split("_")[0], label(rate), meta["current_A"], ambient,
                      time_to_cutoff, delivered, meta["peak_temperature_C"], wall))
    index_path = out / "index.json"
    if index_path.is_file():  # keep the entries of runs not simulated this time (--only)
        done = {e["file"] for e in index}
        old = json.loads(index_path.read_text(encoding="utf-8"))["files"]
        index = [e for e in old if e["file"] not in done] + index
        order = [c.name for c in cases()]
        index.sort(key=lambda e: order.index(e["file"]) if e["file"] in order else len(order))
    index_path.write_text(json.dumps({
        "generator": "python benchmarks/virtual_cells.py --out tests/data/virtual",
        "pybamm_version": version,
        "columns": ["time_s", "current_A", "voltage_V", "temperature_C"],
        "files": index}, indent=1) + "\n", encoding="utf-8")

    print(f"PyBaMM {version}; {model_text}; h = {H_STILL_AIR:g} W/(m2 K)")
    print(f"{'set':13} {'rate':>7} {'current A':>9} {'amb C':>5} {'t_cut s':>9} "
          f"{'Ah out':>7} {'Tmax C':>6} {'wall s':>6}")
    for chem, rate_text, current, ambient, t_cut, ah, tmax, wall in table:
        current_text = "var" if current is None else f"{current:.3f}"
        print(f"{chem:13} {rate_text:>7} {current_text:>9} {ambient:5.0f} {t_cut:9.1f} "
              f"{ah:7.4f} {tmax:6.1f} {wall:6.2f}")
    print(f"total wall time {time.perf_counter() - wall_total:.1f} s; files in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
