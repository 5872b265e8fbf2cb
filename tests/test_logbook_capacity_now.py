"""Capacity today over a pack's life (over_life.capacity_over_life / capacity_now): kinds
of estimate on one scale, the band widened by the fade since the last full discharge,
and a routine charge that stops short of full read as such, on an engine-made life."""

from __future__ import annotations

import numpy as np
import pytest

from dischargelab.logbook.health import EventHealth
from dischargelab.logbook.over_life import (
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
    from dischargelab.logbook import Logbook
    from synthetic_life import LifeSpec, synthetic_life

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


def _hover_log(path, tail_s: float, chemistry: str = "li-ion", temperature: bool = True):
    """A 3S 12 Ah pack (the engine's ``ecm`` cell) rested full, hovered at 27 A to 30 %
    and logged ``tail_s`` after landing, one sample a second."""
    import synthetic_life as sl

    return sl.flight_log(path, [(27.0, 0.7 * 12 * 3600 / 27)], capacity_Ah=12.0, cells=3,
                         chemistry=chemistry, after_s=tail_s, temperature=temperature)


@pytest.mark.parametrize("chemistry", [None, "li-ion"])
def test_a_hover_to_30_percent_of_a_pack_of_unknown_chemistry_gets_an_honest_band(tmp_path,
                                                                                 chemistry):
    from dischargelab.logbook import Logbook

    truth = _hover_log(tmp_path / "hover.csv", 60.0)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.set_pack("quad", cells=3, chemistry=chemistry)
        lb.add(tmp_path / "hover.csv", pack="quad")
        flight = next(e for e in lb.health("quad").events if e.capacity_Ah is not None)
    low, high = flight.capacity_interval95
    assert low < truth < high
    assert flight.capacity_Ah == pytest.approx(truth, rel=0.06)
    if chemistry is None:   # the hover's loaded voltage tells the Li-ion curve from LiPo's
        assert "chemistry read from 1 load(s): the li-ion curve fits" in " ".join(flight.notes)


@pytest.mark.parametrize("chemistry", ["li-ion", "lipo"])
@pytest.mark.parametrize("tail_s", [36.0, 100.0])
def test_a_landing_logged_for_less_time_than_the_flight_took_keeps_the_truth_in_its_band(
        tmp_path, chemistry, tail_s):
    """36-100 s after a 19-minute hover the cell still relaxes (its slow polarisation, and
    the cooling of a warm cell turns the slope flat): the band carries what the rest cannot
    show yet, with no chemistry, cells or label given."""
    from dischargelab.logbook import Logbook

    truth = _hover_log(tmp_path / "hover.csv", tail_s, chemistry, temperature=False)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(tmp_path / "hover.csv", pack="quad")
        health = lb.health("quad")
        flight = next(e for e in health.events if e.capacity_Ah is not None)
    low, high = flight.capacity_interval95
    assert low < truth < high
    assert flight.capacity_Ah == pytest.approx(truth, rel=0.15)
    assert any("1 of its 1 estimate(s) end on a rest shorter than the flight" in n
               for n in health.notes), health.notes
    assert any(n.startswith(f"the log ends {tail_s - 0.5:.0f} s after a 19-minute load")
               for n in flight.notes), flight.notes


def test_a_chemistry_not_known_carries_both_curves_in_the_reading():
    from dischargelab.logbook.estimates import OcvCurve, soc_reading

    unknown, lipo = OcvCurve.unknown(), OcvCurve.prior("lipo")
    reading = {"relaxed_V": 3 * 3.64, "current_A": 0.0}     # 30 % on the mean curve
    soc, sd = soc_reading(unknown, reading, 3)
    assert soc == pytest.approx(0.3, abs=0.05)
    assert sd > 3 * soc_reading(lipo, reading, 3)[1]
    assert unknown.sd_at(1.0) < 0.5 * unknown.sd_at(0.3) and unknown.sd_at(0.3) > 0.1


def _hiding_life(fade_seen: float):
    """A life whose charges read capacity through a curve that hides the fade: the
    capacity estimates fall by ``fade_seen`` over 60 EFC while the resistance doubles."""
    rng = np.random.default_rng(2)
    events = [_event(0, 0.0, 3.0, "coulomb count", "discharge", 0.005)]
    for k, x in enumerate(np.linspace(1.0, 60.0, 40), start=1):
        e = _event(k, float(x), 3.0 * (1 - fade_seen * x / 60) + rng.normal(0, 0.005),
                   "rests before and after (charge ends full)")
        e.resistance_ohm = e.resistance_ref_ohm = 0.03 * (1 + x / 60)
        e.resistance_ref_interval95 = [0.9 * e.resistance_ref_ohm, 1.1 * e.resistance_ref_ohm]
        events.append(e)
    return events


def _window_rise(events) -> float:
    """The rise resistance_rise should read at the life's end: the median of the last
    quarter-of-the-estimates window over the first's, less 1."""
    r = np.array([e.resistance_ref_ohm for e in events[1:]])
    n = len(r) // 4
    return float(np.median(r[-n:]) / np.median(r[:n]) - 1)


def test_a_resistance_that_doubles_takes_the_hidden_fade_off_capacity_today():
    from dischargelab.logbook.over_life import (
        HIDDEN_FADE_PER_RISE,
        HIDDEN_FADE_SD_SHARE,
        _scale_notes,
        hidden_fade,
        resistance_rise,
    )

    events = _hiding_life(0.0)
    rise = _window_rise(events)
    assert rise > 0.5
    assert resistance_rise(events, 0.0, [60.0])[0] == pytest.approx(rise)
    alone = capacity_now(events)
    now = capacity_now(events, per_event=events)
    assert now.rise == pytest.approx(rise)
    # the estimates read 3.0 Ah; lithium lost below their swing goes with the rise
    hidden = HIDDEN_FADE_PER_RISE * rise
    assert now.estimate() == pytest.approx(now.value_Ah * (1 - hidden))
    assert alone.estimate() == pytest.approx(alone.value_Ah)
    low, high = now.interval95()
    # a pack that lost 12 % below the charge its events swing through: held by the band
    assert low < 0.88 * 3.0 < high
    assert not alone.interval95()[0] < 0.88 * 3.0
    # half the correction in the band, on both sides
    sd = np.hypot(np.hypot(now.trend_sd_Ah, DRIFT_SHARE * now.drift_unit_Ah),
                  HIDDEN_FADE_SD_SHARE * hidden * now.value_Ah)
    assert (now.estimate() - low) / now.quantile == pytest.approx(sd)
    assert (high - now.estimate()) / now.quantile == pytest.approx(sd)
    # the pack's trend (what `logbook health` shows) says the same
    trend = capacity_over_life([e for e in events if e.capacity_Ah], per_event=events)
    plain = capacity_over_life(events)
    value, (lo, hi) = trend.interval95(60.0)
    assert value == pytest.approx(plain.interval95(60.0)[0] * (1 - hidden))
    assert hi - lo > 2 * (plain.interval95(60.0)[1][1] - plain.interval95(60.0)[1][0])
    again = type(trend).from_dict(trend.to_dict())
    assert again.interval95(60.0)[1][0] == pytest.approx(lo, rel=1e-3)
    notes = _scale_notes(events, trend, events)
    assert any("resistance rose" in n and f"{hidden:.1%} below the estimates" in n
               for n in notes)
    # without a full discharge the estimates read a generic curve, whose own error is
    # larger: the hidden fade widens the band, and the value stays
    untested = events[1:]
    bare = capacity_now(untested, per_event=untested)
    assert not bare.tested and bare.rise > 0.5
    assert bare.estimate() == pytest.approx(bare.value_Ah)
    low, high = bare.interval95()
    assert high - low > (alone.interval95()[1] - alone.interval95()[0]) + 0.1
    assert capacity_over_life(untested, per_event=untested).interval95(60.0)[0] == \
        pytest.approx(capacity_over_life(untested).interval95(60.0)[0])
    said = _scale_notes(untested, capacity_over_life(untested, per_event=untested), untested)
    assert any("resistance rose" in n and "not taken off" in n for n in said)
    assert not any("below the estimates" in n for n in said)
    # estimates that show some fade miss the same lithium below their swing
    seen = _hiding_life(0.15)
    assert hidden_fade(seen, 0.0, [60.0])[0] == pytest.approx(hidden_fade(events, 0.0,
                                                                          [60.0])[0])


def test_open_circuit_drop_resistances_only_when_the_events_give_no_other():
    from dischargelab.logbook.health import DROP_METHOD
    from dischargelab.logbook.over_life import resistance_over_life

    events = _hiding_life(0.0)
    for e in events[1:]:
        e.resistance_method = "load steps"
    charges = []
    for k, x in enumerate(np.linspace(1.5, 60.0, 40), start=100):
        e = _event(k, float(x), 3.0, "rests before and after")
        e.resistance_ohm = e.resistance_ref_ohm = 0.08
        e.resistance_ref_interval95 = [0.07, 0.09]
        e.resistance_method = DROP_METHOD
        charges.append(e)
    mixed = sorted(events + charges, key=lambda e: e.efc)
    # the trend reads the load steps (0.03 -> 0.06), not the drop's 0.08
    assert resistance_over_life(mixed).at(60.0)[0][0] == pytest.approx(0.06, rel=0.1)
    # alone, the drops are the pack's resistance
    assert resistance_over_life(charges).at(60.0)[0][0] == pytest.approx(0.08, rel=0.01)


def test_the_rise_is_read_from_the_most_repeatable_resistances():
    from dischargelab.logbook.over_life import resistance_rise

    steady = _hiding_life(0.0)        # charges: 0.03 -> 0.06 ohm, smoothly
    rng = np.random.default_rng(5)
    noisy = []
    for k, x in enumerate(np.linspace(1.5, 60.0, 60), start=100):
        # loads regressed over samples interpolated between steps: 20 % from one to the
        # next, and a rise of their own (3x) that the charges do not show
        e = _event(k, float(x), 3.0, "rests before and after", kind="discharge")
        e.resistance_ohm = e.resistance_ref_ohm = 0.03 * (1 + 2 * x / 60) * \
            (1 + rng.normal(0, 0.2))
        e.resistance_method = "regression"
        noisy.append(e)
    mixed = sorted(steady + noisy, key=lambda e: e.efc)
    assert resistance_rise(mixed, 0.0, [60.0])[0] == pytest.approx(_window_rise(steady))
    # either alone is read
    assert resistance_rise(noisy, 0.0, [60.0])[0] > 1.0


def test_a_pack_model_takes_the_capacity_spread_from_the_band_low_side():
    from dischargelab.logbook.results import Pack

    def pack(band):
        return Pack(name="p", label_capacity_Ah=3.0, reference_capacity_Ah=3.0,
                    chemistry="li-ion", cells=1, events=10, efc=50.0, capacity_Ah=2.9,
                    resistance_ohm=0.03, capacity_interval95=band)

    even = pack([2.8, 3.0])._capacity_sd()
    assert even == pytest.approx(0.1 / 1.96 / 2.9, rel=1e-3)
    # a fade the estimates may not show widens the low side only: the spread follows it
    assert pack([2.5, 3.0])._capacity_sd() == pytest.approx(0.4 / 1.96 / 2.9, rel=1e-3)


def test_a_resistance_that_moves_by_less_than_its_scatter_is_not_taken_for_ageing():
    from dischargelab.logbook.over_life import RISE_MIN, _scale_notes, hidden_fade

    events = _hiding_life(0.0)
    for e in events[1:]:         # 8 % over the life: temperature and charge move it more
        e.resistance_ohm = e.resistance_ref_ohm = 0.03 * (1 + 0.08 * e.efc / 60)
    trend = capacity_over_life(events, per_event=events)
    assert 0.08 < RISE_MIN and hidden_fade(events, 0.0, [60.0])[0] == 0.0
    assert capacity_now(events, per_event=events).rise == 0.0
    assert not any("resistance rose" in n for n in _scale_notes(events, trend, events))


def test_a_load_read_under_load_near_the_cutoff_at_a_high_rate_is_a_high_rate_estimate():
    from dischargelab.logbook.over_life import HIGH_RATE_KIND
    from dischargelab.logbook.references import ReferenceCurve, partial_capacity

    q = np.linspace(0.0, 3.0, 61)
    slow = {"curve": {"charge_Ah": q.tolist(),
                      "voltage_V": (4.1 - 0.7 * q / 3 - 0.6 * (q / 3) ** 12).tolist(),
                      "current_A": [0.6] * q.size},
            "rest_voltage_V": 4.15, "resistance_ohm": 0.05, "mean_current_A": 0.6}
    ref = ReferenceCurve(slow, 3.0)

    def run(current_A, share):
        end_V = float(np.interp(share, ref.share, ref.loaded(current_A, None)))
        event = {"curve": {"charge_Ah": [0.0, 3.0 * share], "voltage_V": [4.0, end_V],
                           "current_A": [current_A] * 2},
                 "rest_voltage_V": 4.15, "end_voltage_V": end_V, "end_current_A": current_A,
                 "discharged_Ah": 3.0 * share, "mean_current_A": current_A,
                 "resistance_ohm": 0.05}
        return partial_capacity(event, ref, 1)

    # a mission at 4x the test's current, read under load at 95 %: where the rate moves
    # the cutoff most, its offset is learned as a high-rate estimate's
    cap, _, how = run(2.4, 0.95)
    assert cap == pytest.approx(3.0, rel=0.02) and "at a high rate" in how
    assert estimate_kind(_event(1, 1.0, cap, how, "discharge")) == HIGH_RATE_KIND
    # mid-curve at that rate, or near the cutoff at the test's own: the reference holds
    for current_A, share in ((2.4, 0.5), (0.6, 0.95)):
        cap, _, how = run(current_A, share)
        assert "at a high rate" not in how
        assert estimate_kind(_event(1, 1.0, cap, how, "discharge")) == "load: reference curve"
