"""The unmodelled force's offset on a cable of known length and weight
(estimation/dynamic/offset_term.py, sag_range.span_per_horizontal_tension): the span's motion
per newton of horizontal pull at a held length and height against an independent catenary
solver and the resting cable's closed form, the offset's rows, and the ground station and the
publisher taking the same ``C``."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.models import rests_on_ground
from tether_companion.estimation.dynamic.observability import unmodelled_position_rows
from tether_companion.estimation.dynamic.offset_term import offset_rows
from tether_companion.estimation.dynamic.sag_range import (
    arc_length_m,
    span_per_horizontal_tension,
)
from tether_companion.physics.catenary import solve_known_length

HEAVY_N_PER_M = 0.1 * 9.80665
"""The heavy cable's weight [N/m] (0.1 kg/m, realistic-heavy-sagging-hover)."""


def _state(n: float, e: float, height: float, chord_tension: float) -> list[float]:
    x = [0.0] * state.N_STATES
    x[0], x[1], x[2], x[state.TENSION] = n, e, -height, chord_tension
    return x


def test_the_span_per_pull_of_a_free_catenary_is_the_independent_solvers() -> None:
    """A free heavy catenary (4 m out, 3 m up, 5 N horizontal): physics/catenary.py's
    known-length solver (Martins 2019, not the generated models) gives the horizontal tension
    ``H = w a_m`` at spans either side of the length the model gives; ``da/dH`` is the
    inverse of its slope."""
    span, height, horizontal = 4.0, 3.0, 5.0
    x = _state(span, 0.0, height, horizontal * math.hypot(span, height) / span)
    assert not rests_on_ground(x, (0.0, 0.0, HEAVY_N_PER_M))
    length = arc_length_m(span, height, horizontal, HEAVY_N_PER_M)
    step = 1e-4

    def pull(a: float) -> float:
        return HEAVY_N_PER_M * solve_known_length(a, height, length).a_m

    assert pull(span) == pytest.approx(horizontal, rel=1e-6)
    expected = 2.0 * step / (pull(span + step) - pull(span - step))
    got = span_per_horizontal_tension(span, height, horizontal, HEAVY_N_PER_M)
    assert got == pytest.approx(expected, rel=1e-4)
    assert 0.0 < got < 0.1  # taut: a pull barely moves it


def test_the_span_per_pull_of_a_resting_cable_is_the_closed_forms() -> None:
    """Resting on the anchor's level (1 N horizontal, 3 m up, 8 m out): the hanging part is
    a catenary from its lowest point at the touchdown, ``x_s = c acosh(1 + h / c)``, ``s_s =
    sqrt(h^2 + 2 h c)`` (``c = H / w``), the rest lies flat, ``L = a - x_s + s_s``; so at a
    held length ``da/dH = (dx_s/dH - ds_s/dH)``, large: the grounded part takes up length."""
    span, height, horizontal = 8.0, 3.0, 1.0
    x = _state(span, 0.0, height, horizontal * math.hypot(span, height) / span)
    assert rests_on_ground(x, (0.0, 0.0, HEAVY_N_PER_M))

    def taken(h_n: float) -> float:  # x_s - s_s: the span the hanging part adds to L
        c = h_n / HEAVY_N_PER_M
        return c * math.acosh(1.0 + height / c) - math.sqrt(height * height + 2.0 * height * c)

    step = 1e-5
    expected = (taken(horizontal + step) - taken(horizontal - step)) / (2.0 * step)
    got = span_per_horizontal_tension(span, height, horizontal, HEAVY_N_PER_M)
    assert got == pytest.approx(expected, rel=1e-5)
    assert got > 0.5  # half a metre per newton


def test_with_a_length_the_offset_is_the_curves_motion_across_and_along_the_span() -> None:
    """On a heavy cable with a fused length: across the plane ``r sigma / T_ch`` (the turn of
    the curve about the anchor's vertical, ``a sigma / H``), along the span ``sigma da/dH``
    horizontal (the height held), the length's noise along the cable; without a length or on
    a weightless cable the straight cable's term (the turn about the anchor at a held range)
    at the chord tension."""
    n, e, height, horizontal, sigma, length_std = 6.0, 4.0, 3.0, 1.0, 0.2, 0.05
    span = math.hypot(n, e)
    distance = math.hypot(span, height)
    x = _state(n, e, height, horizontal * distance / span)
    c = np.array(offset_rows(x, HEAVY_N_PER_M, sigma, length_std, True))
    across = np.array([-e / span, n / span, 0.0])
    along = np.array([n / span, e / span, 0.0])
    u = np.array([n, e, -height]) / distance
    radial = span_per_horizontal_tension(span, height, horizontal, HEAVY_N_PER_M)
    assert across @ c @ across == pytest.approx((span * sigma / horizontal) ** 2, rel=1e-12)
    assert along @ c @ along == pytest.approx(
        (radial * sigma) ** 2 + (length_std * (along @ u)) ** 2, rel=1e-12
    )
    assert across @ c @ along == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(c, c.T, atol=0.0)
    assert c[2, 2] == pytest.approx((length_std * u[2]) ** 2, rel=1e-12)  # no pivot down
    straight = unmodelled_position_rows(n, e, -height, x[state.TENSION], sigma, 0.0)
    assert offset_rows(x, HEAVY_N_PER_M, sigma, 0.0, False) == straight
    assert offset_rows(x, 0.0, sigma, length_std, True) == unmodelled_position_rows(
        n, e, -height, x[state.TENSION], sigma, length_std
    )


def test_the_ground_station_and_the_publisher_take_the_same_offset() -> None:
    """The heavy sagging hover (0.1 kg/m, the load cell's kind, tuning seed 1, 8 s): what
    the angle readings left of the offset (the kept ``P``, traced) stays within the ``C`` the
    publisher blends it with at every tick (at most 0.02 times it in trace here). With the
    ground station at the chord tension and the publisher at the drone's (4.6 times it there)
    the kept ``P`` was 4.0-4.5 times that ``C`` in trace (own16 found it)."""
    from tether_companion.bench.estimators.flight import fly
    from tether_companion.bench.estimators.registry import kinds
    from tether_companion.estimation.dynamic import published, published_terms
    from tether_companion.sim.scenario import load_scenario

    seen: list[float] = []
    original = published_terms.reduce_added_rows

    def record(rows, information):  # noqa: ANN001, ANN202
        if information is not None:
            kept_trace = information[0] + information[3] + information[5]
            seen.append(kept_trace / (rows[0][0] + rows[1][1] + rows[2][2]))
        return original(rows, information)

    scenario = dataclasses.replace(
        load_scenario("realistic-heavy-sagging-hover"), seed=1, duration_s=8.0
    )
    twin = published.ADDED_POSITION_TERMS  # the added terms' Python reference, traced
    published_terms.reduce_added_rows = record
    published.ADDED_POSITION_TERMS = published_terms.added_position_terms
    try:
        fly(scenario, [kinds()["dynamic-winch-angle-tension"]])
    finally:
        published_terms.reduce_added_rows = original
        published.ADDED_POSITION_TERMS = twin
    assert len(seen) > 1000
    assert max(seen) < 1.2, max(seen)
