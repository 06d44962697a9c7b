"""Static input nonlinearity ahead of the linear dynamics (a Hammerstein model).

A rotor's thrust grows with the square of its speed, so thrust is close to quadratic in the
throttle command (Martins eq. 6). A linear model from PWM to thrust fits that curve only
near one operating point. Feeding the linear dynamics with each motor's *static* thrust
``v_i = c1 cmd_i + c2 cmd_i^2`` (``cmd`` the normalised throttle in [0, 1]; the shape
``c1, c2`` from the static per-motor fit) leaves them only the motor lag to learn. The
identity map (``kind = "pwm"``) feeds the PWM itself [us], as in the paper.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tether_companion.config import ConfigError, spec
from tether_companion.sysid.processing import IdData, normalised_command

FloatArray = NDArray[np.float64]

INPUT_MAPS = ("quadratic", "pwm")


@dataclass(frozen=True)
class InputMap:
    """Map PWM [us] to the linear model's inputs (see module docstring)."""

    kind: str = spec("pwm", choices=INPUT_MAPS, doc="'pwm' (us) or 'quadratic' (N per motor)")
    pwm_min_us: float = spec(1000.0, minimum=500.0, maximum=2500.0, doc="PWM at zero command [us]")
    pwm_max_us: float = spec(2000.0, minimum=500.0, maximum=2500.0, doc="PWM at full command [us]")
    coefficients_n: tuple[float, float] = spec(
        (1.0, 0.0), doc="(c1, c2) of v = c1 cmd + c2 cmd^2 [N] (quadratic only)"
    )

    def validate(self) -> None:
        """The PWM span must not be empty."""
        if self.pwm_max_us <= self.pwm_min_us:
            raise ConfigError(
                "", "pwm_max_us", self.pwm_max_us, f"must be > pwm_min_us ({self.pwm_min_us})"
            )

    def inputs(self, data: IdData) -> FloatArray:
        """Model inputs from processed data, shape (n, 4): PWM, or ``c1 cmd + c2 cmd^2`` built
        from the separately filtered ``cmd`` and ``cmd^2``."""
        if self.kind == "pwm":
            return data.pwm_us
        c1, c2 = self.coefficients_n
        return c1 * data.command + c2 * data.command_sq

    def map_pwm(self, pwm_us: FloatArray) -> FloatArray:
        """Model inputs from raw pulse widths [us] (any shape)."""
        pwm = np.asarray(pwm_us, dtype=float)
        if self.kind == "pwm":
            return pwm
        cmd = normalised_command(pwm, (self.pwm_min_us, self.pwm_max_us))
        c1, c2 = self.coefficients_n
        return cmd * (c1 + c2 * cmd)

    @property
    def unit(self) -> str:
        """Unit of the mapped inputs."""
        return "us" if self.kind == "pwm" else "N"

    def to_mapping(self) -> dict[str, Any]:
        """Plain data for the thrust-model YAML file."""
        return {
            "kind": self.kind,
            "pwm_min_us": float(self.pwm_min_us),
            "pwm_max_us": float(self.pwm_max_us),
            "coefficients_n": [float(c) for c in self.coefficients_n],
        }


def quadratic_shape(
    coefficients_n: tuple[float, float, float], pwm_range_us: tuple[float, float]
) -> InputMap:
    """The quadratic map shaped by a static curve's ``(c0, c1, c2)`` (``cmd`` if c1 = c2 = 0)."""
    _, c1, c2 = coefficients_n
    if c1 == 0.0 and c2 == 0.0:
        c1 = 1.0
    return InputMap("quadratic", pwm_range_us[0], pwm_range_us[1], (float(c1), float(c2)))
