"""Intervals: the model error, parameter draws flown through the engine for every family,
draws that cannot reach the cutoff, bounded simulations and the mission ambient."""

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dischargelab import engine
from dischargelab.cli import main as cli_main
from dischargelab.errors import DataError, SimulationError
from dischargelab.mission import Mission, Phase, RepeatBlock, load_mission, run_mission
from dischargelab.mission import fly as mission_module
from dischargelab.model import PRESETS, Battery, CellParameters
from dischargelab.models import FAMILIES, get_family
from dischargelab.onerate import one_rate_table_override
from dischargelab.simulate import simulate_current
from dischargelab.uncertainty import (
    EXTRAPOLATION_GROWTH,
    MIN_HELD_OUT_SD,
    PRIOR_RELATIVE_SD,
    PRIOR_WEIGHT_CURVES,
    THERMAL_ABSOLUTE_SD_K,
    bootstrap_parameters,
    held_out_posterior,
    model_error_sd,
    peak_temperature_interval,
    prediction_interval,
    simulation_interval,
)

REPO = Path(__file__).resolve().parents[1]
MISSIONS = REPO / "src" / "dischargelab" / "data" / "missions"
HACKER = PRESETS["hacker-4100-4s-lifepo4"]
SAMSUNG_COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
Z95 = 1.959963984540054

CELL = CellParameters(E0_V=3.75, R_ohm=0.03, K_V_per_Ah=0.008, A_V=0.35, B_per_Ah=2.0,
                      C_Ah=3.1)
ONE_RATE = Battery(CELL, fit_currents_A=(3.0,), name="fitted at 3 A")


def run_cli(capsys, *args):
    with pytest.raises(SystemExit) as exc:
        cli_main([str(a) for a in args])
    captured = capsys.readouterr()
    return exc.value.code, captured.out, captured.err


def thermal_hacker(**changes) -> Battery:
    """The paper's LiFePO4 pack as a shepherd-thermal battery (thermal defaults)."""
    fam = FAMILIES["shepherd-thermal"]
    values = fam.defaults()
    values.update(HACKER.parameters.as_dict())
    values.update({"Cth_J_per_K": 60.0, "Rth_K_per_W": 15.0})
    values.update(changes)
    return replace(HACKER, parameters=CellParameters(values), model="shepherd-thermal")


# ---------------------------------------------------------------------------------------------
# The model error
# ---------------------------------------------------------------------------------------------

def test_model_error_prior_grows_with_the_extrapolation_ratio():
    assert model_error_sd(ONE_RATE, 3.0) == pytest.approx(PRIOR_RELATIVE_SD)
    four = PRIOR_RELATIVE_SD * (1 + 2.0 * math.log(4.0))     # one rate: g = 2
    assert model_error_sd(ONE_RATE, 12.0) == pytest.approx(four, rel=1e-12)
    assert model_error_sd(ONE_RATE, 0.75) == pytest.approx(four, rel=1e-12)   # 4x below
    assert model_error_sd(Battery(CELL), 50.0) == pytest.approx(PRIOR_RELATIVE_SD)  # no currents
    # an isothermal model fitted to data that logged self-heating: g = 4
    heated = replace(ONE_RATE, extra={"fit_temperature_rise_K": 11.0})
    assert model_error_sd(heated, 12.0) == pytest.approx(
        PRIOR_RELATIVE_SD * (1 + 4.0 * math.log(4.0)), rel=1e-12)
    assert model_error_sd(replace(heated, extra={"fit_temperature_rise_K": 2.0}), 12.0) == \
        pytest.approx(four, rel=1e-12)


def test_one_rate_growth_widens_on_a_flat_plateau():
    """Without a measured one-rate law (an empty table): a flatter curve multiplies the
    one-rate growth by (1/3) / ratio, at most 4; a flat one (the middle 60 % of the charge
    holds less than a fifth of the drop, LiFePO4) by 4, whatever its ratio (its time to
    cutoff is set by the knee's rate-dependent position, not by the slope); a sloped one
    keeps it; ecm (its dynamics held absent on one steady rate) has the same growth as
    eq. 6."""
    with one_rate_table_override({}):
        _check_fallback_one_rate_growth()


def _check_fallback_one_rate_growth():
    four = PRIOR_RELATIVE_SD * (1 + 2.0 * math.log(4.0))
    sloped = replace(ONE_RATE, extra={"fit_plateau_ratio": 0.35})
    assert model_error_sd(sloped, 12.0) == pytest.approx(four, rel=1e-12)
    flatter = replace(ONE_RATE, extra={"fit_plateau_ratio": 0.25})
    growth = 2.0 * (1 / 3) / 0.25
    assert model_error_sd(flatter, 12.0) == pytest.approx(
        PRIOR_RELATIVE_SD * (1 + growth * math.log(4.0)), rel=1e-12)
    for ratio in (0.15, 0.1, 0.0):  # flat: the whole factor 4
        flat = replace(ONE_RATE, extra={"fit_plateau_ratio": ratio})
        assert model_error_sd(flat, 12.0) == pytest.approx(
            PRIOR_RELATIVE_SD * (1 + 8.0 * math.log(4.0)), rel=1e-12)
    ecm = Battery(CellParameters(get_family("ecm").defaults()), fit_currents_A=(3.0,),
                  model="ecm")
    assert model_error_sd(ecm, 12.0) == pytest.approx(four, rel=1e-12)


def test_plateau_ratio_of_measured_curves(shared_data):
    """LiFePO4 (K2 26650) is flat, NMC (Samsung 30Q) sloped; a flight has none."""
    import dischargelab as dl
    from dischargelab.fit.result import plateau_ratio

    cols = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
    lfp = dl.read(shared_data / "k2_lfp26650" / "K2_Discharge_Test_20C.txt", columns=cols)
    nmc = dl.read(shared_data / "samsung30q_S001" / "Q30_S001_1C.csv", columns=cols)
    assert plateau_ratio(lfp.to_curve()) < 0.15 < 0.3 < plateau_ratio(nmc.to_curve())
    curve = nmc.to_curve()
    spiky = replace(curve, current_A=curve.current_A * (1 + 0.8 * np.sin(curve.time_s)))
    assert plateau_ratio(spiky) is None


def test_model_error_from_held_out_curves():
    def held_out(value, source="held-out"):
        return replace(ONE_RATE, extra={"model_error": {"relative_sd": value, "source": source}})

    assert model_error_sd(held_out(0.03), 3.0) == pytest.approx(0.03)
    assert model_error_sd(held_out(0.03), 6.0) == pytest.approx(0.03 * (1 + 0.8 * math.log(2)))
    assert model_error_sd(held_out(0.0001), 3.0) == pytest.approx(MIN_HELD_OUT_SD)   # floor
    assert model_error_sd(held_out(0.2, source="guess"), 3.0) == \
        pytest.approx(PRIOR_RELATIVE_SD)                                    # not held-out
    with pytest.raises(DataError, match="relative_sd must be a number"):
        model_error_sd(held_out("big"), 3.0)


def test_held_out_errors_are_pooled_with_the_prior():
    # no error at all on two curves: the prior still counts as two curves
    sd, dof = held_out_posterior([0.0, 0.0])
    assert dof == PRIOR_WEIGHT_CURVES + 2
    assert sd == pytest.approx(PRIOR_RELATIVE_SD * math.sqrt(PRIOR_WEIGHT_CURVES / dof))
    # large held-out errors dominate the prior
    sd, _ = held_out_posterior([0.2, -0.2, 0.2])
    assert 0.15 < sd < 0.2


def test_held_out_model_error_uses_students_t():
    error = {"relative_sd": 0.02, "source": "held-out", "dof": 4}
    battery = replace(ONE_RATE, extra={"model_error": error})
    sim = simulate_current(battery, 3.0, cutoff_cell_V=2.5)
    lo, hi = simulation_interval(battery, sim)["time_to_cutoff_s"]
    t975 = 2.7764451051977987                      # Student's t, 4 degrees of freedom
    assert hi / sim.time_to_cutoff_s == pytest.approx(math.exp(t975 * 0.02), rel=1e-9)
    assert lo / sim.time_to_cutoff_s == pytest.approx(math.exp(-t975 * 0.02), rel=1e-9)
    bad = replace(ONE_RATE, extra={"model_error": dict(error, dof=0)})
    with pytest.raises(DataError, match="dof must be a number >= 1"):
        simulation_interval(bad, sim)


def test_held_out_errors_are_brought_back_to_the_fitted_currents():
    """A curve predicted from another one ten times its current carries the error of a
    ten-fold extrapolation of a one-rate fit: reported, not pooled into the error inside
    the fitted currents. A curve's end left out is predicted from the knees at the other
    currents: its error, divided by 1 + 0.8 ln r (r the ratio to the nearest other
    current; 1 between two others), is pooled. From three curves, a curve left out is
    predicted by a fit that still spans several rates: its error, divided by
    1 + 0.8 ln r, joins the pool."""
    from dischargelab.fit import Curve, held_out_error

    def curve(current, name):
        sim = simulate_current(HACKER, current, cutoff_cell_V=2.8)
        # a rate-dependent capacity the model cannot follow: 4 % short at the high rate
        t = sim.time_s * (1.0 - 0.04 * (current > 10))
        return Curve(t, sim.voltage_V, sim.current_A, name=name,
                     rest_voltage_V=float(sim.voltage_V[0]) + 0.05)

    err = held_out_error([curve(4.1, "1C"), curve(41.0, "10C")], model="shepherd",
                         cells_series=HACKER.cells_series)
    assert err["extrapolation_ratios"] == pytest.approx([10.0, 10.0], rel=0.02)
    raw = err["held_out_rms"]
    assert raw > 0.01
    # the curve ends left out: each knee predicted from the other rate's, r = 10
    assert len(err["end_errors_pct"]) == 2 and err["end_rms"] is not None
    assert err["end_ratios"] == pytest.approx([10.0, 10.0], rel=0.02)

    def back(errors_pct, ratios):
        return [e / 100 / (1 + EXTRAPOLATION_GROWTH * math.log(r))
                for e, r in zip(errors_pct, ratios)]

    sd, dof = held_out_posterior(back(err["end_errors_pct"], err["end_ratios"]))
    assert err["relative_sd"] == pytest.approx(sd) and err["dof"] == dof == 4
    assert err["pooled"] == 2 and err["relative_sd"] < raw

    three = held_out_error([curve(4.1, "1C"), curve(12.3, "3C"), curve(41.0, "10C")],
                           model="shepherd", cells_series=HACKER.cells_series)
    assert len(three["errors_pct"]) == 3 and three["pooled"] == 6
    assert three["end_ratios"] == pytest.approx([3.0, 1.0, 3.33], rel=0.02)
    sd, dof = held_out_posterior(back(three["errors_pct"], three["extrapolation_ratios"])
                                 + back(three["end_errors_pct"], three["end_ratios"]))
    assert three["relative_sd"] == pytest.approx(sd) and three["dof"] == dof == 8


def test_the_model_error_is_never_below_the_fitted_curves_own_error():
    """The rate-capacity check's error at the fitted currents (the fitted curves' own
    times to one voltage) is a lower bound of the model error inside them."""
    from dischargelab.fit import Curve, fit_battery

    def curve(current, name):
        sim = simulate_current(HACKER, current, cutoff_cell_V=2.8)
        t = sim.time_s * (1.0 - 0.06 * (current > 10))   # 6 % short at the high rate
        return Curve(t, sim.voltage_V, sim.current_A, name=name,
                     rest_voltage_V=float(sim.voltage_V[0]) + 0.05)

    res = fit_battery([curve(4.1, "1C"), curve(41.0, "10C")], model="shepherd",
                      cells_series=HACKER.cells_series)
    err = res.model_error
    fitted = np.array(err["rate_capacity"]["fitted_pct"]) / 100
    assert err["fitted_floor"] == pytest.approx(float(np.sqrt(np.mean(fitted ** 2))))
    pooled, _ = held_out_posterior(
        [e / 100 / (1 + EXTRAPOLATION_GROWTH * math.log(r))
         for e, r in zip(err["end_errors_pct"], err["end_ratios"])]
        + [e / 100 for e in err["rate_capacity"]["between_pct"]])
    assert pooled < err["fitted_floor"]          # the held-out errors alone say less
    assert err["relative_sd"] == pytest.approx(err["fitted_floor"])


def test_peak_temperature_interval():
    lo, hi = peak_temperature_interval([45.0], 25.0, 1.0)
    assert lo < 45.0 < hi
    assert 45.0 - lo < hi - 45.0                         # a relative error of the rise
    wide = peak_temperature_interval([45.0], 25.0, 4.0)
    assert wide[1] - wide[0] > hi - lo                   # grows with the extrapolation
    flat = peak_temperature_interval([25.0], 25.0, 1.0)  # no rise: the sensor tolerance
    assert flat[1] - 25.0 == pytest.approx(Z95 * THERMAL_ABSOLUTE_SD_K, rel=0.1)


def test_thermal_prediction_reports_a_peak_temperature_interval():
    battery = replace(thermal_hacker(), covariance=np.diag(
        (0.01 * thermal_hacker().parameters.as_array()) ** 2), fit_currents_A=(20.0,))
    sim = simulate_current(battery, 40.0, cutoff_cell_V=2.5, ambient_C=20.0)
    spread = simulation_interval(battery, sim, draws=100)
    lo, hi = spread["peak_temperature_C"]
    assert lo < sim.peak_temperature_C < hi
    assert sim.peak_temperature_C > 25.0
    # without draws (a preset): the model error alone, around the point value
    alone = simulation_interval(thermal_hacker(), sim)
    assert alone["peak_temperature_C"][0] < sim.peak_temperature_C < \
        alone["peak_temperature_C"][1]
    # isothermal families have none
    assert "peak_temperature_C" not in simulation_interval(
        HACKER, simulate_current(HACKER, 40.0, cutoff_cell_V=2.5))


def test_prediction_without_draws_is_the_model_error_alone():
    sim = simulate_current(HACKER, 20.0, cutoff_cell_V=2.5)
    spread = simulation_interval(HACKER, sim)
    sd = model_error_sd(HACKER, 20.0)
    assert spread["interval_includes"] == ["model error (prior, extrapolation x2.5)"]
    assert spread["draws"] == 0 and spread["draws_not_reaching_cutoff"] == 0
    lo, hi = spread["time_to_cutoff_s"]
    assert lo == pytest.approx(sim.time_to_cutoff_s * math.exp(-Z95 * sd), rel=1e-12)
    assert hi == pytest.approx(sim.time_to_cutoff_s * math.exp(Z95 * sd), rel=1e-12)
    # a callable (one simulation per battery) gives the same answer
    again = simulation_interval(HACKER, lambda b: simulate_current(b, 20.0, cutoff_cell_V=2.5))
    assert again["time_to_cutoff_s"] == spread["time_to_cutoff_s"]


def test_parameter_draws_and_model_error_add_up():
    sd = 0.01 * HACKER.parameters.as_array()
    battery = replace(HACKER, covariance=np.diag(sd**2), fit_currents_A=(20.0,))
    sim = simulate_current(battery, 20.0, cutoff_cell_V=2.5)
    spread = simulation_interval(battery, sim, draws=400, seed=4)
    assert spread["interval_includes"] == ["parameters", "model error (prior, extrapolation x1.0)"]
    assert spread["draws"] == 400 and spread["bootstrap_draws"] == 0
    lo, hi = spread["time_to_cutoff_s"]
    assert lo < sim.time_to_cutoff_s < hi
    alone = math.exp(Z95 * PRIOR_RELATIVE_SD) - math.exp(-Z95 * PRIOR_RELATIVE_SD)
    assert (hi - lo) / sim.time_to_cutoff_s > 1.05 * alone        # the parameters widen it
    assert simulation_interval(battery, sim, draws=400, seed=4) == spread     # seeded


# ---------------------------------------------------------------------------------------------
# Draws that cannot reach the cutoff are results (the predict --cutoff defect)
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def bootstrap_battery(tmp_path_factory, bundled_data):
    path = tmp_path_factory.mktemp("boot") / "q30.json"
    with pytest.raises(SystemExit) as exc:
        cli_main(["fit", str(bundled_data / "Q30_S001_1C.csv"), "--columns", SAMSUNG_COLUMNS,
                  "--bootstrap", "20", "-o", str(path)])
    assert exc.value.code == 0
    return path


def high_cutoff(path, current_A):
    """A cutoff below the fitted cell's starting voltage but above some draws' ones."""
    from dischargelab.model import load_battery

    battery = load_battery(path)
    fam = battery.family
    draws = bootstrap_parameters(battery)
    state = fam.initial_state(draws, charge_Ah=0.0, temperature_C=battery.ambient_C)
    starts = fam.voltage(draws, state, current_A)
    point = fam.initial_state(dict(battery.parameters), temperature_C=battery.ambient_C)
    nominal = float(fam.voltage(battery.parameters, point, current_A))
    assert starts.min() < nominal
    return 0.5 * (starts.min() + nominal), int(np.sum(starts <= 0.5 * (starts.min() + nominal)))


def test_predict_counts_bootstrap_draws_that_cannot_reach_the_cutoff(bootstrap_battery, capsys):
    cutoff, below = high_cutoff(bootstrap_battery, 3.0)
    code, out, err = run_cli(capsys, "predict", bootstrap_battery, "--current", "3",
                             "--cutoff", f"{cutoff:.6f}", "--json")
    assert code == 0, err
    doc = json.loads(out)
    spread = doc["interval95"]
    assert spread["draws"] == 20 and spread["bootstrap_draws"] == 20
    assert spread["draws_not_reaching_cutoff"] == below >= 1
    assert spread["interval_includes"][0] == "parameters"
    lo, hi = spread["time_to_cutoff_s"]
    assert lo <= doc["time_to_cutoff_s"] <= hi
    assert any("cannot reach the cutoff" in w for w in spread["warnings"])
    code, out, _ = run_cli(capsys, "predict", bootstrap_battery, "--current", "3",
                           "--cutoff", f"{cutoff:.6f}")
    assert code == 0 and f"{below} of 20 parameter draws cannot reach the cutoff" in out


def test_a_draw_that_cannot_deliver_the_power_is_counted():
    sd = 0.3 * HACKER.parameters.as_array() * np.array([0, 1, 0, 0, 0, 0])   # R spread
    battery = replace(HACKER, covariance=np.diag(sd**2))
    fam, prm = HACKER.family, HACKER.parameters
    state = fam.initial_state(dict(prm))
    v0 = 4 * fam.voltage(prm, state, 0.0)
    b = 4 * (fam.voltage(prm, state, 0.0) - fam.voltage(prm, state, 1.0))
    power = 0.9 * v0**2 / (4 * b)                  # 90 % of the maximum power at the start
    from dischargelab.engine import Step

    nominal = {"time_to_cutoff_s": 10.0, "capacity_Ah": 1.0, "energy_Wh": 1.0}
    spread = prediction_interval(battery, [Step("power", power)], nominal=nominal,
                                 cutoff_pack_V=4.0, cell_current_A=50.0, draws=200, seed=1)
    assert spread["draws"] == 200
    assert 10 < spread["draws_not_reaching_cutoff"] < 190          # R above nominal: no power
    assert spread["time_to_cutoff_s"][0] == 0.0


# ---------------------------------------------------------------------------------------------
# Any family: missions, draws, ambient
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_every_family_flies_a_mission_with_draws(name):
    fam = FAMILIES[name]
    values = fam.defaults()
    cell = CellParameters(values)
    sd = 0.01 * np.abs(cell.as_array(fam.names))
    battery = Battery(cell, model=name, fit_currents_A=(3.0,), covariance=np.diag(sd**2))
    mission = Mission(items=(Phase("climb", "current", 6.0, 60.0),
                             Phase("cruise", "power", 8.0, 600.0, stretch=True),
                             Phase("land", "current", 2.0, 60.0)),
                      battery=battery, cutoff_cell_V=3.0, reserve_pct=20.0, name=name)
    result = run_mission(mission, draws=40, seed=2)
    assert result.completed and result.stretch["binding"] == "reserve"
    assert result.soc_end_pct > mission.reserve_pct          # the planned cruise fits
    unc = result.uncertainty
    e = unc["endurance_s"]
    assert unc["accepted"] == 40 and e["low"] < result.endurance_s < e["high"]
    if fam.thermal:
        assert result.to_dict()["peak_temperature_C"] > result.mission.resolved_ambient_C


def test_mission_ambient_changes_a_thermal_flight(tmp_path):
    battery = thermal_hacker()
    mission = load_mission(MISSIONS / "paper-table5.toml", battery=battery)
    assert mission.ambient_C is None and mission.resolved_ambient_C == battery.ambient_C
    cold = run_mission(replace(mission, ambient_C=0.0, reserve_pct=0.0))
    warm = run_mission(replace(mission, ambient_C=40.0, reserve_pct=0.0))
    assert warm.endurance_s > cold.endurance_s          # lower resistance when warm
    assert warm.to_dict()["ambient_C"] == 40.0
    assert warm.simulation.temperature_C[0] == pytest.approx(40.0)
    # the isothermal preset does not care
    iso = load_mission(MISSIONS / "paper-table5.toml")
    assert run_mission(replace(iso, ambient_C=0.0)).endurance_s == \
        pytest.approx(run_mission(iso).endurance_s, rel=1e-12)
    # the TOML key and the command-line override
    text = (MISSIONS / "paper-table5.toml").read_text(encoding="utf-8")
    path = tmp_path / "hot.toml"
    path.write_text("ambient_C = 35\n" + text, encoding="utf-8")
    assert load_mission(path).ambient_C == 35.0
    assert load_mission(path, ambient_C=10.0).ambient_C == 10.0
    bad = tmp_path / "bad.toml"
    bad.write_text("ambient_C = 300\n" + text, encoding="utf-8")
    with pytest.raises(DataError, match="ambient_C must be <= 90"):
        load_mission(bad)


def test_cli_endurance_ambient_option(tmp_path, capsys):
    path = thermal_hacker().save(tmp_path / "thermal.json")
    code, out, err = run_cli(capsys, "endurance", path, "paper-table5", "--ambient", "35",
                             "--json", "--draws", "0")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["ambient_C"] == 35.0 and doc["model"] == "shepherd-thermal"
    assert doc["peak_temperature_C"] > 35.0 and doc["uncertainty"] is None


# ---------------------------------------------------------------------------------------------
# Bounded simulations: one clear line
# ---------------------------------------------------------------------------------------------

def test_a_repeat_block_that_never_ends_is_one_clear_error(monkeypatch):
    monkeypatch.setattr(mission_module, "MAX_REPEAT_RUNS", 2)
    monkeypatch.setattr(mission_module, "MAX_PASSES_PER_RUN", 3)
    block = RepeatBlock("orbit", (Phase("leg", "current", 0.5, 60.0),), until="reserve")
    mission = Mission(items=(block,), battery=ONE_RATE, cutoff_cell_V=3.0, name="slow")
    with pytest.raises(SimulationError) as info:
        run_mission(mission)
    text = str(info.value)
    assert "\n" not in text and "did not reach the reserve within 6 passes" in text


def test_the_engine_step_limit_becomes_one_line_and_no_crash_for_draws(monkeypatch):
    real = engine.run

    def short(*args, **kwargs):
        kwargs["max_engine_steps"] = 3
        return real(*args, **kwargs)

    monkeypatch.setattr(engine, "run", short)
    mission = load_mission(MISSIONS / "paper-table5.toml")
    with pytest.raises(SimulationError) as info:
        run_mission(mission)
    text = str(info.value)
    assert "\n" not in text and text.startswith("mission 'Paper Table 5")
    assert "never reaches the cutoff" in text
    # draws that cannot be flown: the interval falls back to the model error, with the reason
    sd = 0.01 * HACKER.parameters.as_array()
    battery = replace(HACKER, covariance=np.diag(sd**2))
    nominal = {"time_to_cutoff_s": 600.0, "capacity_Ah": 3.0, "energy_Wh": 40.0}
    from dischargelab.engine import Step

    spread = prediction_interval(battery, [Step("current", 20.0)], nominal=nominal,
                                 cutoff_pack_V=10.0, cell_current_A=20.0)
    assert spread["interval_includes"] == ["model error (prior, extrapolation x2.5)"]
    assert "could not be flown" in spread["method"]


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_every_family_flies_the_bundled_repeat_until_mission(name):
    fam = FAMILIES[name]
    battery = Battery(CellParameters(fam.defaults()), model=name, cells_series=4,
                      fit_currents_A=(3.0,))
    mission = load_mission("multirotor-hover", battery=battery, cutoff_cell_V=3.0)
    result = run_mission(mission)
    assert result.flight_time_s > 0
