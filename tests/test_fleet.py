"""The executor interface: in process, a LocalCluster, and a real scheduler + workers."""

import os
import subprocess
import sys
import threading
import time

import pytest

from dischargelab.errors import DataError
from dischargelab.fleet import (
    DaskExecutor,
    FleetError,
    InProcessExecutor,
    StartingExecutor,
    WorkerCrash,
    executor,
)
from fleet_tasks import (
    crash_on_seven,
    parent_pid,
    refuse_odd,
    square_slowly,
    square_unless_refused,
)

distributed = pytest.importorskip("distributed")


def wait_for_workers(ex, n: int, timeout_s: float = 60.0) -> None:
    """Wait (bounded) until ``n`` workers have joined the executor's scheduler."""
    deadline = time.monotonic() + timeout_s
    while ex.workers < n and time.monotonic() < deadline:
        time.sleep(0.2)


def test_no_flag_runs_in_process_without_importing_dask():
    code = ("import sys; from dischargelab.fleet import executor; e = executor(); "
            "r = list(e.map_unordered(abs, [-1, -2])); "
            "assert type(e).__name__ == 'InProcessExecutor', e; "
            "assert not any(m.split('.')[0] in ('dask', 'distributed') for m in sys.modules), "
            "sorted(m for m in sys.modules if 'dask' in m); print(r)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, env=dict(os.environ, DISCHARGELAB_SCHEDULER=""))
    assert out.returncode == 0, out.stderr
    assert "(-1, 1)" in out.stdout


def test_in_process_returns_errors_with_their_items():
    with InProcessExecutor() as ex:
        got = dict(ex.map_unordered(refuse_odd, range(4)))
    assert got[0] == 0 and got[2] == 2
    assert isinstance(got[1], DataError) and isinstance(got[3], DataError)


def test_executor_arguments():
    assert isinstance(executor(), InProcessExecutor)
    assert isinstance(executor(workers=1), InProcessExecutor)
    with pytest.raises(FleetError, match="workers must be 1 or more"):
        executor(workers=0)
    with pytest.raises(FleetError, match="not both"):
        executor(workers=2, scheduler="tcp://127.0.0.1:1")


def test_unreachable_scheduler_is_one_clear_error(monkeypatch):
    import dischargelab.fleet as fleet
    from dask_cluster import free_port

    monkeypatch.setattr(fleet, "START_TIMEOUT_S", 3.0)
    start = time.monotonic()
    with pytest.raises(FleetError, match="cannot start or reach the scheduler"):
        DaskExecutor(scheduler=f"tcp://127.0.0.1:{free_port()}")
    assert time.monotonic() - start < 30


@pytest.mark.slow
def test_local_cluster_same_results_bounded_submission_and_a_crashing_task():
    items = list(range(40))
    pulled = []

    def feed():
        for n in items:
            pulled.append(n)
            yield n

    with DaskExecutor(workers=2, max_in_flight=4) as ex:
        assert ex.workers == 2 and ex.shares_files
        seen = []
        for k, (item, result) in enumerate(ex.map_unordered(square_slowly, feed())):
            assert result["square"] == item * item
            # bounded: never more than in_flight items taken ahead of the results
            assert len(pulled) <= k + 1 + 4
            seen.append(item)
        assert sorted(seen) == items
        pids = {r["pid"] for _, r in ex.map_unordered(square_slowly, range(20))}
        assert os.getpid() not in pids
        refused = dict(ex.map_unordered(refuse_odd, range(4)))
        assert refused[2] == 2 and isinstance(refused[1], DataError)
        assert "item 1 is odd" in str(refused[1])

        outcomes = dict(ex.map_unordered(crash_on_seven, range(12)))
        # the workers that replaced the dead ones are forked from the fork server, like the
        # first (spawned ones would import everything again: slow, and seen never to come up)
        parents = {ppid for _, ppid in ex.map_unordered(parent_pid, range(8))}
        if sys.platform != "win32":
            assert os.getpid() not in parents, parents
        batched = dict(ex.map_unordered(crash_on_seven, range(12), per_task=4))
        grouped = dict(ex.map_unordered(square_slowly, range(30), per_task=4))
    assert sorted(grouped) == list(range(30))
    assert all(r["square"] == n * n for n, r in grouped.items())
    assert sorted(batched) == list(range(12))   # 4-7 crashed together, then ran alone
    assert isinstance(batched[7], WorkerCrash)
    assert all(batched[n] == n for n in range(12) if n != 7)
    assert sorted(outcomes) == list(range(12))
    assert isinstance(outcomes[7], WorkerCrash)
    assert "died twice" in str(outcomes[7])
    assert all(outcomes[n] == n for n in range(12) if n != 7)


@pytest.mark.slow
def test_a_starting_cluster_runs_the_first_items_here_and_the_rest_on_its_workers():
    from multiprocessing import forkserver

    start = time.monotonic()
    with executor(workers=2, background=True) as ex:
        assert isinstance(ex, StartingExecutor)
        assert ex.shares_files                   # known before the cluster is up
        server = forkserver._forkserver._forkserver_pid
        assert server is not None                # started at once, before the cluster
        seen = {}
        for item, result in ex.map_unordered(square_unless_refused, range(40), per_task=2):
            assert item not in seen              # each item once, here or there
            seen[item] = result
            if len(seen) == 3:
                ex.ready()                       # then the rest goes to the workers
        assert ex.ready().workers == 2
        parents = {pid for _, pid in ex.map_unordered(parent_pid, range(6))}
    assert time.monotonic() - start < 150
    assert sorted(seen) == list(range(40))
    here = sorted(n for n, r in seen.items() if isinstance(r, dict) and r["pid"] == os.getpid())
    ran_here = here + [1] * (ex.ran_here > 1)    # item 1 is refused, here
    assert 1 <= ex.ran_here <= 3 and sorted(ran_here) == list(range(ex.ran_here))
    for n in (1, 13):                            # refused here (1) and on a worker (13)
        assert isinstance(seen[n], DataError) and f"item {n} is refused" in str(seen[n])
    squares = {n: r for n, r in seen.items() if n not in (1, 13)}
    assert all(r["square"] == n * n for n, r in squares.items())
    assert len({r["pid"] for r in squares.values()} - {os.getpid()}) >= 1
    assert parents == {server}                   # workers forked from that server


@pytest.mark.slow
def test_real_scheduler_and_workers_kill_one_worker_mid_run():
    from dask_cluster import Cluster

    cluster = Cluster(workers=2)
    try:
        with executor(scheduler=cluster.address) as ex:
            wait_for_workers(ex, 2)
            assert ex.workers == 2
            assert not ex.shares_files
            assert ex.sees(__file__)
            results = []
            killer = None
            for item, result in ex.map_unordered(square_slowly, range(120)):
                assert result["square"] == item * item
                results.append(item)
                if len(results) == 10:
                    killer = threading.Thread(target=cluster.kill, args=(cluster.workers[0],))
                    killer.start()
            killer.join()
            assert sorted(results) == list(range(120))   # nothing lost, nothing twice
            assert cluster.workers[0].poll() is not None
    finally:
        cluster.stop()
    assert cluster.alive() == []


@pytest.mark.slow
def test_a_cluster_left_without_workers_ends_the_wait_with_one_line(monkeypatch):
    import dischargelab.fleet as fleet
    from dask_cluster import Cluster

    monkeypatch.setattr(fleet, "NO_WORKER_S", 2.0)
    cluster = Cluster(workers=1)
    try:
        with executor(scheduler=cluster.address) as ex:
            wait_for_workers(ex, 1)
            results = []
            started = None
            with pytest.raises(FleetError, match="no worker for 2 s") as info:
                for item, result in ex.map_unordered(square_slowly, range(200)):
                    results.append(result["square"] == item * item)
                    if started is None:
                        cluster.kill(cluster.workers[0])
                        started = time.monotonic()
            assert time.monotonic() - started < 30          # bounded, not Dask's own wait
            assert results and all(results)                  # what finished was handed over
            assert "\n" not in str(info.value)
    finally:
        cluster.stop()
    assert cluster.alive() == []
