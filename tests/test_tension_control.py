"""Tension-based position control (Martins 5.2) and the catenary bench's comparison."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.bench.catenary import compare, flight
from tether_companion.estimation.catenary_position import force_from_position_ned_n
from tether_companion.sim.tension_control import (
    TensionControlConfig,
    TensionPositionController,
    fly_to_goals,
)

W = 0.05 * 9.80665
LENGTH = 5.2


def _controller():
    return TensionPositionController(TensionControlConfig(), LENGTH, W)


def test_goal_force_and_law_point_the_right_way():
    controller = _controller()
    goal = np.array([3.5, 1.5, -2.5])
    controller.set_goal(goal)
    assert np.allclose(controller.goal_force_ned_n, force_from_position_ned_n(goal, LENGTH, W))
    # at the goal: no horizontal command; altitude held on the height
    v = controller.velocity_setpoint(controller.goal_force_ned_n, 2.5)
    assert np.allclose(v, 0.0, atol=1e-12)
    # the pull felt nearer the anchor: the law sends the drone toward the goal
    for offset in ([-0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [0.15, -0.1, 0.0]):
        here = goal + np.array(offset)
        v = controller.velocity_setpoint(force_from_position_ned_n(here, LENGTH, W), 2.5)
        assert np.dot(v[:2], -np.array(offset[:2])) > 0.0
        # linearised: v = -k (p - p_goal) for small offsets
        assert np.allclose(v[:2], -0.8 * np.array(offset[:2]), atol=0.05)
    # too low: climb (negative down speed), limited
    assert controller.velocity_setpoint(controller.goal_force_ned_n, 1.0)[2] == pytest.approx(-0.5)
    assert controller.velocity_setpoint(controller.goal_force_ned_n, math.nan)[2] == 0.0


def test_unreachable_or_unsteerable_goals_are_refused():
    controller = _controller()
    with pytest.raises(ValueError, match="chord"):
        controller.set_goal(np.array([5.0, 3.0, -3.0]))  # farther than the cable
    with pytest.raises(ValueError, match="no horizontal pull"):
        controller.set_goal(np.array([0.0, 0.0, -3.0]))  # above the anchor


def test_tension_control_reaches_a_goal_in_the_simulator():
    (result,) = fly_to_goals(((3.5, 1.5, -2.5),), hold_s=14.0, average_s=2.0, seed=2)
    assert result.error_m < 0.2, result


def test_catenary_estimator_beats_straight_cable_ekf_on_a_heavy_cable():
    """Short hover on the catenary cable: the catenary position is far better than the
    4-state EKF, whose straight-cable model does not hold there (bench catenary, shortened)."""
    result = compare(flight("hover", seed=3, duration_s=9.0))
    assert np.all(result.rmse_catenary_m < 0.15)
    assert np.linalg.norm(result.rmse_ekf_m) > 3.0 * np.linalg.norm(result.rmse_catenary_m)
    assert result.missing_catenary == 0
