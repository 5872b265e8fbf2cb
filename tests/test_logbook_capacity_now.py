"""Capacity today over a pack's life (results.capacity_over_life / capacity_now): kinds
of estimate on one scale, the band widened by the fade since the last full discharge,
and a routine charge that stops short of full read as such, on an engine-made life."""

from __future__ import annotations

import numpy as np
import pytest

from dischargelab.logbook.health import EventHealth
from dischargelab.logbook.results import (
    DRIFT_SHARE,
    REFERENCE_KIND,
    capacity_now,
    capacity_over_life,
    estimate_kind,
)


def _event(k, efc, cap, method, kind="charge", half=0.03):
    return EventHealth(event_id=k, source="log", start=None, kind=kind, cycle=None,
                       discharged_Ah=1.0, full=method == "coulomb count", capacity_Ah=cap,
                       capacity_interval95=[cap - half, cap + half], capacity_method=method,
                       efc=efc)


def _life(offset=0.05, n=60, efc_end=200.0):
    rng = np.random.default_rng(1)
    truth = lambda x: 3.0 * (1 - 0.0006 * x)  # noqa: E731
    events = [_event(0, 0.0, truth(0.0) + 0.003, "coulomb count", "discharge", 0.005)]
    for k, x in enumerate(np.linspace(0.5, efc_end, n), start=1):
        events.append(_event(k, float(x), (1 + offset) * truth(x) + rng.normal(0, 0.01),
                             "rests before and after (charge ends full)"))
    return events, truth


def test_kinds_are_labelled_by_how_their_capacity_was_estimated():
    events, _ = _life()
    assert estimate_kind(events[0]) == REFERENCE_KIND
    assert estimate_kind(events[1]) == "charge: rests before and after"
    fast = _event(9, 1.0, 2.5, "coulomb count at a high rate", "flight")
    assert estimate_kind(fast) != REFERENCE_KIND


def test_the_band_widens_with_the_fade_since_the_last_full_discharge():
    events, truth = _life()
    plain = capacity_over_life(events, drift_share=0.0)
    wide = capacity_over_life(events)
    x = events[-1].efc
    assert wide.at(x)[1][0] > 1.5 * plain.at(x)[1][0]
    # right after the full discharge nothing has drifted yet
    assert wide.at(0.0)[1][0] == pytest.approx(plain.at(0.0)[1][0], rel=1e-6)
    now = capacity_now(events)
    low, high = now.interval95()
    assert low < truth(x) < high
    assert now.interval95(0.0)[1] - now.interval95(0.0)[0] < high - low
    assert DRIFT_SHARE > 0


def test_charges_reading_high_are_put_on_the_full_discharges_scale():
    events, truth = _life(offset=0.05)
    with_kinds = capacity_now(events)
    x = events[-1].efc
    # the charges read 5 % high; their offset is learned at the full discharge
    assert abs(with_kinds.value_Ah / truth(x) - 1) < 0.02


@pytest.mark.slow
def test_a_routine_charge_to_4_0_v_is_not_full_and_the_band_holds_the_next_test(tmp_path):
    from synthetic_life import LifeSpec, synthetic_life

    from dischargelab.logbook import Logbook

    life = synthetic_life(LifeSpec(cycles=6, test_every=5, cv_V=4.0, fade_per_efc=3e-3,
                                   ocv_wiggle_V=0.008, lli_share=0.3, seed=4))
    # the log up to the second capacity test: the first test, then five cycles charged
    # to 4.0 V (the tests charge to 4.2 V)
    path = tmp_path / "life.csv"
    life.frame[life.frame["time_s"] < life.tests[1][0]].to_csv(path, index=False)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.set_pack("cell", chemistry="li-ion")
        lb.add(path, pack="cell")
        health = lb.health("cell")
    charges = [e for e in health.events if e.kind == "charge" and e.capacity_method]
    full = [e for e in charges if "charge ends full" in e.capacity_method]
    # the 4.2 V charges: before the first test, after it and before the second
    assert len(full) <= 3 and len(charges) - len(full) >= 5
    low, high = health.today["capacity_interval95"]
    assert low <= life.tests[1][2] <= high
