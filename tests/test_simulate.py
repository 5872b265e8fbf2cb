"""Simulation: root-found cutoff, constant power, profiles, invariants, errors."""

import numpy as np
import pytest

from dischargelab.errors import SimulationError
from dischargelab.model import PRESETS, Battery, CellParameters, cell_voltage
from dischargelab.simulate import Step, curve_family, simulate, simulate_current, simulate_power

CELL = Battery(CellParameters(3.75, 0.03, 0.008, 0.35, 2.0, 3.1))
PACK = CELL.with_pack(4, 2)


def test_constant_current_cutoff_is_a_root():
    r = simulate_current(CELL, 3.0, cutoff_cell_V=3.0)
    q_cut = 3.0 * r.time_to_cutoff_s / 3600
    assert cell_voltage(CELL.parameters, 3.0, q_cut) == pytest.approx(3.0, abs=1e-9)
    assert r.capacity_Ah == pytest.approx(q_cut, rel=1e-12)
    assert r.ended_by == "cutoff"
    assert np.all(np.diff(r.voltage_V) < 0)


def test_energy_is_integral_of_power():
    r = simulate_current(CELL, 3.0, cutoff_cell_V=3.0, points=4000)
    mean_v = np.trapezoid(r.voltage_V, r.time_s) / r.time_s[-1]
    assert r.energy_Wh_total == pytest.approx(mean_v * r.capacity_Ah, rel=1e-4)


def test_pack_is_cells_times_cell():
    cell = simulate_current(CELL, 3.0, cutoff_cell_V=3.0)
    pack = simulate_current(PACK, 6.0, cutoff_cell_V=3.0)  # 2 strings: 3 A per cell
    assert pack.time_to_cutoff_s == pytest.approx(cell.time_to_cutoff_s, rel=1e-9)
    assert pack.capacity_Ah == pytest.approx(2 * cell.capacity_Ah, rel=1e-9)
    assert pack.energy_Wh_total == pytest.approx(8 * cell.energy_Wh_total, rel=1e-6)
    assert pack.to_dict()["cutoff_pack_V"] == pytest.approx(12.0)


def test_constant_power_holds_power_and_matches_its_current_twin():
    r = simulate_power(CELL, 10.0, cutoff_cell_V=3.0)
    np.testing.assert_allclose(r.power_W, 10.0, rtol=1e-9)
    assert np.all(np.diff(r.current_A) > 0)  # voltage falls, current rises
    assert r.energy_Wh_total == pytest.approx(10.0 * r.time_to_cutoff_s / 3600, rel=1e-3)
    # the charge delivered equals the integral of the current
    q = np.trapezoid(r.current_A, r.time_s) / 3600
    assert r.capacity_Ah == pytest.approx(q, rel=1e-3)


def test_power_beyond_maximum_is_refused_and_limit_detected():
    with pytest.raises(SimulationError, match="cannot deliver"):
        simulate_power(CELL, 500.0, cutoff_cell_V=2.0)
    r = simulate_power(CELL, 80.0, cutoff_cell_V=0.5)
    assert r.ended_by == "power limit"


def test_time_to_cutoff_shrinks_as_current_grows():
    times = [simulate_current(CELL, i, cutoff_cell_V=3.0).time_to_cutoff_s
             for i in (0.5, 1, 2, 4, 8)]
    assert np.all(np.diff(times) < 0)
    caps = [r.capacity_Ah for r in curve_family(CELL, [0.5, 1, 2, 4, 8], cutoff_cell_V=3.0)]
    assert np.all(np.diff(caps) < 0)


def test_profile_conserves_charge_and_time():
    steps = [Step("current", 5.0, 60.0, "takeoff"), Step("power", 8.0, 120.0, "climb"),
             Step("rest", 0.0, 30.0), Step("current", 2.0, 300.0, "cruise")]
    r = simulate(CELL, steps, cutoff_cell_V=3.0)
    assert r.ended_by == "end" and np.isnan(r.time_to_cutoff_s)
    assert r.duration_s == pytest.approx(510.0)
    q_expected = (5.0 * 60 + 2.0 * 300) / 3600 + np.trapezoid(
        r.current_A[r.step == 1], r.time_s[r.step == 1]) / 3600
    assert r.capacity_Ah == pytest.approx(q_expected, rel=1e-3)
    df = r.to_pandas()
    assert list(df["step"].unique()) == ["takeoff", "climb", "rest", "cruise"]


def test_profile_stops_at_cutoff_inside_a_step():
    r = simulate(CELL, [Step("current", 3.0, 1e6)], cutoff_cell_V=3.0)
    ref = simulate_current(CELL, 3.0, cutoff_cell_V=3.0)
    assert r.ended_by == "cutoff"
    assert r.time_to_cutoff_s == pytest.approx(ref.time_to_cutoff_s, rel=1e-9)


def test_partial_state_of_charge_shortens_discharge():
    full = simulate_current(CELL, 3.0, cutoff_cell_V=3.0)
    half = simulate_current(CELL, 3.0, cutoff_cell_V=3.0, initial_charge_Ah=1.0)
    assert half.time_to_cutoff_s == pytest.approx(full.time_to_cutoff_s - 1200, rel=1e-9)


@pytest.mark.parametrize("kwargs, message", [
    ({"cutoff_cell_V": 4.5}, "not below the starting voltage"),
    ({}, "exactly one cutoff"),
    ({"cutoff_cell_V": 3.0, "cutoff_pack_V": 12.0}, "exactly one cutoff"),
    ({"cutoff_cell_V": 3.0, "initial_charge_Ah": 3.2}, r"q >= C|must be in"),
])
def test_impossible_requests(kwargs, message):
    with pytest.raises(SimulationError, match=message):
        simulate_current(CELL, 3.0, **kwargs)


def test_bad_steps():
    with pytest.raises(SimulationError, match="kind"):
        Step("charge", 1.0)
    with pytest.raises(SimulationError, match="discharge positive"):
        Step("current", -1.0)
    with pytest.raises(SimulationError, match="rest step needs a duration"):
        Step("rest")


def test_paper_presets_simulate():
    for bat in PRESETS.values():
        r = simulate_current(bat, bat.fit_currents_A[0], cutoff_cell_V=2.5)
        assert 0.8 < r.capacity_Ah / bat.parameters.C_Ah < 1.0


def test_a_longer_longest_step_keeps_the_time_to_cutoff():
    """The engine's 60 s longest step bounds a slow discharge's steps; lifted (as the
    fit's held-out checks do), a C/10 discharge takes its 50 points and reaches the same
    cutoff: exactly for an isothermal cell, to 1e-4 with self-heating."""
    from dataclasses import replace

    from dischargelab.models import get_family

    slow = dict(cutoff_cell_V=3.0, points=50)
    capped = simulate_current(CELL, 0.31, **slow)
    free = simulate_current(CELL, 0.31, max_step_s=float("inf"), **slow)
    assert capped.time_s.size > 500 and free.time_s.size < 60
    assert free.time_to_cutoff_s == pytest.approx(capped.time_to_cutoff_s, rel=1e-9)
    thermal = get_family("shepherd-thermal")
    warm = replace(CELL, model="shepherd-thermal", parameters=CellParameters(dict(
        thermal.defaults(), **CELL.parameters.as_dict(), Cth_J_per_K=45.0,
        Rth_K_per_W=20.0)))
    capped = simulate_current(warm, 1.0, **slow)
    free = simulate_current(warm, 1.0, max_step_s=float("inf"), **slow)
    assert capped.peak_temperature_C > warm.ambient_C + 0.5
    assert free.time_to_cutoff_s == pytest.approx(capped.time_to_cutoff_s, rel=1e-4)
