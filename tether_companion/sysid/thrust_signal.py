"""The identification output: total rotor thrust [N] from the accelerometer (paper eq. 36).

An accelerometer at the centre of mass reads the specific force (paper eq. 20)

    a_body = (F_thrust + F_cable) / m,   F_thrust = (0, 0, -T) in FRD body,

so gravity cancels and, with no cable, ``T = -m a_z``: the attitude is not needed. (The
paper's eq. 36 multiplies by ``R_b^v``, which would give the thrust's vertical component in
NED, not the total thrust the motors make.)

On a tethered flight the cable adds ``F_cable / m``: the z reading becomes ``(-T + c_z) / m``
with ``c_z`` the cable force's body-z component (positive when the cable pulls down, i.e.
the drone is above its anchor), so ``-m a_z`` under-reads the thrust by ``c_z``: by the full
tension when the cable hangs straight down. Two ways out:

1. fly the identification untethered or with the tether slack (``c_z`` ~ 0; default);
2. give the tension ``F`` (a constant-tension winch setting, or a load cell column in the
   log). Thrust has no body x/y component, so the accelerometer's x and y read the cable
   alone, ``c_x = m a_x``, ``c_y = m a_y``, and ``c_z = sqrt(F^2 - c_x^2 - c_y^2)``; then
   ``T = c_z - m a_z``.

Rotor drag on the horizontal readings is neglected.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def cable_body_z_n(
    specific_force_body_mps2: FloatArray, mass_kg: float, tension_n: FloatArray | float
) -> FloatArray:
    """Body-z component [N] of a cable pulling with ``tension_n`` (drone above the anchor).

    Parameters
    ----------
    specific_force_body_mps2
        Accelerometer readings, FRD body, shape (n, 3) [m/s^2].
    mass_kg
        Vehicle mass [kg].
    tension_n
        Cable tension magnitude [N], scalar or shape (n,).

    Returns
    -------
    ndarray, shape (n,)
        ``sqrt(max(F^2 - (m a_x)^2 - (m a_y)^2, 0))`` [N].
    """
    horizontal_sq = (mass_kg * specific_force_body_mps2[:, 0]) ** 2 + (
        mass_kg * specific_force_body_mps2[:, 1]
    ) ** 2
    tension = np.broadcast_to(np.asarray(tension_n, dtype=float), horizontal_sq.shape)
    return np.sqrt(np.maximum(tension**2 - horizontal_sq, 0.0))


def total_thrust_n(
    specific_force_body_mps2: FloatArray, mass_kg: float, tension_n: FloatArray | float = 0.0
) -> FloatArray:
    """Total rotor thrust [N], shape (n,), from accelerometer readings, shape (n, 3) [m/s^2].

    ``T = c_z - m a_z`` with ``c_z`` from :func:`cable_body_z_n` (zero when ``tension_n`` is 0).
    """
    return (
        cable_body_z_n(specific_force_body_mps2, mass_kg, tension_n)
        - mass_kg * specific_force_body_mps2[:, 2]
    )
