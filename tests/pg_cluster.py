"""A throwaway PostgreSQL cluster for tests: initdb + pg_ctl on 127.0.0.1, a free port.

The server runs as the ``postgres`` user when the tests run as root (PostgreSQL
refuses to run as root), from a fresh data folder that is removed afterwards. Its
process id is read from ``postmaster.pid`` and checked to be gone after the stop.
Without the server binaries the tests that need it are skipped, except in CI (the
``CI`` environment variable set), where that is a failure.
"""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import pytest

#: Seconds allowed for the server to start or stop.
TIMEOUT_S = 60


def server_binaries() -> Path | None:
    """Folder of Debian's PostgreSQL server binaries (newest version), or None."""
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"),
                   key=lambda p: int(Path(p).parts[-3]) if Path(p).parts[-3].isdigit() else 0)
    return Path(found[-1]).parent if found else None


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _as_postgres(args: list[str]) -> list[str]:
    if os.geteuid() != 0:
        return args
    return ["runuser", "-u", "postgres", "--", *args]


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class Cluster:
    """A running throwaway cluster; ``url(db)`` gives a SQLAlchemy URL."""

    def __init__(self, root: Path, port: int, pid: int, bin_dir: Path):
        self.root, self.port, self.pid, self.bin_dir = root, port, pid, bin_dir
        self._count = 0

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{database}"

    def new_database(self) -> str:
        """A fresh, empty database; returns its URL."""
        import psycopg

        self._count += 1
        name = f"logbook_test_{self._count}"
        with psycopg.connect(f"host=127.0.0.1 port={self.port} user=postgres dbname=postgres",
                             autocommit=True) as conn:
            conn.execute(f"DROP DATABASE IF EXISTS {name}")
            conn.execute(f"CREATE DATABASE {name}")
        return self.url(name)


def start_cluster() -> Cluster:
    """Start a cluster (see the module docstring); skip or fail when it cannot run."""
    bin_dir = server_binaries()
    if bin_dir is None:
        message = ("PostgreSQL server binaries not found (/usr/lib/postgresql/*/bin); "
                   "install Debian's postgresql package (make postgres)")
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    pytest.importorskip("psycopg") if not os.environ.get("CI") else __import__("psycopg")
    root = Path(tempfile.mkdtemp(prefix="dischargelab-pg-"))
    os.chmod(root, 0o755)
    data, sockets = root / "data", root / "sockets"
    data.mkdir()
    sockets.mkdir()
    if os.geteuid() == 0:
        shutil.chown(data, "postgres", "postgres")
        shutil.chown(sockets, "postgres", "postgres")
        shutil.chown(root, "postgres", "postgres")
    port = _free_port()
    run = dict(check=True, capture_output=True, text=True, timeout=TIMEOUT_S)
    subprocess.run(_as_postgres([str(bin_dir / "initdb"), "-D", str(data), "-U", "postgres",
                                 "-A", "trust", "-E", "UTF8", "--no-sync"]), **run)
    cluster = Cluster(root, port, 0, bin_dir)
    start_server(cluster)
    return cluster


def start_server(cluster: Cluster) -> None:
    """Start the cluster's server (again, after :func:`stop_server`) on its port."""
    data, sockets = cluster.root / "data", cluster.root / "sockets"
    options = (f"-c listen_addresses=127.0.0.1 -p {cluster.port} -k {sockets} -c fsync=off "
               "-c synchronous_commit=off -c full_page_writes=off")
    subprocess.run(_as_postgres([str(cluster.bin_dir / "pg_ctl"), "-D", str(data), "-o",
                                 options, "-l", str(cluster.root / "server.log"), "-w", "-t",
                                 str(TIMEOUT_S), "start"]),
                   check=True, capture_output=True, text=True, timeout=TIMEOUT_S)
    cluster.pid = int((data / "postmaster.pid").read_text().splitlines()[0])


def stop_server(cluster: Cluster) -> None:
    """Stop the server now (fast shutdown: open transactions are rolled back, clients cut
    off), keep its data, and check its process is gone."""
    subprocess.run(_as_postgres([str(cluster.bin_dir / "pg_ctl"), "-D",
                                 str(cluster.root / "data"), "-m", "fast", "-w", "-t",
                                 str(TIMEOUT_S), "stop"]),
                   check=True, capture_output=True, text=True, timeout=TIMEOUT_S + 10)
    deadline = time.monotonic() + 10
    while _pid_alive(cluster.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _pid_alive(cluster.pid), f"PostgreSQL server {cluster.pid} still running"


def stop_cluster(cluster: Cluster) -> None:
    """Stop the server, check its process is gone, remove its folder."""
    try:
        if _pid_alive(cluster.pid):
            stop_server(cluster)
    finally:
        shutil.rmtree(cluster.root, ignore_errors=True)
