"""Optional ground-station cable angle: elevation (up from horizontal) and azimuth (from
north) of the cable where it leaves the anchor [rad] as the sensor reads them, each with its
zero error (states ``elevation_zero``, ``azimuth_zero``; generated ``cable_angle_*``: the
catenary's tangent there, flat where the cable rests on the ground). The azimuth innovation is
wrapped to [-pi, pi). The sensor's noise is a direction noise ``sigma`` per axis [rad]: the
elevation's is ``sigma``, the azimuth's ``sigma / cos(elevation)`` (a direction error across
a steep cable turns its azimuth by more).

Skipped as slack only when the filter is sure the cable is slack (:func:`.slack.surely_slack`):
a tension estimate that merely dips below ``slack_tension_n`` must not lock out the angle
that would correct it.

At a low tension the generated tangent is not evaluated as it stands: its horizontal part is
``T_ch p_ne/|p|``, so a member whose chord tension went negative predicts a cable leaving
the anchor away from the drone (elevation ``-el``, azimuth ``+ pi``); those innovations were
gated and then, after ``max_consecutive_rejections``, fused regardless, and a linearised
update of a half-turn innovation threw the position away (slack-gate-wip's angle-alone
runaway). A slack cable does not point back at the anchor: below :data:`MIN_MODEL_TENSION_N`
the model is evaluated at that tension, its Jacobian's tension column 0 (for a weightless cable
the angles do not depend on the tension at all). Not at the slack threshold: a heavy cable's
model there can be a different curve from the state's. A resting cable leaves the anchor flat
wherever the drone is, and its elevation is a hinge at the touchdown kink, where the free
curve's rises ~1 rad per metre of position; a state at 0.15 N resting on the ground, evaluated
at 0.2 N, was put on the free side (0.28 rad against a flat reading) and one update cut its
horizontal standard deviation 0.46 -> 0.03 m with the drone 1.6 m off (the fixed-length
sagging circle, tuning seed 1, 5.7 s, with the load cell's negative readings taken;
docs/estimation-history.md, sag14).

A bearing that far off is beyond the linearisation anyway: when a sample is going to be fused
regardless of the gate (the member's angle was gated ``max_consecutive_rejections`` times in a
row) and its azimuth innovation exceeds :data:`TURN_LIMIT_RAD`, the member's horizontal state
(position, velocity, wind) is first turned about the anchor's vertical by that innovation
(:func:`turn_about_anchor`), the exact correction of a bearing, instead of a linearised
update that moves the drone along the tangent off the circle; counted in
:attr:`CableAngleAid.turns`.

A reading was taken ``latency_s`` before its time stamp (and the stamp may be older than the
filter's time): fused at the drone's position then
(:func:`~tether_companion.estimation.dynamic.aiding.at_reading_time`; 0.05 s at the
take-off's 1.8 m/s descent is 0.09 m, against 0.01 m of noise at the anchor's 1 m).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aid.slack import SLACK, surely_slack
from tether_companion.estimation.dynamic.aiding import AidStatus, at_reading_time, fuse
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.models import UNDEFINED, ModelConstants
from tether_companion.frames import wrap_pi

FloatArray = NDArray[np.float64]

NAME = "cable_angle"

MIN_MODEL_TENSION_N = 1e-3
"""The lowest chord tension [N] the model is evaluated at (module docstring)."""

TURN_LIMIT_RAD = 0.2
"""An azimuth innovation [rad] beyond which a sample fused regardless of the gate turns the
member about the anchor instead (the linearised ``a dpsi`` is then ``tan`` 1.4 % off)."""

_HORIZONTAL_PAIRS = (
    (state.POSITION.start, state.POSITION.start + 1),
    (state.VELOCITY.start, state.VELOCITY.start + 1),
    (state.WIND.start, state.WIND.start + 1),
)
"""The (north, east) index pairs of the states that turn with the bearing."""


def turn_about_anchor(member: MemberFilter, angle_rad: float) -> None:
    """Turn ``member``'s position, velocity and wind about the anchor's vertical by
    ``angle_rad`` [rad] (north toward east), and its covariance with them."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    turn = np.eye(state.N_STATES)
    for north, east in _HORIZONTAL_PAIRS:
        turn[north, north], turn[north, east] = c, -s
        turn[east, north], turn[east, east] = s, c
    member.x = turn @ member.x
    member.P = turn @ member.P @ turn.T


UNIFORM_BEARING_VARIANCE_RAD2 = math.pi**2 / 3.0
"""The variance [rad^2] of a bearing that could be anywhere on the circle."""


def bearing_curvature_variance(x: FloatArray, p: FloatArray) -> float:
    """The variance [rad^2] the azimuth linearised at the state ``x`` leaves out over the
    horizontal position's spread (covariance ``p``): a Gaussian filter's second-order term
    ``0.5 tr(H P H P)`` with ``H`` the bearing ``atan2(e, n)``'s Hessian in (n, e), of size
    ``1/a^2`` at the span ``a``; at most a bearing uniform on the circle's ``pi^2/3`` (its
    value right above the anchor).

    It is ``(sd / a)^4`` for a round spread ``sd``: nothing where the bearing is sure (1e-7
    rad^2 at 0.1 m and 5 m, against the sensor's 1e-4) and the bearing's whole spread where
    the drone may be on either side of the anchor. Without it a member a slack cable had
    brought to 0.43 m from the anchor with 0.33 m of spread took the measured bearing through
    a Jacobian of ``1/a``: its deviation fell 0.33 -> 0.11 m within 0.1 s (one angle and one
    load-cell reading), 2.5 m off (the fixed-length sagging circle, tuning seed 6, 5.7-5.8 s,
    with the load cell's readings below zero taken; sag14 saw the same on seed 1). Added only
    once a load cell's tension has been fused (:class:`CableAngleAid`)."""
    n, e = float(x[0]), float(x[1])
    span2 = n * n + e * e
    if span2 <= 0.0:
        return UNIFORM_BEARING_VARIANCE_RAD2
    cross, diagonal = e * e - n * n, 2.0 * n * e
    hessian = np.array(((diagonal, cross), (cross, -diagonal))) / (span2 * span2)
    hp = hessian @ np.asarray(p)[0:2, 0:2]
    return min(0.5 * float(np.trace(hp @ hp)), UNIFORM_BEARING_VARIANCE_RAD2)


class CableAngleAid:
    """Fuses (elevation, azimuth) [rad], each taken ``latency_s`` [s] before its stamp, unless
    the chord tension is surely below ``slack_tension_n`` [N].

    Once a load cell's tension has been fused (``constants.tension_measured``) the azimuth's
    variance also holds :func:`bearing_curvature_variance`. Not without one: the term is
    ``sd_radial^2 sd_across^2 / a^4``, which an angle-only filter's metres of radial spread
    make large, and it took that filter's fixed-length sagging circle, tuning seed 2, from
    NEES 0.71 to 19.3 (sag14's candidate), so the filters without a load cell keep the plain
    linearisation (docs/estimation-history.md, sag15).

    Attributes
    ----------
    status
        What the sensor did (:class:`AidStatus`).
    turns
        Members turned about the anchor instead of a linearised update (module docstring).
    """

    MIN_COS_ELEVATION = 0.05
    """The azimuth's noise is at most ``sigma / MIN_COS_ELEVATION`` (a cable within 3 degrees
    of the vertical)."""

    def __init__(self, slack_tension_n: float, latency_s: float = 0.0) -> None:
        self.status = AidStatus()
        self.turns = 0
        self._latency_s = latency_s
        self._slack_n = slack_tension_n

    def fuse(
        self,
        bank: FilterBank,
        constants: ModelConstants,
        elevation_rad: float,
        azimuth_rad: float,
        time_s: float,
        noise_std_rad: float,
        age_s: float = 0.0,
    ) -> bool:
        """Fuse one reading [rad] of direction noise ``noise_std_rad`` [rad] at filter time
        ``time_s`` [s], stamped ``age_s`` [s] before it (so taken ``latency_s + age_s``
        before)."""
        if surely_slack(bank.best, self._slack_n):
            self.status.skip(SLACK)
            return False
        for member in bank.filters:
            self._turn_if_far(member, azimuth_rad)

        def measure(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
            h, jac = self.evaluate(constants, xs)
            # predicted azimuth moved by whole turns next to the measured one
            h[1] = azimuth_rad - wrap_pi(azimuth_rad - h[1])
            return h, jac

        z = np.array((elevation_rad, azimuth_rad))
        r = np.diag([sd**2 for sd in self.noise_std_rad(elevation_rad, noise_std_rad)])
        if constants.tension_measured:  # the load cell's filter only (class docstring)
            r[1, 1] += bearing_curvature_variance(bank.best.x, bank.best.P)
        delayed = at_reading_time(measure, self._latency_s + age_s)
        return fuse(bank, NAME, self.status, z, delayed, r, time_s)

    @classmethod
    def noise_std_rad(cls, elevation_rad: float, noise_std_rad: float) -> tuple[float, float]:
        """The (elevation, azimuth) noise standard deviations [rad] of a reading of direction
        noise ``noise_std_rad`` [rad]: ``sigma`` and ``sigma / cos(elevation)`` (module
        docstring), the latter at most ``sigma / MIN_COS_ELEVATION``."""
        cos_elevation = max(math.cos(elevation_rad), cls.MIN_COS_ELEVATION)
        return noise_std_rad, noise_std_rad / cos_elevation

    def evaluate(self, constants: ModelConstants, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The angles (elevation, azimuth) [rad] (2,) and their Jacobian (2, n) as fused at the
        state ``x``: the chord tension floored (module docstring), ``nan`` where the model is
        undefined."""
        low = x[state.TENSION] < MIN_MODEL_TENSION_N
        if low:
            x = x.copy()
            x[state.TENSION] = MIN_MODEL_TENSION_N
        try:
            values, jac_flat = constants.models.cable_angle(x.tolist(), (), constants.values())
        except UNDEFINED:
            return np.full(2, math.nan), np.full((2, state.N_STATES), math.nan)
        jac = np.array(jac_flat).reshape(2, state.N_STATES)
        if low:
            jac[:, state.TENSION] = 0.0
        return np.array(values), jac

    def _turn_if_far(self, member: MemberFilter, azimuth_rad: float) -> None:
        """Turn ``member`` to the measured azimuth [rad] when its next angle is fused
        regardless of the gate and its bearing is more than :data:`TURN_LIMIT_RAD` off."""
        sensor = member.sensors.get(NAME)
        limit = member.max_consecutive_rejections
        if sensor is None or not 0 < limit <= sensor.consecutive_rejections:
            return
        x = member.x
        off = wrap_pi(azimuth_rad - x[state.AZIMUTH_ZERO] - math.atan2(x[1], x[0]))
        if abs(off) > TURN_LIMIT_RAD:
            turn_about_anchor(member, off)
            self.turns += 1
