"""Total rotor thrust from motor outputs: the ``u`` the tether EKF's accelerometer model needs.

A :class:`ThrustInput` maps the latest PWM sample to the total thrust [N] along body -z. The
static one uses the vehicle profile's thrust curve (the paper's eq. 19 generalised); the
motor-lag one runs that curve through the profile's first-order motor lag; system
identification (``tether_companion.sysid``) provides identified ones (ARX, state space)
implementing the same protocol.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import optional_core
from tether_companion.physics.motors import MotorLag, lag_decay
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.physics.vehicle import VehicleProfile

FloatArray = NDArray[np.float64]


@runtime_checkable
class ThrustInput(Protocol):
    """Maps motor pulse widths to the total thrust of all rotors."""

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """Total thrust [N] for pulse widths ``pwm_us`` (shape (n_motors,)) at ``time_s`` [s]."""
        ...


class MotorCurve(Protocol):
    """One motor's static thrust curve and the motor count: a :class:`VehicleProfile`, or a
    ``kind: static`` thrust-model file written by ``tether-companion sysid``."""

    @property
    def thrust_curve(self) -> ThrustCurve:
        """Static PWM-to-thrust map of one motor."""
        ...

    @property
    def n_motors(self) -> int:
        """Number of motors."""
        ...


class StaticThrustInput:
    """Sum of a static thrust curve over the motors (no motor dynamics).

    Evaluates :meth:`ThrustCurve.thrust_n` with scalar arithmetic: it runs on every PWM
    sample of every estimator, where numpy's per-call overhead dominates for 4 motors
    (a test checks that both agree).

    Parameters
    ----------
    vehicle
        The vehicle profile, or anything else with ``thrust_curve`` and ``n_motors``
        (:class:`MotorCurve`, e.g. an identified static model).
    """

    def __init__(self, vehicle: MotorCurve) -> None:
        curve = vehicle.thrust_curve
        self.curve = curve
        self.n_motors = vehicle.n_motors
        self._pwm_min_us = curve.pwm_min_us
        self._per_us = 1.0 / (curve.pwm_max_us - curve.pwm_min_us)
        self._full_scale = curve.command_full_scale
        self._c0, self._c1, self._c2 = curve.coefficients_n
        self._battery = getattr(vehicle, "battery", None)
        self.voltage_ratio = 1.0
        """Battery voltage over the curve's (1 until a voltage is measured, or when the
        profile has no battery model): each motor command is scaled by it."""

    def set_battery_voltage_v(self, voltage_v: float) -> None:
        """Measured battery voltage [V] (SYS_STATUS / BATTERY_STATUS); ignored without a
        battery model in the profile, a non-finite value keeps the ratio at 1."""
        if self._battery is not None and self._battery.enabled:
            self.voltage_ratio = self._battery.ratio(voltage_v)

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """Total thrust [N]; ``time_s`` is unused (the map is static).

        Raises
        ------
        ValueError
            When the number of pulse widths is not the vehicle's motor count.
        """
        if len(pwm_us) != self.n_motors:
            raise ValueError(f"expected {self.n_motors} pulse widths, got {len(pwm_us)}")
        return STATIC_THRUST(
            pwm_us.tolist() if isinstance(pwm_us, np.ndarray) else pwm_us,
            self._pwm_min_us,
            self._per_us,
            self._full_scale * self.voltage_ratio,
            self._c0 * self.n_motors,
            self._c1,
            self._c2,
        )


def static_thrust_n(
    pwm_us: Sequence[float],
    pwm_min_us: float,
    per_us: float,
    scale: float,
    total: float,
    c1: float,
    c2: float,
) -> float:
    """``total`` [N] plus each motor's ``c1 cmd + c2 cmd^2`` [N] for the pulse widths
    ``pwm_us`` [us]: ``cmd`` the command ``(pwm - pwm_min_us) per_us`` clipped to [0, 1] times
    ``scale`` (:meth:`StaticThrustInput.total_thrust_n`: ``total`` is ``n c0``). The reference
    of ``_tension_core.static_thrust`` (:data:`STATIC_THRUST`)."""
    for pwm in pwm_us:
        u = (pwm - pwm_min_us) * per_us
        cmd = (0.0 if u < 0.0 else 1.0 if u > 1.0 else u) * scale
        total += cmd * (c1 + c2 * cmd)
    return total


STATIC_THRUST: Callable[..., float] = static_thrust_n
""":func:`static_thrust_n`, or where the optional C extension ``_tension_core`` is built (and
``TETHER_PURE_PYTHON`` is not set) its twin ``static_thrust``: the same floats, the Python
function called where C could differ (arguments not exact floats, more than 16 motors, a
non-finite result). An extension built before the function existed leaves the Python."""
_CORE = optional_core.load("tether_companion.estimation._tension_core")
if _CORE is not None and hasattr(_CORE, "static_thrust"):
    STATIC_THRUST = functools.partial(_CORE.static_thrust, static_thrust_n)


HOLD_FRACTION = 0.5
""":class:`MotorLagThrustInput` returns the lagged thrust half-way through the new command's
hold: the average over the hold to first order, which is what the IMU ticks until the next PWM
sample see."""
RESTART_GAP_S = 1.0
"""A gap between PWM samples longer than this [s] (or time going back) restarts the motor lag
at the commanded thrust."""


class MotorLagThrustInput:
    """Total thrust [N] of the profile's static curve through its first-order motor lag.

    The paper's static map (PWM -> thrust) ignores that a rotor needs tens of milliseconds to
    reach a new speed. In the open-loop evaluation the commands change slowly and that hardly
    matters; when the autopilot flies on our estimate, every correction it makes is a fast PWM
    change whose thrust arrives late, the accelerometer model then explains the missing thrust
    with the cable, the estimate moves, the autopilot corrects again: a feedback loop that can
    diverge. Modelling the lag that the vehicle profile states (``motor_time_constant_s``)
    breaks it.

    Each motor's thrust follows ``tau f' = f_cmd(pwm) - f``, with the command held between PWM
    samples (zero-order hold, as the flight controller's output is). The lag is linear and the
    same for every motor, so the total thrust is the lagged sum of the static per-motor
    thrusts::

        f(t_k) = f_cmd(t_{k-1}) + (f(t_{k-1}) - f_cmd(t_{k-1})) exp(-(t_k - t_{k-1}) / tau)

    Parameters
    ----------
    vehicle
        Profile giving the thrust curve and ``motor_time_constant_s``.
    """

    def __init__(self, vehicle: VehicleProfile) -> None:
        self._static = StaticThrustInput(vehicle)
        self._lag = MotorLag(vehicle.motor_time_constant_s)
        self._thrust_n = math.nan
        self._command_n = math.nan
        self._time_s = math.nan
        self._interval_s = 0.0

    def set_battery_voltage_v(self, voltage_v: float) -> None:
        """Measured battery voltage [V] for the static curve (see :class:`StaticThrustInput`)."""
        self._static.set_battery_voltage_v(voltage_v)

    @property
    def time_constant_s(self) -> float:
        """Motor time constant ``tau`` [s]."""
        return self._lag.time_constant_s

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """Thrust [N] expected over the hold of the new command ``pwm_us`` [us] given at ``time_s``.

        The estimator uses the value until the next PWM sample, so it is the lagged thrust
        ``HOLD_FRACTION`` of one sample interval (the last one seen) into the new command's hold.

        Raises
        ------
        ValueError
            When the number of pulse widths is not the vehicle's motor count.
        """
        command_n = self._static.total_thrust_n(pwm_us, time_s)
        self._thrust_n, self._interval_s, expected_n = LAGGED_THRUST(
            command_n,
            time_s - self._time_s,
            self._thrust_n,
            self._command_n,
            self._interval_s,
            self._lag.time_constant_s,
        )
        self._command_n = command_n
        self._time_s = time_s
        return expected_n


def lagged_thrust_n(
    command_n: float,
    dt_s: float,
    thrust_n: float,
    last_command_n: float,
    interval_s: float,
    time_constant_s: float,
) -> tuple[float, float, float]:
    """One PWM sample of :class:`MotorLagThrustInput`: the new command's static thrust
    ``command_n`` [N] ``dt_s`` [s] after the last sample (nan for the first), the lagged thrust
    ``thrust_n`` [N] under the previous command ``last_command_n`` [N] then, the last sample
    interval ``interval_s`` [s] and the motor time constant [s]. Returns ``(thrust_n,
    interval_s, expected_n)``: the lagged thrust now and the interval (restarted at the command
    after a gap, :data:`RESTART_GAP_S`), and the thrust expected over the new command's hold
    (``HOLD_FRACTION`` of the interval into it). Each decay is
    :func:`~tether_companion.physics.motors.lag_decay`.

    The reference: :data:`LAGGED_THRUST` is what runs."""
    if not (0.0 < dt_s <= RESTART_GAP_S):  # first sample (nan), time went back, long gap
        thrust_n = command_n
    else:  # exact zero-order-hold response up to now, under the previous command
        decay = lag_decay(dt_s, time_constant_s)
        thrust_n = last_command_n + (thrust_n - last_command_n) * decay
        interval_s = dt_s
    ahead = lag_decay(HOLD_FRACTION * interval_s, time_constant_s)
    return thrust_n, interval_s, command_n + (thrust_n - command_n) * ahead


LAGGED_THRUST: Callable[..., tuple[float, float, float]] = lagged_thrust_n
""":func:`lagged_thrust_n`, or where ``_tension_core`` is built with it (and
``TETHER_PURE_PYTHON`` is not set) its twin ``lagged_thrust``: the same floats (libm's ``exp``
as ``math``'s), the Python function called where C could differ (arguments not exact floats,
a zero time constant, a non-finite result)."""
if _CORE is not None and hasattr(_CORE, "lagged_thrust"):
    LAGGED_THRUST = functools.partial(_CORE.lagged_thrust, lagged_thrust_n)
