"""The logbook database: tables, schema version, forward migrations, connections.

SQLAlchemy 2 Core, the same code for SQLite (the default: one file, no set-up) and
PostgreSQL (``postgresql+psycopg://user@host/db`` for a team).

Tables (all values SI, discharge positive; ``*_json`` columns hold JSON text)::

    logbook_meta  key, value                     -- "schema_version"
    packs         id, name (unique), label_capacity_Ah, chemistry, cells, created_at,
                  version                         -- raised by every write that changes it
    blobs         sha256 (key), compression, size_bytes, data   -- raw files, zlib
    sources       id, sha256 (unique), pack_id, file_name, path, size_bytes, format,
                  added_at, options_json, notes_json
    events        id, source_id, idx, pack_id, kind, start_time, cycle, duration_s,
                  discharged_Ah, discharged_Wh, mean_current_A, max_current_A,
                  rest_voltage_V, rest_after_V, rest_after_s, min_voltage_V,
                  end_voltage_V, end_current_A, resistance_ohm, resistance_low_ohm,
                  resistance_high_ohm, reaches_knee, cells, samples,
                  temperature_start_C, temperature_max_C, ambient_C, cell_spread_V,
                  curve_json, details_json        -- unique (source_id, idx)
    models        id, pack_id, fitted_at, reference_event_id, capacity_Ah,
                  resistance_ohm, battery_json    -- the pack's fitted battery models
    pack_figures  pack_id (key), pack_version, figures_version, computed_at, row_json,
                  pack_json, fleet_json, health_json, model_json, error  -- see .figures

Versions (``logbook_meta.schema_version``; a database is migrated forward when
opened, a newer one is refused). Each step is an Alembic revision shipped in the
package (``migrations/versions/000N_*.py``, revision id ``000N`` for version N), run
on the opening connection inside its write transaction (on PostgreSQL under an
advisory lock, so concurrent openers migrate once); ``alembic_version`` holds the
revision, ``schema_version`` the same number for older dischargelab releases, which
read only it:

* 1: packs, blobs, sources, events without ``cycle`` and ``cell_spread_V``.
* 2: ``events.cycle`` (cycle number from the file name, for the equivalent full
  cycles between logged ones), ``events.cell_spread_V``, and the ``models`` table.
* 3: ``events.details_json``: the event's further figures (rests and their relaxation,
  charges, per-cell figures, how well the sampling resolves the current), JSON.
* 4: ``packs.version`` and ``pack_figures``: each pack's figures stored with the
  version of the pack they were computed from (:mod:`.figures`).
"""

from __future__ import annotations

import os
import shutil
import sys
from contextlib import closing, contextmanager
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy import (
    BigInteger,
    Boolean,
    Column,
    Float,
    ForeignKey,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Table,
    Text,
    UniqueConstraint,
    create_engine,
    event,
    inspect,
    select,
    text,
)
from sqlalchemy.engine import Engine, make_url
from sqlalchemy.exc import ArgumentError, DBAPIError, NoSuchModuleError

from ..errors import LogbookError, LogbookStorageError

#: Version of the tables this code writes (the newest revision in ``migrations/versions``).
SCHEMA_VERSION = 4

#: Folder of the Alembic environment and revisions (package data).
MIGRATIONS_DIR = Path(__file__).with_name("migrations")

#: File name of the default SQLite logbook in the user's data folder.
DEFAULT_FILE_NAME = "logbook.sqlite"

#: Environment variable naming the logbook (a path or a database URL).
ENV_VARIABLE = "DISCHARGELAB_DB"

#: Seconds a writer waits for another writer to finish (SQLite).
BUSY_TIMEOUT_S = 60.0

metadata = MetaData()

logbook_meta = Table(
    "logbook_meta", metadata,
    Column("key", String(64), primary_key=True),
    Column("value", Text, nullable=False),
)

packs = Table(
    "packs", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("name", String(200), nullable=False, unique=True),
    Column("label_capacity_Ah", Float),
    Column("chemistry", String(20)),
    Column("cells", Integer),
    Column("created_at", String(40), nullable=False),
    Column("version", Integer, nullable=False, server_default="0"),
)

blobs = Table(
    "blobs", metadata,
    Column("sha256", String(64), primary_key=True),
    Column("compression", String(10), nullable=False),
    Column("size_bytes", BigInteger, nullable=False),
    Column("data", LargeBinary, nullable=False),
)

sources = Table(
    "sources", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("sha256", String(64), nullable=False, unique=True),
    Column("pack_id", Integer, ForeignKey("packs.id"), nullable=False),
    Column("file_name", String(500), nullable=False),
    Column("path", Text),
    Column("size_bytes", BigInteger, nullable=False),
    Column("format", String(40), nullable=False),
    Column("added_at", String(40), nullable=False),
    Column("options_json", Text, nullable=False),
    Column("notes_json", Text, nullable=False),
)

EVENT_FLOATS = (
    "duration_s", "discharged_Ah", "discharged_Wh", "mean_current_A", "max_current_A",
    "rest_voltage_V", "rest_after_V", "rest_after_s", "min_voltage_V", "end_voltage_V",
    "end_current_A", "resistance_ohm", "resistance_low_ohm", "resistance_high_ohm",
    "temperature_start_C", "temperature_max_C", "ambient_C", "cell_spread_V",
)

events = Table(
    "events", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("source_id", Integer, ForeignKey("sources.id"), nullable=False),
    Column("idx", Integer, nullable=False),
    Column("pack_id", Integer, ForeignKey("packs.id"), nullable=False),
    Column("kind", String(20), nullable=False),
    Column("start_time", String(40)),
    Column("cycle", Integer),
    *[Column(name, Float) for name in EVENT_FLOATS],
    Column("reaches_knee", Boolean, nullable=False),
    Column("cells", Integer),
    Column("samples", Integer, nullable=False),
    Column("curve_json", Text, nullable=False),
    Column("details_json", Text),
    UniqueConstraint("source_id", "idx", name="uq_events_source_idx"),
)

models = Table(
    "models", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("pack_id", Integer, ForeignKey("packs.id"), nullable=False),
    Column("fitted_at", String(40), nullable=False),
    Column("reference_event_id", Integer, ForeignKey("events.id")),
    Column("capacity_Ah", Float),
    Column("resistance_ohm", Float),
    Column("battery_json", Text, nullable=False),
)

pack_figures = Table(
    "pack_figures", metadata,
    Column("pack_id", Integer, ForeignKey("packs.id"), primary_key=True, autoincrement=False),
    Column("pack_version", Integer, nullable=False),
    Column("figures_version", String(60), nullable=False),
    Column("computed_at", String(40), nullable=False),
    Column("row_json", Text),
    Column("pack_json", Text),
    Column("fleet_json", Text),
    Column("health_json", Text),
    Column("model_json", Text),
    Column("error", Text),
)


def now_iso() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.now(UTC).isoformat(timespec="seconds")


# --------------------------------------------------------------------------- locations

def user_data_dir() -> Path:
    """The user's data folder for dischargelab, by the platform's convention.

    Linux and other Unix: ``$XDG_DATA_HOME/dischargelab`` (default
    ``~/.local/share/dischargelab``, XDG Base Directory Specification); macOS:
    ``~/Library/Application Support/dischargelab``; Windows:
    ``%LOCALAPPDATA%\\dischargelab``.
    """
    home = Path.home()
    if sys.platform.startswith("win"):
        base = Path(os.environ.get("LOCALAPPDATA") or home / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = home / "Library" / "Application Support"
    else:
        base = Path(os.environ.get("XDG_DATA_HOME") or home / ".local" / "share")
    return base / "dischargelab"


def resolve_url(url=None) -> str:
    """The database URL of a logbook location.

    ``None``: ``$DISCHARGELAB_DB`` if set, else ``logbook.sqlite`` in
    :func:`user_data_dir`; a path: a SQLite file there; ``sqlite:///...`` or
    ``postgresql+psycopg://...``: used as given.
    """
    if url is None:
        url = os.environ.get(ENV_VARIABLE) or None
    if url is None:
        return f"sqlite:///{user_data_dir() / DEFAULT_FILE_NAME}"
    text_url = str(url)
    if "://" in text_url:
        return text_url
    return f"sqlite:///{Path(text_url).expanduser().resolve()}"


def shown_url(url: str) -> str:
    """The URL without its password, for messages."""
    try:
        return make_url(url).render_as_string(hide_password=True)
    except ArgumentError:
        return url


# --------------------------------------------------------------------------- engines

def _sqlite_pragmas(dbapi_connection, _record) -> None:
    dbapi_connection.isolation_level = None  # transactions are begun by _sqlite_begin
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute(f"PRAGMA busy_timeout={int(BUSY_TIMEOUT_S * 1000)}")
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.close()


def _sqlite_read_only_pragmas(dbapi_connection, _record) -> None:
    dbapi_connection.isolation_level = None
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute(f"PRAGMA busy_timeout={int(BUSY_TIMEOUT_S * 1000)}")
    cursor.close()


def _read_only_file_system(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):  # AttributeError: no statvfs (Windows)
        return False


def _read_only_flags(path: Path) -> str:
    """SQLite URI flags to read ``path`` without writing: read-only mode, and immutable on a
    read-only file system when no write-ahead log is beside it (with one, the log and its
    shared-memory file are read as they are)."""
    wal = path.with_name(path.name + "-wal")
    frozen = _read_only_file_system(path.parent) and not (wal.is_file() and wal.stat().st_size)
    return "mode=ro" + ("&immutable=1" if frozen else "")


def sqlite_writable(path: Path) -> bool:
    """Whether this process may write the SQLite file ``path`` and create its WAL and
    shared-memory files beside it (file, folder and file system writable)."""
    return (os.access(path, os.W_OK) and os.access(path.parent, os.W_OK)
            and not _read_only_file_system(path.parent))


def _sqlite_begin(conn) -> None:
    # a writer takes the write lock at BEGIN, so two writers queue instead of deadlocking
    conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.info.get("write") else "BEGIN")


def create(url: str, new: bool = True) -> Engine:
    """An engine for the URL (SQLite folder created; the driver must be installed).

    ``new=False`` refuses a SQLite file that does not exist yet instead of creating it
    (for reading: a mistyped path should not give an empty logbook).

    Raises
    ------
    MissingExtraError
        SQLAlchemy or the PostgreSQL driver is not installed (names the extra).
    LogbookError
        A URL that SQLAlchemy does not understand.
    """
    from ..errors import require

    try:
        parsed = make_url(url)
    except ArgumentError:
        raise LogbookError(f"logbook location {url!r} is neither a file path nor a database "
                           "URL such as postgresql+psycopg://user@host/db") from None
    backend = parsed.get_backend_name()
    if backend == "postgresql":
        require("psycopg", "postgres")
        if parsed.drivername != "postgresql+psycopg":
            raise LogbookError(f"use postgresql+psycopg://... for PostgreSQL (got "
                               f"{parsed.drivername}://)")
        return create_engine(parsed, pool_pre_ping=True)
    if backend != "sqlite":
        raise LogbookError(f"the logbook stores in SQLite or PostgreSQL, not {backend}")
    database = parsed.database
    if not database or database == ":memory:":
        raise LogbookError("give the logbook a file: an in-memory SQLite database is lost "
                           "when it closes")
    path = Path(database)
    if not new and not path.is_file():
        raise LogbookError(f"no logbook at {path}: adding files creates one "
                           "(Logbook.add, `dischargelab logbook add`)")
    read_only = path.is_file() and not sqlite_writable(path)
    if path.is_file() and path.stat().st_size > 0:
        _check_sqlite_is_a_logbook(path)
    if read_only:
        return _read_only_sqlite(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LogbookStorageError(f"cannot create the logbook {path}: {exc.strerror or exc} "
                                  "(its folder); give a place you may write", "read-only"
                                  ) from None
    try:
        engine = create_engine(parsed, connect_args={"timeout": BUSY_TIMEOUT_S})
    except NoSuchModuleError:  # pragma: no cover - sqlite3 is in the standard library
        raise LogbookError("this Python has no sqlite3 module") from None
    event.listen(engine, "connect", _sqlite_pragmas)
    event.listen(engine, "begin", _sqlite_begin)
    _watch_file(engine, path)
    return engine


def _watch_file(engine: Engine, path: Path) -> None:
    """Refuse a write once the SQLite file was removed or replaced while open: SQLite in WAL
    mode would go on writing to the removed file, and everything written would be lost."""
    opened: dict = {}

    def identity() -> tuple | None:
        try:
            info = os.stat(path)
        except FileNotFoundError:
            return None
        return (info.st_dev, info.st_ino)

    def on_connect(_dbapi_connection, _record) -> None:
        opened.setdefault("file", identity())

    def on_begin(conn) -> None:
        if conn.info.get("write") and opened.get("file") != identity():
            raise LogbookStorageError(
                f"the logbook {path} was removed or replaced while it was open: nothing more "
                "was written to it; restore it, or run the command again to start a new one "
                "there", "unreachable")

    event.listen(engine, "connect", on_connect)
    event.listen(engine, "begin", on_begin)


def _read_only_sqlite(path: Path) -> Engine:
    """An engine reading a SQLite logbook this process may not write, in SQLite's read-only
    mode (see :func:`_read_only_flags`). A write fails with SQLITE_READONLY, which
    :func:`database_errors` says in one line."""
    import sqlite3

    from sqlalchemy.pool import QueuePool

    uri = f"{path.resolve().as_uri()}?{_read_only_flags(path)}"

    def connect():
        return sqlite3.connect(uri, uri=True, timeout=BUSY_TIMEOUT_S, check_same_thread=False)

    engine = create_engine("sqlite://", creator=connect, poolclass=QueuePool)
    event.listen(engine, "connect", _sqlite_read_only_pragmas)
    event.listen(engine, "begin", _sqlite_begin)
    return engine


def sqlite_files(url: str) -> list[Path]:
    """The files of a SQLite logbook (the database, its WAL and shared-memory files);
    none for a server database."""
    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite" or not parsed.database:
        return []
    path = Path(parsed.database)
    return [path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")]


def _check_sqlite_is_a_logbook(path: Path) -> None:
    """Refuse, before anything writes to it, a file that is not SQLite or is another
    program's database (its tables, but none of a logbook's)."""
    import sqlite3

    try:
        with closing(sqlite3.connect(f"{path.resolve().as_uri()}?{_read_only_flags(path)}",
                                     uri=True)) as db:
            names = {row[0] for row in db.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'")}
    except sqlite3.DatabaseError:
        raise LogbookError(f"{path} is not a logbook database that can be opened (not an "
                           "SQLite file, or no permission)") from None
    if names and "logbook_meta" not in names:
        raise LogbookError(f"{path} is another program's SQLite database (tables "
                           f"{', '.join(sorted(names)[:5])}); give the logbook a file of its own")


@contextmanager
def writing(engine: Engine):
    """A write transaction (SQLite: ``BEGIN IMMEDIATE``; PostgreSQL: read committed)."""
    with engine.connect() as conn:
        conn.info["write"] = True
        try:
            with conn.begin():
                yield conn
        finally:
            conn.info.pop("write", None)


def check_writable(engine: Engine) -> None:
    """Raise the driver's error now if the logbook cannot be written (a read-only file or
    server), before any long work: a write of nothing, rolled back."""
    with engine.connect() as conn:
        conn.info["write"] = True
        try:
            with conn.begin() as transaction:
                conn.execute(logbook_meta.update().where(logbook_meta.c.key == "schema_version")
                             .values(value=logbook_meta.c.value))
                transaction.rollback()
        finally:
            conn.info.pop("write", None)


#: Tries of a write transaction that PostgreSQL aborts for a serialization failure or a
#: deadlock (SQLSTATE 40001, 40P01), and the wait before the first retry [s], doubled at
#: each (with jitter, at most :data:`RETRY_MAX_S`): a busy server gets a few seconds, then
#: the error is raised.
RETRY_TRIES = 6
RETRY_FIRST_S = 0.05
RETRY_MAX_S = 2.0
RETRYABLE_STATES = ("40001", "40P01")


def retryable(exc: DBAPIError) -> bool:
    """A transaction the server aborted so that another could go on: run it again."""
    return getattr(exc.orig, "sqlstate", None) in RETRYABLE_STATES


def write(engine: Engine, work, tries: int = RETRY_TRIES):
    """``work(conn)`` in one write transaction (:func:`writing`), run again from the start
    when PostgreSQL aborts it for a serialization failure or a deadlock (bounded,
    :data:`RETRY_TRIES`); returns what ``work`` returns. ``work`` must keep its effects
    inside the transaction (it may run more than once)."""
    import random
    import time

    for attempt in range(tries):
        try:
            with writing(engine) as conn:
                return work(conn)
        except DBAPIError as exc:
            if not retryable(exc) or attempt == tries - 1:
                raise
            wait = min(RETRY_MAX_S, RETRY_FIRST_S * 2 ** attempt)
            time.sleep(wait * random.uniform(0.5, 1.0))
    raise AssertionError("unreachable")  # pragma: no cover - the loop returns or raises


@contextmanager
def reading(engine: Engine):
    """A read transaction."""
    with engine.connect() as conn, conn.begin():
        yield conn


#: SQLite result codes (the low byte of an extended code) and PostgreSQL SQLSTATE classes
#: that say the storage itself refuses, not the request.
SQLITE_READONLY, SQLITE_BUSY, SQLITE_IOERR, SQLITE_FULL, SQLITE_CANTOPEN, SQLITE_NOTADB = \
    8, 5, 10, 13, 14, 26
PG_DISK_FULL = "53100"
PG_READ_ONLY = ("25006", "42501")      # read-only transaction or server; no privilege
PG_GONE = ("08", "57P01", "57P02", "57P03")  # connection exceptions; server shut down


def storage_error(exc: DBAPIError, url: str) -> LogbookError | None:
    """The one line for a driver error that says the storage refuses (full, read-only, gone,
    busy, failing), or None for any other error (a bug, raised as it is)."""
    orig = exc.orig
    where = shown_url(url)
    kept = "what was stored before is kept"
    files = sqlite_files(url)
    if files:
        path = files[0]
        code = getattr(orig, "sqlite_errorcode", None)
        code = None if code is None else code & 0xFF
        text_ = str(orig).lower()
        if code == SQLITE_FULL or "disk is full" in text_:
            try:
                free = f"{shutil.disk_usage(path.parent).free / 1e6:.1f} MB free"
            except OSError:
                free = "no space"
            return LogbookStorageError(
                f"no space left on the device holding the logbook {path} ({free}); free space "
                f"there or move the logbook to a larger disk (Logbook(url), --db); {kept}",
                "full")
        if code == SQLITE_READONLY or "readonly database" in text_:
            return LogbookStorageError(
                f"the logbook {path} is read-only (its file, folder or file system): nothing "
                "was changed; make it writable or give a logbook you may write "
                "(Logbook(url), --db)", "read-only")
        if code == SQLITE_BUSY or "database is locked" in text_:
            return LogbookStorageError(
                f"another program held the logbook {path} locked for {BUSY_TIMEOUT_S:.0f} s; "
                f"try again when it has finished; {kept}", "busy")
        if code == SQLITE_IOERR or "disk i/o error" in text_:
            return LogbookStorageError(
                f"cannot read or write the logbook {path} (disk I/O error: a failing disk, "
                f"a network folder that went away, or the file removed); check the disk; {kept}",
                "io")
        if code in (SQLITE_CANTOPEN, SQLITE_NOTADB) or "not a database" in text_ \
                or "unable to open" in text_:
            return LogbookStorageError(
                f"{path} is not a logbook database that can be opened (not an SQLite file, "
                "or no permission)", "unreachable")
        return None
    state = getattr(orig, "sqlstate", None) or ""
    if state == PG_DISK_FULL:
        return LogbookStorageError(
            f"the PostgreSQL server of the logbook {where} has no space left on its disk; free "
            f"space on the server; {kept}", "full")
    if state in PG_READ_ONLY:
        return LogbookStorageError(
            f"the logbook database {where} is read-only for this user (a read-only server or "
            "transaction, or no write privilege): nothing was changed; grant the user INSERT "
            "and UPDATE or give another database", "read-only")
    if state.startswith(PG_GONE) or exc.connection_invalidated or \
            "connect" in type(orig).__name__.lower() or "connection" in str(orig).lower():
        return LogbookStorageError(
            f"cannot reach the logbook database {where}: is the server running and the URL "
            f"(host, port, user, database) right? {kept}; run the command again when it is "
            "back", "unreachable")
    return None


@contextmanager
def database_errors(url: str):
    """Turn the driver's errors that say the storage refuses into one line that names the
    logbook and the fix (:func:`storage_error`); any other error is raised as it is."""
    try:
        yield
    except DBAPIError as exc:
        problem = storage_error(exc, url)
        if problem is None:
            raise
        raise problem from None


# --------------------------------------------------------------------------- versions

def revision_id(version: int) -> str:
    """The Alembic revision of a schema version (``0004`` for 4)."""
    return f"{int(version):04d}"


def schema_version(conn) -> int | None:
    """The stored schema version, or None for an empty database."""
    if not inspect(conn).has_table("logbook_meta"):
        return None
    value = conn.execute(select(logbook_meta.c.value)
                         .where(logbook_meta.c.key == "schema_version")).scalar()
    try:
        return int(value)
    except (TypeError, ValueError):
        raise LogbookError(f"the logbook's schema version is unreadable ({value!r})") from None


def stored_revision(conn) -> str | None:
    """The Alembic revision the database is at, or None when it was made before the
    revisions were kept (schema 1 to 3 by dischargelab 0.3 and earlier) or is empty."""
    if not inspect(conn).has_table("alembic_version"):
        return None
    return conn.execute(text("SELECT version_num FROM alembic_version")).scalar()


def migrate(conn, found: int | None, target: str = "head") -> None:
    """Run the Alembic revisions from the database's version to ``target`` on ``conn``
    (inside its transaction); a database without Alembic's record is stamped first."""
    from ..errors import require

    require("alembic", "logbook")
    from alembic import command
    from alembic.config import Config

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.set_main_option("path_separator", "os")
    config.attributes["connection"] = conn
    if found is not None and stored_revision(conn) is None:
        command.stamp(config, revision_id(found))
    command.upgrade(config, target)


def prepare(engine: Engine, url: str) -> int:
    """Create the tables of an empty database or migrate an older one forward.

    Returns
    -------
    int
        The schema version the database had when opened (0 when it was empty).

    Raises
    ------
    LogbookError
        The database was written by a newer dischargelab, or holds tables that are
        not a logbook's.
    """
    with reading(engine) as conn:       # the common case: current, nothing to write
        found = schema_version(conn)
        if found == SCHEMA_VERSION and stored_revision(conn) == revision_id(SCHEMA_VERSION):
            return found
        _check_not_newer(found, url)
    with writing(engine) as conn:
        if engine.dialect.name == "postgresql":  # one process creates or migrates at a time
            conn.execute(text("SELECT pg_advisory_xact_lock(7283640151)"))
        found = schema_version(conn)
        if found is None:
            present = set(inspect(conn).get_table_names())
            clash = present & ({t.name for t in metadata.sorted_tables} | {"alembic_version"})
            if clash:
                raise LogbookError(f"{shown_url(url)} holds tables named like a logbook's "
                                   f"({', '.join(sorted(clash))}) but no schema version; "
                                   "give another database")
        _check_not_newer(found, url)
        if found == SCHEMA_VERSION and stored_revision(conn) == revision_id(SCHEMA_VERSION):
            return found
        migrate(conn, found)
        return found or 0


def _check_not_newer(found: int | None, url: str) -> None:
    if found is not None and found > SCHEMA_VERSION:
        raise LogbookError(f"the logbook {shown_url(url)} has schema version {found}, newer "
                           f"than this dischargelab understands ({SCHEMA_VERSION}); "
                           "upgrade dischargelab")


__all__ = ["SCHEMA_VERSION", "MIGRATIONS_DIR", "migrate", "revision_id", "stored_revision",
           "metadata", "pack_figures", "packs", "blobs", "sources", "events", "models",
           "logbook_meta", "resolve_url", "user_data_dir", "create", "prepare", "writing",
           "write", "retryable", "check_writable", "reading", "database_errors", "storage_error",
           "sqlite_writable", "shown_url", "schema_version", "now_iso", "EVENT_FLOATS",
           "ENV_VARIABLE"]
