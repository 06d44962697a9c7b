"""Forces of a catenary tether (Martins 2019, section 6): the tensions at its ends, the curve
from the tension the cable applies to the drone (the inverse problems, both of
:mod:`tether_companion.physics.catenary`'s cases), and that force in the NED world frame.

Same plane and sign conventions as :mod:`tether_companion.physics.catenary`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from tether_companion.physics.catenary import (
    CatenaryCurve,
    EndTensions,
    FloatArray,
    check_finite,
    check_weight,
    solve_known_length,
)


def end_tensions(curve: CatenaryCurve, weight_per_length_n_per_m: float) -> EndTensions:
    """Tensions at both ends of ``curve`` for a cable of weight ``w`` per length (eqs. 11-13).

    Horizontal tension ``w a`` (eq. 11); vertical force on the anchor ``w s1`` and on the
    drone ``-w s2`` with signed arc lengths (eq. 12 with the sign the geometry gives);
    magnitudes ``w sqrt(a^2 + s^2)`` (eq. 13). The two ends and the cable's weight
    ``w (s2 - s1)`` balance.

    Raises
    ------
    ValueError
        ``weight_per_length_n_per_m`` not finite or ``<= 0``.
    """
    w = check_weight(weight_per_length_n_per_m)
    return EndTensions(
        horizontal_n=w * curve.a_m,
        on_anchor_vertical_n=w * curve.s1_m,
        on_drone_vertical_n=-w * curve.s2_m,
        anchor_n=w * math.hypot(curve.a_m, curve.s1_m),
        drone_n=w * math.hypot(curve.a_m, curve.s2_m),
    )


def horizontal_tension_components_n(
    horizontal_n: float, direction_rad: float
) -> tuple[float, float]:
    """Split a horizontal tension into x and y components (eqs. 14-15) [N].

    ``direction_rad`` is the angle ``beta`` of the horizontal force from the world x axis.
    """
    return math.cos(direction_rad) * horizontal_n, math.sin(direction_rad) * horizontal_n


# ---------------------------------------------------------------------------------------------
# section 6: the curve from the tension on the drone


def _check_drone_tension(horizontal_n: float, down_n: float, w: float) -> tuple[float, float]:
    h = check_finite("horizontal_n", horizontal_n)
    v = check_finite("down_n", down_n)
    if h < 0.0:
        raise ValueError(f"horizontal_n is a magnitude and must be >= 0, got {h!r}")
    return h / w, v / w


def _a_asinh_s_over_a(a: float, s: float) -> float:
    """``a asinh(s/a)`` [m] with its ``a -> 0`` limit 0 (eqs. 64 and 71)."""
    return a * math.asinh(s / a) if a > 0.0 else 0.0


def curve_from_tension_lowest_point_at_anchor(
    horizontal_n: float, down_n: float, weight_per_length_n_per_m: float
) -> CatenaryCurve:
    """Case 1 inverse (section 6.1, eqs. 57-64): the curve from the cable's force on the drone.

    Parameters
    ----------
    horizontal_n
        Magnitude of the horizontal force of the cable on the drone [N], ``>= 0``.
    down_n
        Downward component of the cable's force on the drone [N] (NED ``d``), ``>= 0`` in this
        case (the cable rises from the anchor to the drone).
    weight_per_length_n_per_m
        Cable weight per length [N/m], ``> 0``.

    Returns
    -------
    CatenaryCurve
        ``a = T_H / w`` (eq. 57), ``s2 = T_V / w`` (eq. 58), ``x0 = 0``, ``c = -a``. The drone
        is at ``r = a asinh(s2/a)`` (eq. 59) and ``z = sqrt(a^2 + s2^2) - a`` (eq. 60 with
        ``cosh(asinh(u)) = sqrt(1 + u^2)``), whose ``a -> 0`` limits are 0 and ``s2``
        (eqs. 63-64); see :func:`drone_point`.

    Raises
    ------
    ValueError
        Non-finite input, negative horizontal tension or ``down_n < 0`` (the cable would pull
        the drone up, which a cable rising from its lowest point cannot do).
    """
    w = check_weight(weight_per_length_n_per_m)
    a, s2 = _check_drone_tension(horizontal_n, down_n, w)
    if s2 < 0.0:
        raise ValueError(
            f"down_n = {down_n!r} < 0: with the lowest point at the anchor the cable pulls the "
            "drone down"
        )
    return CatenaryCurve(a_m=a, x0_m=0.0, c_m=-a, s1_m=0.0, s2_m=s2)


def curve_from_tension_known_length(
    horizontal_n: float, down_n: float, length_m: float, weight_per_length_n_per_m: float
) -> CatenaryCurve:
    """Case 2 inverse (section 6.2, eqs. 65-71): the curve from the force on the drone and L.

    ``a = T_H / w``, ``s2 = T_V / w``, ``s1 = s2 - L`` (eq. 65 with signed arcs); the anchor at
    ``x = 0`` gives ``x0 = a asinh((L - s2)/a)`` (eq. 66) and ``c`` from eq. 69.

    Parameters
    ----------
    horizontal_n
        Magnitude of the horizontal force of the cable on the drone [N], ``>= 0``.
    down_n
        Downward component of the cable's force on the drone [N] (negative: pulls up, the
        drone is below the anchor).
    length_m
        Paid-out cable length [m], ``> 0``.
    weight_per_length_n_per_m
        Cable weight per length [N/m], ``> 0``.

    Raises
    ------
    ValueError
        Non-finite input, negative horizontal tension, or ``length_m <= 0``.
    """
    w = check_weight(weight_per_length_n_per_m)
    a, s2 = _check_drone_tension(horizontal_n, down_n, w)
    length = check_finite("length_m", length_m)
    if length <= 0.0:
        raise ValueError(f"length_m must be > 0, got {length!r}")
    s1 = s2 - length
    x0 = -_a_asinh_s_over_a(a, s1)
    # 0 = a cosh((0 - x0)/a) + c = sqrt(a^2 + s1^2) + c
    c = -math.hypot(a, s1)
    return CatenaryCurve(a_m=a, x0_m=x0, c_m=c, s1_m=s1, s2_m=s2)


def drone_point(curve: CatenaryCurve) -> tuple[float, float]:
    """``(horizontal_m, height_m)`` of the drone end of ``curve`` (eqs. 59-60, 67-68).

    Relative to the anchor (which every curve here passes through):
    ``x = a asinh(s2/a) - a asinh(s1/a)`` and
    ``y = sqrt(a^2 + s2^2) - sqrt(a^2 + s1^2) = (s2 - s1)(s2 + s1) / (sqrt(a^2 + s2^2) +
    sqrt(a^2 + s1^2))``: no cancellation for a flat cable (large ``a``), and finite as
    ``a -> 0`` (limits eqs. 63-64 and 70-71: ``x -> 0``, ``y -> |s2| - |s1|``).
    """
    a, s1, s2 = curve.a_m, curve.s1_m, curve.s2_m
    x = _a_asinh_s_over_a(a, s2) - _a_asinh_s_over_a(a, s1)
    denominator = math.hypot(a, s2) + math.hypot(a, s1)
    y = (s2 - s1) * (s2 + s1) / denominator if denominator > 0.0 else 0.0
    return x, y


# ---------------------------------------------------------------------------------------------
# NED world frame


def plane_coordinates(position_ned_m: ArrayLike) -> tuple[float, float, FloatArray]:
    """The drone's coordinates in the catenary plane from its NED position (anchor origin).

    Returns
    -------
    horizontal_m, height_m, unit_ne
        Horizontal distance [m], height above the anchor ``-d`` [m], and the horizontal unit
        vector from the anchor toward the drone in (north, east), shape (2,) (zeros when the
        drone is straight above the anchor).
    """
    p = np.asarray(position_ned_m, dtype=float)
    horizontal = math.hypot(float(p[0]), float(p[1]))
    unit = p[:2] / horizontal if horizontal > 0.0 else np.zeros(2)
    return horizontal, -float(p[2]), unit


def force_on_drone_ned_n(
    position_ned_m: ArrayLike, length_m: float, weight_per_length_n_per_m: float
) -> FloatArray:
    """Force of a catenary cable of known length on the drone, NED frame [N], shape (3,).

    The cable hangs freely (no ground contact) from the anchor at the NED origin to the drone
    at ``position_ned_m``: case 2 (:func:`solve_known_length`) then :func:`end_tensions`.
    The horizontal part points from the drone toward the anchor; the ``d`` component is
    ``w s2``.

    Raises
    ------
    ValueError
        As :func:`solve_known_length` and :func:`end_tensions` (notably when the cable is
        not longer than the anchor-to-drone distance).
    """
    horizontal, height, unit = plane_coordinates(position_ned_m)
    curve = solve_known_length(horizontal, height, length_m)
    tensions = end_tensions(curve, weight_per_length_n_per_m)
    return np.array(
        [
            tensions.on_drone_horizontal_n * unit[0],
            tensions.on_drone_horizontal_n * unit[1],
            -tensions.on_drone_vertical_n,
        ]
    )
