"""The ArduPilot parameters that describe a vehicle profile (the inverse of
:func:`tether_companion.vehicle_params.ardupilot.thrust_curve`), for the emulator to answer
the parameter protocol as ArduPilot would."""

from __future__ import annotations

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.frames import FRAMES, ardupilot_frame_ids
from tether_companion.physics.vehicle import VehicleProfile

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
    c0, c1, c2 = curve.coefficients_n
    if curve.command_unit != "pwm_us" or c0 != 0.0 or curve.command_full_scale != 1.0:
        raise ValueError(f"{profile.name}: thrust curve not expressible as MOT_* parameters")
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
