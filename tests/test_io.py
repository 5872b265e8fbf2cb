"""Readers on small written files: formats, units, bad input, segments."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dischargelab.errors import DataError
from dischargelab.io import (
    describe,
    detect_format,
    discharge_reader,
    parse_columns,
    parse_units,
    read_discharge,
)
from dischargelab.model import charge_from_current


def write(path, text, encoding="utf-8", bom=False):
    data = text.encode(encoding)
    if bom:
        data = b"\xef\xbb\xbf" + data
    path.write_bytes(data)
    return path


def discharge_rows(n=60, current=2.0, v0=4.1, dt=1.0, t0=0.0):
    """A constant-current discharge: voltage falls linearly with charge (plain arithmetic)."""
    t = t0 + dt * np.arange(n)
    v = v0 - 0.2 - 0.5 * (t - t0) / (dt * n)
    return t, v, np.full(n, current)


CANON = ["time_s", "voltage_V", "current_A"]


def as_csv(columns, sep=",", header=None, newline="\n"):
    lines = [] if header is None else [sep.join(header)]
    for row in zip(*columns):
        lines.append(sep.join(f"{x:.6g}" for x in row))
    return newline.join(lines) + newline


# ----------------------------------------------------------------- text formats

def test_bom_crlf_header_and_units_from_names(tmp_path):
    t, v, i = discharge_rows()
    text = as_csv([t / 3600, v * 1000, i * 1000, np.full_like(t, 25.0)],
                  header=["Time [h]", "Voltage (mV)", "current_mA", "Temperature (degC)"],
                  newline="\r\n")
    path = write(tmp_path / "bom.csv", text, bom=True)
    frame, meta = read_discharge(path)
    np.testing.assert_allclose(frame["voltage_V"], v, rtol=1e-5)
    np.testing.assert_allclose(frame["current_A"], i, rtol=1e-5)
    np.testing.assert_allclose(frame["time_s"], t - t[0], atol=0.02)  # 6 significant digits of h
    assert meta["units"]["voltage_V"] == "mV (header)"
    assert meta["units"]["time_s"] == "h (header)"
    assert meta["units"]["current_A"] == "mA (header)"
    assert meta["encoding"] == "utf-8 with BOM"
    assert meta["sign_convention"] == "discharge positive"


def test_units_option_ms_and_mv(tmp_path):
    t, v, i = discharge_rows()
    path = write(tmp_path / "ms.csv", as_csv([t * 1000, v * 1000, i], header=["t", "U", "I"]))
    frame, meta = read_discharge(path, units="time_s=ms,voltage_V=mV")
    np.testing.assert_allclose(frame["time_s"], t, rtol=1e-6)
    np.testing.assert_allclose(frame["voltage_V"], v, rtol=1e-5)
    assert meta["units"]["time_s"] == "ms (given)"


def test_millivolts_without_unit_are_refused_with_the_fix(tmp_path):
    t, v, i = discharge_rows()
    path = write(tmp_path / "mv.csv",
                 as_csv([t, v * 1000, i], header=["time", "voltage", "current"]))
    with pytest.raises(DataError, match=r"--units voltage_V=mV"):
        read_discharge(path)


def test_two_column_file_without_header_is_time_and_voltage(tmp_path):
    t, v, _ = discharge_rows()
    path = write(tmp_path / "two.txt", as_csv([t, v], sep="\t"))
    frame, meta = read_discharge(path, current_A=1.5)
    assert meta["column_map"]["time_s"].startswith("column 0")
    assert any("two columns" in n for n in meta["notes"])
    assert (frame["current_A"] == 1.5).all()
    assert meta["current_source"] == "given"


def test_headerless_wide_file_error_shows_first_row_and_flag(tmp_path):
    t, v, i = discharge_rows()
    path = write(tmp_path / "wide.csv", as_csv([t, i, v, v * i]))
    with pytest.raises(DataError) as info:
        read_discharge(path)
    message = str(info.value)
    assert "no header and 4 columns" in message
    assert "first row: 0,2,3.9" in message
    assert "--columns time_s=0" in message


def test_columns_by_index_and_by_name(tmp_path):
    t, v, i = discharge_rows()
    path = write(tmp_path / "named.csv", as_csv([i, t, v], header=["Amps", "Seconds", "Cell"]))
    by_name, _ = read_discharge(path, columns={"voltage_V": "cell", "current_A": "Amps"})
    by_index, _ = read_discharge(path, columns="time_s=1,current_A=0,voltage_V=2")
    pd.testing.assert_frame_equal(by_name, by_index)
    np.testing.assert_allclose(by_name["voltage_V"], v, rtol=1e-5)


def test_ambiguous_voltage_columns_ask_for_columns(tmp_path):
    t, v, i = discharge_rows()
    path = write(tmp_path / "two_v.csv",
                 as_csv([t, v, v, i], header=["time", "voltage", "voltage", "current"]))
    with pytest.raises(DataError, match=r"several columns could be it.*--columns voltage_V="):
        read_discharge(path)


def test_semicolon_with_decimal_comma(tmp_path):
    t, v, i = discharge_rows()
    text = as_csv([t, v, i], sep=";", header=["time_s", "voltage_V", "current_A"]).replace(".", ",")
    frame, meta = read_discharge(write(tmp_path / "eu.csv", text))
    assert meta["delimiter"] == "semicolon"
    assert meta["decimal"] == "comma"
    np.testing.assert_allclose(frame["voltage_V"], v, rtol=1e-5)


def test_whitespace_with_comments_preamble_and_units_line(tmp_path):
    t, v, i = discharge_rows()
    body = as_csv([t, v, i], sep="   ")
    text = ("# exported by a bench logger\n"
            "Instrument: electronic load\n"
            "\n"
            "time voltage current\n"
            "s V A\n" + body)
    frame, meta = read_discharge(write(tmp_path / "ws.dat", text))
    assert meta["delimiter"] == "whitespace"
    assert meta["preamble"] == ["Instrument: electronic load"]
    assert meta["units_line"] == 5
    assert len(frame) == len(t)


def test_partial_last_line_is_dropped_and_reported(tmp_path):
    t, v, i = discharge_rows()
    text = as_csv([t, v, i], header=CANON) + "60,3.39"
    frame, meta = read_discharge(write(tmp_path / "cut.csv", text))
    assert len(frame) == len(t)
    assert meta["dropped"]["partial_last_line"] == 1
    assert "incomplete last line" in meta["summary"]


def test_partial_number_on_last_line_is_tolerated(tmp_path):
    t, v, i = discharge_rows()
    text = as_csv([t, v, i], header=CANON) + "60,3.39,2.0e"
    frame, meta = read_discharge(write(tmp_path / "cut2.csv", text))
    assert len(frame) == len(t)
    assert meta["dropped"]["partial_last_line"] == 1


def test_garbage_names_the_line(tmp_path):
    t, v, i = discharge_rows()
    lines = as_csv([t, v, i], header=CANON).splitlines()
    lines[10] = "9,abc,2"
    with pytest.raises(DataError, match=r"line 11: column 1 'voltage_V' \(voltage_V\) holds 'abc'"):
        read_discharge(write(tmp_path / "junk.csv", "\n".join(lines) + "\n"))


def test_extra_field_names_the_line(tmp_path):
    t, v, i = discharge_rows()
    lines = as_csv([t, v, i], header=CANON).splitlines()
    lines[20] += ",7"
    with pytest.raises(DataError, match=r"line 21 has 4 fields where the rows before have 3"):
        read_discharge(write(tmp_path / "extra.csv", "\n".join(lines) + "\n"))


def test_time_going_backwards_names_the_line(tmp_path):
    t, v, i = discharge_rows()
    t[30] = t[28]
    path = write(tmp_path / "back.csv", as_csv([t, v, i], header=CANON))
    with pytest.raises(DataError,
                       match=r"line 32: time goes backwards \(28 s after 29 s on line 31\)"):
        read_discharge(path)


def test_duplicate_times_are_dropped_and_counted(tmp_path):
    t, v, i = discharge_rows()
    t[31] = t[30]
    path = write(tmp_path / "dup.csv", as_csv([t, v, i], header=CANON))
    frame, meta = read_discharge(path)
    assert meta["dropped"]["duplicate_time"] == 1
    assert len(frame) == len(t) - 1


def test_sentinels_and_nans(tmp_path):
    t, v, i = discharge_rows()
    temp = np.full_like(t, 25.0)
    v[10] = 3.4e38
    temp[12] = -3.4e38
    text = as_csv([t, v, i, temp], header=["time_s", "voltage_V", "current_A", "temperature_C"])
    lines = text.splitlines()
    lines[21] = f"{t[20]:g},,{i[20]:g},25"  # empty voltage field
    frame, meta = read_discharge(write(tmp_path / "sent.csv", "\n".join(lines) + "\n"))
    assert meta["dropped"]["sentinel"] == 1
    assert meta["dropped"]["nan"] == 1
    assert meta["masked"] == {"temperature_C": 1}
    assert len(frame) == len(t) - 2
    assert frame["temperature_C"].isna().sum() == 1
    assert frame["voltage_V"].max() < 5


def test_mostly_empty_required_column_is_an_error(tmp_path):
    t, v, i = discharge_rows()
    lines = as_csv([t, v, i], header=CANON).splitlines()
    for k in range(5, 30):
        lines[k] = f"{t[k - 1]:g},{v[k - 1]:g},"
    with pytest.raises(DataError,
                       match=r"current_A .* is empty or NaN in 25 of 60 rows \(first at line 6\)"):
        read_discharge(write(tmp_path / "holes.csv", "\n".join(lines) + "\n"))


@pytest.mark.parametrize("content, message", [
    ("", "is empty"),
    ("   \n\n", "is empty"),
    ("time_s,voltage_V,current_A\n", "header but no data rows"),
    ("# only a comment\n", "no data lines"),
])
def test_empty_inputs(tmp_path, content, message):
    with pytest.raises(DataError, match=message):
        read_discharge(write(tmp_path / "e.csv", content))


def test_missing_file_and_binary_file(tmp_path):
    with pytest.raises(DataError, match="file not found"):
        read_discharge(tmp_path / "nope.csv")
    (tmp_path / "x.png").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR")
    with pytest.raises(DataError, match="binary file"):
        read_discharge(tmp_path / "x.png")


def test_no_current_column_asks_for_current(tmp_path):
    t, v, _ = discharge_rows()
    path = write(tmp_path / "nocur.csv", as_csv([t, v], header=["time", "voltage"]))
    with pytest.raises(DataError, match=r"--current AMPS"):
        read_discharge(path)


def test_given_current_replaces_the_column_with_a_note(tmp_path):
    t, v, i = discharge_rows(current=2.9)
    path = write(tmp_path / "cur.csv", as_csv([t, v, i], header=CANON))
    frame, meta = read_discharge(path, current_A=3.0)
    assert (frame["current_A"] == 3.0).all()
    assert meta["current_source"] == "given"
    assert any("replaced by the given --current 3 A" in n for n in meta["notes"])


@pytest.mark.parametrize("bad", [0, -2, "abc", float("nan")])
def test_bad_current_option(tmp_path, bad):
    t, v, _ = discharge_rows()
    path = write(tmp_path / "two.txt", as_csv([t, v]))
    with pytest.raises(DataError, match="--current"):
        read_discharge(path, current_A=bad)


# ----------------------------------------------------------------- segments

def lab_cycle(file_sign=+1):
    """charge 40 rows, rest 10, discharge 50 at 3 A, relaxation 15; discharge sign as in file."""
    parts = []
    t = 0.0
    for n, current, v_start, v_step in ((40, -1.5, 3.6, +0.01), (10, 0.0, 4.0, 0.0),
                                       (50, 3.0, 3.9, -0.01), (15, 0.0, 3.5, +0.002)):
        for k in range(n):
            parts.append((t, v_start + v_step * k, file_sign * current))
            t += 1.0
    return np.array(parts).T


@pytest.mark.parametrize("file_sign, convention", [(+1, "discharge positive"),
                                                    (-1, "discharge negative (flipped)")])
def test_charge_rest_discharge_relaxation(tmp_path, file_sign, convention):
    t, v, i = lab_cycle(file_sign)
    path = write(tmp_path / "cycle.csv", as_csv([t, v, i], header=CANON))
    frame, meta = read_discharge(path)
    assert meta["sign_convention"] == convention
    assert len(frame) == 50
    assert meta["dropped"]["charge"] == 40
    assert meta["dropped"]["rest"] == 10
    assert meta["dropped"]["relaxation"] == 15
    assert meta["rest_sample"]["voltage_V"] == pytest.approx(4.0)
    assert meta["rest_sample"]["time_s"] == pytest.approx(-1.0)
    assert meta["time_offset_s"] == 50.0
    assert (frame["current_A"] == 3.0).all()
    assert meta["summary"].startswith("kept 50 of 115 rows (dropped 10 rest rows")


def test_sign_option(tmp_path):
    t, v, i = lab_cycle(-1)
    path = write(tmp_path / "cycle.csv", as_csv([t, v, i], header=CANON))
    frame, meta = read_discharge(path, sign="negative")
    assert meta["sign_convention"] == "discharge negative (flipped)"
    assert meta["sign_source"] == "given"
    assert len(frame) == 50
    # the wrong sign turns the charge into the "discharge": its voltage rises, so it is refused
    with pytest.raises(DataError, match=r"rises from 3\.6.* --sign"):
        read_discharge(path, sign="positive")
    with pytest.raises(DataError, match="--sign must be auto, positive or negative"):
        read_discharge(path, sign="up")


def test_charge_only_file_has_no_discharge(tmp_path):
    t = np.arange(40.0)
    v = 3.6 + 0.01 * t
    path = write(tmp_path / "charge.csv", as_csv([t, v, np.full_like(t, 1.5)],
                                                  header=["time_s", "voltage_V", "current_A"]))
    with pytest.raises(DataError, match=r"no discharge found .*--sign positive or --sign negative"):
        read_discharge(path)


def test_segment_none_keeps_every_valid_row(tmp_path):
    t, v, i = lab_cycle(+1)
    path = write(tmp_path / "cycle.csv", as_csv([t, v, i], header=CANON))
    frame, meta = read_discharge(path, segment="none")
    assert len(frame) == len(t)
    assert meta["rest_sample"] is None
    assert meta["segments"] == []
    assert frame["time_s"].iloc[0] == 0.0


def flights(durations=(8, 20, 12), idle=5, soc_step=1.0):
    """Variable-current flights separated by idle rows; returns time, voltage, current, soc."""
    rng = np.random.default_rng(7)
    rows = []
    t, v, soc = 0.0, 25.0, 100.0
    for n in durations:
        for _ in range(idle):
            rows.append((t, v, 0.9, soc))
            t += 10.0
        for _ in range(n):
            current = rng.uniform(12.0, 24.0)
            v -= 0.05
            soc -= soc_step
            rows.append((t, v - 0.04 * current, current, soc))
            t += 10.0
    for _ in range(idle):
        rows.append((t, v, 0.9, soc))
        t += 10.0
    return np.array(rows).T


def test_several_flights_longest_by_default(tmp_path):
    t, v, i, soc = flights()
    path = write(tmp_path / "flights.csv",
                 as_csv([t, v, i, soc], header=["time_s", "voltage_V", "current_A", "soc_pct"]))
    frame, meta = read_discharge(path)
    assert [s["rows"] for s in meta["segments"]] == [8, 20, 12]
    assert meta["segment"] == 2
    assert len(frame) == 20
    assert meta["current_profile"] == "variable"
    assert meta["dropped"]["other_segments"] == 20
    assert meta["rest_sample"]["current_A"] == pytest.approx(0.9)
    assert "segment 2 of 3" in meta["summary"]
    first, meta1 = read_discharge(path, segment=1)
    assert len(first) == 8 and meta1["segment"] == 1
    assert first["soc_pct"].iloc[0] == 99
    with pytest.raises(DataError, match=r"--segment 4: the file has 3 discharge segment\(s\)"):
        read_discharge(path, segment="4")
    with pytest.raises(DataError, match="--segment counts from 1"):
        read_discharge(path, segment=0)


def test_a_file_parsed_once_reads_as_read_discharge_at_every_segment(tmp_path):
    t, v, i, soc = flights()
    path = write(tmp_path / "flights.csv",
                 as_csv([t, v, i, soc], header=["time_s", "voltage_V", "current_A", "soc_pct"]))
    read = discharge_reader(path, sign="positive")
    for segment in ("auto", 1, 3, "none", 2, "auto"):  # repeated: no call changes the parse
        frame, meta = read(segment=segment)
        expected, expected_meta = read_discharge(path, sign="positive", segment=segment)
        pd.testing.assert_frame_equal(frame, expected)
        assert meta == expected_meta
    with pytest.raises(DataError, match="--current must be"):
        discharge_reader(path, current_A=-1)


def test_pack_swap_inside_load_splits(tmp_path):
    t, v, i, soc = flights(durations=(30,), idle=2)
    k = 2 + 12  # swap during the load: SOC and voltage jump up
    soc[k:] += 40
    v[k:] += 2.0
    path = write(tmp_path / "swap.csv",
                 as_csv([t, v, i, soc], header=["time_s", "voltage_V", "current_A", "soc_pct"]))
    frame, meta = read_discharge(path)
    assert [s["rows"] for s in meta["segments"]] == [12, 18]
    assert meta["segments"][0]["ended_by"] == "state of charge jumps up (pack swap?)"
    assert len(frame) == 18


def test_describe_mentions_summary_and_segments(tmp_path):
    t, v, i, soc = flights()
    path = write(tmp_path / "flights.csv",
                 as_csv([t, v, i, soc], header=["time_s", "voltage_V", "current_A", "soc_pct"]))
    frame, meta = read_discharge(path)
    text = describe(frame, meta)
    assert meta["summary"] in text
    assert "3 discharge segments (kept 2)" in text
    charge = charge_from_current(frame["time_s"], frame["current_A"])[-1]
    assert f"charge {charge:.4g} Ah" in text


# ----------------------------------------------------------------- LabVIEW, DJI, dispatch

def test_lvm_excerpt_from_tests_data():
    from pathlib import Path
    path = Path(__file__).parent / "data" / "k2_lfp26650_20C_excerpt.lvm"
    frame, meta = read_discharge(path, columns="time_s=0,current_A=1,voltage_V=2,temperature_C=4")
    assert meta["format"] == "lvm"
    assert len(frame) == 120
    assert meta["lvm_header"]["Date"] == "2023/09/06"
    assert frame["voltage_V"].iloc[0] == pytest.approx(3.6645)
    assert frame["current_A"].iloc[0] == pytest.approx(2.5855)


def test_lvm_clock_is_the_segments_not_the_runs(shared_data):
    """A rig writing one file per cycle repeats the run's start in every file header;
    the segment header dates the file's own first sample (cycles 500 and 510 of cell C:
    one header time, ten cycles apart)."""
    from dischargelab.logbook.summarise import _start_time

    folder = shared_data / "samsung30q_ageing_cellC"
    starts = [_start_time(read_discharge(folder / f"DischargeCycle{c}.txt")[1])[:16]
              for c in (500, 510)]
    assert starts == ["2024-08-25T12:48", "2024-08-27T03:49"]


LVM_TEMPLATE = """LabVIEW Measurement\t
Writer_Version\t2
Separator\tTab
Decimal_Separator\t.
Description\t{description}
***End_of_Header***\t

Channels\t3\t\t\t
***End_of_Header***\t\t\t\t
X_Value\tUntitled\tUntitled 1\tComment
"""


def test_lvm_without_usable_description_needs_columns(tmp_path):
    t, v, i = discharge_rows()
    body = as_csv([t, -i, v], sep="\t")
    path = write(tmp_path / "a.lvm", LVM_TEMPLATE.format(description="my test") + body)
    with pytest.raises(DataError, match=r"no voltage_V column found .*--columns voltage_V="):
        read_discharge(path)
    frame, meta = read_discharge(path, columns="time_s=0,current_A=1,voltage_V=2")
    assert meta["sign_convention"] == "discharge negative (flipped)"
    np.testing.assert_allclose(frame["voltage_V"], v, rtol=1e-5)
    described = write(tmp_path / "b.lvm",
                      LVM_TEMPLATE.format(description="columns: time, current and voltage") + body)
    frame2, meta2 = read_discharge(described)
    pd.testing.assert_frame_equal(frame, frame2)
    assert any("Description" in n for n in meta2["notes"])


def _seven_column_lvm(tmp_path, strain_at):
    """A discharge whose Description names six columns for seven (one strain column left out)."""
    t, v, i = discharge_rows()
    temp = 20.0 + 0.05 * np.arange(t.size)
    strain = 3.7e-4 + 1e-6 * np.sin(t)
    columns = [t, -i, v, -i * v, temp, 20.5 + 0 * t]
    columns.insert(strain_at, strain)
    description = "Clolumns are: time, Current, Voltage, Power, Battery Temp, and Chamber Temp"
    text = LVM_TEMPLATE.format(description=description).replace(
        "X_Value\tUntitled\tUntitled 1\tComment",
        "X_Value\t" + "\t".join(["Untitled"] + [f"Untitled {k}" for k in range(1, 6)])
        + "\tComment")
    return write(tmp_path / f"strain{strain_at}.lvm", text + as_csv(columns, sep="\t")), v, temp


@pytest.mark.parametrize("strain_at", [5, 6])
def test_lvm_description_missing_a_column_is_placed_by_the_data(tmp_path, strain_at):
    path, v, temp = _seven_column_lvm(tmp_path, strain_at)
    frame, meta = read_discharge(path)  # no flags
    np.testing.assert_allclose(frame["voltage_V"], v, rtol=1e-5)
    np.testing.assert_allclose(frame["temperature_C"], temp, rtol=1e-5)
    assert meta["sign_convention"] == "discharge negative (flipped)"
    assert frame["ambient_temperature_C"].median() == pytest.approx(20.5)
    note = next(n for n in meta["notes"] if "Description" in n)
    assert f"column {strain_at} left unnamed" in note


def test_lvm_description_placement_that_fits_nothing_is_not_used(tmp_path):
    t, v, i = discharge_rows()
    # seven columns, but the voltage is negative wherever the names could put it
    columns = [t, -i, -v, -v, -v, -v, -v]
    text = LVM_TEMPLATE.format(description="Columns are: time, Current, Voltage, Power, A, B")
    path = write(tmp_path / "odd.lvm", text + as_csv(columns, sep="\t"))
    with pytest.raises(DataError, match="no voltage_V column found"):
        read_discharge(path)


DJI_LINE = ("{clock} I/ExceptionLogger : Battery updated: Battery{{exists=true, "
            "currentVoltage={mv}, currentCurrent={ma}, remainPowerPercent={soc}, "
            "smartBattery=true, temperature=20.5}}.")


def test_dji_raw_midnight_rollover_and_events(tmp_path):
    lines = ["23:59:40.000 I/DroneMainControllerDjiImpl : onFlightMode change: GPS_ATTI -> "
             "AUTO_TAKEOFF (state = EXECUTING) (sinceEpoch = 1)"]
    clock = 23 * 3600 + 59 * 60 + 45.0
    for k in range(8):
        s = (clock + 10 * k) % 86400
        stamp = f"{int(s // 3600):02d}:{int(s % 3600 // 60):02d}:{s % 60:06.3f}"
        lines.append(DJI_LINE.format(clock=stamp, mv=24000 - 50 * k, ma=18000, soc=90 - k))
    lines.append("00:01:00.000 I/MyFlightControllerUpdateCallback : "
                 "TAKEOFF_POSITION_UPDATED as landed")
    path = write(tmp_path / "log.txt", "\n".join(lines) + "\n")
    frame, meta = read_discharge(path)
    assert meta["format"] == "dji-raw"
    np.testing.assert_allclose(frame["time_s"], 10.0 * np.arange(8))
    assert any("midnight" in n for n in meta["notes"])
    assert [e["event"] for e in meta["events"]] == ["flight_mode", "landed"]
    assert meta["events"][1]["time_s"] == pytest.approx(75.0)
    assert frame["voltage_V"].iloc[0] == pytest.approx(24.0)
    assert frame["current_A"].iloc[0] == pytest.approx(18.0)
    assert list(frame["flight_mode"].unique()) == ["AUTO_TAKEOFF"]


def test_detect_format():
    assert detect_format("# dischargelab-log v1\n# meta: {}\n") == "dischargelab-log"
    assert detect_format("\ufeffLabVIEW Measurement\t\n") == "lvm"
    assert detect_format("12:00:00.000 I/App : hello\n") == "dji-raw"
    assert detect_format("time,voltage\n0,4.1\n") == "text"


def test_dischargelab_log_is_dispatched(tmp_path):
    from dischargelab.acquire.pipeline import Sample
    from dischargelab.io.logfile import LogWriter

    t, v, i = lab_cycle(+1)
    path = tmp_path / "run.csv"
    with LogWriter(path, {"cells_series": 1}) as writer:
        for k in range(len(t)):
            writer.write(Sample(time_s=t[k], voltage_V=v[k], current_A=i[k], temperature_C=None,
                                seq=k))
            if k == 70:
                writer.event("gap", start_time_s=70.0, end_time_s=71.0)
    with open(path, "a", encoding="utf-8") as fh:
        fh.write("115.0000,3.5")  # a crash cut the last line
    frame, meta = read_discharge(path)
    assert meta["format"] == "dischargelab-log"
    assert len(frame) == 50
    assert meta["dropped"]["charge"] == 40
    assert meta["dropped"]["partial_last_line"] == 1
    assert [e["kind"] for e in meta["events"]] == ["gap"]
    assert meta["rest_sample"]["voltage_V"] == pytest.approx(4.0)


def test_dischargelab_log_with_current_in_header(tmp_path):
    from dischargelab.acquire.pipeline import Sample
    from dischargelab.io.logfile import LogWriter

    t, v, _ = discharge_rows()
    path = tmp_path / "run.csv"
    with LogWriter(path, {"current_given_A": 2.5}) as writer:
        for k in range(len(t)):
            writer.write(Sample(time_s=t[k], voltage_V=v[k], current_A=None, temperature_C=None,
                                seq=k))
    frame, meta = read_discharge(path)
    assert meta["current_source"] == "given"
    assert (frame["current_A"] == 2.5).all()


# ----------------------------------------------------------------- option parsers

def test_parse_columns():
    assert parse_columns("time_s=0,current_A=1,voltage_V=2,temperature_C=4") == {
        "time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4}
    assert parse_columns("voltage_V=Cell voltage (V), time_s = 0") == {
        "voltage_V": "Cell voltage (V)", "time_s": 0}


@pytest.mark.parametrize("text, message", [
    ("time=0", "unknown name 'time'"),
    ("time_s", "NAME=VALUE"),
    ("time_s=0,voltage_V=0", "column 0 for two names"),
    ("time_s=0,time_s=1", "names time_s twice"),
    ("", "is empty"),
])
def test_parse_columns_errors(text, message):
    with pytest.raises(DataError, match=message) as info:
        parse_columns(text)
    assert "--columns" in str(info.value)


def test_parse_units():
    assert parse_units("voltage_V=mv, time_s=hours, current_A=mA") == {
        "voltage_V": "mV", "time_s": "h", "current_A": "mA"}
    with pytest.raises(DataError, match="--units voltage_V=mA: unit not understood"):
        parse_units("voltage_V=mA")


def test_clock_times_with_midnight_rollover(tmp_path):
    t, v, i = discharge_rows(n=30, dt=60.0)
    clock = 23 * 3600 + 50 * 60 + t  # 23:50 .. 00:19
    stamps = [f"{int(c % 86400 // 3600):02d}:{int(c % 3600 // 60):02d}:{c % 60:06.3f}"
              for c in clock]
    lines = ["Time,Voltage(V),Current(A)"] + [f"{s},{a:.4f},{b:.3f}"
                                              for s, a, b in zip(stamps, v, i)]
    frame, meta = read_discharge(write(tmp_path / "clock.csv", "\n".join(lines) + "\n"))
    np.testing.assert_allclose(frame["time_s"], t, atol=1e-6)
    assert meta["units"]["time_s"] == "s (clock)"
    assert any("midnight" in n for n in meta["notes"])


def test_iso_time_stamps(tmp_path):
    t, v, i = discharge_rows(n=20, dt=0.5)
    start = pd.Timestamp("2024-03-01 10:00:00")
    stamps = [(start + pd.Timedelta(seconds=x)).isoformat(sep=" ") for x in t]
    lines = ["Date_Time;U;I"] + [f"{s};{a:.4f};{b:.3f}" for s, a, b in zip(stamps, v, i)]
    frame, meta = read_discharge(write(tmp_path / "iso.csv", "\n".join(lines) + "\n"),
                                 columns={"time_s": "Date_Time"})
    np.testing.assert_allclose(frame["time_s"], t, atol=1e-6)


@pytest.mark.parametrize("header, scale_t, scale_v, scale_i", [
    (["Test_Time(s)", "Step_Time(s)", "Current(A)", "Voltage(V)"], 1, 1, 1),
    (["time/s", "Ewe/V", "<I>/mA", "cycle number"], 1, 1, 1000),
    (["Elapsed [min]", "Cell voltage [mV]", "Load current [A]", "step"], 1 / 60, 1000, 1),
])
def test_instrument_style_headers(tmp_path, header, scale_t, scale_v, scale_i):
    t, v, i = discharge_rows()
    extra = np.arange(t.size, dtype=float)
    columns = {0: t * scale_t, 1: extra, 2: i * scale_i, 3: v * scale_v}
    if header[1] == "Ewe/V":
        columns = {0: t * scale_t, 1: v * scale_v, 2: i * scale_i, 3: extra}
    if header[0].startswith("Elapsed"):
        columns = {0: t * scale_t, 1: v * scale_v, 2: i * scale_i, 3: extra}
    path = write(tmp_path / "inst.csv", as_csv([columns[k] for k in range(4)], header=header))
    frame, meta = read_discharge(path)
    np.testing.assert_allclose(frame["voltage_V"], v, rtol=1e-5)
    np.testing.assert_allclose(frame["current_A"], i, rtol=1e-5)
    np.testing.assert_allclose(frame["time_s"], t, rtol=1e-4, atol=1e-3)


def test_header_unit_tells_temperature_from_time(tmp_path):
    t, v, i = discharge_rows()
    path = write(tmp_path / "tt.csv", as_csv([np.full_like(t, 24.5), t, v, i],
                                             header=["T [°C]", "t [s]", "U [V]", "I [A]"]))
    frame, meta = read_discharge(path)
    assert meta["column_map"]["temperature_C"].startswith("column 0")
    assert meta["column_map"]["time_s"].startswith("column 1")
    assert (frame["temperature_C"] == 24.5).all()


BASE_LINES = ["time_s,voltage_V,current_A"] + [
    f"{k},{4.1 - 0.01 * k:.3f},{2.0 if 3 < k < 40 else 0.0}" for k in range(50)]
MUTATIONS = ["delete", "duplicate", "garbage", "swap", "cut", "empty field", "sentinel",
             "negative", "blank", "comment", "tab"]


def mutate(lines, pos, kind):
    pos %= len(lines)
    if kind == "delete":
        del lines[pos]
    elif kind == "duplicate":
        lines.insert(pos, lines[pos])
    elif kind == "garbage":
        lines[pos] = "x,@#,1"
    elif kind == "swap" and pos + 1 < len(lines):
        lines[pos], lines[pos + 1] = lines[pos + 1], lines[pos]
    elif kind == "cut":
        lines[pos] = lines[pos][: len(lines[pos]) // 2]
    elif kind == "empty field":
        fields = lines[pos].split(",")
        lines[pos] = ",".join(fields[:1] + [""] + fields[2:])
    elif kind == "sentinel":
        lines[pos] = lines[pos].replace(",", ",3.4e38,", 1)
    elif kind == "negative":
        lines[pos] = lines[pos].replace(",", ",-", 1)
    elif kind == "blank":
        lines.insert(pos, "")
    elif kind == "comment":
        lines.insert(pos, "# note, 3")
    elif kind == "tab":
        lines[pos] = lines[pos].replace(",", "\t")


@settings(max_examples=150,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.integers(0, 50), st.sampled_from(MUTATIONS)), max_size=6),
       st.sampled_from([{}, {"current_A": 2.0}, {"segment": "none"}, {"sign": "negative"},
                        {"columns": "time_s=0,voltage_V=1"}]))
def test_damaged_files_load_cleanly_or_fail_with_one_line(tmp_path, mutations, options):
    """Whatever the damage: a clean discharge or one DataError line, never another exception."""
    lines = list(BASE_LINES)
    for pos, kind in mutations:
        if lines:
            mutate(lines, pos, kind)
    path = write(tmp_path / "damaged.csv", "\n".join(lines) + "\n")
    try:
        frame, meta = read_discharge(path, **options)
    except DataError as exc:
        assert "\n" not in str(exc)
        return
    assert len(frame) >= 2
    assert frame["time_s"].iloc[0] == 0.0
    assert (np.diff(frame["time_s"]) > 0).all()
    assert np.isfinite(frame[["time_s", "voltage_V", "current_A"]].to_numpy()).all()
    assert meta["rows_kept"] == len(frame)
    assert "\n" not in meta["summary"]


@settings(max_examples=150,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.text(alphabet=st.sampled_from(list("0123456789.,;\t -+eE\n#abcXV:_")), max_size=300))
def test_random_text_never_raises_anything_but_data_error(tmp_path, text):
    path = write(tmp_path / "random.csv", text)
    try:
        read_discharge(path, current_A=1.0)
    except DataError as exc:
        assert "\n" not in str(exc)
