"""Every real data set in ../shared/data loads with at most a flag or two.

Expected numbers come from the data README (capacities, times to 3.0 V) or from
the files themselves (line counts, first values), never from the reader.
"""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dischargelab.errors import DataError
from dischargelab.io import read_discharge
from dischargelab.model import charge_from_current

SAMSUNG_COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"

# README: capacity to 2.5 V [Ah] and time from load start to 3.0 V [s]
SAMSUNG = {
    "C10": (2.97, 33643.0, 0.3),
    "1C": (2.96, 3264.0, 3.0),
    "2C": (2.94, 1583.0, 6.0),
    "3C": (2.92, 1016.0, 9.0),
    "4C": (2.90, 726.0, 12.0),
}

ENERTECH_NOMINAL_AH = 2.28


def _line_count(path: Path) -> int:
    with open(path, "rb") as fh:
        return sum(1 for line in fh if line.strip())


def _first_row(path: Path) -> list[float]:
    text = path.read_text(encoding="utf-8-sig").splitlines()[0]
    return [float(x) for x in text.replace("\t", ",").split(",") if x.strip()]


@pytest.mark.parametrize("rate", list(SAMSUNG))
def test_samsung_rate_family(shared_data, rate):
    path = shared_data / "samsung30q_S001" / f"Q30_S001_{rate}.csv"
    capacity_Ah, time_to_3V_s, current_A = SAMSUNG[rate]
    frame, meta = read_discharge(path, columns=SAMSUNG_COLUMNS)

    rows = _line_count(path)
    assert meta["rows_read"] == rows
    assert len(frame) == rows - 1  # row 0 is at rest
    assert meta["dropped"]["rest"] == 1
    assert meta["sign_convention"] == "discharge negative (flipped)"
    assert meta["current_source"] == "column"
    assert list(frame.columns[:4]) == ["time_s", "voltage_V", "current_A", "temperature_C"]

    first = _first_row(path)
    rest = meta["rest_sample"]
    assert rest["voltage_V"] == pytest.approx(first[2])
    assert rest["time_s"] < 0  # before load start
    assert meta["time_offset_s"] > first[0]
    assert frame["time_s"].iloc[0] == 0.0
    # constant current, discharge positive, within 2 % of the nominal rate
    assert frame["current_A"].median() == pytest.approx(current_A, rel=0.02)
    assert (frame["current_A"] > 0).all()

    charge = charge_from_current(frame["time_s"], frame["current_A"])
    assert charge[-1] == pytest.approx(capacity_Ah, rel=0.01)
    below = np.flatnonzero(frame["voltage_V"].to_numpy() < 3.0)[0]
    # one sample period (1 s) of tolerance on the README's whole seconds
    assert abs(frame["time_s"].iloc[below] - time_to_3V_s) <= 1.0
    assert "kept" in meta["summary"] and "rest" in meta["summary"]
    json.dumps(meta)  # plain JSON types only: the command line prints it with --json


def test_samsung_self_heating_recorded(shared_data):
    frame, _ = read_discharge(shared_data / "samsung30q_S001" / "Q30_S001_4C.csv",
                              columns=SAMSUNG_COLUMNS)
    # README: the cell reaches about 64 degC at 4C
    assert frame["temperature_C"].max() == pytest.approx(64, abs=2)


def test_samsung_needs_columns_and_says_how(shared_data):
    with pytest.raises(DataError, match=r"--columns time_s=0,current_A=1") as info:
        read_discharge(shared_data / "samsung30q_S001" / "Q30_S001_1C.csv")
    assert "7 columns" in str(info.value)
    assert "first row: 0,0.028243,4.1432" in str(info.value)


def test_bundled_samsung_files_load(bundled_data):
    for path in sorted(bundled_data.glob("*.csv")):
        frame, meta = read_discharge(path, columns=SAMSUNG_COLUMNS)
        assert len(frame) == _line_count(path) - 1
        assert meta["rest_sample"] is not None


@pytest.mark.parametrize("rate", [0.1, 0.5, 1.0, 2.0])
def test_enertech_voltage_files_with_given_current(shared_data, rate):
    name = f"{rate:g}C_discharge_U.txt"
    path = shared_data / "enertech_lco" / name
    current = rate * ENERTECH_NOMINAL_AH
    frame, meta = read_discharge(path, current_A=current)

    rows = _line_count(path)
    assert len(frame) == rows - 1
    assert meta["current_source"] == "given"
    assert (frame["current_A"] == current).all()
    # t = 0 is the rest voltage (README): it becomes the rest sample
    first = _first_row(path)
    assert meta["rest_sample"]["voltage_V"] == pytest.approx(first[1])
    assert meta["rest_sample"]["time_s"] == pytest.approx(-1.0)
    assert any("two columns" in note for note in meta["notes"])
    # cutoff 3.0 V, discharge of roughly the nominal capacity
    assert frame["voltage_V"].iloc[-1] < 3.0
    charge = charge_from_current(frame["time_s"], frame["current_A"])[-1]
    assert 0.9 * ENERTECH_NOMINAL_AH < charge < 1.05 * ENERTECH_NOMINAL_AH


@pytest.mark.parametrize("rate", ["0.5C", "1C", "2C"])
def test_enertech_temperature_files_are_rejected(shared_data, rate):
    path = shared_data / "enertech_lco" / f"{rate}_discharge_T.txt"
    with pytest.raises(DataError, match="temperature file") as info:
        read_discharge(path, current_A=2.28)
    assert "\n" not in str(info.value)
    # also without --current: the voltage check comes first
    with pytest.raises(DataError, match="temperature file"):
        read_discharge(path)


K2_ROWS = {"20C": 3043, "30C": 3074, "40C": 3093, "50C": 3094}


@pytest.mark.parametrize("temperature", list(K2_ROWS))
def test_k2_lvm_with_columns(shared_data, temperature):
    path = shared_data / "k2_lfp26650" / f"K2_Discharge_Test_{temperature}.txt"
    frame, meta = read_discharge(path, columns=SAMSUNG_COLUMNS)
    assert meta["format"] == "lvm"
    assert len(frame) == K2_ROWS[temperature]
    assert meta["rest_sample"] is None  # README: no rest sample first
    assert meta["time_offset_s"] == 0.0
    assert meta["sign_convention"] == "discharge negative (flipped)"
    assert frame["current_A"].mean() == pytest.approx(2.6, rel=0.01)
    assert frame["voltage_V"].iloc[-1] == pytest.approx(2.5, abs=0.01)
    # chamber temperature within 1 degC of the nominal test temperature
    chamber = frame["ambient_temperature_C"].median()
    assert chamber == pytest.approx(float(temperature[:-1]), abs=1.0)
    charge = charge_from_current(frame["time_s"], frame["current_A"])[-1]
    assert charge == pytest.approx(frame["current_A"].mean() * frame["time_s"].iloc[-1] / 3600,
                                   rel=0.005)


def test_k2_lvm_description_inferred_and_recorded(shared_data):
    path = shared_data / "k2_lfp26650" / "K2_Discharge_Test_20C.txt"
    given, _ = read_discharge(path, columns=SAMSUNG_COLUMNS)
    inferred, meta = read_discharge(path)
    pd.testing.assert_frame_equal(given, inferred)
    assert any("Description" in note for note in meta["notes"])
    assert "inferred" in meta["column_map"]["voltage_V"]


# One segment per flight: waddle1 holds 7 flights (3 on the first pack, 4 on the second);
# the others one each (counted from the flight-mode events in tests/test_dji_flights.py).
DJI_SEGMENTS = {
    "19-11-28_waddle1_2019_11_28_18_28": 7,
    "19-12-17_tablet1_2019_12_17_18_49": 1,
    "20-01-12_tablet1_2020_01_12_12_08": 1,
    "20-01-12_tablet3_2020_01_12_13_24": 1,
    "20-01-21_tab3_2020_01_21_20_55": 1,
}


@pytest.mark.parametrize("stem", list(DJI_SEGMENTS))
def test_dji_raw_log_matches_derived_csv(shared_data, stem):
    folder = shared_data / "dji_m100_flights"
    raw, raw_meta = read_discharge(folder / f"raw_{stem}.txt", segment="none")
    derived, derived_meta = read_discharge(folder / f"derived_battery_{stem}.csv",
                                           segment="none")
    assert raw_meta["format"] == "dji-raw"
    assert derived_meta["format"] == "dji-derived-csv"
    assert len(raw) == len(derived) == _line_count(folder / f"derived_battery_{stem}.csv") - 1
    for column in ("time_s", "voltage_V", "current_A", "soc_pct"):
        np.testing.assert_allclose(raw[column], derived[column], atol=1.5e-3)
    assert list(raw["flight_mode"]) == list(derived["flight_mode"])
    assert raw_meta["sign_convention"] == "discharge positive"
    assert raw_meta["events"], "flight events are kept"


@pytest.mark.parametrize("stem", list(DJI_SEGMENTS))
def test_dji_flights_are_segmented(shared_data, stem):
    folder = shared_data / "dji_m100_flights"
    for path in (folder / f"raw_{stem}.txt", folder / f"derived_battery_{stem}.csv"):
        frame, meta = read_discharge(path)
        assert len(meta["segments"]) == DJI_SEGMENTS[stem]
        durations = [s["duration_s"] for s in meta["segments"]]
        kept = meta["segments"][meta["segment"] - 1]
        assert kept["duration_s"] == max(durations)
        assert len(frame) == kept["rows"]
        # in flight: 5-30 A (README), no idle rows kept
        assert frame["current_A"].min() > 4.0
        assert frame["current_A"].max() < 31.0
        assert meta["current_profile"] == "variable"
        json.dumps(meta)


def test_dji_rest_sample_is_last_idle_record_before_takeoff(shared_data):
    folder = shared_data / "dji_m100_flights"
    path = folder / "derived_battery_20-01-12_tablet3_2020_01_12_13_24.csv"
    frame, meta = read_discharge(path)
    # rows 2 and 3 of the file: 78.214 s at 25.914 V idle, then 176.763 s at 18 A
    assert meta["rest_sample"]["voltage_V"] == pytest.approx(25.914)
    assert meta["rest_sample"]["time_s"] == pytest.approx(78.214 - 176.763)
    assert meta["time_offset_s"] == pytest.approx(176.763)
    assert meta["dropped"]["relaxation"] == 2


def test_dji_waddle_segments_selectable(shared_data):
    path = shared_data / "dji_m100_flights" / "raw_19-11-28_waddle1_2019_11_28_18_28.txt"
    _, meta = read_discharge(path)
    # the pack swap (SOC 2 % -> 98 %) lies between flights 3 and 4
    first, _ = read_discharge(path, segment=1)
    fourth, meta4 = read_discharge(path, segment=4)
    assert first["soc_pct"].iloc[0] == 64
    assert fourth["soc_pct"].iloc[0] == 96
    assert meta4["segment"] == 4
    with pytest.raises(DataError, match=r"--segment 9: the file has 7"):
        read_discharge(path, segment=9)


def _lvm_columns(path: Path) -> np.ndarray:
    """The data block of an LVM file parsed with numpy alone (after the X_Value line)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("X_Value")) + 1
    return np.array([[float(x) for x in line.split("\t")[:7]] for line in lines[start:]
                     if line.strip()])


@pytest.mark.parametrize("cycle", ["001", "300", "664"])
def test_cell_c_ageing_files_read_without_flags(shared_data, cycle):
    """The Description names six columns for seven (no strain): read with no options."""
    path = shared_data / "samsung30q_ageing_cellC" / f"DischargeCycle{cycle}.txt"
    frame, meta = read_discharge(path)
    raw = _lvm_columns(path)
    load = raw[:, 1] < -1.0  # README: -3.0 A discharge, negative in the file
    np.testing.assert_allclose(frame["voltage_V"], raw[load, 2], rtol=1e-9)
    np.testing.assert_allclose(frame["temperature_C"], raw[load, 4], rtol=1e-9)
    assert frame["ambient_temperature_C"].median() == pytest.approx(20.8, abs=0.5)
    truth = np.trapezoid(-raw[load, 1], raw[load, 0]) / 3600
    assert charge_from_current(frame["time_s"], frame["current_A"])[-1] == pytest.approx(
        truth, rel=1e-3)
    assert "column 5 left unnamed" in " ".join(meta["notes"])


def test_cell_c_fits_without_flags(shared_data):
    import dischargelab as dl

    result = dl.fit(shared_data / "samsung30q_ageing_cellC" / "DischargeCycle001.txt",
                    bootstrap=0)
    assert result.rmse_V < 0.03


def _cell_c_copy(shared_data, tmp_path, cycle: str, keep_rows: int | None, zero_rows: list,
                 lead: bool = False) -> Path:
    """A copy of a cell C file cut after ``keep_rows`` data rows (None: whole), with rows of
    zeros (the logger's stop or start record) after (or before) the data."""
    path = shared_data / "samsung30q_ageing_cellC" / f"DischargeCycle{cycle}.txt"
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    start = next(k for k, line in enumerate(lines) if line.startswith("X_Value")) + 1
    data = [line for line in lines[start:] if line.strip()]
    data = data[:keep_rows] if keep_rows else data
    last_t = float(data[-1].split("\t")[0])
    zeros = [("\t".join([f"{(last_t + 1 + k) if t is None else t:.6f}"] + ["0.000000"] * 6))
             + "\n" for k, t in enumerate(zero_rows)]
    body = zeros + data if lead else data + zeros
    out = tmp_path / path.name
    out.write_text("".join(lines[:start] + body), encoding="utf-8")
    return out


@pytest.mark.parametrize("zero_time", [None, 0.0])
def test_a_logger_stop_row_of_zeros_is_dropped_and_said(shared_data, tmp_path, zero_time):
    """A test cut short whose logger wrote one last row of zeros (time going on, or 0) reads
    as the discharge it holds; the row is dropped and the notes say so."""
    path = _cell_c_copy(shared_data, tmp_path, "300", 320, [zero_time])
    frame, meta = read_discharge(path)
    raw = _lvm_columns(path)[:-1]
    load = raw[:, 1] < -1.0
    assert len(frame) == int(load.sum())
    np.testing.assert_allclose(frame["voltage_V"], raw[load, 2], rtol=1e-9)
    assert meta["dropped"]["logger_stop"] == 1
    zero_line = 22 + 1 + 320 + 1    # header lines, X_Value, 320 rows, the zero row
    assert any(f"line {zero_line}, the last of the file" in n and "zeros" in n
               for n in meta["notes"])
    assert "logger record of zeros" in meta["summary"]


def test_leading_logger_rows_and_a_whole_file_of_zeros(shared_data, tmp_path):
    path = _cell_c_copy(shared_data, tmp_path, "010", None, [0.0, 0.0], lead=True)
    # two leading records at t = 0 give a duplicate time only if kept: both are dropped
    frame, meta = read_discharge(path)
    assert meta["dropped"]["logger_stop"] == 2 and meta["dropped"]["duplicate_time"] == 0
    # a zero inside the data is still refused (the wrong column, not a logger record)
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    k = next(k for k, line in enumerate(lines) if line.startswith("X_Value")) + 100
    lines[k] = lines[k].split("\t")[0] + "\t0\t0\t0\t0\t0\t0\n"
    path.write_text("".join(lines), encoding="utf-8")
    with pytest.raises(DataError, match=r"voltage column holds 0 at line \d+"):
        read_discharge(path)
