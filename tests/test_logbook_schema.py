"""Logbook schema versions through Alembic, on SQLite files and a throwaway PostgreSQL server.

The databases of earlier versions are made from the DDL those versions wrote
(``tests/data/logbook_schema``: schema 2 and 3 compiled from the tables of the releases that
wrote them, schema 1 by hand) and filled with the events of real cell C files; opening one
with this code must migrate it in place, keep every stored value and give the tables the code
declares, column for column.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("sqlalchemy")
pytest.importorskip("alembic")

from sqlalchemy import MetaData, Table, create_engine, inspect, select, text

from dischargelab.errors import LogbookError
from dischargelab.logbook import Logbook, schema
from dischargelab.logbook.ingest import event_row
from dischargelab.logbook.summarise import summarise_source

DDL = Path(__file__).resolve().parent / "data" / "logbook_schema"
CYCLES = (1, 100, 200)


def cell_c(shared_data, cycles=CYCLES) -> list[Path]:
    return [shared_data / "samsung30q_ageing_cellC" / f"DischargeCycle{c:03d}.txt"
            for c in cycles]


def old_logbook(url: str, version: int, files: list[Path], pack: str = "C") -> None:
    """A logbook of schema ``version`` holding ``files`` as that version stored them (the
    columns it had), written with plain SQL."""
    engine = create_engine(schema.resolve_url(url))
    ddl = (DDL / f"v{version}.{engine.dialect.name}.sql").read_text(encoding="utf-8")
    with engine.begin() as conn:
        for statement in ddl.split("\n;\n"):
            if statement.strip():
                conn.exec_driver_sql(statement)
        tables = MetaData()
        for name in ("packs", "sources", "events"):
            Table(name, tables, autoload_with=conn)
        packs, sources = tables.tables["packs"], tables.tables["sources"]
        pack_id = conn.execute(packs.insert().values(name=pack, created_at="2024-06-01T00:00:00")
                               .returning(packs.c.id)).scalar_one()
        event_columns = set(tables.tables["events"].c.keys())
        for path in files:
            summary = summarise_source(path, keep_raw=False)
            source_id = conn.execute(sources.insert().values(
                sha256=summary.sha256, pack_id=pack_id, file_name=summary.file_name,
                path=str(path), size_bytes=summary.size_bytes, format=summary.format,
                added_at="2024-06-01T00:00:00", options_json="{}",
                notes_json=json.dumps(summary.notes)).returning(sources.c.id)).scalar_one()
            rows = [dict(event_row(e), source_id=source_id, pack_id=pack_id)
                    for e in summary.events]
            conn.execute(tables.tables["events"].insert(),
                         [{c: v for c, v in r.items() if c in event_columns} for r in rows])
    engine.dispose()


def stored_versions(url: str) -> tuple[int, str]:
    engine = create_engine(schema.resolve_url(url))
    with engine.connect() as conn:
        found = (schema.schema_version(conn), schema.stored_revision(conn))
    engine.dispose()
    return found


#: Columns each version added to events (absent, so None, in a migrated older database).
ADDED_LATER = {1: {"cycle", "cell_spread_V"}, 2: set(), 3: set()}


@pytest.mark.parametrize("version", [1, 2, 3])
def test_every_earlier_version_migrates_in_place_and_keeps_its_data(url, version, shared_data,
                                                                     tmp_path):
    files = cell_c(shared_data)
    old_logbook(url, version, files)
    with Logbook(url) as lb:
        assert lb.opened_version == version
        migrated = lb.events("C").rows
        health = lb.health("C")
        assert lb.add(cell_c(shared_data, [300]), pack="C").events == 1   # writes go on
    assert stored_versions(url) == (schema.SCHEMA_VERSION,
                                    schema.revision_id(schema.SCHEMA_VERSION))
    with Logbook(tmp_path / "fresh.sqlite") as fresh:
        fresh.add(files, pack="C")
        expected = fresh.events("C").rows
    assert len(migrated) == len(expected) == len(files)
    for old, new in zip(migrated, expected):
        for key, value in new.items():
            if key != "id":      # where it was stored: the batch goes in SHA-256 order
                assert old[key] == (None if key in ADDED_LATER[version] else value), key
    assert [e.discharged_Ah for e in health.events] == [r["discharged_Ah"] for r in expected]


@pytest.mark.parametrize("start", [None, 2], ids=["new", "from-2"])
def test_databases_have_exactly_the_declared_tables(url, start):
    """Alembic's own comparison of the database with the tables the code declares finds
    nothing to change, for a new logbook and for one migrated from schema 2 (release 0.3.0)."""
    from alembic.autogenerate import compare_metadata
    from alembic.runtime.migration import MigrationContext

    if start is not None:
        old_logbook(url, start, [])
    Logbook(url).close()
    engine = create_engine(schema.resolve_url(url))
    with engine.connect() as conn:
        context = MigrationContext.configure(conn, opts={"compare_type": True,
                                                         "compare_server_default": True})
        diff = compare_metadata(context, schema.metadata)
    engine.dispose()
    # Alembic's own bookkeeping table is not one the code declares
    assert [d for d in diff if not (d[0] == "remove_table" and d[1].name == "alembic_version")
            ] == []


def test_a_newer_revision_is_refused_with_one_line_and_left_alone(url):
    Logbook(url).close()
    engine = create_engine(schema.resolve_url(url))
    with engine.begin() as conn:
        conn.execute(text("UPDATE alembic_version SET version_num = '0009'"))
        conn.execute(text("UPDATE logbook_meta SET value = '9' WHERE key = 'schema_version'"))
    with pytest.raises(LogbookError, match=r"schema version 9, newer than .*\(4\); upgrade "
                                           "dischargelab") as err:
        Logbook(url)
    assert "\n" not in str(err.value)
    with engine.connect() as conn:
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0009"
    engine.dispose()


OPEN_SCRIPT = textwrap.dedent("""
    import sys
    from dischargelab.logbook import Logbook
    with Logbook(sys.argv[1]) as lb:
        print(lb.opened_version, len(lb.events("C").rows))
""")


@pytest.mark.slow
def test_concurrent_openers_migrate_once(url, shared_data):
    """Four processes open the same schema-2 logbook at once: one migrates, the others
    wait for it (SQLite's write lock, PostgreSQL's advisory lock) and find it current."""
    old_logbook(url, 2, cell_c(shared_data))
    procs = [subprocess.Popen([sys.executable, "-c", OPEN_SCRIPT, url], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(4)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0] * 4, [e for _, e in outs]
    opened = sorted(int(out.split()[0]) for out, _ in outs)
    assert opened == [2, 4, 4, 4]
    assert {int(out.split()[1]) for out, _ in outs} == {len(CYCLES)}
    engine = create_engine(schema.resolve_url(url))
    with engine.connect() as conn:
        assert conn.execute(text("SELECT count(*) FROM alembic_version")).scalar() == 1
        assert len(inspect(conn).get_columns("pack_figures")) > 0
    engine.dispose()


def test_revisions_go_down_and_up_again(url):
    """The revisions' downgrades run (for a maintainer going back a step); the logbook then
    opens and migrates forward again."""
    from alembic import command
    from alembic.config import Config

    Logbook(url).close()
    engine = create_engine(schema.resolve_url(url))
    with engine.begin() as conn:
        config = Config()
        config.set_main_option("script_location", str(schema.MIGRATIONS_DIR))
        config.set_main_option("path_separator", "os")
        config.attributes["connection"] = conn
        command.downgrade(config, "0001")
    with engine.connect() as conn:
        assert schema.schema_version(conn) == 1
        assert "models" not in inspect(conn).get_table_names()
        assert conn.execute(select(text("count(*)")).select_from(text("packs"))).scalar() == 0
    engine.dispose()
    with Logbook(url) as lb:
        assert lb.opened_version == 1
    assert stored_versions(url) == (schema.SCHEMA_VERSION, "0004")
