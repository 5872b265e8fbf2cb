"""Client side of adding files: hash, skip what is known, summarise, write in batches.

The client is the only writer of the database. For a list of files and folders it

1. lists the files (folders: data files by suffix, see :data:`DATA_SUFFIXES`),
2. hashes each file (SHA-256) and drops those whose hash the logbook already
   holds, before any work is sent,
3. runs :func:`~dischargelab.logbook.summarise.summarise_source` on the rest
   through an executor (:mod:`dischargelab.fleet`: in this process by default, or
   Dask workers, which get each file's path when they see it, else its bytes),
4. writes the summaries in batches of :data:`BATCH_SOURCES`, one transaction each:
   the raw file (zlib) in ``blobs``, the source, its events. ``sources.sha256`` and
   ``(events.source_id, events.idx)`` are unique and inserts skip conflicts, so two
   writers adding the same files store each event once.
5. keeps one copy of the same flights or tests in other bytes (a raw log and its CSV
   export): a file whose events are those of a file of the pack already stored
   (:mod:`.duplicates`: kind, duration, samples, charge, voltages, currents, clock) is
   skipped and reported with the file it repeats. Within one add the richer file is kept
   (more samples, then more bytes; files are sent largest first), across adds the one
   stored first stays.

A file a reader cannot use is rejected with one line and the others go in; an
error that is not a data problem (a bug) is raised after the finished batches are
written, so nothing already read is lost. Ctrl-C writes what is summarised and
stops: every transaction is whole, and a rerun skips the hashes already stored.
"""

from __future__ import annotations

import functools
import json
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sqlalchemy import func as sqlalchemy_func
from sqlalchemy import select

from ..errors import DischargelabError, LogbookError
from ..io.prepare import LOGGER_STOP
from . import duplicates, schema
from .summarise import (
    SourceSummary,
    check_reader_options,
    safe_file_name,
    sha256_bytes,
    sha256_file,
    summarise_source,
)

#: Summaries written per transaction, and the compressed bytes they may hold at most before
#: they are written anyway (a batch of large flight logs stays small in memory).
BATCH_SOURCES = 25
BATCH_BYTES = 64_000_000

#: Files per task on a cluster: up to this many bytes (at least one file, at most
#: :data:`TASK_FILES`), so a task lasts long enough to pay for its few milliseconds of
#: cluster overhead and short enough to spread the work evenly.
TASK_BYTES = 2_000_000
TASK_FILES = 8

#: File suffixes taken from folders (a file named on its own is always tried), and
#: Maccor's numbered ones (``.001``, ``.002``...).
DATA_SUFFIXES = (".csv", ".txt", ".tsv", ".lvm", ".log", ".bin", ".ulg", ".bbl", ".bfl",
                 ".dat", ".tlog", ".nda", ".ndax", ".mpr", ".mpt", ".res", ".xlsx")

#: Files in folders whose names start with these are documentation, not data.
SKIP_PREFIXES = ("license", "copying", "readme", "notice")

#: Hashes looked up per query.
LOOKUP_CHUNK = 500

#: Accepted values of ``pack_from``.
PACK_FROM = ("parent",)


@dataclass
class AddResult:
    """What :meth:`dischargelab.Logbook.add` did.

    Attributes
    ----------
    added : list of str
        File names added.
    skipped : list of str
        File names already in the logbook (same SHA-256), or repeated in the request.
    rejected : list of (str, str)
        ``(path, one-line reason)`` of files that could not be read.
    events : int
        Events stored.
    changed : set of str
        Packs that got events (their figures are recomputed after the add).
    notes : list of (str, str)
        ``(file name, note)`` for what a reader dropped from a file that went in (the
        logger's record of zeros that ends a test cut short).
    copies : list of (str, str)
        ``(file name, why)`` of files skipped because another file of the pack holds the
        same flights or tests in other bytes (a raw log and its export); ``why`` names
        the file kept.
    not_tried : list of str
        Files in the folders given whose suffix is not a data file's
        (:data:`DATA_SUFFIXES`): not read (a file named on its own is).
    """

    added: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    rejected: list[tuple[str, str]] = field(default_factory=list)
    events: int = 0
    changed: set[str] = field(default_factory=set)
    notes: list[tuple[str, str]] = field(default_factory=list)
    copies: list[tuple[str, str]] = field(default_factory=list)
    not_tried: list[str] = field(default_factory=list)
    #: Sources this add stored: id -> (file name, events), so a richer copy found later in
    #: the same add replaces its poorer twin.
    stored_now: dict = field(default_factory=dict, repr=False)

    def summary(self) -> str:
        """One line: files added, events, files already there, files rejected."""
        text = f"added {len(self.added)} file(s), {self.events} event(s)"
        if self.skipped:
            text += f"; {len(self.skipped)} already in the logbook"
        if self.copies:
            text += f"; {len(self.copies)} skipped as copies of another file"
        if self.rejected:
            text += f"; {len(self.rejected)} rejected"
        return text

    def lines(self) -> list[str]:
        """One line per note, skipped file and rejected file, for printing."""
        out = [f"{name}: {note}" for name, note in self.notes]
        out += [f"{name}: already in the logbook" for name in self.skipped]
        out += [f"{name}: skipped: {why}" for name, why in self.copies]
        out += [f"{Path(path).name}: rejected: {reason}" for path, reason in self.rejected]
        if self.not_tried:
            kinds = Counter(Path(n).suffix.lower() or "no suffix" for n in self.not_tried)
            out.append(f"not tried: {len(self.not_tried)} file(s) in the folders whose type is "
                       f"not a data file's ({', '.join(f'{k} x{v}' for k, v in kinds.items())})"
                       "; name a file to try it")
        return out

    def to_dict(self) -> dict:
        return {"added": list(self.added), "skipped": list(self.skipped),
                "rejected": [{"path": p, "reason": r} for p, r in self.rejected],
                "events": int(self.events),
                "copies": [{"file": f, "reason": r} for f, r in self.copies],
                "not_tried": list(self.not_tried),
                "notes": [{"file": f, "note": n} for f, n in self.notes]}


def _is_documentation(path: Path) -> bool:
    """A file in a folder that is not data whatever its suffix: a licence, a README..., or
    a hidden file."""
    return path.name.lower().startswith((*SKIP_PREFIXES, "."))


def _is_data_file(path: Path) -> bool:
    suffix = path.suffix.lower()
    return (suffix in DATA_SUFFIXES or (len(suffix) == 4 and suffix[1:].isdigit())) \
        and not _is_documentation(path)


def list_files(paths, *, pack: str | None, pack_from: str | None, recursive: bool
               ) -> tuple[list[tuple[Path, str]], list[tuple[str, str]], list[Path]]:
    """``[(file, pack name)]`` for the paths given, ``[(path, reason)]`` for missing ones,
    and the files in folders not taken for their suffix (documentation files and hidden
    ones aside)."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    if pack is None and pack_from is None:
        raise LogbookError("say which pack the files belong to: pack='NAME', or "
                           "pack_from='parent' (each file's folder name)")
    if pack is not None and pack_from is not None:
        raise LogbookError("give pack or pack_from, not both")
    if pack_from is not None and pack_from not in PACK_FROM:
        raise LogbookError(f"pack_from must be one of {', '.join(PACK_FROM)}; got {pack_from!r}")
    if pack is not None and not str(pack).strip():
        raise LogbookError("the pack name is empty")
    files, missing, not_tried = [], [], []
    for given in paths:
        path = Path(given).expanduser()
        if path.is_dir():
            found = path.rglob("*") if recursive else path.glob("*")
            for item in sorted(found):
                if not item.is_file() or _is_documentation(item):
                    continue
                (files if _is_data_file(item) else not_tried).append(item)
        elif path.is_file():
            files.append(path)
        else:
            missing.append((str(path), "no such file or folder"))
    named = [(f, str(pack).strip() if pack is not None else f.resolve().parent.name)
             for f in files]
    return named, missing, not_tried


def _insert(conn, table):
    if conn.dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert
    else:
        from sqlalchemy.dialects.sqlite import insert
    return insert(table)


def bump_versions(conn, pack_ids_: Iterable[int]) -> None:
    """Raise the version of the packs a write changed (in id order, so two writers take the
    rows' locks in the same order); their stored figures are then stale (:mod:`.figures`)."""
    for pid in sorted(set(pack_ids_)):
        conn.execute(schema.packs.update().where(schema.packs.c.id == pid)
                     .values(version=schema.packs.c.version + 1))


def known_hashes(conn, hashes: Iterable[str]) -> set[str]:
    """The hashes among ``hashes`` already stored as sources."""
    hashes = list(hashes)
    found: set[str] = set()
    for k in range(0, len(hashes), LOOKUP_CHUNK):
        chunk = hashes[k:k + LOOKUP_CHUNK]
        found.update(conn.execute(select(schema.sources.c.sha256)
                                  .where(schema.sources.c.sha256.in_(chunk))).scalars())
    return found


def pack_ids(conn, names: Iterable[str]) -> dict[str, int]:
    """Ids of the named packs, created when missing."""
    out = {}
    for name in sorted(set(names)):
        conn.execute(_insert(conn, schema.packs).values(name=name, created_at=schema.now_iso())
                     .on_conflict_do_nothing(index_elements=["name"]))
        out[name] = conn.execute(select(schema.packs.c.id)
                                 .where(schema.packs.c.name == name)).scalar_one()
    return out


def event_row(event: dict) -> dict:
    """A summary event as a row of the ``events`` table (without the ids)."""
    row = {name: event.get(name) for name in schema.EVENT_FLOATS}
    interval = event.get("resistance_interval95") or (None, None)
    row.update(resistance_low_ohm=interval[0], resistance_high_ohm=interval[1],
               idx=int(event["index"]), kind=event["kind"], start_time=event.get("start_time"),
               cycle=event.get("cycle"), reaches_knee=bool(event.get("reaches_knee")),
               cells=event.get("cells"), samples=int(event.get("samples") or 0),
               curve_json=json.dumps(event.get("curve") or {}),
               details_json=json.dumps(event["details"]) if event.get("details") else None)
    return {k: (float(v) if k in schema.EVENT_FLOATS and v is not None else v)
            for k, v in row.items()}


#: Stored sources compared with a new file at most (those whose first event has its kind
#: and duration), so a pack of many similar files costs a bounded lookup.
MAX_CANDIDATES = 50


def stored_copy(conn, pack_id: int, mine: list[dict]) -> int | None:
    """The id of a stored source of the pack whose events are ``mine`` (the content of a new
    file, :func:`~dischargelab.logbook.duplicates.content`), or None."""
    if not mine or mine[0].get("duration_s") is None:
        return None
    e = schema.events
    first = mine[0]
    d = float(first["duration_s"])
    slack = duplicates.ABS_TOL["duration_s"] + duplicates.REL_TOL * abs(d)
    found = conn.execute(select(e.c.source_id).where(
        e.c.pack_id == pack_id, e.c.kind == first["kind"],
        e.c.duration_s.between(d - slack, d + slack)).distinct()
        .order_by(e.c.source_id).limit(MAX_CANDIDATES)).scalars().all()
    for sid in found:
        rows = conn.execute(select(*[e.c[n] for n in duplicates.FIELDS])
                            .where(e.c.source_id == sid)).mappings()
        if duplicates.same_content(mine, duplicates.content([dict(r) for r in rows])):
            return int(sid)
    return None


def source_size(conn, source_id: int) -> tuple[str, int, int]:
    """``(file name, bytes, samples of its load events)`` of a stored source."""
    s, e = schema.sources, schema.events
    name, size = conn.execute(select(s.c.file_name, s.c.size_bytes)
                              .where(s.c.id == source_id)).one()
    samples = conn.execute(select(sqlalchemy_func.sum(e.c.samples)).where(
        e.c.source_id == source_id, e.c.kind.in_(duplicates.LOAD_KINDS))).scalar()
    return str(name), int(size), int(samples or 0)


def drop_source(conn, source_id: int) -> None:
    """Remove a stored source, its events and its bytes (a poorer copy of a file this add
    stores instead)."""
    s, e = schema.sources, schema.events
    ids = select(e.c.id).where(e.c.source_id == source_id)
    conn.execute(schema.models.update().where(schema.models.c.reference_event_id.in_(ids))
                 .values(reference_event_id=None))
    conn.execute(e.delete().where(e.c.source_id == source_id))
    sha = conn.execute(select(s.c.sha256).where(s.c.id == source_id)).scalar_one()
    conn.execute(s.delete().where(s.c.id == source_id))
    conn.execute(schema.blobs.delete().where(schema.blobs.c.sha256 == sha))


def write_summaries(engine, batch: list[tuple[SourceSummary, str, str | None]],
                    result: AddResult) -> None:
    """Store ``(summary, pack, original path)`` items in one transaction (the raw file
    as the summary carries it, compressed).

    The items are written in SHA-256 order, so two writers holding overlapping files take
    the unique keys' locks in the same order and one waits for the other instead of
    deadlocking; PostgreSQL aborting the transaction anyway (a deadlock, a serialization
    failure) runs it again (:func:`~dischargelab.logbook.schema.write`). ``result`` is
    told only once the transaction is committed.
    """
    if not batch:
        return
    ordered = sorted(batch, key=lambda item: item[0].sha256)

    def work(conn) -> tuple[list, list, int, set]:
        ids = pack_ids(conn, [pack for _, pack, _ in ordered])
        added, skipped, events, changed = [], [], 0, set()
        copies: list = []                   # (file skipped, why)
        replaced: dict = {}                 # source id -> (file name, events) dropped
        now = dict(stored_now)              # sources this add stored, as the batch goes
        for summary, pack, path in ordered:
            if conn.execute(select(schema.sources.c.id).where(
                    schema.sources.c.sha256 == summary.sha256)).scalar() is not None:
                skipped.append(summary.file_name)   # another writer stored it first
                continue
            mine = duplicates.content(summary.events)
            twin = stored_copy(conn, ids[pack], mine)
            if twin is not None:
                twin_name, twin_size, twin_samples = source_size(conn, twin)
                richer = duplicates.richness(sum(int(e.get("samples") or 0) for e in mine),
                                             summary.size_bytes) \
                    > duplicates.richness(twin_samples, twin_size)
                if twin in now and richer:
                    drop_source(conn, twin)
                    replaced[twin] = now.pop(twin)
                    copies.append((twin_name, duplicates.reason(summary.file_name, len(mine))))
                    changed.add(pack)
                else:
                    copies.append((summary.file_name, duplicates.reason(twin_name, len(mine))))
                    continue
            if summary.raw_zlib:          # else only the path is recorded (keep_raw=False)
                conn.execute(_insert(conn, schema.blobs).values(
                    sha256=summary.sha256, compression="zlib", size_bytes=summary.size_bytes,
                    data=summary.raw_zlib).on_conflict_do_nothing(index_elements=["sha256"]))
            source_id = conn.execute(_insert(conn, schema.sources).values(
                sha256=summary.sha256, pack_id=ids[pack], file_name=summary.file_name,
                path=path, size_bytes=summary.size_bytes, format=summary.format,
                added_at=schema.now_iso(), options_json=json.dumps(summary.options),
                notes_json=json.dumps(summary.notes),
            ).on_conflict_do_nothing(index_elements=["sha256"])
                .returning(schema.sources.c.id)).scalar()
            if source_id is None:  # another writer stored it first
                skipped.append(summary.file_name)
                continue
            rows = [dict(event_row(e), source_id=source_id, pack_id=ids[pack])
                    for e in summary.events]
            if rows:
                conn.execute(schema.events.insert(), rows)
            added.append(summary.file_name)
            now[source_id] = (summary.file_name, len(rows))
            events += len(rows)
            changed.add(pack)
        bump_versions(conn, [ids[pack] for pack in changed])
        return added, skipped, events, changed, copies, replaced, now

    stored_now = result.stored_now
    added, skipped, events, changed, copies, replaced, now = schema.write(engine, work)
    result.added += added
    result.events += events
    for name, count in replaced.values():       # a poorer copy stored earlier in this add
        if name in result.added:
            result.added.remove(name)
            result.events -= count
    result.stored_now = now
    result.copies += copies
    result.skipped += skipped
    result.changed.update(changed)
    stored = set(added)
    result.notes += [(summary.file_name, note) for summary, _, _ in ordered
                     if summary.file_name in stored
                     for note in summary.notes if LOGGER_STOP in note]


def add_files(engine, paths, *, pack=None, pack_from=None, recursive=False, executor=None,
              progress: Callable[[int, int, str], None] | None = None,
              reader_options: dict | None = None, keep_raw: bool = True) -> AddResult:
    """Add files and folders to the logbook (see :meth:`dischargelab.Logbook.add`)."""
    from ..fleet import InProcessExecutor

    options = check_reader_options(reader_options)
    files, missing, not_tried = list_files(paths, pack=pack, pack_from=pack_from,
                                           recursive=recursive)
    schema.check_writable(engine)       # a read-only logbook says so before any file is read
    result = AddResult(rejected=list(missing), not_tried=[p.name for p in not_tried])
    total = len(files)
    hashed: dict[str, tuple[Path, str, str]] = {}
    for path, pack_name in files:
        try:
            sha = sha256_file(path)
        except OSError as exc:
            result.rejected.append((str(path), f"cannot read it ({exc.strerror or exc})"))
            continue
        if sha in hashed:
            result.skipped.append(path.name)
            continue
        hashed[sha] = (path, pack_name, sha)
    with schema.reading(engine) as conn:
        known = known_hashes(conn, hashed)
    for sha in known:
        result.skipped.append(hashed.pop(sha)[0].name)
    done = total - len(hashed)
    if progress is not None and done:
        progress(done, total, f"{done} already in the logbook")
    # largest first: of two copies of the same flights, the richer is usually stored first
    largest = sorted(hashed.values(), key=lambda item: (-item[0].stat().st_size, str(item[0])))
    by_path = {str(path): (path, pack_name, sha) for path, pack_name, sha in largest}
    task = functools.partial(summarise_source, options=options, keep_raw=keep_raw)
    executor = executor or InProcessExecutor()
    batch: list = []
    batch_bytes = 0
    failure: BaseException | None = None
    try:
        sizes = [path.stat().st_size for path, _, _ in by_path.values()]
        per_task = int(min(TASK_FILES, max(1, TASK_BYTES // max(1, int(np.mean(sizes))))))\
            if sizes else 1
        for item, outcome in executor.map_unordered(task, _payloads(executor, by_path),
                                                    per_task=per_task):
            key = item[0] if isinstance(item, tuple) else item
            path, pack_name, sha = by_path[key]
            done += 1
            if isinstance(outcome, DischargelabError):
                result.rejected.append((str(path), str(outcome).splitlines()[0]))
            elif isinstance(outcome, BaseException):
                failure = outcome
                break
            elif outcome.sha256 != sha:     # the worker read other bytes than were hashed
                result.rejected.append((str(path), "the file changed while it was being "
                                                   "added; add it again"))
            else:
                batch.append((outcome, pack_name, str(path.resolve())))
                batch_bytes += len(outcome.raw_zlib)
            if progress is not None:
                progress(done, total, path.name)
            if len(batch) >= BATCH_SOURCES or batch_bytes >= BATCH_BYTES:
                write_summaries(engine, batch, result)
                batch, batch_bytes = [], 0
    except BaseException:
        # Ctrl-C, a file gone, a lost cluster: keep what is summarised (one transaction), so
        # a rerun only does what is missing
        write_summaries(engine, batch, result)
        raise
    write_summaries(engine, batch, result)
    if failure is not None:
        raise failure
    return result


def _payloads(executor, by_path: dict):
    """What the tasks get: each file's path when the executor's workers see this machine's
    files (in process, a local cluster, a shared folder), else ``(path, bytes)`` read one at a
    time as the executor asks for the next (so only the files in flight are in memory)."""
    paths = list(by_path)
    if not paths:
        return iter(())
    sees = getattr(executor, "sees", None)
    if executor.shares_files or (sees is not None and sees(paths[0])):
        return iter(paths)
    return ((path, Path(path).read_bytes()) for path in paths)


def add_upload(engine, source, pack: str, reader_options: dict | None = None) -> AddResult:
    """Add one uploaded file, stored under its name with no path: ``source`` is
    ``(file name, bytes)`` or a file (an upload received to a temporary file named as the
    upload); see :meth:`dischargelab.Logbook.add_bytes` and
    :meth:`dischargelab.Logbook.add_upload`."""
    if not str(pack or "").strip():
        raise LogbookError("the pack name is empty")
    if isinstance(source, tuple):
        name, data = safe_file_name(source[0]), source[1]
        source, sha = (name, data), sha256_bytes(data)
    else:
        source = Path(source)
        name, sha = source.name, sha256_file(source)
    result = AddResult()
    with schema.reading(engine) as conn:
        if known_hashes(conn, [sha]):
            result.skipped.append(name)
            return result
    try:
        summary = summarise_source(source, check_reader_options(reader_options))
    except DischargelabError as exc:
        result.rejected.append((name, str(exc).splitlines()[0]))
        return result
    write_summaries(engine, [(summary, str(pack).strip(), None)], result)
    return result


__all__ = ["AddResult", "add_files", "add_upload", "list_files", "write_summaries",
           "known_hashes", "event_row", "DATA_SUFFIXES", "BATCH_SOURCES"]
