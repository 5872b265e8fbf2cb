"""``shepherd-thermal``: eq. (6) with temperature-dependent parameters and a lumped thermal state.

The temperature extension of Tremblay's model as used in the Simscape battery
block [2]_, per cell, with ``T`` the cell temperature [degC]::

    f(T)  = exp(beta (1/T - 1/T_ref))                  (Arrhenius, T in K)
    C(T)  = C + dC_dT (T - T_ref)
    V     = E0 + dE0_dT (T - T_ref) - eta_R
            - K f(T) C(T)/(C(T) - q) (i + q) + A exp(-B q)
    eta_R = b asinh(R f(T) i / b),  b = R I_ct T / T_ref   (R f(T) i when G_ct = 1/I_ct = 0)

coupled to a lumped thermal mass [3]_::

    C_th dT/dt = i (U - V) - (T - T_amb) / R_th

with ``U`` the voltage at zero current (heat = current x overpotential).
``T_ref`` is 25 degC. From one constant-current run ``beta`` is not identifiable
(the fit is flat over 1,500-9,000 K), so it is held at a prior of 2,500 K
(activation energy about 20 kJ/mol, shared by R and K) unless the fitted curves
span a wide temperature range; the temperature slopes of E0 and C are held at 0
unless curves at different ambient temperatures are fitted. The thermal
parameters come from a linear regression on the logged cell temperature
(:func:`~dischargelab.models.base.fit_lumped_thermal`).

The fast drop ``eta_R`` (the ohmic drop and the charge transfer of the first seconds)
is linear in the current, ``R f(T) i``, unless the fit holds two or more rates: then
its charge-transfer part may grow less than linearly, as a Butler-Volmer overpotential
``b asinh(R i / b)`` does [4]_ (linear with slope ``R`` at small current, logarithmic
at large). ``b = R I_ct`` per cell, ``I_ct`` = 2 i0 (twice the exchange current) at the
reference temperature, ``b`` growing with the absolute temperature as ``R_g T / (alpha
F)`` does; the fitted parameter is ``G_ct = 1 / I_ct`` [1/A] (0: linear, the model of
every one-rate fit and of battery files of version 1). The fast drop is read from the
load steps of the measured and PyBaMM cells falling with the current (virtual NMC 47
to 21 mOhm from 0.1C to 3C, LCO pouch 55 to 36, Samsung 30Q 35 to 31;
``benchmarks/step_polarisation.py``); one rate cannot tell it from the ohmic drop.

References
----------
.. [1] O. Tremblay, L.-A. Dessaint, World Electric Vehicle Journal 3 (2009).
.. [2] MathWorks, Simscape Electrical "Battery" block: temperature effects
   (E0, R, K Arrhenius; capacity linear in temperature).
.. [3] D. Bernardi, E. Pawlikowski, J. Newman, J. Electrochem. Soc. 132 (1985) 5-12.
.. [4] A. J. Bard, L. R. Faulkner, Electrochemical Methods, 2nd ed., Wiley (2001),
   eq. 3.4.11 (Butler-Volmer: ``i = 2 i0 sinh(alpha F eta / (R_g T))`` for a symmetric
   reaction, ``R_ct = R_g T / (alpha F 2 i0)`` its small-current slope).
"""

from __future__ import annotations

import numpy as np

from .base import (
    REFERENCE_TEMPERATURE_C,
    ZERO_CELSIUS_K,
    Family,
    Parameter,
    Samples,
    State,
    arrhenius,
    arrhenius_dbeta,
)
from .shepherd import C_UPPER_FACTOR, Shepherd, shepherd_terms

#: Prior Arrhenius coefficient of R and K [K] (E_a ~ 20 kJ/mol).
BETA_PRIOR_K = 2500.0

#: Fitted curves whose peak temperatures span at least this much [K] determine beta.
BETA_SPAN_K = 15.0

#: Curves whose ambient temperatures span at least this much [K] determine dE0/dT, dC/dT.
AMBIENT_SPAN_K = 8.0

#: Default heat capacity per Ah of capacity [J/(K Ah)] (an 18650 of 3 Ah is ~45 J/K).
HEAT_CAPACITY_PER_AH = 15.0

#: Default thermal resistance times capacity [K Ah / W] (a bare 18650 in still air ~25 K/W).
THERMAL_RESISTANCE_AH = 75.0


class ShepherdThermal(Family):
    """Eq. (6) with Arrhenius R and K, linear E0(T) and C(T), and a lumped thermal state."""

    name = "shepherd-thermal"
    needs_temperature = True  # without a logged temperature it is eq. 6 held at the ambient
    title = "modified Shepherd with temperature (Tremblay/Simscape) + lumped thermal model"
    description = ("eq. 6 with R, K Arrhenius in T, E0 and C linear in T, and a lumped thermal "
                   "state: predicts self-heating at high rate from a bench test.")
    headline = ("E0_V", "R_ohm", "K_V_per_Ah", "A_V", "B_per_Ah", "C_Ah", "beta_K")
    parameters = Shepherd.parameters[:4] + (
        Parameter("dE0_dT_V_per_K", "V/K", -0.01, 0.01, 0.0, True,
                  "temperature slope of E0", fit=False),
    ) + Shepherd.parameters[4:] + (
        Parameter("dC_dT_Ah_per_K", "Ah/K", -0.5, 0.5, 0.0, False,
                  "temperature slope of the capacity", fit=False),
        Parameter("beta_K", "K", 0.0, 12000.0, BETA_PRIOR_K, False,
                  "Arrhenius coefficient of R and K (E_a / R_gas)", fit=False),
        Parameter("Cth_J_per_K", "J/K", 0.1, 1e6, 45.0, False, "heat capacity", fit=False),
        Parameter("Rth_K_per_W", "K/W", 0.01, 1e4, 25.0, False,
                  "thermal resistance to ambient", fit=False),
        Parameter("G_ct_per_A", "1/A", 0.0, 1e4, 0.0, False,
                  "inverse charge-transfer current 1/(2 i0) of the fast drop (0: linear)",
                  limit_note="the fast drop grows linearly with the current"),
    )
    states = (State("charge_Ah", "Ah", "charge"), State("temperature_C", "degC", "thermal"))
    version = 2
    #: Files of version 1 have a fast drop linear in the current (``G_ct_per_A`` = 0,
    #: held: no covariance).
    upgrades = {1: {"G_ct_per_A": 0.0}}

    # ---- physics ---------------------------------------------------------------------
    def _terms(self, p, q, temperature):
        dt = np.asarray(temperature, dtype=float) - REFERENCE_TEMPERATURE_C
        f = arrhenius(temperature, p["beta_K"])
        cap = p["C_Ah"] + p["dC_dT_Ah_per_K"] * dt
        gain, denom = shepherd_terms(cap, q)
        return dt, f, cap, gain, denom

    def voltage(self, p, state, current_A):
        return self._voltage(p, state["charge_Ah"], current_A, current_A,
                             state["temperature_C"])

    def _voltage(self, p, q, i, i_pol, temperature, r_pol=None):
        """Eq. (6) with temperature [V per cell]: the series resistance carries the current
        ``i`` [A], the polarisation term the current ``i_pol`` [A] (``i`` itself here).

        The polarisation resistance is ``r_pol + K (C/(C - q) - 1)`` [ohm] (before
        Arrhenius): ``r_pol`` at full charge, growing towards the knee with ``K``;
        Tremblay's ``K C/(C - q)`` when ``r_pol`` is None (``r_pol = K``)."""
        q = np.asarray(q, dtype=float)
        i = np.asarray(i, dtype=float)
        dt, f, cap, gain, _ = self._terms(p, q, temperature)
        ok = q < cap
        gain = np.where(ok, gain, 0.0)
        k = p["K_V_per_Ah"]
        r = k * gain if r_pol is None else r_pol + k * (gain - 1.0)
        fast = fast_drop(p["R_ohm"] * f * i, p["G_ct_per_A"] * f * i, temperature)[0]
        v = (p["E0_V"] + p["dE0_dT_V_per_K"] * dt - fast
             - f * r * np.asarray(i_pol, dtype=float) - k * f * gain * q
             + p["A_V"] * np.exp(-p["B_per_Ah"] * q))
        return np.where(ok, v, -np.inf)

    def capacity_Ah(self, p, state):
        dt = np.asarray(state["temperature_C"], dtype=float) - REFERENCE_TEMPERATURE_C
        return p["C_Ah"] + p["dC_dT_Ah_per_K"] * dt

    # ---- fitting ------------------------------------------------------------------------
    def fit_voltage(self, p, data: Samples):
        return self.voltage(p, {"charge_Ah": data.charge, "temperature_C": data.temperature},
                            data.current)

    def jacobian(self, p, data: Samples, names=None):
        names = self.names if names is None else tuple(names)
        if not names:
            return np.empty((data.charge.size, 0))
        columns = self._columns(p, data, data.current)
        return np.column_stack([columns[n]() for n in names])

    def _columns(self, p, data: Samples, i_pol, r_pol=None) -> dict:
        """The Jacobian's columns (each computed when called), the polarisation term
        reading the current ``i_pol`` [A] (the current itself here) with the polarisation
        resistance of :meth:`_voltage` (``r_pol``: its value at full charge, a parameter
        ``Rp_ohm`` of its own; None: Tremblay's ``K C/(C - q)``)."""
        i, q, temp = data.current, data.charge, data.temperature
        dt, f, cap, gain, denom = self._terms(p, q, temp)
        pol = i_pol + q
        k = p["K_V_per_Ah"]
        expo = np.exp(-p["B_per_Ah"] * q)
        d_cap = k * f * pol * q / denom**2
        d_k = gain * pol if r_pol is None else gain * pol - i_pol
        r = k * gain if r_pol is None else r_pol + k * (gain - 1.0)
        zero = np.zeros_like(q)
        fast, shape, d_z, slope = fast_drop(p["R_ohm"] * f * i, p["G_ct_per_A"] * f * i, temp)
        columns = {
            "E0_V": lambda: np.ones_like(q),
            "R_ohm": lambda: -f * i * shape,
            "G_ct_per_A": lambda: -p["R_ohm"] * f * i * d_z * f * i * (
                REFERENCE_TEMPERATURE_C + ZERO_CELSIUS_K) / (temp + ZERO_CELSIUS_K),
            "K_V_per_Ah": lambda: -f * d_k,
            "Rp_ohm": lambda: -f * i_pol,
            "A_V": lambda: expo,
            "dE0_dT_V_per_K": lambda: dt,
            "B_per_Ah": lambda: -p["A_V"] * q * expo,
            "C_Ah": lambda: d_cap,
            "dC_dT_Ah_per_K": lambda: d_cap * dt,
            "beta_K": lambda: (-p["R_ohm"] * f * i * slope - f * r * i_pol
                               - k * f * gain * q) * arrhenius_dbeta(temp),
            "Cth_J_per_K": lambda: zero,
            "Rth_K_per_W": lambda: zero,
        }
        return columns

    def guess(self, data: Samples):
        out = Shepherd().guess(data)
        out.update({n: self.parameter(n).default for n in self.names if n not in out})
        return out

    def start_grid(self, data: Samples, free_nonlinear):
        grid = Shepherd().start_grid(data, free_nonlinear)
        grid["beta_K"] = [BETA_PRIOR_K]
        grid["dC_dT_Ah_per_K"] = [0.0]
        if "G_ct_per_A" in free_nonlinear:  # linear, and Tafel from the fastest rate on
            grid["G_ct_per_A"] = [0.0, 1.0 / max(curve_currents(data))]
        return grid

    def fit_bounds(self, data: Samples):
        """:func:`thermal_bounds`, and the fast drop's inverse charge-transfer current up
        to :data:`TAFEL_DEPTH` over the slowest fitted current."""
        return dict(thermal_bounds(data),
                    G_ct_per_A=(0.0, TAFEL_DEPTH / min(curve_currents(data) or [1.0])))

    def fit_fixed(self, data: Samples):
        fixed = thermal_fixed(data)
        if not rates_apart(data):
            fixed["G_ct_per_A"] = 0.0
        _, ambients = _curve_temperatures(data)
        if not data.has_temperature or np.ptp(ambients) < AMBIENT_SPAN_K:
            fixed["dE0_dT_V_per_K"] = 0.0
            fixed["dC_dT_Ah_per_K"] = 0.0
        return fixed


def fast_drop(x_V, y, temperature_C):
    """The fast drop [V] whose linear value is ``x_V`` = ``R f(T) i`` [V], as the
    Butler-Volmer overpotential ``b asinh(x / b)`` with ``b = x T / (y T_ref)``:
    ``x asinh(z) / z``, ``z = y T_ref / T`` (``y`` = ``G_ct f(T) i`` [-]).

    ``y`` = 0 is the linear drop ``x`` exactly. Returns the drop, its shape
    ``asinh(z) / z`` [-] (the drop over ``x``), ``d shape / dz`` [-] and
    ``d asinh(z) / dz`` = ``1 / sqrt(1 + z^2)`` [-] (the drop's derivative with respect
    to ``x`` at fixed ``b``). A charge current (``i`` < 0) gives the same shape, a
    negative drop.
    """
    t_k = np.asarray(temperature_C, dtype=float) + ZERO_CELSIUS_K
    z = np.asarray(y, dtype=float) * (REFERENCE_TEMPERATURE_C + ZERO_CELSIUS_K) / t_k
    small = np.abs(z) < 1e-3
    z_safe = np.where(small, 1.0, z)
    z2 = z * z
    slope = 1.0 / np.sqrt(1.0 + z2)
    shape = np.where(small, 1.0 - z2 / 6.0, np.arcsinh(z_safe) / z_safe)
    d_z = np.where(small, -z / 3.0 + 0.3 * z * z2,
                   (1.0 / np.sqrt(1.0 + z_safe**2) - np.arcsinh(z_safe) / z_safe) / z_safe)
    return np.asarray(x_V, dtype=float) * shape, shape, d_z, slope


def thermal_bounds(data: Samples) -> dict:
    """Data-dependent bounds shared by the thermal families: capacity above the
    discharged charge, Arrhenius coefficient 300-12,000 K."""
    lo_c = data.q_max * (1.0 + 1e-4)
    return {"C_Ah": (lo_c, max(data.q_max * C_UPPER_FACTOR, lo_c * 1.01)),
            "beta_K": (300.0, 12000.0)}


#: Largest ``G_ct i`` [-] fitted at the slowest rate: asinh(50)/50, a fast drop 8 % of
#: its linear value, is far into the logarithmic (Tafel) range.
TAFEL_DEPTH = 50.0


def curve_currents(data: Samples) -> list[float]:
    """Mean load current [A] of each fitted curve with a positive one."""
    out = []
    for k in range(data.n_curves):
        i = data.current[(data.curve == k) & ~data.is_rest]
        if i.size and np.mean(i) > 0:
            out.append(float(np.mean(i)))
    return out


def rates_apart(data: Samples) -> bool:
    """Two or more fitted curves whose mean currents differ by 20 % or more (as
    :func:`dischargelab.fit.family.several_rates`): what tells a fast drop that grows
    less than linearly with the current from a linear one."""
    currents = curve_currents(data)
    return len(currents) >= 2 and max(currents) >= 1.2 * min(currents)


def thermal_fixed(data: Samples) -> dict:
    """Held parameters shared by the thermal families: the thermal mass and resistance
    (fitted afterwards from the logged temperature) and beta at its prior unless the
    fitted runs span :data:`BETA_SPAN_K` of peak temperature."""
    fixed = {"Cth_J_per_K": HEAT_CAPACITY_PER_AH * data.q_max,
             "Rth_K_per_W": THERMAL_RESISTANCE_AH / data.q_max}
    peaks, _ = _curve_temperatures(data)
    if not data.has_temperature or np.ptp(peaks) < BETA_SPAN_K:
        fixed["beta_K"] = BETA_PRIOR_K
    return fixed


def _curve_temperatures(data: Samples):
    """Peak and starting (ambient) temperature of each fitted curve [degC]."""
    peaks, ambients = [], []
    for k in range(data.n_curves):
        t = data.temperature[(data.curve == k) & ~data.is_rest]
        if t.size:
            peaks.append(float(t.max()))
            ambients.append(float(t[0]))
    return np.array(peaks or [0.0]), np.array(ambients or [0.0])
