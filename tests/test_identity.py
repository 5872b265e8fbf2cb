"""A pack's identity against a mission's [battery] defaults; the mission key table and its
page; the inputs checked against each other."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dischargelab.errors import DataError, DischargelabError
from dischargelab.identity import battery_identity, resolve
from dischargelab.mission import copy_mission, load_mission, mission_catalogue, parse_mission, spec
from dischargelab.mission import keys as mission_keys
from dischargelab.model import PRESETS
from dischargelab.plausibility import check_cutoff, check_given_current

REPO = Path(__file__).resolve().parents[1]
HACKER = PRESETS["hacker-4100-4s-lifepo4"]
ZIPPY = PRESETS["zippy-1100-2s"]


def logbook_pack(battery, name="p"):
    return replace(battery, extra=dict(battery.extra, logbook={"pack": name}))


def test_a_cell_takes_the_missions_pack_and_chemistry_without_a_word():
    cell = replace(HACKER.with_pack(1, 1), chemistry=None)
    out = resolve(cell, series=4, parallel=2, chemistry="lifepo4", cutoff_cell_V=2.6)
    assert (out.battery.cells_series, out.battery.strings_parallel) == (4, 2)
    assert out.battery.chemistry == "lifepo4" and out.cutoff_cell_V == 2.6
    assert out.warnings == [] and "lifepo4" in out.notes[0]


def test_a_pack_keeps_its_layout_chemistry_and_cutoff_and_each_conflict_is_one_line():
    out = resolve(ZIPPY, where="m [battery]", series=4, parallel=1, chemistry="lifepo4",
                  cutoff_cell_V=2.5)
    assert out.battery.cells_series == ZIPPY.cells_series == 2
    assert out.battery.chemistry == "lipo" and out.cutoff_cell_V == 3.0
    assert len(out.warnings) == 3 and all("\n" not in w for w in out.warnings)
    assert "series = 4" in out.warnings[0] and "2 cells" in out.warnings[0]
    assert "lifepo4" in out.warnings[1] and "lipo" in out.warnings[1]
    assert "2.5 V" in out.warnings[2] and "3 V" in out.warnings[2]


def test_a_cutoff_for_the_same_chemistry_is_the_missions_and_a_stored_one_wins():
    assert resolve(HACKER, chemistry="lifepo4", cutoff_cell_V=2.7).cutoff_cell_V == 2.7
    own = replace(ZIPPY, extra=dict(ZIPPY.extra, cutoff_cell_V=3.3))
    out = resolve(own, cutoff_cell_V=3.1)
    assert out.cutoff_cell_V == 3.3 and "3.3 V" in out.warnings[0]
    assert battery_identity(own).cutoff_cell_V == 3.3


def test_explicit_options_win_but_a_logbook_pack_layout_cannot_change():
    assert resolve(ZIPPY, cells_given=3).battery.cells_series == 3
    assert resolve(ZIPPY, cutoff_given=3.4).cutoff_cell_V == 3.4
    pack = logbook_pack(ZIPPY.with_pack(6), "m100")
    assert battery_identity(pack).measured
    with pytest.raises(DataError, match=r"pack 'm100' has 6 cells.*--cells 4"):
        resolve(pack, cells_given=4)
    assert resolve(pack, cells_given=6).battery.cells_series == 6
    with pytest.raises(DataError, match="chemistry must be one of"):
        resolve(ZIPPY, chemistry="nimh")


def test_bundled_missions_are_consistent_with_their_own_battery():
    for row in mission_catalogue():
        m = load_mission(row["name"])
        assert m.warnings == (), row["name"]
        assert check_cutoff(m.cutoff_cell_V, m.battery.chemistry) == []


def test_a_mission_names_its_battery_beside_it_and_refuses_a_missing_one(tmp_path):
    ZIPPY.save(tmp_path / "pack.json")
    text = ('[battery]\nsource = "pack.json"\n[[phase]]\nname = "hover"\ncurrent_A = 5\n'
            'until = "cutoff"\n')
    (tmp_path / "m.toml").write_text(text)
    m = load_mission(tmp_path / "m.toml")
    assert m.battery.cells_series == 2 and m.cutoff_cell_V == 3.0
    (tmp_path / "bad.toml").write_text(text.replace("pack.json", "nope.json"))
    with pytest.raises(DataError, match="nope.json.*beside the mission"):
        load_mission(tmp_path / "bad.toml")


def test_the_parser_takes_its_keys_from_the_table_and_the_page_is_generated():
    assert spec.TOP_KEYS == mission_keys.keys_of("")
    assert spec.BATTERY_KEYS == mission_keys.keys_of("battery")
    assert spec.PHASE_KEYS == mission_keys.keys_of("phase")
    page = (REPO / "docs" / "mission-format.md").read_text(encoding="utf-8")
    assert page == mission_keys.markdown(), (
        "docs/mission-format.md differs from the parser's key table: regenerate it with "
        "python -m dischargelab.mission.keys > docs/mission-format.md")
    for key in mission_keys.KEYS:
        assert f"`{key.name}`" in page
    assert "mission-format" in (REPO / "docs" / "index.md").read_text(encoding="utf-8")


def test_an_unknown_key_is_refused_with_the_close_one():
    with pytest.raises(DataError, match="did you mean 'current_A'"):
        parse_mission({"phase": [{"name": "a", "current": 3, "duration_s": 5}]},
                      battery=ZIPPY)


def test_copy_keeps_an_existing_file_unless_forced(tmp_path):
    dest = tmp_path / "m.toml"
    copy_mission("paper-table5", dest)
    dest.write_text("mine")
    with pytest.raises(DischargelabError, match="exists"):
        copy_mission("paper-table5", dest)
    assert dest.read_text() == "mine"
    copy_mission("paper-table5", dest, force=True)
    assert "Table 5" in dest.read_text()
    with pytest.raises(DataError, match="no bundled mission"):
        copy_mission("nope", tmp_path / "x.toml")


def test_a_cutoff_of_another_chemistry_is_a_warning():
    assert check_cutoff(3.0, "lipo") == [] and check_cutoff(2.5, "lifepo4") == []
    (finding,) = check_cutoff(2.5, "lipo")
    assert finding.level == "warning" and "lipo" in finding.message
    assert check_cutoff(3.3, "lifepo4")[0].arguments == {"cutoff_cell_V": 2.5}
    assert check_cutoff(2.5, None) == []


def _run(name, hours, amps, end_V=3.0):
    t = np.linspace(0, hours * 3600, 50)
    frame = pd.DataFrame({"time_s": t, "voltage_V": np.linspace(4.1, end_V, t.size),
                          "current_A": np.full(t.size, amps)})
    return frame, {"source": f"/x/{name}", "current_source": "given"}


def test_a_given_current_that_the_duration_contradicts_is_named():
    loaded = [_run("2C.txt", 0.5, 4.56), _run("0.1C.txt", 10.0, 4.56)]
    (finding,) = check_given_current(loaded, capacity_Ah=2.28, cutoff_pack_V=3.0)
    assert finding.source == "0.1C.txt" and "4.56 A" in finding.message
    assert "x20" in finding.message
    # far too little for a run that ends at the cutoff
    (low,) = check_given_current([_run("a.txt", 0.5, 0.228)], capacity_Ah=2.28,
                                 cutoff_pack_V=3.0)
    assert low.source == "a.txt"
    # a run stopped early may deliver little: no warning
    assert check_given_current([_run("a.txt", 0.1, 4.56, end_V=3.8)], capacity_Ah=2.28,
                               cutoff_pack_V=3.0) == []
    # without a capacity: the median of three files
    three = [_run("a", 0.5, 4.56), _run("b", 1.0, 2.28), _run("c", 10.0, 2.28)]
    assert [f.source for f in check_given_current(three)] == ["c"]
    measured = [(f, dict(m, current_source="column")) for f, m in loaded]
    assert check_given_current(measured, capacity_Ah=2.28) == []


def test_the_python_api_flies_the_missions_own_battery_and_keeps_a_packs():
    import dischargelab as dl

    own = dl.endurance(None, "paper-table5", draws=0)
    assert own.mission.battery.name == HACKER.name and own.mission.warnings == ()
    zippy = dl.endurance("zippy-1100-2s", "paper-table5", draws=0).to_dict()
    assert zippy["cells_series"] == 2 and zippy["cutoff_cell_V"] == 3.0
    assert sum("paper-table5 [battery]" in w for w in zippy["warnings"]) == 3
