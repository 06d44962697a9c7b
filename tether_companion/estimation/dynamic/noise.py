"""The dynamic filter's noise model from its settings: the process noise spectral density of
each state and the accelerometer force balance's measurement noise.

In the inertial formulation the accelerometer's white noise drives the velocity (its density
converted with the nominal IMU period), and the force balance, fused once per
``imu_ticks_per_fusion`` ticks, carries what the model leaves out (gusts' drag, vibration, the
flight controller's attitude error): correlated over about a second, its white equivalent per
fused sample is ``force_residual_m2ps3`` over the fusion interval.

The wind is a first-order Gauss-Markov process about calm, not a random walk: in a hover the
winch length and the cable angle fix the position but not how the horizontal force splits
between the cable's pull and the wind's drag, and a walking wind let the tension, the thrust
scale and the wind drift together along that split (the gusty hover's north wind to -19 m/s
against the truth's -4, the tension 6 sd off; docs/estimation-history.md, gust24 and gust25).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import INERTIAL, DynamicFilterConfig

FloatArray = NDArray[np.float64]

NOMINAL_IMU_STEP_S = 0.005
"""IMU period the inertial formulation's per-sample noise is converted with [s]."""


def process_noise_density(dynamic: DynamicFilterConfig) -> FloatArray:
    """The diagonal of the process noise spectral density, shape (13,), in the state's units
    squared per second."""
    noise = dynamic.noise
    q = np.zeros(state.N_STATES)
    q[state.POSITION] = noise.position_m2ps
    if dynamic.formulation == INERTIAL:  # the accelerometer's white noise drives the velocity
        q[state.VELOCITY] = dynamic.accel_noise_std_mps2**2 * NOMINAL_IMU_STEP_S
    else:
        q[state.VELOCITY] = noise.acceleration_m2ps3
    q[state.TENSION] = noise.tension_n2ps
    q[state.SCALE] = noise.thrust_scale_per_s
    q[state.BIAS] = noise.accel_bias_m2ps5
    q[state.WIND] = 2.0 * noise.wind_std_mps**2 / noise.wind_correlation_s
    return q


def wind_decay_per_s(dynamic: DynamicFilterConfig) -> float:
    """The wind's reversion rate toward calm, ``1 / tau`` [1/s]: the Gauss-Markov process
    ``w' = -w / tau + n`` whose driving density :func:`process_noise_density` gives
    (``2 sigma^2 / tau``, stationary standard deviation ``sigma``)."""
    return 1.0 / dynamic.noise.wind_correlation_s


def accel_measurement_std_mps2(dynamic: DynamicFilterConfig) -> float:
    """Standard deviation of one fused accelerometer force-balance sample [m/s^2]: the
    sensor's alone in the force-balance formulation; with the unmodelled forces' white
    equivalent over the fusion interval in the inertial one."""
    sensor = dynamic.accel_noise_std_mps2
    if dynamic.formulation != INERTIAL:
        return sensor
    interval_s = NOMINAL_IMU_STEP_S * dynamic.imu_ticks_per_fusion
    unmodelled_sq = dynamic.noise.force_residual_m2ps3 / interval_s
    return math.sqrt(sensor**2 + unmodelled_sq)
