"""The ArduPilot or PX4 parameters that describe a vehicle profile (the inverse of
:func:`tether_companion.vehicle_params.ardupilot.thrust_curve` and
:func:`tether_companion.vehicle_params.px4.thrust_curve`), for the emulator to answer the
parameter protocol as either autopilot would."""

from __future__ import annotations

import math

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.frames import FRAMES, ardupilot_frame_ids
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.vehicle_params.px4 import MOTOR1_FUNCTION, MULTIROTOR_AIRFRAME

PWM_MIN_US = 1000.0
PWM_MAX_US = 2000.0


def ardupilot_parameters(profile: VehicleProfile) -> dict[str, float]:
    """FRAME_CLASS, FRAME_TYPE, MOT_* of ``profile`` with MOT_PWM_MIN/MAX at 1000/2000 us.

    Raises
    ------
    ValueError
        When ArduPilot's parameters cannot express the profile: outputs not in microseconds,
        a curve with thrust at zero command (c0 != 0) or not in normalised throttle, a motor
        layout that is none of the named frames.
    """
    curve = profile.thrust_curve
    c1, c2 = _linear_and_quadratic(profile, "MOT_*")
    frame = next((name for name, motors in FRAMES.items() if motors == profile.motors), None)
    if frame is None:
        raise ValueError(f"{profile.name}: motor layout is none of ArduPilot's frames")
    frame_class, frame_type = ardupilot_frame_ids(frame)
    full_thrust_n = c1 + c2
    span = PWM_MAX_US - PWM_MIN_US
    params = {
        "FRAME_CLASS": float(frame_class),
        "FRAME_TYPE": float(frame_type),
        "MOT_PWM_MIN": PWM_MIN_US,
        "MOT_PWM_MAX": PWM_MAX_US,
        "MOT_SPIN_MIN": (curve.pwm_min_us - PWM_MIN_US) / span,
        "MOT_SPIN_MAX": (curve.pwm_max_us - PWM_MIN_US) / span,
        "MOT_THST_EXPO": c2 / full_thrust_n,
        "MOT_THST_HOVER": profile.mass_kg * GRAVITY_MPS2 / (profile.n_motors * full_thrust_n),
        "MOT_BAT_VOLT_MAX": profile.battery.voltage_max_v,
        "MOT_BAT_VOLT_MIN": profile.battery.voltage_min_v,
    }
    return params


PX4_YAW_MOMENT = 0.05
"""|CA_ROTORn_KM| answered (PX4's default moment ratio); only its sign is read."""


def px4_parameters(profile: VehicleProfile) -> dict[str, float]:
    """CA_AIRFRAME, CA_ROTOR*, THR_MDL_FAC, MPC_THR_HOVER and PWM_MAIN_* of ``profile``.

    Rotor ``i`` sits at ``arm_length_m * radius_scale`` along its ``angle_deg`` (body FRD);
    every motor output ``j`` has the curve's PWM range and function Motor ``j``.

    Raises
    ------
    ValueError
        When PX4's parameters cannot express the profile (outputs not in microseconds, a
        curve with thrust at zero command or not in normalised throttle).
    """
    curve = profile.thrust_curve
    c1, c2 = _linear_and_quadratic(profile, "PX4")
    n = profile.n_motors
    params: dict[str, float] = {
        "CA_AIRFRAME": float(MULTIROTOR_AIRFRAME),
        "CA_ROTOR_COUNT": float(n),
        "THR_MDL_FAC": c2 / (c1 + c2),
        "MPC_THR_HOVER": profile.mass_kg * GRAVITY_MPS2 / (n * (c1 + c2)),
    }
    for i, motor in enumerate(profile.motors):
        radius_m = profile.arm_length_m * motor.radius_scale
        angle = math.radians(motor.angle_deg)
        params[f"CA_ROTOR{i}_PX"] = radius_m * math.cos(angle)
        params[f"CA_ROTOR{i}_PY"] = radius_m * math.sin(angle)
        params[f"CA_ROTOR{i}_KM"] = PX4_YAW_MOMENT if motor.spin == "ccw" else -PX4_YAW_MOMENT
        params[f"PWM_MAIN_MIN{i + 1}"] = curve.pwm_min_us
        params[f"PWM_MAIN_MAX{i + 1}"] = curve.pwm_max_us
        params[f"PWM_MAIN_FUNC{i + 1}"] = float(MOTOR1_FUNCTION + i)
    return params


def _linear_and_quadratic(profile: VehicleProfile, what: str) -> tuple[float, float]:
    """The curve's c1, c2 [N] when it is a pulse-width curve without thrust at zero command."""
    curve = profile.thrust_curve
    c0, c1, c2 = curve.coefficients_n
    if curve.command_unit != "pwm_us" or c0 != 0.0 or curve.command_full_scale != 1.0:
        raise ValueError(f"{profile.name}: thrust curve not expressible as {what} parameters")
    return c1, c2
