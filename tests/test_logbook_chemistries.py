"""A pack's chemistry and its curve read, not assumed: a single high-voltage LiPo cell
counted as one cell, a LiFePO4 pack of no given chemistry read from its loads with its
full discharges found on its own voltages, and the drop added back to a slow full
discharge read where the open-circuit voltage is known when a steep fall from full would
otherwise pass for resistance."""

from __future__ import annotations

import numpy as np
import pytest

from dischargelab.flight import infer_cells
from dischargelab.logbook.references import checked_drop, rest_drop, settled_drop


@pytest.mark.parametrize("volts, cells", [(4.34, 1), (8.70, 2), (4.20, 1), (16.8, 4),
                                          (4 * 3.7, 4), (25.2, 6)])
def test_a_high_voltage_cell_is_not_counted_as_two(volts, cells):
    # 4.34 V was read as 2 cells at 2.17 V each: below any lithium cell's highest rest
    assert infer_cells([volts]) == cells


def _slow_discharge(top_fall_V: float, r_ohm: float = 0.04, current_A: float = 0.6,
                    capacity_Ah: float = 3.0):
    """A slow full discharge over a flat curve (3.3 V at half charge, 0.1 V per unit of
    charge) whose top falls ``top_fall_V`` over its last per cent (a LiFePO4 cell's),
    and the open-circuit voltage it was drawn from."""
    def ocv(soc):
        soc = np.asarray(soc, dtype=float)
        return 3.3 + 0.1 * (soc - 0.5) + top_fall_V * np.exp(-(1.0 - soc) / 0.004)

    q = np.linspace(0.0, capacity_Ah, 3001)
    volts = ocv(1.0 - q / capacity_Ah) - r_ohm * current_A
    event = {"kind": "discharge", "mean_current_A": current_A,
             "rest_voltage_V": float(ocv(1.0)),
             "curve": {"charge_Ah": q.tolist(), "voltage_V": volts.tolist(),
                       "current_A": [current_A] * q.size}}
    return event, ocv


def _load_from_full(counted_Ah: float, relaxed_V: float) -> dict:
    return {"kind": "flight", "rest_after_s": 900.0,
            "details": {"counted_Ah": counted_Ah,
                        "rest_before": {"after_charge": {"taper": True}},
                        "rest_after": {"relaxed_V": relaxed_V}}}


def test_a_steep_fall_from_full_is_not_read_as_resistance():
    event, ocv = _slow_discharge(top_fall_V=0.25)
    # the settled drop's extrapolation from 300 s in takes the fall for resistance
    assert settled_drop(event) > 3 * 0.04
    rests = [(q, float(ocv(1.0 - q / 3.0))) for q in (1.8, 2.0, 2.1)]
    drop, scatter = rest_drop(event, rests)
    assert drop == pytest.approx(0.04, rel=0.02) and scatter < 0.005
    ordered = [event] + [_load_from_full(q, v) for q, v in rests]
    full = lambda charge: bool(charge and charge.get("taper"))  # noqa: E731
    assert checked_drop(ordered, 0, event, 1, full) == pytest.approx(0.04, rel=0.02)
    # no load from full after it: the settled drop, as before
    assert checked_drop([event], 0, event, 1, full) == settled_drop(event)


def test_a_curve_without_a_steep_top_keeps_its_settled_drop():
    event, ocv = _slow_discharge(top_fall_V=0.0)
    rests = [(q, float(ocv(1.0 - q / 3.0))) for q in (1.8, 2.0, 2.1)]
    ordered = [event] + [_load_from_full(q, v) for q, v in rests]
    full = lambda charge: bool(charge and charge.get("taper"))  # noqa: E731
    assert settled_drop(event) == pytest.approx(0.04, rel=0.05)
    assert checked_drop(ordered, 0, event, 1, full) == settled_drop(event)


def test_rests_that_disagree_among_themselves_leave_the_settled_drop():
    event, ocv = _slow_discharge(top_fall_V=0.1)
    # rests 0-150 mV off the curve (relaxation left): their scatter is larger than the gap
    rests = [(q, float(ocv(1.0 - q / 3.0)) + off)
             for q, off in ((1.6, 0.0), (1.8, 0.15), (2.0, 0.05), (2.1, 0.10))]
    ordered = [event] + [_load_from_full(q, v) for q, v in rests]
    full = lambda charge: bool(charge and charge.get("taper"))  # noqa: E731
    drop, scatter = rest_drop(event, rests)
    assert abs(drop - settled_drop(event)) < scatter
    assert checked_drop(ordered, 0, event, 1, full) == settled_drop(event)
    # fewer than three rests give no scatter: no reading
    assert rest_drop(event, rests[:2]) is None


@pytest.mark.slow
def test_a_lifepo4_pack_of_no_given_chemistry_is_read_as_one(tmp_path):
    from dischargelab.logbook import Logbook
    from synthetic_life import LifeSpec, synthetic_life

    life = synthetic_life(LifeSpec(cycles=6, test_every=5, chemistry="lifepo4", cv_V=3.65,
                                   test_cv_V=3.65, fade_per_efc=3e-3, ocv_wiggle_V=0.008,
                                   seed=2))
    path = tmp_path / "life.csv"
    life.frame[life.frame["time_s"] < life.tests[1][0]].to_csv(path, index=False)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.set_pack("cell")
        lb.add(path, pack="cell")
        health = lb.health("cell")
    # the capacity test from a 3.6 V rest is a full discharge on LiFePO4's voltages (on
    # a 4.2 V curve that rest is empty), and it measures the capacity
    fulls = [e for e in health.events if e.full]
    assert len(fulls) == 1
    assert fulls[0].capacity_Ah == pytest.approx(life.tests[0][2], rel=0.01)
    # the missions between rests read through the pack's curve within 5 % of the truth
    caps = [e.capacity_Ah for e in health.events
            if e.kind == "discharge" and not e.full and e.capacity_Ah is not None]
    assert caps and abs(np.median(caps) / life.tests[1][2] - 1) < 0.05
    low, high = health.today["capacity_interval95"]
    assert low <= life.tests[1][2] <= high
