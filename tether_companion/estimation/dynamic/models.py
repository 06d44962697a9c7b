"""The generated models bound to a cable: which variant (the straight line for a weightless
cable, the catenary for one with weight), the constants tuple, and the process models for
:class:`~tether_companion.estimation.ekf.ExtendedKalmanFilter`.

Pure; the process objects cache the generated derivative between the filter's ``jacobian``
and ``derivative`` calls at the same state (one generated call per prediction).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import generated, state

FloatArray = NDArray[np.float64]
Generated = Callable[
    [Sequence[float], Sequence[float], Sequence[float]],
    tuple[tuple[float, ...], tuple[float, ...]],
]


@dataclass(frozen=True, slots=True)
class CableModels:
    """The generated functions of one cable variant."""

    force_balance: Generated
    accel: Generated
    tension: Generated
    cable_angle: Generated
    winch_length: Generated


STRAIGHT = CableModels(
    generated.force_balance_straight,
    generated.accel_straight,
    generated.tension_straight,
    generated.cable_angle_straight,
    generated.winch_length_straight,
)
"""A weightless cable: the straight line (the taut limit)."""
CATENARY = CableModels(
    generated.force_balance_catenary,
    generated.accel_catenary,
    generated.tension_catenary,
    generated.cable_angle_catenary,
    generated.winch_length_catenary,
)
"""A cable with weight: the exact catenary through anchor and drone."""


@dataclass(slots=True)
class ModelConstants:
    """Constants of the generated models (the tuple ``c``), SI units, and the winch's
    paid-out length ``length_m`` [m] (``nan`` while none is known; the initialisation uses it,
    the models do not: the ends, the weight and the tension fix the curve)."""

    mass_kg: float
    drag_per_s: float
    weight_n_per_m: float
    length_m: float = math.nan

    @property
    def models(self) -> CableModels:
        """The variant for this cable's weight."""
        return CATENARY if self.weight_n_per_m > 0.0 else STRAIGHT

    def values(self) -> tuple[float, float, float]:
        """The tuple ``c``."""
        return (self.mass_kg, self.drag_per_s, self.weight_n_per_m)


UNDEFINED = (ZeroDivisionError, OverflowError, ValueError)
"""What the generated arithmetic raises where a model is undefined (at the anchor, at zero
tension, a catenary parameter so small that ``sinh`` overflows)."""


def evaluate(
    model: Generated, x: FloatArray, u: Sequence[float], c: Sequence[float], rows: int
) -> tuple[FloatArray, FloatArray]:
    """A generated measurement's value (rows,) and Jacobian (rows, 13) at ``x``; ``nan`` where
    the model is undefined there (the update then counts the sample non-finite)."""
    try:
        h, jac = model(x.tolist(), u, c)
    except UNDEFINED:
        return np.full(rows, math.nan), np.full((rows, state.N_STATES), math.nan)
    return np.array(h), np.array(jac).reshape(rows, state.N_STATES)


_V_ROWS = slice(3, 6)


class _GeneratedProcess:
    """``ProcessModel`` over a generated ``(x', dv'/dx)`` function; ``p' = v`` rows fixed."""

    is_random_walk = False

    def __init__(self, constants: ModelConstants) -> None:
        self.constants = constants
        self._base = np.zeros((state.N_STATES, state.N_STATES))
        self._base[state.POSITION, state.VELOCITY] = np.eye(3)
        self._x: FloatArray | None = None
        self._xdot: FloatArray = np.zeros(state.N_STATES)

    def _function(self) -> Generated:
        raise NotImplementedError

    def jacobian(self, x: FloatArray, u: FloatArray | None) -> FloatArray:
        """``df/dx`` at ``(x, u)``, shape (13, 13) (caches ``f`` for :meth:`derivative`)."""
        xdot, dv = self._function()(x.tolist(), u.tolist(), self.constants.values())
        self._x = x
        self._xdot = np.array(xdot, dtype=float)
        jac = self._base.copy()
        jac[_V_ROWS] = np.array(dv, dtype=float).reshape(3, state.N_STATES)
        return jac

    def derivative(self, x: FloatArray, u: FloatArray | None) -> FloatArray:
        """``f(x, u)``, shape (13,)."""
        if x is not self._x:
            self.jacobian(x, u)
        return self._xdot


class ForceBalanceProcess(_GeneratedProcess):
    """Formulation (a): ``u = (R_v^b row-major, thrust_n)``; the force balance predicts."""

    def _function(self) -> Generated:
        return self.constants.models.force_balance


class InertialProcess(_GeneratedProcess):
    """Formulation (b): ``u = (R_v^b row-major, f_x, f_y, f_z)``; the accelerometer predicts."""

    def _function(self) -> Generated:
        return generated.inertial
