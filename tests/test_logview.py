"""LogView OpenFormat output: lines parse back, checksum, INI, file and serial targets,
and a whole run (virtual EBC load -> pipeline -> LogView file)."""

import os
import select
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from dischargelab.acquire.logview import (
    DEFAULT_COLUMNS,
    LogViewWriter,
    device_ini,
    format_line,
    parse_line,
    read_openformat,
    xor_checksum,
)
from dischargelab.acquire.pipeline import Pipeline, Sample
from dischargelab.errors import DataError

REPO = Path(__file__).resolve().parents[1]

VALUE = st.one_of(st.none(), st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False))


def test_checksum_of_the_format_descriptions_example():
    # XOR of every byte from '$' to the last ';' of the example line, computed by hand:
    # the description prints "16" after it, which is neither 0x14 nor 20 -- see module notes.
    assert xor_checksum("$1;1;0;1133;318;0;0;0;0;0;20;21;0;") == 0x14


@given(st.integers(1, 8), st.integers(0, 99), st.one_of(st.none(), st.floats(0, 1e6)),
       st.lists(VALUE, max_size=40))
def test_line_round_trip(channel, state, time_s, values):
    line = format_line(channel, state, time_s, values)
    assert line.startswith("$") and line.endswith("\r\n") and line.count("\r\n") == 1
    parsed = parse_line(line)
    assert (parsed.channel, parsed.state) == (channel, state)
    if time_s is None:
        assert parsed.time_s is None
    else:
        # half the format's 1 ms, float rounding aside (0.0625 s is written 0.062)
        assert parsed.time_s == pytest.approx(time_s, abs=5e-4 + 1e-9)
    assert len(parsed.values) == len(values)
    for got, want in zip(parsed.values, values):
        if want is None:
            assert got is None
        else:
            assert got == pytest.approx(want, abs=5e-5)


def test_line_layout_and_checksum():
    line = format_line(1, 1, 12.5, [7.8123, None, 3.0], digits=(3, 3, 1))
    assert line == "$1;1;12.500;7.812;;3.0;" + f"{xor_checksum('$1;1;12.500;7.812;;3.0;'):02X}\r\n"
    assert format_line(2, 1, None, [1.0], checksum=False) == "$2;1;;1.0000;0\r\n"


def test_bad_lines_are_rejected():
    good = format_line(1, 1, 0.0, [7.5, 2.0])
    flipped = good.replace("7.5", "7.6")
    with pytest.raises(DataError, match="checksum"):
        parse_line(flipped)
    assert parse_line(flipped, checksum=False).values[0] == 7.6
    for bad in ["1;1;0;7.5;00", "$1;1", "$x;1;0;1.0;" + "00", "$1;1;0;abc;" + "00"]:
        with pytest.raises(DataError):
            parse_line(bad, checksum=False)
    with pytest.raises(DataError):
        format_line(9, 1, 0.0, [1.0])
    with pytest.raises(DataError):
        format_line(1, 1, 0.0, [1.0] * 41)


def samples_cc(n=50, current=2.0, dt=1.0):
    t = np.arange(n) * dt + 100.0           # pipeline time need not start at 0
    v = 8.2 - 0.01 * np.arange(n)
    return [Sample(float(a), float(b), current, 25.0 + 0.1 * i, i) for i, (a, b) in
            enumerate(zip(t, v))]


def test_writer_file_parses_back(tmp_path):
    path = tmp_path / "run.lvo"
    ini = tmp_path / "dischargelab.ini"
    w = LogViewWriter(path, ini_path=ini)
    data = samples_cc()
    for s in data[:30]:
        w.handle(s)
    w.event("cutoff", voltage_V=7.9)
    for s in data[30:]:
        w.handle(s)
    w.close()
    raw = path.read_bytes()
    assert raw.count(b"\r\n") == len(data) and b"\n\n" not in raw
    lines = read_openformat(path)
    assert [ln.time_s for ln in lines] == pytest.approx([s.time_s - 100.0 for s in data])
    assert [ln.state for ln in lines] == [1] * 30 + [2] * 20
    names = [c[0] for c in DEFAULT_COLUMNS]
    for ln, s in zip(lines, data):
        row = dict(zip(names, ln.values))
        assert row["voltage_V"] == pytest.approx(s.voltage_V, abs=1e-4)
        assert row["current_A"] == pytest.approx(2.0)
        assert row["power_W"] == pytest.approx(s.voltage_V * 2.0, abs=1e-3)
        assert row["temperature_C"] == pytest.approx(s.temperature_C, abs=0.01)
    # charge: 2 A for 49 s
    assert dict(zip(names, lines[-1].values))["charge_Ah"] == pytest.approx(2.0 * 49 / 3600,
                                                                             abs=1e-5)
    text = ini.read_text(encoding="utf-8")
    assert "[Stati]" in text and "StatiAnzahl = 2" in text
    assert text.count("Messgroesse =") == len(DEFAULT_COLUMNS)


def test_missing_current_and_temperature_are_empty(tmp_path):
    path = tmp_path / "v.lvo"
    w = LogViewWriter(path)
    w.handle(Sample(0.0, 7.5, None, None, None))
    w.handle(Sample(1.0, 7.4, None, None, None))
    w.close()
    first = read_openformat(path)[0]
    assert first.values == (7.5, None, None, 0.0, None)


def test_shipped_ini_matches_the_generator():
    shipped = REPO / "docs" / "logview" / "dischargelab.ini"
    assert shipped.read_bytes().decode("utf-8") == device_ini()


def test_writer_to_a_serial_port():
    master, slave = os.openpty()
    try:
        w = LogViewWriter(os.ttyname(slave), baudrate=115200)
        assert w.is_serial
        for s in samples_cc(5):
            w.handle(s)
        received = b""
        deadline = time.monotonic() + 10
        while received.count(b"\r\n") < 5 and time.monotonic() < deadline:
            if select.select([master], [], [], 0.2)[0]:
                received += os.read(master, 4096)
        w.close()
    finally:
        os.close(master)
        os.close(slave)
    lines = [parse_line(x) for x in received.decode("ascii").split("\r\n") if x]
    assert len(lines) == 5 and lines[-1].time_s == pytest.approx(4.0)


def test_whole_run_virtual_load_to_logview(tmp_path):
    pytest.importorskip("serial")
    from dischargelab.acquire.ebc import EbcSource
    from dischargelab.acquire.virtual_load import VirtualEbcLoad

    out = tmp_path / "ebc.lvo"
    with VirtualEbcLoad("zippy-1100-2s", frame_period_s=0.01, time_scale=600) as load:
        source = EbcSource(load.port, current_A=2.0, cutoff_V=6.6, parity="N",
                           command_timeout_s=1.0)
        writer = LogViewWriter(out)
        pipe = Pipeline(source, [writer])
        ended = pipe.run(timeout_s=30)
        load.wait_for_command(0x06, timeout_s=10)   # Disconnect, sent as the source closes
    assert ended == "cutoff" and source.ended_by == "load cutoff"
    lines = read_openformat(out)
    assert len(lines) > 20
    v = np.array([ln.values[0] for ln in lines if ln.state == 1 and ln.values[1]])
    assert v[0] > 7.0 and v.min() >= 6.6 - 1e-3
    assert lines[0].time_s == pytest.approx(0.0, abs=1e-3)
    # the host integrates the reported current over wall-clock time; the load's clock runs
    # 600 times faster, so the charges agree after that scaling (frame timing jitter aside)
    charge = lines[-1].values[3]
    assert charge * 600 == pytest.approx(load.charge_Ah, rel=0.25)
    assert load.state == 0                       # the pipeline's final Stop was obeyed
    assert [c[0] for c in load.commands][-2:] == [0x02, 0x06]   # Stop, Disconnect
