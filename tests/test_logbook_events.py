"""The plain functions behind a pack's events: splitting a log, rests and their relaxation,
counting charge, capacity between two rests, the open-circuit voltage, resistance at
reference conditions, cells apart and the order of a pack's life. Truths are built here."""

from __future__ import annotations

import numpy as np
import pytest

from dischargelab.logbook.cells import cell_figures, drift_flags, weakest_share
from dischargelab.logbook.estimates import (
    MIN_SWING,
    OCV_AGEING_SD,
    OcvCurve,
    capacity_between_rests,
    charge_start_corrections,
    counted_charge,
    drop_resistance,
    regression_resistance,
    resistance_at_reference,
    sampling_figures,
    soc_reading,
    systematic_share,
    widen,
)
from dischargelab.logbook.events import MIN_IDLE_A, charge_figures, idle_threshold, split_log
from dischargelab.logbook.health import order_events
from dischargelab.logbook.relaxation import relaxation, shorter_than_load
from dischargelab.ocv import ocv_from_soc

# --------------------------------------------------------------------------- splitting


def _log(pieces, dt=1.0, seed=0, noise=0.003):
    """Concatenated (kind, duration [s], current [A]) pieces, sampled every ``dt``."""
    rng = np.random.default_rng(seed)
    t, i = [], []
    now = 0.0
    for _, duration, current in pieces:
        n = int(round(duration / dt))
        t.append(now + dt * np.arange(n))
        i.append(np.full(n, float(current)))
        now += n * dt
    i = np.concatenate(i)
    return np.concatenate(t), i + rng.normal(0, noise, i.size)


def test_split_log_finds_discharges_charges_rests_and_gaps():
    pieces = [("rest", 600, 0), ("discharge", 900, 5.0), ("rest", 600, 0),
              ("charge", 1800, -3.0), ("rest", 600, 0)]
    t, i = _log(pieces)
    # a flight's low-throttle moments (20 s idle) belong to it; a regen blip of 3 s too
    i[800:820] = 0.0
    i[1000:1003] = -1.0
    # the logger was off for an hour in the last rest
    t[-300:] += 3600.0
    spans = split_log(t, i)
    assert [s.kind for s in spans] == ["rest", "discharge", "rest", "charge", "rest", "gap",
                                       "rest"]
    assert spans[1].start == 600 and spans[1].stop == 1500
    assert spans[3].start == 2100 and spans[3].stop == 3900
    gap = spans[5]
    assert gap.start == gap.stop == t.size - 300


def test_split_log_by_tester_steps_joins_a_constant_current_then_voltage_charge():
    t, i = _log([("rest", 60, 0), ("cc", 300, -2.0), ("cv", 300, -0.5), ("rest", 60, 0),
                 ("dis", 600, 1.0)], noise=0.0)
    steps = np.repeat([1, 2, 3, 4, 5], [60, 300, 300, 60, 600])
    spans = split_log(t, i, step_index=steps)
    assert [(s.kind, s.steps) for s in spans] == [("rest", (1,)), ("charge", (2, 3)),
                                                  ("rest", (4,)), ("discharge", (5,))]


def test_charge_ending_in_a_voltage_taper_is_full():
    t = np.arange(0.0, 3000.0, 10.0)
    current = np.where(t < 2000, -3.0, -3.0 * np.exp(-(t - 2000) / 200))
    voltage = np.where(t < 2000, 3.7 + 0.5 * t / 2000, 4.2)
    fig = charge_figures(t, voltage, current)
    assert fig["taper"] and fig["charged_Ah"] == pytest.approx(
        (3.0 * 2000 + 3.0 * 200 * (1 - np.exp(-995 / 200))) / 3600, rel=0.01)
    assert not charge_figures(t[:150], voltage[:150], current[:150])["taper"]
    # the same charge logged every 160 s and resampled to 30 s: the last samples lie on the
    # ramp from the taper's last record (4.2 V, 0.25 A) down to the rest's first
    coarse = np.append(t[::16], 3100.0)
    i_c = np.append(current[::16], 0.0)
    v_c = np.append(voltage[::16], 4.12)
    fine = np.arange(0.0, 3100.0, 30.0)
    i_f, v_f = np.interp(fine, coarse, i_c), np.interp(fine, coarse, v_c)
    moving = i_f < -0.01
    assert charge_figures(fine[moving], v_f[moving], i_f[moving])["taper"]
    # a constant-current charge stopped at 4.2 V, then ramped down the same way: not a taper
    i_cc = np.where(fine < 2000, -3.0, np.interp(fine, [2000.0, 2100.0], [-3.0, 0.0]))
    v_cc = np.where(fine < 2000, 3.7 + 0.5 * fine / 2000, np.interp(fine, [2000.0, 2100.0],
                                                                   [4.2, 4.12]))
    moving = i_cc < -0.01
    assert not charge_figures(fine[moving], v_cc[moving], i_cc[moving])["taper"]


# --------------------------------------------------------------------------- relaxation

@pytest.mark.parametrize("shape", ["sqrt", "exp"])
def test_relaxation_extrapolates_what_is_left_and_covers_it(shape):
    """A rest seen for 800 s after a load: the voltage it relaxes to lies inside the reading's
    95 % interval for a diffusion tail (sqrt) and for an RC pair as slow as the rest is long
    (exponential)."""
    t = np.arange(20.0, 800.0, 20.0)
    if shape == "sqrt":
        v_inf, v = 3.70, 3.70 - 0.9 / np.sqrt(t)
    else:
        v_inf, v = 3.70, 3.70 - 0.05 * np.exp(-t / 800.0)
    r = relaxation(t, v, +1, loaded_V=3.5)
    assert r["method"] == "fit" and r["left_V"] > 0
    assert abs(r["relaxed_V"] - v_inf) <= r["half95_V"]
    assert r["relaxed_V"] > v[-1]
    # after a charge the voltage falls back: the sign follows
    down = relaxation(t, 2 * 3.9 - v, -1)
    assert down["left_V"] < 0 and down["relaxed_V"] < 2 * 3.9 - v[-1]


def test_relaxation_of_a_short_rest_uses_a_prior_wider_than_a_fit():
    r = relaxation(np.array([60.0]), np.array([3.68]), +1, loaded_V=3.55)
    assert r["method"] == "prior" and 0 < r["left_V"] < 0.13
    assert r["half95_V"] >= r["left_V"]


def test_a_fit_over_a_rest_shorter_than_the_load_keeps_the_diffusion_it_cannot_see():
    """After a 1,100 s load the diffusion overpotential relaxes as sqrt(t + T) - sqrt(t):
    60 s of it fitted (its slope flattened by cooling) leaves most of it unseen; the
    reading now carries the prior's share, and a rest longer than the load is unchanged."""
    load_s, v_inf, loaded = 1100.0, 3.75, 3.53
    t = np.arange(1.0, 61.0)
    # 50 mV still to relax at 60 s; the ohmic jump from 3.53 V already seen; cooling
    v = v_inf - 0.0019 * (np.sqrt(t + load_s) - np.sqrt(t)) - 0.0001 * t
    fitted = relaxation(t, v, +1, loaded_V=loaded)
    assert fitted["method"] == "fit" and fitted["relaxed_V"] + fitted["half95_V"] < v_inf
    reading = dict(fitted, since_load_s=float(t[-1]))
    short = shorter_than_load(reading, load_s, loaded, +1)
    assert short["relaxed_V"] - short["half95_V"] < v_inf < short["relaxed_V"] + short["half95_V"]
    assert short["method"] == "fit, shorter than the load"
    assert shorter_than_load(reading, 50.0, loaded, +1) is reading


@pytest.mark.parametrize("kind", ["discharge", "flight"])
def test_a_flight_logs_landing_read_soon_gets_the_same_rule_as_a_discharge(kind):
    """A flight read from a flight log is a discharge to the rest after it: its fitted rest
    60 s after a 1,100 s flight takes the prior's share, upwards."""
    from dischargelab.logbook.health import _soon_after
    from dischargelab.logbook.relaxation import SHORT_REST_METHOD

    t = np.arange(1.0, 61.0)
    reading = dict(relaxation(t, 3.70 + 0.0 * t, +1, loaded_V=3.53), since_load_s=60.0)
    event = {"kind": kind, "duration_s": 1100.0, "end_voltage_V": 3.53,
             "resistance_ohm": 0.03, "mean_current_A": 20.0}
    read = _soon_after(reading, event)
    assert read["method"] == SHORT_REST_METHOD and read["relaxed_V"] > reading["relaxed_V"]


# --------------------------------------------------------------------------- charge

def _charge_starts(phases, *, current=3.0, dt=166.5, step_V=0.09, rise_V=0.055, seed=0):
    """Starts of charges at ``current`` sampled every ``dt``, each stepping up after
    ``phases[k] * dt`` into its first interval: the first sample lies ``step_V`` plus the
    rise of the charged share of an interval above the rest (0.3 mV of noise)."""
    rng = np.random.default_rng(seed)
    starts = []
    for p in phases:
        first = 3.68 + step_V + rise_V * (1 - p) + rng.normal(0, 3e-4)
        starts.append({"interval_s": dt, "rest_V": 3.68, "first_V": first, "first_A": current,
                       "next_V": first + rise_V, "next_A": current, "next_interval_s": dt})
    return starts


def test_a_charge_start_between_two_samples_is_placed_by_the_first_ones_voltage():
    """The trapezoid counts half an interval of current whenever the charger stepped up;
    the first sample's voltage says how much of the interval was charging."""
    phases = np.random.default_rng(3).uniform(0, 1, 40)
    starts = _charge_starts(phases)
    added = np.array(charge_start_corrections(starts))
    truth = 3.0 * 166.5 * (0.5 - phases) / 3600.0   # what the trapezoid missed [Ah]
    assert np.max(np.abs(truth)) > 0.05                # up to 0.07 Ah of a 1.7 Ah charge
    # what is left: the like charges' median phase is 1/2 only to ~1/sqrt(4 n)
    assert np.sqrt(np.mean((added - truth) ** 2)) < 0.3 * np.sqrt(np.mean(truth ** 2))
    assert np.max(np.abs(added - truth)) < 0.02
    # a first sample inside the charger's ramp: the start was just before it
    ramp = dict(starts[0], first_A=0.4, first_V=3.69)
    (placed,) = charge_start_corrections(starts[:20] + [ramp])[20:]
    assert placed == pytest.approx((0.5 * 3.0 - 0.4) * 166.5 / 3600.0)


def test_a_charge_start_is_placed_only_among_enough_like_charges():
    starts = _charge_starts(np.linspace(0.05, 0.95, 7))
    assert charge_start_corrections(starts) == [None] * 7          # 7 < 8 like charges
    other = _charge_starts(np.linspace(0.05, 0.95, 8), current=1.5)
    mixed = charge_start_corrections(starts + other)
    assert mixed[:7] == [None] * 7 and all(a is not None for a in mixed[7:])
    assert charge_start_corrections([None, None]) == [None, None]


def test_counted_charge_is_exact_for_steady_samples_and_honest_for_sparse_ones():
    t = np.arange(0.0, 3601.0, 1.0)
    q, sd = counted_charge(t, np.full(t.size, 2.0))
    assert q == pytest.approx(2.0) and sd < 1e-6

    # the CMU mission (take-off 75 s, cruise, landing 105 s) seen every 167 s at a random
    # phase: the 95 % interval from the samples covers the truth about 95 % of the time
    def current(x):
        return np.select([(x >= 0) & (x < 75), (x >= 75) & (x < 875), (x >= 875) & (x < 980)],
                         [15.0, 4.4, 15.0], 0.0)

    fine = np.arange(-10.0, 1100.0, 0.1)
    truth = np.trapezoid(current(fine), fine) / 3600
    rng = np.random.default_rng(4)
    covered = 0
    for _ in range(400):
        ts = np.arange(-300 + rng.uniform(0, 167), 1300, 167.0)
        sampling = sampling_figures(ts, current(ts))
        assert not sampling["resolved"]
        q, sd = counted_charge(ts, current(ts), unresolved=True)
        covered += abs(q - truth) <= 1.96 * sd
    assert covered / 400 >= 0.9
    # the same mission logged at 1 Hz is resolved and counted to well under 1 %
    ts = np.arange(-300.0, 1300.0, 1.0)
    sampling = sampling_figures(ts, current(ts))
    assert sampling["resolved"] and sampling["charge_sd_Ah"] < 0.01 * truth


# --------------------------------------------------------------------------- OCV, capacity

def test_open_circuit_voltage_learned_from_a_slow_discharge():
    soc = np.linspace(1.0, 0.0, 400)
    q = 3.0 * (1.0 - soc)
    ocv = ocv_from_soc(soc, "li-ion")
    current = np.full(soc.size, 0.6)
    curve = OcvCurve.from_discharge(q, 2 * (ocv - 0.05 * current), current, cells=2,
                                    resistance_ohm=0.1, rest_before_V=2 * ocv[0])
    for s in (0.2, 0.45, 0.8):
        assert curve.voltage_at(s) == pytest.approx(ocv_from_soc(s, "li-ion"), abs=0.002)
        assert curve.soc_at(float(ocv_from_soc(s, "li-ion"))) == pytest.approx(s, abs=0.01)


def test_capacity_between_two_rests_and_small_swings():
    curve = OcvCurve.prior("li-ion")
    true_cap = 2.5
    start = {"relaxed_V": 2 * float(curve.voltage_at(0.9)), "half95_V": 0.004, "current_A": 0.0}
    end = {"relaxed_V": 2 * float(curve.voltage_at(0.3)), "half95_V": 0.01, "current_A": 0.0}
    sa, sda = soc_reading(curve, start, 2)
    sb, sdb = soc_reading(curve, end, 2)
    cap, (lo, hi), how = capacity_between_rests(0.6 * true_cap, 0.01, sa, sda, sb, sdb)
    assert cap == pytest.approx(true_cap, rel=0.02) and lo < true_cap < hi
    # a charge: the charge counted is negative and the state of charge rises
    cap2, _, _ = capacity_between_rests(-0.6 * true_cap, 0.01, sb, sdb, sa, sda)
    assert cap2 == pytest.approx(cap)
    cap3, interval, why = capacity_between_rests(0.05, 0.001, 0.5, 0.01, 0.48, 0.01)
    assert cap3 is None and interval is None and f"{100 * MIN_SWING:.0f} %" in why
    assert capacity_between_rests(0.5, 0.01, 0.5, 0.01, 0.6, 0.01)[0] is None  # disagree


def test_reading_counts_the_idle_draw_and_the_relaxation_left():
    curve = OcvCurve.prior("lipo")
    v = float(curve.voltage_at(0.5))
    plain, sd_plain = soc_reading(curve, {"relaxed_V": v, "current_A": 0.0}, 1)
    drawn, sd_drawn = soc_reading(curve, {"relaxed_V": v - 0.05 * 1.0, "current_A": 1.0}, 1,
                                  resistance_ohm=0.05)
    assert drawn == pytest.approx(plain, abs=1e-9) and sd_drawn > sd_plain
    _, sd_left = soc_reading(curve, {"relaxed_V": v, "half95_V": 0.03}, 1)
    assert sd_left > sd_plain



def test_a_rest_after_a_charge_carries_the_gap_between_the_branches():
    """A rest after a charge that stopped short of full sits on the charge branch of the
    open-circuit voltage, the curves are discharge curves: the reading and what every
    such reading shares carry HYSTERESIS_SD_CELL_V; a rest after a discharge does not."""
    from dischargelab.logbook.estimates import HYSTERESIS_SD_CELL_V

    curve = OcvCurve.from_discharge(np.linspace(0, 3, 50), np.linspace(4.15, 3.0, 50),
                                    np.full(50, 0.6), cells=1, resistance_ohm=0.05)
    after_load = {"relaxed_V": float(curve.voltage_at(0.8)), "current_A": 0.0}
    after_charge = dict(after_load, after_charge={"taper": True, "max_voltage_V": 4.0})
    soc, sd = soc_reading(curve, after_load, 1)
    soc_c, sd_c = soc_reading(curve, after_charge, 1)
    slope = curve.slope(soc)
    assert soc_c == soc
    assert sd_c ** 2 - sd ** 2 == pytest.approx((HYSTERESIS_SD_CELL_V / slope) ** 2, rel=0.01)
    plain = systematic_share(curve, [0.8, 0.3], 0.5, None)
    assert systematic_share(curve, [0.8, 0.3], 0.5, None, [0.0, 0.0]) == plain
    branch = systematic_share(curve, [0.8, 0.3], 0.5, None, [HYSTERESIS_SD_CELL_V, 0.0])
    assert branch ** 2 - plain ** 2 == pytest.approx(
        (HYSTERESIS_SD_CELL_V / slope / 0.5) ** 2, rel=0.05)


# --------------------------------------------------------------------------- resistance

def test_resistance_at_reference_temperature_undoes_arrhenius():
    from dischargelab.models.base import arrhenius
    from dischargelab.models.thermal import BETA_PRIOR_K

    r25 = 0.030
    cold = r25 * float(arrhenius(5.0, BETA_PRIOR_K))
    r, (lo, hi), how = resistance_at_reference(cold, [0.95 * cold, 1.05 * cold], 5.0)
    assert r == pytest.approx(r25, rel=1e-9) and lo < r25 < hi and "5 degC" in how
    assert resistance_at_reference(r25, None, None)[0] == pytest.approx(r25)
    wide = resistance_at_reference(cold, [cold, cold], 5.0)[1]
    assert wide[1] - wide[0] > 0  # the Arrhenius coefficient's own uncertainty


def test_regression_resistance_of_a_sparse_log():
    """Samples 12 s apart of a 50 mOhm pack whose current wanders: no load step is short
    enough, the regression finds the resistance."""
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 900.0, 12.0)
    current = 15 + 5 * np.sin(t / 40.0) + rng.normal(0, 1.5, t.size)
    q = np.concatenate(([0.0], np.cumsum(0.5 * (current[1:] + current[:-1]) * np.diff(t))))
    voltage = 24.0 - 0.6 * q / 3600 - 0.05 * current + rng.normal(0, 0.005, t.size)
    r, (lo, hi) = regression_resistance(t, voltage, current)
    assert r == pytest.approx(0.05, rel=0.1) and lo < 0.05 < hi
    assert regression_resistance(t, voltage, np.full(t.size, 15.0)) == (None, None)
    # a steady cruise with two climbs (telemetry every 4 s): its quartiles hardly differ
    t = np.arange(0.0, 200.0, 4.0)
    current = 11.0 + rng.normal(0, 0.5, t.size)
    current[[25, 26, 40]] += 4.0
    q = np.concatenate(([0.0], np.cumsum(0.5 * (current[1:] + current[:-1]) * np.diff(t))))
    voltage = 15.6 - 0.6 * q / 3600 - 0.025 * current + rng.normal(0, 0.005, t.size)
    r, (lo, hi) = regression_resistance(t, voltage, current)
    assert lo < 0.025 < hi and hi - lo < 0.025


def test_drop_resistance_of_a_log_sampled_every_160_s():
    """A 4S pack at 40 mOhm whose mission and charge are seen every 160 s: neither steps
    nor a regression, but the loaded voltage's distance to the curve between the two
    rest readings gives the resistance."""
    from dischargelab.logbook.events import compact_curve

    curve = OcvCurve.prior("li-ion")
    t = np.arange(0.0, 1300.0, 160.0)
    current = np.full(t.size, 6.0)
    q = 6.0 * t / 3600
    soc = 0.95 - q / 3.0
    voltage = 4 * curve.voltage_at(soc) - 0.04 * current
    points = compact_curve(q, voltage, current)
    r, (lo, hi) = drop_resistance(points, 0.95, float(soc[-1]), curve, 4, 1)
    assert r == pytest.approx(0.04, rel=0.02) and lo < 0.04 < hi
    # a charge: the loaded voltage above the curve
    soc_c = float(soc[-1]) + q / 3.0
    points = compact_curve(q, 4 * curve.voltage_at(soc_c) + 0.04 * current, current)
    r, _ = drop_resistance(points, float(soc[-1]), float(soc_c[-1]), curve, 4, -1)
    assert r == pytest.approx(0.04, rel=0.02)
    # read the wrong way round, no positive resistance
    assert drop_resistance(points, float(soc[-1]), float(soc_c[-1]), curve, 4, 1) == (None, None)
    # a light load (0.3 A: 12 mV of drop against the curve's 60 mV): no resistance
    light = compact_curve(q / 20, 4 * curve.voltage_at(0.95 - q / 60) - 0.04 * 0.3,
                          np.full(t.size, 0.3))
    assert drop_resistance(light, 0.95, 0.95 - float(q[-1]) / 60, curve, 4, 1) == (None, None)


def test_capacity_read_through_a_curve_shares_its_error_and_its_ageing():
    """The error shared by every estimate read through one curve: the curve's own over the
    swing, and a share of the fade since it was learned."""
    curve = OcvCurve.prior("lipo")
    fresh = systematic_share(curve, [0.7], 0.6, 0.0)
    assert 0.002 < fresh < 0.05
    # a generic Li-ion curve carries real cells' spread about it: 74 mV per cell at 40 %
    # (an LG M50 rests 42 mV above a 30Q there) over a slope of 0.77 V
    spread = systematic_share(OcvCurve.prior("li-ion"), [0.4], 0.6, 0.0)
    assert spread == pytest.approx(np.hypot(0.015, 0.074) / 0.77 / 0.6, rel=0.05)
    assert systematic_share(curve, [0.7], 0.6, None) == fresh
    aged = systematic_share(curve, [0.7], 0.6, 0.2)
    assert aged == pytest.approx(np.hypot(fresh, OCV_AGEING_SD * 0.2))
    assert systematic_share(curve, [], 0.6, 0.2) == pytest.approx(OCV_AGEING_SD * 0.2)
    lo, hi = widen(3.0, [2.9, 3.1], 0.05)
    assert lo < 2.9 and hi > 3.1 and lo * hi == pytest.approx(9.0, rel=1e-3)


# --------------------------------------------------------------------------- cells

def test_a_weak_cell_stands_off_drifts_and_limits_the_pack():
    """Four cells, one with twice the resistance and 10 % less capacity."""
    curve = OcvCurve.prior("lipo")
    t = np.arange(0.0, 150.0, 0.1)
    current = np.where((t // 20) % 2 == 0, 10.0, 30.0)
    caps = np.array([1.6, 1.6, 1.6, 1.44])
    resistance = np.array([0.005, 0.005, 0.005, 0.010])
    q = np.concatenate(([0.0], np.cumsum(0.5 * (current[1:] + current[:-1])
                                         * np.diff(t)))) / 3600
    soc = 1.0 - q[:, None] / caps
    cells = curve.voltage_at(soc) - current[:, None] * resistance
    rest_before = {"time_s": np.arange(-60.0, 0.0, 1.0),
                   "cells_V": np.tile(curve.voltage_at(np.ones(4)), (60, 1)),
                   "since_load_s": None, "direction": 0}
    end = curve.voltage_at(soc[-1])
    rest_after = {"time_s": t[-1] + np.arange(1.0, 400.0, 1.0),
                  "cells_V": np.tile(end, (399, 1)),
                  "since_load_s": np.arange(1.0, 400.0, 1.0), "direction": 1}
    fig = cell_figures(t, current, cells, before=rest_before, after=rest_after)
    assert fig["count"] == 4 and fig["off"] == [4]
    assert fig["resistance_ohm"][3] == pytest.approx(0.010, rel=0.05)
    assert fig["sag_V"][3] == max(fig["sag_V"])
    share, weakest = weakest_share(curve, fig, float(q[-1]), 0.001)
    assert weakest == 4 and share == pytest.approx(1.44 / caps.mean(), abs=0.03)
    assert drift_flags([[], [4], [4], [4]], [0.0, 0.01, 0.02, 0.03]) == [False, False, True,
                                                                          True]
    assert drift_flags([[4], [4]], [0.03, 0.01]) == [False, False]  # balanced back


# --------------------------------------------------------------------------- order

def _ev(source, idx=0, start=None, cycle=None):
    return {"id": source * 100 + idx, "source_id": source, "idx": idx, "start_time": start,
            "cycle": cycle}


def test_undated_files_follow_what_the_pack_had_when_they_were_added():
    dated = [_ev(2, start="2024-05-01T10:00:00", cycle=1),
             _ev(3, start="2024-05-02T10:00:00", cycle=10),
             _ev(4, start="2024-05-03T10:00:00", cycle=20)]
    first_undated = _ev(1)                                  # added before everything
    later_undated = [_ev(5, cycle=30), _ev(6), _ev(6, idx=1)]  # added after the three
    dated_later = _ev(7, start="2024-05-02T12:00:00")         # dated: at its time
    got = order_events([*later_undated, dated_later, *dated, first_undated])
    assert [(e["source_id"], e["idx"]) for e in got] == [
        (1, 0), (2, 0), (3, 0), (7, 0), (4, 0), (5, 0), (6, 0), (6, 1)]


def test_an_undated_numbered_file_goes_where_its_number_says_among_numbered_dated_ones():
    """A cycle file saved without its clock time, among dated cycle files: placed after
    the dated one of the highest number below its own, whenever it was added."""
    dated = [_ev(2, start="2024-05-01T10:00:00", cycle=1),
             _ev(3, start="2024-05-02T10:00:00", cycle=100),
             _ev(4, start="2024-05-03T10:00:00", cycle=200)]
    for added_first in (True, False):
        undated = _ev(1 if added_first else 5, cycle=110)
        got = order_events([undated, *dated] if added_first else [*dated, undated])
        assert [e["cycle"] for e in got] == [1, 100, 110, 200]


def test_files_sharing_a_date_or_added_together_undated_follow_their_cycle_numbers():
    same_day = [_ev(k, start="2024-05-01T00:00:00", cycle=c) for k, c in
                ((1, 30), (2, 10), (3, 20))]
    assert [e["cycle"] for e in order_events(same_day)] == [10, 20, 30]
    undated = [_ev(k, cycle=c) for k, c in ((1, 30), (2, 10), (3, 20))]
    assert [e["cycle"] for e in order_events(undated)] == [10, 20, 30]
    mixed = [_ev(1, cycle=30), _ev(2), _ev(3, cycle=20)]    # not all numbered: added order
    assert [e["source_id"] for e in order_events(mixed)] == [1, 2, 3]


def test_equivalent_full_cycles_count_discharges_or_else_the_charges():
    from dischargelab.logbook.health import equivalent_full_cycles

    log = [{"kind": "discharge", "discharged_Ah": 1.5}, {"kind": "rest", "discharged_Ah": 0.0},
           {"kind": "charge", "discharged_Ah": 0.0, "details": {"charge": {"charged_Ah": 1.6}}},
           {"kind": "discharge", "discharged_Ah": 1.5}]
    np.testing.assert_allclose(equivalent_full_cycles(log, 3.0), [0.5, 0.5, 0.5, 1.0])
    charger_only = [e for e in log if e["kind"] != "discharge"]
    np.testing.assert_allclose(equivalent_full_cycles(charger_only, 3.0), [0.0, 1.6 / 3])


@pytest.mark.parametrize("amps", [20e-6, 2e-3, 2.0])
def test_split_log_without_steps_at_every_scale(amps):
    """Rest, discharge, rest, charge, rest of a cell at 20 uA, 2 mA and 2 A, recorded every
    10 s, then every 300 s inside the loads: the same five events, no gap."""
    rng = np.random.default_rng(5)
    t, i = [], []
    clock = 0.0
    for level, duration in ((0.0, 600), (amps, 7200), (0.0, 600), (-amps, 7200), (0.0, 600)):
        times = [*np.arange(0.0, 60.0, 10.0), *np.arange(60.0, duration, 300.0)] if level \
            else np.arange(0.0, duration, 10.0)
        t += [clock + s for s in times]
        i += [level + rng.normal(0.0, amps * 1e-3) for _ in times]
        clock += duration
    spans = split_log(np.array(t), np.array(i))
    assert [sp.kind for sp in spans] == ["rest", "discharge", "rest", "charge", "rest"]


def test_idle_threshold_of_noise_alone_keeps_its_floor():
    """A logger's noise with no load stays idle (the small-cell scaling needs a current
    above the noise)."""
    rng = np.random.default_rng(6)
    assert idle_threshold(rng.normal(0.0, 1e-3, 500)) >= MIN_IDLE_A


def test_the_rest_after_a_hard_load_is_read_not_taken_for_a_pack_swap(tmp_path):
    """A 1S pack at 2.25C with 21 mOhm: the load's end lifts the voltage by 8 % (3.07 to
    3.32 V), more than a pack swap's 5 % jump; the current fell with it, so it is the rest
    beginning, and the flight's end is read there (it was the last loaded voltage plus a
    drop, 17 % low). A jump while the load runs on is still a swap."""
    from dischargelab.io.segment import voltage_jumps_up
    from dischargelab.logbook import Logbook

    capacity, amps, ohm = 5.0, 11.25, 0.021
    t = np.arange(0.0, 60 + 1150 + 600, 1.0)
    load = (t >= 60) & (t < 1210)
    current = np.where(load, amps, 0.0)
    soc = 1.0 - np.cumsum(current) / 3600.0 / capacity
    since = np.clip(t - 1210, 0.0, None)
    relax = np.where(t >= 1210, 0.05 * np.exp(-since / 120.0), 0.0)  # polarisation left
    voltage = ocv_from_soc(soc, "li-ion") - current * ohm - np.where(load, 0.05, relax)
    assert voltage[1210] / voltage[1209] > 1.05
    import pandas as pd

    pd.DataFrame({"time_s": t, "voltage_V": voltage, "current_A": current}).to_csv(
        tmp_path / "hard.csv", index=False)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.set_pack("p", cells=1, chemistry="li-ion")
        lb.add(tmp_path / "hard.csv", pack="p")
        (event,) = [e for e in lb.health("p").events if e.capacity_Ah is not None]
    assert not any("no rest after it" in note for note in event.notes)
    assert event.capacity_Ah == pytest.approx(capacity, rel=0.03)
    steps = voltage_jumps_up([3.07, 3.32, 3.60], [11.25, 0.0, 11.25], 2.0)
    assert steps.tolist() == [False, True]
