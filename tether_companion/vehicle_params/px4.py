"""PX4 parameters to a vehicle profile: rotor geometry, PWM range and thrust curve.

How PX4 turns a motor's thrust demand into a pulse (read at commit 15c4f088):

* ``src/lib/mixer_module/functions/FunctionMotors.hpp``, ``updateValues()``: with
  ``f = THR_MDL_FAC`` in (0, 1] the demand ``t`` (0-1, linear in thrust) becomes the output
  ``x`` solving ``f x^2 + (1 - f) x = t`` ("rel_thrust = factor * x^2 + (1-factor) * x"), then
  ``x`` is remapped from [0, 1] to [-1, 1];
* the output driver maps [-1, 1] onto [PWM_MAIN_MINn, PWM_MAIN_MAXn] linearly.

So one rotor gives ``K ((1 - f) x + f x^2)`` with ``x`` the pulse's position in
[PWM_MAIN_MIN, PWM_MAIN_MAX]: our quadratic curve with coefficients ``(0, K (1 - f), K f)``.
``MPC_THR_HOVER`` is the collective thrust demand of a hover, so ``K = m g / (n MPC_THR_HOVER)``.

The geometry comes from the control allocation's rotor list (``CA_ROTOR_COUNT``,
``CA_ROTORn_PX/PY`` [m] in body FRD, ``CA_ROTORn_KM``: > 0 for a counter-clockwise rotor);
motor ``n`` (0-based) is output ``n + 1`` when ``PWM_MAIN_FUNCn+1`` is ``101 + n`` (Motor n+1)
or absent. PX4's battery scaling of the thrust setpoint is not modelled here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from tether_companion.config import ConfigError
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.motor_layout import Motor
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.vehicle_params.ranges import ParamRange, checked_value

SOURCE = "PX4 parameters"
MULTIROTOR_AIRFRAME = 0
MOTOR1_FUNCTION = 101
MAX_ROTORS = 12

PARAMETERS: dict[str, ParamRange] = {
    "CA_AIRFRAME": ParamRange(0, 12, None),
    "CA_ROTOR_COUNT": ParamRange(0, MAX_ROTORS, None),
    "THR_MDL_FAC": ParamRange(0.0, 1.0, 0.0),
    "MPC_THR_HOVER": ParamRange(0.1, 0.8, None),
    "PWM_MAIN_MIN": ParamRange(800, 1400, 1000),
    "PWM_MAIN_MAX": ParamRange(1600, 2200, 2000),
    "CA_ROTOR_PX": ParamRange(-100.0, 100.0, None),
    "CA_ROTOR_PY": ParamRange(-100.0, 100.0, None),
    "CA_ROTOR_KM": ParamRange(-1.0, 1.0, None),
}
"""Documented ranges (PX4 parameter reference ``@min``/``@max``) and firmware defaults; the
per-rotor and per-output names take the rotor or output number (``CA_ROTOR0_PX``,
``PWM_MAIN_MIN1``)."""


def is_px4(params: Mapping[str, float]) -> bool:
    """Whether the parameter set looks like PX4's (it has a control-allocation rotor count)."""
    return "CA_ROTOR_COUNT" in params or "CA_AIRFRAME" in params


def _value(params: Mapping[str, float], name: str, spec_name: str, source: str) -> float:
    return checked_value(params, name, PARAMETERS[spec_name], source)


def rotor_count(params: Mapping[str, float], source: str = SOURCE) -> int:
    """CA_ROTOR_COUNT of a multirotor airframe (at least 4)."""
    airframe = _value(params, "CA_AIRFRAME", "CA_AIRFRAME", source)
    if airframe != MULTIROTOR_AIRFRAME:
        raise ConfigError(source, "CA_AIRFRAME", airframe, "must be 0 (multirotor)")
    count = _value(params, "CA_ROTOR_COUNT", "CA_ROTOR_COUNT", source)
    if count < 4 or not count.is_integer():
        raise ConfigError(source, "CA_ROTOR_COUNT", count, "must be a whole number of 4 to 12")
    return int(count)


def geometry(params: Mapping[str, float], source: str = SOURCE) -> tuple[float, tuple[Motor, ...]]:
    """Arm length [m] (the farthest rotor) and the rotors in output order."""
    n = rotor_count(params, source)
    positions, spins = [], []
    for i in range(n):
        x = _value(params, f"CA_ROTOR{i}_PX", "CA_ROTOR_PX", source)
        y = _value(params, f"CA_ROTOR{i}_PY", "CA_ROTOR_PY", source)
        km = _value(params, f"CA_ROTOR{i}_KM", "CA_ROTOR_KM", source)
        if km == 0.0:
            raise ConfigError(source, f"CA_ROTOR{i}_KM", km, "must be > 0 (ccw) or < 0 (cw)")
        positions.append((x, y))
        spins.append("ccw" if km > 0.0 else "cw")
        function = params.get(f"PWM_MAIN_FUNC{i + 1}")
        if function is not None and float(function) != MOTOR1_FUNCTION + i:
            raise ConfigError(
                source,
                f"PWM_MAIN_FUNC{i + 1}",
                float(function),
                f"must be {MOTOR1_FUNCTION + i} (Motor {i + 1}): motors on other outputs "
                "are not supported",
            )
    radii = [math.hypot(x, y) for x, y in positions]
    arm = max(radii)
    if arm <= 0.0:
        raise ConfigError(source, "CA_ROTOR0_PX", positions[0][0], "rotors must not all sit at 0")
    motors = tuple(
        Motor(math.degrees(math.atan2(y, x)), spin, max(radius / arm, 1e-6))
        for (x, y), spin, radius in zip(positions, spins, radii, strict=True)
    )
    return arm, motors


def pwm_range_us(
    params: Mapping[str, float], n_motors: int, source: str = SOURCE
) -> tuple[float, float]:
    """The motors' common [PWM_MAIN_MINn, PWM_MAIN_MAXn] [us] (older PX4: PWM_MIN/PWM_MAX)."""
    ranges = set()
    for j in range(1, n_motors + 1):
        low_name = f"PWM_MAIN_MIN{j}" if f"PWM_MAIN_MIN{j}" in params else "PWM_MIN"
        high_name = f"PWM_MAIN_MAX{j}" if f"PWM_MAIN_MAX{j}" in params else "PWM_MAX"
        low = _value(params, low_name, "PWM_MAIN_MIN", source)
        high = _value(params, high_name, "PWM_MAIN_MAX", source)
        ranges.add((low, high))
        if len(ranges) > 1:
            raise ConfigError(
                source,
                low_name,
                low,
                f"differs from motor 1's range {sorted(ranges)[0]}: one range for all motors",
            )
    return ranges.pop()


def thrust_curve(
    params: Mapping[str, float], mass_kg: float, n_motors: int, source: str = SOURCE
) -> ThrustCurve:
    """One motor's curve as PX4 linearises it, scaled by the hover thrust (module docstring)."""
    factor = _value(params, "THR_MDL_FAC", "THR_MDL_FAC", source)
    hover = _value(params, "MPC_THR_HOVER", "MPC_THR_HOVER", source)
    low, high = pwm_range_us(params, n_motors, source)
    full_thrust_n = mass_kg * GRAVITY_MPS2 / (n_motors * hover)
    return ThrustCurve(
        command_unit="pwm_us",
        pwm_min_us=low,
        pwm_max_us=high,
        command_full_scale=1.0,
        coefficients_n=(0.0, full_thrust_n * (1.0 - factor), full_thrust_n * factor),
    )
