"""Aerodynamic drag on a multicopter's airframe and rotors (pure functions, SI units).

Two terms, both in the body frame (FRD) and functions of the air-relative velocity
``v_air = v - v_wind`` rotated into the body:

- rotor (momentum) drag: the rotors' induced drag, linear in the body-horizontal air speed,
  ``a_xy = -mu v_air_xy``. This is the model ArduPilot's EKF3 fuses as "drag fusion"
  (``EK3_DRAG_MCOEF``, the coefficient ``mu`` [1/s]; AP_NavEKF3_core "drag fusion"); small
  multirotors have ``mu`` of about 0.1-0.3 1/s (ArduPilot's SITL '+' quad prints
  ``EK3_DRAG_MCOEF = 0.209``). It has no vertical component: a hovering rotor's induced drag
  acts in the rotor plane.
- body (bluff-body) drag: quadratic, ``a_xy = -0.5 rho v_air_xy |v_air_xy| / B``, with the
  ballistic coefficient ``B = m / (C_d A)`` [kg/m^2] of ArduPilot's ``EK3_DRAG_BCOEF_X/Y``
  (SITL's '+' quad: 17.2 kg/m^2). ``B = 0`` means no body drag.
"""

from __future__ import annotations

AIR_DENSITY_KG_M3 = 1.225
"""ISA sea-level air density [kg/m^3]."""


def drag_accel_body_mps2(
    air_u_mps: float,
    air_v_mps: float,
    rotor_drag_per_s: float,
    ballistic_coefficient_kg_per_m2: float,
    air_density_kg_m3: float = AIR_DENSITY_KG_M3,
) -> tuple[float, float]:
    """Body-horizontal drag acceleration (x, y) FRD [m/s^2] for an air velocity [m/s].

    Parameters
    ----------
    air_u_mps, air_v_mps
        Air-relative velocity along body x and y (vehicle velocity minus wind, in FRD) [m/s].
    rotor_drag_per_s
        ``mu`` of the rotor-drag model [1/s] (0: none).
    ballistic_coefficient_kg_per_m2
        ``B = m / (C_d A)`` [kg/m^2] of the quadratic body drag (0: none).
    air_density_kg_m3
        Air density [kg/m^3].
    """
    ax = -rotor_drag_per_s * air_u_mps
    ay = -rotor_drag_per_s * air_v_mps
    if ballistic_coefficient_kg_per_m2 > 0.0:
        k = 0.5 * air_density_kg_m3 / ballistic_coefficient_kg_per_m2
        ax -= k * air_u_mps * abs(air_u_mps)
        ay -= k * air_v_mps * abs(air_v_mps)
    return ax, ay
