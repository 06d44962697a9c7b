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


def cable_direction(position_ned_m: FloatArray) -> tuple[FloatArray, float]:
    """Unit vector from the anchor to the drone (NED), shape (3,), and the distance [m]."""
    pn, pe, pd = float(position_ned_m[0]), float(position_ned_m[1]), float(position_ned_m[2])
    length = math.sqrt(pn * pn + pe * pe + pd * pd)
    return np.array((pn / length, pe / length, pd / length)), length


def _accel_and_jacobians(
    position_ned_m: FloatArray,
    tension_n: float,
    rotation_ned_to_body: FloatArray,
    thrust_n: float,
    mass_kg: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``h_acc`` [m/s^2] shape (3,), ``d h_acc/d p`` shape (3, 3), ``d h_acc/d f_c`` shape (3,)."""
    u, length = cable_direction(position_ned_m)
    ru = rotation_ned_to_body @ u
    inv_m = 1.0 / mass_kg
    accel = -tension_n * inv_m * ru
    accel[2] -= thrust_n * inv_m
    # R (I - u u^T) = R - (R u) u^T
    d_position = (-tension_n * inv_m / length) * (rotation_ned_to_body - np.outer(ru, u))
    return accel, d_position, -inv_m * ru


class FourStateModel:
    """The paper's 4-state model: position and unknown cable tension.

    Parameters
    ----------
    mass_kg
        Vehicle mass [kg].
    min_cable_length_m
        Below this anchor-to-drone distance the cable direction is undefined and the
        accelerometer update is skipped.
    """

    n = 4
    state_names = ("p_n_m", "p_e_m", "p_d_m", "f_c_n")
    has_tension_state = True

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
        """Specific force ``h_acc(x)`` [m/s^2] shape (3,) and its Jacobian shape (3, 4).

        ``tension_n`` is ignored: the tension is the state's fourth component.
        """
        accel, d_position, d_tension = _accel_and_jacobians(
            x[POSITION], float(x[F_C]), rotation_ned_to_body, thrust_n, self.mass_kg
        )
        jac = np.empty((3, 4))
        jac[:, :3] = d_position
        jac[:, 3] = d_tension
        return accel, jac

    def tension_n(self, x: FloatArray, known_tension_n: float = math.nan) -> float:
        """Tension of the state [N]."""
        return float(x[F_C])


class ThreeStateModel:
    """The 3-state model of the authors' earlier work: position only, tension known."""

    n = 3
    state_names = ("p_n_m", "p_e_m", "p_d_m")
    has_tension_state = False

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
        """Specific force ``h_acc(x)`` [m/s^2] shape (3,) and its Jacobian shape (3, 3), given
        the known tension ``tension_n`` [N]."""
        accel, d_position, _ = _accel_and_jacobians(
            x, tension_n, rotation_ned_to_body, thrust_n, self.mass_kg
        )
        return accel, d_position

    def tension_n(self, x: FloatArray, known_tension_n: float = math.nan) -> float:
        """The known tension [N] (the state has none)."""
        return known_tension_n


def altimeter(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Height above the anchor ``h_alt(x) = -p_d`` [m], shape (1,), and its Jacobian (1, n)."""
    jac = np.zeros((1, x.size))
    jac[0, P_D] = -1.0
    return np.array((-x[P_D],)), jac


TetherModel = FourStateModel | ThreeStateModel
