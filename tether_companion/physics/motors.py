"""Motors: first-order thrust lag, quad-X mixing (wrench to motor thrusts) and PWM outputs.

Each motor's thrust ``f_i`` follows the steady-state thrust of its PWM command with a first
order lag of time constant ``tau`` (the vehicle profile's ``motor_time_constant_s``)::

    d f_i / dt = (f_ss(pwm_i) - f_i) / tau

The flight controller holds its PWM outputs between updates (zero-order hold), so over a step
``h`` with constant ``f_ss`` the lag has the exact solution
``f_i(t + h) = f_ss + (f_i(t) - f_ss) exp(-h / tau)``: :class:`MotorLag` gives the decay factor,
:class:`tether_companion.physics.rigid_body.RigidBody` applies it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tether_companion.physics.vehicle import VehicleProfile

FloatArray = NDArray[np.float64]


class MotorLag:
    """Exact first-order lag of motor thrusts toward their steady-state values.

    Parameters
    ----------
    time_constant_s
        Lag time constant ``tau`` [s] (> 0).
    """

    def __init__(self, time_constant_s: float) -> None:
        if not time_constant_s > 0.0:
            raise ValueError(f"motor time constant must be > 0 s, got {time_constant_s!r}")
        self.time_constant_s = float(time_constant_s)

    def decay(self, dt_s: float) -> float:
        """``exp(-dt/tau)``: the fraction of a thrust error left after ``dt_s`` seconds."""
        return math.exp(-dt_s / self.time_constant_s)


class MotorMixer:
    """Turn a wrench (collective thrust, body torques) into motor thrusts and PWM pulses.

    Uses the Moore-Penrose inverse of the vehicle's allocation matrix
    (:meth:`VehicleProfile.allocation_matrix`, shape (4, n)), which for a quad X is the exact
    inverse. Saturation: the collective thrust per motor is clipped to [0, f_max]; the torque
    share is then scaled down uniformly (by the largest factor <= 1) so every motor stays in
    [0, f_max]: attitude authority is kept in proportion, the collective is never traded away.
    """

    def __init__(self, vehicle: VehicleProfile) -> None:
        self.vehicle = vehicle
        self.curve = vehicle.thrust_curve
        self.n_motors = vehicle.n_motors
        allocation = vehicle.allocation_matrix()
        self.allocation = allocation
        pseudo_inverse = np.linalg.pinv(allocation)
        self._collective_column = pseudo_inverse[:, 0].copy()
        self._torque_columns = pseudo_inverse[:, 1:].copy()
        self.min_thrust_n = float(self.curve.thrust_n(self.curve.pwm_min_us))
        self.max_thrust_n = self.curve.max_thrust_n

    def motor_thrusts_n(self, collective_n: float, torque_body_n_m: ArrayLike) -> FloatArray:
        """Motor thrusts [N], shape (n,), for a collective thrust [N] and FRD torques (3,) [N m]."""
        f_min, f_max = self.min_thrust_n, self.max_thrust_n
        collective = self._collective_column * collective_n
        collective = np.clip(collective, f_min, f_max)
        share = self._torque_columns @ np.asarray(torque_body_n_m, dtype=float)
        scale = 1.0
        for base, delta in zip(collective.tolist(), share.tolist(), strict=True):
            if delta > 0.0 and base + delta > f_max:
                scale = min(scale, (f_max - base) / delta)
            elif delta < 0.0 and base + delta < f_min:
                scale = min(scale, (f_min - base) / delta)
        return collective + max(scale, 0.0) * share

    def pwm_us(self, motor_thrusts_n: ArrayLike) -> FloatArray:
        """Whole-microsecond PWM pulses (n,) that make each motor's steady-state thrust [N]."""
        return np.rint(self.curve.pwm_for_thrust(motor_thrusts_n))

    def idle_pwm_us(self) -> FloatArray:
        """PWM pulses (n,) [us] of stopped motors (``pwm_min_us`` on every output)."""
        return np.full(self.n_motors, float(self.curve.pwm_min_us))

    def wrench(self, motor_thrusts_n: ArrayLike) -> FloatArray:
        """(collective [N], roll, pitch, yaw torque [N m]), (4,), of motor thrusts (n,) [N]."""
        return self.allocation @ np.asarray(motor_thrusts_n, dtype=float)
