"""Model physics: hand-computed values, derivatives, pack scaling, battery files."""

import json

import numpy as np
import pytest

from dischargelab.errors import DataError
from dischargelab.model import (
    PRESETS,
    Battery,
    CellParameters,
    cell_voltage,
    charge_from_current,
    load_battery,
    pack_voltage,
)

P = CellParameters(E0_V=3.7, R_ohm=0.02, K_V_per_Ah=0.01, A_V=0.1, B_per_Ah=5.0, C_Ah=2.0)


def test_eq6_by_hand():
    # V = 3.7 - 0.02*1 - 0.01*2/(2-0.5)*(1+0.5) + 0.1*exp(-5*0.5)
    expected = 3.7 - 0.02 - 0.01 * (2 / 1.5) * 1.5 + 0.1 * np.exp(-2.5)
    assert cell_voltage(P, 1.0, 0.5) == pytest.approx(expected, abs=1e-12)
    assert expected == pytest.approx(3.668208500, abs=1e-9)


def test_rest_voltage_at_full_charge_is_e0_plus_a():
    assert cell_voltage(P, 0.0, 0.0) == pytest.approx(P.E0_V + P.A_V)


def test_undefined_beyond_capacity_is_minus_inf():
    v = cell_voltage(P, 1.0, np.array([1.9, 2.0, 2.5]))
    assert np.isfinite(v[0]) and np.isneginf(v[1]) and np.isneginf(v[2])


def test_filtered_current_enters_only_polarisation_resistance():
    v1 = cell_voltage(P, 1.0, 0.5, filtered_current_A=0.0)
    v2 = cell_voltage(P, 1.0, 0.5)
    assert v1 - v2 == pytest.approx(0.01 * (2 / 1.5) * 1.0)


def test_charge_integration_conserves_charge():
    t = np.linspace(0, 1000, 1001)
    q = charge_from_current(t, np.full(t.size, 3.6))
    assert q[0] == 0 and q[-1] == pytest.approx(1.0)
    # a current step: 2 A for 100 s then 4 A for 100 s -> (200 + 400) / 3600 Ah
    t2 = np.array([0, 100, 100.000001, 200])
    q2 = charge_from_current(t2, np.array([2, 2, 4, 4]))
    assert q2[-1] == pytest.approx(600 / 3600, rel=1e-6)


def test_pack_scaling():
    v = pack_voltage(P, 4.0, 1.0, cells_series=4, strings_parallel=2)
    assert v == pytest.approx(4 * cell_voltage(P, 2.0, 0.5))


def test_parameters_broadcast_for_sampling():
    samples = P.replace(R_ohm=np.array([[0.01], [0.02], [0.03]]))
    v = cell_voltage(samples, np.array([1.0, 2.0]), np.array([0.1, 0.2]))
    assert v.shape == (3, 2)
    assert v[1, 0] == pytest.approx(cell_voltage(P, 1.0, 0.1))


def test_battery_file_round_trip(tmp_path):
    cov = np.diag([1e-4, 1e-6, 1e-7, 1e-5, 1e-2, 1e-4])
    bat = Battery(P, cells_series=4, strings_parallel=2, name="test", chemistry="lipo",
                  covariance=cov, fit_currents_A=(1.0, 2.0), extra={"rmse_V": 0.01})
    path = bat.save(tmp_path / "b.json")
    back = load_battery(path)
    assert back.parameters == P
    assert back.cells_series == 4 and back.strings_parallel == 2
    np.testing.assert_allclose(back.covariance, cov)
    assert back.fit_currents_A == (1.0, 2.0)
    assert back.extra["rmse_V"] == 0.01
    assert json.loads(path.read_text())["parameters"]["C_Ah"] == 2.0


def test_presets_are_the_paper_tables():
    z = PRESETS["zippy-1100-2s"]
    assert (z.parameters.R_ohm, z.parameters.K_V_per_Ah, z.parameters.C_Ah) == (0.0373, 0.0115,
                                                                                1.075)
    h = load_battery("hacker-4100-4s-lifepo4")
    assert h.cells_series == 4 and h.parameters.B_per_Ah == 10.0354


@pytest.mark.parametrize("content, message", [
    ("{not json", "not valid JSON"),
    ('{"model": "tremblay"}', "no 'parameters'"),
    ('{"parameters": {"E0_V": 1}}', "missing"),
    ('{"model": "rc2", "parameters": {}}', "unknown model 'rc2'"),
])
def test_bad_battery_files(tmp_path, content, message):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(DataError, match=message):
        load_battery(path)


def test_missing_battery_file_names_presets(tmp_path):
    with pytest.raises(DataError, match="not found.*zippy-1100-2s"):
        load_battery(tmp_path / "nope.json")


def test_voltage_falls_during_constant_current_discharge():
    q = np.linspace(0, 1.99, 500)
    for params in (P, *(b.parameters for b in PRESETS.values())):
        qq = q * params.C_Ah / 2.0
        v = cell_voltage(params, 1.0, qq)
        assert np.all(np.diff(v) < 0)
