"""Quick checks of the benchmark helpers (the full runs are in test_scripts.py, marked slow)."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

import dischargelab as dl

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name):
    spec = importlib.util.spec_from_file_location(f"bench_{name}", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_time_to_cutoff_interpolates_first_crossing():
    # the accuracy benchmark measures time to cutoff with validate's function
    acc = _load("accuracy")
    t = np.array([0.0, 10.0, 20.0, 30.0])
    v = np.array([4.0, 3.2, 2.8, 2.4])
    # crosses 3.0 V half way between 10 s and 20 s
    assert math.isclose(acc.measured_time_to_cutoff(t, v, 3.0), 15.0)
    # a sample exactly at the cutoff counts
    assert math.isclose(acc.measured_time_to_cutoff(t, v, 2.8), 20.0)
    assert math.isnan(acc.measured_time_to_cutoff(t, v, 2.0))


def test_position_of_held_out_runs():
    acc = _load("accuracy")

    def run(current, ambient=25.0):
        return acc.Run("x", None, current, 2.5, ambient, 100.0)

    train = [run(0.3), run(12.0)]
    assert acc.position(run(6.0), train) == "inside"
    assert acc.position(run(20.0), train) == "current outside"
    assert acc.position(run(3.0, 40.0), [run(3.0, 20.0)]) == "ambient outside"


def test_baseline_fit_reaches_the_noise_on_synthetic_data():
    speed = _load("fit_speed")
    curve = speed.synthetic_curve(3.0, dt_s=5.0, seed=1)
    rmse, nfev, n_free = speed.baseline_fit(curve, "shepherd")
    assert n_free == 6 and nfev > 0
    assert rmse < 1.5 * 0.0033  # noise 3 mV plus the 10-bit ADC step


def test_large_csv_reads_back(tmp_path):
    speed = _load("fit_speed")
    path = tmp_path / "large.csv"
    speed.write_large_csv(path, 5000)
    d = dl.read(path)
    assert 4900 <= d.time_s.size <= 5000
    assert np.allclose(d.current_A, 3.0)
    assert d.temperature_C is not None


def test_one_rate_law_from_rows():
    """The measured law: base from the fitted run's own error, the growth per ln r from the
    95th percentile of the errors (a collapsed run left out), up and down apart."""
    bench = _load("one_rate_errors")

    def row(ratio, error, cell="a", collapse=False):
        return {"class": "x", "cell": cell, "ratio": ratio, "error": error, "fitted": "1C",
                "target": "1C" if ratio == 1 else "2C", "collapse": collapse}

    rows = [row(1.0, 0.001), row(1.0, -0.002)]
    rows += [row(2.0, 0.01 * k * math.log(2.0), cell=str(k % 3)) for k in range(1, 21)]
    rows += [row(0.5, -0.02 * math.log(2.0)), row(3.0, 0.9, collapse=True)]
    table = bench.law(rows)["x"]
    assert table["base"] == bench.uncertainty.MIN_HELD_OUT_SD        # fitted runs: 0.2 %
    k = [max(0.01 * j * math.log(2.0) - table["base"], 0) / math.log(2.0) for j in range(1, 21)]
    assert table["up"] == np.quantile(k, 0.95) / 1.959964
    assert table["up_pairs"] == 20 and table["down_pairs"] == 1      # the collapse left out
    assert table["cells"] == ["0", "1", "2", "a"]


def test_one_rate_cache_reuses_a_fit_of_the_same_code(tmp_path):
    """``--cache``: a fit is made once, then read back (same parameters) under a folder named
    by the hash of the model and fit sources."""
    bench = _load("one_rate_errors")
    curve = dl.read(BENCHMARKS.parent / "tests" / "data" / "virtual" / "lfp-spme-2.5V_2C_25C.csv")
    bench.CACHE[:] = [tmp_path]
    try:
        first, model = bench.cached_fit("k", curve, model="shepherd", bootstrap=0, seed=0)
        files = list((tmp_path / bench.code_version()).glob("*.json"))
        assert model == "shepherd" and len(files) == 1
        again, _ = bench.cached_fit("k", curve, model="shepherd", bootstrap=0, seed=0)
    finally:
        bench.CACHE[:] = []
    assert again.to_dict()["parameters"] == first.to_dict()["parameters"]
    assert len(list(tmp_path.rglob("*.json"))) == 1


def test_health_matrix_resamples_and_chooses_the_drift_share():
    import pandas as pd

    matrix = _load("health_matrix")
    frame = pd.DataFrame({"time_s": [0.0, 166.5, 333.0], "voltage_V": [4.0, 3.9, 3.8],
                          "current_A": [1.0, 1.0, 0.0], "temperature_C": [25.0] * 3})
    fine = matrix.resample(frame, 30.0)
    assert np.allclose(np.diff(fine["time_s"]), 30.0)
    assert np.interp(83.25, fine["time_s"], fine["voltage_V"]) == np.float64(3.95)
    rows = pd.DataFrame({"now_Ah": [3.0, 3.0, 3.0], "trend_Ah": [3.0, 3.0, 3.0],
                         "truth_Ah": [2.9, 3.0, 3.01],
                         "trend_sd": [0.01] * 3, "drift_unit": [0.3] * 3,
                         "quantile": [1.96] * 3})
    # 0.1 Ah off with 0.01 Ah of its own: the drift must give 0.05 Ah, a share of 0.167,
    # 0.2 on the grid
    def share(blocks, value):
        return matrix._held(blocks, value, 0.0)

    assert matrix.needed(rows, matrix.SHARES, share) == 0.2
    assert matrix.needed(rows.assign(drift_unit=0.0), matrix.SHARES, share) == float("inf")
    # the hidden fade comes off the trend's value: with the resistance up 60 %, blocks
    # 6 % below their estimates read best at 0.1 per unit of rise, and are held there
    hidden = rows.assign(trend_Ah=3.0, drift_unit=0.0, rise=0.6, seen_fade=0.01,
                         truth_Ah=[2.82, 2.82, 2.83])
    assert matrix._best_per_rise(hidden) == pytest.approx(0.1)
    assert matrix._held(hidden, 0.0, 0.1).all()
    assert matrix._best_per_rise(hidden.assign(truth_Ah=3.0)) == 0.0


def test_health_matrix_counts_a_mission_by_the_recharge_after_it():
    matrix = _load("health_matrix")
    # a mission whose samples miss its charge (trapezoids: 0.5 Ah), then a charge back at
    # constant current (0.76 Ah): the mission's samples carry what the charge puts back
    t = np.array([0.0, 1800.0, 3600.0, 3700.0, 5500.0, 7300.0, 7400.0])
    i = np.array([0.0, 1.0, 0.0, 0.0, -1.0, -1.0, 0.0])
    dq = matrix.recharged_counts(t, i)
    back = -dq[dq < 0].sum()
    assert back == pytest.approx(0.25 + 0.5 + 100 / 7200)
    assert dq[1:3].sum() == pytest.approx(back)
    assert dq[1] == pytest.approx(dq[2])


def test_health_matrix_says_its_pybamm_conditions_are_skipped_without_pybamm(
        monkeypatch, tmp_path, capsys):
    matrix = _load("health_matrix")
    monkeypatch.setattr(matrix, "pybamm_installed", lambda: False)
    matrix.main(["--only", "PyBaMM", "--cache", str(tmp_path)])
    out = capsys.readouterr().out
    assert out.count("skipped: pybamm not installed") == len(matrix.PYBAMM) > 0
