"""Feed a dynamic estimator ticks of a level drone holding its weight (shared by tests)."""

from __future__ import annotations

import numpy as np

from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.output import NavigationEstimate
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

STANDARD_GRAVITY_MPS2 = 9.80665


def level_ticks(est: DynamicTetherEstimator, t: float, n: int = 10) -> NavigationEstimate:
    """``n`` 200 Hz ticks after ``t`` [s] of a level drone at PWM 1700 whose accelerometer
    reads the weight's reaction (FRD, -g on z); the last estimate."""
    estimate = None
    for k in range(1, n + 1):
        tk = t + 0.005 * k
        est.on_attitude(AttitudeSample(tk, 0.0, 0.0, 0.0))
        est.on_pwm(PwmSample(tk, np.full(4, 1700.0)))
        estimate = est.on_imu(
            ImuSample(tk, np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2]), np.zeros(3))
        )
    assert estimate is not None
    return estimate
