"""95 % intervals of fitted parameters: positive parameters stay positive."""

import numpy as np
import pytest

from dischargelab.fit import fit_battery
from dischargelab.fit.family import _interval95
from dischargelab.identifiability import UNDETERMINED_SPAN
from dischargelab.models import get_family
from synthetic import synthetic_curve


def test_log_interval_is_positive_and_matches_the_symmetric_one_when_narrow():
    lo, hi = _interval95(0.02, 0.03, 2.0, positive=True)      # symmetric: [-0.04, 0.08]
    assert 0 < lo < 0.02 < hi
    assert lo * hi == pytest.approx(0.02 ** 2)               # symmetric in ln(value)
    narrow = _interval95(3.0, 0.001, 2.0, positive=True)
    assert narrow == pytest.approx((2.998, 3.002), abs=1e-5)  # delta method: same when tight
    assert _interval95(-0.1, 0.3, 2.0, positive=False) == pytest.approx((-0.7, 0.5))


@pytest.mark.parametrize("model", ["shepherd", "ecm"])
def test_every_positive_parameter_interval_stays_positive(model):
    # one noisy curve without its rest sample: E0 and R are weakly determined
    curve = synthetic_curve(3.0, noise_V=0.01, seed=11)
    curve.rest_voltage_V = None
    res = fit_battery(curve, model=model)
    family = get_family(model)
    for p in family.parameters:
        low, high = res.ci95[p.name]
        if p.lower >= 0 and np.isfinite(low) and low != high:
            assert 0 <= low <= res.parameters[p.name] <= high, (p.name, low, high)
            assert low > 0 or res.parameters[p.name] == 0, (p.name, low, high)
    # an interval wider than the undetermined span is reported, never silently kept
    for p in family.parameters:
        low, high = res.ci95[p.name]
        if p.lower >= 0 and np.isfinite(low) and low > 0 and high / low > UNDETERMINED_SPAN \
                and not p.limit_note and p.name not in res.fixed:
            assert any(w.startswith(f"{p.name}'s 95 % interval") for w in res.warnings), p.name
