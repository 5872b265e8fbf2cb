"""Validation: known answers on synthetic discharges and the real Samsung 30Q rate family."""

import json

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from dischargelab.cli import main as cli_main
from dischargelab.errors import DataError
from dischargelab.model import Battery, CellParameters
from dischargelab.simulate import Step, simulate
from dischargelab.validate import (
    compare_discharge,
    measured_time_to_cutoff,
    profile_steps,
    validate_discharge,
    validate_files,
)

CELL = CellParameters(E0_V=3.75, R_ohm=0.03, K_V_per_Ah=0.008, A_V=0.35, B_per_Ah=2.0,
                      C_Ah=3.1)
PACK = Battery(CELL, cells_series=3, strings_parallel=1, name="3S", fit_currents_A=(3.0,))
COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"


def model_discharge(battery, current_A, cutoff_cell_V, dt_s=1.0, past_cutoff_s=60.0):
    """A 'measurement' made by the model itself, sampled every dt_s past the cutoff."""
    q_cut = brentq(lambda q: battery.voltage(current_A, q) - cutoff_cell_V *
                   battery.cells_series, 0.0, battery.capacity_Ah * (1 - 1e-12), xtol=1e-14)
    t_cut = q_cut * 3600.0 / current_A
    t = np.arange(0.0, min(t_cut + past_cutoff_s, battery.capacity_Ah * 3600 / current_A * 0.9999),
                  dt_s)
    v = battery.voltage(current_A, current_A * t / 3600.0)
    frame = pd.DataFrame({"time_s": t, "voltage_V": v, "current_A": np.full(t.size, current_A)})
    return frame, t_cut


def test_measured_crossing_is_interpolated():
    # 3.5 V at 1 s, 2.9 V at 2 s: 3.0 V is crossed 0.5/0.6 of the way
    assert measured_time_to_cutoff([0, 1, 2, 3], [4.0, 3.5, 2.9, 2.5], 3.0) == \
        pytest.approx(1 + 0.5 / 0.6)
    assert np.isnan(measured_time_to_cutoff([0, 1], [4.0, 3.9], 3.0))


def test_model_against_itself_has_zero_error():
    data, t_cut = model_discharge(PACK, 6.0, 3.0)
    row = validate_discharge(PACK, data, {"source": "self.csv"}, cutoff_cell_V=3.0)
    assert row["profile"] == "constant"
    # linear interpolation of a convex curve over 1 s samples: far below 0.1 s
    assert row["endurance_measured_s"] == pytest.approx(t_cut, abs=0.1)
    assert row["endurance_predicted_s"] == pytest.approx(t_cut, abs=1e-6)
    assert abs(row["endurance_error_pct"]) < 0.01
    assert row["voltage_rmse_pct"] < 1e-9 and row["voltage_max_error_pct"] < 1e-9
    assert set(row) >= {"file", "current_A", "endurance_measured_s", "endurance_predicted_s",
                        "endurance_error_pct", "voltage_rmse_pct", "voltage_max_error_pct"}


def test_validation_case_is_a_result_object():
    data, t_cut = model_discharge(PACK, 6.0, 3.0)
    case = compare_discharge(PACK, data, {"source": "self.csv"}, cutoff_cell_V=3.0)
    row = case.to_dict()
    assert row == case.summary and row is not case.summary
    assert row["endurance_predicted_s"] == pytest.approx(t_cut, abs=1e-6)
    frame = case.to_pandas()
    assert list(frame.columns) == ["time_s", "voltage_measured_V", "voltage_predicted_V",
                                   "current_A"]
    assert len(frame) == len(data)
    assert np.nanmax(np.abs(frame["voltage_measured_V"] - frame["voltage_predicted_V"])) < 1e-9


def test_known_capacity_error_gives_known_endurance_error():
    # the 'measured' cell has 5 % more capacity than the model: errors follow by hand
    bigger = Battery(CELL.replace(C_Ah=CELL.C_Ah * 1.05), cells_series=3)
    data, t_meas = model_discharge(bigger, 6.0, 3.0, dt_s=0.5)
    row = validate_discharge(PACK, data, {"source": "big.csv"}, cutoff_cell_V=3.0)
    q_pred = brentq(lambda q: PACK.voltage(6.0, q) - 9.0, 0, PACK.capacity_Ah * (1 - 1e-12))
    t_pred = q_pred * 3600 / 6.0
    assert row["endurance_predicted_s"] == pytest.approx(t_pred, abs=1e-6)
    assert row["endurance_measured_s"] == pytest.approx(t_meas, abs=0.05)
    assert row["endurance_error_pct"] == pytest.approx(100 * (t_pred - t_meas) / t_meas,
                                                       abs=0.01)
    assert row["endurance_error_s"] < 0                          # model too short
    # voltage error at each sample = model(C) vs model(1.05 C) at the same charge
    t = data["time_s"].to_numpy()
    keep = t <= t_pred
    rel = (PACK.voltage(6.0, 6.0 * t[keep] / 3600) - data["voltage_V"].to_numpy()[keep]) / \
        data["voltage_V"].to_numpy()[keep] * 100
    assert row["voltage_rmse_pct"] == pytest.approx(np.sqrt(np.mean(rel**2)), rel=1e-9)
    assert row["voltage_max_error_pct"] == pytest.approx(np.max(np.abs(rel)), rel=1e-9)
    assert row["voltage_max_error_operational_pct"] < row["voltage_max_error_pct"]


def test_measurement_that_never_reaches_cutoff():
    data, t_cut = model_discharge(PACK, 6.0, 3.0)
    short = data[data["time_s"] < 0.5 * t_cut]
    row = validate_discharge(PACK, short, {"source": "short.csv"}, cutoff_cell_V=3.0)
    assert row["endurance_measured_s"] is None and row["endurance_error_pct"] is None
    assert any("without reaching the cutoff" in w for w in row["warnings"])
    assert row["voltage_rmse_pct"] < 1e-9                          # the curve still compares
    assert row["endurance_predicted_s"] == pytest.approx(t_cut, abs=1e-6)


def test_start_below_cutoff_is_a_clear_error():
    data, _ = model_discharge(PACK, 6.0, 3.0)
    with pytest.raises(DataError, match="at or below the cutoff"):
        validate_discharge(PACK, data, {"source": "x.csv"}, cutoff_cell_V=4.5)


def test_measured_current_profile():
    # 4 A for 20 min, then 9 A until past the cutoff; sampled every second
    sim = simulate(PACK, [Step("current", 4.0, 1200.0), Step("current", 9.0)],
                   cutoff_cell_V=3.0, points_per_step=2)
    t_cut = sim.time_to_cutoff_s
    t = np.arange(0.0, np.floor(t_cut) + 1.0)
    i = np.where(t < 1200.0, 4.0, 9.0)
    i[t == 1200.0] = 4.0                                   # the step happens just after 1200 s
    q = np.where(t <= 1200, 4.0 * t, 4.0 * 1200 + 9.0 * (t - 1200)) / 3600
    v = PACK.voltage(i, q)
    data = pd.DataFrame({"time_s": t, "voltage_V": v, "current_A": i})
    steps, ends = profile_steps(t, i)
    assert len(steps) <= 3                                  # merged, not one step per sample
    assert sum(s.value * s.duration_s for s in steps) / 3600 == pytest.approx(
        np.trapezoid(i, t) / 3600, rel=1e-12)
    row = validate_discharge(PACK, data, {"source": "profile.csv"}, cutoff_cell_V=3.0)
    assert row["profile"] == "measured"
    assert row["endurance_predicted_s"] == pytest.approx(t_cut, abs=1.0)
    # only the charge of the one interval holding the step differs (trapezoid): tiny error
    assert row["voltage_rmse_pct"] < 0.01


# ---------------------------------------------------------------------------------------------
# Real data: Samsung 30Q at five rates
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def samsung_fit(shared_data):
    """Model fitted to the 1C and 4C discharges only (2C and 3C stay unseen)."""
    from dischargelab.fit import Curve, fit_battery
    from dischargelab.io import read_discharge

    folder = shared_data / "samsung30q_S001"
    curves = [Curve.from_frame(*read_discharge(folder / f"Q30_S001_{r}.csv", columns=COLUMNS))
              for r in ("1C", "4C")]
    return fit_battery(curves).battery, folder


def test_samsung_measured_times_match_the_data_description(samsung_fit):
    battery, folder = samsung_fit
    rows = validate_files(battery, [folder / f"Q30_S001_{r}.csv" for r in ("2C", "3C", "4C")],
                          cutoff_cell_V=3.0, columns=COLUMNS)
    # data README: time from load start to 3.0 V is 1583 s (2C), 1016 s (3C), 726 s (4C)
    measured = [r["endurance_measured_s"] for r in rows]
    assert measured == pytest.approx([1583, 1016, 726], abs=1.0)
    assert [r["current_A"] for r in rows] == pytest.approx([6.0, 9.0, 12.0], rel=0.01)


def test_samsung_unseen_rates_within_paper_accuracy(samsung_fit):
    battery, folder = samsung_fit
    rows = validate_files(battery, [folder / f"Q30_S001_{r}.csv" for r in ("2C", "3C", "1C")],
                          cutoff_cell_V=3.0, columns=COLUMNS)
    unseen, seen = rows[:2], rows[2]
    for row in unseen:
        assert row["in_fit"] is False and row["extrapolation"] is False
        # paper 4.4: endurance errors below 6 %, operational voltage error below 2 %
        assert abs(row["endurance_error_pct"]) < 6.0
        assert row["voltage_max_error_operational_pct"] < 2.0
        assert row["voltage_rmse_pct"] < row["voltage_max_error_pct"]
        assert row["endurance_error_s"] == pytest.approx(
            row["endurance_predicted_s"] - row["endurance_measured_s"])
    assert seen["in_fit"] is True
    assert any("used in the fit" in w for w in seen["warnings"])


def test_cli_validate_json_table_and_plot(samsung_fit, tmp_path, capsys):
    battery, folder = samsung_fit
    path = battery.save(tmp_path / "q30.json")
    plot = tmp_path / "val.png"
    with pytest.raises(SystemExit) as info:
        cli_main(["validate", str(path), str(folder / "Q30_S001_2C.csv"),
                  str(folder / "Q30_S001_3C.csv"), "--cutoff", "3.0", "--columns", COLUMNS,
                  "--json", "--plot", str(plot)])
    assert info.value.code == 0
    data = json.loads(capsys.readouterr().out)
    assert [r["file"].endswith(n) for r, n in zip(data["files"], ("2C.csv", "3C.csv"))] == \
        [True, True]
    assert data["summary"]["files"] == 2
    assert plot.stat().st_size > 10_000
    with pytest.raises(SystemExit) as info:
        cli_main(["validate", str(path), str(folder / "Q30_S001_2C.csv"), "--cutoff", "3.0",
                  "--columns", COLUMNS])
    assert info.value.code == 0
    text = capsys.readouterr().out
    row = data["files"][0]
    # 2C was not fitted: its error is a validation, and the table says so
    assert (f"mean |endurance error| on files the fit did not see (validation): "
            f"{abs(row['endurance_error_pct']):.2f} %") in text
    assert "Validation to 3 V/cell" in text


def test_cli_validate_bad_input_is_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        cli_main(["validate", "hacker-4100-4s-lifepo4", str(tmp_path / "none.csv"),
                  "--cutoff", "2.5"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "none.csv" in err


def test_case_object_plots(tmp_path):
    from dischargelab.plot import save

    data, _ = model_discharge(PACK, 6.0, 3.0)
    case = compare_discharge(PACK, data, {"source": "self.csv"}, cutoff_cell_V=3.0)
    out = save(case.plot(), tmp_path / "case.png")
    assert out.stat().st_size > 5_000


# ---------------------------------------------------------------------------------------------
# Interval coverage, thermal ambient, every family
# ---------------------------------------------------------------------------------------------

def test_interval_and_coverage_in_rows_and_summary():
    from dischargelab.uncertainty import model_error_sd
    from dischargelab.validate import summarise

    exact, t_exact = model_discharge(PACK, 6.0, 3.0)
    smaller = Battery(CELL.replace(C_Ah=CELL.C_Ah * 0.8), cells_series=3)
    short, t_short = model_discharge(smaller, 6.0, 3.0)
    rows = [validate_discharge(PACK, exact, {"source": "same.csv"}, cutoff_cell_V=3.0),
            validate_discharge(PACK, short, {"source": "small.csv"}, cutoff_cell_V=3.0)]
    # no parameter draws in PACK: the interval is the model error alone around the prediction
    sd = model_error_sd(PACK, 6.0)
    lo, hi = rows[0]["interval_s"]
    predicted = rows[0]["endurance_predicted_s"]
    assert lo == pytest.approx(predicted * np.exp(-1.959964 * sd), rel=1e-6)
    assert hi == pytest.approx(predicted * np.exp(1.959964 * sd), rel=1e-6)
    assert rows[0]["interval_includes"] == ["model error (prior, extrapolation x2.0)"]
    assert rows[0]["covered"] is True                   # the model against itself
    assert rows[1]["covered"] is False                  # 20 % less capacity: far outside
    assert summarise(rows)["coverage"] == {"covered": 1, "runs": 2, "fraction": 0.5,
                                           "level": 0.95}
    half = exact[exact["time_s"] < 0.5 * t_exact]        # never reaches the cutoff: no verdict
    row = validate_discharge(PACK, half, {"source": "half.csv"}, cutoff_cell_V=3.0)
    assert row["covered"] is None and row["interval_s"] is not None
    assert summarise([row])["coverage"]["fraction"] is None


def thermal_battery():
    from dischargelab.models import FAMILIES

    values = FAMILIES["shepherd-thermal"].defaults()
    values.update(CELL.as_dict())
    values.update({"Cth_J_per_K": 40.0, "Rth_K_per_W": 12.0})
    return Battery(CellParameters(values), cells_series=3, model="shepherd-thermal",
                   fit_currents_A=(6.0,), extra={"ambient_C": 25.0})


def test_thermal_family_simulates_the_run_from_its_ambient():
    battery = thermal_battery()
    sim = simulate(battery, [Step("current", 9.0)], cutoff_cell_V=3.0, ambient_C=40.0,
                   points_per_step=2000)
    t = np.arange(0.0, sim.time_s[-1], 2.0)
    data = pd.DataFrame({"time_s": t, "current_A": np.full(t.size, 9.0),
                         "voltage_V": np.interp(t, sim.time_s, sim.voltage_V),
                         "temperature_C": np.interp(t, sim.time_s, sim.temperature_C)})
    data.loc[len(data)] = [sim.time_s[-1] + 1.0, 9.0, 8.0, 50.0]   # past the cutoff
    row = validate_discharge(battery, data, {"source": "hot.csv"}, cutoff_cell_V=3.0)
    assert row["ambient_C"] == 40.0 and row["peak_temperature_C"] > 40.0
    assert row["endurance_predicted_s"] == pytest.approx(sim.time_to_cutoff_s, rel=1e-4)
    assert row["voltage_rmse_pct"] < 0.05 and row["covered"] is True
    # without a logged temperature the battery's ambient (25 degC) is used: a colder cell
    cold = validate_discharge(battery, data.drop(columns="temperature_C"), {"source": "x.csv"},
                              cutoff_cell_V=3.0)
    assert cold["ambient_C"] == 25.0
    assert cold["endurance_predicted_s"] < row["endurance_predicted_s"]


@pytest.mark.parametrize("name", ["shepherd", "shepherd-thermal", "ecm"])
def test_every_family_flies_a_logged_profile(name):
    from dischargelab.models import FAMILIES

    if name not in FAMILIES:
        pytest.skip(f"model family {name!r} is not registered")
    fam = FAMILIES[name]
    battery = Battery(CellParameters(fam.defaults()), model=name, fit_currents_A=(3.0,))
    t = np.arange(0.0, 2400.0, 1.0)
    i = 3.0 + 1.5 * np.sign(np.sin(t / 90.0))              # 1.5 A / 4.5 A square wave
    sim = simulate(battery, [Step("profile", profile_time_s=tuple(t),
                                  profile_current_A=tuple(i)), Step("current", 3.0)],
                   cutoff_cell_V=3.2)
    keep = sim.step == 0
    data = pd.DataFrame({"time_s": t, "current_A": i,
                         "voltage_V": np.interp(t, sim.time_s[keep], sim.voltage_V[keep])})
    row = validate_discharge(battery, data, {"source": f"{name}.csv"}, cutoff_cell_V=3.2)
    assert row["profile"] == "measured" and row["model"] == name
    # the model against itself: the same engine run, sample by sample
    assert row["voltage_rmse_pct"] < 1e-9
    if sim.ended_by == "cutoff" and sim.step[-1] == 0:
        assert row["endurance_error_s"] == pytest.approx(0.0, abs=1.0)


def test_cli_validate_reports_coverage(tmp_path, capsys):
    data, _ = model_discharge(PACK, 6.0, 3.0)
    csv = tmp_path / "self.csv"
    data.to_csv(csv, index=False)
    battery = PACK.save(tmp_path / "pack.json")
    with pytest.raises(SystemExit) as info:
        cli_main(["validate", str(battery), str(csv), "--cutoff", "3.0", "--json"])
    assert info.value.code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["files"][0]["covered"] is True and len(doc["files"][0]["interval_s"]) == 2
    assert doc["summary"]["coverage"]["covered"] == 1
    with pytest.raises(SystemExit) as info:
        cli_main(["validate", str(battery), str(csv), "--cutoff", "3.0"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    assert "95 % interval coverage: 1/1 runs (100 %" in text and "covered" in text
