"""Blocking work off the event loop, in two bounded thread pools: reads and heavy work.

The event loop only moves bytes (requests, static files, the live stream). Everything that
reads the logbook or computes runs in a thread: the pack list and pack pages in the *read*
pool, uploads, refits and missions in the *work* pool. The pools are separate, so a refit
or an upload being parsed never holds a page, and each is bounded
(:attr:`Limits.read_threads`, :attr:`Limits.work_threads`): requests beyond them wait on
the event loop, where waiting costs nothing. A request whose client has gone while it
waited is dropped before its work starts. Heavy work has a bounded queue
(:attr:`Limits.max_waiting_work`; 503 beyond it).
"""

from __future__ import annotations

import asyncio
import functools
from concurrent.futures import ThreadPoolExecutor

from .guard import RequestRefused
from .limits import Limits


class ClientGone(Exception):
    """The client disconnected while its request waited for a thread."""


class Workers:
    """The read pool and the work pool of one server.

    Parameters
    ----------
    limits : Limits
    """

    def __init__(self, limits: Limits):
        self.limits = limits
        self._read_pool = ThreadPoolExecutor(limits.read_threads,
                                             thread_name_prefix="dischargelab-read")
        self._work_pool = ThreadPoolExecutor(limits.work_threads,
                                             thread_name_prefix="dischargelab-work")
        self._reads = asyncio.Semaphore(limits.read_threads)
        self._works = asyncio.Semaphore(limits.work_threads)
        #: Heavy requests waiting for a work thread now.
        self.waiting_work = 0

    async def read(self, request, func, *args):
        """``func(*args)`` in the read pool, once a read thread is free."""
        async with self._reads:
            return await self._run(request, self._read_pool, func, args)

    async def work(self, request, func, *args, what: str = "refits and missions"):
        """``func(*args)`` in the work pool; 503 when too many already wait for it."""
        if self._works.locked() and self.waiting_work >= self.limits.max_waiting_work:
            raise RequestRefused(503, f"the server is busy with {what} ("
                                      f"{self.waiting_work} waiting); try again in a minute")
        self.waiting_work += 1
        try:
            await self._works.acquire()
        finally:
            self.waiting_work -= 1
        try:
            return await self._run(request, self._work_pool, func, args)
        finally:
            self._works.release()

    @staticmethod
    async def _run(request, pool, func, args):
        if request is not None and await request.is_disconnected():
            raise ClientGone()
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(pool, functools.partial(func, *args))

    def close(self) -> None:
        """End the threads (work not started yet is dropped)."""
        self._read_pool.shutdown(wait=False, cancel_futures=True)
        self._work_pool.shutdown(wait=False, cancel_futures=True)
