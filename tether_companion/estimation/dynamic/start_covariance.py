"""The dynamic filter's starting state and covariance from the start window's construction.

:class:`~tether_companion.estimation.dynamic.initialise.Initialiser` places the drone from a
vector ``theta`` of the window's parameters (its mean accelerometer force, the priors of
what the window cannot measure, the height, the winch length, the cable angle and the
winch's tension). :func:`start_state` maps their spread, and the ground station's
calibration errors (:func:`window_parameter_std`), through that construction by central
differences, so the initial
covariance carries the correlations (position with thrust scale, bias, wind and the
calibration states) that let later data correct the position when those become known.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig, DynamicInitial
from tether_companion.estimation.dynamic.start_angle import AngleReadings

FloatArray = NDArray[np.float64]

THETA_SIZE = 14
"""Parameters of the construction, in this order: the window's mean force per unit mass beyond
gravity (NED [m/s^2], 3), the thrust scale, the accelerometer bias (FRD [m/s^2], 3), the wind
(north, east [m/s]), the height above the anchor [m], the winch length [m], the cable angle's
elevation and azimuth [rad], the winch's tension [N] (each ``nan`` where the window has none)."""
T_ACCEL = slice(0, 3)
T_SCALE = 3
T_BIAS = slice(4, 7)
T_WIND = slice(7, 9)
T_HEIGHT = 9
T_LENGTH = 10
T_ELEVATION = 11
T_AZIMUTH = 12
T_WINCH_TENSION = 13
_REL_STEP = 1e-6
"""Central-difference step relative to the parameter (at least 1e-6 in its unit)."""


def start_state(
    theta: FloatArray,
    placed: FloatArray,
    sigma: FloatArray,
    calibration_std: FloatArray,
    solve: Callable[[FloatArray], FloatArray | None],
    initial: DynamicInitial,
) -> tuple[FloatArray | None, FloatArray | None]:
    """The starting state (``state.N_STATES``,) and covariance, or ``(None, None)`` where
    the construction does not hold around ``theta`` or the covariance is not finite.

    Parameters
    ----------
    theta
        The construction's parameters (``THETA_SIZE``,), laid out as ``THETA_SIZE`` says.
    placed
        ``solve(theta)``: the drone's position NED from the anchor [m] (3) and the chord
        tension [N].
    sigma
        Standard deviation of each parameter (0: exact).
    calibration_std
        The ground station's calibration errors' standard deviations: winch length offset
        [m] and scale, the angle's elevation and azimuth zeros [rad] (0: not used).
    solve
        The construction: parameters to ``(p_n, p_e, p_d, T_ch)``, or None (no rising cable).
    initial
        The filter's priors (the velocity's standard deviation [m/s]).
    """
    active = [i for i in range(THETA_SIZE) if np.isfinite(theta[i]) and sigma[i] > 0.0]
    jac = np.zeros((4, THETA_SIZE))
    for i in active:
        step = _REL_STEP * max(1.0, abs(theta[i]))
        plus, minus = theta.copy(), theta.copy()
        plus[i] += step
        minus[i] -= step
        y_plus, y_minus = solve(plus), solve(minus)
        if y_plus is None or y_minus is None:
            return None, None
        jac[:, i] = (y_plus - y_minus) / (2.0 * step)
    length_m = float(theta[T_LENGTH]) if np.isfinite(theta[T_LENGTH]) else 0.0
    # the ground station's calibration errors: parameters of the construction beside theta
    # (the reading's error is the noise's plus theirs) and states of their own
    # (state.CALIBRATION, whose estimate 0 is off by minus them): one spread, correlated;
    # offset + scale L and the angles' zeros move the drone as their readings do
    calibration_columns = np.stack(
        (jac[:, T_LENGTH], jac[:, T_LENGTH] * length_m, jac[:, T_ELEVATION], jac[:, T_AZIMUTH]),
        axis=1,
    )
    # rows: p (3), T_ch, s, b (3), w (2), calibration (4) as functions of theta and the
    # calibration errors
    rows = np.zeros((14, THETA_SIZE + 4))
    rows[0:4, :THETA_SIZE] = jac
    rows[0:4, THETA_SIZE:] = calibration_columns
    rows[4, T_SCALE] = 1.0
    rows[5:8, T_BIAS] = np.eye(3)
    rows[8:10, T_WIND] = np.eye(2)
    rows[10:14, THETA_SIZE:] = -np.eye(4)
    parameter_std = np.concatenate((np.where(np.isfinite(sigma), sigma, 0.0), calibration_std))
    joint = (rows * parameter_std**2) @ rows.T
    calibration = range(state.CALIBRATION.start, state.CALIBRATION.stop)
    order = [0, 1, 2, state.TENSION, state.SCALE, 8, 9, 10, 11, 12, *calibration]
    p = np.zeros((state.N_STATES, state.N_STATES))
    p[np.ix_(order, order)] = joint
    p[state.VELOCITY, state.VELOCITY] = np.eye(3) * initial.velocity_std_mps**2
    # keep it positive definite when a prior is exact (a calibration not given here
    # enters with its sensor's first reading: ground_station.open_calibration)
    p += np.eye(state.N_STATES) * state.UNSET_CALIBRATION_VARIANCE
    p = 0.5 * (p + p.T)
    if not np.all(np.isfinite(p)):
        return None, None
    x = np.zeros(state.N_STATES)
    x[state.POSITION] = placed[:3]
    x[state.TENSION] = placed[3]
    x[state.SCALE] = float(theta[T_SCALE])
    x[state.WIND] = theta[T_WIND]
    return x, p


def window_parameter_std(
    theta: FloatArray,
    config: DynamicFilterConfig,
    thrust_scale_std: float,
    accel_std_mps2: float,
    n_ticks: int,
    range_std_m: float,
    n_heights: int,
    n_winch_tensions: int,
    angles: AngleReadings,
) -> tuple[FloatArray, FloatArray]:
    """Standard deviations of the construction's parameters ``theta`` (``THETA_SIZE``,) and
    of the ground station's calibration errors (4,): winch offset [m] and scale, the angle's
    elevation and azimuth zeros [rad]; 0 where the window does not use that sensor.

    The window's noise is averaged over its readings: the accelerometer's
    ``accel_std_mps2`` [m/s^2 per tick] over ``n_ticks`` ticks, the rangefinder's
    ``range_std_m`` [m] over ``n_heights`` heights, the load cell's (the config's) over
    ``n_winch_tensions`` winch tensions, the cable angle's over its ``angles``. The rest are
    priors: the thrust scale's ``thrust_scale_std``, the config's bias, wind and winch
    length noise.
    """
    init = config.initial
    sigma = np.zeros(THETA_SIZE)
    sigma[T_ACCEL] = accel_std_mps2 / math.sqrt(n_ticks)
    sigma[T_SCALE] = thrust_scale_std
    sigma[T_BIAS] = init.accel_bias_std_mps2
    sigma[T_WIND] = init.wind_std_mps
    sigma[T_HEIGHT] = range_std_m / math.sqrt(max(n_heights, 1))
    sigma[T_LENGTH] = config.winch_length_noise_std_m
    sigma[T_WINCH_TENSION] = config.load_cell_noise_std_n / math.sqrt(max(n_winch_tensions, 1))
    calibration_std = np.zeros(4)
    if math.isfinite(theta[T_LENGTH]):  # the length places the drone: its calibration too
        calibration_std[0:2] = config.winch_length_offset_std_m, config.winch_length_scale_std
    if math.isfinite(theta[T_ELEVATION]):
        sigma[T_ELEVATION], sigma[T_AZIMUTH] = angles.mean_noise_std(float(theta[T_ELEVATION]))
        calibration_std[2:4] = angles.calibration_std()
    return sigma, calibration_std
