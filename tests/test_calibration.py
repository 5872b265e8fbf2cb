"""Calibration of the divider + follower front end (paper 3.3, eq. 7, Table 1)."""

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from dischargelab.acquire.calibration import (
    Calibration,
    MeterAccuracy,
    adc_step_V,
    fit_calibration,
    load_calibration,
    parse_pair,
    read_points_csv,
)
from dischargelab.cli import main
from dischargelab.errors import DataError

TABLE1 = Path(__file__).parent / "data" / "paper_table1.csv"


def table1(divider):
    with TABLE1.open() as fh:
        rows = [r for r in csv.DictReader(line for line in fh if not line.startswith("#"))
                if r["divider"] == divider]
    return ([float(r["real_V"]) for r in rows], [float(r["measured_V"]) for r in rows],
            [float(r["Ke_paper"]) for r in rows])


# --------------------------------------------------------------------------- the paper's data

def test_paper_33k_gain_is_438_and_linear():
    real, measured, _ = table1("3.3k")
    fit = fit_calibration(real, measured, divider="3.3k")
    assert fit.calibration.gain == pytest.approx(4.38, abs=0.01)      # paper: Ke = 4.38
    assert fit.calibration.offset_V == 0.0                             # "no bias detected"
    assert all(p.status == "linear" for p in fit.points)
    assert fit.nonlinear_from_V is None
    assert fit.calibration.valid_range_V == (7.67, 15.33)
    # the F-test alone would call the offset significant (the points are very smooth) but
    # the offset changes predictions by less than the meter's stated accuracy
    t = fit.offset_test
    assert t.f_p_value < 0.05 and t.chi2_p_value > 0.05 and not t.adopted
    limit = MeterAccuracy().limit_V(np.array(real))
    assert t.max_model_difference_V < limit.min()


def test_paper_27k_nonlinear_above_15V():
    real, measured, _ = table1("2.7k")
    fit = fit_calibration(real, measured, divider="2.7k")
    flagged = sorted(p.real_V for p in fit.points if p.status == "non-linear")
    assert flagged == [15.01, 15.33]                    # the two points near 15 V
    assert fit.calibration.gain == pytest.approx(3.70, abs=0.01)
    assert fit.linear_up_to_V == 13.16 and fit.nonlinear_from_V == 15.01
    # the flagged logger readings are stuck at ~3.77 V: clipping, onset between the points
    assert 13.16 < fit.clip_estimate_V < 15.01
    for p in fit.nonlinear_points:
        assert abs(p.residual_V) > 3 * p.bound_V
        assert p.ke > 3.95                               # Ke "jumps" to ~4.0
    assert fit.calibration.valid_range_V == (5.0, 13.16)


def test_point_ke_is_equation_7_and_matches_the_paper():
    for divider in ("2.7k", "3.3k"):
        real, measured, ke_paper = table1(divider)
        fit = fit_calibration(real, measured, divider=divider)
        by_real = {(p.real_V, p.measured_V): p.ke for p in fit.points}
        for r, m, k in zip(real, measured, ke_paper):
            assert by_real[(r, m)] == pytest.approx(r / m, rel=1e-12)
            # the paper printed the 3.3k logger readings rounded to 10 mV but computed Ke
            # from the unrounded ones: allow that rounding (k * 0.005 V / reading)
            tol = 1e-6 * k if divider == "2.7k" else k * 0.005 / m
            assert abs(r / m - k) <= tol


def test_resolution_is_adc_step_times_gain():
    real, measured, _ = table1("3.3k")
    cal = fit_calibration(real, measured).calibration
    assert adc_step_V(10, 5.0) == pytest.approx(4.8828125e-3)
    assert cal.resolution_V == pytest.approx(cal.gain * 5.0 / 1024)
    # paper: 4.9 mV x 4.38 = 21.46 mV; with the exact 4.883 mV step it is 21.39 mV
    assert cal.resolution_V == pytest.approx(0.0214, abs=0.0001)
    assert fit_calibration(real, measured, adc_bits=12).calibration.resolution_V \
        == pytest.approx(cal.resolution_V / 4, rel=1e-3)


# --------------------------------------------------------------------------- synthetic data

def synthetic(gain, offset, rng, n=12, noise_V=0.005, low=6.0, high=16.0):
    real = np.sort(rng.uniform(low, high, n))
    measured = (real - offset) / gain + rng.normal(0, noise_V / gain, n)
    return real, np.round(measured, 4)


def test_large_offset_is_detected_and_recovered():
    rng = np.random.default_rng(7)
    real, measured = synthetic(4.2, 0.6, rng)
    fit = fit_calibration(real, measured)
    assert fit.offset_test.adopted
    assert fit.calibration.gain == pytest.approx(4.2, rel=0.01)
    assert fit.calibration.offset_V == pytest.approx(0.6, abs=0.05)
    assert np.max(np.abs([p.residual_V for p in fit.points])) < 0.03


@pytest.mark.parametrize("seed", range(5))
def test_no_offset_when_there_is_none(seed):
    rng = np.random.default_rng(seed)
    real, measured = synthetic(4.38, 0.0, rng, noise_V=0.02)
    fit = fit_calibration(real, measured)
    assert not fit.offset_test.adopted
    assert fit.calibration.gain == pytest.approx(4.38, rel=0.003)


def test_offset_forced_and_refused():
    real, measured, _ = table1("3.3k")
    yes = fit_calibration(real, measured, offset="yes")
    assert yes.calibration.offset_V == pytest.approx(yes.offset_test.offset_V)
    assert yes.calibration.offset_V != 0
    no = fit_calibration(real, measured, offset="no")
    assert no.calibration.offset_V == 0


def test_clipping_front_end_is_flagged():
    rng = np.random.default_rng(3)
    real = np.linspace(5, 16.8, 10)
    measured = np.minimum(real / 4.0, 3.5) + rng.normal(0, 0.001, real.size)
    fit = fit_calibration(real, measured)
    flagged = [p.real_V for p in fit.points if p.status == "non-linear"]
    assert flagged and min(flagged) > 14.0           # 3.5 V x 4.0 = 14 V
    assert all(p.status == "linear" for p in fit.points if p.real_V < 14.0)
    assert fit.clip_estimate_V == pytest.approx(14.0, abs=0.2)
    assert fit.calibration.gain == pytest.approx(4.0, rel=0.003)


def test_isolated_bad_reading_is_an_outlier_not_the_range_end():
    real = np.array([6.0, 8.0, 10.0, 12.0, 14.0, 16.0])
    measured = real / 4.0
    measured[2] += 0.15                               # 0.6 V off at the pack
    fit = fit_calibration(real, measured)
    status = {p.real_V: p.status for p in fit.points}
    assert status == {6.0: "linear", 8.0: "linear", 10.0: "outlier", 12.0: "linear",
                      14.0: "linear", 16.0: "linear"}
    assert fit.calibration.gain == pytest.approx(4.0, rel=1e-9)   # the outlier is left out
    assert fit.calibration.valid_range_V == (6.0, 16.0)
    assert fit.nonlinear_from_V is None
    assert any("repeat" in w for w in fit.warnings)


# --------------------------------------------------------------------------- bad input

@pytest.mark.parametrize("real, measured, words", [
    ([11.88], [2.71], "at least 2"),
    ([11.88, 7.67], [2.71, 0.0], "0 V"),
    ([11.88, -7.67], [2.71, 1.74], "negative"),
    ([11.88, 7.67], [2.71, -1.74], "negative"),
    ([11.88, float("nan")], [2.71, 1.74], "finite"),
    ([11.88, 7.67, 5.0], [2.71, 1.74], "measured"),
    ([11.88, 7.67], [2.71, 2.71], "stuck"),
])
def test_bad_points_raise_one_clear_error(real, measured, words):
    with pytest.raises(DataError, match=words):
        fit_calibration(real, measured)


@pytest.mark.parametrize("text", ["11.88", "a,b", "1,2,3", ""])
def test_parse_pair_rejects(text):
    with pytest.raises(DataError):
        parse_pair(text, 1)


def test_parse_pair_separators():
    assert parse_pair("11.88,2.71") == (11.88, 2.71)
    assert parse_pair("11.88; 2.71") == (11.88, 2.71)
    assert parse_pair("11.88 2.71") == (11.88, 2.71)


# --------------------------------------------------------------------------- files

def test_save_load_round_trip(tmp_path):
    real, measured, _ = table1("3.3k")
    cal = fit_calibration(real, measured, divider="3.3k", created="2024-05-01T10:00:00").calibration
    path = cal.save(tmp_path / "sub" / "cal.json")
    back = load_calibration(path)
    assert back.gain == cal.gain and back.offset_V == cal.offset_V
    assert back.divider == "3.3k" and back.created == "2024-05-01T10:00:00"
    assert back.valid_range_V == cal.valid_range_V
    assert len(back.points) == 5 and back.points[0]["status"] == "linear"
    assert back.resolution_V == pytest.approx(cal.resolution_V)
    data = json.loads(path.read_text())
    assert data["format"] == "dischargelab-calibration"
    assert back.apply(2.71) == pytest.approx(cal.gain * 2.71)
    arr = back.apply(np.array([1.0, 2.0]))
    assert arr.shape == (2,) and arr[1] == pytest.approx(2 * cal.gain)


def test_contract_minimal_calibration():
    cal = Calibration(4.38)
    assert cal.apply(3.0) == pytest.approx(13.14)
    assert Calibration(4.0, 0.5).apply(3.0) == pytest.approx(12.5)
    assert cal.in_valid_range(100.0)
    with pytest.raises(DataError):
        Calibration(0.0)
    with pytest.raises(DataError):
        Calibration(-4.38)


def test_load_errors(tmp_path):
    with pytest.raises(DataError, match="not found"):
        load_calibration(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(DataError, match="JSON"):
        load_calibration(bad)
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"parameters": {}}))
    with pytest.raises(DataError, match="gain"):
        load_calibration(other)


def test_read_points_csv_variants(tmp_path):
    plain = tmp_path / "plain.csv"
    plain.write_text("# my points\n11.88,2.71\n7.67,1.74\n")
    assert read_points_csv(plain) == ([11.88, 7.67], [2.71, 1.74])
    swapped = tmp_path / "named.csv"
    swapped.write_text("logger,multimeter\n2.71,11.88\n1.74,7.67\n")
    assert read_points_csv(swapped) == ([11.88, 7.67], [2.71, 1.74])
    real, measured = read_points_csv(TABLE1, "2.7k")
    assert len(real) == 9 and real[0] == 15.33 and measured[0] == 3.773
    with pytest.raises(DataError, match="several dividers"):
        read_points_csv(TABLE1)
    with pytest.raises(DataError, match="no rows for divider"):
        read_points_csv(TABLE1, "4.7k")
    broken = tmp_path / "broken.csv"
    broken.write_text("11.88,2.71\n7.67,oops\n")
    with pytest.raises(DataError, match="row 2"):
        read_points_csv(broken)


# --------------------------------------------------------------------------- command line

def run(argv, capsys, monkeypatch=None, stdin=None):
    if stdin is not None:
        import io
        monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    with pytest.raises(SystemExit) as exc:
        main(argv)
    captured = capsys.readouterr()
    return exc.value.code, captured.out, captured.err


def test_cli_pairs_json_and_file(tmp_path, capsys):
    real, measured, _ = table1("3.3k")
    args = ["calibrate", "--divider", "3.3k", "-o", str(tmp_path / "cal.json"), "--json"]
    for r, m in zip(real, measured):
        args += ["--pair", f"{r},{m}"]
    code, out, err = run(args, capsys)
    assert code == 0, err
    data = json.loads(out)
    assert data["gain"] == pytest.approx(4.38, abs=0.01)
    assert data["offset_test"]["adopted"] is False
    assert load_calibration(tmp_path / "cal.json").gain == pytest.approx(data["gain"])


def test_cli_csv_table_reports_nonlinear(capsys):
    code, out, err = run(["calibrate", "--csv", str(TABLE1), "--divider", "2.7k"], capsys)
    assert code == 0, err
    assert "non-linear" in out and "15.01 V" in out and "resolution" in out


def test_cli_interactive(capsys, monkeypatch):
    code, out, err = run(["calibrate", "--json"], capsys, monkeypatch,
                         stdin="15.33,3.51\nnonsense\n13.16,3.01\n11.88,2.71\n\n")
    assert code == 0, err
    data = json.loads(out)                 # prompts went to stderr, stdout is JSON only
    assert len(data["points"]) == 3
    assert "try again" in err


@pytest.mark.parametrize("args, words", [
    (["--pair", "11.88,2.71"], "at least 2"),
    (["--pair", "11.88,0", "--pair", "7.67,1.74"], "0 V"),
    (["--pair", "11.88,abc", "--pair", "7.67,1.74"], "not two numbers"),
    (["--pair", "-11.88,2.71", "--pair", "7.67,1.74"], "negative"),
    (["--csv", "nowhere.csv"], "not found"),
])
def test_cli_bad_input_one_line(args, words, capsys):
    code, out, err = run(["calibrate", *args], capsys)
    assert code == 2
    assert words in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_cli_no_points_from_empty_stdin(capsys, monkeypatch):
    code, out, err = run(["calibrate"], capsys, monkeypatch, stdin="")
    assert code == 2 and "no calibration points" in err


def test_resolution_of_the_paper_divider_scales_with_gain():
    # a higher gain (bigger divider ratio) gives a coarser resolution, linearly
    step = adc_step_V()
    for gain in (3.7, 4.38, 5.0):
        assert Calibration(gain).resolution_V == pytest.approx(gain * step)
    assert math.isclose(Calibration(4.38).resolution_V * 1000, 21.387, abs_tol=0.001)


def test_cli_plot(tmp_path, capsys):
    png = tmp_path / "ke.png"
    code, out, err = run(["calibrate", "--csv", str(TABLE1), "--divider", "2.7k", "--plot",
                          str(png), "--json"], capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    assert json.loads(out)["plot"] == str(png)
