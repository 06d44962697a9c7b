"""Total rotor thrust from motor outputs: the ``u`` the tether EKF's accelerometer model needs.

A :class:`ThrustInput` maps the latest PWM sample to the total thrust [N] along body -z. The
static one uses the vehicle profile's thrust curve (the paper's eq. 19 generalised);
system identification (``tether_companion.sysid``) provides dynamic ones (ARX, state space)
implementing the same protocol.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from tether_companion.physics.vehicle import VehicleProfile

FloatArray = NDArray[np.float64]


@runtime_checkable
class ThrustInput(Protocol):
    """Maps motor pulse widths to the total thrust of all rotors."""

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """Total thrust [N] for pulse widths ``pwm_us`` (shape (n_motors,)) at ``time_s`` [s]."""
        ...


class StaticThrustInput:
    """Sum of the vehicle profile's static thrust curve over the motors (no motor dynamics).

    Evaluates :meth:`ThrustCurve.thrust_n` with scalar arithmetic: it runs on every PWM
    sample of every estimator, where numpy's per-call overhead dominates for 4 motors
    (a test checks that both agree).
    """

    def __init__(self, vehicle: VehicleProfile) -> None:
        curve = vehicle.thrust_curve
        self.curve = curve
        self.n_motors = vehicle.n_motors
        self._pwm_min_us = curve.pwm_min_us
        self._per_us = 1.0 / (curve.pwm_max_us - curve.pwm_min_us)
        self._full_scale = curve.command_full_scale
        self._c0, self._c1, self._c2 = curve.coefficients_n

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """Total thrust [N]; ``time_s`` is unused (the map is static).

        Raises
        ------
        ValueError
            When the number of pulse widths is not the vehicle's motor count.
        """
        if len(pwm_us) != self.n_motors:
            raise ValueError(f"expected {self.n_motors} pulse widths, got {len(pwm_us)}")
        c1, c2 = self._c1, self._c2
        total = self._c0 * self.n_motors
        for pwm in pwm_us.tolist() if isinstance(pwm_us, np.ndarray) else pwm_us:
            u = (pwm - self._pwm_min_us) * self._per_us
            cmd = (0.0 if u < 0.0 else 1.0 if u > 1.0 else u) * self._full_scale
            total += cmd * (c1 + c2 * cmd)
        return total
