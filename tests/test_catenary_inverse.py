"""Curve from the tension on the drone (Martins 2019 section 6): round trips and limits."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tether_companion.physics.catenary import solve_known_length, solve_lowest_point_at_anchor
from tether_companion.physics.catenary_forces import (
    curve_from_tension_known_length,
    curve_from_tension_lowest_point_at_anchor,
    drone_point,
    end_tensions,
)

W = 0.25  # N/m


@settings(max_examples=200, deadline=None)
@given(
    horizontal=st.floats(min_value=0.0, max_value=200.0),
    height=st.floats(min_value=-100.0, max_value=200.0),
    slack=st.floats(min_value=1e-4, max_value=2.0),
)
def test_known_length_round_trip(horizontal, height, slack):
    """Solve for the curve, compute the force on the drone, invert: the drone comes back."""
    length = math.hypot(horizontal, height) * (1.0 + slack) + 1e-3
    curve = solve_known_length(horizontal, height, length)
    t = end_tensions(curve, W)
    back = curve_from_tension_known_length(t.horizontal_n, -t.on_drone_vertical_n, length, W)
    x, y = drone_point(back)
    assert x == pytest.approx(horizontal, rel=1e-6, abs=1e-6 * length)
    assert y == pytest.approx(height, rel=1e-6, abs=1e-6 * length)


@settings(max_examples=200, deadline=None)
@given(
    horizontal=st.floats(min_value=0.0, max_value=200.0),
    height=st.floats(min_value=1e-2, max_value=200.0),
)
def test_lowest_point_at_anchor_round_trip(horizontal, height):
    curve = solve_lowest_point_at_anchor(horizontal, height)
    t = end_tensions(curve, W)
    back = curve_from_tension_lowest_point_at_anchor(t.horizontal_n, -t.on_drone_vertical_n, W)
    x, y = drone_point(back)
    assert x == pytest.approx(horizontal, rel=1e-6, abs=1e-6 * height)
    assert y == pytest.approx(height, rel=1e-6)


def test_vertical_limits_from_tension():
    """No horizontal tension: r = 0 and z = s2 (eqs. 63-64), z = |s2| - |s1| (eqs. 70-71)."""
    case1 = curve_from_tension_lowest_point_at_anchor(0.0, 2.0 * W, W)
    assert drone_point(case1) == (0.0, 2.0)
    case2 = curve_from_tension_known_length(0.0, 0.0, 1.6, W)
    # thesis eq. 74 with the anchor at height 0: initial estimate z = -|s1| = -L
    assert drone_point(case2) == (0.0, pytest.approx(-1.6))
    case2 = curve_from_tension_known_length(0.0, 3.0 * W, 5.0, W)
    assert drone_point(case2) == (0.0, pytest.approx(3.0 - 2.0))


def test_inverse_bad_input():
    with pytest.raises(ValueError, match="pulls the drone down"):
        curve_from_tension_lowest_point_at_anchor(1.0, -0.1, W)
    with pytest.raises(ValueError, match="magnitude"):
        curve_from_tension_known_length(-1.0, 0.1, 3.0, W)
    with pytest.raises(ValueError, match="length_m must be > 0"):
        curve_from_tension_known_length(1.0, 0.1, 0.0, W)
    with pytest.raises(ValueError, match="weight_per_length"):
        curve_from_tension_known_length(1.0, 0.1, 3.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        curve_from_tension_lowest_point_at_anchor(math.nan, 0.1, W)
