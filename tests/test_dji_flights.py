"""DJI M100 logs: one discharge segment per flight, split at pack changes and landings only.

The flights are counted independently of the reader: a flight is one executed
automatic take-off (``-> AUTO_TAKEOFF (state = EXECUTING)``) in the raw app log.
Counts: waddle1 7 (3 on the first pack, 4 on the second), every other file 1:
11 flights in the five logs. The derived CSV of each log holds the same flights.
"""

import re

import numpy as np
import pytest

from dischargelab.io import read_discharge
from dischargelab.io.dji import flight_breaks, mode_events

FLIGHTS = {
    "19-11-28_waddle1_2019_11_28_18_28": 7,
    "19-12-17_tablet1_2019_12_17_18_49": 1,
    "20-01-12_tablet1_2020_01_12_12_08": 1,
    "20-01-12_tablet3_2020_01_12_13_24": 1,
    "20-01-21_tab3_2020_01_21_20_55": 1,
}

_TAKEOFF = re.compile(r"onFlightMode change: \S+ -> AUTO_TAKEOFF \(state = EXECUTING\)")


def takeoffs(raw_path) -> int:
    """Executed take-offs in a raw app log (each starts one flight)."""
    return len(_TAKEOFF.findall(raw_path.read_text(encoding="utf-8", errors="replace")))


@pytest.mark.parametrize("stem", list(FLIGHTS))
def test_one_segment_per_flight_in_raw_and_derived_files(shared_data, stem):
    folder = shared_data / "dji_m100_flights"
    raw = folder / f"raw_{stem}.txt"
    assert takeoffs(raw) == FLIGHTS[stem]
    for path in (raw, folder / f"derived_battery_{stem}.csv"):
        _, meta = read_discharge(path)
        assert len(meta["segments"]) == FLIGHTS[stem], path.name
        assert all(s["ended_by"] != "gap in the samples" for s in meta["segments"])


def test_logging_gap_inside_a_flight_does_not_split_it(shared_data):
    # the app logged nothing for 50 s in the middle of this flight (548 s -> 598 s)
    path = shared_data / "dji_m100_flights" / "raw_19-12-17_tablet1_2019_12_17_18_49.txt"
    frame, meta = read_discharge(path)
    steps = np.diff(frame["time_s"].to_numpy())
    assert steps.max() > 4 * np.median(steps)
    assert len(meta["segments"]) == 1 and meta["segments"][0]["duration_s"] > 1000


def test_waddle_flights_match_between_raw_and_derived(shared_data):
    folder = shared_data / "dji_m100_flights"
    stem = "19-11-28_waddle1_2019_11_28_18_28"
    _, raw = read_discharge(folder / f"raw_{stem}.txt")
    _, derived = read_discharge(folder / f"derived_battery_{stem}.csv")
    spans = [[(round(s["start_time_s"], 2), s["rows"]) for s in m["segments"]]
             for m in (raw, derived)]
    assert spans[0] == spans[1]
    # the second pack (98 % after the swap) flies flights 4 to 7
    assert [s["start_time_s"] > 3263 for s in raw["segments"]] == [False] * 3 + [True] * 4


def events(*items):
    return [{"time_s": float(t), "event": "landed" if mode == "landed" else "flight_mode",
             "mode": mode} for t, mode in items]


def test_takeoff_mode_reported_in_flight_is_not_a_new_flight():
    log = events((0, "GPS_ATTI"), (10, "AUTO_TAKEOFF"), (14, "GPS_WAYPOINT"),
                 (200, "GPS_ATTI"), (210, "ASSISTED_TAKEOFF"), (212, "GPS_ATTI"),
                 (400, "AUTO_LANDING"), (420, "landed"))
    assert flight_breaks(log) == [10.0, 420.0]


def test_mission_after_a_landing_mode_is_a_new_flight():
    # the derived CSV keeps only the last event per record: the touchdown went unlogged
    modes = ["GPS_WAYPOINT", "AUTO_LANDING", "GPS_ATTI", "GPS_WAYPOINT", "AUTO_LANDING"]
    assert flight_breaks(mode_events([0, 10, 20, 60, 90], modes)) == [60.0]


def test_serial_number_change_is_another_pack():
    log = [{"time_s": 0.0, "event": "serial", "serial": "A"},
           {"time_s": 5.0, "event": "serial", "serial": "A"},
           {"time_s": 9.0, "event": "serial", "serial": "B"}]
    assert flight_breaks(log) == [9.0]
