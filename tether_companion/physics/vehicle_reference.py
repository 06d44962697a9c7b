"""The vehicle profile's key-by-key reference (``docs/vehicle-reference.md``), from the code.

Each key's type, default, range and meaning come from :class:`VehicleProfile`'s field specs;
:data:`WHERE` adds where a user finds the value for their drone and how much it matters to the
estimator. A test keeps the document and every key of the profile in step; regenerate with
``python -m tether_companion.physics.vehicle_reference > docs/vehicle-reference.md``.
"""

from __future__ import annotations

from tether_companion.config import describe
from tether_companion.physics.vehicle import VehicleProfile

WHERE: dict[str, str] = {
    "name": "any label; shown in logs and reports",
    "mass_kg": "weigh the drone ready to fly (battery, payload, tether attachment). "
    "Matters most: the estimator's thrust scale and the tension it infers are proportional to it",
    "inertia_kg_m2": "CAD model or a bifilar pendulum test; used by the simulator and emulator "
    "only (the estimator takes attitude from the flight controller)",
    "arm_length_m": "measure centre to motor axis; simulator/emulator only",
    "yaw_moment_per_thrust_m": "propeller data (torque / thrust coefficient ratio, ~0.01-0.02 m); "
    "simulator/emulator only",
    "drag_coefficient_n_s_per_m": "linear airframe drag, isotropic; usually 0 with "
    "rotor_drag_per_s set (which `sysid --profile-out` identifies from a log with velocity)",
    "rotor_drag_per_s": "ArduPilot's EK3_DRAG_MCOEF (the SITL quad prints 0.209) or identified "
    "by `sysid` from a log with velocity; 0.1-0.3 1/s on small multirotors. Matters in forward "
    "flight: 0.2 1/s at 1 m/s is 0.2 m/s^2 of pull the tether does not make",
    "ballistic_coefficient_kg_per_m2": "ArduPilot's EK3_DRAG_BCOEF_X/Y (m / (Cd A)); 0 ignores "
    "quadratic body drag, which is small below 3 m/s",
    "motor_time_constant_s": "motor step response on a thrust stand, or identified by "
    "`sysid` (the first-order model's time constant); 0.02-0.08 s for 5-12 inch propellers",
    "thrust_curve.command_unit": "what your flight controller's SERVO_OUTPUT_RAW carries: "
    "pwm_us for ArduPilot and PX4 PWM/OneShot/DShot outputs (both report microseconds), raw for "
    "a Crazyflie, normalised for 0-1 actuator logs",
    "thrust_curve.pwm_min_us": "ArduPilot: MOT_PWM_MIN + MOT_SPIN_MIN * (MOT_PWM_MAX - "
    "MOT_PWM_MIN); PX4: PWM_MAIN_MINn; or written by `sysid --from-params`",
    "thrust_curve.pwm_max_us": "ArduPilot: MOT_PWM_MIN + MOT_SPIN_MAX * (MOT_PWM_MAX - "
    "MOT_PWM_MIN); PX4: PWM_MAIN_MAXn",
    "thrust_curve.command_full_scale": "1 when the coefficients are in normalised throttle; "
    "the raw full-scale (65535) when they are in raw commands (Crazyflie, Martins eq. 6)",
    "thrust_curve.coefficients_n": "a thrust stand (fit f = c0 + c1 u + c2 u^2), `sysid` "
    "(static fit), or `sysid --from-params` (ArduPilot: (0, K(1-MOT_THST_EXPO), K MOT_THST_EXPO) "
    "with K = m g / (n MOT_THST_HOVER); PX4: THR_MDL_FAC and MPC_THR_HOVER). Matters most with "
    "the mass: a 5 % scale error is a 5 % tension error",
    "battery.voltage_max_v": "ArduPilot MOT_BAT_VOLT_MAX (4.2 V per cell); 0 when the "
    "flight controller does not compensate or no voltage is reported",
    "battery.voltage_min_v": "ArduPilot MOT_BAT_VOLT_MIN (3.3 V per cell)",
    "frame": "ArduPilot FRAME_CLASS/FRAME_TYPE (quad-x = 1/1, quad-plus = 1/0, hexa-x = 2/1, "
    "octa-x = 3/1, octaquad-x = 4/1, y6 = 5/0); sets the motor order of SERVO_OUTPUT_RAW",
    "motors": "with frame: custom, one {angle_deg, spin, radius_scale} per output channel "
    "(PX4: CA_ROTORn_PX/PY/KM)",
}


def vehicle_reference() -> str:
    """Markdown table of every key of :class:`VehicleProfile` with where to find its value."""
    lines = [
        "| key | type | default | meaning | where to find it |",
        "| --- | --- | --- | --- | --- |",
    ]
    for key, type_name, default, text in describe(VehicleProfile):
        where = WHERE[key]
        lines.append(
            f"| `{key}` | {type_name} | `{default}` | {text.replace('|', '/')} | {where} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # python -m tether_companion.physics.vehicle_reference
    print(vehicle_reference(), end="")
