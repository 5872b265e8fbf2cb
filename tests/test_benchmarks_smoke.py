"""Quick checks of the benchmark helpers (the full runs are in test_scripts.py, marked slow)."""

import importlib.util
import math
from pathlib import Path

import numpy as np

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
