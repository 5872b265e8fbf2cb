"""How a duration is written: one rendering, its units switched at a minute and two hours,
rounded to the last unit shown half away from zero."""

from __future__ import annotations

import math

import pytest

from dischargelab.formatting import (
    MISSING,
    OPEN,
    duration,
    duration_interval,
    mission_text,
)


@pytest.mark.parametrize("seconds, text", [
    (0, "0 s"), (0.4, "0 s"), (-0.4, "0 s"), (0.5, "1 s"), (42.2, "42 s"), (59.49, "59 s"),
    (59.5, "1 min 00 s"), (60, "1 min 00 s"), (61, "1 min 01 s"), (4168.7, "69 min 29 s"),
    (7199.49, "119 min 59 s"), (7199.5, "2 h 00 min"), (7229.9, "2 h 00 min"),
    (7230, "2 h 01 min"), (2 * 86400 + 3600 * 3 + 60 * 5, "51 h 05 min"),
    (-65, "-1 min 05 s"), (-8, "-8 s")])
def test_a_duration_switches_units_at_a_minute_and_two_hours(seconds, text):
    assert duration(seconds) == text


def test_signed_and_missing_durations():
    assert duration(12, signed=True) == "+12 s"
    assert duration(-12, signed=True) == "-12 s"
    assert duration(0.2, signed=True) == "0 s"
    for value in (None, math.nan, math.inf, -math.inf, True, "x"):
        assert duration(value) == MISSING


def test_a_duration_rounds_its_exact_value_half_up_as_tofixed_does():
    # 0.5 and 2.5 are exact in binary: half up (Python's round() would give 0 and 2)
    assert duration(0.5) == "1 s" and duration(2.5) == "3 s"
    # 60.49999999999999 lies below the half: 60 s
    assert duration(60.49999999999999) == "1 min 00 s"


def test_duration_interval_and_mission_texts():
    assert duration_interval([4030, 4350]) == "67 min 10 s - 72 min 30 s"
    assert duration_interval([None, 90]) == f"{OPEN} - 1 min 30 s"
    assert duration_interval(None) == MISSING
    row = {"flight_time_s": 530.0, "endurance_s": 564.2, "cutoff_time_s": math.nan,
           "reserve_time_s": None,
           "uncertainty": {"available": True, "endurance_s": {"low": 527.0, "high": 605.4}},
           "stretch": {"max_s": 334.0, "margin_s": -3.6}}
    assert mission_text(row) == {
        "flight_time_s": "8 min 50 s", "endurance_s": "9 min 24 s", "cutoff_time_s": MISSING,
        "reserve_time_s": MISSING, "endurance_interval95": "8 min 47 s - 10 min 05 s",
        "stretch_max_s": "5 min 34 s", "stretch_margin_s": "-4 s"}
