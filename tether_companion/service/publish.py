"""When the service sends an estimate to the flight controller, and with which health.

Pure and synchronous: :class:`Publisher` turns the estimator's :class:`Estimate` (at IMU rate)
plus the flight controller's own attitude into the messages to send
(:class:`~tether_companion.service.estimate_messages.EstimateMessages` builds them),
decimated to ``publish.rate_hz`` in the flight controller's time base, so the live service and
replay send exactly the same thing for the same input.

Choices, with the reasons:

* Never NaN: an estimate with a non-finite position is never sent. When the estimate is not
  healthy (diverged, slack tether, weak pull, short cable) the publisher stops or, with
  ``on_unhealthy: inflate``, sends the last healthy position (the current one before any was
  healthy) with ``inflated_variance_m2``: a drifting unobservable position is not passed on.
  Stale inputs produce no estimate at all, so nothing is sent.
* An estimator run must stay healthy ``settle_s`` before its first position is sent.
* ``reset_counter`` (uint8, wraps) goes up on every estimator restart, on a jump larger than
  ``jump_m`` between two publications, on resuming after a pause and after a flight-controller
  reboot, so the autopilot resets its position state instead of fighting a step.
* The position may come from the tether EKF (the paper's or the dynamic filter) or from the
  catenary estimator (``position.source``): anything with the :class:`PositionEstimate`
  attributes.
* The tension filter's NAMED_VALUE_FLOATs go at ``filtered_rate_hz`` (FC time); nothing is
  sent for an invalid or stale (``filtered_max_age_s``) value. A health change is announced by
  STATUSTEXT at most once per :data:`STATUSTEXT_MIN_INTERVAL_S`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from tether_companion.estimation.catenary_position import CatenaryPosition
from tether_companion.estimation.tension_kf import TensionEstimate
from tether_companion.mavlink.framing import MAVLinkMessage
from tether_companion.samples import AttitudeSample
from tether_companion.service.estimate_messages import EstimateMessages
from tether_companion.service.health import (
    CONVERGING,
    DIVERGED,
    HEALTH_STATES,
    MOTORS_IDLE,
    NO_ATTITUDE,
    OK,
    STALE,
    PositionEstimate,
    assess_health,
)
from tether_companion.service.publish_config import PublishConfig

STATUSTEXT_MIN_INTERVAL_S = 1.0
"""Shortest gap between two health STATUSTEXTs [s of flight-controller time]."""
_RESUME_GAP_S = 0.5
"""A pause in publication longer than this counts as a reset when publication resumes [s]."""


@dataclass(frozen=True, slots=True)
class Publication:
    """One published estimate, as written to the estimates CSV (units in the names)."""

    time_usec: int
    position_ned_m: tuple[float, float, float]
    tension_n: float
    position_variance_m2: tuple[float, float, float]
    tension_variance_n2: float
    health: str
    reset_counter: int

    CSV_HEADER = (
        "time_usec,north_m,east_m,down_m,tension_n,var_north_m2,var_east_m2,var_down_m2,"
        "var_tension_n2,health,reset_counter"
    )

    def csv_row(self) -> str:
        """One CSV line (no newline), ``repr``-exact floats."""
        values = (
            str(self.time_usec),
            *(repr(v) for v in self.position_ned_m),
            repr(self.tension_n),
            *(repr(v) for v in self.position_variance_m2),
            repr(self.tension_variance_n2),
            self.health,
            str(self.reset_counter),
        )
        return ",".join(values)


@dataclass
class PublisherCounters:
    """What the publisher did (monotonic counts; visible in --status)."""

    estimates: int = 0
    published: int = 0
    withheld: int = 0
    inflated: int = 0
    resets: int = 0
    health_changes: int = 0
    by_health: dict[str, int] = field(default_factory=lambda: dict.fromkeys(HEALTH_STATES, 0))


class Publisher:
    """Decimate estimates to ``rate_hz`` and build the messages to send.

    Parameters
    ----------
    config
        The ``publish`` section.
    has_tension_state
        True for the 4-state estimator (slack detection on the estimated tension).
    messages
        False when nobody reads the messages (replay): none are built, the publication records,
        counters, health and reset counter are the same.
    """

    def __init__(
        self, config: PublishConfig, has_tension_state: bool, *, messages: bool = True
    ) -> None:
        self.config = config
        self.has_tension_state = has_tension_state
        self.messages = messages
        self.counters = PublisherCounters()
        self._build = EstimateMessages(config)
        """Builds the messages."""
        self.reset_counter = 0
        self.health = CONVERGING
        self._announced: str | None = None
        self._next_text_s = -math.inf
        self.last: Publication | None = None
        self._period_s = 1.0 / config.rate_hz
        self._tension_period_s = (
            1.0 / config.tension_rate_hz if config.tension_rate_hz > 0 else math.inf
        )
        self._filtered_period_s = (
            1.0 / config.filtered_rate_hz if config.filtered_rate_hz > 0 else math.inf
        )
        self._next_due_s = -math.inf
        self._next_tension_s = -math.inf
        self._next_filtered_s = -math.inf
        self._last_sent_s = -math.inf
        self._last_sent_position: tuple[float, float, float] | None = None
        self._last_ok_position: tuple[float, float, float] | None = None
        """The last position published healthy: what ``on_unhealthy: inflate`` sends."""
        self._estimator_resets: int | None = None
        self._ever_ok = False
        self._ok_since_s = math.inf

    def restart(self) -> None:
        """A new estimator run (flight-controller reboot): raise reset_counter, reset timing."""
        self._bump_reset()
        self._next_due_s = -math.inf
        self._next_tension_s = -math.inf
        self._next_filtered_s = -math.inf
        self._last_sent_s = -math.inf
        self._last_sent_position = None
        self._last_ok_position = None
        self._estimator_resets = None
        self._ever_ok = False
        self._ok_since_s = math.inf

    def set_health(self, health: str) -> list[MAVLinkMessage]:
        """Record a health state decided outside the estimate (stale inputs); STATUSTEXT if new."""
        return self._health_transition(health)

    def on_filtered(
        self, tension: TensionEstimate, catenary: CatenaryPosition | None = None
    ) -> list[MAVLinkMessage]:
        """NAMED_VALUE_FLOATs of the tension filter (and catenary position), when due.

        Parameters
        ----------
        tension
            The tension filter's estimate at one IMU tick (FC time ``time_s``).
        catenary
            The catenary estimator's position at the same tick (None: not running).

        Nothing is sent for a value that is not finite, a tension not updated within
        ``filtered_max_age_s`` or an invalid catenary position.
        """
        t = tension.time_s
        if (
            not self.messages
            or self._filtered_period_s == math.inf
            or not t >= self._next_filtered_s
        ):
            return []
        fresh = tension.valid and tension.age_s(t) <= self.config.filtered_max_age_s
        position_ok = catenary is not None and catenary.valid
        if not (fresh or position_ok):
            return []
        self._next_filtered_s = _next_due(self._next_filtered_s, t, self._filtered_period_s)
        return self._build.filtered(
            t, tension if fresh else None, catenary if position_ok else None
        )

    def on_estimate(
        self,
        estimate: PositionEstimate,
        attitude: AttitudeSample | None,
        *,
        inputs_stale: bool | str = False,
        motors_idle: bool = False,
        unavailable: str | None = None,
        send_now: Callable[[list[MAVLinkMessage]], None] | None = None,
    ) -> tuple[list[MAVLinkMessage], Publication | None]:
        """Messages to send for this estimate (often none: decimation) and the CSV record.

        Parameters
        ----------
        estimate
            The estimator output at one IMU tick (flight-controller time ``time_s``).
        attitude
            The flight controller's latest ATTITUDE (roll/pitch/yaw to echo back).
        inputs_stale
            The tick could not fuse the accelerometer because the attitude, PWM or known
            tension was missing or too old: the estimate is a prediction only. A health name
            (``stale_attitude``, ``stale_pwm``, ``stale_tension``) says which input; True
            says ``stale``.
        motors_idle
            The motors' thrust is far below the weight: the vehicle stands on something (the
            ground after landing or a reboot) and the model (thrust + cable only) does not hold.
        unavailable
            Why the estimator has no position this tick, when it says so (``stale`` or
            ``slack``; the catenary estimator): the health shown instead of ``diverged``.
        send_now
            Given, a published estimate's messages are handed to it before the CSV record is
            built (and not returned): the flight controller does not wait for the record.
        """
        self.counters.estimates += 1
        out: list[MAVLinkMessage] = []
        t = estimate.time_s
        if self._estimator_resets is not None and estimate.reset_counter != self._estimator_resets:
            self._bump_reset()
            self._ever_ok = False
            self._ok_since_s = math.inf
        self._estimator_resets = estimate.reset_counter
        if unavailable is not None:  # the estimator's own verdict: its values are not read
            health = unavailable
        else:
            health = assess_health(estimate, self.config, self.has_tension_state, self._ever_ok)
        if inputs_stale and health in (OK, CONVERGING):
            health = inputs_stale if isinstance(inputs_stale, str) else STALE
        if motors_idle and health != DIVERGED:
            health = MOTORS_IDLE
        if attitude is None and health == OK:
            health = NO_ATTITUDE
        if health == OK and not self._ever_ok:  # settle: OK for settle_s before the first send
            self._ok_since_s = min(self._ok_since_s, t)
            if t - self._ok_since_s < self.config.settle_s:
                health = CONVERGING
            else:
                self._ever_ok = True
        elif not self._ever_ok:
            self._ok_since_s = math.inf
        if health != self.health or health != self._announced:  # else it returns [] unchanged
            out += self._health_transition(health, t)
        self.counters.by_health[health] += 1
        if (
            self.messages
            and t >= self._next_tension_s
            and math.isfinite(estimate.tension_n)
            and self._tension_period_s < math.inf
        ):
            self._next_tension_s = _next_due(self._next_tension_s, t, self._tension_period_s)
            out.append(self._build.tension(t, estimate.tension_n))
        if t < self._next_due_s:
            return out, None
        self._next_due_s = _next_due(self._next_due_s, t, self._period_s)
        if attitude is None or (health != OK and self.config.on_unhealthy != "inflate"):
            self.counters.withheld += 1  # withheld whatever the position: not read
            return out, None
        # the position as Python floats: a published tick is on the way to the flight
        # controller, and numpy's per-call overhead on 3-vectors was most of this part's cost
        if health != OK and self._last_ok_position is not None:
            position = self._last_ok_position  # inflate holds the last healthy position
        else:
            position = tuple(estimate.position_ned_m.tolist())
        finite = all(map(math.isfinite, position))
        send_inflated = health != OK and self.config.on_unhealthy == "inflate" and finite
        if attitude is None or not finite or (health != OK and not send_inflated):
            self.counters.withheld += 1
            return out, None
        last = self._last_sent_position
        if t - self._last_sent_s > _RESUME_GAP_S and last is not None:
            self._bump_reset()
        elif last is not None and _farther_than(position, last, self.config.jump_m):
            self._bump_reset()
        self._last_sent_s = t
        self._last_sent_position = position
        if health == OK:
            self._last_ok_position = position
        if self.messages:
            out += self._build.position(
                estimate, position, attitude, send_inflated, self.reset_counter
            )
            if send_now is not None:
                send_now(out)
                out = []
        self.counters.published += 1
        self.counters.inflated += int(send_inflated)
        variances = estimate.covariance.diagonal().tolist()
        if send_inflated:
            variances[:3] = (float(self.config.inflated_variance_m2),) * 3
        # positional (a class called with keywords builds a dict: ~2k instructions a call)
        publication = Publication(
            int(round(t * 1e6)),  # time_usec
            position,  # position_ned_m
            float(estimate.tension_n),  # tension_n
            (variances[0], variances[1], variances[2]),  # position_variance_m2
            variances[3] if len(variances) > 3 else 0.0,  # tension_variance_n2
            health,  # health
            self.reset_counter,  # reset_counter
        )
        self.last = publication
        return out, publication

    def _bump_reset(self) -> None:
        self.reset_counter = (self.reset_counter + 1) & 0xFF
        self.counters.resets += 1

    def _health_transition(self, health: str, time_s: float | None = None) -> list[MAVLinkMessage]:
        """Record the health; a STATUSTEXT when the announced one changes, at most one per
        ``STATUSTEXT_MIN_INTERVAL_S`` of FC time (``time_s`` None: at once) so a flapping
        health cannot flood the ground station; the latest state is announced when allowed."""
        if health != self.health:
            self.health = health
            self.counters.health_changes += 1
        if not (self.messages and self.config.statustext) or health == self._announced:
            return []
        if time_s is not None and time_s < self._next_text_s:
            return []
        self._announced = health
        self._next_text_s = -math.inf if time_s is None else time_s + STATUSTEXT_MIN_INTERVAL_S
        return [self._build.statustext(health)]


def _farther_than(
    a: tuple[float, float, float], b: tuple[float, float, float], distance_m: float
) -> bool:
    """Whether ``a`` and ``b`` (NED [m]) are more than ``distance_m`` [m] apart, as
    ``numpy.linalg.norm(a - b)`` says: from the distance in floats where it is clear of the
    bound by more than its rounding, else from numpy's."""
    d0, d1, d2 = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    distance = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if abs(distance - distance_m) > 1e-9 * (distance + abs(distance_m)):
        return distance > distance_m
    return float(np.linalg.norm(np.array(a) - np.array(b))) > distance_m


def _next_due(previous_due_s: float, now_s: float, period_s: float) -> float:
    """Next deadline keeping the phase (average rate exact); restart the phase after a gap."""
    due = previous_due_s + period_s
    return due if now_s - previous_due_s < period_s else now_s + period_s - 1e-9
