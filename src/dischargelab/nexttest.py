"""The next test: the one extra run that would narrow an interval most, and to about what.

From the same error model as the intervals (:mod:`dischargelab.uncertainty`): today's
model error grows with the extrapolation ratio; after one more run at the predicted
current the prediction lies at a fitted current, where a multi-rate fit keeps its
held-out error and a one-rate fit takes the model error measured on two-rate fits of its
class (:mod:`dischargelab.onerate`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from .onerate import one_rate_class, one_rate_table
from .uncertainty import half_width_pct, model_error_base, model_error_info

if TYPE_CHECKING:
    from .model import Battery

#: One more run is advised (:func:`next_test`) when it would narrow the interval's
#: half-width to less than this fraction of today's.
NEXT_TEST_NARROWING = 0.8


#: The extrapolation a one-rate fit's advice speaks of (:func:`fit_next_test`): x4 the
#: fitted current, the far end of the x2-x4 range a bench test is mostly asked about.
ADVICE_RATIO = 4.0


def fit_next_test(battery: Battery, level: float = 0.95) -> dict | None:
    """The next test after a one-rate fit: one more run at :data:`ADVICE_RATIO` times the
    fitted current, and how it would narrow the model error of predictions up to there
    (:func:`next_test`); None for a fit to several rates (each prediction says what would
    narrow its own interval) or when it would not narrow."""
    fitted = [abs(x) for x in battery.fit_currents_A if x]
    if len(fitted) != 1:
        return None
    info = model_error_info(battery, ADVICE_RATIO, "up")
    now = half_width_pct(info["relative_sd"], level, info["dof"])
    advice = next_test(battery, ADVICE_RATIO * fitted[0], now, level)
    if advice is None:
        return None
    pack = advice["current_A"]
    source = (f"one-rate errors measured on {info['measured_cells']} other cells"
              if info.get("measured_cells") else "the documented one-rate prior")
    advice["text"] = (f"next test: fitted on one rate, a prediction at {ADVICE_RATIO:g}x the "
                      f"fitted current ({pack:.3g} A) carries a model error of "
                      f"+-{now:.1f} % ({source}); one more run at {pack:.3g} A would narrow "
                      f"every prediction up to that current to about "
                      f"+-{advice['half_width_pct_after']:.1f} %")
    return advice


def after_one_more_run(battery: Battery) -> tuple[float, float | None] | None:
    """``(sd, dof)`` of the model error at the current of one more run, once that run is
    fitted with the others: a multi-rate fit keeps its held-out error (the run is then a
    fitted current); a one-rate fit becomes a two-rate fit, whose model error is the
    median measured on two-rate fits of its class (``benchmarks/one_rate_errors.py``).
    None when it cannot be told (no measured two-rate fits of the class)."""
    base, source, dof = model_error_base(battery)
    if source == "held-out":
        return base, dof
    cls = one_rate_class(battery)
    entry = (one_rate_table().get("two_rate") or {}).get(cls) if cls else None
    if not isinstance(entry, dict) or not isinstance(entry.get("sd"), (int, float)):
        return None
    dof = entry.get("dof")
    return float(entry["sd"]), float(dof) if isinstance(dof, (int, float)) and dof >= 1 \
        else None


def next_test(battery: Battery, cell_current_A: float, half_width_pct_now: float,
              level: float = 0.95) -> dict | None:
    """The one extra run that would narrow a prediction's interval most, and to about what.

    A run at the predicted current itself: the prediction then lies at a fitted current,
    where the model error is that of the fit inside its currents
    (:func:`after_one_more_run`) and no longer grows with the extrapolation ratio. The
    parameter draws' share is left out of the "after" figure (it is small at a fitted
    current).

    Parameters
    ----------
    battery : Battery
    cell_current_A : float
        Cell current of the prediction [A].
    half_width_pct_now : float
        Half-width of today's interval [% of the prediction].
    level : float

    Returns
    -------
    dict or None
        ``current_A`` (pack current of the run [A]), ``cell_current_A``,
        ``half_width_pct_now``, ``half_width_pct_after`` and ``text``; None when one more
        run would not narrow the interval to :data:`NEXT_TEST_NARROWING` of today's.
    """
    after = after_one_more_run(battery)
    if after is None or not math.isfinite(half_width_pct_now) or not cell_current_A:
        return None
    fitted = [abs(x) for x in battery.fit_currents_A if x]
    if any(abs(abs(cell_current_A) / f - 1.0) < 0.05 for f in fitted):
        return None  # the prediction is already at a fitted current
    width = half_width_pct(after[0], level, after[1])
    if not width < NEXT_TEST_NARROWING * half_width_pct_now:
        return None
    pack = abs(float(cell_current_A)) * battery.strings_parallel
    return {"current_A": pack, "cell_current_A": abs(float(cell_current_A)),
            "half_width_pct_now": float(half_width_pct_now), "half_width_pct_after": width,
            "text": f"next test: one more run at {pack:.3g} A would narrow this interval "
                    f"from +-{half_width_pct_now:.1f} % to about +-{width:.1f} % (the "
                    f"model error measured on fits with one more rate)"}


__all__ = ["ADVICE_RATIO", "NEXT_TEST_NARROWING", "fit_next_test", "next_test",
           "after_one_more_run"]
