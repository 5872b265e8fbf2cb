"""A pack's health from what it already does, on real and synthetic logs: partial discharges
wherever they sit in the pack's life, long logs through the logbook, flights and cells."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from dischargelab.logbook.health import pack_health
from dischargelab.logbook.summarise import summarise_source
from lvm_cut import lvm_cut

CELL_C = "samsung30q_ageing_cellC"

#: Full discharges of cell C given to the pack, and the cycles cut at 60 % of their charge.
FULL_CYCLES = (1, 100, 200, 300, 400, 500, 600, 660)
CUT_CYCLES = (110, 310, 510)


def as_stored(summary, source_id: int, name: str | None = None) -> list[dict]:
    """Summary events as the logbook returns them (ids in the order files were added)."""
    out = []
    for e in summary.events:
        row = dict(e, id=source_id * 1000 + e["index"], source_id=source_id, idx=e["index"],
                   source=name or summary.file_name)
        lo, hi = e["resistance_interval95"] or (None, None)
        row.update(resistance_low_ohm=lo, resistance_high_ohm=hi)
        out.append(row)
    return out


@pytest.fixture(scope="module")
def cell_c_fulls(shared_data):
    return [summarise_source(shared_data / CELL_C / f"DischargeCycle{c:03d}.txt")
            for c in FULL_CYCLES]


@pytest.mark.parametrize("dated", [True, False], ids=["dated", "undated"])
@pytest.mark.parametrize("added", ["before", "after"])
@pytest.mark.parametrize("named", [True, False], ids=["cycle-in-name", "renamed"])
def test_cell_c_partial_discharges_within_3_percent_wherever_they_sit(
        shared_data, tmp_path, cell_c_fulls, dated, added, named):
    """Cuts at 60 % of their charge, with or without a clock time, with or without the cycle
    number in their names, added before or after the full cycles: each within 3 % of the
    full file's charge, its interval covering it."""
    cuts, truth = [], {}
    for k, c in enumerate(CUT_CYCLES):
        name = f"DischargeCycle{c:03d}.txt" if named else f"partial_{'abc'[k]}.txt"
        path = tmp_path / name
        truth[name] = lvm_cut(shared_data / CELL_C / f"DischargeCycle{c:03d}.txt", path, 0.6,
                              dated)
        cuts.append(summarise_source(path))
    order = [*cuts, *cell_c_fulls] if added == "before" else [*cell_c_fulls, *cuts]
    events = []
    for sid, summary in enumerate(order, 1):
        events += as_stored(summary, sid)
    health, reference, _ = pack_health(events)
    partial = {h.source: h for h in health if not h.full}
    assert set(partial) == set(truth)
    for name, h in partial.items():
        assert h.capacity_Ah == pytest.approx(truth[name], rel=0.03), name
        lo, hi = h.capacity_interval95
        assert lo < truth[name] < hi
        assert "matched full discharge" in h.capacity_method
    if not dated and added == "after":  # placed after what the pack had, never before cycle 1
        first = next(k for k, h in enumerate(health) if h.full)
        assert all(k > first for k, h in enumerate(health) if not h.full)


# --------------------------------------------------------------------------- long logs

@pytest.fixture(scope="module")
def short_life(tmp_path_factory):
    """Two cycles of a synthetic cell at 1 Hz as one log: a 1C capacity test, missions,
    rests and CC-CV charges (the engine; known capacity)."""
    from synthetic_life import LifeSpec, synthetic_life

    spec = LifeSpec(cycles=2, test_every=10, test_C=1.0, rest_s=600.0, mission_dt_s=10.0,
                    cv_step_s=60.0)
    life = synthetic_life(spec)
    path = tmp_path_factory.mktemp("life") / "bms_log.csv"
    life.frame.to_csv(path, index=False)
    return path, life


def test_a_long_log_through_the_logbook_gives_its_events_and_their_capacities(short_life,
                                                                             tmp_path):
    from dischargelab.logbook import Logbook

    path, life = short_life
    with Logbook(tmp_path / "lb.sqlite") as lb:
        result = lb.add(path, pack="cell")
        assert result.added == ["bms_log.csv"]
        health = lb.health("cell")
        rows = lb.events("cell").rows
    kinds = [e.health_kind for e in health.events]
    # the cell arrives part-charged: a discharge, then charge, test, charge, mission, charge
    assert [k for k in kinds if k != "rest"] == ["partial", "charge", "full", "charge",
                                               "partial", "charge", "partial", "charge"]
    assert all(kinds[k] == "rest" for k in range(1, len(kinds), 2))
    assert len(rows) == len(kinds) == result.events
    truth = life.tests[0][2]
    test = next(e for e in health.events if e.full)
    assert test.capacity_Ah == pytest.approx(truth, rel=0.005)
    assert test.capacity_method == "coulomb count"
    for e in health.events:
        if e.kind in ("charge", "discharge") and not e.full and e.efc and e.efc > 1:
            assert e.capacity_method.startswith("rests before and after")
            lo, hi = e.capacity_interval95
            assert e.capacity_Ah == pytest.approx(truth, rel=0.03) and lo < truth < hi
            assert 0 <= e.soc_end <= e.soc_start <= 1 or e.kind == "charge"
    charges = [e for e in health.events if e.kind == "charge"]
    assert all(e.charged_Ah > 0 and e.discharged_Ah == 0 for e in charges)
    efc = [e.efc for e in health.events]
    assert all(b >= a for a, b in zip(efc, efc[1:]))
    data = health.to_dict()["events"]
    assert {e["kind"] for e in data} == {"partial", "full", "charge", "rest"}
    assert all(e["resistance_ref_ohm"] is None or e["resistance_ref_ohm"] > 0 for e in data)


@pytest.mark.slow
def test_a_discharge_after_a_charge_that_stopped_short_is_not_full(tmp_path):
    """The short life with its test's charge held at 4.1 V instead of 4.2 V: the rest reads
    90 % and more on the generic curve, but the charge before it ended below the full
    voltage, so the test is read from its rest (not counted as the capacity, 6 % below
    what it delivers from a full charge), and capacity today's band holds that."""
    from dataclasses import replace

    from dischargelab.logbook import Logbook
    from synthetic_life import LifeSpec, synthetic_life

    spec = LifeSpec(cycles=2, test_every=10, test_C=1.0, rest_s=600.0, mission_dt_s=10.0,
                    cv_step_s=60.0, test_cv_V=4.1)
    life = synthetic_life(spec)
    path = tmp_path / "bms_log.csv"
    life.frame.to_csv(path, index=False)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(path, pack="cell")
        health = lb.health("cell")
    assert not any(e.full for e in health.events)
    test = max(health.events, key=lambda e: e.discharged_Ah)
    truth = synthetic_life(replace(spec, test_cv_V=4.2)).tests[0][2]   # from a full charge
    assert test.discharged_Ah < 0.95 * truth
    assert "the charge before it stopped short of full" in " ".join(test.notes)
    # read from its rest, not its count (the generic curve reads the 4.1 V end at 96 %)
    assert test.soc_start < 1.0 and test.capacity_Ah > 1.04 * test.discharged_Ah
    lo, hi = health.today["capacity_interval95"]
    assert lo < truth < hi


def test_a_capacity_test_inside_a_long_log_is_refitted(short_life, tmp_path):
    from dischargelab.logbook import Logbook

    path, life = short_life
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(path, pack="cell")
        battery = lb.fit("cell", model="shepherd", bootstrap=0)
    truth = life.tests[0][2]
    assert battery.extra["logbook_fit"]["capacity_Ah"] == pytest.approx(truth, rel=0.005)
    # fitted to the test's own rows: the model empties just past what the test delivered
    assert truth < battery.capacity_Ah < 1.1 * truth


@pytest.mark.slow
def test_the_cmu_evtol_life_through_the_logbook(shared_data, tmp_path):
    """A real eVTOL cell's whole life as one CSV (one sample every 167 s): its 13 C/5
    capacity tests become full discharges with their own capacity; the missions are judged
    uncountable; the charges, ending full, give the capacity between their rests."""
    from dischargelab.logbook import Logbook

    path = shared_data / "cmu_evtol" / "VAH27.csv"
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(path, pack="VAH27")
        health = lb.health("VAH27")
    counts = Counter(e.health_kind for e in health.events)
    assert counts["full"] == 13 and counts["partial"] == 573
    assert counts["charge"] >= 585 and counts["rest"] >= 1100
    fulls = [e.capacity_Ah for e in health.events if e.full]
    # README: 3.089 -> 2.552 Ah (the tests' delivered charge)
    assert fulls[0] == pytest.approx(3.089, abs=0.01) and fulls[-1] == pytest.approx(2.552,
                                                                                     abs=0.01)
    missions = [e for e in health.events if e.health_kind == "partial"]
    assert all(any("do not follow the current" in n for n in e.notes) for e in missions
               if e.capacity_Ah is not None)
    charges = [e for e in health.events if e.kind == "charge" and e.capacity_Ah is not None
               and not e.outlier]
    assert len(charges) > 500
    # between the 6th and 7th test: the charges' capacities against the tests around them
    k6, k7 = [k for k, e in enumerate(health.events) if e.full][5:7]
    block = [e.capacity_Ah for e in health.events[k6:k7] if e in charges]
    assert np.median(block) == pytest.approx(health.events[k7].capacity_Ah, rel=0.03)
    # too sparse for load steps or a regression, the resistance comes from the loaded
    # voltage's distance to the cell's curve: mOhm of a 3 Ah cell, rising as it ages
    # (27 % over the life, docs/logbook.md), and the estimates show the fade it goes with
    dropped = [e.resistance_ref_ohm for e in missions if e.resistance_method
               == "open-circuit drop" and not e.outlier and e.resistance_ref_ohm]
    assert len(dropped) > 500 and 0.015 < np.median(dropped) < 0.06
    assert np.median(dropped[-20:]) > 1.1 * np.median(dropped[20:40])
    assert not any("resistance rose" in n for n in health.notes)
    # today's: the trend of the missions' and the charges' (a charge's drop at 1C is larger)
    charged = [e.resistance_ref_ohm for e in charges if e.resistance_method
               == "open-circuit drop" and e.resistance_ref_ohm]
    assert np.median(dropped[-20:]) < health.today["resistance_ohm"] < 1.1 * max(
        np.median(charged[-20:]), np.median(dropped[-20:]))


def test_a_rest_after_a_mission_holds_where_it_relaxes_in_its_interval(shared_data):
    """The one long rest after a mission of VAH27 (9,907 s; the cell cools from 48 to
    19.5 degC): read from its first 749 s, as every rest between a mission and its charge
    is, its 95 % interval holds where it got at 9,907 s and where that reading extrapolates
    (the central value lies 6-9 mV below them: the tail is slower than diffusion there)."""
    import pandas as pd

    from dischargelab.logbook.relaxation import relaxation

    frame = pd.read_csv(shared_data / "cmu_evtol" / "VAH27.csv")
    t, v = frame["time_s"].to_numpy(), frame["voltage_V"].to_numpy()
    a = 25277                                       # the long rest's first sample
    assert np.all(np.abs(frame["current_A"].to_numpy()[a:a + 60]) < 0.01)
    since = t[a:a + 60] - 0.5 * (t[a - 1] + t[a])
    short = relaxation(since[:5], v[a:a + 5], +1, loaded_V=v[a - 1])
    long = relaxation(since, v[a:a + 60], +1, loaded_V=v[a - 1])
    assert since[4] == pytest.approx(749, abs=1) and since[-1] > 9900
    assert short["relaxed_V"] > v[a + 4] + 0.01                      # 15 mV left
    for reached in (v[a + 59], long["relaxed_V"]):
        assert short["relaxed_V"] < reached < short["relaxed_V"] + short["half95_V"]


@pytest.fixture(scope="module")
def cmu_first_cycles(shared_data, tmp_path_factory):
    """The first 3,500 samples of the CMU eVTOL cell VAH27 (two capacity tests, ~90
    missions and charges, one sample every 166.5 s) and its events."""
    import pandas as pd

    path = tmp_path_factory.mktemp("cmu") / "VAH27_start.csv"
    pd.read_csv(shared_data / "cmu_evtol" / "VAH27.csv").iloc[:3500].to_csv(path, index=False)
    events = as_stored(summarise_source(path), 1)
    return events, pack_health(events)[0]


def test_the_cmu_charges_starts_are_placed_between_their_samples(cmu_first_cycles):
    """Every charge after a mission takes back about the same charge; counted by
    trapezoids from the rest's last sample, the charger's unseen start makes it wander by
    +-4 %. Placed by the first sample's voltage, the wander between consecutive charges
    shrinks by more than half, and so does their capacities'."""
    from dischargelab.logbook.estimates import charge_start_corrections

    events, health = cmu_first_cycles
    charges = [e for e in events if e["kind"] == "charge"]
    added = charge_start_corrections([e["details"]["charge"].get("start") for e in charges])
    placed = [(-e["details"]["counted_Ah"], a) for e, a in zip(charges, added)
              if a is not None]
    assert len(placed) > 80
    counted = np.array([q for q, _ in placed])
    assert np.std(np.diff(counted + [a for _, a in placed])) < 0.5 * np.std(np.diff(counted))
    caps = np.array([h.capacity_Ah for h in health if h.kind == "charge"
                     and h.capacity_Ah is not None][2:])      # after the second test
    assert np.std(np.diff(caps)) < 0.012 * np.median(caps)
    assert any("its start placed" in n for h in health for n in h.notes)


def test_the_cmu_charges_are_not_flagged_against_the_missions_scatter(cmu_first_cycles):
    """A charge counted to 2 % sits among missions seen by a few samples (30 %): judged
    against their local trend it would be thrown out for the missions' scatter."""
    _, health = cmu_first_cycles
    charges = [h for h in health if h.kind == "charge" and h.capacity_Ah is not None]
    assert len(charges) > 80 and not any(h.outlier for h in charges)


def test_every_shared_flight_log_gets_a_resistance_and_a_capacity_or_a_reason(shared_data):
    logs = [shared_data / "flight_logs" / p for p in
            ("ardupilot_loganalyzer/mechanical_fail.log", "ina3221_fpv_4s/28.csv",
             "ina3221_fpv_4s/29.csv", "px4_ulog_rs/esc_status_log.ulg")]
    logs += sorted((shared_data / "dji_m100_flights").glob("derived_battery_*.csv"))
    for sid, path in enumerate(logs, 1):
        health, _, _ = pack_health(as_stored(summarise_source(path), sid),
                                   cells=6 if "dji" in str(path) else None)
        assert any(h.resistance_ohm is not None for h in health), path.name
        for h in health:
            if h.capacity_Ah is None:
                assert h.capacity_note and "\n" not in h.capacity_note
            else:
                lo, hi = h.capacity_interval95
                assert lo < h.capacity_Ah < hi
    # the INA3221 logger's flight with a rest on each side: a capacity, and each cell apart
    stored = as_stored(summarise_source(shared_data / "flight_logs" / "ina3221_fpv_4s" /
                                        "29.csv"), 1)
    (flight,) = pack_health(stored, chemistry="lipo")[0]
    assert flight.capacity_method == "rests before and after"
    assert 1.0 < flight.capacity_Ah < 1.8  # a 1600 mAh pack, used
    # its chemistry not given (and its one flight cannot tell it): a wider interval that
    # still holds it
    (unknown,) = pack_health(stored)[0]
    lo, hi = unknown.capacity_interval95
    assert lo < 1.5 < hi and hi - lo > 2 * np.diff(flight.capacity_interval95)[0]
    cells = flight.cells
    assert cells["count"] == 4 and len(cells["resistance_ohm"]) == 4
    assert 0.5 < cells["weakest_share"] <= 1.0 and cells["rest_spread_V"] < 0.1
