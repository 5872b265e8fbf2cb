"""Independent fits run side by side: the held-out folds of :mod:`dischargelab.fit.heldout`
in worker processes, one per core.

Each fold is computed exactly as in one process (same inputs, same order of results), so
the results do not depend on the number of workers. Workers are forked, which keeps the
loaded modules and costs a few milliseconds; they are used only where forking is safe
and worth it: a POSIX system with ``fork``, two or more usable cores, and no other thread
in the process (a server or a Dask worker fits in one process). ``DISCHARGELAB_WORKERS``
caps the number of workers (``1``: everything in this process).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import contextmanager
from contextvars import ContextVar

_POOL: ContextVar[ProcessPoolExecutor | None] = ContextVar("fold_workers", default=None)


def usable_workers() -> int:
    """How many worker processes :func:`fold_workers` starts (1: none)."""
    if "fork" not in multiprocessing.get_all_start_methods():
        return 1
    if threading.active_count() > 1 or multiprocessing.parent_process() is not None:
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    cap = os.environ.get("DISCHARGELAB_WORKERS", "").strip()
    limit = int(cap) if cap.isdigit() and int(cap) > 0 else cores or 1
    return max(1, min(cores or 1, limit))


def _ignore_interrupt() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle


@contextmanager
def fold_workers():
    """Worker processes for :func:`submit` inside the ``with`` block (none when
    :func:`usable_workers` is 1; an active pool is reused). They are forked at once,
    while this is the only thread (a caller may start a progress display after)."""
    workers = usable_workers()
    if _POOL.get() is not None or workers < 2:
        yield
        return
    pool = ProcessPoolExecutor(max_workers=workers,
                               mp_context=multiprocessing.get_context("fork"),
                               initializer=_ignore_interrupt)
    pool.submit(int).result()  # forks every worker now (the fork start method)
    token = _POOL.set(pool)
    try:
        yield
    finally:
        _POOL.reset(token)
        pool.shutdown(wait=True, cancel_futures=True)


def submit(func, *args) -> Future:
    """``func(*args)`` in a worker when :func:`fold_workers` is active (its exceptions
    reach :meth:`Future.result`), else here and now (a finished future)."""
    pool = _POOL.get()
    if pool is not None:
        return pool.submit(func, *args)
    done: Future = Future()
    done.set_result(func(*args))
    return done
