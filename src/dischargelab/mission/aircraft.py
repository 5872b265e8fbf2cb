"""Atmosphere and aircraft power: the electric power a flight condition draws.

Fixed-wing drag polar and multirotor hover by momentum theory, vectorised.

References
----------
.. [1] J. D. Anderson, "Introduction to Flight", 8th ed., McGraw-Hill (2016),
   sections 6.3-6.8: drag polar ``C_D = C_D0 + C_L^2 / (pi e AR)``, power required
   ``P = D V``, rate of climb ``R/C = (P_available - P_required) / W``.
.. [2] J. G. Leishman, "Principles of Helicopter Aerodynamics", 2nd ed., Cambridge
   University Press (2006), chapter 2: hover power from momentum theory
   ``P = T^1.5 / sqrt(2 rho A)``, figure of merit, axial climb.
.. [3] ISO 2533:1975 / ICAO Doc 7488, Standard Atmosphere (troposphere).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import DataError

#: Standard acceleration of gravity [m/s^2] (ISO 80000-3).
STANDARD_GRAVITY_M_S2 = 9.80665

#: ISA sea-level air density [kg/m^3].
SEA_LEVEL_AIR_DENSITY_KG_M3 = 1.225



# ---------------------------------------------------------------------------------------------
# Atmosphere and aircraft power (vectorised physics)
# ---------------------------------------------------------------------------------------------

def isa_air_density_kg_m3(altitude_m):
    """Air density of the ISA troposphere [kg/m^3] at geopotential altitude [m].

    ``T = 288.15 - 0.0065 h`` [K], ``p = 101325 (T / 288.15)^(g0 / (L R))`` [Pa],
    ``rho = p / (R T)`` with ``R = 287.05287 J/(kg K)``; valid from -500 m to 11 km.

    References
    ----------
    .. [1] ISO 2533:1975 / ICAO Doc 7488 Standard Atmosphere.
    """
    h = np.asarray(altitude_m, dtype=float)
    if np.any(h < -500.0) or np.any(h > 11000.0):
        raise DataError(f"altitude must be between -500 and 11000 m (ISA troposphere), got "
                        f"{altitude_m}")
    lapse, t0, p0, r_air = 0.0065, 288.15, 101325.0, 287.05287
    temperature = t0 - lapse * h
    pressure = p0 * (temperature / t0) ** (STANDARD_GRAVITY_M_S2 / (lapse * r_air))
    rho = pressure / (r_air * temperature)
    return float(rho) if rho.ndim == 0 else rho


def fixed_wing_power_W(speed_m_s, mass_kg, wing_area_m2, cd0, aspect_ratio, span_efficiency,
                       propulsion_efficiency, air_density_kg_m3=SEA_LEVEL_AIR_DENSITY_KG_M3,
                       climb_rate_m_s=0.0):
    """Electric power [W] of a fixed-wing aircraft in steady flight (parabolic drag polar).

    Lift equals weight (level flight; in a shallow climb ``cos(gamma) ~ 1``)::

        q   = rho V^2 / 2                      dynamic pressure [Pa]
        C_L = m g / (q S)
        C_D = C_D0 + C_L^2 / (pi e AR)
        D   = q S C_D                          drag [N]
        P   = (D V + m g V_climb) / eta        electric power [W]

    Parameters
    ----------
    speed_m_s : airspeed V [m/s]
    mass_kg : take-off mass m [kg]
    wing_area_m2 : wing reference area S [m^2]
    cd0 : zero-lift drag coefficient C_D0 [-]
    aspect_ratio : wing aspect ratio AR = b^2 / S [-]
    span_efficiency : Oswald span efficiency e [-]
    propulsion_efficiency : propeller x motor x controller efficiency eta [-]
    air_density_kg_m3 : air density rho [kg/m^3]
    climb_rate_m_s : rate of climb [m/s]; negative in a descent (power floored at 0 W, a glide)

    Returns
    -------
    float or numpy.ndarray
        Electric power drawn from the battery [W].

    References
    ----------
    .. [1] Anderson, Introduction to Flight, 8th ed., eqs. (6.1c), (6.26), (6.50).
    """
    v = np.asarray(speed_m_s, dtype=float)
    weight = np.asarray(mass_kg, dtype=float) * STANDARD_GRAVITY_M_S2
    dynamic_pressure = 0.5 * np.asarray(air_density_kg_m3, dtype=float) * v**2
    cl = weight / (dynamic_pressure * wing_area_m2)
    cd = cd0 + cl**2 / (math.pi * span_efficiency * aspect_ratio)
    drag = dynamic_pressure * wing_area_m2 * cd
    power = np.maximum((drag * v + weight * climb_rate_m_s) / propulsion_efficiency, 0.0)
    return float(power) if power.ndim == 0 else power


def hover_power_W(mass_kg, rotor_disc_area_m2, figure_of_merit, motor_efficiency,
                  air_density_kg_m3=SEA_LEVEL_AIR_DENSITY_KG_M3, climb_rate_m_s=0.0):
    """Electric power [W] of a multirotor in hover or axial climb (momentum theory).

    Thrust ``T = m g`` shared by all rotors of total disc area ``A``::

        P_ideal = T^1.5 / sqrt(2 rho A)            ideal induced power in hover
        P_hover = P_ideal / (FM * eta_motor)        electric power

    In a climb at ``V_c`` the ideal power grows by
    ``V_c / (2 v_h) + sqrt((V_c / (2 v_h))^2 + 1)`` with ``v_h = sqrt(T / (2 rho A))``
    (the same figure of merit is assumed).

    Parameters
    ----------
    mass_kg : mass m [kg]
    rotor_disc_area_m2 : total disc area of all rotors A [m^2]
    figure_of_merit : rotor figure of merit FM [-] (0.5-0.75 for small rotors)
    motor_efficiency : motor x controller efficiency [-]
    air_density_kg_m3 : air density rho [kg/m^3]
    climb_rate_m_s : axial climb rate V_c >= 0 [m/s]

    Returns
    -------
    float or numpy.ndarray
        Electric power [W].

    References
    ----------
    .. [1] Leishman, Principles of Helicopter Aerodynamics, 2nd ed., eqs. (2.14),
       (2.43) (figure of merit) and section 2.6 (axial climb).
    """
    thrust = np.asarray(mass_kg, dtype=float) * STANDARD_GRAVITY_M_S2
    rho = np.asarray(air_density_kg_m3, dtype=float)
    induced_hover = np.sqrt(thrust / (2.0 * rho * rotor_disc_area_m2))
    ideal = thrust * induced_hover  # = T^1.5 / sqrt(2 rho A)
    ratio_c = np.asarray(climb_rate_m_s, dtype=float) / (2.0 * induced_hover)
    climb_factor = ratio_c + np.sqrt(ratio_c**2 + 1.0)
    power = ideal * climb_factor / (figure_of_merit * motor_efficiency)
    return float(power) if power.ndim == 0 else power
