"""Flight-log readers on the real logs in ../shared/data/flight_logs and on written logs.

Expected numbers come from the data README (measured there with pyulog,
pymavlink, orangebox and pandas), never from the readers. The GPL-licensed logs
are read where they are; nothing is copied into the project.
"""

import json
import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from cli_run import run
from dischargelab.atomic import OutputExistsError, OutputIsInputError
from dischargelab.cli import main
from dischargelab.errors import DataError, MissingExtraError
from dischargelab.io import read_discharge
from dischargelab.io.flightlog import (
    FlightLog,
    convert_flight_log,
    current_intervals,
    detect_flight_log,
    read_flight_log,
)
from flightlog_synth import dataflash_flights, ulog_battery

pytest.importorskip("pymavlink")
pytest.importorskip("pyulog")
pytest.importorskip("orangebox")

ESC = "px4_ulog_rs/esc_status_log.ulg"
SAMPLE = "pyulog_sample/sample_log_small.ulg"
BETAFLIGHT = "betaflight_diatone/btfl_001.bbl"
INA28 = "ina3221_fpv_4s/28.csv"
INA29 = "ina3221_fpv_4s/29.csv"
ARDUPILOT = "ardupilot_loganalyzer/mechanical_fail.log"

# README table: format, cells per battery, flights, records per battery, data span [s],
# mAh by trapezoid per battery, the log's counter per battery (None: no counter)
README = {
    ESC: ("ulog", [6], 1, [73], 39.44, [608.6], [615.8]),
    SAMPLE: ("ulog", [6, 12], 1, [21, 21], 6.0, [0.5, 2.6], [0.4, 3.3]),
    BETAFLIGHT: ("blackbox", [6], 3, None, None, [178.3 + 266.1 + 358.4], [None]),
    INA28: ("inflight-csv", [4], 1, [2202], 147.2, [147.2], [None]),
    INA29: ("inflight-csv", [4], 1, [4738], 318.3, [989.8], [None]),
    ARDUPILOT: ("ardupilot-text", [None], 1, [110], 109.2, [969.0], [959.9]),
}


@pytest.fixture(scope="module")
def logs(shared_data) -> Path:
    return shared_data / "flight_logs"


@cache
def _read(path: str) -> FlightLog:
    return read_flight_log(path)


def read(logs: Path, name: str) -> FlightLog:
    return _read(str(logs / name))


def tolerance_mAh(reference: float) -> float:
    """1 %, or half the last digit the README shows (0.05 mAh), whichever is larger."""
    return max(0.01 * reference, 0.05 + 1e-9)


# --------------------------------------------------------------------------- every bundled log

# the Betaflight log takes orangebox ~7 s to decode: read once per CI run, not again at the
# minimum versions (its other tests there decode a truncated copy)
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n.endswith(".bbl")
                                  else n for n in README])
def test_every_log_loads_without_flags(logs, name):
    fmt, cells, flights, records, span, charge, counter = README[name]
    assert detect_flight_log(logs / name) == fmt
    log = read(logs, name)
    assert log.format == fmt
    assert [b.cells for b in log.batteries] == cells
    assert len(log.spans) == flights
    for k, series in enumerate(log.batteries):
        assert list(series.frame.columns[:3]) == ["time_s", "voltage_V", "current_A"]
        assert "flight" in series.frame
        assert np.all(np.diff(series.frame["time_s"]) > 0)
        assert series.charge_mAh() == pytest.approx(charge[k], abs=tolerance_mAh(charge[k]))
        if counter[k] is not None:
            assert series.counter_mAh() == pytest.approx(counter[k], abs=0.05 + 1e-9)
        if records is not None:
            dropped = sum(series.dropped.values())
            assert series.rows + dropped == records[k]
        if span is not None:
            assert series.duration_s == pytest.approx(span, abs=0.15)
    text = log.summary()
    assert "current offset" in text
    assert json.loads(json.dumps(log.to_dict()))["format"] == fmt


def test_charge_agrees_with_the_logs_own_counter(logs):
    # ArduPilot CurrTot: 969.0 vs 959.9 mAh (0.95 %)
    series = read(logs, ARDUPILOT).batteries[0]
    assert series.charge_mAh() == pytest.approx(series.counter_mAh(), rel=0.01)
    # PX4 discharged_mah integrates the current at a higher rate than the 2 Hz log:
    # 608.6 vs 615.8 mAh in the README (1.2 %)
    series = read(logs, ESC).batteries[0]
    assert series.charge_mAh() == pytest.approx(series.counter_mAh(), rel=0.015)


def test_betaflight_three_flights_one_per_log(logs):
    log = read(logs, BETAFLIGHT)
    assert [s.found_by for s in log.spans] == ["log index"] * 3
    durations = [s.duration_s for s in log.spans]
    assert durations == pytest.approx([65.9, 89.0, 130.0], abs=0.1)
    for part, mAh, first_v, last_v, peak_A in zip(log.flights(), (178.3, 266.1, 358.4),
                                                  (24.88, 23.71, 22.55), (23.20, 22.24, 20.91),
                                                  (141.6, 147.7, 125.3)):
        series = part.batteries[0]
        assert series.charge_mAh() == pytest.approx(mAh, rel=0.01)
        assert series.frame["voltage_V"].iloc[0] == pytest.approx(first_v, abs=0.005)
        assert series.frame["voltage_V"].iloc[-1] == pytest.approx(last_v, abs=0.005)
        assert series.frame["current_A"].max() == pytest.approx(peak_A, abs=0.05)
        assert series.frame["current_A"].min() >= 0
    # sensor spikes above the resting value: 15 frames in flight 1, up to 25.40 V
    first = log.flights()[0].batteries[0].frame["voltage_V"]
    assert first.max() <= 24.93
    assert "15 frame(s)" in " ".join(log.notes)
    assert log.batteries[0].dropped["voltage_spike"] >= 15


def test_ina3221_flight_from_current_and_cells(logs):
    log = read(logs, INA29)
    (span,) = log.spans
    assert span.found_by == "current"
    assert span.start_s == pytest.approx(140.5, abs=0.3)
    assert span.end_s == pytest.approx(285.1, abs=0.3)
    series = log.batteries[0]
    flight = log.flights()[0].batteries[0]
    assert flight.charge_mAh() == pytest.approx(975.5, rel=0.01)
    assert flight.frame["current_A"].mean() == pytest.approx(24.3, abs=0.1)
    cells = series.cell_columns
    assert cells == ["cell1_V", "cell2_V", "cell3_V", "cell4_V"]
    total = series.frame[cells].sum(axis=1) - series.frame["voltage_V"]
    assert np.abs(total).max() <= 0.02 + 1e-9
    # the unplug artefact at the end is dropped, the small negative reading kept
    assert series.dropped["unplug"] == 1
    assert series.frame["voltage_V"].iloc[-1] == pytest.approx(14.84)
    assert (series.frame["current_A"] < 0).sum() == 1
    assert any("negative current" in n for n in series.notes)
    # idle current 0.05-0.4 A (README): the offset is reported, not subtracted
    assert 0.05 <= series.current_offset_A <= 0.4
    assert series.frame["current_A"].iloc[0] == pytest.approx(0.78144)
    log28 = read(logs, INA28)
    assert len(log28.spans) == 1
    assert log28.spans[0].duration_s == pytest.approx(17.5, abs=0.5)


def test_ardupilot_curr_time_from_gps(logs):
    log = read(logs, ARDUPILOT)
    series = log.batteries[0]
    assert series.label == "CURR[0]"
    assert series.rows == 110
    steps = np.diff(series.frame["time_s"])
    assert steps.min() > 0.7 and steps.max() < 1.3
    assert series.duration_s == pytest.approx(109.2, abs=0.05)
    v = series.frame["voltage_V"]
    assert v.iloc[0] == pytest.approx(16.91) and v.min() == pytest.approx(13.83)
    assert series.frame["current_A"].max() == pytest.approx(60.36)
    assert series.capacity_mAh == 4200
    assert log.spans[0].found_by == "arm/disarm"
    assert series.current_offset_A == 0.0


def test_pyulog_sample_two_batteries(logs):
    log = read(logs, SAMPLE)
    assert [b.index for b in log.batteries] == [0, 1]
    assert [b.capacity_mAh for b in log.batteries] == [30000, 6000]
    for series in log.batteries:
        assert series.rows == 21
        assert "temperature_C" not in series.frame  # NaN in every record
        assert series.cell_columns == []  # derived from the pack voltage / 12S in 10 slots
        assert series.current_offset_A is not None
    assert any("12 but the log has only 10" in n for n in log.batteries[1].notes)


def test_px4_log_starting_in_flight_has_no_offset(logs):
    log = read(logs, ESC)
    series = log.batteries[0]
    assert series.current_offset_A is None
    assert "current offset unknown" in log.summary()
    assert series.cell_columns == []
    assert log.spans[0].found_by == "arm/disarm"


# --------------------------------------------------------------------------- read_discharge

@pytest.mark.slow     # decodes the Betaflight log twice (~14 s)
def test_read_discharge_takes_one_flight_of_one_battery(logs):
    frame, meta = read_discharge(logs / BETAFLIGHT)
    assert meta["flight"] == 3  # the longest
    assert meta["format"] == "blackbox"
    assert frame["time_s"].iloc[0] == 0.0
    charge = np.sum(0.5 * (frame["current_A"].to_numpy()[1:] + frame["current_A"].to_numpy()[:-1])
                    * np.diff(frame["time_s"].to_numpy())) / 3.6
    assert charge == pytest.approx(358.4, rel=0.01)
    frame, meta = read_discharge(logs / BETAFLIGHT, flight=2)
    assert meta["flight"] == 2 and len(meta["segments"]) == 3
    frame, meta = read_discharge(logs / SAMPLE)
    assert meta["battery"] == 0
    assert any("battery=1" in n for n in meta["notes"])
    frame, meta = read_discharge(logs / SAMPLE, battery=1)
    assert meta["cells"] == 12
    frame, meta = read_discharge(logs / INA29)
    assert meta["rest_sample"]["voltage_V"] == pytest.approx(16.59)
    assert meta["current_offset_A"] == pytest.approx(read(logs, INA29).batteries[0]
                                                     .current_offset_A)
    assert "current offset" in meta["summary"]
    assert {"cell1_V", "cell4_V"} <= set(frame.columns)
    with pytest.raises(DataError, match="has no battery 7"):
        read_discharge(logs / SAMPLE, battery=7)
    with pytest.raises(DataError, match="flight must be 1 to 1"):
        read_discharge(logs / INA29, flight=2)


def test_read_discharge_flight_options_need_a_flight_log(bundled_data):
    with pytest.raises(DataError, match="not a flight log"):
        read_discharge(bundled_data / "Q30_S001_1C.csv", flight=1)


def test_fit_reads_a_flight(logs):
    from dischargelab.fit import Curve

    frame, meta = read_discharge(logs / INA29)
    curve = Curve.from_frame(frame, meta, name="29")
    assert curve.mean_current_A == pytest.approx(24.3, abs=0.2)


# --------------------------------------------------------------------------- convert

def test_convert_writes_canonical_csv_and_refuses_overwrite(logs, tmp_path):
    out = tmp_path / "29.csv"
    result = convert_flight_log(logs / INA29, out)
    assert result["rows"] == 4737
    text = out.read_text().splitlines()
    assert text[0].startswith("# dischargelab flight-log export: ")
    assert text[2] == "time_s,voltage_V,current_A,cell1_V,cell2_V,cell3_V,cell4_V,flight"
    with pytest.raises(OutputExistsError):
        convert_flight_log(logs / INA29, out)
    convert_flight_log(logs / INA29, out, force=True, flight=1)
    back = read_flight_log(out)
    assert back.format == "flightlog-csv"
    assert back.batteries[0].charge_mAh() == pytest.approx(975.5, rel=0.01)
    frame, meta = read_discharge(out)
    assert meta["flight"] == 1 and len(frame) == back.batteries[0].rows
    copy = tmp_path / "copy.csv"
    copy.write_bytes((logs / INA29).read_bytes())
    with pytest.raises(OutputIsInputError):
        convert_flight_log(copy, copy, force=True)
    assert copy.read_bytes() == (logs / INA29).read_bytes()


def test_cli_convert(logs, tmp_path, capsys):
    out = tmp_path / "bb.csv"
    with pytest.raises(SystemExit) as exc:
        main(["convert", str(logs / SAMPLE), "--battery", "1", "--json", "-o", str(out)])
    assert exc.value.code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["battery"] == 1 and result["rows"] == 21
    with pytest.raises(SystemExit) as exc:
        main(["convert", str(logs / SAMPLE), "-o", str(out)])
    captured = capsys.readouterr()
    assert exc.value.code == 2
    assert "--force" in captured.err and len(captured.err.strip().splitlines()) == 1


# --------------------------------------------------------------------------- written logs

def test_dataflash_bin_two_batteries_cells_and_arming(tmp_path):
    path = tmp_path / "flight.bin"
    expected = dataflash_flights(path)
    assert detect_flight_log(path) == "ardupilot-bin"
    log = read_flight_log(path)
    assert [(round(s.start_s, 1), round(s.end_s, 1)) for s in log.spans] == expected["flights"]
    first, second = log.batteries
    assert first.cells == expected["cells"] and first.cell_columns[-1] == "cell4_V"
    assert first.capacity_mAh == 5000 and second.capacity_mAh == 2200
    assert first.dropped == {"nan": 1, "zero_voltage": 1}
    assert first.current_offset_A == pytest.approx(expected["idle_A"])
    assert second.current_offset_A == pytest.approx(expected["idle_A"] / 2)
    assert {"log_voltage_rest_V", "log_resistance_ohm", "log_energy_Wh",
            "log_remaining_frac", "temperature_C"} <= set(first.frame.columns)
    assert first.frame["temperature_C"].iloc[0] == pytest.approx(25.0)
    in_flight = sum(p.batteries[0].charge_mAh() for p in log.flights())
    assert in_flight == pytest.approx(expected["charge_mAh"][0], rel=0.01)
    assert first.charge_mAh() == pytest.approx(first.counter_mAh(), rel=0.01)


def test_ulog_battery_in_another_topic(tmp_path):
    path = ulog_battery(tmp_path / "power.ulg", topic="power_monitor")
    with pytest.raises(DataError) as exc:
        read_flight_log(path)
    message = str(exc.value)
    assert "\n" not in message
    assert "power_monitor.bus_voltage_v" in message and "topic=" in message
    log = read_flight_log(path, topic="power_monitor",
                          fields={"voltage_V": "bus_voltage_v", "current_A": "bus_current_a"})
    assert log.batteries[0].rows == 40 and len(log.spans) == 1
    with pytest.raises(DataError, match="current_A"):
        read_flight_log(path, topic="power_monitor", fields={"voltage_V": "bus_voltage_v"})


def test_ulog_current_not_measured(tmp_path):
    path = ulog_battery(tmp_path / "sim.ulg", current_a=-1.0)
    with pytest.raises(DataError, match="current_a = -1"):
        read_flight_log(path)
    log = read_flight_log(ulog_battery(tmp_path / "ok.ulg"))
    assert log.batteries[0].dropped == {}
    assert log.batteries[0].counter_mAh() == pytest.approx(log.batteries[0].charge_mAh(),
                                                           rel=0.05)


def test_current_segmentation_rules():
    t = np.arange(0.0, 400.0, 0.1)
    i = np.full(t.size, 0.2)
    i[(t > 50) & (t < 150)] = 20.0
    i[(t > 100) & (t < 105)] = 0.0  # a 5 s pause: the same flight
    i[(t > 30) & (t < 30.3)] = 15.0  # a spin-up blip: no flight
    i[(t > 250) & (t < 260)] = 25.0  # a second flight
    keep = ~((t > 120) & (t < 135))  # a logging gap inside the flight
    spans = current_intervals(t[keep], i[keep])
    assert [(round(a, 1), round(b, 1)) for a, b in spans] == [(50.1, 149.9), (250.1, 259.9)]


# --------------------------------------------------------------------------- damaged files

def _truncations(size: int):
    return sorted({10, 17, 100, 600, 5000, size // 3, (2 * size) // 3, size - 7})


@pytest.mark.parametrize("name", [ESC, SAMPLE, ARDUPILOT, INA29])
def test_truncated_copies_read_or_fail_in_one_line(logs, tmp_path, capfd, name):
    data = (logs / name).read_bytes()
    for cut in _truncations(len(data)):
        path = tmp_path / f"cut{cut}{Path(name).suffix}"
        path.write_bytes(data[:cut])
        _read_or_one_line_error(path)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_truncated_blackbox_and_binary_dataflash(logs, tmp_path, capfd):
    data = (logs / BETAFLIGHT).read_bytes()
    for cut in (50, 3000, 700_000):
        path = tmp_path / f"cut{cut}.bbl"
        path.write_bytes(data[:cut])
        _read_or_one_line_error(path)
    written = dataflash_flights(tmp_path / "full.bin")
    assert written
    data = (tmp_path / "full.bin").read_bytes()
    for cut in _truncations(len(data)):
        path = tmp_path / f"cut{cut}.bin"
        path.write_bytes(data[:cut])
        _read_or_one_line_error(path)
    damaged = bytearray(data)
    damaged[len(data) // 2:len(data) // 2 + 400] = bytes(400)
    path = tmp_path / "damaged.bin"
    path.write_bytes(bytes(damaged))
    _read_or_one_line_error(path)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


@pytest.mark.parametrize("magic", [b"ULog\x01\x12\x35\x01", b"\xa3\x95", b"\xa3\x95\x80\x80",
                                   b"H Product:Blackbox flight data recorder by Nicholas "
                                   b"Sherlock\n", b"FMT, 128, 89, FMT, BBnNZ, Type\n"])
def test_random_bytes_behind_a_magic(tmp_path, capfd, magic):
    rng = np.random.default_rng(7)
    path = tmp_path / "random.dat"
    path.write_bytes(magic + rng.integers(0, 256, 20_000, dtype=np.uint8).tobytes())
    with pytest.raises(DataError) as exc:
        read_flight_log(path)
    assert "\n" not in str(exc.value) and str(exc.value).startswith("random.dat")
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def _read_or_one_line_error(path: Path) -> None:
    try:
        log = read_flight_log(path)
    except DataError as exc:
        assert "\n" not in str(exc), str(exc)
        assert str(exc).startswith(path.name) or "not a flight log" in str(exc)
        return
    assert isinstance(log, FlightLog) and log.batteries


def test_detection_leaves_other_files_alone(shared_data, logs, bundled_data):
    assert detect_flight_log(logs / "README.md") is None
    assert detect_flight_log(logs / "px4_ulog_rs" / "LICENSE") is None
    assert detect_flight_log(bundled_data / "Q30_S001_1C.csv") is None
    assert detect_flight_log(logs / "no-such-file.bin") is None


# --------------------------------------------------------------------------- optional extra

def test_import_does_not_load_the_log_libraries():
    code = ("import sys, dischargelab, dischargelab.io, dischargelab.io.flightlog; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('pymavlink', 'pyulog', 'orangebox')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "[]"


def test_missing_extra_names_itself(logs, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyulog", None)
    with pytest.raises(MissingExtraError, match=r"dischargelab\[logs\]"):
        read_flight_log(logs / ESC)


BAD_CELLS = ["nan", "inf", "-inf", "1e308", "-1e308", "", "x", "-", "0", "9" * 30, "4.1.2"]


def test_damaged_inflight_csv_reads_or_fails_in_one_line(logs, tmp_path):
    rng = np.random.default_rng(3)
    lines = (logs / INA29).read_text().splitlines()
    for case in range(40):
        edited = list(lines)
        for _ in range(int(rng.integers(1, 30))):
            k = int(rng.integers(0, len(edited)))
            fields = edited[k].split(",")
            fields[int(rng.integers(0, 8))] = str(rng.choice(BAD_CELLS))
            edited[k] = ",".join(fields)
        if case % 4 == 0:  # rows swapped
            a, b = sorted(rng.integers(0, len(edited), 2))
            edited[a], edited[b] = edited[b], edited[a]
        path = tmp_path / f"damaged{case}.csv"
        path.write_text("\n".join(edited[: int(rng.integers(10, len(edited)))]) + "\n")
        try:
            frame, meta = read_discharge(path)
        except DataError as exc:
            assert "\n" not in str(exc)
            continue
        assert np.isfinite(frame[["time_s", "voltage_V", "current_A"]].to_numpy()).all()


def _glitch_cell(source: Path, target: Path, column: int, stretches: int, seed: int = 0):
    """A copy of an INA3221 log whose cell ``column`` (0-based CSV column) reads 0 V or
    saturates in ``stretches`` stretches of 1-11 samples; returns how many samples."""
    rng = np.random.default_rng(seed)
    lines = source.read_text(encoding="utf-8").splitlines()
    starts = np.sort(rng.choice(np.arange(20, len(lines) - 40, 15), stretches, replace=False))
    bad = 0
    for k, start in enumerate(starts):
        for j in range(start, start + int(rng.integers(1, 12))):
            parts = lines[j].split(",")
            parts[column] = ("0.00", "6.55", "0.26", "4.98")[k % 4]
            lines[j] = ",".join(parts)
            bad += 1
    target.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return bad


def test_a_glitching_cell_channel_is_masked_and_counted(logs, tmp_path, capsys):
    """One cell channel of 28.csv reading outside 1.0-4.5 V in 17 stretches: the log
    still reads, those cell samples are masked and counted, the pack voltage is kept."""
    glitchy = tmp_path / "28_glitch.csv"
    bad = _glitch_cell(logs / INA28, glitchy, column=4, stretches=17)
    log = read_flight_log(glitchy)
    series = log.batteries[0]
    assert series.masked == {"cell3_V": bad}
    assert f"cell 3: {bad} sample(s) in 17 stretch(es)" in " ".join(log.notes)
    clean = read(logs, INA28).batteries[0]
    assert series.rows == clean.rows
    assert series.frame["voltage_V"].equals(clean.frame["voltage_V"])
    assert int(series.frame["cell3_V"].isna().sum()) == bad
    other = ["cell1_V", "cell2_V", "cell4_V"]
    assert series.frame[other].equals(clean.frame[other])
    assert "masked" in log.summary()
    code, out, err = run(capsys, "flight", glitchy)
    assert code == 0, err
    assert f"masked {bad} sample(s) of cell3_V" in out + err


def test_no_real_log_has_masked_cells(logs):
    for name in README:
        for series in read(logs, name).batteries:
            assert not series.masked, name

