"""Queries of the logbook database (reads, pack settings, fitted models, raw files)."""

from __future__ import annotations

import hashlib
import json
import zlib
from pathlib import Path

from sqlalchemy import func, select

from ..errors import LogbookError
from . import schema
from .ingest import bump_versions, pack_ids


def pack_row(conn, name: str) -> dict:
    """The pack named ``name`` as a dict; LogbookError when there is none."""
    row = conn.execute(select(schema.packs).where(schema.packs.c.name == name)).mappings().first()
    if row is None:
        raise LogbookError(f"no pack named {name!r} in the logbook; Logbook.packs() lists them "
                           "(`dischargelab logbook packs`)")
    return dict(row)


def pack_names(conn) -> list[str]:
    """Every pack name, sorted."""
    return list(conn.execute(select(schema.packs.c.name).order_by(schema.packs.c.name)).scalars())


def pack_events(conn, pack_id: int, curves: bool = True) -> list[dict]:
    """The stored events of a pack, with ``source`` (file name), ``curve`` and ``details``
    decoded (``curves=False``: without the curves and details, for listing)."""
    e, s = schema.events, schema.sources
    columns = list(e.c) if curves else [c for c in e.c
                                        if c.name not in ("curve_json", "details_json")]
    query = (select(*columns, s.c.file_name.label("source"), s.c.sha256)
             .join(s, s.c.id == e.c.source_id).where(e.c.pack_id == pack_id)
             .order_by(e.c.id))
    out = []
    for row in conn.execute(query).mappings():
        item = dict(row)
        if curves:
            item["curve"] = json.loads(item.pop("curve_json"))
            details = item.pop("details_json", None)
            item["details"] = json.loads(details) if details else {}
        out.append(item)
    return out


def set_pack(conn, name: str, **settings) -> None:
    """Create the pack if needed and store the settings given (None leaves a setting)."""
    pid = pack_ids(conn, [name])[name]
    values = {k: v for k, v in settings.items() if v is not None}
    if values:
        conn.execute(schema.packs.update().where(schema.packs.c.id == pid).values(**values))
        bump_versions(conn, [pid])


def counts(conn) -> dict[int, int]:
    """Events per pack id."""
    e = schema.events
    return dict(conn.execute(select(e.c.pack_id, func.count()).group_by(e.c.pack_id)).all())


def latest_model(conn, pack_id: int) -> dict | None:
    """The pack's most recent fitted model row (``battery`` decoded), or None."""
    m = schema.models
    row = conn.execute(select(m).where(m.c.pack_id == pack_id).order_by(m.c.id.desc())
                       .limit(1)).mappings().first()
    if row is None:
        return None
    item = dict(row)
    item["battery"] = json.loads(item.pop("battery_json"))
    return item


def save_model(conn, pack_id: int, battery_dict: dict, reference_event_id: int | None,
               capacity_Ah: float | None, resistance_ohm: float | None) -> None:
    conn.execute(schema.models.insert().values(
        pack_id=pack_id, fitted_at=schema.now_iso(), reference_event_id=reference_event_id,
        capacity_Ah=capacity_Ah, resistance_ohm=resistance_ohm,
        battery_json=json.dumps(battery_dict)))
    bump_versions(conn, [pack_id])


def raw_file(conn, sha256: str) -> bytes:
    """The stored bytes of a source file; for a source added with ``keep_raw=False``, the
    file at its recorded path when its SHA-256 still matches."""
    row = conn.execute(select(schema.blobs.c.compression, schema.blobs.c.data)
                       .where(schema.blobs.c.sha256 == sha256)).first()
    if row is not None:
        compression, data = row
        return zlib.decompress(data) if compression == "zlib" else bytes(data)
    path = conn.execute(select(schema.sources.c.path)
                        .where(schema.sources.c.sha256 == sha256)).scalar()
    if path is None:
        raise LogbookError(f"no stored file with SHA-256 {sha256}")
    try:
        data = Path(path).read_bytes()
    except OSError:
        data = b""
    if hashlib.sha256(data).hexdigest() != sha256:
        raise LogbookError(f"{path} was added without keeping its bytes and is no longer there "
                           "as it was; add it again (keeping its bytes) to recompute from it")
    return data


def path_only_sources(conn) -> list[Path]:
    """Files added without keeping their bytes: the logbook's only copy is where they are."""
    s, b = schema.sources, schema.blobs
    kept = select(b.c.sha256)
    rows = conn.execute(select(s.c.path).where(s.c.path.is_not(None))
                        .where(s.c.sha256.not_in(kept))).scalars()
    return [Path(p) for p in rows]


def source_of_event(conn, event_id: int) -> dict:
    """File name, SHA-256, reader options and segment number (from 1) of an event's source;
    for an event of a long log (split into events by the logbook), ``rows``: its first and
    stop row in the file read whole (``segment="none"``)."""
    e, s = schema.events, schema.sources
    row = conn.execute(select(s.c.file_name, s.c.sha256, s.c.options_json, e.c.idx,
                              e.c.details_json)
                       .join(e, e.c.source_id == s.c.id).where(e.c.id == event_id)).first()
    if row is None:
        raise LogbookError(f"no event {event_id} in the logbook")
    details = json.loads(row[4]) if row[4] else {}
    out = {"file_name": row[0], "sha256": row[1], "options": json.loads(row[2]),
           "segment": int(row[3]) + 1}
    if details.get("long_log") and details.get("rows"):
        out["rows"] = [int(x) for x in details["rows"]]
    return out


__all__ = ["pack_row", "pack_names", "pack_events", "set_pack", "counts", "latest_model",
           "save_model", "raw_file", "source_of_event", "path_only_sources"]
