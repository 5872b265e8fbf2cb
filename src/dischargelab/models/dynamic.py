"""``shepherd-dynamic``: eq. (6) with Tremblay's filtered current, temperature and heat.

Per cell, discharge current ``i`` > 0, discharged charge ``q`` [Ah], cell
temperature ``T`` [degC], as ``shepherd-thermal`` except that the polarisation
term reads a lowpass-filtered current ``i*`` [1]_::

    i*' = (i - i*) / tau                                  [A]
    V   = E0 + dE0_dT (T - T_ref) - R f(T) i
          - K f(T) C(T)/(C(T) - q) (i* + q) + A exp(-B q)

At a constant current ``i* = i`` once the load has lasted a few ``tau``, so a
constant-current curve is eq. (6) again; after a load step only the series
resistance ``R`` appears at once, and the polarisation resistance
``K C/(C - q)`` builds up over ``tau``, as a cell's voltage does after a step
(charge transfer and diffusion). That is what eq. (6) cannot do: with ``i* = i``
the whole polarisation appears with the step, so a fit to a slow drain from rest,
whose load step shows only the series resistance, gives the polarisation that
builds over the following minute to the curve shape (E0, A, K) and a flight at a
higher current sags less in the model than in the pack. With the filtered current
the load step pins ``R`` and the curve's end pins ``K``: the split between
resistance and curve shape is set by physics, not by the fit's freedom.

``tau`` [s] is held at :data:`POLARISATION_TAU_S` (measured on load steps of real
cells, see its comment) unless the data vary their current (a flight log, a pulse
test) or hold several rates, which can show it.

References
----------
.. [1] O. Tremblay, L.-A. Dessaint, "Experimental validation of a battery dynamic
   model for EV applications", World Electric Vehicle Journal 3 (2009) 289-298
   (the filtered current ``i*`` in the polarisation term).
.. [2] MathWorks, Simscape Electrical "Battery" block ("battery response time",
   the filter time constant of ``i*``; temperature effects).
"""

from __future__ import annotations

import numpy as np

from .base import Parameter, Samples, State, arrhenius, filtered_samples
from .thermal import BETA_PRIOR_K, ShepherdThermal

#: Time constant of the filtered current [s] for data that cannot show it (one steady
#: current): the polarisation of measured cells after a load step builds with this time
#: constant (see ``benchmarks/slow_to_fast.py``, load steps of the Samsung 30Q).
POLARISATION_TAU_S = 30.0

#: The load step is read from the first load sample within this time of the load start [s]
#: (a logger that starts later has already seen the polarisation build).
STEP_WINDOW_S = 5.0

#: A curve whose current varies by this coefficient of variation or more shows the time
#: constant (a flight, pulses); a resistor drain (its current falling with the voltage by
#: about a quarter over the run) does not.
VARYING_CV = 0.25

#: Bounds of the filtered current's time constant [s] when it is fitted.
TAU_BOUNDS_S = (1.0, 600.0)


class ShepherdDynamic(ShepherdThermal):
    """Eq. (6) with Tremblay's filtered current in the polarisation term, Arrhenius R and
    K, linear E0(T) and C(T), and a lumped thermal state."""

    name = "shepherd-dynamic"
    #: At several constant rates the filtered current equals the current after the first
    #: minute of each run: the fit is shepherd-thermal's, which ``auto`` already compares.
    several_rates_candidate = False
    version = 1
    title = ("modified Shepherd with Tremblay's filtered current, temperature and a lumped "
             "thermal model")
    description = ("eq. 6 whose polarisation K C/(C-q) i* reads the current filtered over tau "
                   "(Tremblay 2009): after a load step only R appears at once, the "
                   "polarisation builds up; temperature and self-heating as shepherd-thermal.")
    headline = ShepherdThermal.headline + ("tau_s",)
    parameters = ShepherdThermal.parameters + (
        Parameter("tau_s", "s", *TAU_BOUNDS_S, POLARISATION_TAU_S, False,
                  "time constant of the polarisation's filtered current",
                  limit_note="the polarisation's time constant sits at the edge of its range"),
    )
    states = (State("charge_Ah", "Ah", "charge"), State("i_f_A", "A", "lowpass", tau="tau_s"),
              State("temperature_C", "degC", "thermal"))

    # ---- physics ---------------------------------------------------------------------
    def voltage(self, p, state, current_A):
        return self._voltage(p, state["charge_Ah"], current_A, state["i_f_A"],
                             state["temperature_C"])

    # ---- fitting ------------------------------------------------------------------------
    def fit_voltage(self, p, data: Samples):
        i_f, _ = filtered_samples(data, p["tau_s"])
        return self._voltage(p, data.charge, data.current, i_f, data.temperature)

    def jacobian(self, p, data: Samples, names=None):
        names = self.names if names is None else tuple(names)
        if not names:
            return np.empty((data.charge.size, 0))
        i_f, s_f = filtered_samples(data, p["tau_s"])
        columns = self._columns(p, data, i_f)
        _, f, _, gain, _ = self._terms(p, data.charge, data.temperature)
        columns["tau_s"] = lambda: -p["K_V_per_Ah"] * f * gain * s_f
        return np.column_stack([columns[n]() for n in names])

    def start_grid(self, data: Samples, free_nonlinear):
        grid = super().start_grid(data, free_nonlinear)
        grid["tau_s"] = [POLARISATION_TAU_S]
        return grid

    def fit_bounds(self, data: Samples):
        return dict(super().fit_bounds(data), tau_s=TAU_BOUNDS_S)

    def fit_fixed(self, data: Samples):
        fixed = super().fit_fixed(data)
        if not varying_current(data):
            fixed["tau_s"] = POLARISATION_TAU_S
            r_step = step_resistance(data, fixed.get("beta_K", BETA_PRIOR_K))
            if r_step is not None:
                fixed["R_ohm"] = r_step
        return fixed

    def fit_notes(self, data: Samples, fixed: dict) -> list[str]:
        notes = []
        if fixed.get("tau_s") == POLARISATION_TAU_S and not varying_current(data):
            notes.append(f"tau_s held at {POLARISATION_TAU_S:g} s (the time constant with "
                         "which measured cells' polarisation builds after a load step): one "
                         "constant current cannot show it")
        r_step = step_resistance(data, fixed.get("beta_K", BETA_PRIOR_K))
        if r_step is not None and fixed.get("R_ohm") == r_step:
            notes.append(f"R_ohm = {1000 * r_step:.4g} mOhm from the load step (rest voltage "
                         "less the first load sample, over the current): the one thing in "
                         "one constant current that tells the series resistance from E0; "
                         "the polarisation K C/(C-q) i* builds after the step")
        return notes


def step_resistance(data: Samples, beta_K: float) -> float | None:
    """Series resistance [ohm] shown by the load step of one-rate data: the rest voltage
    less the first load sample, over its current, read at the reference temperature
    (Arrhenius ``beta_K``); the mean over the curves that have both. None without a rest
    sample or a load step, or when the step is not a drop.

    The filtered current starts at 0 when the load does, so the first load sample
    carries ``R i`` only: the polarisation ``K C/(C-q) i*`` builds after it. A slow
    drain shows nothing else that separates ``R`` from ``E0`` (one current), and a fit
    left to choose gives the step to the curve shape where eq. (6) misfits the
    open-circuit voltage (``R`` at 0 on a LiPo pack's slow drain).
    """
    steps = []
    for k in range(data.n_curves):
        mine = data.curve == k
        rest = np.flatnonzero(mine & data.is_rest)
        load = np.flatnonzero(mine & ~data.is_rest)
        if rest.size == 0 or load.size < 2:
            continue
        i = data.current[load]
        first = load[np.argmax(i >= 0.5 * np.median(i))]
        if data.time[first] > STEP_WINDOW_S:
            continue
        f = float(arrhenius(data.temperature[first], beta_K))
        steps.append((data.voltage[rest[0]] - data.voltage[first]) / (f * data.current[first]))
    if not steps or not np.mean(steps) > 0:
        return None
    return float(min(np.mean(steps), ShepherdThermal().parameter("R_ohm").upper))


def varying_current(data: Samples) -> bool:
    """True when the load current of ``data`` can show a time constant: several curves at
    different rates, or a current that varies within a curve (coefficient of variation of
    its samples, pauses at zero included, at least :data:`VARYING_CV`)."""
    means, varies = [], False
    for k in range(data.n_curves):
        i = data.current[(data.curve == k) & ~data.is_rest]
        if i.size < 2 or not np.mean(i) > 0:
            continue
        means.append(float(np.mean(i)))
        varies |= bool(np.std(i) >= VARYING_CV * np.mean(i))
    return varies or (len(means) >= 2 and max(means) >= 1.2 * min(means))
