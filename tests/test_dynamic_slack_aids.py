"""The winch length and the cable angle when the filter's tension dips below
``slack_tension_n``: a low but unsure tension (or a negative one, or one sure of a pushing
cable) must not lock out the angle that would correct it, a drone the filter has beyond the
paid-out line is pulled in whatever the tension, a surely slack cable skips both, and a bearing
far off is turned, not linearised (aid/slack.py, aid/winch.py, aid/cable_angle.py; the lock-out
was found on ArduPilot SITL, docs/estimation-history.md "The aids' slack lock-out")."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aid.cable_angle import turn_about_anchor
from tether_companion.estimation.dynamic.aid.slack import SLACK
from tether_companion.estimation.dynamic.aid.winch import _chord
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.frames import wrap_pi
from tether_companion.sim.scenario import load_scenario

SURELY_SLACK = (0.05, 0.02)
"""A chord tension [N] and its standard deviation [N] surely in the slack range [0, 0.2 N)."""


def _started() -> tuple[DynamicTetherEstimator, np.ndarray, float]:
    """An estimator after 3 s of the paper circle (straight cable), its best member's position
    [m] (the reference the tests' readings are made from) and the time [s]; the ground
    station's readings are taken when stamped (latency 0: the tests' readings are of the
    position at their stamp)."""
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=3.0, seed=2)
    dynamic = dataclasses.replace(
        DynamicFilterConfig(), winch_latency_s=0.0, cable_angle_latency_s=0.0
    )
    run = run_dynamic(scenario, EstimatorConfig(), dynamic)
    assert run.estimator.initialised
    est = run.estimator
    return est, est.bank.best.x[state.POSITION].copy(), float(run.time_s[-1])


def _believe(est: DynamicTetherEstimator, tension_n: float, sd_n: float, shift_m) -> None:
    """Every member believes a chord tension ``tension_n`` +- ``sd_n`` [N] (uncorrelated with
    the rest) and its position moved by ``shift_m`` [m], with the shift's square added to its
    horizontal variances (a filter that drifted and knows it)."""
    shift = np.asarray(shift_m, dtype=float)
    for member in est.bank.filters:
        x, p = member.x.copy(), member.P.copy()
        x[state.TENSION] = tension_n
        x[state.POSITION] += shift
        p[state.TENSION, :] = 0.0
        p[:, state.TENSION] = 0.0
        p[state.TENSION, state.TENSION] = sd_n**2
        for axis in (0, 1):
            p[axis, axis] += float(shift @ shift)
        member.x, member.P = x, p


def _angles(p: np.ndarray) -> tuple[float, float]:
    """Elevation and azimuth [rad] of the straight cable from the anchor to ``p`` (NED)."""
    return math.atan2(-p[2], math.hypot(p[0], p[1])), math.atan2(p[1], p[0])


def _across(p: np.ndarray, distance_m: float) -> np.ndarray:
    """A horizontal shift [m] across the cable."""
    return distance_m * np.array((-p[1], p[0], 0.0)) / math.hypot(p[0], p[1])


def _pulled_back(tension_n: float, sd_n: float) -> None:
    """Believing ``tension_n`` +- ``sd_n`` [N] with the drone put 1.5 m across the cable, five
    angles to where it was are fused and pull the position back."""
    est, truth, t = _started()
    _believe(est, tension_n, sd_n, _across(truth, 1.5))
    before = np.linalg.norm(est.bank.best.x[state.POSITION][:2] - truth[:2])
    for k in range(1, 6):
        est.on_cable_angle(*_angles(truth), t + 0.001 * k, 0.01)
    after = np.linalg.norm(est.bank.best.x[state.POSITION][:2] - truth[:2])
    assert est.ground_station.cable_angle.status.fused == 5
    assert SLACK not in est.ground_station.cable_angle.status.skipped_by_reason
    assert after < 0.3 * before


def test_an_unsure_low_tension_still_hears_the_cable_angle() -> None:
    """Tension believed 0.1 N (below the 0.2 N threshold) but +- 0.5 N: fused (the former
    point-estimate gate skipped it)."""
    _pulled_back(0.1, 0.5)


def test_a_negative_tension_does_not_turn_the_cable_angle_around() -> None:
    """Tension believed -0.3 +- 0.5 N: the model's tangent ``T_ch p/|p|`` would point from the
    drone back to the anchor (azimuth + pi) and gate every sample; the angle is fused."""
    _pulled_back(-0.3, 0.5)


def test_a_filter_sure_of_a_pushing_cable_still_hears_the_angle() -> None:
    """Tension believed -2 +- 0.3 N: no cable pushes, so this is no slack cable but a filter
    that is wrong; the angle is fused."""
    _pulled_back(-2.0, 0.3)


def test_a_surely_slack_cable_skips_the_angle_and_an_unreachable_length() -> None:
    """Tension surely slack (0.05 +- 0.02 N): the angle is skipped, and so is a paid-out length
    longer than the drone's distance (the slack line only says the drone is nearer)."""
    est, truth, t = _started()
    _believe(est, *SURELY_SLACK, (0.0, 0.0, 0.0))
    est.on_cable_angle(*_angles(truth), t + 0.001, 0.01)
    est.set_paid_out_length_m(float(np.linalg.norm(truth)) + 1.0, t + 0.002)
    assert est.ground_station.cable_angle.status.skipped_by_reason[SLACK] == 1
    assert est.ground_station.winch.status.skipped_by_reason[SLACK] == 1
    assert est.ground_station.cable_angle.status.fused == 0
    assert est.ground_station.winch.status.fused == 0


def test_a_drone_beyond_the_line_is_pulled_within_it_whatever_the_tension() -> None:
    """Tension surely slack, but the filter has the drone 1 m farther out than the paid-out
    line reaches: the length is fused as the bound it is (the line bounds the distance; a
    slack cable's drone may be anywhere inside it), so the distance moves to the prior's
    truncated to the line, within it, and keeps the truncated spread, not the encoder's
    noise: fused as the length itself (the old rule) it sat on the line at a few centimetres
    (aid/winch.py, truncation.py).

    The truncation is a linear update, so it is exact in the distance linearised at the
    prior: the reading (distance + the winch calibration this first reading opens + noise,
    variance ``s``) is truncated at the line, and the distance takes its own share ``v / s``
    of that (the regression of the distance on the reading). The distance at the new mean is
    above its linearisation by the distance's curvature (``|p|`` is convex; the height,
    known from the rangefinder, stays while the range moves ~1.4 m: 0.11 m here) and still
    within the line. This test compared the distance at the new mean with the reading's
    truncated moments to a tenth of the prior's spread, which held only while the start was
    1.1 m wide (the start before startvel23's; 0.55 m since)."""
    est, truth, t = _started()
    _believe(est, *SURELY_SLACK, (0.0, 0.0, 0.0))
    member = est.bank.best
    x0, p0 = member.x.copy(), member.P.copy()
    value, jac = _chord(x0)
    read = float(value[0])
    length = read - 1.0
    est.set_paid_out_length_m(length, t + 0.001)
    assert est.ground_station.winch.status.fused == 1
    x1, p1 = member.x.copy(), member.P.copy()
    # the prior with the calibration as the reading opened it (consider states: the update
    # keeps their own block)
    prior = p0.copy()
    prior[state.CALIBRATION, state.CALIBRATION] = p1[state.CALIBRATION, state.CALIBRATION]
    noise = float(est.ground_station.winch._r[0, 0])
    s = float(jac[0] @ prior @ jac[0]) + noise
    distance = np.zeros(state.N_STATES)
    distance[state.POSITION] = jac[0, state.POSITION]
    v = float(distance @ prior @ distance)
    beta = (length - read) / math.sqrt(s)
    mills = (
        math.exp(-0.5 * beta * beta)
        / math.sqrt(2.0 * math.pi)
        / (0.5 * math.erfc(-beta / math.sqrt(2.0)))
    )
    truncated_mean = read - math.sqrt(s) * mills  # the reading's truncated mean and variance
    truncated_variance = s * (1.0 - mills * (beta + mills))
    expected = read + v / s * (truncated_mean - read)
    expected_sd = math.sqrt(v - (v / s) ** 2 * (s - truncated_variance))
    linearised = read + float(distance @ (x1 - x0))
    linearised_sd = math.sqrt(float(distance @ p1 @ distance))
    assert math.sqrt(s) > 0.5  # a start half a metre wide or more: the line is within 2 sd
    assert abs(linearised - expected) < 0.01 * math.sqrt(s)
    assert abs(linearised_sd - expected_sd) < 0.01 * expected_sd
    assert linearised_sd > 0.3 * math.sqrt(s)  # not the encoder's noise
    after = float(_chord(x1)[0][0])
    assert linearised <= after < length


def test_a_bearing_far_off_is_turned_about_the_anchor() -> None:
    """Every member's drone turned 90 degrees about the anchor: the angles are gated until the
    gate gives way, and then the members are turned back by the measured azimuth, the range
    kept, instead of a linearised update along the tangent."""
    est, truth, t = _started()
    for member in est.bank.filters:
        turn_about_anchor(member, math.pi / 2)
    limit = est.bank.best.max_consecutive_rejections
    for k in range(1, limit + 2):
        est.on_cable_angle(*_angles(truth), t + 0.001 * k, 0.01)
    p = est.bank.best.x[state.POSITION]
    assert est.ground_station.cable_angle.status.gated == limit
    assert est.ground_station.cable_angle.turns == len(est.bank.filters)
    assert abs(wrap_pi(math.atan2(p[1], p[0]) - math.atan2(truth[1], truth[0]))) < 0.02
    assert abs(math.hypot(p[0], p[1]) - math.hypot(truth[0], truth[1])) < 0.1


def test_turning_about_the_anchor_keeps_the_covariance_in_the_turned_frame() -> None:
    """A quarter turn maps north to east in the state and in its covariance (the range and
    the variances along and across the cable are kept)."""
    est, _, _ = _started()
    member = est.bank.best
    x, p = member.x.copy(), member.P.copy()
    turn_about_anchor(member, math.pi / 2)
    np.testing.assert_allclose(member.x[:2], (-x[1], x[0]), atol=1e-12)
    np.testing.assert_allclose(member.x[11:13], (-x[12], x[11]), atol=1e-12)
    np.testing.assert_allclose(member.P[0, 0], p[1, 1], rtol=1e-12)
    np.testing.assert_allclose(member.P[1, 1], p[0, 0], rtol=1e-12)
    np.testing.assert_allclose(member.x[2:3], x[2:3])
