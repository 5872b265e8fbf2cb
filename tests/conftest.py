"""Shared fixtures: where the real measured data sets live."""

import os
import signal
import threading
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# Property tests check correctness, not speed: a slow first example on a
# busy 2-core CI machine must not fail them. In CI the examples are drawn
# from a fixed seed so a run can be repeated exactly.
settings.register_profile(
    "dischargelab",
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=bool(os.environ.get("CI")),
)
settings.load_profile("dischargelab")

# PyBaMM (the PyBaMM lives) starts a telemetry thread when imported without this; a thread
# left beside the suite keeps the fit's fold workers from forking in later tests.
os.environ.setdefault("PYBAMM_DISABLE_TELEMETRY", "true")

REPO = Path(__file__).resolve().parents[1]

#: No test may run longer than this [s] (the slowest take about a minute on a busy 2-core
#: machine): a test waiting on a server or a cluster that never answers fails, with the
#: place it waited, instead of holding the suite until the CI job's own limit.
TEST_LIMIT_S = int(os.environ.get("DISCHARGELAB_TEST_LIMIT_S", "600"))


class TestTooLong(Exception):
    """Raised in a test that ran past :data:`TEST_LIMIT_S`."""


@pytest.fixture(autouse=True)
def bounded_in_time(request):
    """Every test is bounded in time (SIGALRM in the main thread, POSIX)."""
    if not hasattr(signal, "SIGALRM") or threading.current_thread() is not threading.main_thread():
        yield
        return

    def too_long(signum, frame):
        raise TestTooLong(f"{request.node.nodeid} ran longer than {TEST_LIMIT_S} s")

    previous = signal.signal(signal.SIGALRM, too_long)
    signal.alarm(TEST_LIMIT_S)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _find_shared_data() -> Path | None:
    env = os.environ.get("DISCHARGELAB_SHARED_DATA")
    if env:
        return Path(env)
    for parent in [REPO, *REPO.parents]:
        candidate = parent / "shared" / "data"
        if (candidate / "samsung30q_S001").is_dir():
            return candidate
    return None


SHARED_DATA = _find_shared_data()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Folder of real measured discharges (../shared/data beside the checkout).

    Missing data fails the test rather than skipping it, so CI can never pass
    without exercising the real sets.
    """
    if SHARED_DATA is None:
        pytest.fail("real data folder ../shared/data not found; set DISCHARGELAB_SHARED_DATA")
    return SHARED_DATA


@pytest.fixture(scope="session")
def bundled_data() -> Path:
    """Samsung 30Q demo files bundled with the package."""
    return REPO / "src" / "dischargelab" / "data" / "samsung30q"


@pytest.fixture(scope="module")
def pg():
    """A throwaway PostgreSQL server for one test module (``tests/pg_cluster.py``)."""
    from pg_cluster import start_cluster, stop_cluster

    cluster = start_cluster()
    try:
        yield cluster
    finally:
        stop_cluster(cluster)


@pytest.fixture(params=["sqlite", "postgresql"])
def url(request, tmp_path):
    """A new logbook's location on each backend: a SQLite file, a PostgreSQL database."""
    if request.param == "sqlite":
        return str(tmp_path / "logbook.sqlite")
    return request.getfixturevalue("pg").new_database()
