"""Health of the published position: the states, their words, and how an estimate gets one.

Pure functions of one estimate and the ``publish`` thresholds; the :class:`Publisher` adds what
depends on history (settling, stale inputs, idle motors) and announces changes in STATUSTEXT.

The paper's filters are judged by their covariance and estimated tension
(:func:`assess_health`); the dynamic filter says itself whether its position is observable
(its ``status`` and ``reason``), which :func:`dynamic_health` maps onto these states:

==============  ==================================================================
filter status   health
==============  ==================================================================
ok              ``ok`` (still subject to the variance bound of :func:`assess_health`)
initialising    ``converging``
learning        ``learning``, or ``short_cable`` closer than ``short_cable_m``
weak_pull       ``weak_pull``, or ``short_cable`` closer than ``short_cable_m``
slack           ``slack``, or ``short_cable`` closer than ``short_cable_m``
on_ground       ``motors_idle`` (motors idle, or the filter's height below touchdown_height_m)
stale_inputs    judged as usual: the stale input is named by the session
reset           ``diverged`` (reset_counter goes up with the filter's restart)
==============  ==================================================================

and an accelerometer update skipped because the drone is within
``estimator.min_cable_length_m`` of the anchor is ``short_cable`` too.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import output as dynamic_output
from tether_companion.estimation.dynamic.output import Approximation
from tether_companion.estimation.estimate import EstimatorHealth
from tether_companion.estimation.observability import RANGEFINDER
from tether_companion.service.publish_config import PublishConfig

FloatArray = NDArray[np.float64]

OK = "ok"
CONVERGING = "converging"
DIVERGED = "diverged"
SLACK = "slack"
STALE = "stale"
NO_ATTITUDE = "no_attitude"
MOTORS_IDLE = "motors_idle"
NO_RANGE = "no_range"
NO_IMU = "no_imu"
STALE_ATTITUDE = "stale_attitude"
STALE_PWM = "stale_pwm"
STALE_TENSION = "stale_tension"
WEAK_PULL = "weak_pull"
SHORT_CABLE = "short_cable"
LEARNING = "learning"
HEALTH_STATES = (
    OK,
    CONVERGING,
    LEARNING,
    DIVERGED,
    SLACK,
    STALE,
    NO_ATTITUDE,
    MOTORS_IDLE,
    NO_RANGE,
    NO_IMU,
    STALE_ATTITUDE,
    STALE_PWM,
    STALE_TENSION,
    WEAK_PULL,
    SHORT_CABLE,
)
"""Health of the published position, worst cases last in the status text."""

_HEALTH_TEXT = {
    OK: "position OK",
    CONVERGING: "converging, position withheld",
    LEARNING: "learning thrust & wind, position withheld",
    DIVERGED: "estimate diverged",
    SLACK: "tether slack, position unobservable",
    STALE: "inputs stale, no estimate",
    NO_ATTITUDE: "no attitude from FC",
    MOTORS_IDLE: "on ground or touching down, no position",
    NO_RANGE: "no rangefinder height, position unknown",
    NO_IMU: "no IMU data, no estimate",
    STALE_ATTITUDE: "attitude stale, position withheld",
    STALE_PWM: "motor outputs stale, position withheld",
    STALE_TENSION: "tension reading stale, position withheld",
    WEAK_PULL: "pull too weak, position unobservable",
    SHORT_CABLE: "cable short/slack near anchor, no position",
}


def health_text(health: str) -> str:
    """What a health state means, in words (the STATUSTEXT after ``TETHER: ``)."""
    return _HEALTH_TEXT[health]


class PositionEstimate(Protocol):
    """What the publisher reads from an estimate (the EKF's
    :class:`~tether_companion.estimation.estimate.Estimate` or a catenary one)."""

    @property
    def time_s(self) -> float:
        """Flight-controller time [s]."""

    @property
    def position_ned_m(self) -> FloatArray:
        """Position from the anchor, NED, shape (3,) [m]."""

    @property
    def tension_n(self) -> float:
        """Tension magnitude [N]."""

    @property
    def covariance(self) -> FloatArray:
        """Covariance, shape (n, n): position block [m^2] first, then tension [N^2] if n > 3."""

    @property
    def position_covariance_m2(self) -> FloatArray:
        """Position block of the covariance, shape (3, 3) [m^2]."""

    @property
    def reset_counter(self) -> int:
        """Restarts of the estimator run so far."""


def assess_health(
    estimate: PositionEstimate, config: PublishConfig, has_tension_state: bool, ever_ok: bool
) -> str:
    """Health of one estimate (one of :data:`HEALTH_STATES`, never STALE/NO_ATTITUDE here).

    Parameters
    ----------
    estimate
        The estimator's output.
    config
        Publication thresholds (variance bound, slack tension).
    has_tension_state
        True for the 4-state model (a near-zero estimated tension then means a slack tether).
    ever_ok
        Whether this estimator run was healthy before: a too-large variance before the first
        healthy estimate is ``converging``, after it ``diverged``.

    An estimate that offers its values approximately (the dynamic filter's ``approximate()``:
    Python floats within a bound of their rounding, cheaper than its exact arrays) is judged
    on them where every test is clear by more than that bound; otherwise, and for the other
    estimates, on the exact values.
    """
    verdict = None
    approximate = getattr(estimate, "approximate", None)
    if approximate is not None:
        approx = approximate()
        if approx is not None:
            verdict = _approximate_verdict(approx, config, has_tension_state)
    if verdict is None:
        verdict = _exact_verdict(estimate, config, has_tension_state)
    if verdict == _VARIANCE:
        if getattr(estimate, "missing_input", None) == RANGEFINDER:
            return NO_RANGE  # the variance grew because the height is not measured
        return DIVERGED if ever_ok else CONVERGING
    return verdict


_VARIANCE = "variance"
"""Verdict: a position variance not positive or beyond ``max_position_variance_m2``."""
_APPROXIMATE_MARGIN = 1e-9
"""Relative margin of an approximate value to a threshold (as the dynamic filter's own)."""


def _exact_verdict(estimate: PositionEstimate, config: PublishConfig, has_tension: bool) -> str:
    """DIVERGED (not finite), :data:`_VARIANCE`, SLACK or OK from the exact values."""
    # in scalars: this runs at every IMU tick, and numpy's per-call overhead on 3- and
    # 16-element arrays was most of the publisher's cost
    isfinite = math.isfinite
    if not (
        all(map(isfinite, estimate.position_ned_m.tolist()))
        and all(map(isfinite, estimate.covariance.ravel().tolist()))
        and isfinite(estimate.tension_n)
    ):
        return DIVERGED
    variances = estimate.position_covariance_m2.diagonal().tolist()
    if min(variances) <= 0.0 or max(variances) >= config.max_position_variance_m2:
        return _VARIANCE
    if has_tension and estimate.tension_n < config.slack_tension_n:
        return SLACK
    return OK


def _approximate_verdict(
    approx: Approximation, config: PublishConfig, has_tension: bool
) -> str | None:
    """:func:`_exact_verdict` from an approximation (its values within ``covariance_tol``,
    its finiteness known or not), None when a test is not clear."""
    if not approx.finite:
        return None
    north, _, east = approx.horizontal
    variances = (north, east, approx.down_variance)
    smallest, largest = min(variances), max(variances)
    tol = approx.covariance_tol
    bound = config.max_position_variance_m2
    if not (smallest > tol and abs(largest - bound) > tol + _APPROXIMATE_MARGIN * bound):
        return None
    if largest >= bound:
        return _VARIANCE
    if has_tension:
        tension, slack = approx.tension_n, config.slack_tension_n
        if not abs(tension - slack) > _APPROXIMATE_MARGIN * (abs(tension) + abs(slack)):
            return None
        if tension < slack:
            return SLACK
    return OK


def dynamic_health(
    estimate: dynamic_output.NavigationEstimate, short_cable_m: float, near_anchor: bool
) -> str | None:
    """The health a dynamic-filter estimate forces (None: judge it by :func:`assess_health`).

    Parameters
    ----------
    estimate
        A :class:`~tether_companion.estimation.dynamic.output.NavigationEstimate`.
    short_cable_m
        Below this distance from the anchor [m] a weak pull or slack cable is ``short_cable``.
    near_anchor
        This tick's accelerometer update was skipped for the drone being at the anchor.
    """
    status = estimate.status
    if status == dynamic_output.OK or status == dynamic_output.STALE_INPUTS:
        return SHORT_CABLE if near_anchor else None
    if status in _DYNAMIC_WITHHELD:
        if near_anchor or _closer_than(estimate, short_cable_m):
            return SHORT_CABLE
        return _DYNAMIC_WITHHELD[status]
    return _DYNAMIC_STATUS_HEALTH.get(status, DIVERGED)  # a status added later: withheld


_DYNAMIC_WITHHELD = {
    dynamic_output.LEARNING: LEARNING,
    dynamic_output.WEAK_PULL: WEAK_PULL,
    dynamic_output.SLACK: SLACK,
}
"""Filter statuses that withhold a position far from the anchor, and their health."""
_DYNAMIC_STATUS_HEALTH = {
    dynamic_output.INITIALISING: CONVERGING,
    dynamic_output.ON_GROUND: MOTORS_IDLE,
    dynamic_output.RESET: DIVERGED,
}


def _closer_than(estimate: dynamic_output.NavigationEstimate, distance_m: float) -> bool:
    """Whether the estimate's position is closer than ``distance_m`` [m] to the anchor: from
    its approximate position where that is clear, else from the exact one."""
    approx = estimate.approximate()
    if approx is not None:
        n, e, d = approx.position
        distance = math.sqrt(n * n + e * e + d * d)
        tol = 2.0 * approx.position_tol + _APPROXIMATE_MARGIN * (distance + distance_m)
        if abs(distance - distance_m) > tol:
            return distance < distance_m
    return float(np.linalg.norm(estimate.position_ned_m)) < distance_m


_STALE_HEALTH = (STALE_ATTITUDE, STALE_PWM, STALE_TENSION)


def stale_counts(health: EstimatorHealth) -> tuple[int, int, int]:
    """The estimator's stale-input counters (attitude, PWM, known tension)."""
    return health.stale_attitude, health.stale_pwm, health.stale_tension


def stale_input_health(before: tuple[int, int, int], after: tuple[int, int, int]) -> str | bool:
    """The publisher health naming the input that kept this tick from fusing (False: none)."""
    if after == before:  # the usual tick: one comparison of the tuples
        return False
    for name, old, new in zip(_STALE_HEALTH, before, after, strict=True):
        if new > old:
            return name
    return False
