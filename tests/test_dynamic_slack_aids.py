"""The winch length and the cable angle skipped as slack: what the filter does today when its
tension estimate dips below ``slack_tension_n`` (it skips them on the point estimate), and
the lock-out that follows, kept as strict xfails until it is fixed."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aid.winch import SLACK
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.sim.scenario import load_scenario


def _started() -> tuple[DynamicTetherEstimator, np.ndarray, float]:
    """An estimator after 3 s of the paper circle (straight cable), its best member's position
    [m] (the reference the tests' readings are made from) and the time [s]."""
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=3.0, seed=2)
    run = run_dynamic(scenario, EstimatorConfig(), DynamicFilterConfig())
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


LOCK_OUT = (
    "the aids skip on the tension's point estimate: a filter whose tension dips below "
    "slack_tension_n stops hearing the winch and the angle that would correct it (ArduPilot "
    "SITL, winch + angle, the circle after the taut hold: 80 s of drift to 15 m, 1 run in 3). "
    "Two fixes measured, seeds 6-8, 30 s, not taken (docs/estimation.md): a gate on the "
    "tension's 3-sigma upper bound (branch slack-gate-wip-a) made the sagging circle publish "
    "2-7 % of its ticks, all beyond 3 sigma; that gate for the angle only with the chord "
    "fused beyond the line (slack-gate-wip) ran the angle-alone kind away (gusty hover "
    "0.51 -> 44.8 m RMSE, withheld)"
)


@pytest.mark.xfail(strict=True, reason=LOCK_OUT)
def test_an_unsure_low_tension_still_hears_the_cable_angle() -> None:
    """Tension believed 0.1 N (below the 0.2 N threshold) but +- 0.5 N, and the drone put
    1.5 m across the cable: the angle to where it was is fused and pulls the position back."""
    est, truth, t = _started()
    _believe(est, 0.1, 0.5, _across(truth, 1.5))
    before = np.linalg.norm(est.bank.best.x[state.POSITION][:2] - truth[:2])
    for k in range(1, 6):
        est.on_cable_angle(*_angles(truth), t + 0.001 * k, 0.01)
    after = np.linalg.norm(est.bank.best.x[state.POSITION][:2] - truth[:2])
    assert est.cable_angle.status.fused == 5
    assert SLACK not in est.cable_angle.status.skipped_by_reason
    assert after < 0.3 * before


def test_a_surely_slack_cable_skips_the_angle_and_an_unreachable_length() -> None:
    """Tension surely slack (-0.5 +- 0.05 N): the angle is skipped, and so is a paid-out length
    longer than the drone's distance (the slack line only says the drone is nearer)."""
    est, truth, t = _started()
    _believe(est, -0.5, 0.05, (0.0, 0.0, 0.0))
    est.on_cable_angle(*_angles(truth), t + 0.001, 0.01)
    est.set_paid_out_length_m(float(np.linalg.norm(truth)) + 1.0, t + 0.002)
    assert est.cable_angle.status.skipped_by_reason[SLACK] == 1
    assert est.winch.status.skipped_by_reason[SLACK] == 1
    assert est.cable_angle.status.fused == 0 and est.winch.status.fused == 0


@pytest.mark.xfail(strict=True, reason=LOCK_OUT)
def test_a_drone_beyond_the_line_is_pulled_in_whatever_the_tension() -> None:
    """Tension surely slack, but the filter has the drone 1 m farther out than the paid-out
    line reaches: the length is fused (the line bounds the distance) and the range shrinks."""
    est, truth, t = _started()
    _believe(est, -0.5, 0.05, (0.0, 0.0, 0.0))
    before = float(np.linalg.norm(est.bank.best.x[state.POSITION]))
    length = before - 1.0
    est.set_paid_out_length_m(length, t + 0.001)
    after = float(np.linalg.norm(est.bank.best.x[state.POSITION]))
    assert est.winch.status.fused == 1
    assert abs(after - length) < 0.5 * abs(before - length)
