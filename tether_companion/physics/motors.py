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

import functools
import math
from bisect import bisect_left
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tether_companion.physics.vehicle import VehicleProfile

FloatArray = NDArray[np.float64]


def lag_decay(dt_s: float, time_constant_s: float) -> float:
    """``exp(-dt/tau)``: the fraction of a thrust error left after ``dt_s`` [s] of a first-order
    lag with time constant ``time_constant_s`` [s]."""
    return math.exp(-dt_s / time_constant_s)


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
        return lag_decay(dt_s, self.time_constant_s)


@functools.cache
def lag_function(n_motors: int) -> Callable[[Sequence[float], Sequence[float], float], list[float]]:
    """``lag(targets, thrusts, decay)``: the ``n_motors`` thrusts [N] after a step whose
    :meth:`MotorLag.decay` is ``decay``, each ``f_ss + (f - f_ss) decay`` for its steady-state
    target ``f_ss`` (straight-line code per motor count: this runs at every physics step)."""
    motors = range(n_motors)
    source = (
        "def lag(targets, thrusts, decay):\n"
        f"    {''.join(f's{i}, ' for i in motors)}= targets\n"
        f"    {''.join(f'f{i}, ' for i in motors)}= thrusts\n"
        f"    return [{', '.join(f's{i} + (f{i} - s{i}) * decay' for i in motors)}]\n"
    )
    namespace: dict = {}
    exec(compile(source, f"<generated motor lag, {n_motors} motors>", "exec"), namespace)  # noqa: S102
    return namespace["lag"]


class MotorMixer:
    """Turn a wrench (collective thrust, body torques) into motor thrusts and PWM pulses.

    Uses the Moore-Penrose inverse of the vehicle's allocation matrix
    (:meth:`VehicleProfile.allocation_matrix`, shape (4, n)), which for a quad X is the exact
    inverse. Saturation: the collective thrust per motor is clipped to [f_min, f_max]; the
    torque share is then scaled down uniformly (by the largest factor <= 1) so every motor
    stays in range: attitude authority is kept in proportion, the collective is never traded.

    PWM outputs are whole microseconds. The thrust curve is tabulated once at every whole
    microsecond in [pwm_min_us, pwm_max_us]; a thrust maps to the pulse whose steady-state
    thrust is nearest, and a pulse maps back by table look-up (scalar, no arrays: this runs
    at the controller's rate).
    """

    def __init__(self, vehicle: VehicleProfile) -> None:
        self.vehicle = vehicle
        self.curve = vehicle.thrust_curve
        self.n_motors = vehicle.n_motors
        self.allocation = vehicle.allocation_matrix()
        pseudo_inverse = np.linalg.pinv(self.allocation)
        self._collective_share = pseudo_inverse[:, 0].tolist()
        self._torque_rows = [tuple(row) for row in pseudo_inverse[:, 1:].tolist()]
        self._mix = _mixing_function(tuple(self._collective_share), tuple(self._torque_rows))
        first = math.ceil(self.curve.pwm_min_us)
        last = math.floor(self.curve.pwm_max_us)
        self._first_pwm_us = first
        self._thrust_table_n: list[float] = self.curve.thrust_n(np.arange(first, last + 1)).tolist()
        self.min_thrust_n = self._thrust_table_n[0]
        self.max_thrust_n = self._thrust_table_n[-1]

    def motor_thrusts_n(self, collective_n: float, torque_body_n_m: Sequence[float]) -> list[float]:
        """Motor thrusts [N], n values, for a collective thrust [N] and FRD torques (3,) [N m]
        (the saturation rule of the class docstring; :func:`_mixing_function`'s code)."""
        return self._mix(collective_n, torque_body_n_m, self.min_thrust_n, self.max_thrust_n)

    def pwm_us(self, motor_thrusts_n: Sequence[float]) -> list[float]:
        """Whole-microsecond PWM pulses whose steady-state thrusts are nearest the given [N]."""
        table = self._thrust_table_n
        last = len(table) - 1
        pulses = []
        for thrust in motor_thrusts_n:
            i = bisect_left(table, thrust)
            if i > last:
                i = last
            elif i > 0 and thrust - table[i - 1] <= table[i] - thrust:
                i -= 1
            pulses.append(float(self._first_pwm_us + i))
        return pulses

    def thrusts_for_pwm_us(self, pwm_us: Sequence[float]) -> list[float]:
        """Steady-state thrusts [N] of whole-microsecond pulses (clipped to the curve's range)."""
        table = self._thrust_table_n
        last = len(table) - 1
        return [table[min(max(int(p) - self._first_pwm_us, 0), last)] for p in pwm_us]

    def idle_pwm_us(self) -> list[float]:
        """PWM pulses [us] of stopped motors (the lowest whole microsecond on every output)."""
        return [float(self._first_pwm_us)] * self.n_motors

    def wrench(self, motor_thrusts_n: ArrayLike) -> FloatArray:
        """(collective [N], roll, pitch, yaw torque [N m]), (4,), of motor thrusts (n,) [N]."""
        return self.allocation @ np.asarray(motor_thrusts_n, dtype=float)


@functools.cache
def _mixing_function(
    collective_share: tuple[float, ...], torque_rows: tuple[tuple[float, float, float], ...]
) -> Callable[[float, Sequence[float], float, float], list[float]]:
    """``mix(collective_n, torque, f_min, f_max)``: :meth:`MotorMixer.motor_thrusts_n` as
    straight-line code for one allocation's pseudo-inverse (its entries written in as exact
    literals), one motor after another (no list, comprehension or loop: this runs at the
    controller's rate). For motor ``i`` with collective share ``c_i`` and torque row
    ``(a_i, b_i, e_i)``::

        base_i  = min(max(c_i T, f_min), f_max)
        share_i = a_i tau_l + b_i tau_m + e_i tau_n
        scale   = max(min(1, (f_max - base_i) / share_i where base_i + share_i > f_max,
                             (f_min - base_i) / share_i where base_i + share_i < f_min), 0)
        f_i     = base_i + scale share_i
    """
    if not all(map(math.isfinite, (*collective_share, *(v for r in torque_rows for v in r)))):
        raise ValueError("the allocation's pseudo-inverse is not finite")
    lines = ["tl, tm, tn = torque", "scale = 1.0"]
    for i, (c, (a, b, e)) in enumerate(zip(collective_share, torque_rows, strict=True)):
        # min()/max() as comparisons in the builtins' order (a later value replaces the
        # first only when it compares smaller/greater: the same floats, nan included),
        # without their calls
        lines += [
            f"b{i} = {c!r} * collective_n",
            f"if f_min > b{i}:",
            f"    b{i} = f_min",
            f"if f_max < b{i}:",
            f"    b{i} = f_max",
            f"d{i} = {a!r} * tl + {b!r} * tm + {e!r} * tn",
            f"if d{i} > 0.0 and b{i} + d{i} > f_max:",
            f"    limit = (f_max - b{i}) / d{i}",
            "    if limit < scale:",
            "        scale = limit",
            f"elif d{i} < 0.0 and b{i} + d{i} < f_min:",
            f"    limit = (f_min - b{i}) / d{i}",
            "    if limit < scale:",
            "        scale = limit",
        ]
    lines += ["if 0.0 > scale:", "    scale = 0.0"]
    lines.append(
        "return [" + ", ".join(f"b{i} + scale * d{i}" for i in range(len(torque_rows))) + "]"
    )
    source = "def mix(collective_n, torque, f_min, f_max):\n" + "".join(
        f"    {line}\n" for line in lines
    )
    namespace: dict = {}
    exec(compile(source, "<generated motor mixing>", "exec"), namespace)  # noqa: S102
    return namespace["mix"]
