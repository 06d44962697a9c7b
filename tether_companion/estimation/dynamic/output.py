"""What the dynamic tether filter hands to the service: :class:`NavigationEstimate`, and its
counters (:class:`DynamicHealth`).

One estimate per IMU tick: position and velocity of the drone relative to the tether anchor
(NED), their joint 6x6 covariance, the cable tension at the drone, and an observability status
with a human-readable reason, so the publisher can withhold or inflate with the reason shown.

Compatibility with :class:`~tether_companion.estimation.estimate.Estimate` (the paper's
filters) and the service's ``PositionEstimate`` protocol: ``time_s``, ``position_ned_m``,
``tension_n``, ``covariance`` (position block first, then the tension variance: shape (4, 4),
the 4-state layout the publisher and its CSV read), ``position_covariance_m2``,
``reset_counter``, ``accel_fused`` and ``health`` have the same meaning and units. New:
``velocity_ned_mps``, ``position_velocity_covariance`` (6, 6), ``velocity_covariance_m2ps2``,
``status``, ``reason``, ``observable``, ``thrust_scale``, ``accel_bias_body_mps2``,
``wind_ne_mps``.

Pure data; its values are computed when first read (see
:mod:`~tether_companion.estimation.dynamic.published`), nothing else.
"""

from __future__ import annotations

import dataclasses
import math
import operator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from tether_companion.estimation.dynamic.published import TickSource

FloatArray = NDArray[np.float64]

OK = "ok"
"""Position observable and the filter converged: publish."""
INITIALISING = "initialising"
"""No state yet: the first second of data has not given a cable direction and a height."""
WEAK_PULL = "weak_pull"
"""The horizontal pull is too weak for the horizontal position (covariance beyond the bound)."""
LEARNING = "learning"
"""The horizontal position is beyond the bound only for the thrust scale and the wind not yet
learned (the cable's pull trades against them in a steady hover, until motion or a load cell
separates them)."""
SLACK = "slack"
"""The cable tension at the drone is below the slack threshold: the direction says nothing."""
ON_GROUND = "on_ground"
"""The motors carry much less than the weight: standing on the ground, the model does not hold."""
STALE_INPUTS = "stale_inputs"
"""This tick had no fresh attitude or PWM: prediction only, the force balance not fused."""
RESET = "reset"
"""The filter diverged (non-finite or inconsistent state) or had an IMU gap and restarted."""

STATUSES = (OK, INITIALISING, LEARNING, WEAK_PULL, SLACK, ON_GROUND, STALE_INPUTS, RESET)
"""Every status, best first."""

POSITION_BLOCK = slice(0, 3)
"""Rows/columns of the position in :attr:`NavigationEstimate.position_velocity_covariance`."""
VELOCITY_BLOCK = slice(3, 6)
"""Rows/columns of the velocity in :attr:`NavigationEstimate.position_velocity_covariance`."""


class Approximation:
    """A tick's published values in Python floats, to within their rounding.

    Attributes
    ----------
    state
        The state's values (13).
    duration_s
        The step's duration ``T`` [s] (0 without a step).
    position
        Position NED [m] (3).
    horizontal
        Published horizontal position covariance: north-north, north-east, east-east [m^2].
    down_variance
        Published down variance [m^2].
    tension_n
        Tension at the drone [N].
    finite
        Whether every published value (position, covariance, tension and its variance) is
        finite for sure (False: not known).
    position_tol, covariance_tol
        Absolute bounds of the position's [m] and the covariance entries' [m^2] rounding.
    """

    __slots__ = (
        "covariance_tol",
        "down_variance",
        "duration_s",
        "finite",
        "horizontal",
        "position",
        "position_tol",
        "state",
        "tension_n",
    )

    def __init__(
        self,
        state: list[float],
        duration_s: float,
        horizontal: tuple[float, float, float],
        down_variance: float,
        tension_n: float,
        finite: bool,
        position_tol: float,
        covariance_tol: float,
    ) -> None:
        self.state = state
        self.duration_s = duration_s
        self.position = state[:3]
        self.horizontal = horizontal
        self.down_variance = down_variance
        self.tension_n = tension_n
        self.finite = finite
        self.position_tol = position_tol
        self.covariance_tol = covariance_tol


class ExactValues:
    """Every field of one tick's estimate (the arithmetic of the former per-tick
    computation; ``reason`` None while it waits to be read, the status known already:
    :meth:`~tether_companion.estimation.dynamic.published.TickSource.reason`)."""

    __slots__ = (
        "bias",
        "covariance",
        "position",
        "reason",
        "scale",
        "status",
        "tension",
        "tension_variance",
        "velocity",
        "wind",
    )

    def __init__(self, *values) -> None:  # noqa: ANN002 - the slots in order
        (
            self.position,
            self.velocity,
            self.covariance,
            self.tension,
            self.tension_variance,
            self.status,
            self.reason,
            self.scale,
            self.bias,
            self.wind,
        ) = values


class NavigationEstimate:
    """The dynamic filter's output at one IMU tick (SI units, NED from the tether anchor).

    Made by the filter from what the tick's values are computed from (a ``source``:
    :class:`~tether_companion.estimation.dynamic.published.TickSource`), they are computed
    when first read and kept: the status alone cheaply, every other field exactly (the same
    values whenever read); or made from the values themselves (keyword arguments, as below).
    Read-only.

    Attributes
    ----------
    time_s
        Flight-controller time of the IMU tick [s].
    position_ned_m
        Drone position relative to the anchor, NED, shape (3,) [m].
    velocity_ned_mps
        Drone velocity, NED, shape (3,) [m/s].
    position_velocity_covariance
        Joint covariance of (position, velocity), shape (6, 6): position block [m^2] first
        (:data:`POSITION_BLOCK`), then velocity [m^2/s^2] (:data:`VELOCITY_BLOCK`),
        cross terms [m^2/s]. Symmetric positive definite, finite.
    tension_n
        Magnitude of the cable's force on the drone [N].
    tension_variance_n2
        Its variance [N^2].
    reset_counter
        Filter restarts so far (for ``VISION_POSITION_ESTIMATE.reset_counter``).
    status
        One of :data:`STATUSES`: ``ok`` when the position may be published.
    reason
        Why the status is not ``ok``, in words fit for a STATUSTEXT (empty when ``ok``).
    accel_fused
        Whether this tick fused the accelerometer force balance.
    thrust_scale
        Estimated ratio of the true thrust to the thrust map's (1 = map exact).
    accel_bias_body_mps2
        Estimated accelerometer bias, FRD body, shape (3,) [m/s^2].
    wind_ne_mps
        Estimated wind, north and east, shape (2,) [m/s].
    health_values
        The filter's counters at this tick in field order of its health record; read them
        through ``health`` (a tuple, cheap at the IMU rate).
    health_type
        The class that names ``health_values`` (set by the filter).
    """

    __slots__ = (
        "_covariance4",
        "_source",
        "_status",
        "_values",
        "accel_fused",
        "health_type",
        "health_values",
        "reset_counter",
        "time_s",
    )

    def __init__(
        self,
        *,
        time_s: float,
        position_ned_m: FloatArray,
        velocity_ned_mps: FloatArray,
        position_velocity_covariance: FloatArray,
        tension_n: float,
        tension_variance_n2: float,
        reset_counter: int,
        status: str,
        reason: str,
        accel_fused: bool,
        thrust_scale: float,
        accel_bias_body_mps2: FloatArray,
        wind_ne_mps: FloatArray,
        health_values: tuple,
        health_type: type | None = None,
    ) -> None:
        self.time_s = time_s
        self.reset_counter = reset_counter
        self.accel_fused = accel_fused
        self.health_values = health_values
        self.health_type = health_type
        self._source = None
        self._status = status
        self._values = ExactValues(
            position_ned_m,
            velocity_ned_mps,
            position_velocity_covariance,
            tension_n,
            tension_variance_n2,
            status,
            reason,
            thrust_scale,
            accel_bias_body_mps2,
            wind_ne_mps,
        )
        self._covariance4: FloatArray | None = None

    @classmethod
    def of_tick(
        cls,
        time_s: float,
        reset_counter: int,
        accel_fused: bool,
        health_values: tuple,
        health_type: type | None,
        source: TickSource,
    ) -> NavigationEstimate:
        """The estimate whose values ``source`` computes when they are read."""
        estimate = cls.__new__(cls)
        estimate.time_s = time_s
        estimate.reset_counter = reset_counter
        estimate.accel_fused = accel_fused
        estimate.health_values = health_values
        estimate.health_type = health_type
        estimate._source = source
        estimate._status = None
        estimate._values = None
        estimate._covariance4 = None
        return estimate

    def _exact(self) -> ExactValues:
        values = self._values
        if values is None:
            assert self._source is not None
            values = self._values = self._source.values()
        return values

    @property
    def status(self) -> str:
        """One of :data:`STATUSES`."""
        status = self._status
        if status is None:
            assert self._source is not None
            status = self._status = self._source.status()
        return status

    def approximate(self) -> Approximation | None:
        """The published position, covariance and tension as Python floats with bounds of
        their rounding (None: none cheaper than the exact values; read those)."""
        return None if self._source is None else self._source.approximate()

    @property
    def position_ned_m(self) -> FloatArray:
        return self._exact().position

    @property
    def velocity_ned_mps(self) -> FloatArray:
        return self._exact().velocity

    @property
    def position_velocity_covariance(self) -> FloatArray:
        return self._exact().covariance

    @property
    def tension_n(self) -> float:
        return self._exact().tension

    @property
    def tension_variance_n2(self) -> float:
        return self._exact().tension_variance

    @property
    def reason(self) -> str:
        reason = self._exact().reason
        if reason is None:
            assert self._source is not None
            reason = self._source.reason()
        return reason

    @property
    def thrust_scale(self) -> float:
        return self._exact().scale

    @property
    def accel_bias_body_mps2(self) -> FloatArray:
        return self._exact().bias

    @property
    def wind_ne_mps(self) -> FloatArray:
        return self._exact().wind

    @property
    def observable(self) -> bool:
        """Whether the status is ``ok`` (the position may be published as is)."""
        return self.status == OK

    @property
    def position_covariance_m2(self) -> FloatArray:
        """Position block of the covariance, shape (3, 3) [m^2]."""
        return self.position_velocity_covariance[POSITION_BLOCK, POSITION_BLOCK]

    @property
    def velocity_covariance_m2ps2(self) -> FloatArray:
        """Velocity block of the covariance, shape (3, 3) [m^2/s^2]."""
        return self.position_velocity_covariance[VELOCITY_BLOCK, VELOCITY_BLOCK]

    @property
    def covariance(self) -> FloatArray:
        """Position block then tension variance, shape (4, 4) [m^2, N^2]: the layout of the
        paper's 4-state :class:`~tether_companion.estimation.estimate.Estimate` that the
        publisher and its CSV read (position-tension cross terms left at zero; made once)."""
        out = self._covariance4
        if out is None:
            out = np.zeros((4, 4))
            out[:3, :3] = self.position_covariance_m2
            out[3, 3] = self.tension_variance_n2
            self._covariance4 = out
        return out

    @property
    def health(self):  # noqa: ANN201 - the filter's health record type
        """The filter's counters at this tick (its health record type), or the raw tuple."""
        if self.health_type is None:
            return self.health_values
        return self.health_type(*self.health_values)

    def __repr__(self) -> str:
        fields = ("time_s", "status", "position_ned_m", "tension_n", "reset_counter")
        text = ", ".join(f"{name}={getattr(self, name)!r}" for name in fields)
        return f"NavigationEstimate({text})"


@dataclass(slots=True)
class DynamicHealth:
    """Counters of what the dynamic filter did with its inputs (monotonic except ``last_*``).

    Field names shared with :class:`~tether_companion.estimation.estimate.EstimatorHealth`
    mean the same (the service reads ``stale_attitude``, ``stale_pwm``, ``stale_tension``).
    """

    imu_ticks: int = 0
    accel_fused: int = 0
    accel_gated: int = 0
    stale_attitude: int = 0
    stale_pwm: int = 0
    stale_tension: int = 0
    on_ground: int = 0
    near_anchor: int = 0
    range_fused: int = 0
    range_gated: int = 0
    range_out_of_range: int = 0
    range_stale: int = 0
    load_cell_fused: int = 0
    winch_fused: int = 0
    cable_angle_fused: int = 0
    rest_fused: int = 0
    rest_settled: int = 0
    nonfinite_rejected: int = 0
    pwm_invalid: int = 0
    out_of_order: int = 0
    initialisations: int = 0
    resets: int = 0
    pd_repairs: int = 0
    last_accel_nis: float = math.nan
    last_range_nis: float = math.nan

    def values(self) -> tuple:
        """All fields in declaration order (a cheap snapshot)."""
        return _HEALTH_VALUES(self)


_HEALTH_VALUES = operator.attrgetter(*(f.name for f in dataclasses.fields(DynamicHealth)))
