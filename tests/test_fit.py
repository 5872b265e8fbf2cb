"""Fitting: synthetic round trips, identifiability, real data, bad input."""

import numpy as np
import pytest

from dischargelab.errors import DataError, FitError
from dischargelab.fit import Curve, fit_battery, guess_parameters
from dischargelab.identifiability import analyse
from dischargelab.model import PARAMETER_NAMES
from synthetic import TRUE, measurement_noise, synthetic_curve


@pytest.mark.parametrize("start", [{"B_per_Ah": 0.3, "C_Ah": 3.5}, {"B_per_Ah": 20.0,
                                                                    "C_Ah": 3.02}])
def test_round_trip_two_currents_two_starts(start):
    curves = [synthetic_curve(1.5, seed=1), synthetic_curve(6.0, seed=2)]
    res = fit_battery(curves, guess=start, n_best=1)
    true = TRUE.as_dict()
    for name in PARAMETER_NAMES:
        est, err = res.parameters.as_dict()[name], res.stderr[name]
        assert abs(est - true[name]) < 4 * err + 1e-9, (name, est, true[name], err)
        assert est == pytest.approx(true[name], rel=0.05), name
    assert res.rmse_V < 1.5 * measurement_noise()
    assert not res.warnings


def test_round_trip_one_current_with_rest_sample():
    res = fit_battery(synthetic_curve(3.0, seed=3))
    assert any("rest voltage" in n for n in res.notes)
    assert res.parameters.C_Ah == pytest.approx(TRUE.C_Ah, rel=0.01)
    assert res.parameters.R_ohm == pytest.approx(TRUE.R_ohm, abs=0.01)
    assert res.rmse_V < 1.5 * measurement_noise()


def test_pack_scaling_in_fit():
    curve = synthetic_curve(3.0, cells=4, ke=4.38, noise_V=0.01, seed=4)
    res = fit_battery(curve, cells_series=4)
    assert res.parameters.C_Ah == pytest.approx(TRUE.C_Ah, rel=0.01)
    assert res.rmse_V * 4 < 1.5 * measurement_noise(0.01, 4.38)
    assert res.battery.cells_series == 4


def test_one_current_without_rest_resolves_e0_r_with_warning():
    res = fit_battery(synthetic_curve(3.0, rest=False, seed=5))
    assert res.fixed["R_ohm"] == 0.0
    assert any("E0 and R are not separable" in w for w in res.warnings)
    # E0 absorbs R*i: E0_fit = E0 - R*i
    assert res.parameters.E0_V == pytest.approx(TRUE.E0_V - TRUE.R_ohm * 3.0, abs=0.02)


def test_given_e0_determines_r():
    res = fit_battery(synthetic_curve(3.0, rest=False, seed=6), fixed={"E0_V": TRUE.E0_V})
    assert res.parameters.R_ohm == pytest.approx(TRUE.R_ohm, abs=0.01)
    assert not any("not separable" in w for w in res.warnings)


def test_jacobian_detects_e0_r_collinearity():
    c = synthetic_curve(3.0, rest=False)
    from dischargelab.fit import _stack
    from dischargelab.models import get_family

    data = _stack([c], 1, 1, use_rest=False, weighting="samples", max_samples=c.time_s.size)
    jac = get_family("shepherd").jacobian(TRUE, data, PARAMETER_NAMES[:4])  # E0, R, K, A free
    ident = analyse(jac, list(PARAMETER_NAMES[:4]), TRUE.as_dict(),
                    dict.fromkeys(PARAMETER_NAMES, (-10, 10)))
    assert ident.singular_values[-1] < 1e-6
    assert any("E0 and R" in w and "--e0" in w for w in ident.warnings)
    assert {"E0_V", "R_ohm"} <= set(ident.directions[0])


def test_paper_mode_reports_scaling_degeneracy():
    curve = synthetic_curve(3.0, rest=False, seed=7)
    res = fit_battery(curve, fixed={"E0_V": TRUE.E0_V}, paper_mode=True)
    assert any("scale together" in w and "NOT a validation" in w for w in res.warnings)
    # the exact degeneracy shows as a vanishing singular value
    assert res.identifiability.singular_values[-1] < 1e-6
    assert res.to_dict()["paper_mode"]["current_scale"] == pytest.approx(res.current_scale)
    # the fitted curve itself is still good
    assert res.rmse_V < 1.5 * measurement_noise()


def test_paper_mode_needs_e0():
    with pytest.raises(FitError, match="E0_V"):
        fit_battery(synthetic_curve(3.0), paper_mode=True)


def test_fixed_parameter_is_honoured_and_bound_reported():
    res = fit_battery(synthetic_curve(3.0, seed=8), fixed={"K_V_per_Ah": 0.008},
                      bounds={"A_V": (0.0, 0.2)})
    assert res.parameters.K_V_per_Ah == 0.008 and res.stderr["K_V_per_Ah"] == 0
    assert res.parameters.A_V == pytest.approx(0.2)
    assert any("A_V" in w and "upper bound" in w for w in res.warnings)


def test_fit_never_evaluates_beyond_capacity():
    c = synthetic_curve(3.0, seed=9)
    res = fit_battery(c)
    assert res.parameters.C_Ah > c.charge_Ah.max()
    with pytest.raises(FitError, match="q >= C"):
        fit_battery(c, fixed={"C_Ah": float(c.charge_Ah.max()) * 0.99})


def test_guess_from_data():
    g = guess_parameters(synthetic_curve(3.0, seed=10))
    assert g["C_Ah"] == pytest.approx(TRUE.C_Ah, rel=0.1)
    assert g["R_ohm"] == pytest.approx(TRUE.R_ohm + TRUE.K_V_per_Ah, abs=0.01)


def test_result_json_keys_and_battery():
    res = fit_battery(synthetic_curve(3.0, seed=11))
    doc = res.to_dict()
    for key in ("model", "cells_series", "parameters", "stderr", "rmse_V", "n_samples",
                "warnings"):
        assert key in doc
    assert set(doc["parameters"]) == set(PARAMETER_NAMES) == set(doc["stderr"])
    bat = res.battery
    assert bat.covariance.shape == (6, 6)
    assert bat.fit_currents_A == pytest.approx((3.0,))
    assert "E0_V" in res.report()


@pytest.mark.parametrize("mutate, message", [
    (lambda t, v, i: (t, np.where(np.arange(v.size) == 50, np.nan, v), i), "NaN"),
    (lambda t, v, i: (np.where(np.arange(t.size) == 30, 5.0, t), v, i), "does not increase"),
    (lambda t, v, i: (t, v, -i), "not a discharge"),
    (lambda t, v, i: (t[:5], v[:5], i[:5]), "at least 10"),
])
def test_bad_curves(mutate, message):
    c = synthetic_curve(3.0)
    t, v, i = mutate(c.time_s.copy(), c.voltage_V.copy(), c.current_A.copy())
    with pytest.raises(DataError, match=message):
        Curve(t, v, i)


def test_unknown_parameter_name():
    with pytest.raises(FitError, match="unknown parameter 'R'"):
        fit_battery(synthetic_curve(3.0), fixed={"R": 0.01})


def test_real_samsung_fits_and_predicts(shared_data):
    from dischargelab.io import read_discharge
    from dischargelab.simulate import simulate_current

    spec = {"time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4}
    curves = []
    for rate in ("C10", "1C", "4C"):
        data, meta = read_discharge(shared_data / "samsung30q_S001" / f"Q30_S001_{rate}.csv",
                                    columns=spec)
        curves.append(Curve.from_frame(data, meta, name=rate))
    res = fit_battery(curves)
    assert res.rmse_V < 0.1
    for curve in curves:
        v = curve.voltage_V
        k = np.flatnonzero(v <= 2.5)
        t_meas = curve.time_s[k[0]] if k.size else curve.time_s[-1]
        pred = simulate_current(res.battery, curve.mean_current_A, cutoff_cell_V=2.5)
        assert abs(pred.time_to_cutoff_s / t_meas - 1) < 0.03, curve.name


def test_capacity_at_the_delivered_charge_is_physics_not_a_bound_problem():
    """A capacity at its lower bound (the charge the runs delivered) is a note that says a
    cell cannot hold less than it delivered, not "widen the bound"; a capacity bound the
    user set stays a bound problem."""
    from dischargelab.fit.family import _physical_limits
    from dischargelab.identifiability import Identifiability
    from dischargelab.models import get_family

    def ident():
        return Identifiability(["C_Ah"], np.ones(1), [], np.eye(1), [],
                               [("C_Ah", "lower", 2.9403)],
                               ["C_Ah = 2.9403 sits at its lower bound 2.9403: the bound, not "
                                "the data, sets it. Widen it with --bound C_Ah=LOW:HIGH"])

    notes, found = [], ident()
    _physical_limits(get_family("shepherd"), found, notes, delivered_Ah=2.9400)
    assert not found.warnings and found.at_bounds   # auto still prefers a pinned capacity
    assert "cannot hold less than it delivered" in notes[0] and "widen" not in notes[0].lower()
    notes, found = [], ident()
    _physical_limits(get_family("shepherd"), found, notes, delivered_Ah=2.0)   # user's bound
    assert found.at_bounds and "Widen" in found.warnings[0] and not notes


def test_adiabatic_log_gets_a_thermal_resistance_limit_warning():
    """A logged temperature that never shows cooling (its rise speeds up while the heat
    stays about constant: no loss to the ambient could explain it) fits the thermal
    resistance at its limit, and the fit says it is a limit, not a measurement."""
    import dischargelab as dl

    curve = synthetic_curve(6.0, dt_s=5.0)
    charge = np.concatenate([[0.0], np.cumsum(np.diff(curve.time_s) * curve.current_A[1:])])
    heated = dl.Discharge(curve.time_s, curve.voltage_V, curve.current_A,
                          25.0 + 12.0 * (charge / charge[-1]) ** 2, name="adiabatic")
    res = dl.fit(heated, model="shepherd-thermal", bootstrap=0)
    assert res.thermal["Rth_K_per_W"] >= 1e4
    assert any("limit, not a measurement" in w for w in res.warnings)
