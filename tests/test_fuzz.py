"""Fuzzing the readers and ``dischargelab fit``: bad input is one line, never a crash.

Inputs: random bytes, real files cut anywhere, real files with cells replaced by
NaN, inf, huge, empty or non-numeric values, rows swapped (time going
backwards), byte-order marks alone, headers without data. The properties:

* :func:`read_discharge` returns a discharge or raises :class:`DataError` with
  a one-line message;
* ``dischargelab fit FILE -o out.json`` exits 0 with a battery file, or exits 2
  with one line on stderr, no traceback and no file written;
* input that holds no discharge at all always exits 2.

Derandomized, with modest example counts (the file runs in a few seconds).
"""

import contextlib
import io
import json
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from dischargelab.cli import main
from dischargelab.errors import DataError
from dischargelab.io import read_discharge

REPO = Path(__file__).resolve().parents[1]
SAMSUNG = (REPO / "src/dischargelab/data/samsung30q/Q30_S001_4C.csv").read_bytes()
DJI_LOG = b"""20:56:04.479 I/Drone : onFlightMode change: GPS_ATTI -> AUTO_TAKEOFF
20:56:10.000 I/ExceptionLogger : Battery updated: Battery{exists=true, currentVoltage=25730, \
currentCurrent=18000, remainPowerPercent=98, smartBattery=true, temperature=17.9}.
20:56:22.000 I/ExceptionLogger : Battery updated: Battery{exists=true, currentVoltage=25500, \
currentCurrent=18200, remainPowerPercent=97, smartBattery=true, temperature=18.0}.
20:56:34.000 I/ExceptionLogger : Battery updated: Battery{exists=true, currentVoltage=25310, \
currentCurrent=17900, remainPowerPercent=96, smartBattery=true, temperature=18.1}.
20:56:46.000 I/ExceptionLogger : Battery updated: Battery{exists=true, currentVoltage=25150, \
currentCurrent=18100, remainPowerPercent=95, smartBattery=true, temperature=18.2}.
"""
COLUMNS = "time_s=0,current_A=1,voltage_V=2"
SETTINGS = dict(derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

BAD_VALUES = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e31", "", "x", "-", "0",
              "9" * 30, "1e-320", "4.1.2", "\x00"]


def mutated(base: bytes, edits) -> bytes:
    """``base`` (a CSV) with cells replaced, rows swapped, dropped or cut."""
    lines = base.decode("utf-8-sig").splitlines()[:400]
    for position, column, value, kind in edits:
        if not lines:
            break
        k = position % len(lines)
        fields = lines[k].split(",")
        if kind == "cell":
            fields[column % len(fields)] = value
            lines[k] = ",".join(fields)
        elif kind == "column":          # a column empty or garbage on every row
            lines = [",".join(value if j == column % len(f) else x for j, x in enumerate(f))
                     for f in (line.split(",") for line in lines)]
        elif kind == "swap":            # time goes backwards
            j = (position // 7) % len(lines)
            lines[k], lines[j] = lines[j], lines[k]
        elif kind == "drop":
            del lines[k]
        elif kind == "cut":
            lines[k] = lines[k][:column * 3]
    return "\n".join(lines).encode()


edits = st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 6), st.sampled_from(BAD_VALUES),
                           st.sampled_from(["cell", "column", "swap", "drop", "cut"])),
                 max_size=6)

files = st.one_of(
    st.binary(max_size=300),
    st.integers(0, len(SAMSUNG)).map(lambda n: SAMSUNG[:n]),
    st.integers(0, len(DJI_LOG)).map(lambda n: DJI_LOG[:n]),
    edits.map(lambda e: mutated(SAMSUNG, e)),
    st.sampled_from([b"\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff", b"\xef\xbb\xbf\r\n",
                     b"time_s,voltage_V,current_A\n", b"time_s,voltage_V,current_A\n,,\n,,\n,,\n",
                     b"\xef\xbb\xbftime_s;voltage_V\n"]),
)

#: Input holding no discharge at all: fit must refuse it.
garbage = st.one_of(
    st.binary(max_size=200).filter(lambda b: b"," not in b and b";" not in b),
    st.sampled_from([b"", b"\xef\xbb\xbf", b"\xef\xbb\xbf\n\n", b"\xff\xfe\x00\x00",
                     b"time_s,voltage_V,current_A\n",
                     b"time_s,voltage_V,current_A\nnan,nan,nan\nnan,nan,nan\ninf,inf,inf\n",
                     b"time_s,voltage_V,current_A\n,,\n,,\n,,\n",
                     b"time_s,voltage_V,current_A\n3,4.1,1\n2,4.0,1\n1,3.9,1\n0,3.8,1\n",
                     b"time_s,voltage_V,current_A\n0,1e308,1\n1,1e308,1\n2,1e308,1\n"]),
)


@pytest.fixture(scope="module")
def folder():
    with tempfile.TemporaryDirectory() as name:
        yield Path(name)


def fit_cli(folder: Path, data: bytes):
    """Run ``dischargelab fit`` in-process on ``data``; (status, stderr, output path)."""
    source, out = folder / "in.csv", folder / "out.json"
    source.write_bytes(data)
    out.unlink(missing_ok=True)
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        with pytest.raises(SystemExit) as exc:
            main(["fit", str(source), "--columns", COLUMNS, "--bootstrap", "0", "-o", str(out)])
    return exc.value.code, stderr.getvalue(), out


#: A time column that is infinite on every row (a found case: format sniffing must not warn).
INFINITE_TIME = mutated(SAMSUNG, [(0, 0, "inf", "column")])


@settings(max_examples=150, **SETTINGS)
@given(data=files)
@example(data=INFINITE_TIME)
def test_reader_returns_a_discharge_or_a_one_line_data_error(folder, data):
    path = folder / "read.csv"
    path.write_bytes(data)
    for options in ({}, {"columns": COLUMNS}, {"current_A": 2.0}):
        try:
            frame, meta = read_discharge(path, **options)
        except DataError as exc:
            message = str(exc)
            assert message and "\n" not in message and "\r" not in message
        else:
            assert len(frame) >= 2 and json.dumps(meta, default=str)


@settings(max_examples=60, **SETTINGS)
@given(data=files)
@example(data=INFINITE_TIME)
def test_fit_exits_0_with_a_file_or_2_with_one_line(folder, data):
    code, err, out = fit_cli(folder, data)
    assert "Traceback" not in err
    if code == 0:
        assert "parameters" in json.loads(out.read_text())
    else:
        assert code == 2, err
        assert len(err.strip().splitlines()) == 1 and err.startswith("error: ")
        assert not out.exists()


@settings(max_examples=40, **SETTINGS)
@given(data=garbage)
def test_fit_refuses_input_without_a_discharge(folder, data):
    code, err, out = fit_cli(folder, data)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()
