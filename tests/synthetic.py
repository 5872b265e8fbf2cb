"""Seeded synthetic discharges from the model: noise plus a 10-bit ADC step."""

import numpy as np

from dischargelab.fit import Curve
from dischargelab.model import CellParameters, cell_voltage

TRUE = CellParameters(E0_V=3.75, R_ohm=0.03, K_V_per_Ah=0.008, A_V=0.35, B_per_Ah=2.0,
                      C_Ah=3.1)

#: Arduino-style 10-bit ADC with a 5 V reference and a divider gain Ke [V].
ADC_STEP_V = 5.0 / 1024


def adc_step(ke: float = 1.0) -> float:
    """Voltage resolution [V] of the logger for divider gain ``ke``."""
    return ADC_STEP_V * ke


def synthetic_curve(current_A=3.0, *, params=TRUE, noise_V=0.003, ke=1.0, cells=1,
                    cutoff_cell_V=2.7, dt_s=1.0, seed=0, rest=True, name="") -> Curve:
    """Constant-current discharge to the cutoff sampled every ``dt_s``.

    Pack voltage = cells * model + Gaussian noise, then quantised to the ADC step.
    """
    rng = np.random.default_rng(seed)
    q_end = params.C_Ah * 0.999
    t = np.arange(0.0, q_end * 3600 / current_A, dt_s)
    q = current_A * t / 3600
    v = cell_voltage(params, current_A, q)
    keep = v > cutoff_cell_V
    t, v = t[keep], v[keep] * cells
    step = adc_step(ke)

    def measure(x):
        return np.round((x + rng.normal(0, noise_V, np.shape(x))) / step) * step

    rest_v = float(measure(cells * (params.E0_V + params.A_V))) if rest else None
    return Curve(t, measure(v), np.full(t.size, current_A), name=name or f"{current_A:g} A",
                 rest_voltage_V=rest_v)


def measurement_noise(noise_V=0.003, ke=1.0) -> float:
    """RMS of noise plus quantisation error [V]."""
    return float(np.sqrt(noise_V ** 2 + adc_step(ke) ** 2 / 12))
