"""The dynamic filter's starting state and covariance from the start window's construction.

:class:`~tether_companion.estimation.dynamic.initialise.Initialiser` places the drone from a
vector ``theta`` of the window's parameters (its mean accelerometer force, the priors of
what the window cannot measure, the height, the winch length, the cable angle and the
winch's tension). :func:`start_state` maps their spread, and the ground station's
calibration errors, through that construction by central differences, so the initial
covariance carries the correlations (position with thrust scale, bias, wind and the
calibration states) that let later data correct the position when those become known.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicInitial

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
