"""The start window's motion from the force: the drone's position and velocity at its end.

:class:`~tether_companion.estimation.dynamic.initialise.Initialiser` keeps, for each IMU tick
of the window that follows a rangefinder height, a :data:`ForceSnapshot`. :func:`fitted_motion`
places the drone at each such tick from that tick's force (the cable's curve,
:func:`~tether_companion.estimation.dynamic.start_placement.place`) and fits a quadratic in
time through those positions (:func:`~.start_angle.quadratic_fit`): its value and slope at
the window's end are the start's position and velocity. Where the force cannot tell the
bearing, the weightless cable's start is placed by the cable angle's readings instead
(:meth:`~.start_angle.AngleReadings.motion`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.start_angle import (
    AngleReadings,
    held_slope_se,
    quadratic_fit,
)
from tether_companion.estimation.dynamic.start_placement import place

FloatArray = NDArray[np.float64]

ForceSnapshot = tuple[float, FloatArray, FloatArray, float]
"""One tick of the window: its time [s], the mass times the specific force rotated to NED
(``m R^T f`` [N]), the thrust's direction times the thrust from the map, unscaled
(``R^T e_z T``, NED [N]), and the rangefinder height above the anchor read last [m]."""

MotionFit = tuple[FloatArray, FloatArray, FloatArray, FloatArray]
"""Position NED from the anchor [m], velocity NED [m/s], and the velocity's and the position's
standard errors per axis [m/s, m]."""

MIN_PLACED_TICKS = 10
"""Fewest ticks the force must place for the fit to be taken."""


def fitted_motion(
    time_s: float,
    snapshots: Sequence[ForceSnapshot],
    snapshot_readings: Sequence[int],
    thrust_scale: float,
    length_m: float,
    wind_ne_mps: FloatArray,
    wind_drag_n: FloatArray,
    cable_weight_n_per_m: float,
    angles: AngleReadings,
    by_azimuth: bool = False,
    winch_tension_n: float = math.nan,
) -> MotionFit | None:
    """Position [m] and velocity [m/s] at ``time_s`` from a quadratic fit of the window's
    per-tick positions, and their standard errors, or None where fewer than
    :data:`MIN_PLACED_TICKS` ticks are placed.

    Each tick's cable force (NED [N]) is its ``m R^T f`` plus ``thrust_scale`` times its
    thrust vector, plus ``wind_drag_n`` (the drag of the wind ``wind_ne_mps`` [m/s] at the
    window's mean attitude, added only where that wind is not zero). ``by_azimuth``: each
    tick placed with the cable angle read nearest in time and the winch's tension
    ``winch_tension_n`` [N] (``nan``: none), a heavy cable whose pull the wind could turn.

    The position's standard error is not used (measured and not taken, start10, live24).
    With a winch length ``length_m`` [m] (``nan``: none) the velocity's is counted over the
    held height readings ``snapshot_readings`` (each snapshot's reading count,
    :func:`.start_angle.held_slope_se`: as 191 independent ticks it read 0.40 m/s on
    realistic-circle seed 42 with the fit's v_d 1.5 m/s off, circle22; 0.25 m/s with it
    1.5 m/s off on the MAVProxy test's live start, live24). Without one, as over the ticks:
    honest, the angle alone's light 1 N winch hover ran 46-54 m off (its heavy-cable start
    placed 2-5 sd short, startvel23).
    """
    times, positions, readings = [], [], []
    for snapshot, reading in zip(snapshots, snapshot_readings):
        t, accel_force, thrust_vector, height = snapshot
        force = accel_force + thrust_scale * thrust_vector
        if wind_ne_mps.any():
            force = force + wind_drag_n
        elevation, azimuth = angles.angle_at(t) if by_azimuth else (math.nan, math.nan)
        placed = place(
            force, height, length_m, cable_weight_n_per_m, elevation, azimuth, winch_tension_n
        )
        if placed is not None:
            times.append(t)
            positions.append(placed[:3])
            readings.append(reading)
    if len(times) < MIN_PLACED_TICKS:
        return None
    relative_s = np.asarray(times) - time_s
    position, velocity, velocity_se, position_se = quadratic_fit(
        relative_s, np.asarray(positions)
    )
    if math.isfinite(length_m):  # the winch's length holds the range (see the docstring)
        # each tick's position holds the height read last: ~20 readings, not ~200 samples
        velocity_se = held_slope_se(relative_s, np.asarray(readings), velocity_se)
    return position, velocity, velocity_se, position_se
