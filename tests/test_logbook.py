"""The pack logbook against real databases: SQLite files and a throwaway PostgreSQL server.

Every test that stores something runs on both backends (``url`` fixture). Expected
capacities come from integrating the raw LabVIEW files with numpy here, never from
the readers.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sqlalchemy")

import dischargelab as dl
from dischargelab.errors import LogbookError, MissingExtraError
from dischargelab.logbook import Logbook
from dischargelab.logbook.schema import SCHEMA_VERSION, resolve_url

CELL_C = "samsung30q_ageing_cellC"

#: Cycles around the overcharged cycle 300 (README: over- and undercharged cycles).
AROUND_300 = [240, 250, 260, 270, 280, 290, 300, 310, 320, 330, 340, 350, 360]


def cell_c_files(shared_data: Path, cycles) -> list[Path]:
    return [shared_data / CELL_C / f"DischargeCycle{c:03d}.txt" for c in cycles]


def integrated_Ah(path: Path) -> float:
    """Charge of the discharge in an LVM file: numpy on the raw columns (time, current)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("X_Value")) + 1
    raw = np.array([[float(x) for x in line.split("\t")[:2]] for line in lines[start:]
                    if line.strip()])
    load = raw[:, 1] < -1.0  # -3 A discharge, negative in these files
    return float(np.trapezoid(-raw[load, 1], raw[load, 0]) / 3600.0)


# --------------------------------------------------------------------------- ingest

def test_add_twice_health_and_outlier(url, shared_data):
    files = cell_c_files(shared_data, AROUND_300)
    seen = []
    with Logbook(url) as lb:
        result = lb.add(files, pack="cell C", progress=lambda d, t, m: seen.append((d, t, m)))
        assert sorted(result.added) == sorted(p.name for p in files)
        assert result.events == len(files) and not result.rejected
        # every file, then the pack's figures recomputed and stored once
        assert seen[-2][:2] == (len(files), len(files))
        assert seen[-1] == (1, 1, "figures of cell C") and lb.stale() == []
        again = lb.add(files, pack="cell C")
        assert again.added == [] and again.events == 0
        assert sorted(again.skipped) == sorted(p.name for p in files)
        assert all(line.endswith("already in the logbook") for line in again.lines())
        health = lb.health("cell C")
    data = health.to_dict()
    assert data["pack"] == "cell C"
    assert set(data["events"][0]) == {
        "source", "start", "kind", "discharged_Ah", "capacity_Ah", "capacity_interval95",
        "resistance_ohm", "efc", "outlier",  # the keys of the first release, kept
        "event_id", "event_kind", "cycle", "full", "notes",
        "capacity_method", "capacity_note", "resistance_interval95", "resistance_ref_ohm",
        "resistance_ref_interval95", "charged_Ah", "soc_start", "soc_end", "cells",
        "capacity_systematic", "capacity_own_interval95", "resistance_method"}
    assert {e["kind"] for e in data["events"]} == {"full"}
    by_name = {e["source"]: e for e in data["events"]}
    for path in files:
        event = by_name[path.name]
        truth = integrated_Ah(path)
        assert event["capacity_Ah"] == pytest.approx(truth, rel=0.01)
        lo, hi = event["capacity_interval95"]
        assert lo < event["capacity_Ah"] < hi
        assert 0.02 < event["resistance_ohm"] < 0.08  # an 18650 at ~3 A: tens of mOhm
    # README: some cycles were overcharged; cycle 300 delivers 2.62 Ah between 2.55 and 2.58
    flagged = [e["source"] for e in data["events"] if e["outlier"]]
    assert flagged == ["DischargeCycle300.txt"]
    # cycle numbers from the file names: EFC counts the cycles between logged ones
    # (cycles before the first logged one count like it; gaps take the neighbours' mean)
    efc = [e["efc"] for e in data["events"]]
    caps = [integrated_Ah(p) for p in files]
    total = AROUND_300[0] * caps[0]
    for k in range(1, len(caps)):
        total += (AROUND_300[k] - AROUND_300[k - 1] - 1) * (caps[k] + caps[k - 1]) / 2 + caps[k]
    assert efc[-1] == pytest.approx(total / caps[0], rel=1e-4)
    assert np.all(np.diff(efc) > 0)
    forecast = data["forecast"]
    assert {"threshold_Ah", "eol_efc", "eol_efc_interval95", "band"} <= set(forecast)
    band = forecast["band"]
    assert len(band["efc"]) == len(band["lo"]) == len(band["hi"]) == len(band["capacity_Ah"])
    assert all(lo <= m <= hi for lo, m, hi in zip(band["lo"], band["capacity_Ah"], band["hi"]))
    lo, hi = forecast["eol_efc_interval95"]
    assert lo < forecast["eol_efc"] and (hi is None or forecast["eol_efc"] < hi)


def test_bad_file_rejected_with_one_line_rest_goes_in(url, shared_data, tmp_path):
    folder = tmp_path / "pack A"
    folder.mkdir()
    for path in cell_c_files(shared_data, [1, 10, 20]):
        (folder / path.name).write_bytes(path.read_bytes())
    good = (folder / "DischargeCycle010.txt").read_bytes()
    (folder / "cut.txt").write_bytes(good[:400])  # cut inside the header
    lines = good.split(b"\n")
    lines[1000] = b"1000.1\t-3.0\t3.\xff\x00garbage\t-11.9\t24.1\t0.0003\t20.7\r"
    (folder / "broken.txt").write_bytes(b"\n".join(lines))  # a corrupt row mid-file
    (folder / "noise.csv").write_bytes(bytes(range(256)) * 20)
    (folder / "LICENSE").write_text("not data")
    with Logbook(url) as lb:
        result = lb.add(folder, pack_from="parent")
        assert sorted(result.added) == ["DischargeCycle001.txt", "DischargeCycle010.txt",
                                        "DischargeCycle020.txt"]
        rejected = {Path(p).name: why for p, why in result.rejected}
        assert set(rejected) == {"broken.txt", "cut.txt", "noise.csv"}
        assert all("\n" not in why and why for why in rejected.values())
        assert [r["name"] for r in lb.packs().to_dict()["rows"]] == ["pack A"]
        assert len(lb.events("pack A").rows) == 3
        with pytest.raises(LogbookError, match="no pack named 'nope'.*packs"):
            lb.health("nope")
        with pytest.raises(LogbookError, match="pack='NAME'"):
            lb.add(folder)


def test_raw_file_kept_by_hash_and_upload_deduplicated(url, shared_data):
    path = cell_c_files(shared_data, [100])[0]
    data = path.read_bytes()
    with Logbook(url) as lb:
        first = lb.add_bytes(path.name, data, pack="p")
        assert first.added == [path.name] and first.events == 1
        assert lb.add_bytes("renamed.txt", data, pack="p").skipped == ["renamed.txt"]
        assert lb.add(path, pack="p").skipped == [path.name]
        import hashlib

        assert lb.raw(hashlib.sha256(data).hexdigest()) == data


def test_flight_logs_and_dji_flights_become_flight_events(url, shared_data):
    dji = shared_data / "dji_m100_flights" / "derived_battery_19-11-28_waddle1_2019_11_28_18_28.csv"
    ina = shared_data / "flight_logs" / "ina3221_fpv_4s" / "29.csv"
    with Logbook(url) as lb:
        result = lb.add([dji, ina], pack="drone")
        assert not result.rejected
        assert result.events == 7 + 1  # README: waddle1 holds 7 flights
        rows = lb.events("drone").rows
    assert {r["kind"] for r in rows} == {"flight"}
    ina_row = next(r for r in rows if r["source"] == "29.csv")
    assert ina_row["discharged_Ah"] == pytest.approx(0.976, abs=0.01)  # README: one flight
    assert ina_row["cell_spread_V"] is not None  # the INA3221 logger measures each cell


# --------------------------------------------------------------------------- schema

V1_DDL = [
    "CREATE TABLE logbook_meta (key VARCHAR(64) PRIMARY KEY, value TEXT NOT NULL)",
    "CREATE TABLE packs (id INTEGER PRIMARY KEY, name VARCHAR(200) NOT NULL UNIQUE, "
    "\"label_capacity_Ah\" FLOAT, chemistry VARCHAR(20), cells INTEGER, "
    "created_at VARCHAR(40) NOT NULL)",
    "CREATE TABLE blobs (sha256 VARCHAR(64) PRIMARY KEY, compression VARCHAR(10) NOT NULL, "
    "size_bytes BIGINT NOT NULL, data {blob} NOT NULL)",
    "CREATE TABLE sources (id INTEGER PRIMARY KEY, sha256 VARCHAR(64) NOT NULL UNIQUE, "
    "pack_id INTEGER NOT NULL REFERENCES packs(id), file_name VARCHAR(500) NOT NULL, "
    "path TEXT, size_bytes BIGINT NOT NULL, format VARCHAR(40) NOT NULL, "
    "added_at VARCHAR(40) NOT NULL, options_json TEXT NOT NULL, notes_json TEXT NOT NULL)",
    "CREATE TABLE events (id INTEGER PRIMARY KEY, source_id INTEGER NOT NULL REFERENCES "
    "sources(id), idx INTEGER NOT NULL, pack_id INTEGER NOT NULL REFERENCES packs(id), "
    "kind VARCHAR(20) NOT NULL, start_time VARCHAR(40), duration_s FLOAT, "
    "\"discharged_Ah\" FLOAT, \"discharged_Wh\" FLOAT, \"mean_current_A\" FLOAT, "
    "\"max_current_A\" FLOAT, \"rest_voltage_V\" FLOAT, "
    "\"rest_after_V\" FLOAT, rest_after_s FLOAT, \"min_voltage_V\" FLOAT, \"end_voltage_V\" FLOAT, "
    "\"end_current_A\" FLOAT, resistance_ohm FLOAT, resistance_low_ohm FLOAT, "
    "resistance_high_ohm FLOAT, \"temperature_start_C\" FLOAT, \"temperature_max_C\" FLOAT, "
    "\"ambient_C\" FLOAT, reaches_knee BOOLEAN NOT NULL, cells INTEGER, samples INTEGER NOT NULL, "
    "curve_json TEXT NOT NULL, UNIQUE (source_id, idx))",
]


def _execute(url: str, statements: list[str]) -> None:
    from sqlalchemy import create_engine, text

    engine = create_engine(resolve_url(url))
    blob = "BYTEA" if engine.dialect.name == "postgresql" else "BLOB"
    with engine.begin() as conn:
        for sql in statements:
            conn.execute(text(sql.replace("{blob}", blob)))
    engine.dispose()


def test_version_1_database_migrates_forward(url):
    curve = json.dumps({"charge_Ah": [0.0, 1.0, 2.0], "voltage_V": [4.0, 3.6, 3.0],
                        "current_A": [2.0, 2.0, 2.0]})
    _execute(url, V1_DDL + [
        "INSERT INTO logbook_meta VALUES ('schema_version', '1')",
        "INSERT INTO packs (id, name, created_at) VALUES (1, 'old', '2024-01-01T00:00:00')",
        "INSERT INTO sources (id, sha256, pack_id, file_name, size_bytes, format, added_at, "
        "options_json, notes_json) VALUES (1, 'ab', 1, 'old.csv', 10, 'text', "
        "'2024-01-01T00:00:00', '{}', '[]')",
        "INSERT INTO events (id, source_id, idx, pack_id, kind, \"discharged_Ah\", duration_s, "
        "\"end_current_A\", reaches_knee, samples, curve_json) VALUES (1, 1, 0, 1, 'discharge', "
        f"2.0, 3600, 2.0, FALSE, 3, '{curve}')",
    ])
    with Logbook(url) as lb:
        assert lb.opened_version == 1
        rows = lb.events("old").rows
        assert rows[0]["discharged_Ah"] == 2.0 and rows[0]["cycle"] is None
    with Logbook(url) as lb:  # opened again: already current
        assert lb.opened_version == SCHEMA_VERSION


def test_newer_database_is_refused_with_one_line(url):
    Logbook(url).close()
    _execute(url, [f"UPDATE logbook_meta SET value = '{SCHEMA_VERSION + 7}' "
                   "WHERE key = 'schema_version'"])
    newer = rf"schema version {SCHEMA_VERSION + 7}, newer than .*upgrade"
    with pytest.raises(LogbookError, match=newer) as err:
        Logbook(url)
    assert "\n" not in str(err.value)


def test_not_a_database_file(tmp_path):
    path = tmp_path / "notes.sqlite"
    path.write_text("this is a text file, not a database\n" * 100)
    with pytest.raises(LogbookError, match="not a logbook database"):
        Logbook(path)


def test_export_never_replaces_the_logbook_or_a_file_it_keeps_by_path(tmp_path, shared_data):
    from dischargelab.atomic import OutputIsInputError

    db = tmp_path / "lb.sqlite"
    kept = tmp_path / "DischargeCycle001.txt"
    kept.write_bytes(cell_c_files(shared_data, [1])[0].read_bytes())
    with Logbook(db) as lb:
        lb.add(kept, pack="C", keep_raw=False)
        for target in (db, kept):
            before = target.read_bytes()
            with pytest.raises(OutputIsInputError):
                lb.export(target, force=True)
            assert target.read_bytes() == before
        assert lb.export(tmp_path / "out.csv").stat().st_size > 0


def test_cycle_numbers_come_from_the_name_but_not_from_a_date(tmp_path, shared_data):
    from dischargelab.logbook.summarise import safe_file_name, summarise_source

    data = cell_c_files(shared_data, [1])[0].read_bytes()
    for name, cycle in (("DischargeCycle042.txt", 42), ("cycle_20240501.txt", None),
                        ("Cycle-7.txt", 7)):
        assert summarise_source((name, data), keep_raw=False).events[0]["cycle"] == cycle
    assert safe_file_name("..") == safe_file_name("") == "upload"
    assert safe_file_name("C:\\logs\\run 1.bbl") == "run 1.bbl"
    assert safe_file_name("a\x00b.csv") == "a_b.csv"
    long = safe_file_name("\u00e9" * 200 + ".ulg")
    assert long.endswith(".ulg") and len(long.encode()) <= 120


def test_another_programs_sqlite_file_is_left_untouched(tmp_path):
    import sqlite3

    path = tmp_path / "shop.sqlite"
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE customers (name TEXT)")
    before = path.read_bytes()
    for create in (True, False):
        with pytest.raises(LogbookError, match="another program's SQLite database"):
            Logbook(path, create=create)
    assert path.read_bytes() == before and not (tmp_path / "shop.sqlite-wal").exists()


# --------------------------------------------------------------------------- concurrency

ADD_SCRIPT = textwrap.dedent("""
    import sys
    from dischargelab.logbook import Logbook
    url, files = sys.argv[1], sys.argv[2:]
    with Logbook(url) as lb:
        r = lb.add(files, pack="shared")
    print(len(r.added), len(r.skipped), len(r.rejected))
""")


@pytest.mark.slow
def test_two_concurrent_adds_store_each_event_once(url, shared_data):
    files = [str(p) for p in cell_c_files(shared_data, range(400, 520, 10))]
    Logbook(url).close()  # created first, so both writers find the tables
    procs = [subprocess.Popen([sys.executable, "-c", ADD_SCRIPT, url, *files],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (_out, err) in zip(procs, outs):
        assert p.returncode == 0, err
    added = [int(out.split()[0]) for out, _ in outs]
    skipped = [int(out.split()[1]) for out, _ in outs]
    assert sum(added) == len(files) and [a + s for a, s in zip(added, skipped)] == [12, 12]
    with Logbook(url) as lb:
        rows = lb.events("shared").rows
    assert len(rows) == len(files)
    assert sorted(r["source"] for r in rows) == sorted(Path(f).name for f in files)


def test_sqlite_and_postgresql_give_identical_health(pg, tmp_path, shared_data):
    files = cell_c_files(shared_data, AROUND_300[:9])
    results = []
    for url in (str(tmp_path / "a.sqlite"), pg.new_database()):
        with Logbook(url) as lb:
            lb.add(files, pack="same")
            lb.set_pack("same", label_capacity_Ah=3.0, chemistry="li-ion")
            results.append((lb.health("same").to_dict(), lb.events("same").to_dict()))
    assert results[0] == results[1]


# --------------------------------------------------------------------------- locations, extras

def test_default_location_and_environment(tmp_path, monkeypatch):
    monkeypatch.delenv("DISCHARGELAB_DB", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    if sys.platform.startswith("linux"):
        expected = tmp_path / "data" / "dischargelab" / "logbook.sqlite"
        assert resolve_url(None) == f"sqlite:///{expected}"
    monkeypatch.setenv("DISCHARGELAB_DB", str(tmp_path / "env.sqlite"))
    with Logbook() as lb:
        assert lb.url == f"sqlite:///{tmp_path / 'env.sqlite'}"
    assert (tmp_path / "env.sqlite").is_file()
    with pytest.raises(LogbookError, match="SQLite or PostgreSQL"):
        Logbook("mysql://u@h/db")


def test_import_dischargelab_does_not_import_sqlalchemy():
    code = "import sys, dischargelab; print('sqlalchemy' in sys.modules, dischargelab.Logbook)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.startswith("False")


def test_missing_extra_is_named(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "sqlalchemy", None)
    with pytest.raises(MissingExtraError, match=r"dischargelab\[logbook\]"):
        Logbook(tmp_path / "x.sqlite")


# --------------------------------------------------------------------------- pack model

def test_endurance_with_a_pack_uses_todays_capacity(tmp_path, shared_data):
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(cell_c_files(shared_data, [1, 100, 200, 300, 400, 500, 600, 664]), pack="C")
        lb.set_pack("C", chemistry="li-ion", cells=1)
        fitted = lb.fit("C", bootstrap=20)
        pack = lb.pack("C")
    last = integrated_Ah(shared_data / CELL_C / "DischargeCycle664.txt")
    assert fitted.extra["logbook_fit"]["capacity_Ah"] == pytest.approx(last, rel=1e-3)
    today = pack.battery()
    assert "scaled to its health today" in today.extra["note"]
    factor = today.extra["logbook"]["capacity_factor"]
    assert factor == pytest.approx(pack.capacity_Ah / last, rel=1e-3)
    assert today.capacity_Ah == pytest.approx(fitted.capacity_Ah * factor)
    hours = dl.predict(pack, current=3.0, cutoff=2.5, interval=False).to_dict()[
        "time_to_cutoff_s"] / 3600
    # the model at today's capacity discharges about that capacity at 3 A
    assert hours * 3.0 == pytest.approx(pack.capacity_Ah, rel=0.05)
    flown = dl.endurance(pack, "multirotor-hover", draws=10)
    assert any("scaled to its health today" in n for n in flown.to_dict()["notes"])
    fresh = dl.endurance(fitted, "multirotor-hover", draws=0)
    assert flown.to_dict()["notes"] and not fresh.to_dict()["notes"]


def test_a_high_voltage_pack_that_only_flies_flies_the_lihv_prior(tmp_path, shared_data):
    """A DJI Matrice 100 pack (6S, rests at 4.35 V per cell off the charger): today's model
    of a pack without a full discharge is the LiHV prior, starting at its full rest."""
    path = (shared_data / "dji_m100_flights"
            / "derived_battery_19-12-17_tablet1_2019_12_17_18_49.csv")
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.set_pack("m100", cells=6)
        lb.add(path, pack="m100")
        pack = lb.pack("m100")
    today = pack.battery()
    assert "LiHV" in today.extra["note"]
    assert today.voltage(np.zeros(1), np.zeros(1))[0] / 6 == pytest.approx(4.33, abs=0.01)


def test_export_csv(tmp_path, shared_data):
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(cell_c_files(shared_data, [1, 10]), pack="C")
        out = lb.export(tmp_path / "events.csv")
        import pandas as pd

        table = pd.read_csv(out)
        assert list(table["pack"]) == ["C", "C"]
        assert {"capacity_Ah", "efc", "outlier", "capacity_low_Ah"} <= set(table.columns)
        from dischargelab.atomic import OutputExistsError

        with pytest.raises(OutputExistsError):
            lb.export(out)
        if os.environ.get("CI") or _has("pyarrow"):
            parquet = lb.export(tmp_path / "events.parquet", format="parquet")
            assert pd.read_parquet(parquet)["pack"].tolist() == ["C", "C"]


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


@pytest.mark.slow
def test_every_ageing_file_and_a_test_cut_short_by_the_logger_go_in(tmp_path, shared_data):
    """All of cell C, and a copy of cycle 340 cut after 320 rows that ends with the
    logger's row of zeros (as 17 of 1,311 held-out files do): the copy goes in as a partial
    event, the row dropped and said; its charge counts in EFC; its capacity is left out
    (too little of the capacity to tell)."""
    folder = tmp_path / "cell C"
    folder.mkdir()
    files = sorted((shared_data / CELL_C).glob("DischargeCycle*.txt"))
    lines = (shared_data / CELL_C / "DischargeCycle340.txt").read_text(
        encoding="utf-8").splitlines(keepends=True)
    start = next(k for k, line in enumerate(lines) if line.startswith("X_Value")) + 1
    last_t = float(lines[start + 319].split("\t")[0])
    cut = lines[:start + 320] + [f"{last_t + 1:.6f}" + "\t0.000000" * 6 + "\n"]
    (folder / "DischargeCycle345.txt").write_text("".join(cut), encoding="utf-8")
    with Logbook(tmp_path / "lb.sqlite") as lb:
        result = lb.add([*files, folder], pack="C")
        assert not result.rejected and len(result.added) == len(files) + 1
        assert result.notes == [("DischargeCycle345.txt",
                                 "dropped 1 row at line 344, the last of the file: the logger's "
                                 "record of zeros (voltage and current 0, not a battery "
                                 "reading)")]
        assert any(line.startswith("DischargeCycle345.txt: dropped 1 row") for line in
                   result.lines())
        events = lb.health("C").events
    by_name = {e.source: e for e in events}
    cut_event = by_name["DischargeCycle345.txt"]
    assert cut_event.health_kind == "partial" and cut_event.capacity_Ah is None
    assert "too little" in (cut_event.capacity_note or "")
    raw = np.array([[float(x) for x in line.split("\t")[:2]] for line in cut[start:-1]])
    load = raw[:, 1] < -1.0
    charge = float(np.trapezoid(-raw[load, 1], raw[load, 0]) / 3600.0)
    assert cut_event.discharged_Ah == pytest.approx(charge, rel=1e-3)
    k = [e.source for e in events].index("DischargeCycle345.txt")
    before, after = events[k - 1], events[k + 1]     # cycles 340 and 350
    reference = events[0].capacity_Ah                 # EFC counts in first full discharges
    # EFC from 340 to 350: cycles 341-344 as their neighbours' mean, the cut one's own charge,
    # then 346-349 and 350 likewise
    step = (after.efc - before.efc) * reference
    expected = (4 * (before.discharged_Ah + charge) / 2 + charge
                + 4 * (charge + after.discharged_Ah) / 2 + after.discharged_Ah)
    assert step == pytest.approx(expected, rel=1e-6)
