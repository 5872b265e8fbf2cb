"""`dischargelab logbook ...` and `endurance --pack`: parse, call the library, print."""

from __future__ import annotations

import json

import pytest

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
    plot = tmp_path / "health.png"
    code, out, _ = run(capsys, "logbook", "health", "C", "--db", db, "--plot", plot)
    assert code == 0 and plot.stat().st_size > 10_000 and "end of life" in out

    code, out, _ = run(capsys, "logbook", "packs", "--db", db, "--json")
    assert [r["name"] for r in json.loads(out)["rows"]] == ["C"]
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
