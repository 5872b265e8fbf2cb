"""MAVLink telemetry logs (.tlog): the shared real logs, joined recordings, corrupt bytes,
unknown values, and the commands that take flight logs."""

import json
import struct

import numpy as np
import pytest

from cli_run import run
from dischargelab.errors import DataError
from dischargelab.io.flightlog import convert_flight_log, detect_flight_log, read_flight_log
from dischargelab.io.tlog import SESSION_SPACER_S, is_tlog

pytest.importorskip("pymavlink")

TLOGS = "flight_logs/mavlink_tlog"
#: file -> (consumed-charge counter of the log [mAh], flights by arming)
WITH_BATTERY = {"thayer_rural.tlog": (624.0, 2), "olivieri_20211202-132614.tlog": (1434.0, 1),
                "ardusub_small.tlog": (30.0, 1)}
NO_BATTERY = "codelever_2013-10-13_16-58-51.tlog"
#: The counters count whole mAh: a log of 30 mAh cannot be checked closer than one step.
COUNTER_STEP_MAH = 1.0


def _within_counter(charge_mAh: float, counter_mAh: float) -> bool:
    return abs(charge_mAh - counter_mAh) <= max(0.01 * counter_mAh, COUNTER_STEP_MAH)


@pytest.fixture(scope="module")
def tlogs(shared_data):
    return shared_data / TLOGS


@pytest.mark.parametrize("name", sorted(WITH_BATTERY))
def test_shared_tlog_converts_with_charge_matching_its_counter(tlogs, tmp_path, name):
    counter, flights = WITH_BATTERY[name]
    assert detect_flight_log(tlogs / name) == "mavlink-tlog"
    out = tmp_path / "flight.csv"
    result = convert_flight_log(tlogs / name, out)
    assert result["format"] == "mavlink-tlog" and result["flights"] == flights
    log = read_flight_log(tlogs / name)
    series = log.batteries[0]
    assert series.label == "BATTERY_STATUS[0]"
    assert series.counter_mAh() == pytest.approx(counter)
    assert _within_counter(result["charge_mAh"], counter), (result["charge_mAh"], counter)
    assert np.all(np.diff(series.frame["time_s"]) > 0)
    assert log.skipped["corrupt_messages"] == 0
    # the export reads back with its flights
    again = read_flight_log(out)
    assert len(again.spans) == flights
    assert again.batteries[0].charge_mAh() == pytest.approx(result["charge_mAh"], rel=1e-4)


def test_log_without_battery_data_says_so_in_one_line(tlogs, tmp_path, capsys):
    with pytest.raises(DataError) as info:
        read_flight_log(tlogs / NO_BATTERY)
    text = str(info.value)
    assert "\n" not in text and "no battery data" in text and "current unknown (-1)" in text
    code, out, err = run(capsys, "convert", tlogs / NO_BATTERY, "-o", tmp_path / "x.csv")
    assert code == 2 and err.count("\n") == 1 and "no battery data" in err
    assert not (tmp_path / "x.csv").exists()


def test_flights_come_from_the_vehicle_heartbeat_not_the_ground_station(tlogs):
    log = read_flight_log(tlogs / "olivieri_20211202-132614.tlog")
    assert [s.found_by for s in log.spans] == ["arm/disarm"]
    assert log.spans[0].duration_s == pytest.approx(439.0, abs=1.0)   # armed 438 s (README)
    assert [e["event"] for e in log.events] == ["armed", "disarmed"]


def test_joined_recordings_become_sessions_and_time_never_steps_back(tlogs, tmp_path):
    one = (tlogs / "olivieri_20211202-132614.tlog").read_bytes()
    single = read_flight_log(tlogs / "olivieri_20211202-132614.tlog").batteries[0]
    twice = tmp_path / "twice.tlog"
    twice.write_bytes(one + one)              # the second recording's clock goes back
    log = read_flight_log(twice)
    series = log.batteries[0]
    t = series.frame["time_s"].to_numpy()
    assert np.all(np.diff(t) > 0)
    assert sorted(set(series.frame["session"])) == [1, 2]
    assert len(log.spans) == 2
    assert series.charge_mAh() == pytest.approx(2 * single.charge_mAh(), rel=1e-6)
    assert series.counter_mAh() == pytest.approx(2 * single.counter_mAh())
    gap = t[series.frame["session"].to_numpy() == 2][0] - \
        t[series.frame["session"].to_numpy() == 1][-1]
    assert gap >= SESSION_SPACER_S
    assert any("2 recording sessions" in n for n in log.notes)


def test_recordings_of_two_vehicles_joined_keep_their_batteries_apart(tlogs, tmp_path):
    joined = tmp_path / "joined.tlog"
    joined.write_bytes((tlogs / "olivieri_20211202-132614.tlog").read_bytes()
                       + (tlogs / "ardusub_small.tlog").read_bytes())
    log = read_flight_log(joined)
    assert len(log.batteries) == 2 and len(log.spans) == 2
    charges = sorted(b.charge_mAh() for b in log.batteries)
    assert charges[0] == pytest.approx(30.4, abs=0.2) and charges[1] == pytest.approx(1436, abs=2)


def test_corrupt_bytes_are_skipped_and_counted(tlogs, tmp_path):
    data = bytearray((tlogs / "olivieri_20211202-132614.tlog").read_bytes())
    rng = np.random.default_rng(7)
    for position in rng.integers(0, len(data), 300):
        data[position] ^= 0xFF
    damaged = tmp_path / "damaged.tlog"
    damaged.write_bytes(bytes(data))
    log = read_flight_log(damaged)
    series = log.batteries[0]
    assert log.skipped["corrupt_messages"] > 10
    assert any("corrupt message" in n for n in log.notes)
    assert len(log.spans) == 1
    assert np.all(np.diff(series.frame["time_s"]) > 0)
    assert _within_counter(series.charge_mAh(), series.counter_mAh())


def test_a_recording_cut_short_is_read_up_to_the_cut(tlogs, tmp_path):
    data = (tlogs / "olivieri_20211202-132614.tlog").read_bytes()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[: len(data) // 2 + 5])
    log = read_flight_log(cut)
    assert log.skipped["truncated_messages"] == 1
    assert log.batteries[0].rows > 100


# ----------------------------------------------------------------------------- synthetic

def _tlog(messages) -> bytes:
    """A telemetry log of (time [s], message) pairs, encoded by pymavlink (MAVLink 2)."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    out = b""
    for t, build in messages:
        out += struct.pack(">Q", int(t * 1e6)) + build(mav).pack(mav)
        mav.seq = (mav.seq + 1) % 256   # as MAVLink.send does
    return out


def _battery(volts_mV, centiamps, consumed, temperature=32767):
    cells = [volts_mV] + [65535] * 9 if isinstance(volts_mV, int) else list(volts_mV)
    return lambda mav: mav.battery_status_encode(0, 0, 0, temperature, cells, centiamps,
                                                 consumed, -1, 50)


def _status(volts_mV, centiamps):
    return lambda mav: mav.sys_status_encode(0, 0, 0, 0, volts_mV, centiamps, 50, 0, 0, 0, 0,
                                             0, 0)


def _heartbeat(armed):
    return lambda mav: mav.heartbeat_encode(2, 3, 128 if armed else 0, 0, 4)


T0 = 1.7e9


def test_unknown_values_are_missing_and_sys_status_stands_in(tmp_path):
    messages = []
    for k in range(40):
        t = T0 + k
        messages.append((t, _heartbeat(10 <= k < 30)))
        current = 1000 if 10 <= k < 30 else 20          # 10 A in flight
        if k in (12, 13):
            messages.append((t + 0.1, _battery(65535, current, 10 + k)))   # voltage unknown
        elif k == 14:
            messages.append((t + 0.1, _battery(15000, -1, 10 + k)))        # current unknown
        else:
            messages.append((t + 0.1, _battery(15000 - 10 * k, current, 10 + k)))
    path = tmp_path / "unknown.tlog"
    path.write_bytes(_tlog(messages))
    assert is_tlog(path.read_bytes()[:4096])
    log = read_flight_log(path)
    series = log.batteries[0]
    assert series.rows == 37 and series.dropped["unknown_value"] == 3
    assert "temperature_C" not in series.frame          # 32767 = unknown in every record
    assert any("voltage unknown" in n for n in series.notes)
    assert [s.found_by for s in log.spans] == ["arm/disarm"]
    assert log.spans[0].start_s == pytest.approx(10.0) and log.spans[0].end_s == pytest.approx(30)

    # no usable BATTERY_STATUS current: SYS_STATUS is read instead
    messages = [(T0 + k, _battery(15000, -1, -1)) for k in range(20)] + \
               [(T0 + k + 0.5, _status(14800, 500)) for k in range(20)]
    messages.sort(key=lambda m: m[0])
    path = tmp_path / "status.tlog"
    path.write_bytes(_tlog(messages))
    series = read_flight_log(path).batteries[0]
    assert series.label == "SYS_STATUS" and series.rows == 20
    assert series.frame["current_A"].iloc[0] == pytest.approx(5.0)
    assert series.frame["voltage_V"].iloc[0] == pytest.approx(14.8)


def test_cell_voltages_and_a_restarting_counter(tmp_path):
    messages = []
    for k in range(30):
        consumed = k * 3 if k < 15 else (k - 15) * 3      # the counter restarts (battery swap)
        messages.append((T0 + k, _battery([3900, 3910, 3905, 3895] + [65535] * 6, 1080,
                                          consumed, temperature=2515)))
    path = tmp_path / "cells.tlog"
    path.write_bytes(_tlog(messages))
    log = read_flight_log(path)
    series = log.batteries[0]
    assert series.cells == 4 and series.cell_columns == ["cell1_V", "cell2_V", "cell3_V",
                                                         "cell4_V"]
    assert series.frame["voltage_V"].iloc[0] == pytest.approx(15.61)
    assert series.frame["temperature_C"].iloc[0] == pytest.approx(25.15)
    assert sorted(set(series.frame["session"])) == [1, 2]
    assert series.counter_mAh() == pytest.approx(42 + 42)
    # 10.8 A for 28 one-second steps inside the two sessions: 84 mAh, none across the join
    assert series.charge_mAh() == pytest.approx(10.8 * 28 / 3.6)


def test_other_files_are_not_telemetry_logs(tmp_path, shared_data):
    noise = tmp_path / "noise.bin"
    noise.write_bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    assert detect_flight_log(noise) is None
    text = shared_data / "samsung30q_S001" / "Q30_S001_1C.csv"
    assert not is_tlog(text.read_bytes()[:4096])


# ----------------------------------------------------------------------------- commands

def test_flight_and_logbook_take_telemetry_logs(tlogs, capsys):
    code, out, err = run(capsys, "flight", tlogs / "olivieri_20211202-132614.tlog", "--json")
    assert code == 0, err
    report = json.loads(out)
    assert len(report["flights"]) == 1
    assert report["format"] == "mavlink-tlog"
    assert report["flights"][0]["charge_Ah"] == pytest.approx(1.436, abs=0.005)
    from dischargelab.logbook.summarise import summarise_source

    summary = summarise_source(tlogs / "thayer_rural.tlog", keep_raw=False)
    assert summary.format == "mavlink-tlog"
    assert [e["kind"] for e in summary.events] == ["flight", "flight"]
    # the arrival times are UNIX times: the flights get their clock time (UTC)
    assert [e["start_time"][:16] for e in summary.events] == ["2024-08-15T15:03",
                                                              "2024-08-15T15:07"]
