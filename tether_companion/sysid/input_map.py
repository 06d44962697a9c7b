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

from tether_companion.physics.thrust import ThrustCurve

FloatArray = NDArray[np.float64]

INPUT_MAPS = ("quadratic", "pwm")


@dataclass(frozen=True)
class InputMap:
    """Map PWM [us] to the linear model's inputs.

    Attributes
    ----------
    kind
        ``"pwm"`` (identity, inputs in us) or ``"quadratic"`` (static thrust per motor [N]).
    curve
        For ``"quadratic"``: the curve whose ``c1, c2`` shape the map (``c0`` is dropped:
        a constant belongs to the operating point).
    """

    kind: str = "pwm"
    curve: ThrustCurve | None = None

    def __call__(self, pwm_us: FloatArray) -> FloatArray:
        """Model inputs, same shape as ``pwm_us``."""
        pwm = np.asarray(pwm_us, dtype=float)
        if self.kind == "pwm" or self.curve is None:
            return pwm
        cmd = self.curve.command(pwm)
        _, c1, c2 = self.curve.coefficients_n
        return cmd * (c1 + c2 * cmd)

    @property
    def unit(self) -> str:
        """Unit of the mapped inputs."""
        return "us" if self.kind == "pwm" else "N"

    def to_mapping(self) -> dict[str, Any]:
        """Plain data for the thrust-model YAML file."""
        if self.kind == "pwm" or self.curve is None:
            return {"kind": "pwm"}
        c0, c1, c2 = self.curve.coefficients_n
        return {
            "kind": "quadratic",
            "pwm_min_us": float(self.curve.pwm_min_us),
            "pwm_max_us": float(self.curve.pwm_max_us),
            "coefficients_n": [float(c1), float(c2)],
        }


def quadratic_shape(curve: ThrustCurve) -> InputMap:
    """The quadratic input map shaped by ``curve`` (falls back to ``cmd`` when c1 = c2 = 0)."""
    _, c1, c2 = curve.coefficients_n
    if c1 == 0.0 and c2 == 0.0:
        c1 = 1.0
    shaped = ThrustCurve(
        pwm_min_us=curve.pwm_min_us,
        pwm_max_us=curve.pwm_max_us,
        command_full_scale=1.0,
        coefficients_n=(0.0, c1, c2),
    )
    return InputMap(kind="quadratic", curve=shaped)
