"""Thrust input with the motors' first-order lag, from the vehicle profile.

The paper's static map (PWM -> thrust) ignores that a rotor needs tens of milliseconds to
reach a new speed. In the open-loop evaluation the commands change slowly and that hardly
matters; when the autopilot flies on our estimate, every correction it makes is a fast PWM
change whose thrust arrives late, the accelerometer model then explains the missing thrust with
the cable, the estimate moves, the autopilot corrects again: a feedback loop that can diverge.
Modelling the lag that the vehicle profile states (``motor_time_constant_s``) breaks it.

Each motor's thrust follows ``tau f' = f_cmd(pwm) - f``, with the command held between PWM
samples (zero-order hold, as the flight controller's output is). The lag is linear and the same
for every motor, so the total thrust is the lagged sum of the static per-motor thrusts:

    f(t_k) = f_cmd(t_{k-1}) + (f(t_{k-1}) - f_cmd(t_{k-1})) exp(-(t_k - t_{k-1}) / tau)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.thrust_input import StaticThrustInput
from tether_companion.physics.vehicle import VehicleProfile

FloatArray = NDArray[np.float64]

HOLD_FRACTION = 0.5
"""The returned thrust is the lagged thrust half-way through the new command's hold: the
average over the hold to first order, which is what the IMU ticks until the next PWM sample
see."""
RESTART_GAP_S = 1.0
"""A gap between PWM samples longer than this [s] (or time going back) restarts the lag at
the commanded thrust."""


class MotorLagThrustInput:
    """Total thrust [N] of the static curve through a first-order motor lag.

    Parameters
    ----------
    vehicle
        Profile giving the thrust curve and ``motor_time_constant_s``.
    """

    def __init__(self, vehicle: VehicleProfile) -> None:
        self._static = StaticThrustInput(vehicle)
        self.time_constant_s = vehicle.motor_time_constant_s
        self._thrust_n = math.nan
        self._command_n = math.nan
        self._time_s = math.nan
        self._interval_s = 0.0

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """Thrust [N] expected over the hold of the new command ``pwm_us`` [us] given at ``time_s``.

        The estimator uses the value until the next PWM sample, so it is the lagged thrust
        ``HOLD_FRACTION`` of one sample interval (the last one seen) into the new command's hold.
        """
        command_n = self._static.total_thrust_n(pwm_us, time_s)
        dt = time_s - self._time_s
        if not (0.0 < dt <= RESTART_GAP_S):  # first sample (nan), time went back, long gap
            self._thrust_n = command_n
        else:  # exact zero-order-hold response up to now, under the previous command
            decay = math.exp(-dt / self.time_constant_s)
            self._thrust_n = self._command_n + (self._thrust_n - self._command_n) * decay
            self._interval_s = dt
        self._command_n = command_n
        self._time_s = time_s
        ahead = math.exp(-HOLD_FRACTION * self._interval_s / self.time_constant_s)
        return command_n + (self._thrust_n - command_n) * ahead
