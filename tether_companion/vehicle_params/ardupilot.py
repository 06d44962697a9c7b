"""ArduPilot Copter parameters to a vehicle profile: frame, PWM range and thrust curve.

How ArduPilot turns a thrust demand into a pulse (read in ``libraries/AP_Motors`` at commit
04dc0b71, ``AP_Motors_Thrust_Linearization.cpp``):

* ``thrust_to_actuator`` (line 104): ``actuator = SPIN_MIN + (SPIN_MAX - SPIN_MIN) * a`` where
  ``a = apply_thrust_curve_and_volt_scaling(thrust)`` (line 119) solves
  ``e a^2 + (1 - e) a = lift_max * thrust`` with ``e = MOT_THST_EXPO`` clipped to [-1, 1]
  (line 131), then divides by the filtered voltage ratio ``v`` (line 123).
* ``AP_MotorsMulticopter::output_to_pwm``: ``pwm = PWM_MIN + (PWM_MAX - PWM_MIN) * actuator``.
* ``update_lift_max_from_batt_voltage`` (line 156): ``v = V / MOT_BAT_VOLT_MAX`` with ``V``
  clipped to [max(MOT_BAT_VOLT_MIN, 0.6 MOT_BAT_VOLT_MAX), MOT_BAT_VOLT_MAX], filtered at
  0.5 Hz; ``lift_max = v (1 - e) + e v^2`` (line 184); compensation is off (``v = 1``) when
  ``MOT_BAT_VOLT_MAX <= 0`` or ``MOT_BAT_VOLT_MIN >= MOT_BAT_VOLT_MAX`` (line 163).
* ``get_compensation_gain`` (line 189) scales the throttle demand by ``1 / lift_max``.

The curve ArduPilot inverts is therefore a rotor thrust of ``K ((1 - e) a v + e (a v)^2)``
with ``a`` the output's position between the SPIN_MIN and SPIN_MAX pulses: our quadratic
:class:`ThrustCurve` with ``pwm_min_us``/``pwm_max_us`` at those pulses and coefficients
``(0, K (1 - e), K e)``, exactly. The compensated demand makes each rotor give ``K * throttle``
at any voltage, so a hover at ``MOT_THST_HOVER`` (the learned hover throttle, 0-1) gives the
scale ``K = m g / (n MOT_THST_HOVER)`` from the mass alone. Air-density compensation (also in
``get_compensation_gain``: the demand is divided by the air-density ratio too) is left out, so
a hover throttle ArduPilot learned away from sea-level density gives a ``K`` too high (4.3 %
after a SITL hover at its 584 m field, docs/ardupilot.md).
"""

from __future__ import annotations

from collections.abc import Mapping

from tether_companion.config import ConfigError
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.battery import BatteryCompensation
from tether_companion.physics.frames import ardupilot_frame
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.vehicle_params.ranges import ParamRange, checked_value

PARAMETERS: dict[str, ParamRange] = {
    "FRAME_CLASS": ParamRange(0, 17, None),
    "FRAME_TYPE": ParamRange(0, 19, None),
    "MOT_PWM_MIN": ParamRange(0, 2000, 1000),
    "MOT_PWM_MAX": ParamRange(0, 2000, 2000),
    "MOT_SPIN_MIN": ParamRange(0.0, 0.3, 0.15),
    "MOT_SPIN_MAX": ParamRange(0.9, 1.0, 0.95),
    "MOT_THST_EXPO": ParamRange(-1.0, 1.0, 0.65),
    "MOT_THST_HOVER": ParamRange(0.125, 0.6875, None),
    "MOT_BAT_VOLT_MAX": ParamRange(0.0, 53.0, 0.0),
    "MOT_BAT_VOLT_MIN": ParamRange(0.0, 42.0, 0.0),
    "RC3_MIN": ParamRange(800, 2200, 1100),
    "RC3_MAX": ParamRange(800, 2200, 1900),
}
"""What is read, with the range the source documents (``@Range``) or enforces
(MOT_THST_HOVER: ``AP_MOTORS_THST_HOVER_MIN/MAX`` in ``AP_MotorsMulticopter.h``) and the
firmware default used when a parameter is absent. FRAME_CLASS, FRAME_TYPE and MOT_THST_HOVER
(default 0.35) are required: without them there is no frame and no scale."""

SOURCE = "ArduPilot parameters"


def is_ardupilot(params: Mapping[str, float]) -> bool:
    """Whether the parameter set looks like ArduPilot Copter's (FRAME_CLASS or MOT_*)."""
    return "FRAME_CLASS" in params or any(name.startswith("MOT_") for name in params)


def _value(params: Mapping[str, float], name: str, source: str) -> float:
    """The parameter's value, its default when absent, checked against its range."""
    return checked_value(params, name, PARAMETERS[name], source)


def frame_name(params: Mapping[str, float], source: str = SOURCE) -> str:
    """Motor layout (:data:`tether_companion.physics.frames.FRAMES`) of FRAME_CLASS/TYPE."""
    frame_class = _value(params, "FRAME_CLASS", source)
    frame_type = _value(params, "FRAME_TYPE", source)
    name = ardupilot_frame(int(frame_class), int(frame_type))
    if name is None or not frame_class.is_integer() or not frame_type.is_integer():
        raise ConfigError(
            source,
            "FRAME_CLASS",
            frame_class,
            f"with FRAME_TYPE {frame_type:g} is not a supported multicopter frame "
            "(quad/hexa/octa X, +; quad H, V; Y6; octaquad X, +)",
        )
    return name


def pwm_range_us(params: Mapping[str, float], source: str = SOURCE) -> tuple[float, float]:
    """MOT_PWM_MIN/MAX [us]; both 0 means the throttle channel's RC3_MIN/RC3_MAX (ArduPilot's
    fallback in ``AP_MotorsMulticopter``)."""
    low, high = _value(params, "MOT_PWM_MIN", source), _value(params, "MOT_PWM_MAX", source)
    names = ("MOT_PWM_MIN", "MOT_PWM_MAX")
    if low == 0.0 and high == 0.0:
        low, high = _value(params, "RC3_MIN", source), _value(params, "RC3_MAX", source)
        names = ("RC3_MIN", "RC3_MAX")
    if low >= high:
        raise ConfigError(source, names[0], low, f"must be < {names[1]} ({high:g})")
    return low, high


def thrust_curve(
    params: Mapping[str, float], mass_kg: float, n_motors: int, source: str = SOURCE
) -> ThrustCurve:
    """One motor's curve as ArduPilot linearises it, scaled by the hover throttle (see module
    docstring)."""
    spin_min = _value(params, "MOT_SPIN_MIN", source)
    spin_max = _value(params, "MOT_SPIN_MAX", source)
    if spin_min >= spin_max:
        raise ConfigError(
            source, "MOT_SPIN_MIN", spin_min, f"must be < MOT_SPIN_MAX ({spin_max:g})"
        )
    expo = _value(params, "MOT_THST_EXPO", source)
    hover = _value(params, "MOT_THST_HOVER", source)
    low, high = pwm_range_us(params, source)
    full_thrust_n = mass_kg * GRAVITY_MPS2 / (n_motors * hover)
    span = high - low
    return ThrustCurve(
        command_unit="pwm_us",
        pwm_min_us=low + spin_min * span,
        pwm_max_us=low + spin_max * span,
        command_full_scale=1.0,
        coefficients_n=(0.0, full_thrust_n * (1.0 - expo), full_thrust_n * expo),
    )


def battery_compensation(
    params: Mapping[str, float], source: str = SOURCE
) -> BatteryCompensation | None:
    """MOT_BAT_VOLT_MAX/MIN as ArduPilot uses them, or None when compensation is off."""
    high = _value(params, "MOT_BAT_VOLT_MAX", source)
    low = _value(params, "MOT_BAT_VOLT_MIN", source)
    if high <= 0.0 or low >= high:
        return None
    return BatteryCompensation(voltage_max_v=high, voltage_min_v=max(low, 0.6 * high))
