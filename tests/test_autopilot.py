"""autopilot-params: ArduPilot .param and PX4 .params files derived from the model."""

import json

import numpy as np
import pytest

from dischargelab.autopilot import autopilot_params
from dischargelab.cli import main
from dischargelab.model import Battery, CellParameters
from dischargelab.simulate import simulate_current

#: A 3 Ah Li-ion cell (shepherd parameters of the bundled Samsung 30Q 1C fit, rounded).
CELL = Battery(CellParameters(E0_V=3.45, R_ohm=0.03, K_V_per_Ah=0.012, A_V=0.6, B_per_Ah=1.2,
                              C_Ah=3.15), chemistry="li-ion", fit_currents_A=(3.0,),
               extra={"nominal_capacity_Ah": 3.0})

ARDUPILOT = {"BATT_CAPACITY", "BATT_LOW_VOLT", "BATT_CRT_VOLT", "BATT_ARM_VOLT",
             "MOT_BAT_VOLT_MAX", "MOT_BAT_VOLT_MIN"}
PX4 = {"BAT1_N_CELLS", "BAT1_V_EMPTY", "BAT1_V_CHARGED", "BAT1_R_INTERNAL", "BAT1_CAPACITY"}


def _ardupilot_file(text):
    """Parse as Mission Planner does: NAME,VALUE lines, # comments."""
    values = {}
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        name, value = line.split(",")
        values[name] = float(value)
    return values


def _qgc_file(text):
    """Parse as QGroundControl does: vehicle, component, name, value, type (tab separated)."""
    values, types = {}, {}
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        vehicle, component, name, value, kind = line.split("\t")
        assert vehicle == "1" and component == "1" and kind in ("6", "9")
        values[name] = float(value)
        types[name] = kind
    return values, types


def test_ardupilot_file_has_every_setting_in_a_consistent_order(tmp_path):
    res = autopilot_params(CELL, firmware="ardupilot", cells=4, load_current_A=6.0)
    values = _ardupilot_file(res.write(tmp_path / "b.param").read_text())
    assert ARDUPILOT <= set(values)
    assert values["BATT_CAPACITY"] == 3000  # a 3 Ah cell as a 4S pack
    assert values["MOT_BAT_VOLT_MAX"] > values["BATT_ARM_VOLT"] > values["BATT_LOW_VOLT"] \
        > values["BATT_CRT_VOLT"] > values["MOT_BAT_VOLT_MIN"] == pytest.approx(10.0)
    assert values["BATT_FS_VOLTSRC"] == 1
    assert all(f"# {name}" in res.text() for name in ARDUPILOT)  # each value explained


def test_low_voltage_leaves_the_reserve_at_the_stated_load():
    res = autopilot_params(CELL, firmware="ardupilot", cells=4, load_current_A=6.0,
                           reserve_s=120.0)
    low = res.to_dict()["parameters"]["BATT_LOW_VOLT"]
    pack = CELL.with_pack(4)
    sim = simulate_current(pack, 6.0, cutoff_cell_V=2.5)
    rest = np.array([float(pack.voltage(0.0, q)) for q in sim.charge_Ah])
    t_low = float(np.interp(-low, -rest, sim.time_s))  # rest voltage falls with time
    assert sim.time_to_cutoff_s - t_low == pytest.approx(120.0, abs=3.0)


def test_px4_file_loads_as_qgroundcontrol_params(tmp_path):
    res = autopilot_params(CELL, firmware="px4", cells=4, load_current_A=6.0)
    values, types = _qgc_file(res.write(tmp_path / "b.params").read_text())
    assert PX4 <= set(values)
    assert values["BAT1_N_CELLS"] == 4 and types["BAT1_N_CELLS"] == "6"
    assert values["BAT1_CAPACITY"] == 3000 and types["BAT1_CAPACITY"] == "9"
    assert 4.0 < values["BAT1_V_CHARGED"] < 4.3
    assert 2.8 < values["BAT1_V_EMPTY"] < values["BAT1_V_CHARGED"]
    # per-cell DC resistance: R + K C/(C - q) of eq. 6 near half charge
    assert 0.03 < values["BAT1_R_INTERNAL"] < 0.06


def test_cli_writes_once_and_refuses_to_overwrite(tmp_path, capsys):
    cell = CELL.save(tmp_path / "cell.json")
    out = tmp_path / "b.param"
    args = ["autopilot-params", str(cell), "--firmware", "ardupilot", "--cells", "4",
            "--load", "6", "-o", str(out), "--json"]
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 0
    doc = json.loads(capsys.readouterr().out)
    assert ARDUPILOT <= set(doc["parameters"]) and doc["file"] == str(out)
    before = out.read_bytes()
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2 and out.read_bytes() == before
    assert "--force" in capsys.readouterr().err


def test_a_reserve_longer_than_the_flight_is_refused():
    from dischargelab.errors import SimulationError

    with pytest.raises(SimulationError, match="reserve"):
        autopilot_params(CELL, firmware="px4", cells=4, load_current_A=30.0, reserve_s=3600)
