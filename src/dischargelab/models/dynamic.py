"""``shepherd-dynamic``: eq. (6) with Tremblay's filtered current, temperature and heat.

Per cell, discharge current ``i`` > 0, discharged charge ``q`` [Ah], cell
temperature ``T`` [degC], as ``shepherd-thermal`` except that the polarisation
term reads a lowpass-filtered current ``i*`` [1]_ and its resistance at full
charge is a parameter of its own, ``Rp``::

    i*' = (i - i*) / tau                                  [A]
    V   = E0 + dE0_dT (T - T_ref) - R f(T) i
          - f(T) [Rp + K (C(T)/(C(T) - q) - 1)] i*
          - K f(T) C(T)/(C(T) - q) q + A exp(-B q)

Tremblay's eq. is ``Rp = K`` (``K C/(C - q) (i* + q)``; battery files of version 1).

At a constant current ``i* = i`` once the load has lasted a few ``tau``, so a
constant-current curve is eq. (6) with the polarisation resistance ``Rp`` at full
charge; after a load step only the series resistance ``R`` appears at once, and the
polarisation builds up over ``tau``, as a cell's voltage does after a step (charge
transfer and diffusion). That is what eq. (6) cannot do: with ``i* = i`` the whole
polarisation appears with the step, so a fit to a slow drain from rest, whose load
step shows only the series resistance, gives the polarisation that builds over the
following minute to the curve shape (E0, A, K) and a flight at a higher current sags
less in the model than in the pack. With the filtered current the load step pins
``R`` and the curve's end pins ``K``.

Why ``Rp`` of its own: Tremblay ties the polarisation at full charge to the knee's
``K``. Measured cells build 0.3-2 times their series resistance over the first
minutes after a step whatever their knee says (:func:`load_step`, ``R`` and ``Rp``:
Samsung 30Q 32-36 and 9-17 mOhm, Enertech pouch 35 and 16, a Neware-logged cell 27 and
23, PyBaMM NMC 38 and 22 at 0.5C, PyBaMM LiFePO4 72-80 and 100-150), where the knee's
``K`` gives 5-18 mOhm. With the tie, what ``K`` is short of goes to the curve's shape
(``A exp(-B q)`` falling over the first minutes), which does not grow with the current:
a one-rate model then sags too little at a higher current (virtual cells up to 0.7 points more
optimistic than eq. 6 with ``R`` left free), and a discharge of a Neware-logged cell
from a partial charge was missed by +15.7 % (+5.7 % with ``Rp``). On one rate ``R`` and
``Rp`` are both read from the load step (:func:`load_step`), ``K`` from the knee.

``tau`` [s] is held at :data:`POLARISATION_TAU_S` (measured on load steps of real
cells, see its comment) unless the data vary their current (a flight log, a pulse
test) or hold several rates, which can show it; ``Rp`` is then fitted too.

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

#: The load step is read only when the first load sample comes within this time of the
#: load start [s] (a logger that starts later has missed the step).
STEP_WINDOW_S = 5.0

#: A curve whose current varies by this coefficient of variation or more shows the time
#: constant (a flight, pulses); a resistor drain (its current falling with the voltage by
#: about a quarter over the run) does not.
VARYING_CV = 0.25

#: The load step's transient is read over this time after the load start [s]: from the
#: seconds after the step (a tester's current ramp, the fastest polarisation) to four
#: ``tau``, or up to ten ``tau`` when that holds fewer than :data:`TRANSIENT_SAMPLES`
#: samples (a sparse log, or a long one thinned for the fit: three coefficients against
#: the ADC's noise; a C/10 drain at 0.3 A reads 3 mOhm per mV).
TRANSIENT_S = (2.0, 4 * POLARISATION_TAU_S, 10 * POLARISATION_TAU_S)

#: The samples the transient's window holds when the log allows (see :data:`TRANSIENT_S`).
TRANSIENT_SAMPLES = 24

#: Bounds of the filtered current's time constant [s] when it is fitted.
TAU_BOUNDS_S = (1.0, 600.0)


class ShepherdDynamic(ShepherdThermal):
    """Eq. (6) with Tremblay's filtered current in the polarisation term, its resistance
    at full charge ``Rp`` of its own, Arrhenius R, Rp and K, linear E0(T) and C(T), and a
    lumped thermal state."""

    name = "shepherd-dynamic"
    #: At several constant rates the filtered current equals the current after the first
    #: minute of each run: the fit is shepherd-thermal's, which ``auto`` already compares.
    several_rates_candidate = False
    version = 2
    title = ("modified Shepherd with Tremblay's filtered current, temperature and a lumped "
             "thermal model")
    description = ("eq. 6 whose polarisation (Rp + K (C/(C-q) - 1)) i* reads the current "
                   "filtered over tau (Tremblay 2009): after a load step only R appears at "
                   "once, the polarisation Rp builds up; on one rate R and Rp are read from "
                   "the load step; temperature and self-heating as shepherd-thermal.")
    headline = ShepherdThermal.headline + ("Rp_ohm", "tau_s")
    parameters = ShepherdThermal.parameters + (
        Parameter("tau_s", "s", *TAU_BOUNDS_S, POLARISATION_TAU_S, False,
                  "time constant of the polarisation's filtered current",
                  limit_note="the polarisation's time constant sits at the edge of its range"),
        Parameter("Rp_ohm", "ohm", 0.0, 2.0, 0.0, True,
                  "polarisation resistance at full charge (builds over tau after a step)",
                  limit_note="no polarisation builds after a load step at full charge"),
    )
    #: Files of version 1 lack ``Rp_ohm``: Tremblay's polarisation resistance at full
    #: charge is ``K`` (the same random variable, so its covariance is K's).
    upgrades = {1: {"Rp_ohm": "K_V_per_Ah"}}
    states = (State("charge_Ah", "Ah", "charge"), State("i_f_A", "A", "lowpass", tau="tau_s"),
              State("temperature_C", "degC", "thermal"))

    # ---- physics ---------------------------------------------------------------------
    def voltage(self, p, state, current_A):
        return self._voltage(p, state["charge_Ah"], current_A, state["i_f_A"],
                             state["temperature_C"], p["Rp_ohm"])

    # ---- fitting ------------------------------------------------------------------------
    def fit_voltage(self, p, data: Samples):
        i_f, _ = filtered_samples(data, p["tau_s"])
        return self._voltage(p, data.charge, data.current, i_f, data.temperature, p["Rp_ohm"])

    def jacobian(self, p, data: Samples, names=None):
        names = self.names if names is None else tuple(names)
        if not names:
            return np.empty((data.charge.size, 0))
        i_f, s_f = filtered_samples(data, p["tau_s"])
        columns = self._columns(p, data, i_f, p["Rp_ohm"])
        _, f, _, gain, _ = self._terms(p, data.charge, data.temperature)
        r_pol = p["Rp_ohm"] + p["K_V_per_Ah"] * (gain - 1.0)
        columns["tau_s"] = lambda: -f * r_pol * s_f
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
            step = load_step(data, fixed.get("beta_K", BETA_PRIOR_K))
            if step is None:  # nothing shows the build: the polarisation comes with R
                fixed["Rp_ohm"] = 0.0
            else:  # R is left to the fit (to E0) where no rest sample shows it
                r_ohm, fixed["Rp_ohm"] = step
                if r_ohm is not None:
                    fixed["R_ohm"] = r_ohm
        return fixed

    def fit_notes(self, data: Samples, fixed: dict) -> list[str]:
        notes = []
        if fixed.get("tau_s") == POLARISATION_TAU_S and not varying_current(data):
            notes.append(f"tau_s held at {POLARISATION_TAU_S:g} s (the time constant with "
                         "which measured cells' polarisation builds after a load step): one "
                         "constant current cannot show it")
        step = load_step(data, fixed.get("beta_K", BETA_PRIOR_K))
        if step is not None and step[0] is None and fixed.get("Rp_ohm") == step[1]:
            notes.append(f"Rp_ohm = {1000 * step[1]:.4g} mOhm from the polarisation building "
                         "over the first minutes of the load (no rest sample before it: the "
                         "series resistance cannot be told from E0)")
        elif step is not None and step[0] is not None and step[1] is None \
                and fixed.get("R_ohm") == step[0]:
            notes.append(f"R_ohm = {1000 * step[0]:.4g} mOhm from the load step (the voltage "
                         "drop over the current at the step): the one thing in one constant "
                         "current that tells the resistance from E0")
        elif step is not None and step[0] is not None and step[1] is not None \
                and fixed.get("R_ohm") == step[0]:
            notes.append(f"R_ohm = {1000 * step[0]:.4g} mOhm and Rp_ohm = {1000 * step[1]:.4g} "
                         "mOhm from the load step (the voltage drop over the current in the "
                         "first minutes, read as R + Rp (1 - exp(-t/tau)) plus the open-circuit "
                         "voltage's slope): the one thing in one constant current that tells "
                         "the resistances from E0")
        elif fixed.get("Rp_ohm") == 0.0 and not varying_current(data):
            notes.append("Rp_ohm held at 0 (no load step from rest: nothing shows the "
                         "polarisation build; R carries it)")
        return notes


def load_step(data: Samples, beta_K: float) -> tuple[float | None, float] | None:
    """Series and polarisation resistance [ohm] shown by the load step of one-rate data,
    read at the reference temperature (Arrhenius ``beta_K``); the means over the curves
    that have a rest sample and a load step. ``(None, Rp)`` when no curve has a rest
    sample: the polarisation building over the first minutes still shows ``Rp``, but
    nothing separates ``R`` from ``E0``. None without a load step, or when the step is not
    a drop.

    The apparent resistance ``r(t) = (V_rest - V(t)) / i`` over :data:`TRANSIENT_S` is
    fitted (linear least squares) as ``R + Rp (1 - exp(-t/tau)) + s t`` with ``tau`` at
    :data:`POLARISATION_TAU_S` and ``s t`` the open-circuit voltage falling with the
    charge: the model's own response to a step at full charge. ``R`` is thus the drop
    at the step instant extrapolated back from the seconds after it: the ohmic drop and
    whatever builds within a few seconds (charge transfer, double layer, the first
    seconds of diffusion: on a Neware-logged cell at 3 A the drop grows from 18 to
    30 mOhm within 5 s), which a 30 s lowpass cannot follow and a logger sampling every
    few seconds does not resolve. With fewer than four samples in that window ``R`` is
    the first load sample's (within :data:`STEP_WINDOW_S` of the load start) and ``Rp``
    0. A slow drain shows nothing else that separates ``R`` and ``Rp`` from ``E0`` (one
    current), and a fit left to choose gives the step to the curve shape where eq. (6)
    misfits the open-circuit voltage (``R`` at 0 on a LiPo pack's slow drain).

    Without a rest sample (a logger started with the load on) the voltage itself is fitted
    as ``c - f i Rp (1 - exp(-t/tau)) - s t``, its time counted from the first load
    sample: the build's curvature gives ``Rp``, while ``c`` holds ``E0 - R i`` (a log that
    starts after the build has passed reads ``Rp`` near 0).
    """
    rested = [k for k in range(data.n_curves) if np.any((data.curve == k) & data.is_rest)]
    r_s, rp_s = [], []
    for k in rested or range(data.n_curves):
        mine = data.curve == k
        rest = np.flatnonzero(mine & data.is_rest)
        load = np.flatnonzero(mine & ~data.is_rest)
        if load.size < 2:
            continue
        on = load[data.current[load] >= 0.5 * np.median(data.current[load])]
        t = data.time[on]
        if t.size == 0 or t[0] > STEP_WINDOW_S:
            continue
        f = arrhenius(data.temperature[on], beta_K)
        w = _transient_window(t)
        if rest.size:
            r = (data.voltage[rest[0]] - data.voltage[on]) / (f * data.current[on])
            if np.count_nonzero(w) >= 4:
                (r0, rp, _), *_ = np.linalg.lstsq(_transient_basis(t[w], 1.0), r[w],
                                                  rcond=None)
            else:
                r0, rp = r[0], 0.0
            r_s.append(float(r0))
        elif np.count_nonzero(w) >= 4:
            load_A = f[w] * data.current[on][w]
            (_, rp, _), *_ = np.linalg.lstsq(_transient_basis(t[w], -load_A),
                                             data.voltage[on][w], rcond=None)
        else:
            continue
        rp_s.append(max(float(rp), 0.0))
    upper = ShepherdThermal().parameter("R_ohm").upper
    if not rested:
        return None if not rp_s else (None, float(min(np.mean(rp_s), upper)))
    if not r_s or not np.mean(r_s) > 0:
        return None
    return float(min(np.mean(r_s), upper)), float(min(np.mean(rp_s), upper))


def _transient_window(t: np.ndarray) -> np.ndarray:
    """Samples of the load step's transient (:data:`TRANSIENT_S`), ``t`` [s] from the load
    start."""
    after = np.flatnonzero(t >= TRANSIENT_S[0])
    end = TRANSIENT_S[1]
    if after.size:
        end = max(end, min(t[after[min(TRANSIENT_SAMPLES, after.size) - 1]], TRANSIENT_S[2]))
    return (t >= TRANSIENT_S[0]) & (t <= end)


def _transient_basis(t: np.ndarray, scale) -> np.ndarray:
    """Columns of the step's response: a constant, ``scale (1 - exp(-t/tau))`` (the
    polarisation building) and ``t`` (the open-circuit voltage's slope)."""
    return np.column_stack([np.ones(t.size), -scale * np.expm1(-t / POLARISATION_TAU_S), t])


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
