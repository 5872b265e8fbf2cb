"""A pack's figures over its life from per-event estimates: the smoother (trend.py) and the
end-of-life forecast (forecast.py), on synthetic lives whose truth is known."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from dischargelab.logbook.forecast import fit_fade, forecast_capacity, forecast_eol
from dischargelab.logbook.trend import DEFAULT_NUGGET_SHARE, Z95, Smoothed, smooth

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def lives():
    """The seeded generator of capacity lives the forecast is calibrated on."""
    if "bench_lives" not in sys.modules:  # a dataclass module must be known while it loads
        spec = importlib.util.spec_from_file_location("bench_lives", BENCHMARKS / "_lives.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules["bench_lives"] = module
        spec.loader.exec_module(module)
    return sys.modules["bench_lives"]


# --------------------------------------------------------------------------- smoother

def test_capacity_now_of_a_straight_fade_holds_the_truth_and_names_its_events():
    rng = np.random.default_rng(0)
    x = np.linspace(0, 300, 31)
    truth = 3.0 - 0.001 * x
    y = truth + rng.normal(0, 0.004, x.size)
    y[12] += 0.08  # an overcharged cycle
    s = smooth(x, y, y - 0.0005, y + 0.0005)  # coulomb-count intervals: far too tight
    value, (lo, hi) = s.interval95(300.0)
    assert lo < truth[-1] < hi and hi - lo < 0.02
    assert s.nugget == pytest.approx(0.004, rel=0.5)  # the scatter the intervals miss
    assert s.weights[12] < 0.2 < np.median(s.weights)
    assert s.influence.sum() == pytest.approx(1.0)
    assert np.argmax(s.influence) == x.size - 1  # today's value rests on the latest events
    assert np.abs(s.influence[:10]).sum() < 0.1 < 0.8 < s.influence[-10:].sum()


def test_estimates_are_weighted_by_their_intervals():
    """A precise estimate pulls the trend towards it, a vague one hardly at all."""
    x = np.arange(10.0) * 10
    y = 3.0 - 0.002 * x
    y[-1] += 0.05
    wide = np.full(x.size, 0.01)
    narrow = wide.copy()
    narrow[-1] = 0.001
    vague = wide.copy()
    vague[-1] = 0.1
    pulled = smooth(x, y, y - narrow, y + narrow, robust=False).interval95(90.0)[0]
    ignored = smooth(x, y, y - vague, y + vague, robust=False).interval95(90.0)[0]
    assert pulled > ignored + 0.02
    assert ignored == pytest.approx(3.0 - 0.18, abs=0.015)


def test_an_error_the_estimates_share_does_not_average_out():
    """A thousand estimates read through one curve that is 3 % off: alone they make a band
    far narrower than the error; their shared standard deviation keeps it honest."""
    rng = np.random.default_rng(4)
    x = np.linspace(0, 200, 1000)
    truth = 3.0 - 0.002 * x
    y = 1.03 * truth + rng.normal(0, 0.06, x.size)
    half = np.full(x.size, 0.12)
    naive = smooth(x, y, y - half, y + half)
    value, (lo, hi) = naive.interval95(200.0)
    assert not lo < truth[-1] < hi and naive.systematic == 0.0
    honest = smooth(x, y, y - half, y + half, systematic=0.02 * y)
    value, (lo, hi) = honest.interval95(200.0)
    assert lo < truth[-1] < hi and hi - lo < 0.2 * truth[-1]
    assert honest.systematic == pytest.approx(0.02 * value, rel=0.05)
    band_lo, band_hi = honest.band()
    assert np.all(band_hi - band_lo > 3.5 * 0.02 * truth.min())  # all along the life
    assert Smoothed.from_dict(honest.to_dict()).systematic == pytest.approx(honest.systematic)


def test_few_estimates_and_the_band_ahead():
    one = smooth([50.0], [2.5], [2.49], [2.51])
    value, (lo, hi) = one.interval95(50.0)
    assert value == 2.5 and (hi - lo) / 2 == pytest.approx(
        Z95 * np.hypot(0.01 / Z95, DEFAULT_NUGGET_SHARE * 2.5), rel=1e-9)
    two = smooth([0.0, 100.0], [3.0, 2.8])
    assert two.interval95(50.0)[0] == pytest.approx(2.9)
    # ahead of the last estimate the value is carried on by the trend and widens
    x = np.linspace(0, 100, 20)
    s = smooth(x, 3.0 - 0.002 * x + np.random.default_rng(1).normal(0, 0.003, x.size))
    (m1, m2), (s1, s2) = s.at([100.0, 150.0])
    assert m2 == pytest.approx(m1 - 0.1, abs=0.02) and s2 > s1
    assert smooth([np.nan], [np.nan]) is None


def test_smoothed_band_round_trips_through_its_dict():
    x = np.linspace(0, 200, 25)
    s = smooth(x, 3.0 - 0.001 * x + np.random.default_rng(2).normal(0, 0.003, x.size))
    d = s.to_dict()
    back = Smoothed.from_dict(d)
    assert back.to_dict()["value"] == pytest.approx(d["value"])
    assert back.to_dict()["lo"] == pytest.approx(d["lo"])
    assert back.interval95(200.0)[1] == pytest.approx(s.interval95(200.0)[1], rel=1e-9)


@pytest.mark.slow
def test_capacity_now_covers_the_truth_on_synthetic_lives():
    """Capacity tests and partial estimates over seeded lives: the 95 % interval holds the
    true capacity in at least 85 % of 60 lives (the benchmark measures it on more)."""
    gen = lives()
    hits = []
    for seed in range(60):
        life = gen.make_life(700 + seed, seed % 2 == 0, partial_share=(seed % 3) / 2)
        x, q, lo, hi = life.upto((0.3 + 0.8 * (seed % 5) / 4) * life.eol_efc)
        _, (a, b) = smooth(x, q, lo, hi).interval95(float(x[-1]))
        hits.append(a <= float(life.truth(x[-1])[()]) <= b)
    assert np.mean(hits) >= 0.85


# --------------------------------------------------------------------------- forecast

def bent(x, knee=400.0, before=0.0008, after=0.002):
    """Relative capacity: a line that bends at ``knee`` EFC to a faster fade."""
    return 1.0 - before * x - (after - before) * np.clip(x - knee, 0, None)


def test_a_knee_in_the_data_is_found_and_a_line_is_not_bent():
    rng = np.random.default_rng(4)
    x = np.linspace(0, 560, 57)
    q = 3.0 * bent(x) + rng.normal(0, 0.004, x.size)
    fit = fit_fade(x, q)
    assert "knee" in fit.family and fit.bend_odds > 100
    assert fit.knee_efc == pytest.approx(400, rel=0.1)
    straight = fit_fade(x, 3.0 * (1 - 0.0008 * x) + rng.normal(0, 0.004, x.size))
    assert straight.family == "line" and straight.knee_efc is None and straight.bend_odds < 1


def test_forecast_after_a_knee_is_finite_centred_and_physical():
    rng = np.random.default_rng(5)
    x = np.linspace(0, 450, 46)
    q = 3.0 * bent(x) + rng.normal(0, 0.004, x.size)
    truth = 400 + (1 - 0.4 - 0.0008 * 400) / 0.002  # 40 % of new, well after the knee
    fit, ahead = forecast_capacity(x, q, None, None, 3.0, 0.4 * 3.0)
    lo, hi = ahead.interval95
    assert lo is not None and hi is not None and lo <= truth <= hi
    assert ahead.eol_efc == pytest.approx(truth, rel=0.1)
    assert ahead.crossed > 0.975 and np.all(ahead.low > 0)
    # far futures stay above zero: the band is built on the logarithm of the capacity
    assert forecast_eol(fit, 3.0, 0.05 * 3.0, paths=500).low.min() > 0


@pytest.mark.slow
def test_end_of_life_interval_is_calibrated_on_synthetic_lives():
    """Lives with and without knees, forecast from half their life: the 95 % interval holds
    the true crossing in at least 85 % of 40 (the benchmark measures it on more)."""
    from dischargelab.logbook.outliers import flag_outliers

    gen = lives()
    hits = []
    for seed in range(40):
        life = gen.make_life(900 + seed, seed % 2 == 0)
        x, q, lo, hi = life.upto(0.5 * life.eol_efc)
        keep = ~flag_outliers(x, q)
        _, ahead = forecast_capacity(x[keep], q[keep], lo[keep], hi[keep], life.q0_Ah,
                                     0.8 * life.q0_Ah)
        a, b = ahead.interval95
        hits.append((a or 0) <= life.eol_efc <= (b or np.inf))
    assert np.mean(hits) >= 0.85


# --------------------------------------------------------------------------- a pack's health

def cell_c_rows(shared_data, cycles) -> list[dict]:
    """Stored-event rows of cell C's files (what the logbook hands to build_health)."""
    from dischargelab.logbook.summarise import summarise_source

    rows = []
    for k, c in enumerate(cycles):
        summary = summarise_source(shared_data / "samsung30q_ageing_cellC" /
                                   f"DischargeCycle{c:03d}.txt")
        for e in summary.events:
            lo, hi = e["resistance_interval95"] or (None, None)
            rows.append(dict(e, id=10 * k + e["index"], source=summary.file_name,
                             resistance_low_ohm=lo, resistance_high_ohm=hi))
    return rows


PACK = {"name": "C", "label_capacity_Ah": None, "cells": 1, "chemistry": "li-ion"}


def test_health_round_trips_through_its_json(shared_data):
    """The figures can be stored once and read back: from_dict(to_dict()) says the same."""
    import json

    from dischargelab.logbook.results import Health, build_health

    h = build_health(PACK, cell_c_rows(shared_data, range(10, 200, 10)), None, 0.8)
    d = json.loads(json.dumps(h.to_dict()))
    back = Health.from_dict(d)
    assert back.to_dict() == d
    assert back.capacity_now_Ah == h.capacity_now_Ah and back.efc_now == h.efc_now
    assert [e.full for e in back.events] == [e.full for e in h.events]
    assert back.forecast.eol_efc == h.forecast.eol_efc


def test_resistance_at_reference_conditions_and_cells_are_used_when_events_give_them(
        shared_data, monkeypatch, tmp_path):
    """Events that carry a resistance at reference conditions and per-cell figures (the
    per-event estimates' contract): the trend uses the former, the plot shows the cells."""
    from dischargelab.logbook import health as per_event
    from dischargelab.logbook.results import build_health
    from dischargelab.plot import save

    plain = per_event.EventHealth.to_dict

    def richer(self):
        d = plain(self)
        if d["resistance_ohm"] is not None:
            d["resistance_ref_ohm"] = 0.9 * d["resistance_ohm"]
            d["resistance_ref_interval95"] = [0.88 * d["resistance_ohm"],
                                              0.92 * d["resistance_ohm"]]
        d["cells"] = {"rest_spread_V": 0.004 + 1e-5 * (d["efc"] or 0), "drift": False}
        return d

    monkeypatch.setattr(per_event.EventHealth, "to_dict", richer)
    h = build_health(PACK, cell_c_rows(shared_data, range(10, 120, 10)), None, 0.8)
    assert h.today["resistance_basis"] == "reference conditions"
    last = h.events[-1]
    assert h.resistance_now_ohm == pytest.approx(0.9 * last.resistance_ohm, rel=0.05)
    axes = h.plot()
    assert len(axes) == 3 and axes[2].get_ylabel() == "cell spread [mV]"
    assert "reference conditions" in axes[1].get_ylabel()
    assert save(axes[0], tmp_path / "h.png").stat().st_size > 10_000


def test_an_offset_between_kinds_of_estimate_is_learned_not_read_as_fade():
    # a pack with full discharges early in its life and charges all along that read 5 %
    # high (their constant-voltage overshoot): the charges carry the trend after the last
    # full discharge, on the full discharges' scale
    rng = np.random.default_rng(3)
    x_full = np.array([0.0, 5.0, 10.0, 15.0])
    x_charge = np.linspace(0.0, 100.0, 60)
    truth = lambda x: 3.0 - 0.002 * x  # noqa: E731
    y_full = truth(x_full) + rng.normal(0, 0.003, x_full.size)
    y_charge = 1.05 * truth(x_charge) + rng.normal(0, 0.01, x_charge.size)
    x = np.r_[x_full, x_charge]
    y = np.r_[y_full, y_charge]
    half = np.r_[np.full(x_full.size, 0.005), np.full(x_charge.size, 0.03)]
    kinds = ["full"] * x_full.size + ["charge"] * x_charge.size
    s = smooth(x, y, y - half, y + half, kinds=kinds, offset_sd={"charge": 0.06})
    value, (lo, hi) = s.interval95(100.0)
    assert lo < truth(100.0) < hi
    assert abs(value - truth(100.0)) < 0.03          # without the offset: +0.14 Ah
    assert s.offsets["charge"] == pytest.approx(0.05 * 2.9, abs=0.04)
    # one kind alone: its offset unknown, the band carries its prior
    only = smooth(x_charge, y_charge, y_charge - 0.03, y_charge + 0.03,
                  kinds=["charge"] * x_charge.size, offset_sd={"charge": 0.06})
    plain = smooth(x_charge, y_charge, y_charge - 0.03, y_charge + 0.03)
    assert only.at(100.0)[1][0] > 2 * plain.at(100.0)[1][0]
    assert only.at(100.0)[1][0] == pytest.approx(0.06, rel=0.3)


def test_estimates_sharing_one_efc_are_each_counted():
    x = np.array([0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0])
    y = np.array([3.0, 3.02, 2.99, 3.01, 2.98, 3.0, 2.97, 2.99])
    s = smooth(x, y, y - 0.01, y + 0.01)
    assert np.isfinite(s.influence).all() and s.influence.sum() == pytest.approx(1.0)
    assert s.interval95(3.0)[0] == pytest.approx(2.98, abs=0.01)
