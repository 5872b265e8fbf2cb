"""Analog front end of the logger: ADC codes to volts, amperes and degrees.

Channel assignment of the firmware (``docs/acquisition.md`` shows the wiring):

* A0 :data:`VOLTAGE_CHANNEL`: pack voltage through the divider and the op-amp
  voltage follower (paper 3.1); scaled by the calibration gain Ke (paper eq. 7).
* A1 :data:`CURRENT_CHANNEL`: current sensor output, a Hall sensor such as the
  ACS712 or a shunt amplifier, as ``V = zero_V + sensitivity * I``.
* A2 :data:`TEMPERATURE_CHANNEL`: NTC thermistor to ground with a fixed
  resistor to the 5 V reference (Beta equation).

References
----------
.. [1] ATmega328P datasheet, section 24.7 "ADC conversion result":
   ``ADC = V_in * 1024 / V_ref``.
.. [2] Allegro ACS712 datasheet: output ``Vcc/2`` at 0 A, sensitivity 185 mV/A
   (ACS712ELCTR-05B), 100 mV/A (-20A), 66 mV/A (-30A) at Vcc = 5 V.
.. [3] NTC Beta equation, e.g. Vishay NTCLE100E3 application note:
   ``1/T = 1/T25 + ln(R/R25)/B``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DataError

VOLTAGE_CHANNEL = 0
CURRENT_CHANNEL = 1
TEMPERATURE_CHANNEL = 2

#: Arduino Uno ADC: 10 bits, 5 V reference (AVcc).
ADC_BITS = 10
ADC_REFERENCE_V = 5.0
ADC_STEPS = 1 << ADC_BITS


def adc_to_volts(code, reference_V: float = ADC_REFERENCE_V, bits: int = ADC_BITS):
    """Pin voltage [V] for an ADC code: the middle of the code's interval.

    The converter truncates (``code = floor(V * 2**bits / V_ref)`` [1]_), so the
    unbiased estimate of the input is ``(code + 0.5) * V_ref / 2**bits``.
    """
    return (np.asarray(code, dtype=float) + 0.5) * reference_V / (1 << bits)


def volts_to_adc(volts, reference_V: float = ADC_REFERENCE_V, bits: int = ADC_BITS):
    """ADC code for a pin voltage [V] (truncating, clipped to 0..2**bits - 1) [1]_."""
    steps = 1 << bits
    code = np.floor(np.asarray(volts, dtype=float) * steps / reference_V)
    return np.clip(np.nan_to_num(code, nan=0.0, posinf=steps - 1, neginf=0.0), 0, steps - 1
                   ).astype(int)


@dataclass(frozen=True)
class CurrentSensor:
    """Linear current sensor: ``V_out = zero_V + sensitivity_V_per_A * I`` [2]_.

    Wire it so that DISCHARGE current raises the output (ACS712: current enters
    IP+ and leaves IP-); the result is then discharge positive.
    """

    name: str
    sensitivity_V_per_A: float
    zero_V: float = ADC_REFERENCE_V / 2

    def current_A(self, pin_V):
        """Current [A] (discharge positive) from the sensor output voltage [V]."""
        return (np.asarray(pin_V, dtype=float) - self.zero_V) / self.sensitivity_V_per_A

    def pin_voltage(self, current_A):
        """Sensor output [V] for a current [A]."""
        return self.zero_V + self.sensitivity_V_per_A * np.asarray(current_A, dtype=float)

    def resolution_A(self) -> float:
        """Current of one ADC step [A]."""
        return ADC_REFERENCE_V / ADC_STEPS / self.sensitivity_V_per_A

    def to_dict(self) -> dict:
        return {"name": self.name, "sensitivity_V_per_A": self.sensitivity_V_per_A,
                "zero_V": self.zero_V}


#: Hall-effect sensors of the ACS712 family at Vcc = 5 V [2]_.
CURRENT_SENSORS: dict[str, CurrentSensor] = {
    "acs712-5a": CurrentSensor("acs712-5a", 0.185),
    "acs712-20a": CurrentSensor("acs712-20a", 0.100),
    "acs712-30a": CurrentSensor("acs712-30a", 0.066),
}


def current_sensor(spec: str) -> CurrentSensor:
    """A preset name, or ``"shunt:SENS_V_PER_A[:ZERO_V]"`` for a shunt amplifier."""
    key = spec.strip().lower()
    if key in CURRENT_SENSORS:
        return CURRENT_SENSORS[key]
    if key.startswith("shunt:"):
        parts = key.split(":")[1:]
        try:
            sens = float(parts[0])
            zero = float(parts[1]) if len(parts) > 1 else 0.0
        except (ValueError, IndexError):
            parts = None
        if parts is not None and sens > 0:
            return CurrentSensor(spec, sens, zero)
    raise DataError(f"unknown current sensor {spec!r}; use one of "
                    f"{', '.join(CURRENT_SENSORS)} or shunt:V_PER_A[:ZERO_V] "
                    "(e.g. shunt:0.5 for a 10 mOhm shunt with a gain-50 amplifier)")


@dataclass(frozen=True)
class Thermistor:
    """NTC thermistor from the pin to ground, ``fixed_ohm`` from the 5 V reference to the pin.

    ``V_pin = V_ref * R_ntc / (R_ntc + R_fixed)``; temperature by the Beta
    equation [3]_. Defaults: 10 kOhm at 25 degC, B = 3950 K, 10 kOhm fixed.
    """

    r25_ohm: float = 10_000.0
    beta_K: float = 3950.0
    fixed_ohm: float = 10_000.0

    def temperature_C(self, pin_V):
        """Temperature [degC] from the pin voltage [V]; NaN outside 0 < V < V_ref."""
        v = np.asarray(pin_V, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = self.fixed_ohm * v / (ADC_REFERENCE_V - v)
            inv_t = 1.0 / 298.15 + np.log(r / self.r25_ohm) / self.beta_K
            t = 1.0 / inv_t - 273.15
        return np.where((v > 0) & (v < ADC_REFERENCE_V) & np.isfinite(t), t, np.nan)

    def pin_voltage(self, temperature_C):
        """Pin voltage [V] at a temperature [degC]."""
        t = np.asarray(temperature_C, dtype=float) + 273.15
        r = self.r25_ohm * np.exp(self.beta_K * (1.0 / t - 1.0 / 298.15))
        return ADC_REFERENCE_V * r / (r + self.fixed_ohm)

    def to_dict(self) -> dict:
        return {"r25_ohm": self.r25_ohm, "beta_K": self.beta_K, "fixed_ohm": self.fixed_ohm}


def finite_or_none(value) -> float | None:
    """``float(value)`` or None for NaN/inf."""
    value = float(value)
    return value if math.isfinite(value) else None
