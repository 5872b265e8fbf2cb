"""Flights in: fit from partial discharges, flight reports, remaining-time replay.

Real logs from ../shared/data/flight_logs (the GPL-licensed ones are read where they
are, never copied). Expected figures come from that folder's README, measured there
independently of these readers: 29.csv flies 144.6 s from 140.5 s, its first record
under 3.3 V per cell comes 115.8 s after take-off; Betaflight holds three flights of
one pack without recharging.
"""

import json

import numpy as np
import pytest

import dischargelab as dl
from cli_run import run
from dischargelab.errors import DataError
from dischargelab.flight import (
    CAPACITY_TOLERANCE,
    GENERIC_OCV_V,
    OCV_SOC,
    analyse_flight,
    flight_curves,
    ocv_from_soc,
    resistance_windows,
    soc_from_rest_voltage,
)

pytest.importorskip("orangebox")
pytest.importorskip("pyulog")
pytest.importorskip("pymavlink")

INA29 = "ina3221_fpv_4s/29.csv"
BETAFLIGHT = "betaflight_diatone/btfl_001.bbl"
LOGS = [INA29, "ina3221_fpv_4s/28.csv", BETAFLIGHT, "ardupilot_loganalyzer/mechanical_fail.log",
        "px4_ulog_rs/esc_status_log.ulg", "pyulog_sample/sample_log_small.ulg"]

#: README: the 29.csv pack is a Dinogy 1600 mAh 4S; first record under 3.3 V/cell 115.8 s
#: after take-off (take-off at 140.5 s).
LABEL_29_AH = 1.6
FIRST_UNDER_3V3_S = 115.8


@pytest.fixture(scope="module")
def logs(shared_data):
    return shared_data / "flight_logs"




# --------------------------------------------------------------------------- OCV prior

@pytest.mark.parametrize("chemistry", list(GENERIC_OCV_V))
def test_generic_ocv_is_monotone_and_inverts(chemistry):
    table = GENERIC_OCV_V[chemistry]
    assert table.shape == OCV_SOC.shape and np.all(np.diff(table) < 0)
    soc = np.linspace(0.02, 0.98, 49)
    assert soc_from_rest_voltage(ocv_from_soc(soc, chemistry), chemistry) == \
        pytest.approx(soc, abs=1e-9)
    assert soc_from_rest_voltage(table[0] + 0.1, chemistry) == 1.0
    assert soc_from_rest_voltage(table[-1] - 0.1, chemistry) == 0.0


def test_resistance_windows_recover_a_known_resistance():
    rng = np.random.default_rng(3)
    t = np.arange(0, 60, 0.1)
    i = 20 + 15 * rng.standard_normal(t.size)
    v = 16.5 - 0.002 * t - 0.025 * i + 0.005 * rng.standard_normal(t.size)
    rows = resistance_windows(t, v, i, 8.0)
    good = rows[rows["determined"]]
    assert len(good) >= 6
    assert np.median(good["resistance_ohm"]) == pytest.approx(0.025, rel=0.02)


# --------------------------------------------------------------------------- INA3221 29.csv

@pytest.fixture(scope="module")
def fit29(logs):
    flights = flight_curves(logs / INA29, capacity_Ah=LABEL_29_AH)
    return flights, dl.fit(flights, model="ecm", bootstrap=0)


def test_29_initial_charge_from_the_rest_voltage(fit29):
    flights, _ = fit29
    (curve,) = flights.curves
    row = flights.flights[0]
    # 16.65 V at rest before take-off: 4.16 V/cell, near full on the LiPo prior
    assert row["rest_before_V"] == pytest.approx(16.65, abs=0.02)
    assert 0.95 < row["soc_start"] <= 1.0
    assert curve.initial_charge_Ah == pytest.approx((1 - row["soc_start"]) * LABEL_29_AH)
    assert curve.charge_Ah[-1] == pytest.approx(0.9755, abs=0.01)  # README: 975.5 mAh
    assert not flights.knee_reached


def test_29_capacity_held_near_the_label_and_said_so(fit29):
    _, result = fit29
    cell = result.parameters["C_Ah"]
    assert LABEL_29_AH * (1 - CAPACITY_TOLERANCE) - 1e-9 <= cell <= \
        LABEL_29_AH * (1 + CAPACITY_TOLERANCE) + 1e-9
    text = " ".join(result.notes)
    assert "capacity not determined by these flights" in text and "±10 %" in text
    assert "prior" in text and "no battery temperature" in text
    assert result.rmse_V < 0.03  # per cell


@pytest.mark.slow
def test_29_replay_at_mid_flight_against_the_truth(fit29, logs):
    _, result = fit29
    report = analyse_flight(logs / INA29, result.battery, capacity_Ah=LABEL_29_AH, cutoff=3.3)
    (flight,) = report.flights
    s = flight.summary
    mid = s["replay_mid_flight"]
    takeoff = s["load_start_s"]
    assert takeoff == pytest.approx(140.5, abs=0.1)
    # one 67 ms record under 3.3 V/cell at a 73 A peak, 115.8 s after take-off (README): a
    # sag, not the end of the pack; with the 10 s low-voltage timer there is no truth
    assert s["cutoff_dip_at_s"] - takeoff == pytest.approx(FIRST_UNDER_3V3_S, abs=0.1)
    assert s["cutoff_reached_at_s"] is None and mid["true_s"] is None
    assert mid["time_s"] + mid["first_dip_s"] - takeoff == pytest.approx(FIRST_UNDER_3V3_S,
                                                                         abs=0.1)
    assert any("sag at a current peak" in n for n in flight.notes)
    for key in ("px4_s", "ardupilot_s", "model_s", "model_profile_s"):
        assert mid[key] > 0
    assert s["rmse_V"] < 0.12 and max(s["rmse_cell_V"]) < 0.08
    assert s["charge_Ah"] == pytest.approx(0.9755, abs=0.005)
    # without the timer the first record under the cutoff is the truth, and the model
    # flying the logged load finds the same crossing
    instant = analyse_flight(logs / INA29, result.battery, capacity_Ah=LABEL_29_AH, cutoff=3.3,
                             low_timer_s=0.0).flights[0].summary["replay_mid_flight"]
    assert instant["time_s"] + instant["true_s"] - takeoff == pytest.approx(FIRST_UNDER_3V3_S,
                                                                            abs=0.1)
    assert instant["model_logged_load_s"] == pytest.approx(instant["true_s"], abs=10.0)


def _write_ina_csv(path, t, cell_V, current_A, cells, pack_V=None):
    """An INA3221-style CSV: time [ms], pack [V], equal cell voltages [V], current [mA],
    shunt voltage [mV] (0.5 mOhm shunt), a trailing comma; pack = cells x cell_V unless
    given."""
    pack = cells * np.asarray(cell_V) if pack_V is None else np.asarray(pack_V)
    with open(path, "w", encoding="utf-8") as fh:
        for k in range(len(t)):
            fh.write(f"{t[k] * 1000:.0f},{pack[k]:.3f}," + ",".join([f"{cell_V[k]:.3f}"] * cells)
                     + f",{current_A[k] * 1000:.1f},{current_A[k] * 0.5:.2f},\n")


def _spiky_drain_log(path, battery, cutoff_cell_V):
    """An INA3221-style CSV of a known pack flown to its cutoff: 20 s at rest, then 3C
    with a 6C peak of 0.4 s every 6 s, 15 Hz; the voltage is the model's."""
    from dischargelab.engine import Step, run

    dt, rest_s = 1 / 15, 20.0
    hover = 3.0 * battery.capacity_Ah
    t_load = np.arange(0.0, 3600.0 * 1.2 / 3.0, dt)
    current = np.where((t_load % 6.0) < 0.4, 6.0 * battery.capacity_Ah, hover)
    res = run(battery.family, dict(battery.parameters), [Step(
        "profile", duration_s=float(t_load[-1]), profile_time_s=tuple(t_load),
        profile_current_A=tuple(current))], cutoff_pack_V=0.7 * cutoff_cell_V *
        battery.cells_series, cells_series=battery.cells_series,
        strings_parallel=battery.strings_parallel, record=True)
    t_sim = np.asarray(res.series["time_s"])
    v_sim = np.asarray(res.series["voltage_V"])
    end = t_sim[-1] + 2.0                      # landed on the alarm, then off
    t = np.r_[np.arange(0.0, rest_s, dt), rest_s + t_load[t_load <= end]]
    i = np.r_[np.full(int(np.ceil(rest_s / dt)), 0.2), current[t_load <= end]][:t.size]
    v = np.interp(t - rest_s, t_sim, v_sim)
    v[t < rest_s] = float(battery.voltage(0.0, 0.0))
    _write_ina_csv(path, t, v / battery.cells_series, i, battery.cells_series, pack_V=v)
    return rest_s


@pytest.mark.slow
def test_replay_of_a_drain_to_the_cutoff_by_the_true_model(tmp_path):
    """A log made by a known pack under a spiky load down to its cutoff: the peaks dip
    under the cutoff early, the pack reaches it for good later; the model at the recent
    mean load replays the remaining time at mid-flight within 10 % of that truth."""
    from dischargelab.model import PRESETS

    battery = PRESETS["zippy-1100-2s"]
    log = tmp_path / "drain.csv"
    _spiky_drain_log(log, battery, 3.3)
    report = analyse_flight(log, battery, cutoff=3.3, capacity_Ah=battery.capacity_Ah)
    (flight,) = report.flights
    s = flight.summary
    assert s["cutoff_dip_at_s"] < s["cutoff_reached_at_s"]
    mid = s["replay_mid_flight"]
    assert mid["true_s"] > 60
    assert mid["time_s"] + mid["true_s"] == pytest.approx(s["cutoff_reached_at_s"], abs=0.2)
    for key in ("model_s", "model_profile_s", "model_logged_load_s"):
        assert mid[key] == pytest.approx(mid["true_s"], rel=0.10), key
    assert mid["first_dip_s"] < 0.9 * mid["true_s"]


# --------------------------------------------------------------------------- Betaflight

@pytest.mark.slow     # decodes the Betaflight log (~7 s)
def test_betaflight_three_flights_of_one_pack_fitted_together(logs):
    flights = flight_curves(logs / BETAFLIGHT, capacity_Ah=1.3)
    starts = [c.initial_charge_Ah for c in flights.curves]
    assert len(starts) == 3 and starts[0] < starts[1] < starts[2]
    drawn = [f["charge_Ah"] for f in flights.flights]
    assert drawn == pytest.approx([0.1783, 0.2661, 0.3584], abs=0.005)  # README
    result = dl.fit(flights, model="ecm", bootstrap=0)
    assert len(result.curves) == 3 and result.rmse_V < 0.05
    assert result.cells_series == 6
    assert any("drew gives" in n for n in result.notes)  # rest voltage vs counted charge


def test_fit_needs_a_capacity_when_the_log_has_none(logs):
    with pytest.raises(DataError, match=r"capacity_Ah=AH \(--capacity AH\)"):
        flight_curves(logs / INA29)


# --------------------------------------------------------------------------- command line

@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n.endswith(".bbl")
                                  else n for n in LOGS])
def test_every_bundled_log_runs_through_flight_without_flags(logs, capsys, name):
    code, out, err = run(capsys, "flight", logs / name)
    assert code == 0, err
    assert "flight 1" in out and "duration" in out


@pytest.mark.parametrize("content", [b"ULog\x01\x12\x35\x01garbage", bytes(range(256)) * 40,
                                     b"time,voltage\n0,4.1\n1,4.0\n"])
def test_corrupt_or_foreign_log_one_line_exit_2_nothing_written(tmp_path, capsys, content):
    log = tmp_path / "flight.ulg"
    log.write_bytes(content)
    plot = tmp_path / "plot.png"
    code, out, err = run(capsys, "flight", log, "-o", plot, "--json")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and err.startswith("error: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.ulg"]


@pytest.mark.slow
def test_fit_and_flight_commands_on_a_flight_log(logs, tmp_path, capsys):
    pack = tmp_path / "pack.json"
    code, _, err = run(capsys, "fit", logs / INA29, "--model", "ecm", "--bootstrap", "0")
    assert code == 2 and "--capacity" in err and len(err.strip().splitlines()) == 1
    code, out, err = run(capsys, "fit", logs / INA29, "--flight", "1", "--battery", "0",
                         "--capacity", LABEL_29_AH, "--model", "ecm", "--bootstrap", "0",
                         "-o", pack, "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["cells_series"] == 4 and doc["battery_file"] == str(pack)
    assert any("capacity not determined" in n for n in doc["notes"])
    saved = json.loads(pack.read_text())
    assert saved["nominal_capacity_Ah"] == pytest.approx(LABEL_29_AH)
    plot = tmp_path / "flight.png"
    code, out, err = run(capsys, "flight", logs / INA29, "--battery-model", pack, "--cutoff",
                         "3.3", "-o", plot, "--json")
    assert code == 0, err
    doc = json.loads(out)
    (flight,) = doc["flights"]
    assert flight["replay"] and flight["replay_mid_flight"]["model_s"] > 0
    assert plot.stat().st_size > 10_000
    code, _, err = run(capsys, "fit", logs / INA29, "--flight", "2", "--capacity", "1.6")
    assert code == 2 and "flight" in err


def test_flight_options_need_a_flight_log(bundled_data, capsys):
    code, _, err = run(capsys, "fit", bundled_data / "Q30_S001_1C.csv", "--capacity", "3")
    assert code == 2 and "flight logs" in err


@pytest.mark.slow
def test_validate_flies_a_flight_from_its_charge_at_take_off_at_the_ambient(fit29, logs):
    """A thermal family fitted without a logged temperature simulates the cells' heating
    with the thermal prior (a 1.6 Ah LiPo cell of a 4S pack in the airflow of flight) in
    the fit and in every replay, and validate starts the flight from the charge the rest
    voltage before take-off gives: the same voltage as `flight`."""
    _, result = fit29
    battery = result.battery
    prior = battery.extra["thermal_prior"]
    assert prior["cooling"] == "airflow" and prior["chemistry"] == "lipo"
    assert battery.parameters["Cth_J_per_K"] == pytest.approx(prior["Cth_J_per_K"])
    assert 20.0 < prior["Cth_J_per_K"] < 60.0         # 1.6 Ah x 3.7 V / 160 Wh/kg x 1 J/(g K)
    assert 2.0 < prior["fit_virtual_rise_K"] < 40.0   # 144 s at 24 A (15C) warms the pack
    (case,) = dl.validate(battery, [logs / INA29], cutoff=3.3)
    row = case.to_dict()
    report = analyse_flight(logs / INA29, battery, capacity_Ah=LABEL_29_AH, cutoff=3.3)
    flown = report.flights[0].summary
    # both read the rest sample at its idle current (about 0.25 A)
    assert row["initial_charge_Ah"] == pytest.approx(flown["initial_charge_model_Ah"], abs=0.005)
    assert "from the rest voltage" in row["notes"][0]
    assert row["voltage_rmse_V"] < 0.15


@pytest.mark.slow
def test_validate_a_spiky_drain_by_when_the_pack_stays_under_the_cutoff(tmp_path):
    """Under a varying current the measured and predicted times are both when the voltage
    stays under the cutoff for the low-voltage timer, not the first peak's dip."""
    from dischargelab.model import PRESETS
    from dischargelab.validate import compare_discharge

    battery = PRESETS["zippy-1100-2s"]
    log = tmp_path / "drain.csv"
    _spiky_drain_log(log, battery, 3.3)
    (case,) = dl.validate(battery, [log], cutoff=3.3)
    row = case.to_dict()
    assert row["low_timer_s"] == 10.0 and row["profile"] == "measured"
    assert abs(row["endurance_error_pct"]) < 1.0
    assert row["covered"]
    # the first dip under the cutoff comes at a current peak, well before
    first = compare_discharge(battery, dl.read(log).to_pandas(), {"source": str(log)}, 3.3,
                              low_timer_s=0.0)
    assert first.summary["endurance_measured_s"] < 0.9 * row["endurance_measured_s"]


def _ocv_drain_log(path, capacity_Ah, current_A, *, end_soc=0.05, rest_after_s=60.0, dt=1.0,
                   r_cell=0.04):
    """An INA3221-style CSV of a 4S LiPo that follows the generic OCV with ``r_cell`` ohm
    per cell: 20 s at rest, a constant drain down to ``end_soc``, then rest."""
    from dischargelab.flight import ocv_from_soc

    t_load = np.arange(0.0, (1.0 - end_soc) * capacity_Ah * 3600.0 / current_A, dt)
    t = np.r_[np.arange(0.0, 20.0, dt), 20.0 + t_load,
              20.0 + t_load[-1] + np.arange(dt, rest_after_s, dt)]
    i = np.where((t >= 20.0) & (t <= 20.0 + t_load[-1]), current_A, 0.05)
    soc = 1.0 - np.r_[0.0, np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t))] / 3600.0 / capacity_Ah
    _write_ina_csv(path, t, ocv_from_soc(soc, "lipo") - r_cell * i, i, 4)


def test_a_full_drain_gives_the_capacity_when_no_label_is_known(tmp_path):
    log = tmp_path / "drain.csv"
    _ocv_drain_log(log, 5.0, 1.5)
    flights = flight_curves(log)
    assert flights.capacity_Ah == pytest.approx(5.0, rel=0.1)
    assert flights.capacity_source.startswith("estimated from flight 1")
    assert flights.knee_reached
    # a shallow flight cannot tell: one clear line asks for the label
    shallow = tmp_path / "shallow.csv"
    _ocv_drain_log(shallow, 5.0, 1.5, end_soc=0.7)
    with pytest.raises(DataError, match="no flight drains the pack deep enough"):
        flight_curves(shallow)


def test_a_slow_drain_predicts_a_fast_spiky_drain_of_the_same_pack(tmp_path):
    """One slow full drain (0.3C) fits ecm with its RC pairs held absent (one constant
    current cannot show them); it predicts a 3.5C drain with 5.5C peaks of the same pack
    (generic LiPo OCV, 8 mOhm per cell) within 5 % to 3.3 V/cell, and its voltage."""
    from dischargelab.flight import ocv_from_soc

    slow, fast = tmp_path / "slow.csv", tmp_path / "fast.csv"
    _ocv_drain_log(slow, 5.0, 1.5, end_soc=0.02, r_cell=0.008)
    dt, cap = 1 / 15, 5.0
    t_load = np.arange(0.0, 3600 / 3.5, dt)
    i_load = np.where((t_load % 5) < 0.5, 5.5 * cap, (3.5 * cap * 5 - 5.5 * cap * 0.5) / 4.5)
    t = np.r_[np.arange(0.0, 20.0, dt), 20.0 + t_load]
    i = np.r_[np.full(int(np.ceil(20.0 / dt)), 0.05), i_load][:t.size]
    soc = 1 - np.r_[0.0, np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t))] / 3600 / cap
    cell = ocv_from_soc(soc, "lipo") - 0.008 * i
    stop = min(int(np.argmax((cell <= 3.3) & (i < 5 * cap))) + int(15 / dt), t.size)
    _write_ina_csv(fast, t[:stop], cell[:stop], i[:stop], 4)
    result = dl.fit(flight_curves(slow), bootstrap=0)
    assert result.model == "ecm" and "held absent" in result.notes[0]
    assert result.parameters["R1_ohm"] == 0.0 and result.parameters["R2_ohm"] == 0.0
    (case,) = dl.validate(result.battery, [fast], cutoff=3.3)
    row = case.to_dict()
    assert abs(row["endurance_error_pct"]) < 5.0
    assert row["voltage_rmse_V"] / 4 < 0.05
