"""Estimates <-> MAVLink: the position and velocity estimates the service sends
(VISION_POSITION_ESTIMATE, ODOMETRY, VISION_SPEED_ESTIMATE) and the emulator reads, and the
LOCAL_POSITION_NED the emulator sends. Units and the covariance layout are those of
:mod:`tether_companion.mavlink.units` (its table)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from tether_companion.frames import rotation_ned_to_body
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.mavlink.units import (
    MAV_FRAME_BODY_FRD,
    MAV_FRAME_LOCAL_FRD,
    MAV_FRAME_LOCAL_NED,
    POSE_DIM,
    FloatArray,
    covariance_to_urt,
    euler_from_quaternion,
    quaternion_from_euler,
    seconds_to_boot_ms,
    seconds_to_usec,
    urt_to_covariance,
)


@dataclass(frozen=True, slots=True)
class PoseEstimate:
    """An external pose estimate as carried by VISION_POSITION_ESTIMATE or ODOMETRY.

    Attributes
    ----------
    time_s
        The sender's timestamp (``usec`` / ``time_usec``) [s], meant to be flight-controller time.
    position_ned_m
        Position, shape (3,), local NED frame [m].
    euler_rad
        (roll, pitch, yaw) [rad].
    covariance
        (6, 6) pose covariance (x, y, z, roll, pitch, yaw) or None when sent as unknown.
    reset_counter
        The estimate's reset counter (0-255).
    """

    time_s: float
    position_ned_m: FloatArray
    euler_rad: tuple[float, float, float]
    covariance: FloatArray | None
    reset_counter: int


def vision_position_estimate_message(estimate: PoseEstimate) -> MAVLinkMessage:
    """VISION_POSITION_ESTIMATE from a :class:`PoseEstimate` (``usec`` = ``time_s`` in us)."""
    p = estimate.position_ned_m
    return dialect.MAVLink_vision_position_estimate_message(
        seconds_to_usec(estimate.time_s),
        float(p[0]),
        float(p[1]),
        float(p[2]),
        *(float(a) for a in estimate.euler_rad),
        covariance_to_urt(estimate.covariance),
        estimate.reset_counter & 0xFF,
    )


def pose_from_vision_position_estimate(msg: MAVLinkMessage) -> PoseEstimate:
    """VISION_POSITION_ESTIMATE to a :class:`PoseEstimate` (values not checked for NaN)."""
    return PoseEstimate(
        time_s=msg.usec * 1e-6,
        position_ned_m=np.array([msg.x, msg.y, msg.z], dtype=float),
        euler_rad=(float(msg.roll), float(msg.pitch), float(msg.yaw)),
        covariance=urt_to_covariance(msg.covariance),
        reset_counter=int(msg.reset_counter),
    )


@dataclass(frozen=True)
class VelocityEstimate:
    """A velocity estimate as sent to or received from a flight controller.

    Attributes
    ----------
    time_s
        The sender's timestamp [s] (flight-controller time, as :class:`PoseEstimate`).
    velocity_ned_m_s
        Velocity, shape (3,), local NED frame [m/s].
    covariance
        (3, 3) velocity covariance, NED [m^2/s^2], or None when unknown.
    reset_counter
        The estimate's reset counter (0-255).
    """

    time_s: float
    velocity_ned_m_s: FloatArray
    covariance: FloatArray | None
    reset_counter: int


UNKNOWN_RATE_VARIANCE = 1.0e4
"""ODOMETRY velocity-covariance diagonal for the angular rates we do not estimate [rad^2/s^2]
(finite: one NaN in entry 0 would void the linear-velocity block too)."""


def odometry_message(
    estimate: PoseEstimate,
    velocity: VelocityEstimate | None = None,
    *,
    frame_id: int = MAV_FRAME_LOCAL_NED,
) -> MAVLinkMessage:
    """ODOMETRY with pose in ``frame_id`` (LOCAL_NED or LOCAL_FRD) and, if given, velocity.

    The velocity is sent in the body frame (``child_frame_id`` BODY_FRD), rotated from NED
    with the pose's roll, pitch and yaw, its covariance as ``R Sigma R^T``: ArduPilot takes
    ODOMETRY only with ``frame_id`` LOCAL_FRD and ``child_frame_id`` BODY_FRD and rotates the
    velocity back with the quaternion; PX4 reads the velocity frame from ``child_frame_id``.
    Without a velocity the fields are NaN and the velocity covariance is marked unknown.
    """
    p = estimate.position_ned_m
    if velocity is None:
        body_velocity = [math.nan] * 3
        velocity_covariance = covariance_to_urt(None)
    else:
        rotation = rotation_ned_to_body(*estimate.euler_rad)
        body_velocity = [float(v) for v in rotation @ np.asarray(velocity.velocity_ned_m_s)]
        if velocity.covariance is None:
            velocity_covariance = covariance_to_urt(None)
        else:
            twist = np.eye(POSE_DIM) * UNKNOWN_RATE_VARIANCE
            twist[:3, :3] = rotation @ np.asarray(velocity.covariance) @ rotation.T
            velocity_covariance = covariance_to_urt(0.5 * (twist + twist.T))
    return dialect.MAVLink_odometry_message(
        seconds_to_usec(estimate.time_s),
        frame_id,
        MAV_FRAME_BODY_FRD,
        float(p[0]),
        float(p[1]),
        float(p[2]),
        quaternion_from_euler(*estimate.euler_rad),
        *body_velocity,
        math.nan,
        math.nan,
        math.nan,
        covariance_to_urt(estimate.covariance),
        velocity_covariance,
        estimate.reset_counter & 0xFF,
        dialect.MAV_ESTIMATOR_TYPE_VIO,
        0,
    )


def velocity_from_odometry(msg: MAVLinkMessage) -> VelocityEstimate | None:
    """The NED velocity of an ODOMETRY (None when its velocity is NaN, i.e. not sent).

    A BODY_FRD ``child_frame_id`` is rotated to NED with the
    message's quaternion; LOCAL_NED / LOCAL_FRD is taken as NED.

    Raises
    ------
    ValueError
        When ``child_frame_id`` is none of those, or the quaternion has no norm.
    """
    body = np.array([msg.vx, msg.vy, msg.vz], dtype=float)
    if not np.all(np.isfinite(body)):
        return None
    covariance_6 = urt_to_covariance(msg.velocity_covariance)
    covariance = None if covariance_6 is None else covariance_6[:3, :3]
    if msg.child_frame_id == MAV_FRAME_BODY_FRD:
        rotation = rotation_ned_to_body(*euler_from_quaternion(msg.q)).T
        velocity = rotation @ body
        if covariance is not None:
            covariance = rotation @ covariance @ rotation.T
    elif msg.child_frame_id in (MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_FRD):
        velocity = body
    else:
        raise ValueError(f"ODOMETRY child_frame_id {msg.child_frame_id} is not BODY_FRD or local")
    return VelocityEstimate(msg.time_usec * 1e-6, velocity, covariance, int(msg.reset_counter))


def vision_speed_estimate_message(velocity: VelocityEstimate) -> MAVLinkMessage:
    """VISION_SPEED_ESTIMATE: NED velocity [m/s] and its row-major 3x3 covariance (NaN in
    entry 0 when unknown). ArduPilot (VISO_TYPE MAVLink) fuses it as NED velocity with its own
    VISO_VEL_M_NSE, ignoring the covariance; it is sent for consumers that read it."""
    v = np.asarray(velocity.velocity_ned_m_s, dtype=float)
    if velocity.covariance is None:
        covariance = [math.nan] + [0.0] * 8
    else:
        matrix = np.asarray(velocity.covariance, dtype=float)
        if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
            raise ValueError("velocity covariance must be a finite (3, 3) matrix")
        covariance = [float(x) for x in (0.5 * (matrix + matrix.T)).ravel()]
    return dialect.MAVLink_vision_speed_estimate_message(
        seconds_to_usec(velocity.time_s),
        float(v[0]),
        float(v[1]),
        float(v[2]),
        covariance,
        velocity.reset_counter & 0xFF,
    )


def velocity_from_vision_speed_estimate(msg: MAVLinkMessage) -> VelocityEstimate:
    """VISION_SPEED_ESTIMATE to a :class:`VelocityEstimate` (values not checked for NaN)."""
    values = np.asarray(msg.covariance, dtype=float)
    covariance = None if math.isnan(values[0]) else values.reshape(3, 3)
    return VelocityEstimate(
        msg.usec * 1e-6,
        np.array([msg.x, msg.y, msg.z], dtype=float),
        covariance,
        int(msg.reset_counter),
    )


def pose_from_odometry(msg: MAVLinkMessage) -> PoseEstimate:
    """ODOMETRY to a :class:`PoseEstimate`.

    LOCAL_FRD is taken as NED (the emulator's local frame has true north along x).

    Raises
    ------
    ValueError
        When ``frame_id`` is not LOCAL_NED or LOCAL_FRD, or the quaternion has no norm.
    """
    if msg.frame_id not in (MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_FRD):
        raise ValueError(f"ODOMETRY frame_id {msg.frame_id} is not LOCAL_NED or LOCAL_FRD")
    return PoseEstimate(
        time_s=msg.time_usec * 1e-6,
        position_ned_m=np.array([msg.x, msg.y, msg.z], dtype=float),
        euler_rad=euler_from_quaternion(msg.q),
        covariance=urt_to_covariance(msg.pose_covariance),
        reset_counter=int(msg.reset_counter),
    )


def local_position_ned_message(
    time_s: float, position_ned_m: ArrayLike, velocity_ned_m_s: ArrayLike
) -> MAVLinkMessage:
    """LOCAL_POSITION_NED [m, m/s] relative to the EKF origin, ``time_boot_ms``."""
    p = np.asarray(position_ned_m, dtype=float)
    v = np.asarray(velocity_ned_m_s, dtype=float)
    return dialect.MAVLink_local_position_ned_message(
        seconds_to_boot_ms(time_s), *(float(x) for x in p), *(float(x) for x in v)
    )
