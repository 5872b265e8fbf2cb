"""Segment finding on canonical frames: sign, load runs, splits, rest sample."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dischargelab.errors import DataError
from dischargelab.io.segment import (
    choose_segment,
    detect_sign,
    find_segments,
    runs,
    voltage_step_rest,
)


def frame(t, v, i, **extra):
    data = {"time_s": np.asarray(t, float), "voltage_V": np.asarray(v, float),
            "current_A": np.asarray(i, float)}
    data.update(extra)
    return pd.DataFrame(data)


def test_runs():
    assert runs(np.array([0, 1, 1, 0, 1, 0, 0, 1], bool)) == [(1, 3), (4, 5), (7, 8)]
    assert runs(np.zeros(3, bool)) == []


def test_detect_sign_discharge_negative():
    t = np.arange(100.0)
    v = 4.1 - 0.005 * t
    sign, evidence = detect_sign(t, np.full(100, -3.0), v)
    assert sign == -1
    assert "falls while the current is negative" in evidence


def test_detect_sign_uses_voltage_not_magnitude():
    # fast charge at 6 A (voltage rises), then slow discharge at 1 A (voltage falls):
    # the larger current is the charge, and it is positive in this file
    t = np.arange(200.0)
    i = np.where(t < 60, 6.0, -1.0)
    v = np.where(t < 60, 3.6 + 0.01 * t, 4.2 - 0.004 * (t - 60))
    sign, _ = detect_sign(t, i, v)
    assert sign == -1


def _burst_flight(burst_s: float, hover_A: float, gust: float, fall_V: float,
                  resistance_ohm: float):
    """(t, i, v) of a 4S flight over 500 s: ``burst_s`` at 45 A, then a hover at
    ``hover_A`` +- ``gust`` (a new level every 30 s); the open-circuit voltage falls by
    ``fall_V`` with the charge moved, the loaded voltage ``resistance_ohm`` x i below."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 500.0, 0.5)
    i = np.where(t < burst_s, 45.0, hover_A)
    for start in np.arange(burst_s, 500.0, 30.0):
        i[(t >= start) & (t < start + 30)] = hover_A * rng.uniform(1 - gust, 1 + gust)
    q = np.cumsum(i) * 0.5 / 3600
    return t, i, 15.2 - fall_V * q / q[-1] - resistance_ohm * i


@pytest.mark.parametrize("file_sign", [1, -1])
def test_detect_sign_of_a_flight_from_a_take_off_burst_to_a_light_hover(file_sign):
    """A 4S flight over the flat middle of a LiPo curve: 20 s at 45 A, then a hover at
    22-38 A (gusts every 30 s) for 8 minutes; the drop at the burst's current exceeds the
    0.3 V fall of the open-circuit voltage over the flight, so the last loaded voltage
    lies above the first. The voltage still falls with the charge moved at any current."""
    t, i, v = _burst_flight(20.0, 30.0, 0.25, 0.3, 0.03)
    assert v[-1] > v[0]
    sign, evidence = detect_sign(t, file_sign * i, v)
    assert sign == file_sign, evidence


def test_a_flight_whose_loaded_voltage_ends_above_its_take_off_is_read(tmp_path):
    """A minute's climb at 45 A, then a hover at 22-28 A on the flat of a LiPo curve, a
    rest before and after: the loaded voltage ends 0.7 V above the climb's. Read as one
    discharge (its sign found, and not refused as a voltage that rises)."""
    import pandas as pd

    import dischargelab as dl

    t, i, v = _burst_flight(60.0, 25.0, 0.1, 0.2, 0.045)
    assert np.median(v[-100:]) > np.median(v[:100]) + 0.5
    rest = np.arange(1.0, 31.0)
    frame = pd.DataFrame({"time_s": np.concatenate((rest - 31.0, t, 500.0 + rest)),
                          "voltage_V": np.concatenate((np.full(30, 15.2), v,
                                                       np.full(30, 15.0))),
                          "current_A": np.concatenate((np.zeros(30), i, np.zeros(30)))})
    frame.to_csv(tmp_path / "flight.csv", index=False)
    for sign in ("auto", "positive"):
        d = dl.read(tmp_path / "flight.csv", sign=sign)
        assert d.current_A.max() == pytest.approx(45.0) and d.time_s[-1] > 490


def test_detect_sign_without_trend_uses_majority():
    t = np.arange(50.0)
    sign, evidence = detect_sign(t, np.full(50, 2.0), np.full(50, 3.7))
    assert sign == 1
    assert "no clear voltage trend" in evidence


def test_find_segments_constant_current_lab_cycle():
    i = np.concatenate([np.zeros(5), np.full(20, 3.0), np.zeros(5), np.full(10, -1.0),
                        np.zeros(2), np.full(30, 3.0), np.zeros(4)])
    t = np.arange(i.size, dtype=float)
    v = 4.0 - 0.001 * t
    search = find_segments(frame(t, v, i))
    assert [(s.start, s.stop) for s in search.segments] == [(5, 25), (42, 72)]
    assert [s.ended_by for s in search.segments] == ["current falls to idle",
                                                     "current falls to idle"]
    assert search.threshold_A == pytest.approx(0.6)  # 20 % of the 3 A load
    assert not search.variable
    assert (search.state[30:40] == -1).all()
    assert choose_segment(search, frame(t, v, i), "auto").number == 2
    assert choose_segment(search, frame(t, v, i), 1).number == 1


def test_gaps_split_only_variable_current():
    t = np.concatenate([np.arange(20.0), 100 + np.arange(20.0)])
    v = 4.0 - 0.001 * t
    constant = find_segments(frame(t, v, np.full(40, 3.0)))
    assert len(constant.segments) == 1
    rng = np.random.default_rng(1)
    variable = find_segments(frame(t, v, rng.uniform(10, 25, 40)))
    assert [s.rows for s in variable.segments] == [20, 20]
    assert variable.segments[0].ended_by == "gap in the samples"
    assert variable.gap_limit_s == pytest.approx(4.0)


def test_landed_rows_are_idle_and_breaks_split():
    t = np.arange(30.0)
    i = np.full(30, 15.0)
    mode = np.array(["GPS_WAYPOINT"] * 30, dtype=object)
    mode[10:12] = "LANDED"
    search = find_segments(frame(t, 25 - 0.01 * t, i, flight_mode=mode), breaks_s=[20.5])
    assert [(s.start, s.stop) for s in search.segments] == [(0, 10), (12, 21), (21, 30)]
    assert search.segments[0].ended_by == "landed"
    assert search.segments[1].ended_by == "take-off or landing event"


def test_voltage_jump_without_current_drop_is_a_swap():
    t = np.arange(40.0)
    v = 21.0 - 0.01 * t
    v[25:] += 4.0
    search = find_segments(frame(t, v, np.full(40, 15.0)))
    assert [s.rows for s in search.segments] == [25, 15]
    assert search.segments[0].ended_by == "voltage jumps up (pack swap?)"


def test_voltage_rise_when_current_drops_is_not_a_swap():
    t = np.arange(40.0)
    i = np.where((t > 15) & (t < 20), 6.0, 20.0)
    v = 24.0 - 0.01 * t - 0.05 * i  # 0.7 V recovery = 3 % when the load drops
    v[16] += 0.5  # plus a 2 % overshoot
    search = find_segments(frame(t, v, i))
    assert len(search.segments) == 1


def test_short_runs_are_not_segments():
    i = np.array([0, 5, 5, 0, 0, 5, 5, 5, 5, 0], float)
    t = np.arange(i.size, dtype=float)
    search = find_segments(frame(t, 4 - 0.01 * t, i))
    assert [(s.start, s.stop) for s in search.segments] == [(5, 9)]
    assert search.short_rows[[1, 2]].all()


def test_no_discharge_is_an_error():
    t = np.arange(10.0)
    with pytest.raises(DataError, match="never positive"):
        find_segments(frame(t, np.full(10, 4.0), np.full(10, -2.0)))
    search = find_segments(frame(t, np.full(10, 4.0), np.array([0, 5, 0, 0, 0, 0, 0, 0, 0, 0.])))
    with pytest.raises(DataError, match="no discharge found"):
        choose_segment(search, frame(t, np.full(10, 4.0), np.zeros(10)), "auto")


def test_voltage_step_rest():
    v = np.concatenate([[4.18], 4.126 - 0.002 * np.arange(20)])
    is_rest, why = voltage_step_rest(v)
    assert is_rest and "load switched on" in why
    # K2-like start: the first step is not larger than the next ones
    v = np.array([3.6645, 3.6394, 3.5378, 3.4546, 3.385, 3.3373, 3.309, 3.2927, 3.2818, 3.2724,
                  3.2665, 3.2622, 3.2567])
    assert voltage_step_rest(v)[0] is False
    assert voltage_step_rest([4.1, 4.0])[0] is False


@settings(max_examples=60)
@given(st.lists(st.tuples(st.sampled_from(["idle", "load", "charge"]),
                          st.integers(min_value=3, max_value=15)), min_size=1, max_size=8))
def test_segments_are_the_load_blocks(blocks):
    """Constant-current blocks: every load block (not touching another) is one segment."""
    level = {"idle": 0.0005, "load": 4.0, "charge": -2.0}  # idle: logger noise < 1 mA
    merged = []
    for kind, n in blocks:  # adjacent blocks of the same kind are one block
        if merged and merged[-1][0] == kind:
            merged[-1] = (kind, merged[-1][1] + n)
        else:
            merged.append((kind, n))
    i = np.concatenate([np.full(n, level[kind]) for kind, n in merged])
    t = np.arange(i.size, dtype=float)
    v = 4.0 - 0.001 * t
    expected, k = [], 0
    for kind, n in merged:
        if kind == "load":
            expected.append((k, k + n))
        k += n
    if not expected:
        with pytest.raises(DataError):
            find_segments(frame(t, v, i))
        return
    search = find_segments(frame(t, v, i))
    assert [(s.start, s.stop) for s in search.segments] == expected


@pytest.mark.parametrize("amps", [50e-6, 0.5e-3, 5.0])
def test_a_small_cells_discharge_is_found_at_its_own_scale(amps):
    """A rest, a constant-current discharge and a rest: found at 50 uA as at 5 A (the 1 mA
    floor gives way when the current stands above its noise)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 3000.0, 10.0)
    on = (t >= 500) & (t < 2500)
    i = np.where(on, amps, 0.0) + rng.normal(0.0, amps * 1e-3, t.size)
    v = 4.1 - 0.5 * np.cumsum(on) / on.sum() - 0.05 * on
    search = find_segments(frame(t, v, i))
    assert len(search.segments) == 1
    seg = search.segments[0]
    assert seg.rows == int(on.sum())


def test_noise_alone_is_no_discharge():
    """A logger's noise around zero with no load is not a small cell's discharge."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 3000.0, 10.0)
    i = rng.normal(0.0, 2e-4, t.size)
    v = 3.9 + rng.normal(0.0, 1e-4, t.size)
    with pytest.raises(DataError):
        find_segments(frame(t, v, i))
