"""``shepherd``: the modified Shepherd (Tremblay) model, eq. (6) of the paper.

Per cell, discharge current ``i`` > 0, discharged charge ``q`` [Ah]::

    V = E0 - R*i - K*C/(C - q) * (i_f + q) + A*exp(-B*q)

with ``i_f = i`` (the paper's simplification for constant current) unless the
state carries a filtered current ``i_f_A``. Near
``q -> C`` the model diverges; where ``q >= C`` the voltage is ``-inf``.

References
----------
.. [1] "Measuring battery discharge characteristics for accurate UAV endurance
   estimation", eq. (6) (see ``../shared/paper``).
.. [2] O. Tremblay, L.-A. Dessaint, World Electric Vehicle Journal 3 (2009).
"""

from __future__ import annotations

import numpy as np

from .base import Family, Parameter, Samples

#: Default upper bound of C as a multiple of the largest discharged charge.
C_UPPER_FACTOR = 20.0


def shepherd_terms(C, q):
    """``C/(C - q)`` [-] and ``C - q`` [Ah], with q >= C mapped to inf gain."""
    denom = np.asarray(C - q, dtype=float)
    num = np.broadcast_to(np.asarray(C, dtype=float), denom.shape)
    gain = np.divide(num, denom, out=np.full(denom.shape, np.inf), where=denom > 0)
    return gain, denom


class Shepherd(Family):
    """The paper's eq. (6), isothermal."""

    name = "shepherd"
    version = 1
    title = "modified Shepherd (paper eq. 6)"
    description = ("E0 - R i - K C/(C-q) (i+q) + A exp(-B q); isothermal, the paper's model. "
                   "Good near the fitted rate; misses self-heating at high rate.")
    headline = ("E0_V", "R_ohm", "K_V_per_Ah", "A_V", "B_per_Ah", "C_Ah")
    parameters = (
        Parameter("E0_V", "V", 0.5, 6.0, 3.7, True, "battery constant voltage"),
        Parameter("R_ohm", "ohm", 0.0, 2.0, 0.02, True, "internal resistance"),
        Parameter("K_V_per_Ah", "V/Ah", 0.0, 20.0, 0.01, True, "polarisation constant"),
        Parameter("A_V", "V", 0.0, 3.0, 0.1, True, "exponential zone amplitude"),
        Parameter("B_per_Ah", "1/Ah", 1e-3, 1e4, 3.0, False, "exponential zone inverse time "
                  "constant"),
        Parameter("C_Ah", "Ah", 1e-3, 1e4, 3.0, False, "maximum capacity"),
    )

    # ---- physics ---------------------------------------------------------------------
    def voltage(self, p, state, current_A):
        q = np.asarray(state["charge_Ah"], dtype=float)
        i = np.asarray(current_A, dtype=float)
        i_f = np.asarray(state.get("i_f_A", i), dtype=float)
        C = np.asarray(p["C_Ah"], dtype=float)
        gain, _ = shepherd_terms(C, q)
        ok = q < C
        gain = np.where(ok, gain, 0.0)
        v = (p["E0_V"] - p["R_ohm"] * i - p["K_V_per_Ah"] * gain * (i_f + q)
             + p["A_V"] * np.exp(-p["B_per_Ah"] * q))
        return np.where(ok, v, -np.inf)

    # ---- fitting ------------------------------------------------------------------------
    def fit_voltage(self, p, data: Samples):
        return self.voltage(p, {"charge_Ah": data.charge}, data.current)

    def jacobian(self, p, data: Samples, names=None):
        names = self.names if names is None else tuple(names)
        i, q = data.current, data.charge
        gain, denom = shepherd_terms(p["C_Ah"], q)
        pol = i + q
        expo = np.exp(-p["B_per_Ah"] * q)
        columns = {
            "E0_V": lambda: np.ones_like(q),
            "R_ohm": lambda: -i,
            "K_V_per_Ah": lambda: -gain * pol,
            "A_V": lambda: expo,
            "B_per_Ah": lambda: -p["A_V"] * q * expo,
            "C_Ah": lambda: p["K_V_per_Ah"] * q * pol / denom**2,
        }
        return np.column_stack([columns[n]() for n in names]) if names else \
            np.empty((q.size, 0))

    def input_derivatives(self, p, data: Samples):
        """``dV/di`` [ohm] and ``dV/dq`` [V/Ah] at every sample (for the paper's fitted
        current scale, which multiplies both the current and the charge)."""
        i, q = data.current, data.charge
        gain, denom = shepherd_terms(p["C_Ah"], q)
        expo = np.exp(-p["B_per_Ah"] * q)
        dv_di = -p["R_ohm"] - p["K_V_per_Ah"] * gain
        dv_dq = (-p["K_V_per_Ah"] * (p["C_Ah"] * (i + q) / denom**2 + gain)
                 - p["A_V"] * p["B_per_Ah"] * expo)
        return dv_di, dv_dq

    def guess(self, data: Samples):
        q_max = data.q_max
        out = self.defaults()
        load = ~data.is_rest
        first = np.flatnonzero(load)[0]
        v_first, i_first = data.voltage[first], data.current[first]
        rest = data.voltage[data.is_rest]
        r_step = (rest[0] - v_first) / i_first if rest.size and i_first > 0 else 0.01
        out.update({"E0_V": (rest[0] if rest.size else v_first) - 0.05,
                    "R_ohm": max(float(r_step), 0.0), "K_V_per_Ah": 0.01, "A_V": 0.05,
                    "B_per_Ah": 10.0 / q_max, "C_Ah": q_max * 1.05})
        return out

    def start_grid(self, data: Samples, free_nonlinear):
        q_max = data.q_max
        return {"B_per_Ah": [x / q_max for x in (2.0, 8.0, 30.0, 100.0)],
                "C_Ah": [q_max * f for f in (1.003, 1.03, 1.15)]}

    def fit_bounds(self, data: Samples):
        lo_c = data.q_max * (1.0 + 1e-4)
        return {"C_Ah": (lo_c, max(data.q_max * C_UPPER_FACTOR, lo_c * 1.01))}
