"""The held-out folds in worker processes give the very same fit as in one process."""

import json
import threading

import pytest

import dischargelab as dl
from dischargelab.fit import workers

COLUMNS = {"time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4}


@pytest.fixture(scope="module")
def runs(bundled_data):
    return [dl.read(bundled_data / f"Q30_S001_{r}.csv", columns=COLUMNS)
            for r in ("C10", "4C")]


def _fingerprint(res):
    return json.dumps({"model": res.model, "parameters": res.parameters.as_dict(),
                       "model_error": res.model_error, "notes": res.notes[:1]},
                      sort_keys=True, default=str)


@pytest.mark.skipif(workers.usable_workers() < 2, reason="needs fork and two cores")
def test_workers_change_nothing(runs, monkeypatch):
    monkeypatch.setenv("DISCHARGELAB_WORKERS", "2")
    assert workers.usable_workers() == 2
    parallel = dl.fit(runs, bootstrap=0)  # auto: every candidate's folds, pipelined
    monkeypatch.setenv("DISCHARGELAB_WORKERS", "1")
    assert workers.usable_workers() == 1
    alone = dl.fit(runs, bootstrap=0)
    assert parallel.model_error["source"] == "held-out"
    assert _fingerprint(parallel) == _fingerprint(alone)


def test_no_fork_beside_another_thread(monkeypatch):
    monkeypatch.setenv("DISCHARGELAB_WORKERS", "2")
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    try:
        assert workers.usable_workers() == 1
        with workers.fold_workers():
            assert workers.submit(sum, [1, 2]).result() == 3  # ran here, no pool
            assert workers._POOL.get() is None
    finally:
        stop.set()
        other.join(5)


@pytest.mark.skipif(workers.usable_workers() < 2, reason="needs fork and two cores")
def test_worker_errors_reach_the_caller(monkeypatch):
    monkeypatch.setenv("DISCHARGELAB_WORKERS", "2")
    with workers.fold_workers():
        assert workers._POOL.get() is not None
        with pytest.raises(ZeroDivisionError):
            workers.submit(divmod, 1, 0).result()
    assert workers._POOL.get() is None


def test_a_battery_reaches_a_worker_whole(runs):
    """What the workers are handed (a fitted battery) pickles to an equal copy."""
    import pickle

    battery = dl.fit(runs, model="shepherd", bootstrap=0).battery
    copy = pickle.loads(pickle.dumps(battery))
    assert copy.parameters == battery.parameters and copy.model == battery.model
