"""Catenary solvers (Martins 2019 section 3): recovery of generating curves, limits, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from tether_companion.physics.catenary import (
    CatenaryCurve,
    initial_guess_known_length,
    initial_guess_lowest_point_at_anchor,
    solve_known_length,
    solve_lowest_point_at_anchor,
)
from tether_companion.physics.catenary_forces import drone_point, end_tensions, force_on_drone_ned_n

RELATIVE = 1e-6


def _close(got: float, want: float, scale: float) -> bool:
    """Relative error below RELATIVE, relative to max(|want|, scale) (scale = span of the
    problem, for quantities such as x0 that may be near zero)."""
    return abs(got - want) <= RELATIVE * max(abs(want), scale)


def _generated(a: float, x0: float, span: float) -> tuple[float, float, float, CatenaryCurve]:
    """A catenary through the anchor (0, 0) with parameter a and lowest point x0, and the
    drone at x = span: returns (horizontal, height, length, curve)."""
    u1, u2 = -x0 / a, (span - x0) / a
    c = -a * math.cosh(u1)
    # differences of cosh and sinh as products: the generated data carry relative rounding
    # only, so the test measures the solver, not cancellation in its own inputs
    mean, half = 0.5 * (u1 + u2), 0.5 * (u2 - u1)
    height = 2.0 * a * math.sinh(mean) * math.sinh(half)
    length = 2.0 * a * math.cosh(mean) * math.sinh(half)
    return span, height, length, CatenaryCurve(a, x0, c, a * math.sinh(u1), a * math.sinh(u2))


def _relative_slack(horizontal: float, height: float, length: float) -> float:
    chord = math.hypot(horizontal, height)
    return (length - chord) / chord


# Random geometries: a in [0.05, 50] m; the ends at (x - x0)/a in [-6, 6] (slopes up to
# sinh(6) ~ 200, 89.7 deg), the span at least 2e-3 a, and the cable at least 1e-8 longer than
# its chord. The problem's condition number is about 1 / (2 relative slack): for a nearly
# taut cable the rounding of the inputs alone (1e-16) moves a by 1e-16 / (2 slack).
spans_over_a = st.floats(min_value=2e-3, max_value=12.0)
a_values = st.floats(min_value=0.05, max_value=50.0)
anchor_u = st.floats(min_value=-6.0, max_value=6.0)


@settings(max_examples=300, deadline=None)
@given(a=a_values, span_over_a=spans_over_a, u1=anchor_u)
def test_known_length_recovers_generating_curve(a, span_over_a, u1):
    assume(u1 + span_over_a <= 6.0)
    span = a * span_over_a
    x0 = -u1 * a
    horizontal, height, length, want = _generated(a, x0, span)
    assume(_relative_slack(horizontal, height, length) >= 1e-8)
    got = solve_known_length(horizontal, height, length)
    assert _close(got.a_m, want.a_m, 0.0)
    assert _close(got.x0_m, want.x0_m, span)
    assert _close(got.c_m, want.c_m, span)
    assert _close(got.s1_m, want.s1_m, length)
    assert _close(got.s2_m, want.s2_m, length)
    x, y = drone_point(got)
    assert _close(x, horizontal, span) and _close(y, height, span)


@settings(max_examples=300, deadline=None)
@given(a=a_values, span_over_a=st.floats(min_value=1e-3, max_value=12.0))
def test_lowest_point_at_anchor_recovers_generating_curve(a, span_over_a):
    span = a * span_over_a
    horizontal, height, length, want = _generated(a, 0.0, span)
    got = solve_lowest_point_at_anchor(horizontal, height)
    assert _close(got.a_m, want.a_m, 0.0)
    assert got.x0_m == 0.0 and got.s1_m == 0.0
    assert _close(got.c_m, want.c_m, 0.0)
    assert _close(got.length_m, length, 0.0)


@settings(max_examples=200, deadline=None)
@given(a=a_values, span_over_a=spans_over_a)
def test_level_case_recovers_curve(a, span_over_a):
    """Delta Y = 0: the lowest point is mid-span (eq. 32 with x0 = x_average)."""
    span = a * span_over_a
    horizontal, height, length, want = _generated(a, 0.5 * span, span)
    got = solve_known_length(horizontal, 0.0, length)
    assert abs(height) < 1e-12 * max(1.0, length)
    assert _close(got.a_m, want.a_m, 0.0)
    assert _close(got.x0_m, 0.5 * span, span)


@settings(max_examples=300, deadline=None)
@given(
    horizontal=st.floats(min_value=0.0, max_value=1e3),
    height=st.floats(min_value=-1e3, max_value=1e3),
    slack=st.floats(min_value=1e-6, max_value=1e3),
)
def test_known_length_never_raises_on_valid_input(horizontal, height, slack):
    length = math.hypot(horizontal, height) * (1.0 + slack) + slack
    curve = solve_known_length(horizontal, height, length)
    assert all(math.isfinite(v) for v in (curve.a_m, curve.x0_m, curve.c_m, curve.s1_m, curve.s2_m))
    assert curve.a_m >= 0.0
    assert curve.length_m == pytest.approx(length, rel=1e-9)
    x, y = drone_point(curve)
    assert x == pytest.approx(horizontal, rel=1e-6, abs=1e-6 * length)
    assert y == pytest.approx(height, rel=1e-6, abs=1e-6 * length)


@settings(max_examples=300, deadline=None)
@given(
    horizontal=st.floats(min_value=0.0, max_value=1e3),
    height=st.floats(min_value=1e-3, max_value=1e3),
)
def test_lowest_point_at_anchor_never_raises_on_valid_input(horizontal, height):
    curve = solve_lowest_point_at_anchor(horizontal, height)
    assert curve.a_m >= 0.0 and math.isfinite(curve.s2_m)
    x, y = drone_point(curve)
    assert x == pytest.approx(horizontal, rel=1e-6, abs=1e-6 * height)
    assert y == pytest.approx(height, rel=1e-6)


@settings(max_examples=200, deadline=None)
@given(
    horizontal=st.floats(min_value=0.0, max_value=1e3),
    height=st.floats(min_value=-1e3, max_value=1e3),
    shortfall=st.floats(min_value=0.0, max_value=1.0),
)
def test_length_not_longer_than_chord_is_value_error(horizontal, height, shortfall):
    chord = math.hypot(horizontal, height)
    with pytest.raises(ValueError, match="chord"):
        solve_known_length(horizontal, height, chord * (1.0 - shortfall))


def test_thesis_level_example_by_hand():
    """Level span 2 m, length 2.5 m: 2 a sinh(1/a) = 2.5 (solved independently by bisection)."""
    lo, hi = 0.1, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 2.0 * mid * math.sinh(1.0 / mid) > 2.5:
            lo = mid
        else:
            hi = mid
    curve = solve_known_length(2.0, 0.0, 2.5)
    assert curve.a_m == pytest.approx(lo, rel=1e-12)
    assert curve.x0_m == pytest.approx(1.0, abs=1e-12)
    assert curve.s1_m == pytest.approx(-1.25) and curve.s2_m == pytest.approx(1.25)


def test_initial_guesses_are_close_for_moderate_sag():
    """The Taylor guesses (eqs. 25 and 36-39) land near the answer when x/a is small; the
    sign-corrected Cardano coefficients are needed for that (the printed ones have no
    positive root)."""
    _, height, length, want = _generated(5.0, 0.0, 2.0)
    assert initial_guess_lowest_point_at_anchor(2.0, height) == pytest.approx(5.0, rel=1e-3)
    _, height, length, want = _generated(5.0, 0.7, 2.0)
    assert initial_guess_known_length(2.0, height, length) == pytest.approx(5.0, rel=1e-3)


def test_vertical_limits():
    """Horizontal span 0: a = 0 and the limits of eqs. 63-64 (case 1) and 70-71 (case 2)."""
    curve = solve_lowest_point_at_anchor(0.0, 4.0)
    assert (curve.a_m, curve.s1_m, curve.s2_m) == (0.0, 0.0, 4.0)
    assert drone_point(curve) == (0.0, 4.0)
    folded = solve_known_length(0.0, 3.0, 5.0)
    assert folded.a_m == 0.0
    assert folded.lowest_point_height_m == pytest.approx(-1.0)  # (dy - L)/2
    assert folded.s2_m == pytest.approx(4.0) and folded.length_m == pytest.approx(5.0)
    assert drone_point(folded)[1] == pytest.approx(3.0)
    with pytest.raises(ValueError, match="vertical"):
        folded.height_at_m(0.0)


def test_near_vertical_is_continuous_with_limit():
    """A tiny horizontal offset gives nearly the vertical limit's tensions, not a blow-up."""
    w = 0.2
    limit = end_tensions(solve_known_length(0.0, 3.0, 5.0), w)
    near = end_tensions(solve_known_length(1e-6, 3.0, 5.0), w)
    assert near.horizontal_n < 1e-6
    assert near.on_drone_vertical_n == pytest.approx(limit.on_drone_vertical_n, rel=1e-5)


def test_end_tensions_balance_weight_and_match_slopes():
    w = 0.35
    _, height, length, curve = _generated(2.0, 1.1, 4.0)
    t = end_tensions(curve, w)
    assert t.horizontal_n == pytest.approx(w * 2.0)
    # vertical forces on the supports balance the cable's weight
    assert -(t.on_anchor_vertical_n + t.on_drone_vertical_n) == pytest.approx(w * length)
    # the force on the drone is along the tangent back into the cable: slope sinh((x-x0)/a)
    slope = math.sinh((4.0 - 1.1) / 2.0)
    assert t.on_drone_vertical_n / t.on_drone_horizontal_n == pytest.approx(slope)
    assert t.drone_n == pytest.approx(math.hypot(t.horizontal_n, t.on_drone_vertical_n))
    # eq. 13 magnitude equals w (y - c) at each end
    assert t.drone_n == pytest.approx(w * (height - curve.c_m))
    assert t.anchor_n == pytest.approx(w * (0.0 - curve.c_m))


def test_drone_below_lowest_point_side_pulls_up():
    """Drone below the anchor with the lowest point beyond it: s2 < 0, the cable pulls the
    drone UP (the thesis' |x - x0| would give the wrong sign)."""
    _, height, length, curve = _generated(1.0, 6.0, 4.0)
    assert curve.s2_m < 0.0 and height < 0.0
    solved = solve_known_length(4.0, height, length)
    assert end_tensions(solved, 0.1).on_drone_vertical_n > 0.0


def test_force_on_drone_ned_points_to_anchor_and_down():
    position = np.array([3.0, -4.0, -2.0])
    force = force_on_drone_ned_n(position, 8.0, 0.1)
    horizontal = force[:2]
    assert np.dot(horizontal, position[:2]) < 0.0
    assert abs(horizontal[0] * position[1] - horizontal[1] * position[0]) < 1e-12
    curve = solve_known_length(5.0, 2.0, 8.0)
    assert force[2] == pytest.approx(0.1 * curve.s2_m)
    assert np.linalg.norm(force) == pytest.approx(end_tensions(curve, 0.1).drone_n)


def test_height_at_matches_endpoints():
    _, height, _, curve = _generated(3.0, 2.0, 5.0)
    assert curve.height_at_m(0.0) == pytest.approx(0.0, abs=1e-12)
    assert curve.height_at_m(5.0) == pytest.approx(height)
    assert curve.height_at_m(2.0) == pytest.approx(curve.lowest_point_height_m)


@pytest.mark.parametrize(
    ("horizontal", "height", "length", "match"),
    [
        (math.nan, 1.0, 2.0, "horizontal_m must be a finite"),
        (1.0, math.inf, 2.0, "height_m must be a finite"),
        (1.0, 1.0, math.nan, "length_m must be a finite"),
        (-1.0, 1.0, 5.0, "horizontal_m is a distance"),
        (1.0, 1.0, -5.0, "length_m must be >= 0"),
        (3.0, 4.0, 5.0, "chord"),
        (3.0, 4.0, 4.0, "chord"),
    ],
)
def test_known_length_bad_input(horizontal, height, length, match):
    with pytest.raises(ValueError, match=match):
        solve_known_length(horizontal, height, length)


@pytest.mark.parametrize(
    ("horizontal", "height", "match"),
    [
        (math.nan, 1.0, "horizontal_m must be a finite"),
        (1.0, -math.inf, "height_m must be a finite"),
        (-0.5, 1.0, "horizontal_m is a distance"),
        (1.0, 0.0, "drone must be above the anchor"),
        (1.0, -2.0, "drone must be above the anchor"),
    ],
)
def test_lowest_point_at_anchor_bad_input(horizontal, height, match):
    with pytest.raises(ValueError, match=match):
        solve_lowest_point_at_anchor(horizontal, height)


@pytest.mark.parametrize("w", [0.0, -0.1, math.nan, math.inf])
def test_end_tensions_bad_weight(w):
    curve = solve_known_length(1.0, 1.0, 2.0)
    with pytest.raises(ValueError, match="weight_per_length_n_per_m"):
        end_tensions(curve, w)


@pytest.mark.parametrize(
    ("alpha", "beta", "gamma"),
    [(-2.0, 0.0, -3.0), (1.5, 0.2, 4.0), (-0.1, 0.0, -1e-6), (3.0, 3.0, 1.0 + 1e-3)],
)
def test_cardano_real_root_matches_numpy(alpha, beta, gamma):
    from tether_companion.physics.catenary import _cardano_real_root

    roots = np.roots([1.0, alpha, beta, gamma])
    real = roots[np.abs(roots.imag) < 1e-7].real
    got = _cardano_real_root(alpha, beta, gamma)
    assert np.min(np.abs(real - got)) < 1e-6 * max(1.0, abs(got))


def test_thesis_printed_cardano_signs_have_no_positive_root():
    """Eq. 25's coefficients as printed (alpha, gamma > 0) give a negative real root only:
    the sign correction in docs/catenary.md is needed for a usable guess."""
    from tether_companion.physics.catenary import _cardano_real_root

    x, dy = 2.0, 1.0
    printed = _cardano_real_root(x**2 / (2 * dy), 0.0, x**4 / (24 * dy))
    assert printed < 0.0
    assert initial_guess_lowest_point_at_anchor(x, dy) > 0.0
