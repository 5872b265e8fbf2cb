"""``shepherd-thermal``: eq. (6) with temperature-dependent parameters and a lumped thermal state.

The temperature extension of Tremblay's model as used in the Simscape battery
block [2]_, per cell, with ``T`` the cell temperature [degC]::

    f(T)  = exp(beta (1/T - 1/T_ref))                  (Arrhenius, T in K)
    C(T)  = C + dC_dT (T - T_ref)
    V     = E0 + dE0_dT (T - T_ref) - R f(T) i
            - K f(T) C(T)/(C(T) - q) (i + q) + A exp(-B q)

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

References
----------
.. [1] O. Tremblay, L.-A. Dessaint, World Electric Vehicle Journal 3 (2009).
.. [2] MathWorks, Simscape Electrical "Battery" block: temperature effects
   (E0, R, K Arrhenius; capacity linear in temperature).
.. [3] D. Bernardi, E. Pawlikowski, J. Newman, J. Electrochem. Soc. 132 (1985) 5-12.
"""

from __future__ import annotations

import numpy as np

from .base import (
    REFERENCE_TEMPERATURE_C,
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
    version = 1
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
    )
    states = (State("charge_Ah", "Ah", "charge"), State("temperature_C", "degC", "thermal"))

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
        v = (p["E0_V"] + p["dE0_dT_V_per_K"] * dt - p["R_ohm"] * f * i
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
        columns = {
            "E0_V": lambda: np.ones_like(q),
            "R_ohm": lambda: -f * i,
            "K_V_per_Ah": lambda: -f * d_k,
            "Rp_ohm": lambda: -f * i_pol,
            "A_V": lambda: expo,
            "dE0_dT_V_per_K": lambda: dt,
            "B_per_Ah": lambda: -p["A_V"] * q * expo,
            "C_Ah": lambda: d_cap,
            "dC_dT_Ah_per_K": lambda: d_cap * dt,
            "beta_K": lambda: (-p["R_ohm"] * f * i - f * r * i_pol - k * f * gain * q)
            * arrhenius_dbeta(temp),
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
        return grid

    def fit_bounds(self, data: Samples):
        return thermal_bounds(data)

    def fit_fixed(self, data: Samples):
        fixed = thermal_fixed(data)
        _, ambients = _curve_temperatures(data)
        if not data.has_temperature or np.ptp(ambients) < AMBIENT_SPAN_K:
            fixed["dE0_dT_V_per_K"] = 0.0
            fixed["dC_dT_Ah_per_K"] = 0.0
        return fixed


def thermal_bounds(data: Samples) -> dict:
    """Data-dependent bounds shared by the thermal families: capacity above the
    discharged charge, Arrhenius coefficient 300-12,000 K."""
    lo_c = data.q_max * (1.0 + 1e-4)
    return {"C_Ah": (lo_c, max(data.q_max * C_UPPER_FACTOR, lo_c * 1.01)),
            "beta_K": (300.0, 12000.0)}


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
