"""Garbage is not fitted: units, cell count, flat voltage and E0 checked before the fit."""

import json

import numpy as np
import pandas as pd
import pytest

from cli_run import run
from dischargelab.errors import DataError
from dischargelab.io import read_discharge
from dischargelab.plausibility import (
    PlausibilityError,
    check_discharge,
    check_discharges,
    check_e0,
    infer_cells,
    raise_for,
)

COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"




def scaled_copy(bundled_data, path, factor, header=None):
    """The bundled 1C discharge with the voltage column multiplied by ``factor``."""
    lines = (bundled_data / "Q30_S001_1C.csv").read_text(encoding="utf-8-sig").splitlines()
    rows = []
    for line in lines:
        fields = line.split(",")
        fields[2] = f"{float(fields[2]) * factor:.6g}"
        rows.append(",".join(fields))
    path.write_text("\n".join(([header] if header else []) + rows) + "\n")
    return path


@pytest.fixture
def millivolts(bundled_data, tmp_path):
    # the header says volts, the numbers are millivolts: no unit hint in the file can help
    return scaled_copy(bundled_data, tmp_path / "mv.csv", 1000.0,
                       header="time_s,current_A,voltage_V,power_W,temperature_C,strain,ambient_C")


@pytest.fixture
def pack_12s(bundled_data, tmp_path):
    return scaled_copy(bundled_data, tmp_path / "pack12s.csv", 12.0)


def test_millivolts_read_as_volts_is_caught_and_nothing_written(capsys, millivolts, tmp_path):
    out, plot = tmp_path / "b.json", tmp_path / "fit.png"
    code, stdout, err = run(capsys, "fit", millivolts, "-o", out, "--plot", plot)
    assert code == 2
    assert "millivolts" in err and "--units voltage_V=mV" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists() and not plot.exists()


def test_12s_pack_fitted_as_1s_is_caught_and_nothing_written(capsys, pack_12s, tmp_path):
    out = tmp_path / "b.json"
    code, _, err = run(capsys, "fit", pack_12s, "--columns", COLUMNS, "-o", out)
    assert code == 2
    assert "looks like a 12S pack: pass --cells 12" in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_right_cell_count_fits(capsys, pack_12s, tmp_path):
    code, _, err = run(capsys, "fit", pack_12s, "--columns", COLUMNS, "--cells", "12",
                       "--bootstrap", "0", "-o", tmp_path / "b.json")
    assert code == 0, err
    assert "looks like" not in err


def test_near_miss_is_a_warning_shown_even_quiet_or_json_and_fatal_when_strict(
        capsys, pack_12s, tmp_path):
    base = ["fit", pack_12s, "--columns", COLUMNS, "--cells", "11", "--bootstrap", "0"]
    code, _, err = run(capsys, *base, "--quiet")
    assert code == 0 and "warning:" in err and "looks like a 12S pack: pass --cells 12" in err
    code, stdout, err = run(capsys, *base, "--json")
    assert code == 0 and "looks like a 12S pack" in err
    assert any("12S" in w for w in json.loads(stdout)["data_warnings"])
    out = tmp_path / "strict.json"
    code, _, err = run(capsys, *base, "--strict", "-o", out)
    assert code == 2 and "pass --cells 12" in err and not out.exists()


def test_wild_e0_is_caught(capsys, bundled_data, tmp_path):
    code, _, err = run(capsys, "fit", bundled_data / "Q30_S001_1C.csv", "--columns", COLUMNS,
                       "--e0", "37", "-o", tmp_path / "b.json")
    assert code == 2 and "E0 per cell" in err and "--e0 3.7" in err
    assert not (tmp_path / "b.json").exists()


def test_flat_voltage_shows_no_discharge(capsys, tmp_path):
    t = np.arange(0, 3600, 10.0)
    v = 3.7 + 0.002 * np.random.default_rng(1).standard_normal(t.size)
    path = tmp_path / "flat.csv"
    pd.DataFrame({"time_s": t, "current_A": 1.0, "voltage_V": v}).to_csv(path, index=False)
    code, _, err = run(capsys, "fit", path, "-o", tmp_path / "b.json")
    assert code == 2 and "no discharge visible" in err
    assert not (tmp_path / "b.json").exists()


# ------------------------------------------------------------------ library

def test_findings_speak_of_arguments_and_give_the_fix(pack_12s):
    frame, meta = read_discharge(pack_12s, columns=COLUMNS)
    (finding,) = check_discharge(frame, meta)
    assert finding.level == "error" and finding.check == "cell_count"
    assert finding.arguments == {"cells_series": 12}
    assert finding.text().endswith("looks like a 12S pack: pass cells_series=12")
    assert finding.text({"cells_series": "--cells"}).endswith("pass --cells 12")
    with pytest.raises(PlausibilityError) as exc:
        raise_for([finding])
    assert isinstance(exc.value, DataError) and "--" not in str(exc.value)


def test_bundled_measurements_raise_nothing(bundled_data):
    loaded = [read_discharge(bundled_data / name, columns=COLUMNS)
              for name in ("Q30_S001_C10.csv", "Q30_S001_1C.csv", "Q30_S001_4C.csv")]
    assert check_discharges(loaded, chemistry="li-ion", e0_V=3.9) == []


def test_milliamperes_read_as_amperes_are_suspected():
    t = np.arange(0, 36000.0, 60.0)
    frame = pd.DataFrame({"time_s": t, "voltage_V": np.linspace(4.1, 3.0, t.size),
                          "current_A": 300.0})  # 0.3 A logged in mA: "3000 Ah"
    (finding,) = check_discharge(frame, {"source": "c10.csv"})
    assert finding.level == "warning" and finding.arguments == {"units": "current_A=mA"}


@pytest.mark.parametrize("volts, chemistry, cells", [(50.4, None, 12), (16.8, "lipo", 4),
                                                     (14.4, "lifepo4", 4), (3.0, None, 1),
                                                     (43.2, "lifepo4", 12)])
def test_infer_cells(volts, chemistry, cells):
    assert infer_cells(volts, chemistry) == cells


def test_e0_given_for_the_pack_is_explained():
    (finding,) = check_e0(14.8, cells_series=4)
    assert "3.7 V" in finding.text() and finding.arguments == {"e0_V": 3.7}
    assert check_e0(3.9) == []
