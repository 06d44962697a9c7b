"""Time alignment of the estimators' inputs: the latest attitude and PWM at each IMU tick.

The estimators tick at the IMU rate. Attitude and motor outputs arrive on their own streams;
an :class:`InputAligner` keeps the latest of each, converted once per sample (the rotation
``R_v^b`` and tilt per attitude sample, the total thrust per PWM sample through a
:class:`ThrustInput`), and at an IMU sample returns either the aligned inputs or why there are
none (non-finite IMU sample, attitude or PWM missing or older/newer than its staleness bound).

The aligner keeps no counters: it reports why, and each estimator counts in its own health.
Pure and synchronous.

Sharing: a host running several estimators on the same streams (the tether EKF and the
tension filter) can give them one aligner and feed each estimator every sample as before. The
aligner remembers the last sample object of each stream and its outcome, so the second
estimator handed the same object gets the stored outcome without a second conversion; in
particular a stateful, time-dependent thrust input (motor lag, identified linear model) is
advanced exactly once per PWM sample.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterator

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation import optional_core
from tether_companion.estimation.thrust_input import ThrustInput
from tether_companion.frames import rotation_ned_to_body_rows
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

FloatArray = NDArray[np.float64]

NONFINITE_INPUT = "nonfinite"
"""A sample, or the thrust derived from it, contains NaN/inf."""
STALE_ATTITUDE = "stale_attitude"
"""No attitude yet, or the latest one is further from the IMU time than its bound."""
STALE_PWM = "stale_pwm"
"""No PWM yet, or the latest one is further from the IMU time than its bound."""

ROTATION_ROWS: Callable[[float, float, float], list[list[float]]] = rotation_ned_to_body_rows
""":func:`~tether_companion.frames.rotation_ned_to_body_rows`, or where the optional C extension
``_tension_core`` is built (and ``TETHER_PURE_PYTHON`` is not set) its twin ``rotation_rows``:
the same floats (libm's ``sin``/``cos`` as ``math``'s), the Python function called where C
could differ (angles not exact finite floats, for ``math``'s error on an infinity). Once per
ATTITUDE sample."""
_CORE = optional_core.load("tether_companion.estimation._tension_core")
if _CORE is not None and hasattr(_CORE, "rotation_rows"):
    ROTATION_ROWS = functools.partial(_CORE.rotation_rows, rotation_ned_to_body_rows)


class Rotation:
    """One attitude's ``R_v^b`` (paper eq. 2): its rows as Python floats, made at once, and
    the numpy matrix, made on first read (the scalar filters never read it).

    Attributes
    ----------
    rows
        ``R_v^b`` row by row (do not modify).
    """

    __slots__ = ("_matrix", "rows")

    def __init__(self, rows: list[list[float]]) -> None:
        self.rows = rows
        self._matrix: FloatArray | None = None

    @property
    def matrix(self) -> FloatArray:
        """``R_v^b``, shape (3, 3): ``v_body = R @ v_ned`` (the same array at every read)."""
        if self._matrix is None:
            self._matrix = np.array(self.rows)
        return self._matrix


_IDENTITY = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


class AlignedInputs:
    """Inputs of one IMU tick, aligned in time.

    Attributes
    ----------
    time_s
        IMU time [s].
    specific_force_body_mps2
        Accelerometer specific force, FRD body frame, shape (3,) [m/s^2].
    rotation
        The latest attitude's :class:`Rotation`.
    thrust_n
        Total rotor thrust of the latest motor outputs, along body -z [N].

    Unpacks as ``time_s, specific_force_body_mps2, rotation_ned_to_body, thrust_n`` (which
    makes the matrix; scalar code reads the attributes it needs instead). The aligner that made
    it holds the same inputs as Python floats (:attr:`InputAligner.specific_force_values`,
    :attr:`InputAligner.rotation_rows`).
    """

    __slots__ = ("rotation", "specific_force_body_mps2", "thrust_n", "time_s")

    def __init__(
        self,
        time_s: float,
        specific_force_body_mps2: FloatArray,
        rotation: Rotation,
        thrust_n: float,
    ) -> None:
        self.time_s = time_s
        self.specific_force_body_mps2 = specific_force_body_mps2
        self.rotation = rotation
        self.thrust_n = thrust_n

    def __iter__(self) -> Iterator:
        return iter(
            (self.time_s, self.specific_force_body_mps2, self.rotation.matrix, self.thrust_n)
        )

    @property
    def rotation_ned_to_body(self) -> FloatArray:
        """``R_v^b`` of the latest attitude (paper eq. 2), shape (3, 3): ``v_body = R @ v_ned``."""
        return self.rotation.matrix

    @property
    def rotation_body_to_ned(self) -> FloatArray:
        """``R_b^v = (R_v^b)^T``, shape (3, 3): ``v_ned = R @ v_body``."""
        return self.rotation.matrix.T


class InputAligner:
    """Latest attitude and PWM, checked against staleness bounds at each IMU sample.

    Parameters
    ----------
    attitude_staleness_s
        Largest ``|t_imu - t_attitude|`` for an aligned tick [s].
    pwm_staleness_s
        Largest ``|t_imu - t_pwm|`` for an aligned tick [s].
    thrust_input
        PWM-to-thrust map, called once per accepted-finite PWM sample with
        ``(pwm_us, time_s)`` (it may be stateful and time-dependent).

    Attributes
    ----------
    attitude
        Latest finite attitude sample (``None`` before the first).
    rotation_ned_to_body
        ``R_v^b`` of ``attitude``, shape (3, 3) (identity before the first; made on first
        read).
    rotation_rows
        The same row by row as Python floats (computed once per attitude sample).
    specific_force_values
        The specific force of the last IMU sample handed to :meth:`align`, 3 Python floats
        [m/s^2] (converted once per sample).
    cos_tilt
        ``cos(roll) cos(pitch)`` of ``attitude`` (the rangefinder's tilt correction).
    pwm_time_s, thrust_n
        Time [s] and total thrust [N] of the latest accepted PWM sample (``nan`` before).
    """

    def __init__(
        self, attitude_staleness_s: float, pwm_staleness_s: float, thrust_input: ThrustInput
    ) -> None:
        self.attitude_staleness_s = attitude_staleness_s
        self.pwm_staleness_s = pwm_staleness_s
        self.thrust_input = thrust_input
        self.attitude: AttitudeSample | None = None
        self._rotation = Rotation(_IDENTITY)
        self.specific_force_values: list[float] = [math.nan] * 3
        self.cos_tilt = 1.0
        self.pwm_time_s = math.nan
        self.thrust_n = math.nan
        self._attitude_in: AttitudeSample | None = None
        self._attitude_outcome: str | None = None
        self._pwm_in: PwmSample | None = None
        self._pwm_outcome: str | None = None
        self._imu_in: ImuSample | None = None
        self._imu_outcome: AlignedInputs | str = NONFINITE_INPUT

    @property
    def rotation_rows(self) -> list[list[float]]:
        """``R_v^b`` of :attr:`attitude` row by row (Python floats)."""
        return self._rotation.rows

    @property
    def rotation_ned_to_body(self) -> FloatArray:
        """``R_v^b`` of :attr:`attitude`, shape (3, 3) (made on first read)."""
        return self._rotation.matrix

    def on_attitude(self, sample: AttitudeSample) -> str | None:
        """Store the latest attitude; ``None`` when stored, else :data:`NONFINITE_INPUT`."""
        if sample is self._attitude_in:  # the same sample from another estimator
            return self._attitude_outcome
        self._attitude_in = sample
        t, roll, pitch, yaw = sample.time_s, sample.roll_rad, sample.pitch_rad, sample.yaw_rad
        if not (
            math.isfinite(t) and math.isfinite(roll) and math.isfinite(pitch) and math.isfinite(yaw)
        ):
            self._attitude_outcome = NONFINITE_INPUT
            return NONFINITE_INPUT
        self.attitude = sample
        self._rotation = Rotation(ROTATION_ROWS(roll, pitch, yaw))
        self.cos_tilt = math.cos(roll) * math.cos(pitch)
        self._attitude_outcome = None
        self._imu_in = None
        return None

    def on_pwm(self, sample: PwmSample) -> str | None:
        """Store the total thrust of the latest motor outputs; ``None`` when stored, else
        :data:`NONFINITE_INPUT` (pulse widths, time or the resulting thrust).

        Raises
        ------
        ValueError
            From the thrust input, when it refuses the pulse widths (wrong motor count);
            nothing is stored, and the same sample is offered to the thrust input again if
            handed in again.
        """
        if sample is self._pwm_in:  # the same sample from another estimator
            return self._pwm_outcome
        if not math.isfinite(sample.time_s + sum(sample.pwm_us.tolist())):  # NaN/inf in any
            outcome: str | None = NONFINITE_INPUT
        else:
            thrust_n = self.thrust_input.total_thrust_n(sample.pwm_us, sample.time_s)
            if math.isfinite(thrust_n):
                self.pwm_time_s = sample.time_s
                # a Python float: a numpy scalar would make every product of the scalar EKF
                # update a numpy operation (several times slower)
                self.thrust_n = float(thrust_n)
                self._imu_in = None
                outcome = None
            else:
                outcome = NONFINITE_INPUT
        self._pwm_in, self._pwm_outcome = sample, outcome
        return outcome

    def align(self, sample: ImuSample) -> AlignedInputs | str:
        """The inputs aligned at the IMU sample's time, or why not.

        Returns
        -------
        AlignedInputs or str
            The aligned inputs, else :data:`NONFINITE_INPUT` (IMU time or specific force),
            :data:`STALE_ATTITUDE` or :data:`STALE_PWM` (checked in that order; these module
            constants themselves, so ``is`` compares). Changes no state apart from a cache of
            this outcome: the caller may still drop the tick.
        """
        if sample is self._imu_in:  # the same tick from another estimator, inputs unchanged
            return self._imu_outcome
        t = sample.time_s
        force = sample.specific_force_body_mps2
        outcome: AlignedInputs | str
        values = self.specific_force_values = force.tolist()
        if not math.isfinite(t + values[0] + values[1] + values[2]):  # NaN/inf in any
            outcome = NONFINITE_INPUT
        elif self.attitude is None or not (
            abs(t - self.attitude.time_s) <= self.attitude_staleness_s
        ):
            outcome = STALE_ATTITUDE
        elif not abs(t - self.pwm_time_s) <= self.pwm_staleness_s:  # nan before the first
            outcome = STALE_PWM
        else:
            outcome = AlignedInputs(t, force, self._rotation, self.thrust_n)
        self._imu_in, self._imu_outcome = sample, outcome
        return outcome


def aligner_for(
    shared: InputAligner | None,
    attitude_staleness_s: float,
    pwm_staleness_s: float,
    thrust_input: ThrustInput | None,
    default_thrust_input: Callable[[], ThrustInput],
) -> InputAligner:
    """An estimator's aligner: ``shared`` checked against the estimator's settings, else a
    private one with ``thrust_input`` (or ``default_thrust_input()`` when that is ``None``).

    Raises
    ------
    ValueError
        When ``shared`` has other staleness bounds [s], or comes with a different
        ``thrust_input`` (a shared aligner brings its own).
    """
    if shared is None:
        thrust = thrust_input if thrust_input is not None else default_thrust_input()
        return InputAligner(attitude_staleness_s, pwm_staleness_s, thrust)
    bounds = (shared.attitude_staleness_s, shared.pwm_staleness_s)
    if bounds != (attitude_staleness_s, pwm_staleness_s):
        raise ValueError(
            f"shared aligner's staleness bounds (attitude, PWM) {bounds} s differ from the "
            f"estimator's {(attitude_staleness_s, pwm_staleness_s)} s"
        )
    if thrust_input is not None and thrust_input is not shared.thrust_input:
        raise ValueError("a shared aligner brings its own thrust input; do not give another")
    return shared
