"""The dischargelab log file: round trip, crash tolerance, never overwrite."""

import json
import time

import numpy as np
import pytest

from dischargelab.acquire.pipeline import Sample
from dischargelab.atomic import OutputExistsError
from dischargelab.errors import DataError
from dischargelab.io.logfile import LOG_MAGIC, LogWriter, is_log_file, read_log


def samples(n, *, current=None, temperature=None):
    return [Sample(time_s=k * 0.5, voltage_V=12.6 - 0.001 * k, current_A=current,
                   temperature_C=temperature, seq=k & 0xFFFF) for k in range(n)]


def test_round_trip_with_events(tmp_path):
    path = tmp_path / "run.csv"
    meta = {"port": "/dev/ttyACM0", "rate_Hz": 2.0, "cells_series": 3, "chemistry": "lipo",
            "calibration": {"gain": 4.38, "offset_V": 0.0}, "firmware": "x 1.0.0"}
    with LogWriter(path, meta) as log:
        for s in samples(10, current=2.0, temperature=25.5):
            log.write(s)
        log.event("gap", start_time_s=4.5, end_time_s=7.0, duration_s=2.5)
        log.handle(Sample(7.0, 12.5, None, None, 0))
    assert is_log_file(path)
    assert path.read_text().splitlines()[0] == LOG_MAGIC
    data, m = read_log(path)
    assert list(data.columns) == ["time_s", "voltage_V", "current_A", "temperature_C", "seq"]
    assert len(data) == 11
    np.testing.assert_allclose(data["voltage_V"][:10], [12.6 - 0.001 * k for k in range(10)])
    assert np.isnan(data["current_A"].iloc[-1]) and data["current_A"].iloc[0] == 2.0
    assert data["seq"].tolist() == list(range(10)) + [0]
    assert m["cells_series"] == 3 and m["calibration"]["gain"] == 4.38
    assert m["format"] == "dischargelab-log" and m["current_source"] == "column"
    assert m["sign_convention"] == "discharge positive"
    assert "start_time" in m
    assert [e["kind"] for e in m["events"]] == ["gap"]
    assert m["events"][0]["duration_s"] == 2.5
    assert m["dropped"] == {"partial_last_line": 0, "malformed": 0}


def test_given_current_fills_the_column(tmp_path):
    path = tmp_path / "run.csv"
    with LogWriter(path, {"current_given_A": 1.7}) as log:
        for s in samples(5):
            log.write(s)
    data, meta = read_log(path)
    assert meta["current_source"] == "given"
    assert (data["current_A"] == 1.7).all()
    assert "temperature_C" not in data


def test_partial_last_line_from_a_crash_is_tolerated(tmp_path):
    path = tmp_path / "run.csv"
    with LogWriter(path, {}) as log:
        for s in samples(20):
            log.write(s)
    text = path.read_text()
    path.write_text(text[:-7])                 # cut inside the last row, as kill -9 may
    data, meta = read_log(path)
    assert len(data) == 19
    assert meta["dropped"] == {"partial_last_line": 1, "malformed": 0}


def test_malformed_rows_are_dropped_and_counted(tmp_path):
    path = tmp_path / "run.csv"
    with LogWriter(path, {}) as log:
        for s in samples(5):
            log.write(s)
    lines = path.read_text().splitlines()
    lines.insert(5, "1.0,abc,,,3")
    lines.insert(6, "1.0,2.0")
    path.write_text("\n".join(lines) + "\n")
    data, meta = read_log(path)
    assert len(data) == 5
    assert meta["dropped"]["malformed"] == 2


def test_never_overwrites_unless_asked(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("precious")
    with pytest.raises(OutputExistsError, match="already exists"):
        LogWriter(path, {})
    assert path.read_text() == "precious"
    LogWriter(path, {}, overwrite=True).close()
    assert is_log_file(path)


def test_not_a_log_file(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("time,voltage\n0,1\n")
    assert not is_log_file(path)
    with pytest.raises(DataError, match="not a dischargelab log"):
        read_log(path)


def test_data_reaches_the_file_without_close(tmp_path):
    """The timer flushes and fsyncs: an unclosed writer's rows are on disk within ~interval."""
    path = tmp_path / "run.csv"
    log = LogWriter(path, {}, fsync_interval_s=0.2)
    try:
        log.write(Sample(0.0, 12.0, None, None, 0))
        deadline = time.monotonic() + 10
        while "12.0000" not in path.read_text():
            assert time.monotonic() < deadline, "row not flushed by the fsync timer"
            time.sleep(0.02)
    finally:
        log.close()


def test_events_are_json_and_nan_safe(tmp_path):
    path = tmp_path / "run.csv"
    with LogWriter(path, {"x": float("nan")}) as log:
        log.event("alarm", message="hot", value=float("inf"))
    lines = path.read_text().splitlines()
    assert json.loads(lines[1][len("# meta: "):])["x"] is None
    event = json.loads(lines[3][len("# event: "):])
    assert event["kind"] == "alarm" and event["value"] is None
