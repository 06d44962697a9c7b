"""Static input nonlinearity ahead of the linear dynamics (a Hammerstein model).

A rotor's thrust grows with the square of its speed, so thrust is close to quadratic in the
throttle command (Martins eq. 6). A linear model from PWM to thrust fits that curve only
near one operating point. With ``kind = "quadratic"`` the linear dynamics get two inputs per
motor, the normalised throttle ``cmd_i`` in [0, 1] and ``cmd_i^2``: every motor's
``lag(c0 + c1 cmd_i + c2 cmd_i^2)`` is then exactly a linear system of these inputs, and the
curve's coefficients are estimated together with the dynamics. ``kind = "pwm"`` feeds the
PWM itself [us], as in the paper.
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

    kind: str = spec("pwm", choices=INPUT_MAPS, doc="'pwm' (us) or 'quadratic' (cmd and cmd^2)")
    pwm_min_us: float = spec(1000.0, minimum=500.0, maximum=2500.0, doc="PWM at zero command [us]")
    pwm_max_us: float = spec(2000.0, minimum=500.0, maximum=2500.0, doc="PWM at full command [us]")

    def validate(self) -> None:
        """The PWM span must not be empty."""
        if self.pwm_max_us <= self.pwm_min_us:
            raise ConfigError(
                "", "pwm_max_us", self.pwm_max_us, f"must be > pwm_min_us ({self.pwm_min_us})"
            )

    def inputs(self, data: IdData) -> FloatArray:
        """Model inputs from processed data: PWM, shape (n, 4), or ``[cmd, cmd^2]``, shape
        (n, 8), from the separately filtered ``cmd`` and ``cmd^2``."""
        if self.kind == "pwm":
            return data.pwm_us
        return np.hstack([data.command, data.command_sq])

    def map_pwm(self, pwm_us: FloatArray) -> FloatArray:
        """Model inputs from one PWM sample, shape (n_motors,) [us] -> (n_inputs,)."""
        pwm = np.asarray(pwm_us, dtype=float)
        if self.kind == "pwm":
            return pwm
        cmd = normalised_command(pwm, (self.pwm_min_us, self.pwm_max_us))
        return np.concatenate([cmd, cmd * cmd])

    def inputs_per_motor(self) -> int:
        """Model inputs per motor: 1 (pwm) or 2 (quadratic)."""
        return 1 if self.kind == "pwm" else 2

    def to_mapping(self) -> dict[str, Any]:
        """Plain data for the thrust-model YAML file."""
        return {
            "kind": self.kind,
            "pwm_min_us": float(self.pwm_min_us),
            "pwm_max_us": float(self.pwm_max_us),
        }
