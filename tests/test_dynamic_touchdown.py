"""The touchdown: near the ground the dynamic filter withholds its position (status
``on_ground``, the height in the reason), because the ground's contact force is no part of its
model and the rangefinder is below its minimum range (docs/estimation-history.md, "The
touchdown (split10)"). Without the rule the take-off's landing published 0.2-0.5 s of ticks
whose down error grew to 0.3-0.6 m at a claimed 0.11-0.14 m."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from level_ticks import level_ticks

from tether_companion.bench.estimators.flight import fly
from tether_companion.bench.estimators.registry import kinds
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.estimation.dynamic.on_ground import (
    THRUST_BELOW_WEIGHT,
    on_ground_reason,
)
from tether_companion.estimation.dynamic.output import ON_GROUND, NavigationEstimate
from tether_companion.sim.scenario import load_scenario


def _started(**dynamic: float) -> tuple[DynamicTetherEstimator, float]:
    """An estimator after 3 s of the paper circle (the anchor at ground level) and the time."""
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=3.0, seed=1)
    run = run_dynamic(scenario, EstimatorConfig(), DynamicFilterConfig(**dynamic))
    assert run.estimator.initialised
    return run.estimator, float(run.time_s[-1])


def _ticks_at_height(
    est: DynamicTetherEstimator, t: float, height_m: float, n: int = 10
) -> NavigationEstimate:
    """Every member placed ``height_m`` above the ground (at rest), then ``n`` level ticks of
    a drone holding its weight; the last estimate."""
    for member in est.bank.filters:
        x = member.x.copy()
        x[2] = -height_m  # the ground is at the anchor's level: down = -height
        x[3:6] = 0.0
        member.x = x
    return level_ticks(est, t, n)


def test_touching_down_withholds_the_position_and_says_why() -> None:
    est, t = _started()
    estimate = _ticks_at_height(est, t, 0.1)
    assert estimate.status == ON_GROUND and not estimate.observable
    assert "touching down" in estimate.reason and "< 0.3 m" in estimate.reason
    assert np.all(np.isfinite(estimate.position_ned_m))  # the filter runs on, only withheld


def test_above_the_touchdown_height_and_with_the_rule_off_it_is_not_on_the_ground() -> None:
    est, t = _started()
    assert _ticks_at_height(est, t, 1.0).status != ON_GROUND
    off, t_off = _started(touchdown_height_m=0.0)
    assert _ticks_at_height(off, t_off, 0.1).status != ON_GROUND


def test_the_on_ground_reasons() -> None:
    assert on_ground_reason(True, -2.0, 1.0, 0.3) == THRUST_BELOW_WEIGHT
    assert on_ground_reason(False, -2.0, 1.0, 0.3) == ""  # 3 m above the ground
    assert on_ground_reason(False, 0.8, 1.0, 0.3).startswith("touching down: 0.20 m")
    assert on_ground_reason(False, math.nan, 1.0, 0.3) == ""  # no state: not decided here


@pytest.mark.slow
def test_the_take_offs_landing_publishes_nothing_beyond_three_sigma() -> None:
    """The realistic take-off, tuning seed 1, the cable-angle kinds (those published through
    the landing): no published tick beyond 3 sigma on any axis, and none once the drone is
    within 0.15 m of the ground (~10 s)."""
    scenario = dataclasses.replace(load_scenario("realistic-takeoff-figure8"), seed=1)
    registry = kinds()
    names = ("dynamic-angle", "dynamic-winch-angle")
    record = fly(scenario, [registry[n] for n in names])
    landing = record.time_s > 20.0
    height_m = scenario.ground.anchor_height_m - record.position_ned_m[:, 2]  # above the ground
    touching = landing & (height_m < 0.15)
    for name in names:
        trace = record.traces[name]
        published = trace.published & landing
        assert published.any()
        error = trace.position_ned_m - record.position_ned_m
        sigma = np.sqrt(np.diagonal(trace.position_covariance_m2, axis1=1, axis2=2))
        beyond = np.any(np.abs(error) > 3.0 * sigma, axis=1)
        assert not np.any(published & beyond), name
        assert not np.any(trace.published & touching), name
