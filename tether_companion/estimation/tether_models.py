"""Measurement models of a drone on a taut, straight tether (Al-Radaideh & Sun 2021, sec. 2-3).

State layouts (declared once, here):

* 4-state: ``x = (p_n, p_e, p_d, f_c)``: position of the drone relative to the anchor in NED
  [m] and cable tension magnitude [N];
* 3-state: ``x = (p_n, p_e, p_d)``; the tension is known (a load cell) and passed in.

With ``u = p / |p|`` (anchor to drone), the cable pulls the drone with ``-f_c u`` (NED). With
``R = R_v^b(phi, theta, psi)`` (paper eq. 2) and total thrust ``T``, the accelerometer's
specific force in the FRD body frame is, **in SI units** [m/s^2],

    h_acc(x) = ( [0, 0, -T] + R (-f_c u) ) / m

which is ``g`` times the architecture's (and the paper's) form in units of g; we keep SI
inside and convert the paper's noise figures instead (see ``docs/estimation.md``). Jacobians:

    d h_acc / d p   = -(f_c / m) R (I - u u^T) / |p|
    d h_acc / d f_c = -R u / m

The altimeter is the tilt-corrected downward rangefinder: ``h_alt(x) = -p_d`` (height above
the anchor) with ``d h_alt / d p = [0, 0, -1]``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

P_N, P_E, P_D, F_C = 0, 1, 2, 3
"""Indices of the state vector (the 3-state model uses the first three)."""
POSITION = slice(P_N, P_D + 1)
"""Slice of the position block of either state vector."""


def accel_values(
    position_ned_m: list[float],
    tension_n: float,
    rotation_rows: list[list[float]],
    thrust_n: float,
    mass_kg: float,
    tension_column: bool,
) -> tuple[tuple[float, float, float], list[float]]:
    """``h_acc`` [m/s^2] (3 values) and its Jacobian's entries row by row (3 x 4 with the
    ``d/d f_c`` column, else 3 x 3), as Python floats; ``rotation_rows`` is ``R_v^b`` row by row.

    Written in scalars (the EKF evaluates it at every IMU tick and numpy's per-call overhead
    would dominate 3x3 arithmetic): with ``a = R u``,
    ``h = -(f_c/m) a - (0, 0, T/m)``, ``dh/dp = -(f_c/(m |p|)) (R - a u^T)``, ``dh/df_c = -a/m``.
    """
    pn, pe, pd = position_ned_m
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation_rows
    inv_length = 1.0 / math.sqrt(pn * pn + pe * pe + pd * pd)
    un, ue, ud = pn * inv_length, pe * inv_length, pd * inv_length
    a0 = r00 * un + r01 * ue + r02 * ud
    a1 = r10 * un + r11 * ue + r12 * ud
    a2 = r20 * un + r21 * ue + r22 * ud
    k = -tension_n / mass_kg
    kl = k * inv_length
    accel = (k * a0, k * a1, k * a2 - thrust_n / mass_kg)
    if tension_column:
        inv_m = -1.0 / mass_kg
        return accel, [
            kl * (r00 - a0 * un), kl * (r01 - a0 * ue), kl * (r02 - a0 * ud), inv_m * a0,
            kl * (r10 - a1 * un), kl * (r11 - a1 * ue), kl * (r12 - a1 * ud), inv_m * a1,
            kl * (r20 - a2 * un), kl * (r21 - a2 * ue), kl * (r22 - a2 * ud), inv_m * a2,
        ]  # fmt: skip
    return accel, [
        kl * (r00 - a0 * un), kl * (r01 - a0 * ue), kl * (r02 - a0 * ud),
        kl * (r10 - a1 * un), kl * (r11 - a1 * ue), kl * (r12 - a1 * ud),
        kl * (r20 - a2 * un), kl * (r21 - a2 * ue), kl * (r22 - a2 * ud),
    ]  # fmt: skip


class _StraightTetherModel:
    """Accelerometer model shared by both state layouts (the tension is a state or given).

    Parameters
    ----------
    mass_kg
        Vehicle mass [kg].
    min_cable_length_m
        Below this anchor-to-drone distance the cable direction is undefined and the
        accelerometer update is skipped.
    """

    n: int
    """State dimension."""
    has_tension_state: bool
    """Whether the tension is the state's component ``F_C``."""

    def __init__(self, mass_kg: float, min_cable_length_m: float = 0.1) -> None:
        self.mass_kg = float(mass_kg)
        self.min_cable_length_m = float(min_cable_length_m)

    def accel(
        self,
        x: FloatArray,
        rotation_ned_to_body: FloatArray,
        thrust_n: float,
        tension_n: float = math.nan,
    ) -> tuple[FloatArray, FloatArray]:
        """Specific force ``h_acc(x)`` [m/s^2] shape (3,) and its Jacobian shape (3, n).

        ``tension_n`` [N] is the known tension of the 3-state model; the 4-state model ignores
        it (the tension is the state's fourth component).
        """
        accel, jacobian = self.accel_values(
            x.tolist(), rotation_ned_to_body.tolist(), thrust_n, tension_n
        )
        return np.array(accel), np.array(jacobian).reshape(3, self.n)

    def accel_values(
        self,
        state: list[float],
        rotation_rows: list[list[float]],
        thrust_n: float,
        tension_n: float = math.nan,
    ) -> tuple[tuple[float, float, float], list[float]]:
        """:meth:`accel` on Python floats: ``h_acc`` (3 values) and the Jacobian's 3 x n
        entries row by row (``state`` the n state values, ``rotation_rows`` ``R_v^b`` row by
        row)."""
        if self.has_tension_state:
            tension_n = state[F_C]
        return accel_values(
            state[P_N : P_D + 1],
            tension_n,
            rotation_rows,
            thrust_n,
            self.mass_kg,
            self.has_tension_state,
        )


class FourStateModel(_StraightTetherModel):
    """The paper's 4-state model: position and unknown cable tension."""

    n = 4
    has_tension_state = True

    def tension_n(self, x: FloatArray | list[float], known_tension_n: float = math.nan) -> float:
        """Tension of the state [N]."""
        return float(x[F_C])


class ThreeStateModel(_StraightTetherModel):
    """The 3-state model of the authors' earlier work: position only, tension known."""

    n = 3
    has_tension_state = False

    def tension_n(self, x: FloatArray | list[float], known_tension_n: float = math.nan) -> float:
        """The known tension [N] (the state has none)."""
        return known_tension_n


def altimeter(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Height above the anchor ``h_alt(x) = -p_d`` [m], shape (1,), and its Jacobian (1, n)."""
    jac = np.zeros((1, x.size))
    jac[0, P_D] = -1.0
    return np.array((-x[P_D],)), jac
