"""Journeys: a pack flies as what it is, a user's mission names its battery, the bundled
missions can be listed and copied, and a current given for the wrong file is named.

Each test runs the command line as a user does, on the shared data, and checks the answer
against what the data say themselves (the DJI M100 flies a 6S LiPo; the Enertech files'
durations fix their currents).
"""

from __future__ import annotations

import json
import shutil
import tomllib

import pytest

from cli_run import run

pytest.importorskip("sqlalchemy")

import dischargelab as dl
from dischargelab.cell import CUTOFF_CELL_VOLTAGE_V

LCO = "enertech_lco"


@pytest.fixture(scope="module")
def m100_db(tmp_path_factory, shared_data):
    """A logbook holding the DJI M100's logged flights as pack 'm100' (nothing set by hand)."""
    path = tmp_path_factory.mktemp("m100") / "logbook.sqlite"
    files = sorted((shared_data / "dji_m100_flights").glob("derived_battery_*.csv"))
    with dl.Logbook(str(path)) as lb:
        assert lb.add(files, pack="m100").events > 0
    return path


def check_flown_as_6s_lipo(result: dict) -> None:
    assert result["cells_series"] == 6 and result["strings_parallel"] == 1
    assert result["chemistry"] == "lipo"
    assert result["cutoff_cell_V"] == CUTOFF_CELL_VOLTAGE_V["lipo"]
    assert result["cutoff_pack_V"] == pytest.approx(6 * CUTOFF_CELL_VOLTAGE_V["lipo"])
    said = [w for w in result["warnings"] if w.startswith("paper-table5 [battery]")]
    assert len(said) == 3, result["warnings"]
    assert "series = 4" in said[0] and "6 cells" in said[0]
    assert "lifepo4" in said[1] and "lipo" in said[1]
    assert "2.5 V" in said[2] and "3 V" in said[2]


def test_a_logbook_pack_flies_as_its_own_6s_lipo_on_a_bundled_mission(
        capsys, m100_db):
    code, out, err = run(capsys, "endurance", "--pack", "m100", "paper-table5", "--db", m100_db,
                         "--draws", "0", "--json")
    assert code == 0, err
    check_flown_as_6s_lipo(json.loads(out))
    # the terminal says the same, one line per conflict
    code, out, err = run(capsys, "endurance", "--pack", "m100", "paper-table5", "--db", m100_db,
                         "--draws", "0")
    assert code == 0, err
    assert "(6S1P" in out and "3 V/cell (18.00 V pack)" in out
    assert out.count("warning: paper-table5 [battery]") == 3
    # a layout that contradicts the measured pack is refused in one line
    code, out, err = run(capsys, "endurance", "--pack", "m100", "paper-table5", "--db", m100_db,
                         "--draws", "0", "--cells", "4")
    assert code != 0 and "6 cells" in err and "--cells 4" in err
    assert len(err.strip().splitlines()) == 1


def test_the_pack_page_flies_the_same_pack(m100_db, tmp_path):
    pytest.importorskip("starlette")
    from web_helpers import ServerProcess

    server = ServerProcess(["serve", "--db", str(m100_db), "--port", "0"], cwd=tmp_path)
    try:
        status, body = server.request("POST", "/api/packs/m100/endurance",
                                      b'{"mission": "paper-table5"}',
                                      {"Content-Type": "application/json"}, timeout_s=300)
    finally:
        server.stop()
    assert status == 200, body
    result = body if isinstance(body, dict) else json.loads(body)
    check_flown_as_6s_lipo(result)


def test_a_battery_file_of_a_pack_keeps_its_layout_in_the_report(capsys, tmp_path):
    pytest.importorskip("matplotlib")
    code, out, err = run(capsys, "report", "zippy-1100-2s", "--mission", "paper-table5",
                         "--draws", "0", "-o", tmp_path / "r.html", "--json")
    assert code == 0, err
    mission = json.loads(out)["mission"]
    assert mission["cells_series"] == 2 and mission["chemistry"] == "lipo"
    assert mission["cutoff_cell_V"] == CUTOFF_CELL_VOLTAGE_V["lipo"]
    assert any("series = 4" in w for w in mission["warnings"])


def test_a_user_mission_names_its_battery_file_beside_it(capsys, tmp_path, shared_data):
    folder = tmp_path / "missions"
    folder.mkdir()
    code, _, err = run(capsys, "fit", shared_data / LCO / "1C_discharge_U.txt", "--current",
                       "2.28", "--model", "shepherd", "-o", folder / "lco.json")
    assert code == 0, err
    cell = dl.load(folder / "lco.json")
    (folder / "quad.toml").write_text(
        'name = "quad"\n\n[battery]\nsource = "lco.json"\nchemistry = "lipo"\nseries = 3\n'
        'parallel = 2\ncutoff_cell_V = 3.2\nreserve_pct = 25\n\n'
        '[[phase]]\nname = "climb"\ncurrent_A = 6\nduration_s = 30\n\n'
        '[[phase]]\nname = "hover"\ncurrent_A = 4\nstretch = true\nduration_min = 5\n',
        encoding="utf-8")
    # run from another folder: the source is relative to the mission file
    code, out, err = run(capsys, "endurance", folder / "quad.toml", "--draws", "0", "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result["cells_series"] == 3 and result["strings_parallel"] == 2
    assert result["capacity_Ah"] == pytest.approx(2 * cell.capacity_Ah)
    assert result["cutoff_cell_V"] == 3.2 and result["reserve_pct"] == 25
    assert result["warnings"] == [w for w in result["warnings"] if "[battery]" not in w]
    # a source that is not there is named with where it was looked for
    shutil.move(folder / "lco.json", tmp_path / "elsewhere.json")
    code, _, err = run(capsys, "endurance", folder / "quad.toml", "--draws", "0")
    assert code != 0 and "lco.json" in err and "beside the mission" in err


def test_missions_list_show_and_copy(capsys, tmp_path):
    code, out, err = run(capsys, "missions", "list", "--json")
    assert code == 0, err
    names = [m["name"] for m in json.loads(out)["missions"]]
    assert {"paper-table5", "fixed-wing-survey", "multirotor-hover"} <= set(names)
    code, shown, err = run(capsys, "missions", "show", "paper-table5")
    assert code == 0, err
    table = tomllib.loads(shown)["battery"]
    assert table["chemistry"] == "lifepo4" and table["cutoff_cell_V"] == 2.5
    dest = tmp_path / "mine.toml"
    assert run(capsys, "missions", "copy", "paper-table5", dest)[0] == 0
    assert dest.read_text(encoding="utf-8") == shown
    dest.write_text("edited", encoding="utf-8")
    code, _, err = run(capsys, "missions", "copy", "paper-table5", dest)
    assert code != 0 and "--force" in err and dest.read_text(encoding="utf-8") == "edited"
    assert run(capsys, "missions", "copy", "paper-table5", dest, "--force")[0] == 0
    # the copy flies as the bundled one
    code, out, err = run(capsys, "endurance", dest, "--draws", "0", "--json")
    assert code == 0, err
    assert json.loads(out)["cells_series"] == 4 and json.loads(out)["warnings"] is not None


def test_a_current_given_for_the_wrong_file_is_named(capsys, tmp_path, shared_data):
    data = shared_data / LCO
    code, _, err = run(capsys, "fit", data / "1C_discharge_U.txt", "--current", "2.28",
                       "--model", "shepherd", "-o", tmp_path / "lco.json")
    assert code == 0, err
    code, out, err = run(capsys, "validate", tmp_path / "lco.json", data / "2C_discharge_U.txt",
                         data / "0.1C_discharge_U.txt", "--current", "4.56", "--cutoff", "3.0")
    assert code == 0, err
    warned = [line for line in out.splitlines() if "that current is not this file's" in line]
    assert len(warned) == 1, out
    assert warned[0].startswith("warning: 0.1C_discharge_U.txt:") and "4.56 A" in warned[0]
    # fit checks the files against each other: the slow run cannot have drawn 2.28 A
    code, _, err = run(capsys, "fit", data / "0.1C_discharge_U.txt", data / "1C_discharge_U.txt",
                       data / "2C_discharge_U.txt", "--current", "2.28", "--model", "shepherd",
                       "-o", tmp_path / "three.json")
    assert code == 0, err
    warned = [line for line in err.splitlines() if "that current is not this file's" in line]
    assert len(warned) == 1 and warned[0].startswith("warning: 0.1C_discharge_U.txt:"), err
    # each file with its own current: no such warning
    code, out, err = run(capsys, "validate", tmp_path / "lco.json", data / "2C_discharge_U.txt",
                         data / "0.1C_discharge_U.txt", "--current", "4.56,0.228",
                         "--cutoff", "3.0", "--json")
    assert code == 0, err
    for row in json.loads(out)["files"]:
        assert not any("not this file's" in w for w in row["warnings"])


def test_cells_and_a_cutoff_that_disagree_with_the_voltages_and_the_chemistry_are_named(
        capsys, shared_data):
    flight = (shared_data / "dji_m100_flights"
              / "derived_battery_19-12-17_tablet1_2019_12_17_18_49.csv")
    code, out, err = run(capsys, "validate", "zippy-1100-2s", flight, "--cutoff", "2.5",
                         "--json")
    assert code == 0, err
    (row,) = json.loads(out)["files"]
    cells = [w for w in row["warnings"] if "per cell for 2 cells in series" in w]
    assert len(cells) == 1 and "--cells 6" in cells[0]
    cutoff = [w for w in row["warnings"] if "a cutoff of 2.5 V per cell" in w]
    assert len(cutoff) == 1 and "lipo" in cutoff[0] and "--cutoff 3" in cutoff[0]


def test_a_bench_cell_flies_in_the_pack_its_mission_was_planned_for(capsys, tmp_path,
                                                                    bundled_data):
    """multirotor-hover names its pack by `source` (a 4S LiFePO4 preset) without a `series`
    key: a cell fitted on the bench flew it as one cell (1S1P), where the mission's own
    battery and paper-table5's `series = 4` put it into four."""
    cell = tmp_path / "cell.json"
    code, _, err = run(capsys, "fit", bundled_data / "Q30_S001_1C.csv", "--columns",
                       "time_s=0,current_A=1,voltage_V=2,temperature_C=4", "--bootstrap", "0",
                       "-o", cell)
    assert code == 0, err
    planned = dl.load("hacker-4100-4s-lifepo4")
    code, out, err = run(capsys, "endurance", cell, "multirotor-hover", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert (doc["cells_series"], doc["strings_parallel"]) == (planned.cells_series,
                                                              planned.strings_parallel)
    assert planned.cells_series == 4


def test_a_pack_that_cannot_take_off_says_so_in_one_way(capsys, tmp_path, bundled_data):
    """A single 1C cell on paper-table5 (4S, a 50 A take-off): it cannot take off. The
    table showed "nan V" for voltages never reached, and the extrapolation warning said
    "far above the fitted currents" beside a ratio of x1.0 (no charge drawn to weigh)."""
    cell = tmp_path / "cell.json"
    code, _, err = run(capsys, "fit", bundled_data / "Q30_S001_1C.csv", "--columns",
                       "time_s=0,current_A=1,voltage_V=2,temperature_C=4", "--model",
                       "shepherd", "--bootstrap", "0", "-o", cell)
    assert code == 0, err
    code, out, err = run(capsys, "endurance", cell, "paper-table5", "--draws", "0")
    assert code == 0, err
    assert "cannot fly" in out + err and "nan" not in out.lower()
    ratio = [line for line in (out + err).splitlines()
             if "far above the fitted currents" in line]
    assert ratio and "(x1.0," not in ratio[0]
