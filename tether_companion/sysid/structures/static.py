"""Static polynomial per motor (Martins 2019 eq. 6 form): ``T = sum_i f(cmd_i)``,
``f(cmd) = c0 + c1 cmd + c2 cmd^2`` with ``cmd`` the normalised throttle in [0, 1].

All motors share one curve (same motor, ESC and propeller on every arm), so the fit is a
three-parameter linear least squares of the total thrust on ``(n, sum cmd_i, sum cmd_i^2)``
with the coefficients held non-negative (thrust never falls with command). The result is a
:class:`~tether_companion.physics.thrust.ThrustCurve`, the vehicle profile's own format. It has
no dynamics, so its prediction is its simulation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import lsq_linear

from tether_companion.physics.thrust import ThrustCurve
from tether_companion.sysid.processing import IdData
from tether_companion.sysid.structures.base import FitContext

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class StaticFit:
    """A fitted per-motor static curve."""

    curve: ThrustCurve
    n_motors: int
    structure: str = "static"
    orders: str = "quadratic per motor"

    @property
    def n_params(self) -> int:
        """Three curve coefficients."""
        return 3

    def simulate(self, pwm_us: FloatArray) -> FloatArray:
        """Total thrust [N], shape (n,), summed over the motors' curves."""
        return np.sum(self.curve.thrust_n(pwm_us), axis=1)

    def predict(self, pwm_us: FloatArray, thrust_n: FloatArray, k: int) -> FloatArray:
        """A static model ignores past outputs: the prediction is the simulation."""
        return self.simulate(pwm_us)

    def to_mapping(self) -> dict[str, Any]:
        """The curve in the vehicle profile's ``thrust_curve`` format."""
        curve = asdict(self.curve)
        curve["coefficients_n"] = [float(c) for c in curve["coefficients_n"]]
        return {
            "kind": "static",
            "structure": self.structure,
            "n_motors": self.n_motors,
            "thrust_curve": curve,
        }


def fit_static(experiments: Sequence[IdData], context: FitContext) -> StaticFit:
    """Least-squares shared quadratic curve (see module docstring)."""
    shape = ThrustCurve(
        pwm_min_us=context.pwm_min_us, pwm_max_us=context.pwm_max_us, command_full_scale=1.0
    )
    pwm = np.concatenate([e.pwm_us for e in experiments])
    thrust = np.concatenate([e.thrust_n for e in experiments])
    cmd = shape.command(pwm)
    design = np.column_stack(
        [np.full(len(thrust), pwm.shape[1]), cmd.sum(axis=1), (cmd**2).sum(axis=1)]
    )
    result = lsq_linear(design, thrust, bounds=(0.0, np.inf))
    if not result.success:
        raise ArithmeticError(f"static curve least squares failed: {result.message}")
    coefficients = tuple(float(c) for c in result.x)
    curve = ThrustCurve(
        pwm_min_us=context.pwm_min_us,
        pwm_max_us=context.pwm_max_us,
        command_full_scale=1.0,
        coefficients_n=coefficients,
    )
    return StaticFit(curve=curve, n_motors=pwm.shape[1])
