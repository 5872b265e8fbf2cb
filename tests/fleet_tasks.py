"""Tasks for the executor tests; importable by Dask worker processes (tests/ on their path)."""

import os
import time

from dischargelab.errors import DataError


def square_slowly(n: int) -> dict:
    """A small pure task: ``{"n": n, "square": n * n, "pid": ...}`` after a short wait."""
    time.sleep(0.05)
    return {"n": n, "square": n * n, "pid": os.getpid()}


def refuse_odd(n: int) -> int:
    """Raises a library error for odd numbers (a bad file), returns even ones."""
    if n % 2:
        raise DataError(f"item {n} is odd")
    return n


def crash_on_seven(n: int) -> int:
    """Kills its worker process on 7 (a file that crashes its reader)."""
    if n == 7:
        os._exit(3)
    time.sleep(0.02)
    return n


def crash_on_file(task, file_name: str, item):
    """Run ``task(item)``, but kill the worker process when ``item`` is ``file_name``
    (a file that crashes its reader)."""
    name = item[0] if isinstance(item, tuple) else item
    if os.path.basename(str(name)) == file_name:
        os._exit(3)
    return task(item)


def square_unless_refused(n: int) -> dict:
    """:func:`square_slowly`, but items 1 and 13 are refused (a bad file) with a library
    error."""
    if n in (1, 13):
        raise DataError(f"item {n} is refused")
    return square_slowly(n)


def parent_pid(n: int) -> int:
    """The process id of the task's process's parent."""
    return os.getppid()
