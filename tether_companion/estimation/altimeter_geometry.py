"""Height of the drone above the anchor from a downward rangefinder reading.

The rangefinder sees the ground under the drone, not the anchor, and sits at an offset from the
centre of mass. With ``d`` the reading along the sensor's axis (body down), ``R_b^v`` the body
to NED rotation and ``r`` the sensor's mounting point (body FRD, from the centre of mass), over
flat ground:

* the sensor's height above the ground is ``d cos(phi) cos(theta)`` (tilt-corrected);
* the centre of mass is ``(R_b^v r)_down`` higher than the sensor;
* the anchor is ``anchor_height_m`` above the ground under the drone;

so the height above the anchor is ``d cos(phi) cos(theta) + (R_b^v r)_down - anchor_height_m``
[m] (pure function; the estimators fuse it as the altimeter measurement). The keys are
``estimator.ground_station.anchor_height_m`` and ``estimator.rangefinder.offset_frd_m``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def height_above_anchor_m(
    distance_m: float,
    rotation_ned_to_body: FloatArray | list[list[float]],
    offset_frd_m: tuple[float, float, float],
    anchor_height_m: float,
) -> float:
    """Height [m] of the centre of mass above the anchor (module docstring).

    Parameters
    ----------
    distance_m
        Rangefinder reading along the sensor axis (body down) [m].
    rotation_ned_to_body
        ``R_v^b`` of the attitude at the reading, shape (3, 3) (an array or rows of floats).
    offset_frd_m
        Sensor mounting point from the centre of mass, body FRD [m].
    anchor_height_m
        Anchor height above the ground [m].
    """
    (_, _, r02), (_, _, r12), (_, _, r22) = rotation_ned_to_body  # rows of R_v^b
    cos_tilt = float(r22)  # (R_v^b)[2, 2] = cos(phi) cos(theta)
    x, y, z = offset_frd_m
    offset_down = float(r02 * x + r12 * y + r22 * z)  # (R_b^v r)_down
    return distance_m * cos_tilt + offset_down - anchor_height_m
