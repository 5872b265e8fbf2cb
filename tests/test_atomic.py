"""Never lose an input: the output policy, duplicate inputs and atomic writes."""

import json
import os
import shutil
import stat

import pytest

from cli_run import run
from dischargelab.atomic import (
    DuplicateInputError,
    OutputError,
    OutputExistsError,
    OutputIsInputError,
    atomic_path,
    check_inputs,
    check_outputs,
    write_json,
    write_text,
)

SAMSUNG_COLUMNS = "time_s=0,current_A=1,voltage_V=2"




# ------------------------------------------------------------------ library policy

def test_output_that_is_an_input_is_refused_by_path_symlink_and_inode(tmp_path):
    data = tmp_path / "run.csv"
    data.write_text("1,2\n")
    link = tmp_path / "alias.csv"
    link.symlink_to(data)
    hard = tmp_path / "hard.csv"
    os.link(data, hard)
    for output in (data, tmp_path / "." / "run.csv", link, hard):
        with pytest.raises(OutputIsInputError, match="also an input"):
            check_outputs([output], [data], force=True)


def test_existing_output_needs_force_and_two_outputs_must_differ(tmp_path):
    out = tmp_path / "b.json"
    out.write_text("{}")
    with pytest.raises(OutputExistsError, match="force=True"):
        check_outputs([out], [])
    assert check_outputs([out, None], [], force=True) == [out]
    with pytest.raises(OutputError, match="same output file"):
        check_outputs([tmp_path / "x.png", tmp_path / "x.png"], [])
    with pytest.raises(OutputError, match="folder"):
        check_outputs([tmp_path], [], force=True)


def test_duplicate_inputs_name_both_files(tmp_path):
    a = tmp_path / "a.csv"
    a.write_text("1,2\n3,4\n")
    copy = tmp_path / "copy.csv"
    shutil.copy(a, copy)
    with pytest.raises(DuplicateInputError, match="a.csv and .*a.csv are the same file"):
        check_inputs([a, a])
    with pytest.raises(DuplicateInputError, match=r"a.csv and .*copy.csv are identical copies"):
        check_inputs([a, copy])
    other = tmp_path / "b.csv"
    other.write_text("1,2\n3,5\n")
    assert check_inputs([a, other, tmp_path / "missing.csv"])[1] == other


def test_atomic_write_keeps_the_old_file_when_writing_fails(tmp_path):
    path = tmp_path / "battery.json"
    write_json(path, {"v": 1})
    with pytest.raises(RuntimeError):
        with atomic_path(path) as tmp:
            tmp.write_text('{"v": 2, "trunc')
            raise RuntimeError("crash mid-write")
    assert json.loads(path.read_text()) == {"v": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["battery.json"]  # no temporary left


def test_atomic_write_has_ordinary_permissions_and_old_import_works(tmp_path):
    from dischargelab.jsonfile import write_json as old_write_json

    path = old_write_json(tmp_path / "a.json", {"x": 1})
    text = write_text(tmp_path / "b.txt", "hello")
    umask = os.umask(0)
    os.umask(umask)
    for p in (path, text):
        assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask


# ------------------------------------------------------------------ every writing command

@pytest.fixture
def files(tmp_path, bundled_data):
    """A data file, a battery file (also under .png/.html names), a mission, calibration points."""
    from dischargelab.model import load_battery

    data = tmp_path / "run.csv"
    shutil.copy(bundled_data / "Q30_S001_1C.csv", data)
    battery = load_battery("zippy-1100-2s").save(tmp_path / "battery.json")
    shutil.copy(battery, tmp_path / "battery.png")
    shutil.copy(battery, tmp_path / "battery.html")
    mission = tmp_path / "mission.toml"
    mission.write_text('name = "hover"\n[battery]\ncutoff_cell_V = 3.0\n'
                       '[[phase]]\nname = "hover"\ncurrent_A = 5\nduration_s = 60\n')
    points = tmp_path / "points.csv"
    points.write_text("15.33,3.51\n13.16,3.01\n11.88,2.71\n7.67,1.74\n")
    return tmp_path


WRITES_ONTO_AN_INPUT = {
    "fit -o": ["fit", "{d}/run.csv", "--columns", SAMSUNG_COLUMNS, "-o", "{d}/run.csv"],
    "fit --plot": ["fit", "{d}/run.csv", "--columns", SAMSUNG_COLUMNS, "--plot", "{d}/run.csv"],
    "predict --csv": ["predict", "{d}/battery.json", "--current", "1", "--cutoff", "3",
                      "--csv", "{d}/battery.json"],
    "curves -o": ["curves", "{d}/battery.png", "--currents", "1", "--cutoff", "3",
                  "-o", "{d}/battery.png"],
    "endurance --csv": ["endurance", "{d}/battery.json", "{d}/mission.toml",
                        "--csv", "{d}/mission.toml"],
    "endurance --plot": ["endurance", "{d}/battery.png", "{d}/mission.toml",
                         "--plot", "{d}/battery.png"],
    "validate --plot": ["validate", "{d}/battery.json", "{d}/run.csv", "--cutoff", "3",
                        "--columns", SAMSUNG_COLUMNS, "--plot", "{d}/run.csv"],
    "report -o": ["report", "{d}/battery.html", "-o", "{d}/battery.html"],
    "calibrate -o": ["calibrate", "--csv", "{d}/points.csv", "-o", "{d}/points.csv"],
    "acquire --out": ["acquire", "--port", "{d}/none", "--out", "{d}/battery.json",
                      "--calibration", "{d}/battery.json"],
    "virtual-device --record": ["virtual-device", "--battery", "{d}/battery.json",
                                "--record", "{d}/battery.json", "--duration", "1"],
}


@pytest.mark.parametrize("name", list(WRITES_ONTO_AN_INPUT))
def test_no_command_writes_onto_its_input(capsys, files, name):
    args = [a.format(d=files) for a in WRITES_ONTO_AN_INPUT[name]]
    before = {p.name: p.read_bytes() for p in files.iterdir()}
    code, _, err = run(capsys, *args, "--force")
    assert code == 2, err
    assert "is also an input" in err and len(err.strip().splitlines()) == 1
    assert {p.name: p.read_bytes() for p in files.iterdir()} == before


REPLACES_AN_OUTPUT = {
    "fit -o": ["fit", "{d}/run.csv", "--columns", SAMSUNG_COLUMNS, "--bootstrap", "0",
               "-o", "{d}/old.json"],
    "fit --plot": ["fit", "{d}/run.csv", "--columns", SAMSUNG_COLUMNS, "--bootstrap", "0",
                   "--plot", "{d}/old.png"],
    "predict --plot": ["predict", "{d}/battery.json", "--current", "1", "--cutoff", "3",
                       "--plot", "{d}/old.png"],
    "curves -o": ["curves", "{d}/battery.json", "--currents", "1", "--cutoff", "3",
                  "-o", "{d}/old.png"],
    "endurance --csv": ["endurance", "{d}/battery.json", "{d}/mission.toml", "--draws", "0",
                        "--csv", "{d}/old.csv"],
    "validate --plot": ["validate", "{d}/battery.json", "{d}/run.csv", "--cutoff", "3",
                        "--columns", SAMSUNG_COLUMNS, "--plot", "{d}/old.png"],
    "report -o": ["report", "{d}/battery.json", "-o", "{d}/old.html"],
    "calibrate --plot": ["calibrate", "--csv", "{d}/points.csv", "--plot", "{d}/old.png"],
    "acquire --out": ["acquire", "--port", "{d}/none", "--ke", "4.38", "--out", "{d}/old.csv"],
    "acquire --logview": ["acquire", "--port", "{d}/none", "--ke", "4.38", "--out",
                          "{d}/new.csv", "--logview", "{d}/old.txt"],
    "virtual-device --record": ["virtual-device", "--record", "{d}/old.csv", "--duration", "1"],
}


@pytest.mark.parametrize("name", list(REPLACES_AN_OUTPUT))
def test_existing_outputs_are_kept_without_force(capsys, files, name):
    args = [a.format(d=files) for a in REPLACES_AN_OUTPUT[name]]
    target = next(files / a.rsplit("/", 1)[1] for a in args if "/old." in a)
    target.write_bytes(b"keep me")
    code, _, err = run(capsys, *args)
    assert code == 2, err
    assert "already exists" in err and "--force" in err
    assert len(err.strip().splitlines()) == 1
    assert target.read_bytes() == b"keep me"


@pytest.mark.parametrize("name", ["fit -o", "curves -o", "report -o", "endurance --csv"])
def test_force_replaces_an_existing_output(capsys, files, name):
    args = [a.format(d=files) for a in REPLACES_AN_OUTPUT[name]]
    target = next(files / a.rsplit("/", 1)[1] for a in args if "/old." in a)
    target.write_bytes(b"old")
    code, _, err = run(capsys, *args, "--force")
    assert code == 0, err
    assert target.read_bytes() != b"old" and target.stat().st_size > 100
    assert not [p for p in files.iterdir() if p.name.startswith(".")]  # no temporaries


def test_demo_refuses_to_replace_its_files_without_force(capsys, tmp_path):
    (tmp_path / "battery.json").write_text("mine")
    code, _, err = run(capsys, "demo", "--out", tmp_path)
    assert code == 2 and "battery.json already exists" in err and "--force" in err
    assert (tmp_path / "battery.json").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["battery.json"]


@pytest.mark.parametrize("twice", ["same path", "copy"])
def test_fit_refuses_the_same_discharge_twice(capsys, files, twice):
    second = files / "run.csv"
    if twice == "copy":
        second = files / "run-copy.csv"
        shutil.copy(files / "run.csv", second)
    code, _, err = run(capsys, "fit", files / "run.csv", second, "--columns", SAMSUNG_COLUMNS,
                       "-o", files / "b.json")
    assert code == 2
    assert "run.csv and" in err and second.name in err and "give each input once" in err
    assert not (files / "b.json").exists()


def test_virtual_device_link_never_replaces_a_file(capsys, tmp_path):
    keep = tmp_path / "run.csv"
    keep.write_text("measurement")
    code, _, err = run(capsys, "virtual-device", "--link", keep, "--duration", "1")
    assert code == 2 and "port link" in err
    assert keep.read_text() == "measurement"
