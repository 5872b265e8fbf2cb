"""The plain fit the speed benchmarks compare against: scipy's bounded ``least_squares``
(trf, 2-point numeric Jacobian) of one family on the same stacked samples, free
parameters, bounds and start (the family's ``guess``) as :func:`dischargelab.fit.fit_battery`,
with none of its extras (multi-start, covariance, held-out errors, uncertainty)."""

import numpy as np
from scipy.optimize import least_squares

from dischargelab.fit import _resolve_e0_r, _spec, _stack
from dischargelab.models import get_family

#: Residual [V] where a model is undefined (q >= C): least_squares needs finite residuals;
#: the fitter never evaluates there.
UNDEFINED_RESIDUAL_V = 10.0


def plain_least_squares(curves, family_name, *, held=None, max_samples=None):
    """Fit ``family_name`` to ``curves`` with ``held`` parameters fixed.

    ``max_samples``: per curve (None: the fit's own thinning). Returns (RMSE [V] over the
    load samples, function evaluations, free parameters, stacked samples)."""
    family = get_family(family_name)
    extra = {} if max_samples is None else {"max_samples": max_samples}
    stack = _stack(list(curves), 1, 1, True, "equal", **extra)
    fixed, bounds = _spec(family, held, None, stack, False)
    _resolve_e0_r(family, stack, fixed, [], [])
    free = [n for n in family.names if n not in fixed]
    lo = np.array([bounds[n][0] for n in free])
    hi = np.array([bounds[n][1] for n in free])
    guess = family.guess(stack)
    span = hi - lo
    x0 = np.clip([guess[n] for n in free], lo + 1e-9 * span, hi - 1e-9 * span)
    base = {n: fixed.get(n, guess.get(n)) for n in family.names}
    w = stack.weight

    def resid(x):
        p = dict(base)
        p.update(zip(free, x))
        with np.errstate(invalid="ignore", over="ignore"):
            r = (family.fit_voltage(p, stack) - stack.voltage) * w
        return np.where(np.isfinite(r), r, UNDEFINED_RESIDUAL_V)

    sol = least_squares(resid, x0, jac="2-point", bounds=(lo, hi), method="trf",
                        x_scale="jac")
    load = ~stack.is_rest
    r = resid(sol.x) / w
    return (float(np.sqrt(np.mean(r[load] ** 2))), int(sol.nfev), len(free),
            int(stack.voltage.size))
