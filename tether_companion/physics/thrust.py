"""Static motor thrust curves: PWM pulse width [us] to thrust [N].

A curve is a quadratic in a motor command ``cmd = u * command_full_scale`` where
``u = (pwm - pwm_min) / (pwm_max - pwm_min)`` is clipped to [0, 1]:

    f(cmd) = c0 + c1 * cmd + c2 * cmd**2      [N]

With ``command_full_scale = 65535`` and ``(c0, c1, c2) = (5.485e-4, 1.033e-6, 2.130e-11)``
this is Martins (2019) eq. 6 for a Crazyflie 2.0 (Foerster 2015); with
``command_full_scale = 1`` the coefficients are in normalised throttle.

``command_unit`` says what the flight controller's motor outputs (SERVO_OUTPUT_RAW, log
outputs) carry; ``pwm_min_us`` / ``pwm_max_us`` are in that unit (the names are kept from when
only microseconds existed):

* ``pwm_us``: pulse width in microseconds, 500-2500 (ArduPilot and PX4 PWM outputs);
* ``raw``: an unsigned integer motor command, 0-65535 (Crazyflie firmware);
* ``normalised``: a 0-1 output (PX4 ``actuator_motors``, logs);
* ``dshot``: a DShot throttle value, 0-2047 (48-2047 are throttle steps).

ArduPilot's own curve (``MOT_THST_EXPO``, ``MOT_SPIN_MIN/MAX``) is this quadratic exactly:
see :func:`tether_companion.vehicle_params.ardupilot.thrust_curve`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tether_companion.config import ConfigError, spec

FloatArray = NDArray[np.float64]

COMMAND_UNITS: dict[str, tuple[float, float]] = {
    "pwm_us": (500.0, 2500.0),
    "raw": (0.0, 65535.0),
    "normalised": (0.0, 1.0),
    "dshot": (0.0, 2047.0),
}
"""Motor output units and the range of values each can carry."""


@dataclass(frozen=True)
class ThrustCurve:
    """Quadratic thrust map of one motor (see module docstring)."""

    command_unit: str = spec(
        "pwm_us",
        choices=tuple(COMMAND_UNITS),
        doc="what the motor outputs carry: pwm_us (500-2500), raw (0-65535), normalised (0-1), "
        "dshot (0-2047)",
    )
    pwm_min_us: float = spec(
        1000.0, minimum=0.0, doc="output at zero command, in command_unit (us for pwm_us)"
    )
    pwm_max_us: float = spec(
        2000.0, minimum=0.0, doc="output at full command, in command_unit (us for pwm_us)"
    )
    command_full_scale: float = spec(1.0, exclusive_minimum=0.0, doc="command value at pwm_max_us")
    coefficients_n: tuple[float, float, float] = spec(
        (0.0, 0.5, 7.5), doc="(c0, c1, c2) of f = c0 + c1*cmd + c2*cmd^2 [N]"
    )

    def validate(self) -> None:
        """Refuse curves that are not usable (outputs outside the unit's range, empty span,
        thrust falling with command)."""
        low, high = COMMAND_UNITS[self.command_unit]
        for key, value in (("pwm_min_us", self.pwm_min_us), ("pwm_max_us", self.pwm_max_us)):
            if not low <= value <= high:
                raise ConfigError(
                    "",
                    key,
                    value,
                    f"must be a number >= {low} and <= {high} (command_unit {self.command_unit!r})",
                )
        if self.pwm_max_us <= self.pwm_min_us:
            raise ConfigError(
                "", "pwm_max_us", self.pwm_max_us, f"must be > pwm_min_us ({self.pwm_min_us})"
            )
        c0, c1, c2 = self.coefficients_n
        full = self.command_full_scale
        if c1 < 0.0 or c1 + 2.0 * c2 * full < 0.0:
            raise ConfigError(
                "",
                "coefficients_n",
                self.coefficients_n,
                "thrust must not decrease with command over [0, full scale]",
            )
        if c0 < 0.0:
            raise ConfigError(
                "",
                "coefficients_n",
                self.coefficients_n,
                "c0 (thrust at zero command) must be >= 0",
            )

    def command(self, pwm_us: ArrayLike) -> FloatArray:
        """Motor command ``u * command_full_scale`` for pulse widths [us] (clipped to range)."""
        u = (np.asarray(pwm_us, dtype=float) - self.pwm_min_us) / (
            self.pwm_max_us - self.pwm_min_us
        )
        return np.clip(u, 0.0, 1.0) * self.command_full_scale

    def thrust_n(self, pwm_us: ArrayLike, voltage_ratio: float = 1.0) -> FloatArray:
        """Steady-state thrust [N] for pulse widths [us], element-wise.

        ``voltage_ratio`` is the battery voltage over the one the curve holds at
        (:class:`tether_companion.physics.battery.BatteryCompensation`): the motor command
        is scaled by it, as ArduPilot's thrust linearisation assumes.
        """
        cmd = self.command(pwm_us) * voltage_ratio
        c0, c1, c2 = self.coefficients_n
        return c0 + cmd * (c1 + c2 * cmd)

    @property
    def max_thrust_n(self) -> float:
        """Thrust at full command [N]."""
        return float(self.thrust_n(self.pwm_max_us))

    def pwm_for_thrust(self, thrust_n: ArrayLike) -> FloatArray:
        """Inverse map: pulse width [us] giving ``thrust_n`` (clipped to the curve's range)."""
        c0, c1, c2 = self.coefficients_n
        f = np.clip(np.asarray(thrust_n, dtype=float), c0, self.max_thrust_n)
        if c2 == 0.0:
            cmd = (f - c0) / c1 if c1 > 0.0 else np.zeros_like(f)
        else:
            cmd = (-c1 + np.sqrt(np.maximum(c1 * c1 + 4.0 * c2 * (f - c0), 0.0))) / (2.0 * c2)
        u = cmd / self.command_full_scale
        return self.pwm_min_us + np.clip(u, 0.0, 1.0) * (self.pwm_max_us - self.pwm_min_us)


def hover_pwm_us(curve: ThrustCurve, mass_kg: float, n_motors: int, gravity_mps2: float) -> float:
    """Pulse width [us] at which ``n_motors`` equal motors hold ``mass_kg`` in a hover."""
    per_motor = mass_kg * gravity_mps2 / n_motors
    if per_motor > curve.max_thrust_n:
        return math.inf
    return float(curve.pwm_for_thrust(per_motor))
