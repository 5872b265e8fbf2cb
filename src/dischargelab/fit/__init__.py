"""Fit any model family to one or several measured discharges.

Method
------
Bounded nonlinear least squares on the cell voltage, eq. (8) of the paper,
solved by **variable projection** over the family's parameters: for fixed
nonlinear parameters (for ``shepherd`` B, C and, in paper mode, a current scale)
the voltage is linear in the family's linear parameters (E0, R, K, A), which are
eliminated by a linear least-squares solve (bounded where a bound binds); the
reduced problem is solved by projected Levenberg-Marquardt with Kaufman's
analytic Jacobian from a small grid of starts. A final bounded ``least_squares``
polish over all free parameters (analytic Jacobian) enforces the bounds on the
linear parameters when the projected solution violates them. Families with a
thermal state get their heat capacity and thermal resistance from the logged
cell temperature afterwards (a linear regression, see
:func:`dischargelab.models.base.fit_lumped_thermal`).

Identifiability (see DESIGN.md and :mod:`dischargelab.identifiability`):

* one constant current: only ``E0 - R*i`` is determined. A rest sample before
  the load (i = 0) separates them: the fit then uses it as a data point
  (``V_rest = E0 + A``, so the load step gives ``R + K``). Without a rest sample,
  a given E0 or a second current, R is fixed to 0 and a warning says so.
* with the current free (paper mode) R, K, B, C and i scale together: the fit
  still runs (to reproduce the paper) and the warning says the curve alone
  cannot determine C.

Standard errors come from the Jacobian at the optimum, ``cov = s^2 (J^T J)^-1``,
with ``s^2`` the residual variance inflated for the serial correlation of the
residuals (AR(1) effective sample size ``n (1 - rho) / (1 + rho)``): residuals of
a model fit to a smooth curve are far from independent, and ignoring that would
give error bars that are too small.

References
----------
.. [1] paper eq. (6), (8), section 3.4 (see ``../shared/paper``).
.. [2] G. Golub, V. Pereyra, "Separable nonlinear least squares: the variable
   projection method and its applications", Inverse Problems 19 (2003) R1.
.. [3] L. Kaufman, "A variable projection method for solving separable nonlinear
   least squares problems", BIT 15 (1975) 49-57.
"""


from __future__ import annotations

import time

from ..discharge import Curve
from ..errors import FitError
from .auto import AUTO, choose_model, fit_auto, fit_with_model_error, selection_score
from .family import guess_parameters
from .heldout import HELD_OUT_TAIL, held_out_error, rate_capacity_error
from .problem import CURRENT_SCALE, _resolve_e0_r, _spec, _stack  # noqa: F401  (benchmarks)
from .result import FitResult


def fit_battery(curves, *, cells_series: int = 1, strings_parallel: int = 1,
                fixed: dict | None = None, bounds: dict | None = None,
                guess: dict | None = None, paper_mode: bool = False, use_rest: bool = True,
                weighting: str = "equal", n_best: int | None = None, bootstrap: int = 0,
                seed: int = 0, model="shepherd", model_error: bool = True,
                progress=None, bootstrap_method: str = "linearised",
                cooling: str | None = "still-air", chemistry: str | None = None) -> FitResult:
    """Fit a model family to one or several discharges with shared parameters.

    Parameters
    ----------
    curves : Curve or sequence of Curve
        Pack-level measurements, each with its own (logged or commanded) current.
    cells_series, strings_parallel : int
        Pack configuration; the fit is per cell.
    fixed : dict, optional
        ``{name: value}`` parameters held fixed (e.g. ``{"E0_V": 4.1}``).
    bounds : dict, optional
        ``{name: (lower, upper)}`` overriding the family's default bounds.
    guess : dict, optional
        Starting values of nonlinear parameters tried before the built-in grid.
    paper_mode : bool
        Reproduce the paper's setup (``shepherd`` only): E0 must be fixed, the
        current is scaled by a fitted factor together with R, K, A, B, C. The
        result is degenerate by construction and says so.
    use_rest : bool
        Use each curve's rest voltage (i = 0) as a data point.
    weighting : {"equal", "samples"}
        "equal" gives each curve the same total weight whatever its length.
    n_best : int, optional
        Number of best grid starts refined by the variable-projection solver
        (default: the family's ``n_best``).
    bootstrap : int
        Number of moving-block bootstrap refits stored with the result (0 = none);
        they carry the parameter uncertainty into simulations.
    seed : int
        Seed of the bootstrap.
    cooling : {"still-air", "airflow"} or None
        How the cells are cooled, for the thermal prior of a thermal family fitted
        without a logged temperature (:func:`dischargelab.fit.family.fit_self_heating`): still air
        (a bench) or the airflow of flight; None holds the cell at the ambient.
    chemistry : {"lipo", "li-ion", "lifepo4"}, optional
        For that thermal prior; default from the full cell's voltage.
    bootstrap_method : {"linearised", "refit"}
        ``"linearised"``: each replica is the optimum plus one Gauss-Newton step
        (exact for the linear parameters, the delta method for the others; about
        the cost of one residual evaluation per replica); ``"refit"``: every replica
        refitted (about one fit each).
    model : str or Family
        Model family name (``dischargelab.models.FAMILIES``), or ``"auto"``: pick
        by evidence (see :func:`choose_model`).
    model_error : bool
        With two or more curves at different currents, estimate the model's own
        error from leave-one-curve-out predictions (stored in ``model_error``).
    progress : callable, optional
        Called as ``progress(done, total)`` during the bootstrap refits.

    Returns
    -------
    FitResult

    Raises
    ------
    FitError
        Bad fixed/bounds specification or no convergence.
    """
    t_start = time.perf_counter()
    curves = [curves] if isinstance(curves, Curve) else list(curves)
    if not curves:
        raise FitError("no discharge curves to fit")
    if model == AUTO:
        return fit_auto(curves, t_start, cells_series=cells_series,
                         strings_parallel=strings_parallel, fixed=fixed, bounds=bounds,
                         guess=guess, paper_mode=paper_mode, use_rest=use_rest,
                         weighting=weighting, n_best=n_best, bootstrap=bootstrap, seed=seed,
                         progress=progress, bootstrap_method=bootstrap_method,
                         cooling=cooling, chemistry=chemistry)
    res = fit_with_model_error(curves, cells_series=cells_series,
                               strings_parallel=strings_parallel, fixed=fixed, bounds=bounds,
                               guess=guess, paper_mode=paper_mode, use_rest=use_rest,
                               weighting=weighting, n_best=n_best, bootstrap=bootstrap,
                               seed=seed, model=model, model_error=model_error,
                               progress=progress, bootstrap_method=bootstrap_method,
                               cooling=cooling, chemistry=chemistry)
    res.elapsed_s = time.perf_counter() - t_start
    return res


__all__ = ["Curve", "FitResult", "fit_battery", "guess_parameters", "held_out_error",
           "choose_model", "selection_score", "rate_capacity_error", "AUTO", "CURRENT_SCALE",
           "HELD_OUT_TAIL"]
