"""The generated models bound to a cable: which variant (the straight line for a weightless
cable, the catenary for one with weight) and the constants tuple. The bank members
(:mod:`~tether_companion.estimation.dynamic.member`) call the generated process function
directly. Pure.
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
    anchor_tension: Generated
    cable_angle: Generated
    winch_length: Generated


STRAIGHT = CableModels(
    generated.force_balance_straight,
    generated.accel_straight,
    generated.tension_straight,
    generated.anchor_tension_straight,
    generated.cable_angle_straight,
    generated.winch_length_straight,
)
"""A weightless cable: the straight line (the taut limit)."""


def rests_on_ground(x: Sequence[float], c: Sequence[float]) -> bool:
    """Whether the cable of state ``x`` (constants ``c``) lies partly on the anchor's level:
    the free catenary through anchor and drone with the state's horizontal tension ``H``
    would have its lowest point between them, below the anchor; on the ground it touches
    down at ``x_t = a - c acosh(1 + b/c)`` > 0 instead (``c = H/w``, span ``a``, height
    ``b``; derive.py). False for a weightless cable, a drone at or below the anchor's level,
    right above it, or without tension."""
    weight = c[2]
    span = math.hypot(x[0], x[1])
    height = -x[2]
    tension = x[state.TENSION]
    if weight <= 0.0 or height <= 0.0 or span <= 0.0 or tension <= 0.0:
        return False
    parameter = tension * span / (math.hypot(span, height) * weight)
    return span > parameter * math.acosh(1.0 + height / parameter)


SLACK_FLOOR_N = 1e-3
"""The chord tension [N] below which a heavy cable's models continue linearly
(:func:`_free_or_grounded`)."""


def _free_or_grounded(free: Generated, grounded: Generated) -> Generated:
    """The generated ``free`` model, or ``grounded`` where the cable rests on the ground.

    Below a chord tension of :data:`SLACK_FLOOR_N` (a cable at or past slack; a cable pulls,
    it does not push) the resting cable's model at that floor, continued linearly in the
    tension with its Jacobian there: at a chord tension near 0 a heavy cable lies on the
    ground up to below the drone and hangs straight up (force ``H`` horizontally and
    ``w b + H`` at the drone, smooth in ``T_ch``). The free catenary evaluated at ``T_ch < 0``
    is its mirror image, a cable bowed upward that pushes, whose tension at the drone grows
    without bound as ``T_ch -> 0-`` (``dh/dT_ch`` 11-110 instead of ~0.9 on the light 1 N
    figure-8): a filter that went there fused the winch's measured tension with no effect
    and stayed slack the whole flight (docs/estimation-history.md, slack12)."""

    def model(
        x: Sequence[float], u: Sequence[float], c: Sequence[float]
    ) -> tuple[tuple[float, ...], tuple[float, ...]]:
        tension = x[state.TENSION]
        if tension < SLACK_FLOOR_N and c[2] > 0.0 and -x[2] > 0.0:
            at_floor = list(x)
            at_floor[state.TENSION] = SLACK_FLOOR_N
            value, jac = grounded(at_floor, u, c)
            step = tension - SLACK_FLOOR_N
            n = state.N_STATES
            return tuple(
                v + jac[row * n + state.TENSION] * step for row, v in enumerate(value)
            ), jac
        return (grounded if rests_on_ground(x, c) else free)(x, u, c)

    model.__doc__ = free.__doc__
    return model


CATENARY = CableModels(
    _free_or_grounded(generated.force_balance_catenary, generated.force_balance_grounded),
    _free_or_grounded(generated.accel_catenary, generated.accel_grounded),
    _free_or_grounded(generated.tension_catenary, generated.tension_grounded),
    _free_or_grounded(generated.anchor_tension_catenary, generated.anchor_tension_grounded),
    _free_or_grounded(generated.cable_angle_catenary, generated.cable_angle_grounded),
    _free_or_grounded(generated.winch_length_catenary, generated.winch_length_grounded),
)
"""A cable with weight: the exact catenary through anchor and drone, resting on the anchor's
level (a winch on the ground) where the free curve would dip below it."""


UNDEFINED = (ZeroDivisionError, OverflowError, ValueError)
"""What the generated arithmetic raises where a model is undefined (at the anchor, at zero
tension, a catenary parameter so small that ``sinh`` overflows)."""


@dataclass(slots=True)
class ModelConstants:
    """Constants of the generated models (the tuple ``c``), SI units, the winch's
    paid-out length ``length_m`` [m] (``nan`` while none is known; the initialisation uses it,
    the models do not: the ends, the weight and the tension fix the curve), and whether a
    measured tension (a load cell, the winch's) has been fused (``tension_measured``: the
    tension's variance is then a measurement's, not only the weak pull's reading,
    :mod:`~tether_companion.estimation.dynamic.sag_range`)."""

    mass_kg: float
    drag_per_s: float
    weight_n_per_m: float
    length_m: float = math.nan
    tension_measured: bool = False

    @property
    def models(self) -> CableModels:
        """The variant for this cable's weight."""
        return CATENARY if self.weight_n_per_m > 0.0 else STRAIGHT

    def values(self) -> tuple[float, float, float]:
        """The tuple ``c``."""
        return (self.mass_kg, self.drag_per_s, self.weight_n_per_m)

    def tension_at_drone(self, x: list[float], p: FloatArray) -> tuple[float, float]:
        """The cable's tension at the drone [N] and its variance [N^2] (first order through
        the model's Jacobian) at the state's values ``x`` with covariance ``p``; the chord
        tension where the curve is undefined (at the anchor), 0 N for a chord tension <= 0
        (a slack cable: no curve; its catenary overflowed to 1e98 N on the sagging circle)."""
        tension, variance = max(x[state.TENSION], 0.0), float(p[state.TENSION, state.TENSION])
        if tension > 0.0:
            try:
                (tension,), jac = self.models.tension(x, (), self.values())
            except UNDEFINED:
                return tension, variance
            jac_row = np.array(jac)
            variance = float(jac_row @ (p @ jac_row))
        return tension, variance


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
