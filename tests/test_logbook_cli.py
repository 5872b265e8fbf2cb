"""`dischargelab logbook ...` and `endurance --pack`: parse, call the library, print."""

from __future__ import annotations

import json

import pytest

import dischargelab as dl
from cli_run import run

pytest.importorskip("sqlalchemy")

CELL_C = "samsung30q_ageing_cellC"


def test_logbook_commands_end_to_end(capsys, tmp_path, shared_data):
    db = tmp_path / "lb.sqlite"
    folder = shared_data / CELL_C
    files = [folder / f"DischargeCycle{c:03d}.txt" for c in (1, 100, 200, 300, 400, 500, 600)]
    code, out, err = run(capsys, "logbook", "add", *files, "--pack", "C", "--db", db,
                         "--chemistry", "li-ion", "--cells", "1", "--json")
    assert code == 0, err
    assert json.loads(out)["events"] == 7
    code, out, _ = run(capsys, "logbook", "add", files[0], tmp_path / "missing.csv",
                       "--pack", "C", "--db", db)
    assert code == 0
    assert "added 0 file(s), 0 event(s); 1 already in the logbook; 1 rejected" in out
    assert "DischargeCycle001.txt: already in the logbook" in out
    code, out, err = run(capsys, "logbook", "add", tmp_path / "missing.csv", "--pack", "C",
                         "--db", db)
    assert code == 2 and "missing.csv: rejected: no such file or folder" in err

    code, out, _ = run(capsys, "logbook", "health", "C", "--db", db, "--json")
    health = json.loads(out)
    assert code == 0 and health["pack"] == "C" and len(health["events"]) == 7
    assert health["forecast"]["threshold_Ah"] == pytest.approx(0.8 * health["events"][0][
        "capacity_Ah"])
    # today's figures with their intervals and the events they come from, the trends
    lo, hi = health["capacity_now_interval95"]
    assert lo < health["capacity_now_Ah"] < hi
    assert health["capacity_from"][-1]["source"] == "DischargeCycle600.txt"
    assert {"efc", "value", "lo", "hi"} <= set(health["trend"]["capacity"])
    assert {"shape", "bend_odds", "knee_efc", "band"} <= set(health["forecast"])
    plot = tmp_path / "health.png"
    code, out, _ = run(capsys, "logbook", "health", "C", "--db", db, "--plot", plot)
    assert code == 0 and plot.stat().st_size > 10_000 and "end of life" in out
    assert "capacity today (EFC" in out and "trend: " in out

    code, out, _ = run(capsys, "logbook", "packs", "--db", db, "--json")
    rows = json.loads(out)["rows"]
    assert [r["name"] for r in rows] == ["C"]
    assert rows[0]["capacity_interval95"] == pytest.approx(health["capacity_now_interval95"])
    code, out, _ = run(capsys, "logbook", "events", "C", "--db", db)
    assert code == 0 and "Events of C" in out
    code, out, _ = run(capsys, "logbook", "events", "C", "--db", db, "--json")
    assert json.loads(out)["events"][-1]["source"] == "DischargeCycle600.txt"
    csv = tmp_path / "all.csv"
    assert run(capsys, "logbook", "export", csv, "--db", db)[0] == 0
    code, _, err = run(capsys, "logbook", "export", csv, "--db", db)
    assert code == 2 and "--force" in err and len(err.strip().splitlines()) == 1

    code, out, err = run(capsys, "logbook", "fit", "C", "--db", db, "--bootstrap", "0")
    assert code == 0, err
    code, out, err = run(capsys, "endurance", "--pack", "C", "--db", db, "paper-table5",
                         "--cells", "4", "--draws", "0", "--json")
    assert code == 0, err
    assert any("scaled to its health today" in n for n in json.loads(out)["notes"])


def test_unknown_pack_and_newer_database_are_one_line_errors(capsys, tmp_path):
    db = tmp_path / "lb.sqlite"
    for command in (["logbook", "packs"], ["logbook", "health", "nope"]):
        code, _, err = run(capsys, *command, "--db", db)
        assert code == 2 and err.strip() == (f"error: no logbook at {db}: adding files creates "
                                             "one (Logbook.add, `dischargelab logbook add`)")
    assert not db.exists()  # reading a mistyped path creates nothing
    code, out, _ = run(capsys, "logbook", "add", tmp_path / "missing.csv", "--pack", "C",
                       "--db", db)
    assert code == 2 and db.exists()
    code, _, err = run(capsys, "logbook", "health", "nope", "--db", db)
    assert code == 2 and err.strip().startswith("error: no pack named 'nope'")
    assert len(err.strip().splitlines()) == 1
    code, _, err = run(capsys, "endurance", "--pack", "nope", "--db", db, "a.toml", "b.toml")
    assert code == 2 and "MISSION alone" in err


FLIGHTS = "flight_logs/ina3221_fpv_4s"


def test_a_pack_that_only_flies_gets_endurance_and_autopilot_settings(capsys, tmp_path,
                                                                      shared_data):
    """No full discharge, no fitted model: the chemistry's prior at today's capacity (from
    the flights themselves, between their rests) and resistance, said in the notes with
    the events those come from."""
    db = tmp_path / "lb.sqlite"
    flights = sorted((shared_data / FLIGHTS).glob("*.csv"))
    # a LiPo pack, said so: its rests read through the LiPo curve
    code, _, err = run(capsys, "logbook", "add", *flights, "--pack", "fpv", "--chemistry",
                       "lipo", "--db", db)
    assert code == 0, err
    with dl.Logbook(db) as lb:
        today = lb.pack("fpv").capacity_Ah
    assert 1.0 < today < 1.6                        # a 1.5 Ah 4S pack, from its flights
    code, out, err = run(capsys, "endurance", "--pack", "fpv", "--db", db, "multirotor-hover",
                         "--draws", "0", "--json")
    assert code == 0, err
    note = next(n for n in json.loads(out)["notes"] if "logbook pack 'fpv'" in n)
    assert "lipo prior" in note and "no fitted model" in note
    assert "capacity today" in note and "resistance" in note
    assert flights[-1].name in note                 # the events it comes from
    code, out, err = run(capsys, "autopilot-params", "--pack", "fpv", "--db", db,
                         "--firmware", "ardupilot", "--load", "15", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert any("logbook pack 'fpv'" in n for n in doc["notes"])
    settings = doc["parameters"]
    assert settings["BATT_CAPACITY"] == pytest.approx(1000 * today, abs=1)
    assert 4 * 3.0 < settings["BATT_LOW_VOLT"] < 4 * 4.2  # a 4S pack, read from the logs
    code, _, err = run(capsys, "autopilot-params", "--firmware", "px4")
    assert code == 2 and "--pack NAME" in err
