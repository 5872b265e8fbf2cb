"""Errors that do not mislead: user errors in one line, bugs shown as bugs, honest messages."""

import json
import sys

import pytest

from cli_run import run
from dischargelab.cli import BUG_LINE


def test_a_bug_is_reported_as_a_bug_with_its_traceback(capsys, monkeypatch, tmp_path):
    import dischargelab.io

    def broken(*args, **kwargs):
        raise ValueError("internal slip")

    monkeypatch.setattr(dischargelab.io, "read_discharge", broken)
    data = tmp_path / "run.csv"
    data.write_text("0,4.1\n1,4.0\n")
    code, _, err = run(capsys, "fit", data, "--current", "1")
    assert code == 1
    assert "Traceback" in err and "ValueError: internal slip" in err
    assert err.strip().splitlines()[-1] == BUG_LINE


def test_a_user_error_is_one_line_without_traceback(capsys, tmp_path):
    code, _, err = run(capsys, "fit", tmp_path / "missing.csv")
    assert code == 2
    assert err.strip() == f"error: file not found: {tmp_path / 'missing.csv'}"


@pytest.mark.parametrize("args", [["fit"], ["fit", "x.csv", "--cells", "0"], ["no-such"],
                                  ["predict", "zippy-1100-2s", "--bogus"]])
def test_usage_errors_are_one_line_with_status_2(capsys, args):
    code, _, err = run(capsys, *args)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("error: ")
    assert "--help" in err


@pytest.mark.parametrize("content, message", [
    ("this is not json", "not valid JSON"),
    ('{"name": "a pack"}', "not a battery file"),
    ('[1, 2, 3]', "not a battery file"),
    ('{"model": "tremblay", "parameters": {"E0_V": 3.7}}', "missing"),
])
def test_bad_battery_files_are_named_as_battery_files(capsys, tmp_path, content, message):
    path = tmp_path / "pack.json"
    path.write_text(content)
    for args in (["predict", path, "--current", "1", "--cutoff", "3"],
                 ["endurance", path, "paper-table5", "--draws", "0"],
                 ["curves", path, "--currents", "1", "--cutoff", "3"]):
        code, _, err = run(capsys, *args)
        assert code == 2, err
        assert err.startswith(f"error: battery file {path}: ") and message in err
        assert len(err.strip().splitlines()) == 1


def test_demo_without_matplotlib_stops_before_any_work(capsys, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    out = tmp_path / "demo"
    code, stdout, err = run(capsys, "demo", "--out", out)
    assert code == 2
    assert "pip install 'dischargelab[plot]'" in err and len(err.strip().splitlines()) == 1
    assert stdout == "" and not out.exists()


def test_virtual_device_summary_is_readable_and_json_lines(capsys, tmp_path):
    code, _, err = run(capsys, "virtual-device", "--duration", "0.5", "--link", tmp_path / "a")
    assert code == 0
    assert "{'" not in err and "frames produced" in err and "disconnects" in err
    code, out, _ = run(capsys, "virtual-device", "--duration", "0.5", "--link", tmp_path / "b",
                       "--json")
    started, stopped = [json.loads(line) for line in out.splitlines()]
    assert started["event"] == "started" and started["port"] == str(tmp_path / "b")
    assert stopped["event"] == "stopped" and "produced" in stopped["frames"]
