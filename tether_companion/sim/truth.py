"""What a simulated flight tells about itself: its noise-free state at an instant
(:class:`TruthState`, the reference every estimator is scored against) and the error that
ends a flight that cannot be flown (:class:`FlightImpossibleError`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.errors import InputError

FloatArray = NDArray[np.float64]


class FlightImpossibleError(InputError):
    """The scenario's flight cannot be flown (crash, saturation, non-finite state).

    The message names the simulation time and the cause; the command line prints it on one
    line and exits with code 2, like any other bad input.
    """


@dataclass(frozen=True, slots=True)
class TruthState:
    """Noise-free state of the simulated vehicle at ``time_s`` (SI units, NED/FRD)."""

    time_s: float
    position_ned_m: FloatArray
    """Position of the drone relative to the anchor, NED, shape (3,) [m]."""
    velocity_ned_m_s: FloatArray
    """Velocity, NED, shape (3,) [m/s]."""
    euler_rad: FloatArray
    """(roll, pitch, yaw), shape (3,) [rad]."""
    body_rates_rad_s: FloatArray
    """(p, q, r), FRD, shape (3,) [rad/s]."""
    motor_thrust_n: FloatArray
    """Each motor's thrust, shape (n_motors,) [N]."""
    pwm_us: FloatArray
    """PWM outputs, whole microseconds, shape (n_motors,) [us]."""
    cable_force_ned_n: FloatArray
    """Force of the cable on the drone, NED, shape (3,) [N]."""
    tension_n: float
    """Cable tension at the drone end [N]."""
    specific_force_body_mps2: FloatArray
    """Accelerometer specific force without noise or bias, FRD, shape (3,) [m/s^2]."""
    landed: bool
    """True while the drone rests on the ground."""
    wind_ned_m_s: FloatArray
    """Wind (mean + gusts) at the drone, NED, shape (3,) [m/s]."""
    battery_voltage_v: float
    """Battery pack voltage [V]."""
