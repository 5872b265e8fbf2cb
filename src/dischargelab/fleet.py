"""One executor interface for fleet-scale work: in this process, or on a Dask cluster.

A task is a pure function of one item (a file path, or a file's name and bytes) that
returns a small, serialisable summary; it never touches the database. An executor
maps it over items and yields ``(item, outcome)`` as each finishes, in any order;
``outcome`` is the task's result or the exception it raised (the caller decides
which exceptions are rejections and which are bugs). At most ``max_in_flight``
items are submitted and not yet collected, so a big folder never floods memory
or a scheduler, and the client is the only writer of whatever stores the results.

* :class:`InProcessExecutor` runs the tasks one after the other here, with no Dask
  import at all (``workers=1`` or nothing given).
* :class:`DaskExecutor` runs them on ``dask.distributed`` workers: a
  ``LocalCluster`` of ``workers`` processes it starts and ends itself, or an
  existing cluster at a scheduler address (``tcp://host:port``). A worker that
  dies mid-task has its task retried on another worker by the scheduler; a task
  whose worker dies twice is reported as failed (:class:`WorkerCrash`) instead of
  being retried for ever.

:func:`executor` picks one from the arguments (or ``DISCHARGELAB_SCHEDULER``);
``background=True`` starts a Dask one in a thread (:class:`StartingExecutor`), so the
caller lists and hashes its files while the workers come up, and the first tasks run in
this process until they are (a local cluster's fork server, :func:`start_fork_server`,
imports the workers' modules meanwhile on the other core).

References
----------
Dask distributed documentation: "Futures" (``Client.submit``, ``as_completed``),
"Resilience" (a task whose workers die more than ``allowed-failures`` times
raises ``KilledWorker``) and "Dask Best Practices" (bounded submission, small
results, pure functions).
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from itertools import islice
from typing import Any, Protocol

from .errors import DischargelabError, require

#: Environment variable naming the scheduler of an existing cluster.
SCHEDULER_ENV = "DISCHARGELAB_SCHEDULER"

#: Items submitted and not yet collected, by default, in process.
DEFAULT_MAX_IN_FLIGHT = 64

#: Tasks in flight per Dask worker: enough to keep every worker busy while results
#: travel back, few enough that the client holds only a handful of payloads at a time.
IN_FLIGHT_PER_WORKER = 2

#: Deaths of a task's worker after which the task counts as failed (the first death
#: is retried elsewhere, the second is the task's fault).
WORKER_DEATHS_ALLOWED = 1

#: Seconds to wait for a cluster's workers to come up (or connect to a scheduler).
START_TIMEOUT_S = 60.0

#: Seconds a cluster may have no worker at all while tasks wait before the wait ends with
#: :class:`FleetError` (every worker died and none came back, or all left the scheduler).
#: A nanny restarts a crashed worker in a few seconds, over a minute on a starved machine.
NO_WORKER_S = 300.0

#: Seconds between looks for a finished task while none is waiting to be collected.
POLL_S = 0.01

#: Seconds of waiting between two looks at the cluster's worker list.
LOOK_S = 1.0

#: Modules a local cluster's workers import as they start (the readers and the logbook's
#: tasks, with pandas and scipy): a few seconds each worker would otherwise spend on its
#: first task, spent while the client lists and hashes its files.
PRELOAD = ("dischargelab.io", "dischargelab.logbook.summarise", "dischargelab.logbook.figures")


#: Dask settings of a local cluster's workers: no statistical profiler (it samples the task's
#: stack every 10 ms), and the event loop's watchdog and system and memory monitors woken
#: every second or more instead of every 20-500 ms. Each wake-up takes the interpreter lock
#: from the task; on the logbook's tasks (pure Python and pandas) they cost 10-15 % of a
#: worker's speed (``benchmarks/fleet.py``). A worker still reports a blocked loop, and
#: its memory is still watched, only less often.
QUIET_WORKERS = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}


class FleetError(DischargelabError):
    """The cluster cannot be started or reached, or it lost every worker."""


class WorkerCrash(DischargelabError):
    """A task's worker process died twice while running it (the task kills workers)."""


class Executor(Protocol):
    """What the logbook's ingest and fleet analysis need from an executor."""

    workers: int
    shares_files: bool

    def map_unordered(self, func: Callable[[Any], Any], items: Iterable[Any],
                      per_task: int = 1) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, result or exception)`` for every item, in completion order;
        ``per_task`` items may share one task."""
        ...

    def describe(self) -> str:
        """Where the tasks run, for progress lines."""
        ...

    def close(self) -> None:
        ...


class InProcessExecutor:
    """Runs every task in this process, one after the other (no Dask import).

    Parameters
    ----------
    max_in_flight : int
        Kept for the interface; in process one item is in flight at a time.
    """

    workers = 1
    shares_files = True

    def __init__(self, max_in_flight: int = DEFAULT_MAX_IN_FLIGHT):
        if max_in_flight < 1:
            raise FleetError("max_in_flight must be at least 1")
        self.max_in_flight = int(max_in_flight)

    def map_unordered(self, func: Callable[[Any], Any], items: Iterable[Any],
                      per_task: int = 1) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, func(item))``, or ``(item, exception)`` when ``func`` raised one
        (``per_task`` is for the interface: here every item is its own call)."""
        for item in items:
            yield item, _outcome(func, item)

    def describe(self) -> str:
        return "in this process"

    def close(self) -> None:
        return None

    def __enter__(self) -> InProcessExecutor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class DaskExecutor:
    """Run tasks on a ``dask.distributed`` cluster.

    Parameters
    ----------
    workers : int, optional
        Start a ``LocalCluster`` of this many worker processes (one thread each) on
        127.0.0.1; it is ended by :meth:`close`.
    scheduler : str, optional
        Address of an existing scheduler (``tcp://host:port``) instead. Its
        ``distributed.scheduler.allowed-failures`` decides how often a task whose
        worker dies is retried; start it with
        ``DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES=1`` and
        ``DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION=1.0`` to fail a task at its
        second worker death, and only that task, as a local cluster does.
    max_in_flight : int, optional
        Tasks submitted and not yet collected [default: :data:`IN_FLIGHT_PER_WORKER`
        per worker].
    """

    def __init__(self, workers: int | None = None, scheduler: str | None = None,
                 max_in_flight: int | None = None):
        if (workers is None) == (scheduler is None):
            raise FleetError("give either workers (a local cluster) or scheduler (an "
                             "existing one)")
        require("distributed", "dask")
        import dask
        from distributed import Client, LocalCluster

        self.cluster = None
        self._worker_start_setting = None
        try:
            if scheduler is None:
                # a nanny reads the start method again each time it restarts a worker that
                # died: it stays set while the cluster runs (else a restarted worker is
                # spawned, importing everything again, instead of forked from the server)
                self._worker_start_setting = dask.config.set(
                    {"distributed.worker.multiprocessing-method": _start_method()})
                # one task per worker at a time: a worker that dies takes only the task it
                # was running with it (queued ones would count a death too)
                with dask.config.set({"distributed.scheduler.allowed-failures":
                                      WORKER_DEATHS_ALLOWED,
                                      "distributed.scheduler.worker-saturation": 1.0,
                                      **QUIET_WORKERS}):
                    # no dashboard; the status servers Dask always runs listen on
                    # loopback only, on free ports
                    self.cluster = LocalCluster(
                        n_workers=int(workers), threads_per_worker=1, processes=True,
                        host="127.0.0.1", dashboard_address=None, silence_logs=50,
                        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                        worker_dashboard_address="127.0.0.1:0", preload=list(PRELOAD))
                self.client = Client(self.cluster, timeout=START_TIMEOUT_S)
            else:
                self.client = Client(scheduler, timeout=START_TIMEOUT_S)
                self.client.wait_for_workers(1, timeout=START_TIMEOUT_S)
        except (OSError, TimeoutError) as exc:
            self.close()
            where = f"the scheduler at {scheduler}" if scheduler else "a local cluster"
            raise FleetError(f"cannot start or reach {where} ({_first_line(exc)}); check "
                             "the address and that its workers run") from None
        self.scheduler = scheduler
        self._max_in_flight = max_in_flight

    @property
    def workers(self) -> int:
        """Workers connected now."""
        return len(self.client.scheduler_info(n_workers=-1).get("workers", {}))

    @property
    def max_in_flight(self) -> int:
        """Tasks pending at most: as given, else :data:`IN_FLIGHT_PER_WORKER` per worker
        connected now (a cluster that grows gets more)."""
        return int(self._max_in_flight or IN_FLIGHT_PER_WORKER * max(1, self.workers))

    @property
    def shares_files(self) -> bool:
        """True when the workers see this machine's files (a local cluster)."""
        return self.cluster is not None

    def sees(self, path) -> bool:
        """True when every worker sees ``path`` as a file of the same size as here."""
        size = os.path.getsize(path)
        try:
            sizes = self.client.run(_file_size, os.path.abspath(path))
        except OSError:
            return False
        return bool(sizes) and all(s == size for s in sizes.values())

    def describe(self) -> str:
        where = self.scheduler or "a local cluster on 127.0.0.1"
        return f"{self.workers} Dask worker(s) at {where}"

    def map_unordered(self, func: Callable[[Any], Any], items: Iterable[Any],
                      per_task: int = 1) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, result or exception)`` as tasks finish; at most
        ``max_in_flight`` tasks pending.

        ``per_task`` items go to one task (the per-task cost of the cluster, a few
        milliseconds, is then shared: worth it when an item takes tens of
        milliseconds). When the workers running a task of several items die twice,
        its items are run again one per task, and an item whose own task's worker
        dies twice yields :class:`WorkerCrash`. Stopping the iteration early (or
        Ctrl-C) cancels what is still pending.
        """
        from distributed import as_completed
        from distributed.scheduler import KilledWorker

        source = iter(items)
        alone: deque = deque()      # items of a crashed task, to run one per task
        pending: dict = {}          # future key -> (future, items of the task)
        done = as_completed()

        def submit_next() -> bool:
            group = [alone.popleft()] if alone else list(islice(source, max(1, per_task)))
            if not group:
                return False
            # sealed: Dask's graph parser walks a plain argument's lists and dicts object by
            # object (0.14 s for one pack's figures job of ~25,000 numbers, in this process)
            future = self.client.submit(run_batch, func, Sealed(group), pure=False)
            pending[future.key] = (future, group)
            done.add(future)
            return True

        limit = self.max_in_flight
        try:
            for _ in range(limit):
                if not submit_next():
                    break
            while not done.is_empty():
                future = self._next_finished(done)
                _, group = pending.pop(future.key)
                try:
                    outcomes = future.result()
                except KilledWorker:
                    if len(group) > 1:   # one of them crashes its reader: find which
                        alone.extend(group)
                        outcomes = []
                    else:
                        outcomes = [WorkerCrash(
                            f"{_label(group[0])}: the worker process died twice while working "
                            "on it (it crashes its reader); skipped")]
                except Exception as exc:  # handed to the caller, like InProcessExecutor
                    outcomes = [exc] * len(group)
                future.release()
                yield from zip(group, outcomes)
                while len(pending) < limit and submit_next():
                    pass
        finally:
            if pending:
                self.client.cancel([f for f, _ in pending.values()])
                pending.clear()
            done.clear()

    def _next_finished(self, done):
        """The next finished future of ``done`` (a ``distributed.as_completed``); waits as
        long as tasks run, but :class:`FleetError` once the cluster has had no worker for
        :data:`NO_WORKER_S` seconds (its worker list is asked for once every
        :data:`LOOK_S` of waiting: each look is a call to the scheduler)."""
        last_look = time.monotonic()
        no_worker_since = None
        while not done.has_ready():
            time.sleep(POLL_S)
            now = time.monotonic()
            if now - last_look < LOOK_S:
                continue
            last_look = now
            if self.client.scheduler_info().get("workers"):
                no_worker_since = None
            elif no_worker_since is None:
                no_worker_since = now
            elif now - no_worker_since > NO_WORKER_S:
                where = self.scheduler or "the local cluster"
                raise FleetError(f"{where} has had no worker for {NO_WORKER_S:.0f} s (every "
                                 "worker died or left and none came back); what finished is "
                                 "kept: run again, with fewer workers or without a cluster")
        return next(done)

    def close(self) -> None:
        client = getattr(self, "client", None)
        if client is not None:
            client.close()
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None
        if self._worker_start_setting is not None:
            self._worker_start_setting.__exit__(None, None, None)
            self._worker_start_setting = None

    def __enter__(self) -> DaskExecutor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class StartingExecutor:
    """A :class:`DaskExecutor` started in a thread: the caller goes on (opens its database,
    lists and hashes its files) while the cluster comes up, and the first tasks run here,
    in this process, until it is up (a core is otherwise idle then).

    A local cluster's fork server is started at once, before Dask is imported here, so
    that its imports (the readers, pandas, scipy) run on the other core while this process
    imports Dask and hashes its files.

    Parameters
    ----------
    on_ready : callable, optional
        Called with the executor once it is up (from the starting thread).
    **options
        As :class:`DaskExecutor`.
    """

    def __init__(self, on_ready: Callable[[DaskExecutor], None] | None = None, **options):
        self._ready = threading.Event()
        self._executor: DaskExecutor | None = None
        self._error: BaseException | None = None
        self._local = options.get("workers") is not None
        #: Items run here while the cluster came up (for progress lines and tests).
        self.ran_here = 0
        if self._local:
            start_fork_server()

        def start() -> None:
            try:
                self._executor = DaskExecutor(**options)
                if on_ready is not None:
                    on_ready(self._executor)
            except BaseException as exc:  # raised again at the first use, in the caller
                self._error = exc
            finally:
                self._ready.set()

        self._thread = threading.Thread(target=start, name="dischargelab-cluster-start",
                                        daemon=True)
        self._thread.start()

    def ready(self) -> DaskExecutor:
        """The executor once it is up (waits at most :data:`START_TIMEOUT_S` more than Dask
        itself allows); raises what the start raised."""
        if not self._ready.wait(timeout=2 * START_TIMEOUT_S):
            raise FleetError(f"the Dask cluster did not start within {2 * START_TIMEOUT_S:.0f} s")
        if self._error is not None:
            raise self._error
        assert self._executor is not None
        return self._executor

    @property
    def is_ready(self) -> bool:
        """True once the start has ended (up, or failed: :meth:`ready` then raises)."""
        return self._ready.is_set()

    @property
    def workers(self) -> int:
        return self.ready().workers

    @property
    def max_in_flight(self) -> int:
        return self.ready().max_in_flight

    @property
    def shares_files(self) -> bool:
        """A local cluster's workers see this machine's files (known before it is up)."""
        return True if self._local else self.ready().shares_files

    def sees(self, path) -> bool:
        return True if self._local else self.ready().sees(path)

    def describe(self) -> str:
        return self.ready().describe()

    def map_unordered(self, func: Callable[[Any], Any], items: Iterable[Any],
                      per_task: int = 1) -> Iterator[tuple[Any, Any]]:
        """As :meth:`DaskExecutor.map_unordered`; while the cluster is still coming up, the
        next item runs here instead (one at a time, as :class:`InProcessExecutor`), and
        once it is up every item left goes to it. Each item runs once, either here or there,
        and its outcome is the same."""
        source = iter(items)
        while not self._ready.is_set():
            item = next(source, _END)
            if item is _END:
                return
            self.ran_here += 1
            yield item, _outcome(func, item)
        yield from self.ready().map_unordered(func, source, per_task=per_task)

    def close(self) -> None:
        self._ready.wait(timeout=2 * START_TIMEOUT_S)
        if self._executor is not None:
            self._executor.close()

    def __enter__(self) -> StartingExecutor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


#: End of an iterator (a value no item can be).
_END = object()


def _outcome(func: Callable[[Any], Any], item: Any) -> Any:
    """``func(item)``, or the exception it raised (handed to the caller, which re-raises
    what is a bug)."""
    try:
        return func(item)
    except Exception as exc:
        return exc


def executor(workers: int | None = None, scheduler: str | None = None,
             background: bool = False, on_ready=None):
    """The executor the arguments ask for.

    ``scheduler`` (or the ``DISCHARGELAB_SCHEDULER`` environment variable) uses that
    cluster; ``workers`` > 1 starts a local cluster; otherwise the tasks run in this
    process and Dask is not imported. ``background=True`` returns a Dask executor at once
    and starts it in a thread (:class:`StartingExecutor`, ``on_ready`` called when up).
    """
    scheduler = scheduler or os.environ.get(SCHEDULER_ENV) or None
    if scheduler and workers not in (None, 1):
        raise FleetError("give either workers or a scheduler address, not both")
    if workers is not None and workers < 1:
        raise FleetError(f"workers must be 1 or more, got {workers}")
    if not scheduler and not (workers and workers > 1):
        return InProcessExecutor()
    options = {"scheduler": scheduler} if scheduler else {"workers": workers}
    if background:
        return StartingExecutor(on_ready=on_ready, **options)
    return DaskExecutor(**options)


def _start_method() -> str:
    """How a local cluster starts its worker processes: ``"forkserver"`` with the workers'
    modules (:data:`PRELOAD`) imported once, in the fork server, where the platform has one;
    else ``"spawn"`` (Dask's default), where every worker imports them itself.

    Forked from a server that holds the modules, a worker is up in a fraction of a second
    and ends without unwinding its interpreter; two spawned workers import pandas, scipy and
    the readers twice (about 3 s of CPU each) and take about 1 s to end. The preload list is
    given to the fork server before Dask names its own (Dask's would import every optional
    package it knows into this process). Where Dask has no such flag (a version that starts
    its fork server differently), the workers are spawned.
    """
    from distributed import utils as dask_utils

    if not hasattr(dask_utils, "_forkserver_preload_set") or not start_fork_server():
        return "spawn"
    dask_utils._forkserver_preload_set = True
    return "forkserver"


def start_fork_server() -> bool:
    """Start this process's multiprocessing fork server, importing ``distributed`` and
    :data:`PRELOAD` as it starts, unless it runs already; False where the platform has none
    or Dask is not installed, or it cannot be started (the workers are then spawned).

    It returns at once (the server imports in a process of its own, about 3 s of one core),
    and needs no Dask import here: a local cluster calls it before its own imports, so
    that the two overlap. The server ends with this process.
    """
    import importlib.util
    import multiprocessing

    if ("forkserver" not in multiprocessing.get_all_start_methods()
            or importlib.util.find_spec("distributed") is None):
        return False
    from multiprocessing import forkserver

    if not _FORK_SERVER["preload_set"]:
        multiprocessing.get_context("forkserver").set_forkserver_preload(
            ["distributed", *PRELOAD])
        _FORK_SERVER["preload_set"] = True
    try:
        forkserver.ensure_running()
    except OSError:     # no socket or process to spare: Dask's spawned workers still work
        return False
    return True


#: Whether this process gave the fork server its preload list (once: a running server
#: keeps the list it started with).
_FORK_SERVER = {"preload_set": False}


class Sealed:
    """An argument handed to a Dask task as one opaque object: pickled whole, never walked
    by the graph parser (which looks into every list, tuple and dict it gets for task
    references, at a cost per contained object in the client)."""

    __slots__ = ("value",)

    def __init__(self, value: Any):
        self.value = value


def run_batch(func: Callable[[Any], Any], items: Sealed) -> list:
    """``func`` over sealed ``items`` on a worker: each result, or the exception it raised."""
    return [_outcome(func, item) for item in items.value]


def _file_size(path: str) -> int:
    """Size of ``path`` on a worker, -1 when it does not see it (runs on the workers)."""
    return os.path.getsize(path) if os.path.isfile(path) else -1


def _label(item) -> str:
    name = getattr(item, "name", None) or (item[0] if isinstance(item, tuple) else item)
    return os.path.basename(str(name))


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
