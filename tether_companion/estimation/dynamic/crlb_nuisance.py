"""The nuisance parameters of the dynamic filter's Cramer-Rao bound (:mod:`.crlb`): errors of a
simulated flight that are no state of the filter's model but limit what the flight's data can
tell, estimated beside the state in the bound (the state's bound is the augmented bound's
marginal):

* :class:`CalibrationPrior`: the ground station's calibration errors, constants of the flight
  (the winch encoder's zero and scale, the angle sensor's zero errors);
* :class:`HeadingError`: the flight controller's heading error, a first-order Gauss-Markov
  angle added to the yaw the filter is given; its columns are the prediction's and the force
  balance's derivatives in their yaw input (:func:`yaw_column_of_specific_force`,
  :func:`yaw_column_of_model`);
* :class:`TerrainNoise`: the ground's elevation under the rangefinder, a first-order
  Gauss-Markov process in the distance flown (:func:`gauss_markov_step`).

Units SI, NED from the anchor, FRD body. Pure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.frames import rotation_ned_to_body_rows

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CalibrationPrior:
    """The ground station's per-flight calibration errors, unknown constants the bound
    estimates beside the state (nuisance parameters with a Gaussian prior; the bound of the
    state is then the marginal of the augmented bound: a constant error that the data cannot
    separate from the position stays in it). The winch reports ``offset + (1 + scale) L``, the
    angle sensor ``(elevation + elevation bias, azimuth + azimuth bias)``.

    Attributes
    ----------
    winch_offset_std_m
        The encoder's zero offset [m].
    winch_scale_std
        The encoder's scale error [1].
    elevation_bias_std_rad, azimuth_bias_std_rad
        The angle sensor's zero errors [rad].

    A zero standard deviation is an error known to be zero: it is left out of the augmented
    state.
    """

    winch_offset_std_m: float
    winch_scale_std: float
    elevation_bias_std_rad: float
    azimuth_bias_std_rad: float

    def std(self) -> FloatArray:
        """The prior standard deviations, indexed by :data:`OFFSET`, :data:`SCALE`,
        :data:`ELEVATION_BIAS`, :data:`AZIMUTH_BIAS`."""
        return np.array(
            [
                self.winch_offset_std_m,
                self.winch_scale_std,
                self.elevation_bias_std_rad,
                self.azimuth_bias_std_rad,
            ]
        )


OFFSET, SCALE, ELEVATION_BIAS, AZIMUTH_BIAS = range(4)
"""Indices of the calibration errors in :meth:`CalibrationPrior.std`."""


@dataclass(frozen=True)
class HeadingError:
    """The flight controller's heading error: a first-order Gauss-Markov angle [rad] added to
    the true yaw in the attitude the filter is given (the simulator's heading error,
    ``heading_error_*`` or else ``attitude_error_*``). Its column in the model is the
    derivative of the prediction and the force balance with respect to their yaw input
    (:func:`yaw_column_of_specific_force`, :func:`yaw_column_of_model`).

    Attributes
    ----------
    std_rad
        Stationary standard deviation [rad] (also its prior).
    time_constant_s
        Correlation time [s].
    """

    std_rad: float
    time_constant_s: float


@dataclass(frozen=True)
class TerrainNoise:
    """The ground's elevation under the rangefinder, a nuisance state of the height reading: a
    first-order Gauss-Markov process in the distance flown horizontally, ``exp(-s / l)``
    correlated (the simulator's undulations of wavelength ``lambda`` in random directions have
    ``l = lambda / 2 pi``, the integral of their correlation along a line). Under a hovering
    drone it is a constant; the rangefinder's own white noise stays in
    :attr:`BoundNoise.range_var_m2`.

    Attributes
    ----------
    std_m
        Standard deviation of the elevation [m] (also its prior).
    correlation_m
        Correlation length along the path [m].
    """

    std_m: float
    correlation_m: float


_YAW_TURN = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
"""``d Rz(e) / d e`` at ``e = 0``, ``Rz`` the yaw factor of ``R_v^b``:
``R_v^b(roll, pitch, yaw + e) = R_v^b(roll, pitch, yaw) Rz(e)``, so a NED vector ``w`` seen
through a yaw ``e`` larger is seen as ``Rz(e) w``."""


def yaw_column_of_specific_force(
    euler_rad: FloatArray, specific_force_body_mps2: FloatArray
) -> FloatArray:
    """``d (R_v^b(yaw)^T f) / d yaw`` [m/s^2/rad], shape (3,): how the inertial prediction's
    NED acceleration turns with its yaw input, ``Rz'(0)^T a = (-a_e, a_n, 0)`` with
    ``a = R^T f``."""
    rows = rotation_ned_to_body_rows(*euler_rad)
    a = np.array(rows).T @ specific_force_body_mps2
    return _YAW_TURN.T @ a


def yaw_column_of_model(jacobian: FloatArray, x: list[float]) -> FloatArray:
    """``d h / d yaw`` of a generated model whose only dependence on the yaw input is through
    ``R_v^b`` applied to the state's NED vectors (position, velocity, the horizontal wind;
    gravity and the cable's weight point down): by the chain rule through the state,
    ``H_p Rz' p + H_v Rz' v + H_w (Rz' w)_ne`` with ``jacobian`` the model's (rows, 17)
    Jacobian at ``x``. Shape (rows,)."""
    p = np.asarray(x[0:3])
    v = np.asarray(x[3:6])
    wind = np.array([x[state.WIND.start], x[state.WIND.start + 1], 0.0])
    return (
        jacobian[:, state.POSITION] @ (_YAW_TURN @ p)
        + jacobian[:, state.VELOCITY] @ (_YAW_TURN @ v)
        + jacobian[:, state.WIND] @ (_YAW_TURN @ wind)[:2]
    )


def gauss_markov_step(
    transition: FloatArray, process: FloatArray, column: int, decay: float, std: float
) -> None:
    """Write a first-order Gauss-Markov state's step into ``transition`` and ``process`` (the
    step's noise variances) at ``column``: ``a = exp(-decay)``, variance ``std^2 (1 - a^2)``
    (stationary at ``std``)."""
    a = math.exp(-decay)
    transition[column, column] = a
    process[column] = std * std * (1.0 - a * a)
