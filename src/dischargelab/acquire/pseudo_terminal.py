"""Pseudo-terminals for the virtual devices (POSIX only)."""

from __future__ import annotations

import os
import tty


def open_raw_pty() -> tuple[int, int, str]:
    """Open a pseudo-terminal in raw mode with a non-blocking master.

    Raw mode: no echo and no line discipline before the host opens the slave.
    Non-blocking master: a full pty buffer drops bytes instead of stalling the
    device (as a real USB-serial device would lose them).

    Returns (master fd, slave fd, slave path).
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


def close_fds(*fds) -> None:
    """Close file descriptors, ignoring None and ones already closed."""
    for fd in fds:
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass
