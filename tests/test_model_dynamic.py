"""``shepherd-dynamic``: eq. 6 with Tremblay's filtered current, the series resistance of a
one-rate fit from its load step, and ``auto`` on one rate."""

from dataclasses import replace

import numpy as np
import pytest

import dischargelab as dl
from dischargelab import engine
from dischargelab.discharge import Discharge
from dischargelab.fit.auto import ONE_RATE_FAMILY, choose_model
from dischargelab.models import get_family
from dischargelab.models.base import lowpass_samples
from dischargelab.models.dynamic import POLARISATION_TAU_S

DYN = get_family("shepherd-dynamic")
CELL = dict(E0_V=3.75, R_ohm=0.03, K_V_per_Ah=0.015, Rp_ohm=0.015, A_V=0.35, B_per_Ah=2.0, C_Ah=3.1,
            dE0_dT_V_per_K=0.0, dC_dT_Ah_per_K=0.0, beta_K=2500.0, Cth_J_per_K=1e6,
            Rth_K_per_W=25.0, tau_s=POLARISATION_TAU_S)


def _step_response(current_A, seconds):
    res = engine.run(DYN, CELL, [engine.Step("current", current_A, seconds)],
                     cutoff_pack_V=2.5, record=True, max_dt_s=0.5)
    return res.series


def test_after_a_load_step_only_the_series_resistance_appears_at_once():
    i = 6.0
    s = _step_response(i, 300.0)
    t, v = s["time_s"], s["voltage_V"]
    full = CELL["E0_V"] + CELL["A_V"]  # rest voltage at q = 0
    # the first sample: the series drop only (the polarisation K C/(C-q) i* is still 0)
    assert full - v[0] == pytest.approx(CELL["R_ohm"] * i, rel=1e-6)
    # the polarisation builds with tau: after 5 tau the voltage is eq. 6's at that charge
    late = np.flatnonzero(t >= 5 * POLARISATION_TAU_S)[0]
    thermal = get_family("shepherd-thermal")
    steady = thermal.voltage(CELL, {"charge_Ah": s["charge_Ah"][late], "temperature_C": 25.0},
                             i)
    pol = CELL["K_V_per_Ah"] * i * CELL["C_Ah"] / (CELL["C_Ah"] - s["charge_Ah"][late])
    assert v[late] == pytest.approx(steady, abs=0.01 * pol)
    # the drop over the first minute is mostly the polarisation building, not the charge
    assert 0.5 * CELL["K_V_per_Ah"] * i < v[0] - v[np.flatnonzero(t >= 60)[0]]


def _slow_drain(current_A=0.6, noise_V=0.0005, seed=1, dt_s=2.0):
    """A constant-current drain written by the family itself, from rest, 25 degC."""
    t = np.arange(0.0, 0.95 * CELL["C_Ah"] * 3600 / current_A, dt_s)
    i = np.full(t.size, current_A)
    q = current_A * t / 3600.0
    first = np.zeros(t.size, bool)
    first[0] = True
    i_f, _ = lowpass_samples(t, i, first, POLARISATION_TAU_S)
    v = DYN.voltage(CELL, {"charge_Ah": q, "i_f_A": i_f, "temperature_C": 25.0}, i)
    v = v + np.random.default_rng(seed).normal(0.0, noise_V, t.size)
    return Discharge(t, v, i, None, CELL["E0_V"] + CELL["A_V"], "slow drain")


def test_a_version_1_battery_file_loads_with_tremblays_polarisation_resistance():
    """Version 1 had no Rp_ohm: its polarisation resistance at full charge was K."""
    from dischargelab.model import Battery

    names = [n for n in DYN.names if n != "Rp_ohm"]
    cov = np.diag(np.arange(1.0, len(names) + 1)) * 1e-8
    old = {"model": "shepherd-dynamic", "model_version": 1,
           "parameters": {n: CELL[n] for n in names},
           "covariance": {"names": names, "matrix": cov.tolist()}}
    bat = Battery.from_dict(old)
    assert bat.parameters["Rp_ohm"] == CELL["K_V_per_Ah"]
    k, rp = DYN.names.index("K_V_per_Ah"), DYN.names.index("Rp_ohm")
    assert bat.covariance[rp, rp] == bat.covariance[k, k] == bat.covariance[k, rp]
    state = {"charge_Ah": np.array([0.0, 1.5, 2.9]), "i_f_A": np.array([0.0, 2.0, 3.0]),
             "temperature_C": 30.0}
    tremblay = get_family("shepherd-thermal")._voltage(
        CELL, state["charge_Ah"], 3.0, state["i_f_A"], 30.0)  # K C/(C-q) i*
    np.testing.assert_allclose(DYN.voltage(dict(bat.parameters.items()), state, 3.0), tremblay,
                               rtol=1e-12)
    with pytest.raises(dl.DataError):
        Battery.from_dict(dict(old, model_version=2))  # a version-2 file needs Rp_ohm
    for bad in (names[:-1] + ["X_ohm"], names[:-1] + [names[0]], "E0_V"):
        with pytest.raises(dl.DataError, match="covariance"):
            Battery.from_dict(dict(old, covariance={"names": bad, "matrix": cov.tolist()}))


def test_one_rate_fit_takes_the_series_resistance_from_the_load_step():
    res = dl.fit(_slow_drain(), model="shepherd-dynamic", bootstrap=0, cooling=None)
    p = res.parameters
    # the first load sample carries R i and the ADC noise of one sample
    assert p["R_ohm"] == pytest.approx(CELL["R_ohm"], abs=2 * 0.0005 * np.sqrt(2) / 0.6)
    assert p["tau_s"] == POLARISATION_TAU_S
    assert "R_ohm" in res.fixed and "tau_s" in res.fixed
    assert any("from the load step" in n for n in res.notes)
    assert any("tau_s held at" in n for n in res.notes)
    assert p["K_V_per_Ah"] == pytest.approx(CELL["K_V_per_Ah"], rel=0.1)
    # a faster constant current from this slow fit: the cell's own time to 3.0 V within 1 %
    fast = 3.0
    truth = engine.run(DYN, CELL, [engine.Step("current", fast)], cutoff_pack_V=3.0).end_s[0]
    pred = res.battery.predict(current=fast, cutoff=3.0, ambient=25.0).to_dict()
    assert pred["time_to_cutoff_s"] == pytest.approx(truth, rel=0.01)


def test_without_a_rest_sample_the_resistance_is_not_made_up():
    drain = replace(_slow_drain(), rest_voltage_V=None)
    res = dl.fit(drain, model="shepherd-dynamic", bootstrap=0, cooling=None)
    assert not any("from the load step" in n for n in res.notes)
    assert any("E0 and R are not separable" in w for w in res.warnings)
    assert res.parameters["R_ohm"] == 0.0


def test_without_a_rest_sample_the_polarisation_build_still_shows_rp():
    """A logger started with the load on: the build over the first minutes (its curvature
    against the open-circuit voltage's slope) still gives Rp; R goes to E0."""
    bare = replace(_slow_drain(), rest_voltage_V=None)
    res = dl.fit(bare, model="shepherd-dynamic", bootstrap=0, cooling=None)
    assert res.parameters["Rp_ohm"] == pytest.approx(CELL["Rp_ohm"], rel=0.15)
    assert "Rp_ohm" in res.fixed and res.fixed["R_ohm"] == 0.0
    assert any("from the polarisation building" in n for n in res.notes)
    # a log that starts after the build has passed shows none of it
    late = _slow_drain()
    skip = late.time_s >= 10 * POLARISATION_TAU_S
    cut = Discharge(late.time_s[skip] - late.time_s[skip][0], late.voltage_V[skip],
                    late.current_A[skip], None, None, "late start")
    res = dl.fit(cut, model="shepherd-dynamic", bootstrap=0, cooling=None)
    assert res.parameters["Rp_ohm"] < 0.1 * CELL["Rp_ohm"]


def test_a_varying_current_fits_the_time_constant():
    t = np.arange(0.0, 3000.0, 1.0)
    i = np.where((t // 120) % 2 == 0, 3.0, 0.8)
    q = np.r_[0.0, np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t))] / 3600.0
    first = np.zeros(t.size, bool)
    first[0] = True
    truth = dict(CELL, tau_s=45.0)
    i_f, _ = lowpass_samples(t, i, first, truth["tau_s"])
    v = DYN.voltage(truth, {"charge_Ah": q, "i_f_A": i_f, "temperature_C": 25.0}, i)
    d = Discharge(t, v, i, None, CELL["E0_V"] + CELL["A_V"], "pulses")
    res = dl.fit(d, model="shepherd-dynamic", bootstrap=0, cooling=None,
                 fixed={"A_V": CELL["A_V"], "B_per_Ah": CELL["B_per_Ah"],
                        "C_Ah": CELL["C_Ah"]})
    assert "tau_s" not in res.fixed
    assert res.parameters["tau_s"] == pytest.approx(45.0, rel=0.02)
    assert res.parameters["R_ohm"] == pytest.approx(CELL["R_ohm"], rel=0.02)


def test_auto_fits_one_rate_with_the_dynamic_family_and_several_without_it():
    slow = _slow_drain().to_curve()
    names, why = choose_model([slow])
    assert names == [ONE_RATE_FAMILY] == ["shepherd-dynamic"] and "load step" in why
    assert choose_model([slow], cooling=None)[0] == ["shepherd"]
    fast = _slow_drain(current_A=2.0).to_curve()
    assert "shepherd-dynamic" not in choose_model([slow, fast])[0]


def test_samsung_slow_drain_load_step_is_the_cells_series_resistance(shared_data):
    """Samsung 30Q C/10 (real): the load step gives 30-40 mOhm, the series resistance
    the 1C-4C runs show at their own load steps (29-33 mOhm); the fit left free put
    10 mOhm there and the rest into the curve shape."""
    cols = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
    d = dl.read(shared_data / "samsung30q_S001" / "Q30_S001_C10.csv", columns=cols)
    res = dl.fit(replace(d, temperature_C=None), model="shepherd-dynamic", bootstrap=0,
                 cooling=None)
    assert 0.030 < res.parameters["R_ohm"] < 0.040


def test_a_flight_far_from_the_knee_falls_back_to_shepherd_thermal(shared_data):
    # a DJI M100 flight ends at 40-50 % charge: with R and Rp held at the load step, nothing
    # in it sets shepherd-dynamic's K and C (K sits at 0; C ran to its bound, 94 Ah, when Rp
    # was tied to K); auto keeps the earlier one-rate family and says why
    path = sorted((shared_data / "dji_m100_flights").glob("derived_battery_*.csv"))[1]
    res = dl.fit(dl.read(path), cells=6, bootstrap=0)
    assert res.model == "shepherd-thermal"
    assert "does not reach the end-of-discharge knee" in res.notes[0]
    delivered = float(res.curves[0].charge_Ah[-1])
    assert float(res.parameters["C_Ah"]) < 1.5 * delivered
