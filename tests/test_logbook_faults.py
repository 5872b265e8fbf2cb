"""The logbook when its storage fails: a full disk, a read-only file, a PostgreSQL server
stopped in the middle of an add, two writers on the same files.

Each fault must give one line that names the problem and the fix, a non-zero exit,
whole batches (a file's source and events together or not at all), nothing stored before
touched, and a rerun that completes with each file once. The faults are real: SQLite's
own SQLITE_FULL (a page limit, and as root a small tmpfs), a read-only mount (as root) or
file mode, a throwaway PostgreSQL server stopped with ``pg_ctl stop -m fast``.
"""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import threading
import time
from contextlib import closing
from pathlib import Path

import pytest

from pg_cluster import _pid_alive, start_server, stop_server

pytest.importorskip("sqlalchemy")

from dischargelab.errors import LogbookStorageError
from dischargelab.logbook import Logbook, schema
from dischargelab.logbook.ingest import AddResult, write_summaries
from dischargelab.logbook.summarise import summarise_source

CELL_C = "samsung30q_ageing_cellC"
#: Seconds a CLI run may take here (70 files in process on a busy 2-core machine).
CLI_TIMEOUT_S = 600


def cell_c(shared_data: Path) -> list[Path]:
    return sorted((shared_data / CELL_C).glob("DischargeCycle*.txt"))


def cli(*args, timeout: float = CLI_TIMEOUT_S) -> subprocess.CompletedProcess:
    """``dischargelab ARGS`` as a user runs it (its own process)."""
    return subprocess.run([sys.executable, "-c", "from dischargelab.cli import main; main()",
                           *map(str, args)], capture_output=True, text=True, timeout=timeout)


def one_error_line(stderr: str) -> str:
    """The error line of a failed command: exactly one, no traceback."""
    lines = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in stderr and "bug" not in stderr, stderr
    return lines[0]


def sqlite_contents(path: Path) -> dict:
    """What a SQLite logbook holds per source: its events (whole-batch check) and values."""
    with closing(sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)) as db:
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        rows = db.execute("SELECT s.sha256, s.file_name, count(e.id), "
                          "sum(e.\"discharged_Ah\") FROM sources s LEFT JOIN events e "
                          "ON e.source_id = s.id GROUP BY s.id").fetchall()
    return {sha: (name, n, q) for sha, name, n, q in rows}


def page_count(path: Path) -> int:
    with closing(sqlite3.connect(path)) as db:
        return db.execute("PRAGMA page_count").fetchone()[0]


def check_whole(contents: dict, files: list[Path]) -> None:
    """Every stored file has its one event (cell C files hold one discharge each)."""
    names = sorted(name for name, _, _ in contents.values())
    assert len(names) == len(set(names)), "a file stored twice"
    assert set(names) <= {f.name for f in files}
    assert all(n == 1 for _, n, _ in contents.values()), "a source without its event"


# --------------------------------------------------------------------------- full disk

def test_a_full_database_stops_the_add_with_one_line_and_a_rerun_completes(
        shared_data, tmp_path, monkeypatch):
    """SQLite's own SQLITE_FULL (``PRAGMA max_page_count`` on every connection): the batch
    that does not fit is not written, the ones before are kept, a rerun with room adds the
    rest, each file once."""
    files = cell_c(shared_data)
    db = tmp_path / "lb.sqlite"
    with Logbook(db) as lb:
        lb.add(files[:1], pack="C")
        empty = page_count(db)
        lb.add(files[1:3], pack="C")
    before = sqlite_contents(db)
    pages = page_count(db)
    per_file = (pages - empty) / 2
    limited = schema._sqlite_pragmas

    def pragmas(dbapi_connection, record):
        limited(dbapi_connection, record)
        # room for the first batch of 25 files, not for the second
        dbapi_connection.execute(f"PRAGMA max_page_count={int(pages + 35 * per_file)}")

    monkeypatch.setattr(schema, "_sqlite_pragmas", pragmas)
    with Logbook(db) as lb:
        with pytest.raises(LogbookStorageError) as err:
            lb.add(files, pack="C")
    message = str(err.value)
    assert err.value.reason == "full" and "\n" not in message
    assert message.startswith(f"no space left on the device holding the logbook {db} (")
    assert "free space there or move the logbook" in message and "--db" in message
    after = sqlite_contents(db)
    check_whole(after, files)
    assert {k: v for k, v in after.items() if k in before} == before   # untouched
    assert 3 < len(after) < len(files)                  # some batches went in, not all
    monkeypatch.setattr(schema, "_sqlite_pragmas", limited)
    with Logbook(db) as lb:
        result = lb.add(files, pack="C")
        assert len(result.added) == len(files) - len(after)
        assert len(result.skipped) == len(after)
        assert lb.stale() == []
    final = sqlite_contents(db)
    check_whole(final, files)
    assert len(final) == len(files)


def root_only():
    return pytest.mark.skipif(os.geteuid() != 0 or not sys.platform.startswith("linux"),
                              reason="mounting a small file system needs root on Linux")


def mount_tmpfs(path: Path, size: str) -> None:
    path.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                          capture_output=True, text=True, timeout=30)
    if done.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")


def remount(path: Path, options: str) -> None:
    subprocess.run(["mount", "-o", f"remount,{options}", str(path)], check=True, timeout=30)


def unmount(path: Path) -> None:
    subprocess.run(["umount", str(path)], check=True, timeout=30)


@root_only()
@pytest.mark.slow
def test_a_real_full_disk_is_one_line_and_a_rerun_with_room_completes(shared_data, tmp_path):
    """The whole command on a 3 MB file system: exit 2, one line naming the device and the
    fix; after the file system grows, the same command adds the rest."""
    files = cell_c(shared_data)
    mnt = tmp_path / "small"
    mount_tmpfs(mnt, "3m")
    try:
        db = mnt / "lb.sqlite"
        done = cli("logbook", "add", shared_data / CELL_C, "--pack", "C", "--db", db)
        assert done.returncode == 2, done.stderr
        line = one_error_line(done.stderr)
        assert f"no space left on the device holding the logbook {db}" in line
        assert "free space there or move the logbook" in line
        stored = sqlite_contents(db)
        check_whole(stored, files)
        assert 0 < len(stored) < len(files)
        remount(mnt, "size=64m")
        done = cli("logbook", "add", shared_data / CELL_C, "--pack", "C", "--db", db)
        assert done.returncode == 0, done.stderr
        assert f"added {len(files) - len(stored)} file(s)" in done.stdout
        final = sqlite_contents(db)
        check_whole(final, files)
        assert len(final) == len(files)
        assert {k: v for k, v in final.items() if k in stored} == stored
    finally:
        unmount(mnt)


# --------------------------------------------------------------------------- read-only

def test_a_read_only_logbook_is_read_and_refuses_writes_with_one_line(shared_data, tmp_path):
    """A logbook this process may not write (as root: a read-only mount; otherwise its file
    and folder without write permission): the reading commands answer (its stale figures
    computed in memory), adding is refused with one line and the file is left as it was."""
    files = cell_c(shared_data)
    root = os.geteuid() == 0
    folder = tmp_path / "ro"
    if root:
        mount_tmpfs(folder, "16m")
    else:
        folder.mkdir()
    db = folder / "lb.sqlite"
    try:
        with Logbook(db) as lb:
            lb.add(files[:4], pack="C", refresh=False)       # left stale on purpose
        before = db.read_bytes()
        if root:
            remount(folder, "ro")
        else:
            db.chmod(0o444)
            folder.chmod(0o555)
        done = cli("logbook", "add", *files[4:6], "--pack", "C", "--db", db)
        assert done.returncode == 2, done.stderr
        line = one_error_line(done.stderr)
        assert f"the logbook {db} is read-only" in line and "nothing was changed" in line
        done = cli("logbook", "packs", "--json", "--db", db)
        assert done.returncode == 0, done.stderr
        assert '"events": 4' in done.stdout
        with Logbook(db, create=False) as lb:
            assert lb.stale() == ["C"]                      # read, never written
            assert lb.health("C").efc_now > 0
        assert db.read_bytes() == before
    finally:
        if root:
            unmount(folder)
        else:
            folder.chmod(0o755)


def test_a_sqlite_logbook_removed_while_open_takes_no_more_writes(shared_data, tmp_path):
    """The SQLite file is removed (a user, a sync tool) while a logbook is open: SQLite in
    WAL mode would go on writing to the removed file and lose everything; the next write is
    refused with one line instead."""
    files = cell_c(shared_data)[:3]
    db = tmp_path / "lb.sqlite"
    with Logbook(db) as lb:
        lb.add(files[:1], pack="C", refresh=False)
        for suffix in ("", "-wal", "-shm"):
            Path(f"{db}{suffix}").unlink(missing_ok=True)
        with pytest.raises(LogbookStorageError, match=r"was removed or replaced while it was "
                                                      r"open: nothing more was written") as err:
            lb.add(files[1:], pack="C")
        assert err.value.reason == "unreachable"
    assert not db.exists()


# --------------------------------------------------------------------------- PostgreSQL

def pg_contents(url: str) -> dict:
    from sqlalchemy import create_engine, text

    engine = create_engine(url)
    with engine.connect() as conn:
        rows = conn.execute(text(
            "SELECT s.sha256, s.file_name, count(e.id), sum(e.\"discharged_Ah\") FROM sources s "
            "LEFT JOIN events e ON e.source_id = s.id GROUP BY s.id")).all()
    engine.dispose()
    return {sha: (name, n, q) for sha, name, n, q in rows}


@pytest.mark.slow
def test_postgresql_stopped_mid_add_is_one_line_and_a_rerun_completes(pg, shared_data):
    files = cell_c(shared_data)
    url = pg.new_database()
    with Logbook(url) as lb:
        lb.add(files[:2], pack="C")
    before = pg_contents(url)
    proc = subprocess.Popen([sys.executable, "-c", "from dischargelab.cli import main; main()",
                             "logbook", "add", str(shared_data / CELL_C), "--pack", "C",
                             "--db", url], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        deadline = time.monotonic() + CLI_TIMEOUT_S
        while len(pg_contents(url)) <= len(before):       # the first batch is in
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the add wrote nothing"
            time.sleep(0.2)
        stop_server(pg)
        out, err = proc.communicate(timeout=CLI_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if not _pid_alive(pg.pid):
            start_server(pg)
    assert proc.returncode == 2, err
    line = one_error_line(err)
    assert "cannot reach the logbook database" in line and "run the command again" in line
    stored = pg_contents(url)
    check_whole(stored, files)
    assert {k: v for k, v in stored.items() if k in before} == before
    assert len(before) < len(stored) < len(files)
    done = cli("logbook", "add", shared_data / CELL_C, "--pack", "C", "--db", url)
    assert done.returncode == 0, done.stderr
    final = pg_contents(url)
    check_whole(final, files)
    assert len(final) == len(files)


def together(target, n: int = 2, timeout_s: float = 120) -> None:
    """``target(k)`` for k = 0..n-1 in threads of their own, waited for (bounded)."""
    threads = [threading.Thread(target=target, args=(k,)) for k in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=timeout_s)
        assert not t.is_alive(), "a writer is still running"


def test_two_writers_with_overlapping_files_in_opposite_orders_store_each_once(
        pg, shared_data):
    """Two clients write the same 24 files at the same moment, one in the reverse order of
    the other, each in one transaction: the batch goes in SHA-256 order, so one waits for
    the other instead of deadlocking; each file is stored once."""
    summaries = [summarise_source(p) for p in cell_c(shared_data)[:24]]
    url = pg.new_database()
    with Logbook(url) as lb:
        lb.set_pack("shared", refresh=False)   # so the writers meet on the files, not the pack
    engine = schema.create(url)
    start = threading.Barrier(2, timeout=60)
    results, errors = [AddResult(), AddResult()], []

    def writer(k: int) -> None:
        batch = [(s, "shared", None) for s in (summaries if k == 0 else summaries[::-1])]
        try:
            start.wait()
            write_summaries(engine, batch, results[k])
        except Exception as exc:  # reported below with the other writer's outcome
            errors.append(exc)

    together(writer)
    engine.dispose()
    assert not errors, errors
    added = results[0].added + results[1].added
    assert sorted(added) == sorted(s.file_name for s in summaries)
    assert sorted(results[0].skipped + results[1].skipped) == sorted(added)
    stored = pg_contents(url)
    assert len(stored) == len(summaries) and all(n == 1 for _, n, _ in stored.values())


@pytest.mark.parametrize("fault", ["deadlock", "serialization"])
def test_a_transaction_postgresql_aborts_is_run_again(pg, fault):
    """A real deadlock (two transactions updating two rows in opposite orders) and a real
    serialization failure (two SERIALIZABLE read-modify-writes of one row): the one the
    server aborts is run again by :func:`schema.write`, so both writes land."""
    from sqlalchemy import text

    url = pg.new_database()
    with Logbook(url) as lb:
        lb.set_pack("a", refresh=False)
        lb.set_pack("b", refresh=False)
    engine = schema.create(url)
    met = threading.Barrier(2, timeout=60)
    tries = [0, 0]
    errors = []

    def work(k: int, conn) -> None:
        tries[k] += 1
        if fault == "serialization":
            conn.execute(text("SET TRANSACTION ISOLATION LEVEL SERIALIZABLE"))
            version = conn.execute(text("SELECT version FROM packs WHERE name = 'a'")).scalar()
            if tries[k] == 1:
                met.wait()               # both have read before either writes
            conn.execute(text("UPDATE packs SET version = :v WHERE name = 'a'"),
                         {"v": version + 1})
        else:
            first, second = ("a", "b") if k == 0 else ("b", "a")
            conn.execute(text(f"UPDATE packs SET version = version + 1 WHERE name = '{first}'"))
            if tries[k] == 1:
                met.wait()               # each holds one row and asks for the other's
            conn.execute(text(f"UPDATE packs SET version = version + 1 WHERE name = '{second}'"))

    def run(k: int) -> None:
        try:
            schema.write(engine, lambda conn: work(k, conn))
        except Exception as exc:  # reported below
            errors.append(exc)

    together(run)
    with engine.connect() as conn:
        versions = dict(conn.execute(text("SELECT name, version FROM packs")).all())
    engine.dispose()
    assert not errors, errors
    assert sorted(tries) == [1, 2]               # one ran once, the aborted one again
    if fault == "serialization":
        assert versions["a"] == 2
    else:
        assert versions == {"a": 2, "b": 2}
