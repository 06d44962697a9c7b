"""What the paper filters' pipeline hands out at each IMU tick: :class:`Estimate` (the state,
its covariance, the tension and flags, arrays built only when read) and the counters of what
it did with its inputs, :class:`EstimatorHealth` (made by
:class:`~tether_companion.estimation.pipeline.TetherEstimator`)."""

from __future__ import annotations

import dataclasses
import math
import operator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.tether_models import POSITION

FloatArray = NDArray[np.float64]


@dataclass(slots=True)
class EstimatorHealth:
    """Counters of what the pipeline did with its inputs (all monotonic except the flags).

    Attributes
    ----------
    imu_ticks
        IMU samples that advanced the filter.
    accel_fused, accel_gated, accel_forced
        Accelerometer updates fused, rejected by the innovation gate, fused after the gate
        yielded (see ``gate.max_consecutive_rejections``).
    stale_attitude, stale_pwm, stale_tension
        IMU ticks without an accelerometer update because the attitude, PWM or known
        tension (3-state) was missing or older than its staleness bound.
    near_anchor
        IMU ticks without an accelerometer update because the estimate was closer to the
        anchor than ``min_cable_length_m`` (cable direction undefined).
    range_fused, range_gated, range_out_of_range, range_stale
        Rangefinder samples fused, gated, outside the valid range or tilt, or without a
        fresh attitude / older than the filter.
    nonfinite_rejected
        Samples (any kind) or derived inputs containing NaN/inf, rejected before the filter.
    pwm_invalid
        PWM samples the thrust input refused (not one pulse width per motor).
    out_of_order
        Samples older than the filter time, dropped.
    resets
        Filter restarts (long IMU gap, non-finite state); equals ``reset_counter``.
    pd_repairs
        Covariances repaired after losing positive definiteness.
    last_accel_nis, last_range_nis
        Normalised innovation squared of the last accelerometer / rangefinder sample.
    """

    imu_ticks: int = 0
    accel_fused: int = 0
    accel_gated: int = 0
    accel_forced: int = 0
    stale_attitude: int = 0
    stale_pwm: int = 0
    stale_tension: int = 0
    near_anchor: int = 0
    range_fused: int = 0
    range_gated: int = 0
    range_out_of_range: int = 0
    range_stale: int = 0
    nonfinite_rejected: int = 0
    pwm_invalid: int = 0
    out_of_order: int = 0
    resets: int = 0
    pd_repairs: int = 0
    last_accel_nis: float = math.nan
    last_range_nis: float = math.nan

    def copy(self) -> EstimatorHealth:
        """A snapshot."""
        return EstimatorHealth(*_HEALTH_VALUES(self))

    def values(self) -> tuple:
        """All fields in declaration order (a cheap snapshot)."""
        return _HEALTH_VALUES(self)


_HEALTH_VALUES = operator.attrgetter(*(f.name for f in dataclasses.fields(EstimatorHealth)))


class Estimate:
    """The estimator's output at one IMU tick (read-only).

    Attributes
    ----------
    time_s
        Flight-controller time of the tick [s].
    position_ned_m
        Drone position relative to the tether anchor, NED, shape (3,) [m].
    tension_n
        Cable tension [N]: the state's (4-state) or the known one (3-state).
    covariance
        State covariance, shape (n, n): position block [m^2] first, then tension [N^2].
    reset_counter
        Increments each time the filter restarts (for VISION_POSITION_ESTIMATE.reset_counter).
    accel_fused
        Whether this tick fused the accelerometer.
    health_values
        The pipeline's counters at this tick, in :class:`EstimatorHealth` field order; read
        them as ``estimate.health`` (kept as a tuple: an estimate is made at every IMU tick).
    missing_input
        The input whose absence leaves part of the position unobserved (``"rangefinder"``:
        no height fused for ``observability.range_lost_after_s``; the covariance along the
        cable grows meanwhile), or None.

    The estimator makes it from the filter's state and covariance as Python floats
    (:meth:`of_values`, also readable as :attr:`state_values` and :attr:`covariance_values`)
    and builds the arrays only when ``position_ned_m`` or ``covariance`` is first read: an
    estimate is made at every IMU tick and most consumers offline read a few numbers.
    """

    __slots__ = (
        "time_s",
        "tension_n",
        "reset_counter",
        "accel_fused",
        "health_values",
        "missing_input",
        "_state",
        "_covariance_values",
        "_position",
        "_covariance",
    )

    def __init__(
        self,
        time_s: float,
        position_ned_m: FloatArray,
        tension_n: float,
        covariance: FloatArray,
        reset_counter: int,
        accel_fused: bool,
        health_values: tuple,
        missing_input: str | None = None,
    ) -> None:
        self._describe(time_s, tension_n, reset_counter, accel_fused, health_values, missing_input)
        self._position: FloatArray | None = position_ned_m
        self._covariance: FloatArray | None = covariance
        self._state: list[float] | None = None
        self._covariance_values: list[float] | None = None

    def _describe(
        self,
        time_s: float,
        tension_n: float,
        reset_counter: int,
        accel_fused: bool,
        health_values: tuple,
        missing_input: str | None,
    ) -> None:
        """Set the fields both constructors share."""
        self.time_s = time_s
        self.tension_n = tension_n
        self.reset_counter = reset_counter
        self.accel_fused = accel_fused
        self.health_values = health_values
        self.missing_input = missing_input

    @classmethod
    def of_values(
        cls,
        time_s: float,
        state: list[float],
        covariance: list[float],
        tension_n: float,
        reset_counter: int,
        accel_fused: bool,
        health_values: tuple,
        missing_input: str | None,
    ) -> Estimate:
        """An estimate from the state (n values, position first) and covariance (n*n values,
        row-major) as lists the estimate keeps (give it copies)."""
        estimate = cls.__new__(cls)
        estimate._describe(
            time_s, tension_n, reset_counter, accel_fused, health_values, missing_input
        )
        estimate._state = state
        estimate._covariance_values = covariance
        estimate._position = None
        estimate._covariance = None
        return estimate

    @property
    def position_ned_m(self) -> FloatArray:
        """Drone position relative to the tether anchor, NED, shape (3,) [m]."""
        position = self._position
        if position is None:
            state = self._state
            assert state is not None
            position = self._position = np.array(state[POSITION])
        return position

    @property
    def covariance(self) -> FloatArray:
        """State covariance, shape (n, n): position block [m^2] first, then tension [N^2]."""
        covariance = self._covariance
        if covariance is None:
            n = len(self._state)  # type: ignore[arg-type]
            covariance = np.array(self._covariance_values).reshape(n, n)
            self._covariance = covariance
        return covariance

    @property
    def state_values(self) -> list[float]:
        """The position (3 values, NED [m]) followed by the state's tension [N] if it has one,
        as Python floats (a list the caller must not change)."""
        state = self._state
        if state is None:
            state = self._state = self._position.tolist()  # type: ignore[union-attr]
            n = self.covariance.shape[0]
            if n > len(state):
                state.append(self.tension_n)
        return state

    @property
    def covariance_values(self) -> list[float]:
        """The covariance's n*n entries row-major as Python floats (a list the caller must not
        change)."""
        values = self._covariance_values
        if values is None:
            values = self._covariance_values = self.covariance.ravel().tolist()
        return values

    @property
    def health(self) -> EstimatorHealth:
        """Snapshot of the pipeline's counters at this tick."""
        return EstimatorHealth(*self.health_values)

    @property
    def position_covariance_m2(self) -> FloatArray:
        """Position block of the covariance, shape (3, 3) [m^2]."""
        return self.covariance[POSITION, POSITION]

    def __repr__(self) -> str:
        return (
            f"Estimate(time_s={self.time_s!r}, position_ned_m={self.position_ned_m!r}, "
            f"tension_n={self.tension_n!r}, reset_counter={self.reset_counter!r}, "
            f"accel_fused={self.accel_fused!r}, missing_input={self.missing_input!r})"
        )
