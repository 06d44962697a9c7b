"""Typed sensor samples in SI units, shared by the simulator, MAVLink decoding and estimators.

Every sample carries ``time_s``: the flight controller's clock (time since its boot) in
seconds. Decoders convert MAVLink's microseconds/milliseconds and autopilot-specific units
into these types; nothing downstream sees milli-g or centimetres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class ImuSample:
    """One accelerometer + gyro reading in the FRD body frame.

    Attributes
    ----------
    time_s
        Flight-controller time [s].
    specific_force_body_mps2
        Accelerometer specific force (non-gravitational force per unit mass), shape (3,),
        FRD body frame [m/s^2]. At rest on level ground it reads about (0, 0, -g).
    angular_rate_body_rad_s
        Gyro body rates (p, q, r), shape (3,) [rad/s].
    """

    time_s: float
    specific_force_body_mps2: FloatArray
    angular_rate_body_rad_s: FloatArray


@dataclass(frozen=True, slots=True)
class AttitudeSample:
    """The flight controller's attitude estimate: Euler angles of the FRD body frame [rad]."""

    time_s: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


@dataclass(frozen=True, slots=True)
class PwmSample:
    """Motor output pulse widths [us], shape (n_motors,), in the vehicle profile's motor order."""

    time_s: float
    pwm_us: FloatArray


@dataclass(frozen=True, slots=True)
class RangeSample:
    """A downward rangefinder reading along the sensor's axis [m] (not yet tilt-corrected)."""

    time_s: float
    distance_m: float
