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

    def simulate(self, data: IdData) -> FloatArray:
        """Total thrust [N], shape (n,): ``n c0 + c1 sum cmd_i + c2 sum cmd_i^2`` (filtered)."""
        return _design(data) @ np.asarray(self.curve.coefficients_n)

    def predict(self, data: IdData, k: int) -> FloatArray:
        """A static model ignores past outputs: the prediction is the simulation."""
        return self.simulate(data)

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


def _design(data: IdData) -> FloatArray:
    """Regressors ``(n_motors, sum cmd_i, sum cmd_i^2)``, shape (n, 3)."""
    n_motors = data.command.shape[1]
    return np.column_stack(
        [np.full(len(data), float(n_motors)), data.command.sum(axis=1), data.command_sq.sum(axis=1)]
    )


def fit_static(experiments: Sequence[IdData], context: FitContext) -> StaticFit:
    """Least-squares shared quadratic curve (see module docstring)."""
    design = np.vstack([_design(e) for e in experiments])
    thrust = np.concatenate([e.thrust_n for e in experiments])
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
    return StaticFit(curve=curve, n_motors=experiments[0].command.shape[1])
