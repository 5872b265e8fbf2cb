"""Command line: end to end on real files, JSON contracts, one-line errors."""

import json
import subprocess
import sys

import pytest

from cli_run import run
from dischargelab.cli import main
from dischargelab.model import PARAMETER_NAMES
from dischargelab.models import FAMILIES

SAMSUNG_COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"




@pytest.fixture(scope="module")
def battery_file(tmp_path_factory, bundled_data):
    path = tmp_path_factory.mktemp("cli") / "battery.json"
    with pytest.raises(SystemExit) as exc:
        main(["fit", str(bundled_data / "Q30_S001_1C.csv"), "--columns", SAMSUNG_COLUMNS,
              "--nominal-capacity", "3.0", "-o", str(path)])
    assert exc.value.code == 0
    return path


@pytest.fixture(scope="module")
def untested_battery(battery_file, tmp_path_factory):
    """The battery file without the cutoff its fitted run stopped at (a hand-written one)."""
    doc = json.loads(battery_file.read_text())
    assert doc.pop("tested_cutoff_cell_V") == pytest.approx(2.5, abs=0.02)
    path = tmp_path_factory.mktemp("cli") / "untested.json"
    path.write_text(json.dumps(doc))
    return path


def test_fit_json_contract(capsys, bundled_data, tmp_path):
    code, out, err = run(capsys, "fit", bundled_data / "Q30_S001_1C.csv", "--columns",
                         SAMSUNG_COLUMNS, "--json", "-o", tmp_path / "b.json",
                         "--plot", tmp_path / "fit.png")
    assert code == 0, err
    doc = json.loads(out)  # JSON alone on stdout
    # one rate with a logged temperature: the dynamic thermal family is chosen (and says why)
    assert doc["model"] == "shepherd-dynamic" and doc["cells_series"] == 1
    assert any("chosen automatically" in n for n in doc["notes"])
    names = set(FAMILIES[doc["model"]].names)
    assert set(doc["parameters"]) == names == set(doc["stderr"]) and set(PARAMETER_NAMES) < names
    assert doc["n_samples"] > 3000 and 0 < doc["rmse_V"] < 0.05
    assert isinstance(doc["warnings"], list)
    saved = json.loads((tmp_path / "b.json").read_text())
    assert saved["parameters"] == doc["parameters"]
    assert saved["source"][0]["source"].endswith("Q30_S001_1C.csv")
    assert (tmp_path / "fit.png").stat().st_size > 20_000


def test_predict_json_contract(capsys, battery_file):
    code, out, _ = run(capsys, "predict", battery_file, "--c-rate", "2", "--cutoff", "2.5",
                       "--json")
    assert code == 0
    doc = json.loads(out)
    for key in ("current_A", "cutoff_V", "time_to_cutoff_s", "capacity_Ah", "energy_Wh"):
        assert key in doc
    assert doc["current_A"] == pytest.approx(6.0)  # 2C of the nominal 3.0 Ah
    # Samsung 30Q measured 1583 s from load start to 3.0 V at 2C; to 2.5 V a bit longer
    assert 1500 < doc["time_to_cutoff_s"] < 1900


def test_predict_power_and_table(capsys, battery_file, tmp_path):
    code, out, _ = run(capsys, "predict", battery_file, "--power", "20", "--cutoff", "2.5",
                       "--plot", tmp_path / "p.png", "--csv", tmp_path / "p.csv")
    assert code == 0 and "time to cutoff" in out
    assert (tmp_path / "p.png").exists() and (tmp_path / "p.csv").read_text().startswith(
        "time_s,")


def test_curves_plot_and_json(capsys, battery_file, tmp_path):
    code, out, _ = run(capsys, "curves", battery_file, "--currents", "1,3,6,12", "--cutoff",
                       "2.5", "-o", tmp_path / "c.png", "--json")
    assert code == 0
    rows = json.loads(out)
    times = [r["time_to_cutoff_s"] for r in rows]
    assert times == sorted(times, reverse=True)
    assert (tmp_path / "c.png").stat().st_size > 20_000


def test_multi_file_fit_separates_e0_and_r(capsys, bundled_data):
    files = [bundled_data / f for f in ("Q30_S001_C10.csv", "Q30_S001_1C.csv",
                                        "Q30_S001_4C.csv")]
    code, out, _ = run(capsys, "fit", *files, "--columns", SAMSUNG_COLUMNS, "--json",
                       "--model", "shepherd", "--bootstrap", "0")
    assert code == 0
    doc = json.loads(out)
    assert doc["n_curves"] == 3 and doc["model"] == "shepherd"
    assert 0.015 < doc["parameters"]["R_ohm"] < 0.045


def test_multi_rate_auto_fit_is_physical_and_says_why(capsys, bundled_data):
    files = [bundled_data / f for f in ("Q30_S001_C10.csv", "Q30_S001_1C.csv",
                                        "Q30_S001_4C.csv")]
    code, out, _ = run(capsys, "fit", *files, "--columns", SAMSUNG_COLUMNS, "--json",
                       "--bootstrap", "0")
    assert code == 0
    doc = json.loads(out)
    assert "chosen automatically" in doc["notes"][0] and "held-out" in doc["notes"][0]
    # the bundled 3-rate fit: no parameter at a bound, RMSE <= 15 mV, held-out error <= 2 %
    assert not doc["identifiability"]["at_bounds"]
    assert doc["rmse_V"] <= 0.015
    assert max(abs(e) for e in doc["model_error"]["errors_pct"]) <= 2.0


def test_paper_mode_prints_degeneracy(capsys, shared_data):
    code, out, _ = run(capsys, "fit", shared_data / "enertech_lco" / "1C_discharge_U.txt",
                       "--current", "2.28", "--e0", "3.9", "--paper-mode")
    assert code == 0
    assert "scale together" in out and "paper mode: fitted current" in out


@pytest.mark.parametrize("args, message", [
    (["fit", "missing.csv"], "not found"),
    (["predict", "{battery}", "--current", "3", "--cutoff", "4.6"], "not below the starting"),
    (["predict", "{untested}", "--current", "3"], "give a cutoff"),
    (["predict", "{battery}", "--current", "3", "--power", "5", "--cutoff", "3"],
     "exactly one load"),
    (["curves", "{battery}", "--currents", "1,x", "--cutoff", "3"], "numbers separated"),
    (["fit", "{battery}", "--fix", "R_ohm"], "NAME=VALUE"),
])
def test_errors_are_one_line(capsys, battery_file, untested_battery, args, message):
    args = [a.replace("{battery}", str(battery_file)).replace("{untested}",
                                                               str(untested_battery))
            for a in args]
    code, out, err = run(capsys, *args)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_error_in_subprocess_has_no_traceback(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,voltage_V,current_A\n0,4.1,2\n1,nan,2\n")
    proc = subprocess.run([sys.executable, "-m", "dischargelab", "fit", str(bad)],
                          capture_output=True, text=True)
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr and proc.stderr.startswith("error:")


def test_help_has_examples(capsys):
    for command in ("fit", "predict", "curves", "demo"):
        code, out, _ = run(capsys, command, "--help")
        assert code == 0 and "Example" in out


def test_import_stays_light():
    code = ("import sys, dischargelab, dischargelab.fit, dischargelab.simulate, dischargelab.cli;"
            "bad=[m for m in ('matplotlib','serial','pymavlink') if m in sys.modules];"
            "print(bad); sys.exit(1 if bad else 0)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_the_package_and_the_command_line_load_no_numerics_until_used():
    """``import dischargelab`` and the command line's import load neither numpy, pandas nor
    scipy (a cluster's fork server starts before them); the API's names load on first use,
    and ``dischargelab.fit`` is the function even when the submodule was imported first."""
    code = ("import sys, dischargelab, dischargelab.cli;"
            "print(sorted(m for m in ('numpy', 'pandas', 'scipy') if m in sys.modules));"
            "import dischargelab.fit.auto, dischargelab.validate;"
            "print(callable(dischargelab.fit), callable(dischargelab.validate),"
            " dischargelab.Battery.__name__, 'numpy' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split("\n")[:2] == ["[]", "True True Battery True"]


def test_cutoff_defaults_to_the_chemistry_and_says_so(capsys):
    code, out, err = run(capsys, "predict", "hacker-4100-4s-lifepo4", "--current", "20",
                         "--json")
    assert code == 0
    assert json.loads(out)["cutoff_V"] == 2.5
    assert "cutoff 2.5 V/cell, the usual one for lifepo4" in err


def test_validate_without_cutoff_needs_a_chemistry(capsys, untested_battery, bundled_data):
    code, _, err = run(capsys, "validate", untested_battery, bundled_data / "Q30_S001_2C.csv",
                       "--columns", SAMSUNG_COLUMNS)
    assert code == 2 and "give a cutoff" in err and "names no chemistry" in err
    assert len(err.strip().splitlines()) == 1
