"""The generated models bound to a cable: which variant (winch length known or the chord),
the constants tuple, and the process models for
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
    """The generated functions of one cable-length variant."""

    force_balance: Generated
    accel: Generated
    tension: Generated
    cable_angle: Generated


KNOWN_LENGTH = CableModels(
    generated.force_balance_known_length,
    generated.accel_known_length,
    generated.tension_known_length,
    generated.cable_angle_known_length,
)
"""The cable's length is an input (the winch reports it)."""
CHORD_LENGTH = CableModels(
    generated.force_balance_chord_length,
    generated.accel_chord_length,
    generated.tension_chord_length,
    generated.cable_angle_chord_length,
)
"""The cable's length is taken as the anchor-to-drone distance (no winch report)."""


@dataclass(slots=True)
class ModelConstants:
    """Constants of the generated models (the tuple ``c``), SI units.

    ``length_m`` is ``nan`` while no winch length is known: the chord variant is used.
    """

    mass_kg: float
    drag_per_s: float
    weight_n_per_m: float
    length_m: float = math.nan

    @property
    def models(self) -> CableModels:
        """The variant for the current length knowledge."""
        return CHORD_LENGTH if math.isnan(self.length_m) else KNOWN_LENGTH

    def values(self) -> tuple[float, float, float, float]:
        """The tuple ``c`` (length 0 when unknown: the chord variant ignores it)."""
        length = 0.0 if math.isnan(self.length_m) else self.length_m
        return (self.mass_kg, self.drag_per_s, self.weight_n_per_m, length)


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
