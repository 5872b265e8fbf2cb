"""Every model family: analytic Jacobian against finite differences, file round trip,
engine invariants."""

import numpy as np
import pytest

from dischargelab import engine
from dischargelab.model import Battery, CellParameters
from dischargelab.models import FAMILIES, Samples, get_family


def _samples(with_temperature=True):
    """Two curves (0.5 A and 3 A) with a rest point each and a rising temperature."""
    parts = []
    for k, (cur, n) in enumerate(((0.5, 60), (3.0, 40))):
        t = np.linspace(5.0, 3600.0 * 1.8 / cur, n)
        q = cur * t / 3600.0
        i = np.full(n, cur) * (1 + 0.1 * np.sin(t / 50.0))
        temp = 25.0 + 15.0 * (q / q.max()) * cur / 3.0 if with_temperature else np.full(n, 25.0)
        parts.append(dict(t=np.r_[t, 0.0], q=np.r_[q, 0.0], i=np.r_[i, 0.0],
                          T=np.r_[temp, 25.0], rest=np.r_[np.zeros(n, bool), True],
                          curve=np.full(n + 1, k)))
    cat = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    data = Samples(voltage=np.zeros(cat["t"].size), current=cat["i"], charge=cat["q"],
                   time=cat["t"], temperature=cat["T"], weight=np.ones(cat["t"].size),
                   curve=cat["curve"], is_rest=cat["rest"], n_curves=2,
                   has_temperature=with_temperature)
    ref = dict(E0_V=3.7, R_ohm=0.02, K_V_per_Ah=0.01, A_V=0.3, B_per_Ah=5.0, C_Ah=2.0)
    data.voltage = get_family("shepherd").fit_voltage(ref, data)
    return data


def _point(family, data):
    p = family.guess(data)
    p.update({n: v for n, v in family.fit_fixed(data).items() if n not in p})
    for par in family.parameters:  # move every value off zero so each column is exercised
        if p[par.name] == 0.0 and not par.linear:
            p[par.name] = 0.3 * par.upper if par.upper > 0 else 0.3 * par.lower
    if "C_Ah" in p:
        p["C_Ah"] = 2.0
    if "beta_K" in p:
        p["beta_K"] = 2500.0
    if "Rp_ohm" in p:  # linear, and the time constant's column reads it
        p["Rp_ohm"] = 0.012
    return p


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_jacobian_matches_central_differences(name):
    fam = get_family(name)
    data = _samples()
    p = _point(fam, data)
    jac = fam.jacobian(p, data)
    assert jac.shape == (data.current.size, len(fam.names))
    for k, n in enumerate(fam.names):
        h = 1e-6 * max(abs(p[n]), 1e-3)
        up, dn = dict(p), dict(p)
        up[n] += h
        dn[n] -= h
        data._cache.clear()
        fd = (fam.fit_voltage(up, data) - fam.fit_voltage(dn, data)) / (2 * h)
        data._cache.clear()
        np.testing.assert_allclose(jac[:, k], fd, rtol=2e-5, atol=1e-8 * max(1, np.abs(fd).max()),
                                   err_msg=f"{name}: d V / d {n}")


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_linear_parameters_are_linear(name):
    fam = get_family(name)
    data = _samples()
    p = _point(fam, data)
    for n in fam.linear_names:
        a, b = dict(p), dict(p)
        a[n], b[n] = p[n] + 0.1, p[n] + 0.2
        mid = dict(p, **{n: p[n] + 0.15})
        np.testing.assert_allclose(fam.fit_voltage(mid, data),
                                   0.5 * (fam.fit_voltage(a, data) + fam.fit_voltage(b, data)),
                                   atol=1e-12, err_msg=f"{name}: {n} is not linear")


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_battery_file_round_trip_records_family_and_version(name, tmp_path):
    fam = get_family(name)
    p = CellParameters(_point(fam, _samples()))
    bat = Battery(p, cells_series=3, model=name, covariance=np.eye(len(fam.names)) * 1e-6)
    path = bat.save(tmp_path / "cell.json")
    back = Battery.from_dict(__import__("json").loads(path.read_text()))
    assert back.model == name and back.to_dict()["model_version"] == fam.version
    assert back.to_dict()["written_by"].startswith("dischargelab ")
    for n in fam.names:
        assert back.parameters[n] == pytest.approx(p[n])


def test_old_battery_files_load_as_shepherd():
    data = {"model": "tremblay", "parameters": {"E0_V": 3.7, "R_ohm": 0.02, "K_V_per_Ah": 0.01,
                                                "A_V": 0.1, "B_per_Ah": 5.0, "C_Ah": 2.0}}
    assert Battery.from_dict(data).model == "shepherd"


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_engine_time_to_cutoff_shrinks_with_current(name):
    fam = get_family(name)
    p = _point(fam, _samples())
    p["C_Ah"] = 2.0
    times = []
    for current in (0.5, 2.0, 6.0):
        res = engine.run(fam, p, [engine.Step("current", current)], cutoff_pack_V=2.8)
        assert res.ended_by[0] == "cutoff"
        times.append(res.end_s[0])
    assert times[0] > times[1] > times[2] > 0


def test_engine_shepherd_matches_closed_form_root():
    from scipy.optimize import brentq

    fam = get_family("shepherd")
    p = dict(E0_V=3.7, R_ohm=0.02, K_V_per_Ah=0.01, A_V=0.1, B_per_Ah=5.0, C_Ah=2.0)
    res = engine.run(fam, p, [engine.Step("current", 3.0)], cutoff_pack_V=3.0)
    q = brentq(lambda q: fam.voltage(p, {"charge_Ah": q}, 3.0) - 3.0, 0, 2 - 1e-12, xtol=1e-14)
    assert res.end_s[0] == pytest.approx(q * 3600 / 3.0, rel=1e-9)


def test_engine_vectorised_draws_match_single_runs():
    fam = get_family("shepherd-thermal")
    base = _point(fam, _samples())
    draws = dict(base, R_ohm=np.array([0.01, 0.03, 0.05]))
    steps = [engine.Step("current", 4.0, 60.0), engine.Step("power", 9.0)]
    res = engine.run(fam, draws, steps, cutoff_pack_V=3.0)
    for k, r in enumerate((0.01, 0.03, 0.05)):
        one = engine.run(fam, dict(base, R_ohm=r), steps, cutoff_pack_V=3.0)
        assert res.end_s[k] == pytest.approx(one.end_s[0], rel=1e-9)


def test_engine_never_hangs_when_the_cutoff_is_unreachable():
    from dischargelab.errors import SimulationError

    fam = get_family("shepherd")
    p = dict(E0_V=3.7, R_ohm=0.0, K_V_per_Ah=0.0, A_V=0.0, B_per_Ah=5.0, C_Ah=1e4)
    with pytest.raises(SimulationError, match="did not end"):
        engine.run(fam, p, [engine.Step("current", 1e-6)], cutoff_pack_V=3.0,
                   max_engine_steps=1000)


def test_thermal_engine_heats_more_at_high_rate():
    fam = get_family("shepherd-thermal")
    p = _point(fam, _samples())
    p.update(Cth_J_per_K=45.0, Rth_K_per_W=20.0, C_Ah=2.0)
    peaks = [engine.run(fam, p, [engine.Step("current", c)], cutoff_pack_V=2.8,
                        ambient_C=25.0).peak_temperature_C[0] for c in (0.5, 4.0)]
    assert 25.0 < peaks[0] < peaks[1]


def test_thermal_engine_is_stable_for_a_short_thermal_time_constant():
    """R_th C_th = 2 s against steps of about a minute: the temperature follows
    T_amb + Q R_th without overshoot (an explicit scheme oscillates and diverges)."""
    from dischargelab.model import PRESETS

    fam = get_family("shepherd-thermal")
    p = fam.defaults()
    p.update(PRESETS["hacker-4100-4s-lifepo4"].parameters.as_dict())
    p.update(Cth_J_per_K=1.0, Rth_K_per_W=2.0)
    res = engine.run(fam, p, [engine.Step("current", 20.0)], cutoff_pack_V=2.5, ambient_C=25.0,
                     steps_per_discharge=100, record=True)
    temp = np.asarray(res.series["temperature_C"])
    assert np.all(np.isfinite(temp)) and np.all(temp >= 25.0 - 1e-9)
    assert np.all(np.diff(temp) >= -0.2)           # no oscillation
    assert temp.max() < 25.0 + 2.0 * 20.0 * 1.0     # Q R_th with at most 1 V overpotential
