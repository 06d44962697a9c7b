"""Rotations between the NED world (vehicle) frame and the FRD body frame.

Conventions (Al-Radaideh & Sun 2021, section 2.1): Euler angles roll ``phi``, pitch
``theta``, yaw ``psi`` in radians, applied yaw-pitch-roll (3-2-1). ``R_v^b`` (eq. 2) maps a
vector expressed in the NED vehicle frame into the FRD body frame; its transpose maps body to
NED.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def rotation_ned_to_body_rows(
    roll_rad: float, pitch_rad: float, yaw_rad: float
) -> list[list[float]]:
    """``R_v^b(phi, theta, psi)`` of the paper's eq. 2 row by row, as Python floats (for scalar
    code: no array made)."""
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    return [
        [cp * cy, cp * sy, -sp],
        [sr * sp * cy - cr * sy, sr * sp * sy + cr * cy, sr * cp],
        [cr * sp * cy + sr * sy, cr * sp * sy - sr * cy, cr * cp],
    ]


def rotation_ned_to_body(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """``R_v^b(phi, theta, psi)`` of the paper's eq. 2, shape (3, 3): ``v_body = R @ v_ned``."""
    return np.array(rotation_ned_to_body_rows(roll_rad, pitch_rad, yaw_rad))


def rotation_body_to_ned(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """``R_b^v = (R_v^b)^T``, shape (3, 3): ``v_ned = R @ v_body``."""
    return rotation_ned_to_body(roll_rad, pitch_rad, yaw_rad).T


def euler_rate_matrix(roll_rad: float, pitch_rad: float) -> FloatArray:
    """Matrix of the paper's eq. 5 mapping body rates (p, q, r) to Euler-angle rates [rad/s]."""
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp = math.cos(pitch_rad)
    tp = math.tan(pitch_rad)
    return np.array(
        [
            [1.0, sr * tp, cr * tp],
            [0.0, cr, -sr],
            [0.0, sr / cp, cr / cp],
        ]
    )


def euler_from_rotation_body_to_ned(rotation: FloatArray) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] of a body-to-NED rotation matrix (inverse of eq. 2's transpose)."""
    pitch = -math.asin(max(-1.0, min(1.0, float(rotation[2, 0]))))
    roll = math.atan2(float(rotation[2, 1]), float(rotation[2, 2]))
    yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    return roll, pitch, yaw


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi) [rad]."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi
