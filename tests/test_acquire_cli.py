"""The acquisition commands: acquire, virtual-device, demo-acquire."""

import json
import os
import subprocess
import sys

import pytest

from dischargelab.acquire.virtual_device import VirtualDevice
from dischargelab.cli import main
from dischargelab.io.logfile import read_log


def run_cli(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args)
    captured = capsys.readouterr()
    return exc.value.code, captured.out, captured.err


def test_acquire_runs_for_a_duration_and_writes_json(tmp_path, capsys):
    out = tmp_path / "run.csv"
    logview = tmp_path / "run.lvof"
    with VirtualDevice("zippy-1100-2s", speed=10, seed=11) as dev:
        code, stdout, _ = run_cli(["acquire", "--port", dev.port, "--out", str(out),
                                   "--ke", "4.38", "--cells", "2", "--rate", "5",
                                   "--current", "1.1", "--duration", "20", "--quiet",
                                   "--logview", str(logview), "--json"], capsys)
    assert code == 0
    result = json.loads(stdout)
    assert result["ended_by"] == "duration"
    data, meta = read_log(out)
    assert len(data) == result["summary"]["rows_written"] >= 100
    assert data["time_s"].iloc[-1] >= 20
    assert meta["cells_series"] == 2 and meta["current_source"] == "given"
    assert meta["source_info"]["time_scale"] == 10
    # charge from the given current over the logged time
    assert result["summary"]["charge_Ah"] == pytest.approx(1.1 * data["time_s"].iloc[-1] / 3600)
    lines = logview.read_text().splitlines()
    assert len(lines) == len(data) and lines[0].startswith("$1;1;")


def test_acquire_infers_the_cell_count_and_says_so(tmp_path, capsys):
    out = tmp_path / "run.csv"
    with VirtualDevice("hacker-4100-4s-lifepo4", current_A=4.1, speed=10, seed=12) as dev:
        code, stdout, _ = run_cli(["acquire", "--port", dev.port, "--out", str(out),
                                   "--ke", "4.38", "--chemistry", "lifepo4", "--rate", "5",
                                   "--duration", "2", "--json"], capsys)
    assert code == 0
    data, meta = read_log(out)
    assert meta["cells_series"] == 4 and meta["cells_inferred"] is True
    assert any("inferred" in e.get("message", "") for e in meta["events"])
    assert json.loads(stdout)["limits"]["cutoff_pack_V"] == pytest.approx(10.0)


def test_acquire_cutoff_exit_status_and_loud_message(tmp_path, capsys):
    out = tmp_path / "run.csv"
    with VirtualDevice("zippy-1100-2s", current_A=4.0, speed=300, seed=13) as dev:
        code, stdout, stderr = run_cli(["acquire", "--port", dev.port, "--out", str(out),
                                        "--ke", "4.38", "--cells", "2", "--rate", "2",
                                        "--no-live", "--every", "100"], capsys)
    assert code == 3
    # no relay: dischargelab never drove the load, so it must not claim to have switched it off
    assert "CUTOFF" in stderr and "load switched off" not in stderr
    assert "does not drive this load" in stderr and "switch it off by hand" in stderr
    assert "cutoff" in stdout and "not driven by dischargelab" in stdout
    _, meta = read_log(out)
    assert "cutoff" in [e["kind"] for e in meta["events"]]


def test_acquire_cutoff_switches_a_driven_load_off_and_says_so(tmp_path, capsys):
    out = tmp_path / "run.csv"
    with VirtualDevice("zippy-1100-2s", current_A=4.0, speed=300, seed=13, relay=True) as dev:
        code, stdout, stderr = run_cli(["acquire", "--port", dev.port, "--out", str(out),
                                        "--ke", "4.38", "--cells", "2", "--rate", "2",
                                        "--switch-load", "--json"], capsys)
        assert dev.load_switched_off.wait(5)
    assert code == 3
    assert "load switched off" in stderr
    assert json.loads(stdout)["load"] == "switched off"


def test_acquire_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "run.csv"
    out.write_text("keep me")
    code, stdout, stderr = run_cli(["acquire", "--port", str(tmp_path / "none"), "--out",
                                    str(out), "--ke", "4.38"], capsys)
    assert code == 2
    assert "already exists" in stderr and "--force" in stderr
    assert len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr
    assert out.read_text() == "keep me"


@pytest.mark.parametrize("args, message", [
    (["--ke", "4.38", "--calibration", "cal.json"], "either --calibration or --ke"),
    (["--ke", "4.38", "--plot"], "needs a graphical display"),
    ([], "cannot open serial port"),
    (["--ke", "4.38", "--rate", "2000"], "exceeds what 115200 baud carries"),
])
def test_acquire_bad_input_is_one_line(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if not args:
        args = ["--ke", "4.38"]
    code, _, stderr = run_cli(["acquire", "--port", str(tmp_path / "no-such-port"), "--out",
                               str(tmp_path / "x.csv"), *args], capsys)
    assert code == 2
    assert message in stderr
    assert len(stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.csv").exists()


def test_arduino_source_requires_a_gain(tmp_path, capsys):
    code, _, stderr = run_cli(["acquire", "--port", str(tmp_path / "p"), "--out",
                               str(tmp_path / "x.csv")], capsys)
    assert code == 2 and "--ke" in stderr


def test_virtual_device_command_prints_a_working_port(tmp_path):
    from dischargelab.acquire.arduino import ArduinoSource

    proc = subprocess.Popen([sys.executable, "-m", "dischargelab", "virtual-device", "--json",
                             "--speed", "5", "--duration", "60", "--link",
                             str(tmp_path / "tty")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        text = ""                                  # pretty-printed JSON: read to the brace
        while not text.rstrip().endswith("}"):
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
            text += line
        info = json.loads(text)
        assert info["port"] == str(tmp_path / "tty")
        source = ArduinoSource(info["port"], rate_Hz=5, calibration=4.38)
        samples = []
        while len(samples) < 5:
            samples += source.read(1.0)
        source.close()
        assert 6.5 < samples[0].voltage_V < 8.6            # a 2S LiPo
    finally:
        proc.terminate()
        proc.wait(30)
    assert proc.returncode == 0


def test_python_dash_m_entry_point():
    result = subprocess.run([sys.executable, "-m", "dischargelab", "acquire", "--help"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "--port" in result.stdout and "exit status" in result.stdout


@pytest.mark.slow
def test_demo_acquire_fits_the_true_model(tmp_path, capsys):
    code = None
    with pytest.raises(SystemExit) as exc:
        main(["demo-acquire", "--out", str(tmp_path), "--seconds", "8", "--json"])
    code = exc.value.code
    assert code in (0, None)
    summary = json.loads(capsys.readouterr().out)
    assert summary["ended_by"] == "cutoff"
    assert summary["logged_time_to_cutoff_s"] == pytest.approx(
        summary["expected_time_to_cutoff_s"], rel=0.03)
    # the fit reproduces the logged curve to about the ADC step (21 mV pack = 10.7 mV per cell)
    assert summary["rmse_V"] < 0.012
    # E0 - R*i is what one constant-current curve determines (DESIGN.md): within half an
    # ADC step per cell (21.4 mV / 2 cells / 2)
    assert summary["E0_minus_Ri_fitted_V"] == pytest.approx(summary["E0_minus_Ri_true_V"],
                                                            abs=0.005)
    p = {r["parameter"]: r for r in summary["parameters"]}
    assert p["C_Ah"]["fitted"] == pytest.approx(p["C_Ah"]["true"], rel=0.01)
    for name in ("K_V_per_Ah", "A_V"):
        assert p[name]["fitted"] == pytest.approx(p[name]["true"], rel=0.05)
    assert p["B_per_Ah"]["fitted"] == pytest.approx(p["B_per_Ah"]["true"], rel=0.10)
    assert os.path.exists(summary["plot"])


def test_acquire_with_an_electronic_load_source(tmp_path, capsys):
    """--source ebc-a20 goes through the same factory, pipeline and log file."""
    from dischargelab.acquire.virtual_load import VirtualEbcLoad

    out = tmp_path / "ebc.csv"
    with VirtualEbcLoad("zippy-1100-2s", frame_period_s=0.01, time_scale=600.0) as load:
        code, stdout, _ = run_cli(["acquire", "--source", "ebc-a20", "--port", load.port,
                                   "--out", str(out), "--cells", "2", "--current", "2.0",
                                   "--json"], capsys)
    result = json.loads(stdout)
    assert code == 3 and result["ended_by"] == "cutoff"
    data, meta = read_log(out)
    assert meta["source_kind"] == "ebc-a20" and meta["current_source"] == "column"
    assert data["current_A"].median() == pytest.approx(2.0, abs=0.02)
    assert data["voltage_V"].min() < 6.1           # one frame = 6 battery-seconds before the end


def test_importing_does_not_load_pyserial_or_matplotlib():
    code = ("import sys, dischargelab, dischargelab.acquire, dischargelab.cli, "
            "dischargelab.acquire.arduino, dischargelab.acquire.virtual_device; "
            "bad = [m for m in ('serial', 'matplotlib') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
