"""Rotor drag from a flight log with velocity: the accelerometer's in-plane specific force
against the in-plane velocity, both in the body frame.

A multicopter's rotors (and airframe) push back against its velocity through the air; thrust
acts along body -z only, so in the body x-y plane the accelerometer reads only that drag
(and a cable's pull, which an identification flight keeps slack):

    f_b,xy = -(mu) v_b,xy        [m/s^2],   mu [1/s]

``mu`` is fitted by least squares over the airborne samples (still air assumed: wind makes
``v`` the ground velocity, not the air velocity, and biases ``mu``): the profile's
``rotor_drag_per_s`` (ArduPilot's ``EK3_DRAG_MCOEF``).
The velocity comes from the log (LOCAL_POSITION_NED or GPS); IMU and attitude are interpolated
onto its stamps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tether_companion.frames import rotation_ned_to_body
from tether_companion.sysid.logs.flightlog import FlightLog

MIN_SPEED_MPS = 0.3
"""Samples slower than this in the body plane carry little drag information; a fit needs
:data:`MIN_SAMPLES` faster ones."""
MIN_SAMPLES = 50


@dataclass(frozen=True)
class DragFit:
    """Identified rotor drag."""

    mu_per_s: float
    """Drag per unit mass and speed [1/s] (``EK3_DRAG_MCOEF``)."""
    coefficient_n_s_per_m: float
    """``mu * mass`` [N per m/s]: the same drag as a force per speed."""
    samples: int
    residual_rms_mps2: float


def identify_drag(log: FlightLog, mass_kg: float) -> DragFit | None:
    """``mu`` and the profile's drag coefficient from ``log``, or None when the log has no
    velocity or too few samples faster than :data:`MIN_SPEED_MPS`."""
    velocity = log.velocity_ned_mps
    if velocity is None or len(velocity) < MIN_SAMPLES:
        return None
    t = velocity.time_s
    inside = (t >= log.specific_force_body_mps2.time_s[0]) & (t <= log.euler_rad.time_s[-1])
    t, v_ned = t[inside], velocity.values[inside]
    force = np.column_stack(
        [
            np.interp(
                t, log.specific_force_body_mps2.time_s, log.specific_force_body_mps2.values[:, i]
            )
            for i in range(3)
        ]
    )
    euler = np.column_stack(
        [
            np.interp(t, log.euler_rad.time_s, np.unwrap(log.euler_rad.values[:, i]))
            for i in range(3)
        ]
    )
    v_body = np.array(
        [rotation_ned_to_body(*e) @ v for e, v in zip(euler, v_ned, strict=True)]
    ).reshape(-1, 3)
    v_xy, f_xy = v_body[:, :2], force[:, :2]
    fast = np.hypot(v_xy[:, 0], v_xy[:, 1]) >= MIN_SPEED_MPS
    if int(fast.sum()) < MIN_SAMPLES:
        return None
    v, f = v_xy[fast].ravel(), f_xy[fast].ravel()
    mu = float(-(v @ f) / (v @ v))
    residual = f + mu * v
    return DragFit(
        mu_per_s=mu,
        coefficient_n_s_per_m=mu * mass_kg,
        samples=int(fast.sum()),
        residual_rms_mps2=float(math.sqrt(np.mean(residual**2))),
    )
