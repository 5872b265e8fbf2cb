"""Missions: hand-computed endurance, max-cruise root finding, power phases, TOML errors,
uncertainty propagation and the example missions."""

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from dischargelab.cli import main as cli_main
from dischargelab.errors import DataError
from dischargelab.mission import (
    Mission,
    Phase,
    RepeatBlock,
    fixed_wing_power_W,
    hover_power_W,
    isa_air_density_kg_m3,
    load_mission,
    mission_outcomes,
    mission_summary,
    mission_uncertainty,
    run_mission,
)
from dischargelab.model import PRESETS, Battery, CellParameters
from dischargelab.simulate import Step, simulate, simulate_current, simulate_power
from dischargelab.uncertainty import sample_parameters

REPO = Path(__file__).resolve().parents[1]
MISSIONS = REPO / "src" / "dischargelab" / "data" / "missions"
HACKER = PRESETS["hacker-4100-4s-lifepo4"]

#: A Li-ion cell with a clear knee (numbers of the order of an 18650 high-drain cell).
CELL = CellParameters(E0_V=3.75, R_ohm=0.03, K_V_per_Ah=0.008, A_V=0.35, B_per_Ah=2.0,
                      C_Ah=3.1)
PACK = Battery(CELL, cells_series=4, strings_parallel=2, name="test 4S2P",
               chemistry="li-ion", fit_currents_A=(3.0, 9.0))


#: Engine steps per phase for comparisons with simulate that must agree to rounding
#: (missions and simulate fly the same engine; simulate uses at least 50).
SAME_STEPS = 50


def current_mission(phases, reserve=20.0, cutoff=3.0, battery=PACK, soc=100.0):
    return Mission(items=tuple(phases), battery=battery, cutoff_cell_V=cutoff,
                   reserve_pct=reserve, initial_soc_pct=soc, name="test")


# ---------------------------------------------------------------------------------------------
# Hand-computed endurance
# ---------------------------------------------------------------------------------------------

def test_constant_current_mission_matches_hand_calculation_and_simulate():
    # 10 A for 10 min, then 20 A until the cutoff (pack 4S2P: 5 A then 10 A per cell).
    mission = current_mission([Phase("cruise", "current", 10.0, 600.0),
                               Phase("dash", "current", 20.0, until="cutoff")], reserve=0.0)
    result = run_mission(mission)
    q1 = 10.0 * 600.0 / 3600.0                                  # pack Ah after the cruise
    cutoff_pack = 3.0 * 4
    q_cut = brentq(lambda q: PACK.voltage(20.0, q) - cutoff_pack, q1,
                   PACK.capacity_Ah * (1 - 1e-12), xtol=1e-14)
    hand = 600.0 + (q_cut - q1) * 3600.0 / 20.0
    assert result.flight_time_s == pytest.approx(hand, abs=1e-6)
    alone = simulate_current(PACK, 20.0, cutoff_cell_V=3.0, initial_charge_Ah=q1)
    assert result.flight_time_s == pytest.approx(600.0 + alone.time_to_cutoff_s, abs=1e-6)
    assert result.ended_by == "cutoff" and not result.completed
    assert result.simulation.voltage_V[-1] == pytest.approx(cutoff_pack, abs=1e-9)
    assert result.cutoff_time_s == pytest.approx(hand, abs=1e-6)


def test_fixed_mission_charge_energy_and_soc():
    phases = [Phase("a", "current", 30.0, 60.0), Phase("b", "current", 8.0, 900.0),
              Phase("c", "current", 4.0, 120.0)]
    result = run_mission(current_mission(phases), points_per_step=SAME_STEPS)
    charge = (30 * 60 + 8 * 900 + 4 * 120) / 3600.0
    assert result.completed and result.ended_by == "end"
    assert result.flight_time_s == pytest.approx(1080.0)
    assert result.simulation.capacity_Ah == pytest.approx(charge, rel=1e-12)
    assert result.soc_end_pct == pytest.approx(100 * (1 - charge / PACK.capacity_Ah))
    rows = result.phases
    assert [r["phase"] for r in rows] == ["a", "b", "c"]
    assert sum(r["charge_Ah"] for r in rows) == pytest.approx(charge, rel=1e-12)
    # the same steps through simulate (the same engine, same resolution): the same energy
    sim = simulate(PACK, [Step("current", 30, 60), Step("current", 8, 900),
                          Step("current", 4, 120)], cutoff_cell_V=3.0,
                   points_per_step=SAME_STEPS)
    assert result.simulation.energy_Wh_total == pytest.approx(sim.energy_Wh_total, rel=1e-12)


def test_initial_state_of_charge_starts_partly_discharged():
    mission = current_mission([Phase("hover", "current", 15.0, until="cutoff")], reserve=0.0,
                              soc=80.0)
    result = run_mission(mission, points_per_step=SAME_STEPS)
    ref = simulate_current(PACK, 15.0, cutoff_cell_V=3.0,
                           initial_charge_Ah=0.2 * PACK.capacity_Ah, points=SAME_STEPS)
    assert result.flight_time_s == pytest.approx(ref.time_to_cutoff_s, rel=1e-12)
    assert result.soc_pct[0] == pytest.approx(80.0)


def test_stretch_with_current_phases_matches_hand_formula():
    # only the reserve binds (low currents): d_max = (q_reserve - q_other) / I_cruise
    phases = [Phase("climb", "current", 12.0, 60.0),
              Phase("cruise", "current", 6.0, 600.0, stretch=True),
              Phase("land", "current", 3.0, 60.0)]
    mission = current_mission(phases, reserve=25.0)
    result = run_mission(mission)
    q_res = 0.75 * PACK.capacity_Ah
    hand = (q_res - (12 * 60 + 3 * 60) / 3600.0) * 3600.0 / 6.0
    assert result.stretch["binding"] == "reserve"
    assert result.stretch["max_s"] == pytest.approx(hand, abs=2e-3)
    assert result.endurance_s == pytest.approx(120.0 + hand, abs=2e-3)
    assert result.stretch["margin_s"] == pytest.approx(hand - 600.0, abs=2e-3)


# ---------------------------------------------------------------------------------------------
# Maximum cruise: remaining phases end exactly at the reserve (or the cutoff)
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["paper-table5.toml", "fixed-wing-survey.toml"])
def test_max_cruise_lands_exactly_at_reserve(name):
    mission = load_mission(MISSIONS / name)
    result = run_mission(mission)
    st = result.stretch
    assert st["binding"] == "reserve"
    k = mission.stretch_index
    at_max = replace(mission, items=tuple(replace(it, duration_s=st["max_s"]) if i == k else it
                                          for i, it in enumerate(mission.items)))
    flown = run_mission(at_max)
    assert flown.completed
    # the root is found to 1e-5 s of cruise: < 2e-6 % of the capacity at these currents
    assert flown.soc_end_pct == pytest.approx(mission.reserve_pct, abs=1e-5)
    longer = replace(at_max, items=tuple(replace(it, duration_s=st["max_s"] + 1.0) if i == k
                                         else it for i, it in enumerate(at_max.items)))
    assert run_mission(longer).soc_end_pct < mission.reserve_pct


def test_max_cruise_limited_by_cutoff_of_a_later_phase():
    # a hard go-around at 40 A (20 A/cell) after the cruise: its voltage sag binds first
    phases = [Phase("cruise", "current", 8.0, 600.0, stretch=True),
              Phase("go-around", "current", 40.0, 20.0)]
    mission = current_mission(phases, reserve=0.0)
    result = run_mission(mission)
    assert result.stretch["binding"] == "cutoff"
    at_max = replace(mission, items=(replace(phases[0], duration_s=result.stretch["max_s"]),
                                     phases[1]))
    flown = run_mission(at_max)
    assert flown.completed
    assert flown.min_voltage_V == pytest.approx(mission.cutoff_pack_V, abs=1e-4)


def test_stretch_without_planned_duration_flies_the_maximum():
    phases = [Phase("cruise", "current", 6.0, None, stretch=True),
              Phase("land", "current", 3.0, 60.0)]
    result = run_mission(current_mission(phases))
    assert result.flight_time_s == pytest.approx(result.endurance_s)
    assert result.soc_end_pct == pytest.approx(20.0, abs=1e-4)
    assert result.stretch["margin_s"] is None


def test_infeasible_mission_is_reported():
    phases = [Phase("cruise", "current", 6.0, 300.0, stretch=True),
              Phase("long loiter", "current", 10.0, 3000.0)]
    result = run_mission(current_mission(phases))
    assert result.stretch["binding"] == "infeasible" and result.stretch["max_s"] == 0.0
    assert any("cannot be completed" in w for w in result.warnings)


def test_a_current_the_pack_cannot_deliver_is_said_with_the_current_it_could():
    # 4S1P of the test cell: 60 A at take-off is far beyond it (the cutoff comes at once)
    pack = PACK.with_pack(4, 1)
    mission = current_mission([Phase("climb", "current", 5.0, 30.0),
                               Phase("dash", "current", 60.0, 10.0),
                               Phase("cruise", "current", 4.0, 300.0)], battery=pack)
    result = run_mission(mission)
    found = result.cannot_deliver
    assert result.ended_by == "cutoff" and not result.completed
    assert found["phase"] == "dash" and found["kind"] == "current" and found["load"] == 60.0
    # the limit: the pack voltage after the climb, as the dash starts, reaches the cutoff
    climb = simulate(pack, [Step("current", 5.0, 30.0)], cutoff_cell_V=3.0)
    q = climb.charge_Ah[-1]
    limit = brentq(lambda i: float(pack.voltage(i, q)) - 12.0, 0.0, 60.0, xtol=1e-9)
    assert found["max_current_A"] == pytest.approx(limit, rel=1e-6)
    assert found["soc_pct"] == pytest.approx(100 * (1 - q / pack.capacity_Ah), rel=1e-9)
    message = found["message"]
    assert message.startswith("the pack cannot deliver the 60 A of 'dash' at 99 % charge")
    assert f"at most {limit:.3g} A there" in message and "C per cell" in message
    assert result.warnings[0] == message
    assert not any("does not complete" in w for w in result.warnings)
    assert result.to_dict()["cannot_deliver"]["message"] == message
    # just under the limit the dash flies; a flight that runs down mid-phase is no such case
    ok = run_mission(current_mission([Phase("climb", "current", 5.0, 30.0),
                                      Phase("dash", "current", 0.99 * limit, 10.0)],
                                     battery=pack, reserve=0.0))
    assert ok.cannot_deliver is None and ok.phases[1]["duration_s"] > 0
    empty = run_mission(current_mission([Phase("hover", "current", 10.0, until="cutoff")],
                                        battery=pack, reserve=0.0))
    assert empty.ended_by == "cutoff" and empty.cannot_deliver is None


def test_a_power_the_pack_cannot_deliver_is_said_with_the_power_it_could():
    mission = current_mission([Phase("boost", "power", 5000.0, 5.0)])
    result = run_mission(mission)
    found = result.cannot_deliver
    assert found["kind"] == "power" and result.flight_time_s == 0.0
    # largest V * i with V = a - b i >= the cutoff, from the pack's own voltage
    a = float(PACK.voltage(0.0, 0.0))
    b = a - float(PACK.voltage(1.0, 0.0))
    i_cut = (a - 12.0) / b
    best = a * a / (4 * b) if a / 2 >= 12.0 else i_cut * 12.0
    assert found["max_power_W"] == pytest.approx(best, rel=1e-9)
    assert f"at most {best:.4g} W there" in found["message"]
    assert "cannot deliver the 5000 W of 'boost' at 100 % charge" in found["message"]


def test_a_cutoff_above_the_rest_voltage_is_said_as_such():
    result = run_mission(current_mission([Phase("hover", "current", 1.0, 60.0)], cutoff=4.5))
    assert result.cannot_deliver["max_current_A"] == 0.0
    assert "even without load its voltage" in result.cannot_deliver["message"]


def test_a_bundled_mission_is_named_not_located():
    assert load_mission("paper-table5").source == "paper-table5"
    path = MISSIONS / "paper-table5.toml"
    assert load_mission(path).source == str(path)
    assert load_mission("paper-table5").name == load_mission(path).name


# ---------------------------------------------------------------------------------------------
# Power phases use simulate's V*i = P solution
# ---------------------------------------------------------------------------------------------

def test_power_phase_until_cutoff_matches_simulate_power():
    mission = current_mission([Phase("hover", "power", 400.0, until="cutoff")], reserve=0.0)
    result = run_mission(mission, points_per_step=SAME_STEPS)
    ref = simulate_power(PACK, 400.0, cutoff_cell_V=3.0, points=SAME_STEPS)
    assert result.flight_time_s == pytest.approx(ref.time_to_cutoff_s, rel=1e-9)
    assert result.simulation.energy_Wh_total == pytest.approx(ref.energy_Wh_total, rel=1e-6)
    assert np.allclose(result.simulation.power_W, 400.0, rtol=1e-9)


def test_mixed_power_and_current_phases_match_simulate_steps():
    phases = [Phase("takeoff", "current", 40.0, 20.0), Phase("cruise", "power", 250.0, 900.0),
              Phase("land", "power", 120.0, 60.0)]
    result = run_mission(current_mission(phases), points_per_step=SAME_STEPS)
    sim = simulate(PACK, [Step("current", 40, 20), Step("power", 250, 900),
                          Step("power", 120, 60)], cutoff_cell_V=3.0,
                   points_per_step=SAME_STEPS)
    assert result.simulation.charge_Ah[-1] == pytest.approx(sim.charge_Ah[-1], rel=1e-12)
    assert result.phases[1]["mean_power_W"] == pytest.approx(250.0, rel=1e-6)


def test_until_reserve_ends_exactly_at_reserve_with_power():
    mission = current_mission([Phase("loiter", "power", 150.0, until="reserve")], reserve=30.0)
    result = run_mission(mission)
    assert result.ended_by == "reserve" and result.completed
    assert result.soc_end_pct == pytest.approx(30.0, abs=1e-6)
    assert result.reserve_time_s == pytest.approx(result.flight_time_s, abs=1e-3)


# ---------------------------------------------------------------------------------------------
# Flight-condition power: hand calculations
# ---------------------------------------------------------------------------------------------

def test_fixed_wing_power_hand_calculation():
    # V = 15 m/s, m = 2 kg, S = 0.5 m^2, CD0 = 0.025, AR = 10, e = 0.8, eta = 0.5, rho = 1.225
    # q = 0.5*1.225*15^2 = 137.8125 Pa; W = 19.6133 N; CL = W/(q S) = 0.284638
    # CD = 0.025 + 0.284638^2/(pi*0.8*10) = 0.0282237; D = q S CD = 1.944783 N
    # P = D V / eta = 58.3435 W; climbing at 2 m/s adds W*2/eta = 78.4532 W
    level = fixed_wing_power_W(15.0, 2.0, 0.5, 0.025, 10.0, 0.8, 0.5, 1.225)
    assert level == pytest.approx(58.3435, rel=1e-5)
    climb = fixed_wing_power_W(15.0, 2.0, 0.5, 0.025, 10.0, 0.8, 0.5, 1.225, climb_rate_m_s=2.0)
    assert climb - level == pytest.approx(78.4532, rel=1e-5)
    # a steep descent is a glide: no negative electric power
    assert fixed_wing_power_W(15.0, 2.0, 0.5, 0.025, 10.0, 0.8, 0.5, 1.225, -5.0) == 0.0
    # vectorised over speeds; the minimum-power speed sits where induced = parasite/3
    speeds = np.linspace(6, 30, 2401)
    power = fixed_wing_power_W(speeds, 2.0, 0.5, 0.025, 10.0, 0.8, 0.5, 1.225)
    v_best = speeds[np.argmin(power)]
    cl_best = math.sqrt(3 * math.pi * 0.8 * 10 * 0.025)    # CL at minimum power required
    v_theory = math.sqrt(2 * 2.0 * 9.80665 / (1.225 * 0.5 * cl_best))
    assert v_best == pytest.approx(v_theory, abs=0.02)


def test_hover_power_hand_calculation():
    # T = 1.5*9.80665 = 14.709975 N; T^1.5 = 56.4177; sqrt(2*1.225*0.2) = 0.7
    # P = 56.4177 / 0.7 / (0.6*0.8) = 167.910 W
    assert hover_power_W(1.5, 0.2, 0.6, 0.8, 1.225) == pytest.approx(167.910, rel=1e-5)
    # climbing at the induced velocity v_h multiplies the ideal power by (1+sqrt5)/2
    v_h = math.sqrt(14.709975 / (2 * 1.225 * 0.2))
    ratio = hover_power_W(1.5, 0.2, 0.6, 0.8, 1.225, climb_rate_m_s=2 * v_h) / \
        hover_power_W(1.5, 0.2, 0.6, 0.8, 1.225)
    assert ratio == pytest.approx(1 + math.sqrt(2), rel=1e-12)


def test_isa_density_table_values():
    # ISO 2533: sea level 1.2250, 1000 m 1.1117, tropopause (11 km geopotential) 0.36392
    for h, rho in [(0, 1.2250), (1000, 1.1117), (11000, 0.36392)]:
        assert isa_air_density_kg_m3(h) == pytest.approx(rho, abs=1e-4)
    with pytest.raises(DataError, match="altitude"):
        isa_air_density_kg_m3(20000)


def test_toml_flight_condition_phase_uses_the_formula():
    mission = load_mission(MISSIONS / "fixed-wing-survey.toml")
    survey = next(p for p in mission.phases() if p.name == "survey lines")
    rho = isa_air_density_kg_m3(400.0)
    expected = fixed_wing_power_W(15.0, 2.5, 0.45, 0.030, 2.0**2 / 0.45, 0.80, 0.55, rho)
    assert survey.kind == "power" and survey.value == pytest.approx(expected, rel=1e-12)
    assert survey.detail["lift_coefficient"] == pytest.approx(
        2.5 * 9.80665 / (0.5 * rho * 15**2 * 0.45), rel=1e-12)
    row = next(r for r in run_mission(mission).phases if r["phase"] == "survey lines")
    assert row["mean_power_W"] == pytest.approx(expected, rel=1e-6)
    assert row["flight_condition"]["speed_m_s"] == 15.0
    hover = load_mission(MISSIONS / "multirotor-hover.toml")
    block = hover.items[1]
    area = 4 * math.pi * 0.254**2 / 4
    assert block.phases[0].value == pytest.approx(hover_power_W(1.5, area, 0.6, 0.8, 1.225),
                                                  rel=1e-6)


# ---------------------------------------------------------------------------------------------
# Repeat blocks
# ---------------------------------------------------------------------------------------------

def test_repeat_count_equals_flat_expansion():
    leg, turn = Phase("leg", "power", 200.0, 50.0), Phase("turn", "current", 25.0, 10.0)
    repeated = current_mission([RepeatBlock("laps", (leg, turn), count=3)])
    flat = current_mission([leg, turn] * 3)
    a, b = run_mission(repeated), run_mission(flat)
    assert a.flight_time_s == pytest.approx(b.flight_time_s)
    assert a.soc_end_pct == pytest.approx(b.soc_end_pct, rel=1e-12)
    assert [r["repetition"] for r in a.phases] == [1, 1, 2, 2, 3, 3]


@pytest.mark.parametrize("until", ["cutoff", "reserve"])
def test_repeat_until_end(until):
    leg, turn = Phase("leg", "current", 8.0, 50.0), Phase("turn", "current", 16.0, 10.0)
    mission = current_mission([Phase("climb", "current", 20.0, 30.0),
                               RepeatBlock("laps", (leg, turn), until=until)], reserve=25.0)
    result = run_mission(mission)
    if until == "cutoff":
        assert result.ended_by == "cutoff"
        assert result.simulation.voltage_V[-1] == pytest.approx(mission.cutoff_pack_V)
    else:
        assert result.ended_by == "reserve"
        assert result.soc_end_pct == pytest.approx(25.0, abs=1e-6)
    assert result.phases[-1]["repetition"] > 10


# ---------------------------------------------------------------------------------------------
# TOML errors: one clear line each
# ---------------------------------------------------------------------------------------------

BASE = """
[battery]
source = "hacker-4100-4s-lifepo4"
"""

TOML_ERRORS = [
    ("unknown key", BASE + '[[phase]]\nname = "a"\ncurrent_A = 5\nduraton_s = 4\n',
     "unknown key 'duraton_s' (did you mean 'duration_s'?)"),
    ("missing load", BASE + '[[phase]]\nname = "a"\nduration_s = 4\n', "missing load"),
    ("negative current", BASE + '[[phase]]\nname = "a"\ncurrent_A = -5\nduration_s = 4\n',
     "current_A must be >= 0"),
    ("negative duration", BASE + '[[phase]]\nname = "a"\ncurrent_A = 5\nduration_s = -4\n',
     "duration_s must be >= 0"),
    ("two stretch", BASE + '[[phase]]\nname = "a"\ncurrent_A = 5\nstretch = true\n'
                           '[[phase]]\nname = "b"\ncurrent_A = 5\nstretch = true\n',
     "only one phase may have stretch = true"),
    ("after until", BASE + '[[phase]]\nname = "a"\ncurrent_A = 5\nuntil = "cutoff"\n'
                           '[[phase]]\nname = "b"\ncurrent_A = 5\nduration_s = 3\n',
     "nothing can follow it"),
    ("two loads", BASE + '[[phase]]\nname = "a"\ncurrent_A = 5\npower_W = 3\nduration_s = 3\n',
     "give one load"),
    ("no duration", BASE + '[[phase]]\nname = "a"\ncurrent_A = 5\n', "missing duration"),
    ("bad until", BASE + '[[phase]]\nname = "a"\ncurrent_A = 5\nuntil = "empty"\n',
     "until must be 'cutoff' or 'reserve'"),
    ("no phases", BASE, "no phases"),
    ("no aircraft", BASE + '[[phase]]\nname = "a"\nspeed_m_s = 15\nduration_s = 3\n',
     "needs an [aircraft] table"),
    ("unknown top", BASE + 'phases = 3\n[[phase]]\nname = "a"\ncurrent_A = 5\nduration_s = 3\n',
     "unknown key 'phases'"),
    ("bad reserve", BASE.replace('"\n', '"\nreserve_pct = 120\n', 1)
     + '[[phase]]\nname = "a"\ncurrent_A = 5\nduration_s = 3\n', "reserve_pct must be <="),
    ("hover on fixed wing", BASE + '[aircraft]\ntype = "fixed-wing"\nmass_kg = 2\n'
                                   'wing_area_m2 = 0.4\ncd0 = 0.03\naspect_ratio = 8\n'
                                   'span_efficiency = 0.8\npropulsion_efficiency = 0.5\n'
                                   '[[phase]]\nname = "a"\nhover = true\nduration_s = 3\n',
     "hover = true needs a multirotor"),
    ("efficiency above one", BASE + '[aircraft]\ntype = "multirotor"\nmass_kg = 2\n'
                                    'rotor_disc_area_m2 = 0.2\nfigure_of_merit = 1.4\n'
                                    'motor_efficiency = 0.8\n'
                                    '[[phase]]\nname = "a"\nhover = true\nduration_s = 3\n',
     "figure_of_merit must be <= 1"),
    ("nested repeat", BASE + '[[phase]]\nname = "r"\nrepeat = 2\nphases = [{ name = "x", '
                             'repeat = 2, phases = [] }]\n', "cannot be nested"),
    ("repeat zero", BASE + '[[phase]]\nname = "r"\nrepeat = 0\nphases = [{ name = "x", '
                           'current_A = 3, duration_s = 5 }]\n', "repeat must be >= 1"),
    ("stretch and until", BASE + '[[phase]]\nname = "a"\ncurrent_A = 5\nstretch = true\n'
                                 'until = "cutoff"\n', "cannot be combined"),
]


@pytest.mark.parametrize("label,text,message", TOML_ERRORS, ids=[t[0] for t in TOML_ERRORS])
def test_toml_errors_are_one_clear_line(tmp_path, label, text, message):
    path = tmp_path / "m.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DataError) as info:
        load_mission(path)
    text = str(info.value)
    assert message in text
    assert "\n" not in text and text.startswith(str(path))


def test_invalid_toml_syntax_and_missing_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[battery\nsource = 1\n", encoding="utf-8")
    with pytest.raises(DataError, match="not valid TOML"):
        load_mission(path)
    with pytest.raises(DataError, match="not found"):
        load_mission(tmp_path / "none.toml")


def test_cli_reports_toml_error_on_one_line(tmp_path, capsys):
    path = tmp_path / "m.toml"
    path.write_text(TOML_ERRORS[0][1], encoding="utf-8")
    with pytest.raises(SystemExit) as info:
        cli_main(["endurance", "hacker-4100-4s-lifepo4", str(path)])
    assert info.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and "duraton_s" in captured.err


def test_cli_endurance_json_and_outputs(tmp_path, capsys):
    plot, csv = tmp_path / "flight.png", tmp_path / "flight.csv"
    with pytest.raises(SystemExit) as info:
        cli_main(["endurance", "hacker-4100-4s-lifepo4", str(MISSIONS / "paper-table5.toml"),
                  "--json", "--plot", str(plot), "--csv", str(csv)])
    assert info.value.code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["completed"] and data["stretch"]["binding"] == "reserve"
    assert data["uncertainty"]["accepted"] == 0                 # a preset: model error only
    assert data["uncertainty"]["interval_includes"][0].startswith("model error (prior")
    assert plot.stat().st_size > 10_000
    import pandas as pd

    frame = pd.read_csv(csv)
    assert {"time_s", "voltage_V", "current_A", "power_W", "soc_pct", "phase"} <= set(frame)
    assert frame["soc_pct"].iloc[-1] == pytest.approx(data["soc_end_pct"])


def test_paper_table5_mission_file():
    mission = load_mission(MISSIONS / "paper-table5.toml")
    currents = [p.value for p in mission.phases()]
    assert currents == [50, 46, 28, 22, 9, 4]                  # paper Table 5
    result = run_mission(mission)
    # "the aircraft flew around 10 minutes" (paper 4.4): cruise to the cutoff ~ 10.5 min
    to_cutoff = run_mission(replace(mission, reserve_pct=0.0))
    assert 9.5 * 60 < to_cutoff.endurance_s < 11.5 * 60
    assert 8 * 60 < result.flight_time_s < 10 * 60
    # the preset is fitted at 50 A only: cruise, descent and landing are extrapolations
    assert any("extrapolation" in w and "landing" in w for w in result.warnings)


# ---------------------------------------------------------------------------------------------
# Uncertainty
# ---------------------------------------------------------------------------------------------

def with_covariance(battery, relative_sd):
    sd = relative_sd * battery.parameters.as_array()
    return replace(battery, covariance=np.diag(sd**2))


@pytest.mark.parametrize("name", ["paper-table5.toml", "fixed-wing-survey.toml",
                                  "multirotor-hover.toml"])
def test_draw_evaluation_reproduces_the_flown_mission(name):
    # the draws and the flown mission go through the same engine and the same search
    mission = load_mission(MISSIONS / name)
    flown = run_mission(mission)
    same = {k: np.repeat(v, 3) for k, v in mission.battery.parameters.items()}
    draws = mission_outcomes(mission, same)
    assert np.ptp(draws["endurance_s"]) == 0.0
    assert draws["endurance_s"][0] == pytest.approx(flown.endurance_s, rel=1e-9)
    assert draws["flight_time_s"][0] == pytest.approx(flown.flight_time_s, rel=1e-9)
    assert draws["soc_end_pct"][0] == pytest.approx(flown.soc_end_pct, rel=1e-9)
    if flown.stretch is not None:
        assert draws["max_stretch_s"][0] == pytest.approx(flown.stretch["max_s"], rel=1e-9)
        assert draws["binding"][0] == flown.stretch["binding"]


@pytest.mark.parametrize("name", ["paper-table5.toml", "fixed-wing-survey.toml"])
def test_batched_draws_agree_with_each_draw_alone(name):
    mission = load_mission(MISSIONS / name)
    battery = with_covariance(mission.battery, 0.02)
    params, _ = sample_parameters(battery, 4, seed=3)
    draws = mission_outcomes(mission, params)
    for k in range(4):
        one = CellParameters({n: float(v[k]) for n, v in params.items()})
        ref = mission_summary(mission.with_battery(replace(battery, parameters=one)))
        for key in ("endurance_s", "max_stretch_s", "soc_end_pct"):
            assert draws[key][k] == pytest.approx(ref[key], rel=1e-9)


def test_interval_contains_nominal_and_shrinks_with_covariance():
    mission = load_mission(MISSIONS / "fixed-wing-survey.toml")
    wide = mission_uncertainty(mission.with_battery(with_covariance(mission.battery, 0.02)),
                               draws=300, seed=1)
    narrow = mission_uncertainty(mission.with_battery(with_covariance(mission.battery, 0.005)),
                                 draws=300, seed=1)
    for unc in (wide, narrow):
        e = unc["endurance_s"]
        assert unc["available"] and e["low"] < e["nominal"] < e["high"]
        assert unc["interval_includes"][0] == "parameters"
        assert unc["interval_includes"][1].startswith("model error (prior, extrapolation x")
        alone = unc["parameters_only"]["endurance_s"]
        assert e["low"] < alone["low"] < alone["high"] < e["high"]   # model error widens it

    def width(u):
        return u["parameters_only"]["endurance_s"]["high"] - \
            u["parameters_only"]["endurance_s"]["low"]

    # the endurance is smooth in the parameters: 4x smaller sigma -> about 4x narrower
    assert width(narrow) < 0.4 * width(wide)
    again = mission_uncertainty(mission.with_battery(with_covariance(mission.battery, 0.02)),
                                draws=300, seed=1)
    assert again["endurance_s"] == wide["endurance_s"]            # seeded


def test_interval_from_a_real_fit_covariance(shared_data):
    from dischargelab.fit import Curve, fit_battery
    from dischargelab.io import read_discharge

    cols = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
    curves = [Curve.from_frame(*read_discharge(shared_data / "samsung30q_S001" /
                                               f"Q30_S001_{r}.csv", columns=cols))
              for r in ("1C", "4C")]
    battery = fit_battery(curves).battery
    mission = current_mission([Phase("climb", "current", 20.0, 60.0),
                               Phase("cruise", "current", 10.0, 1200.0, stretch=True),
                               Phase("land", "current", 6.0, 60.0)],
                              battery=battery.with_pack(4, 2))
    result = run_mission(mission, draws=300, seed=0)
    unc = result.uncertainty
    assert unc["available"] and unc["accepted"] == 300
    e = unc["endurance_s"]
    assert e["low"] <= result.endurance_s <= e["high"]
    # the parameters alone: a few percent wide, not zero
    alone = unc["parameters_only"]["endurance_s"]
    assert 0.002 < (alone["high"] - alone["low"]) / result.endurance_s < 0.2
    assert e["low"] < alone["low"] and alone["high"] < e["high"]
    assert unc["interval_includes"][0] == "parameters" and len(unc["interval_includes"]) == 2
    assert not any("extrapolation" in w for w in result.warnings)


def test_no_covariance_gives_the_model_error_alone():
    mission = load_mission(MISSIONS / "paper-table5.toml")
    result = run_mission(mission, draws=200)
    unc = result.uncertainty
    assert unc["available"] and unc["accepted"] == 0
    ratio = unc["model_error"]["extrapolation_ratio"]
    assert ratio > 1.5                                  # fitted at 50 A, flown at 4-46 A
    assert unc["interval_includes"] == [f"model error (prior, extrapolation x{ratio:.1f})"]
    sd = 0.015 * (1 + 2.0 * math.log(ratio))            # prior of a one-rate fit
    assert unc["model_error"]["relative_sd"] == pytest.approx(sd, rel=1e-12)
    e = unc["endurance_s"]
    assert e["low"] == pytest.approx(result.endurance_s * math.exp(-1.959964 * sd), rel=1e-6)
    assert e["high"] == pytest.approx(result.endurance_s * math.exp(1.959964 * sd), rel=1e-6)
    assert "no parameter draws" in unc["method"]
    with pytest.raises(DataError, match="no covariance"):
        sample_parameters(HACKER, 10)


def test_unphysical_draws_are_rejected():
    battery = replace(HACKER, covariance=np.diag([0, 0.005**2, 0, 0, 0, 0]))   # R ~ N(4.7, 5) mohm
    params, info = sample_parameters(battery, 400, seed=2)
    assert np.all(params.R_ohm >= 0)
    assert 0.1 < info["rejected_fraction"] < 0.3                  # P(R < 0) = 17 %
    assert any("unphysical" in w for w in info["warnings"])
