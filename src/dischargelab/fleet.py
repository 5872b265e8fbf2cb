"""Where the work of many files runs: one executor interface.

An executor maps a pure function over items and yields ``(item, outcome)`` as each
finishes, in any order; ``outcome`` is the function's result or the exception it
raised (the caller decides which exceptions are rejections and which are bugs).
At most ``max_in_flight`` items are submitted and not yet collected, so a big
folder never floods memory or a scheduler. Tasks are pure functions of their item
(file -> small summary): they never open the logbook database, and their results
are small and serialisable (Dask best practices: bounded submission, small results,
no globals).

Only :class:`InProcessExecutor` lives here; a ``dask.distributed`` executor
(LocalCluster or a scheduler address) implements the same method.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any, Protocol

#: Items submitted and not yet collected, by default.
DEFAULT_MAX_IN_FLIGHT = 64


class Executor(Protocol):
    """What the logbook's ingest needs from an executor."""

    def map_unordered(self, func: Callable[[Any], Any], items: Iterable[Any]
                      ) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, result or exception)`` for every item, in completion order."""
        ...


class InProcessExecutor:
    """Runs every task in this process, one after the other (no parallelism).

    Parameters
    ----------
    max_in_flight : int
        Kept for the interface; in process one item is in flight at a time.
    """

    def __init__(self, max_in_flight: int = DEFAULT_MAX_IN_FLIGHT):
        if max_in_flight < 1:
            raise ValueError("max_in_flight must be at least 1")
        self.max_in_flight = int(max_in_flight)

    def map_unordered(self, func: Callable[[Any], Any], items: Iterable[Any]
                      ) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, func(item))``, or ``(item, exception)`` when ``func`` raised one."""
        for item in items:
            try:
                outcome = func(item)
            except Exception as exc:  # handed to the caller, which re-raises what is a bug
                outcome = exc
            yield item, outcome

    def __repr__(self) -> str:
        return "InProcessExecutor()"


__all__ = ["Executor", "InProcessExecutor", "DEFAULT_MAX_IN_FLIGHT"]
