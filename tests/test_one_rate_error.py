"""The measured one-rate error: its classes, its law, the packaged table, and the advice on
the one more run that would narrow an interval most (predict, fit, their JSON and CLI)."""

import json
import math
from dataclasses import replace

import pytest

import dischargelab as dl
from dischargelab.cli import main as cli_main
from dischargelab.model import Battery, CellParameters
from dischargelab.nexttest import fit_next_test, next_test
from dischargelab.onerate import (
    FLAT_PLATEAU_RATIO,
    one_rate_class,
    one_rate_table,
    one_rate_table_override,
)
from dischargelab.uncertainty import (
    PRIOR_RELATIVE_SD,
    half_width_pct,
    model_error_info,
    model_error_sd,
)

CELL = CellParameters(E0_V=3.75, R_ohm=0.03, K_V_per_Ah=0.008, A_V=0.35, B_per_Ah=2.0,
                      C_Ah=3.1)
SLOPED_LOGGED = Battery(CELL, fit_currents_A=(3.0,), extra={
    "fit_plateau_ratio": 0.35, "fit_temperature_rise_K": 9.0})
TABLE = {"one_rate": {"shepherd / sloped / temperature": {
             "base": 0.004, "up": 0.01, "down": 0.02, "cells": ["a", "b", "c"]},
                      "shepherd / flat / no temperature": {
             "base": 0.005, "up": 0.05, "down": None, "cells": ["d", "e", "g"]},
                      "shepherd / sloped / no temperature": {
             "base": 0.005, "up": 0.01, "down": 0.01, "cells": ["f"]}},
         "two_rate": {"shepherd / sloped / temperature": {"sd": 0.006, "dof": 8.0}}}
SAMSUNG = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"


def test_class_is_what_the_file_shows():
    assert one_rate_class(SLOPED_LOGGED) == "shepherd / sloped / temperature"
    flat = replace(SLOPED_LOGGED, extra={"fit_plateau_ratio": FLAT_PLATEAU_RATIO / 2})
    assert one_rate_class(flat) == "shepherd / flat / no temperature"
    assert one_rate_class(Battery(CELL, fit_currents_A=(3.0,))) is None   # a flight, a preset
    # ecm on one steady rate: measured with its dynamics held absent, not fitted anyway
    ecm = dl.models.get_family("ecm")
    held = Battery(CellParameters(ecm.defaults()), fit_currents_A=(3.0,), model="ecm",
                   extra={"fit_plateau_ratio": 0.35, "fixed": dict(ecm.steady_fixed)})
    assert one_rate_class(held) == "ecm / sloped / no temperature"
    freed = replace(held, extra={"fit_plateau_ratio": 0.35, "fixed": {}})
    assert one_rate_class(freed) is None


def test_measured_law_sets_the_one_rate_model_error():
    with one_rate_table_override(TABLE):
        assert model_error_sd(SLOPED_LOGGED, 3.0) == pytest.approx(0.004)
        assert model_error_sd(SLOPED_LOGGED, 12.0) == pytest.approx(0.004 + 0.01 * math.log(4))
        assert model_error_sd(SLOPED_LOGGED, 0.75) == pytest.approx(0.004 + 0.02 * math.log(4))
        info = model_error_info(SLOPED_LOGGED, 4.0)    # side unknown: the wider growth
        assert info["relative_sd"] == pytest.approx(0.004 + 0.02 * math.log(4))
        assert info["measured_cells"] == 3 and "3 other cells" in info["label"]
        assert info["dof"] == 2                      # Student's t: the cells less one
        # a side never measured takes the other's growth
        flat = replace(SLOPED_LOGGED, extra={"fit_plateau_ratio": 0.05})
        assert model_error_sd(flat, 0.75) == pytest.approx(0.005 + 0.05 * math.log(4))
        # a class measured on fewer than three cells, or not held at all: the documented prior
        one_cell = replace(SLOPED_LOGGED, extra={"fit_plateau_ratio": 0.35})
        assert model_error_sd(one_cell, 3.0) == pytest.approx(PRIOR_RELATIVE_SD)
        unknown = replace(SLOPED_LOGGED, model="ecm",
                          parameters=CellParameters(dl.models.get_family("ecm").defaults()))
        assert model_error_sd(unknown, 3.0) == pytest.approx(PRIOR_RELATIVE_SD)


def test_packaged_table_narrows_sloped_curves_with_temperature_and_not_flat_ones():
    table = one_rate_table()
    laws = table["one_rate"]
    logged = laws["shepherd-thermal / sloped / temperature"]
    assert logged["base"] >= 0.005 and logged["up"] > 0 and len(logged["cells"]) >= 4
    # the evidence: a curved discharge with a logged temperature extrapolates better than a
    # flat plateau without one (the documented prior was 1.5 % growing by 2 x 1.5 % per ln r)
    flat = laws["shepherd-thermal / flat / no temperature"]
    assert logged["up"] < flat["up"]
    assert logged["base"] + logged["up"] * math.log(4) < 0.015 * (1 + 2 * math.log(4))
    for entry in table["two_rate"].values():
        assert 0 < entry["sd"] < 0.05 and entry["dof"] >= 1


def test_next_test_names_the_run_and_the_narrower_interval():
    with one_rate_table_override(TABLE):
        sd_now = model_error_sd(SLOPED_LOGGED, 12.0)
        now = half_width_pct(sd_now, dof=2)
        advice = next_test(SLOPED_LOGGED, 12.0, now)
        assert advice["current_A"] == pytest.approx(12.0)
        assert advice["half_width_pct_after"] == pytest.approx(
            100 * math.sinh(2.306004 * 0.006), rel=1e-5)        # Student t, 8 dof
        assert advice["half_width_pct_after"] < advice["half_width_pct_now"] == now
        assert "12 A" in advice["text"]
        # at a fitted current, or when it would hardly narrow: no advice
        assert next_test(SLOPED_LOGGED, 3.0, now) is None
        assert next_test(SLOPED_LOGGED, 12.0, 1.05 * advice["half_width_pct_after"]) is None
        # a pack: the advice speaks of the pack current
        pack = replace(SLOPED_LOGGED, strings_parallel=2)
        assert next_test(pack, 12.0, now)["current_A"] == pytest.approx(24.0)
        # the fit's own advice: one more run at 4x the fitted current
        fitted = fit_next_test(SLOPED_LOGGED)
        assert fitted["current_A"] == pytest.approx(12.0)
        assert "4x the fitted current" in fitted["text"]
    # a multi-rate fit keeps its held-out error at the new run's current
    multi = replace(SLOPED_LOGGED, fit_currents_A=(0.3, 3.0), extra={
        "model_error": {"relative_sd": 0.01, "source": "held-out", "dof": 6}})
    now = half_width_pct(model_error_sd(multi, 12.0), dof=6)
    advice = next_test(multi, 12.0, now)
    assert advice["half_width_pct_after"] == pytest.approx(half_width_pct(0.01, dof=6))
    assert fit_next_test(multi) is None


@pytest.fixture(scope="module")
def one_rate_fit(bundled_data):
    d = dl.read(bundled_data / "Q30_S001_1C.csv", columns=SAMSUNG)
    return dl.fit(d, bootstrap=10)


def test_predict_and_fit_give_the_next_test(one_rate_fit, tmp_path, capsys):
    fit = one_rate_fit
    assert fit.model == "shepherd-dynamic"
    doc = fit.to_dict()["next_test"]
    assert doc["current_A"] == pytest.approx(4 * fit.fit_currents_A[0])
    assert "next test" in fit.report()
    out = fit.predict(current=12.0, cutoff=2.5).to_dict()
    advice = out["next_test"]
    assert set(advice) >= {"current_A", "half_width_pct_now", "half_width_pct_after"}
    lo, hi = out["interval95"]["time_to_cutoff_s"]
    assert advice["half_width_pct_now"] == pytest.approx(
        100 * (hi - lo) / 2 / out["time_to_cutoff_s"])
    assert advice["half_width_pct_after"] < advice["half_width_pct_now"]
    assert advice["current_A"] == pytest.approx(12.0, rel=0.01)
    # at the fitted current nothing would narrow it
    assert "next_test" not in fit.predict(current=fit.fit_currents_A[0], cutoff=2.5).to_dict()
    # the command line: text and JSON
    path = tmp_path / "cell.json"
    fit.save(path)
    for args in ([str(path), "--current", "12", "--cutoff", "2.5"],
                 [str(path), "--current", "12", "--cutoff", "2.5", "--json"]):
        with pytest.raises(SystemExit) as exc:
            cli_main(["predict", *args])
        assert exc.value.code in (0, None)
    text = capsys.readouterr().out
    assert "next test: one more run at 12 A" in text
    doc = json.loads(text[text.index("{"):])
    assert doc["next_test"]["half_width_pct_after"] < doc["next_test"]["half_width_pct_now"]
