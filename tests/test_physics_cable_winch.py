"""The constant-tension winch on a heavy cable (physics/cable_winch.py) against independent
computations: the catenary equations solved from scratch with scipy, the fixed-length catenary
model fed the length this one pays out, the weightless line, the slack and vertical limits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics import catenary, catenary_forces
from tether_companion.physics.cable import (
    CableConfig,
    CatenaryCable,
    ConstantTensionCable,
    ElasticCable,
    make_cable,
)
from tether_companion.physics.cable_anchor import anchor_direction_ned
from tether_companion.physics.cable_winch import (
    WinchCatenaryCable,
    tension_at_drone_n,
    winch_catenary,
)
from tether_companion.sim.ground_sensors import GroundSensorConfig, GroundSensors

G = GRAVITY_MPS2
spans = st.floats(0.3, 20.0)
heights = st.floats(0.3, 10.0)
tensions = st.floats(0.2, 20.0)
densities = st.floats(0.005, 0.3)


def _scratch(x: float, h: float, t_a: float, w: float) -> tuple[float, float, float, float]:
    """(pull, down, paid out, on the ground) from the catenary equations, solved afresh.

    ``y = c cosh((x - x0)/c) + k`` through (0, 0) and (x, h) with tension ``w c cosh(x0/c) =
    t_a`` at the anchor, lowest point at or before the anchor (``x0 <= 0``): one equation in
    ``c`` by Brent's method. If none fits (the lowest point would fall between the ends, below
    the anchor), the cable lies on the ground with ``c = t_a / w`` and rises from a touchdown
    point ``x_t`` with ``c (cosh((x - x_t)/c) - 1) = h``."""
    a = t_a / w
    if a * math.cosh(x / a) - a - h >= 0.0:  # even the flattest rising curve is too high
        c = a
        x_t = brentq(lambda xt: c * (math.cosh((x - xt) / c) - 1.0) - h, 0.0, x, xtol=1e-14)
        rise = c * math.sinh((x - x_t) / c)
        return w * c, w * rise, x_t + rise, x_t

    def x0_of(c: float) -> float:
        return -c * math.acosh(a / c)

    def residual(c: float) -> float:
        return c * math.cosh((x - x0_of(c)) / c) - (a + h)

    low = max(a * 1e-6, x / 600.0)  # cosh stays finite; the residual is positive there
    c = brentq(residual, low, a, xtol=1e-15 * a, rtol=1e-15)
    x0 = x0_of(c)
    s2 = c * math.sinh((x - x0) / c)
    return w * c, w * s2, s2 - c * math.sinh(-x0 / c), 0.0


@settings(max_examples=30, deadline=None)
@given(spans, heights, tensions, densities)
def test_matches_the_catenary_equations_solved_from_scratch(
    x: float, h: float, t_a: float, rho: float
) -> None:
    w = rho * G
    cable = winch_catenary(x, h, t_a, w)
    pull, down, paid_out, on_ground = _scratch(x, h, t_a, w)
    assert cable.pull_n == pytest.approx(pull, rel=1e-7, abs=1e-9)
    assert cable.down_n == pytest.approx(down, rel=1e-7, abs=1e-9)
    assert cable.paid_out_m == pytest.approx(paid_out, rel=1e-7, abs=1e-9)
    assert cable.on_ground_m == pytest.approx(on_ground, rel=1e-6, abs=1e-7)
    # the tension at the drone is T_a + w h, and it is the force's magnitude
    assert cable.drone_tension_n == pytest.approx(t_a + w * h, rel=1e-12)
    assert math.hypot(cable.pull_n, cable.down_n) == pytest.approx(t_a + w * h, rel=1e-9)


@settings(max_examples=30, deadline=None)
@given(spans, heights, tensions, densities)
def test_the_fixed_length_catenary_of_the_paid_out_length_pulls_the_same(
    x: float, h: float, t_a: float, rho: float
) -> None:
    """The known-length catenary (Martins case 2, or the fixed-length cable's part on the
    ground) of the length this winch paid out gives back the same force and anchor tangent."""
    w = rho * G
    position = (0.6 * x, -0.8 * x, -h)
    winch = WinchCatenaryCable(t_a, rho, G)
    force = winch.force_on_drone_ned_n(position, (0.0, 0.0, 0.0))
    direction = anchor_direction_ned(winch, position)
    if winch_catenary(x, h, t_a, w).on_ground_m > 0.0:
        fixed = CatenaryCable(ElasticCable(winch.paid_out_m, 1e15, 0.0, rho), rho)
        expected = fixed.force_on_drone_ned_n(position, (0.0, 0.0, 0.0))
        assert direction == pytest.approx(anchor_direction_ned(fixed, position), abs=1e-12)
    else:
        expected = catenary_forces.force_on_drone_ned_n(position, winch.paid_out_m, w)
        ends = catenary_forces.end_tensions(catenary.solve_known_length(x, h, winch.paid_out_m), w)
        assert ends.anchor_n == pytest.approx(t_a, rel=1e-7)  # the winch's set-point
        up = ends.on_anchor_vertical_n / ends.anchor_n
        assert direction[2] == pytest.approx(-up, abs=1e-7)
    assert force == pytest.approx(expected, rel=1e-7, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(
    st.tuples(st.floats(-20.0, 20.0), st.floats(-20.0, 20.0), st.floats(-20.0, 5.0)).filter(
        lambda p: math.dist(p, (0.0, 0.0, 0.0)) > 0.1
    ),
    tensions,
)
def test_a_weightless_cable_is_the_papers_straight_line(
    position: tuple[float, float, float], tension: float
) -> None:
    straight = ConstantTensionCable(tension).force_on_drone_ned_n(position, (0, 0, 0))
    light = WinchCatenaryCable(tension, 1e-13, G).force_on_drone_ned_n(position, (0, 0, 0))
    assert light == pytest.approx(straight, abs=1e-9)
    exact = WinchCatenaryCable(tension, 0.0, G)
    assert exact.force_on_drone_ned_n(position, (0, 0, 0)) == pytest.approx(straight, abs=1e-12)
    assert exact.paid_out_m == pytest.approx(math.dist(position, (0, 0, 0)), rel=1e-12)


def test_the_lowest_point_reaches_the_ground_exactly_at_the_touchdown_span() -> None:
    w, t_a, h = 0.1 * G, 1.0, 3.0
    a = t_a / w
    touchdown_span = a * math.acosh(1.0 + h / a)  # the rising curve from its lowest point
    before = winch_catenary(touchdown_span * (1 - 1e-9), h, t_a, w)
    after = winch_catenary(touchdown_span * (1 + 1e-9), h, t_a, w)
    assert before.on_ground_m == 0.0 and before.anchor_elevation_rad > 0.0
    assert after.on_ground_m > 0.0 and after.anchor_elevation_rad == 0.0
    for field in ("pull_n", "down_n", "paid_out_m"):
        assert getattr(before, field) == pytest.approx(getattr(after, field), rel=1e-6)
    far = winch_catenary(touchdown_span + 2.0, h, t_a, w)
    assert far.pull_n == t_a and far.on_ground_m == pytest.approx(2.0)
    assert far.paid_out_m == pytest.approx(after.paid_out_m + 2.0, rel=1e-6)


def test_a_slack_winch_leaves_the_drone_only_the_hanging_cable() -> None:
    """T_a -> 0: the cable rests on the ground up to below the drone and hangs straight up."""
    w = 0.1 * G
    for t_a in (0.0, 1e-9):
        cable = winch_catenary(4.0, 3.0, t_a, w)
        assert cable.pull_n == pytest.approx(t_a, abs=1e-12)
        assert cable.down_n == pytest.approx(w * 3.0, rel=1e-4)
        assert cable.paid_out_m == pytest.approx(7.0, rel=1e-4)
        assert cable.on_ground_m == pytest.approx(4.0, rel=1e-4)


def test_vertical_below_and_at_the_anchor() -> None:
    w = 0.05 * G
    up = winch_catenary(0.0, 3.0, 2.0, w)
    assert (up.pull_n, up.down_n, up.paid_out_m) == (0.0, 2.0 + 3.0 * w, 3.0)
    cable = WinchCatenaryCable(2.0, 0.05, G)
    assert cable.force_components(0.0, 0.0, -3.0, 0, 0, 0) == (0.0, 0.0, 2.0 + 3.0 * w)
    assert anchor_direction_ned(cable, (0.0, 0.0, -3.0)) == pytest.approx((0.0, 0.0, -1.0))
    # at or below the anchor's level: the straight line at T_a
    for position in ((3.0, 4.0, 0.0), (3.0, 0.0, 1.0)):
        straight = ConstantTensionCable(2.0).force_on_drone_ned_n(position, (0, 0, 0))
        assert cable.force_on_drone_ned_n(position, (0, 0, 0)) == pytest.approx(straight)
        assert cable.tension_n == 2.0
    assert cable.force_components(0.0, 0.0, 0.0, 0, 0, 0) == (0.0, 0.0, 0.0)
    assert cable.tension_n == 0.0


def test_set_point_release_and_bad_input() -> None:
    cable = make_cable(
        CableConfig(model="winch_catenary", tension_n=3.0, linear_density_kg_per_m=0.1)
    )
    assert isinstance(cable, WinchCatenaryCable)
    before = cable.force_on_drone_ned_n((5.0, 0.0, -3.0), (0, 0, 0))
    cable.set_tension_n(6.0)
    after = cable.force_on_drone_ned_n((5.0, 0.0, -3.0), (0, 0, 0))
    assert cable.tension_n == pytest.approx(6.0 + 0.1 * G * 3.0)
    assert -after[0] > -before[0] + 2.5
    cable.set_winch_rate_mps(1.0)
    cable.advance(1.0)  # the winch pays out what the tension needs, not a rate
    assert cable.paid_out_m == pytest.approx(winch_catenary(5.0, 3.0, 6.0, 0.1 * G).paid_out_m)
    cable.release()
    assert cable.force_components(5.0, 0.0, -3.0, 0, 0, 0) == (0.0, 0.0, 0.0)
    assert cable.tension_n == 0.0
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match=">= 0"):
            cable.set_tension_n(bad)
    with pytest.raises(ValueError, match=">= 0"):
        WinchCatenaryCable(3.0, -0.1, G)
    for args in ((math.nan, 3.0, 1.0, 1.0), (4.0, math.inf, 1.0, 1.0), (4.0, 3.0, 1.0, math.nan)):
        with pytest.raises(ValueError, match="finite"):
            winch_catenary(*args)
    for args in ((-4.0, 3.0, 1.0, 1.0), (4.0, 3.0, -1.0, 1.0), (4.0, 3.0, 1.0, -1.0)):
        with pytest.raises(ValueError, match=">= 0"):
            winch_catenary(*args)


def test_the_winch_encoder_reads_the_paid_out_length() -> None:
    """Off, the drum encoder reports the winch's paid-out length (arc plus ground part)."""
    cable = WinchCatenaryCable(1.0, 0.1, G)
    sensors = GroundSensors(GroundSensorConfig(), "winch_catenary", seed=3)
    lengths = []
    for i, north in enumerate(np.linspace(1.0, 7.0, 13)):
        position = (float(north), 0.0, -3.0)
        cable.force_on_drone_ned_n(position, (0, 0, 0))
        readings = sensors.read(i * 0.005, cable, position, cable.tension_n)
        assert readings.paid_out_m == cable.paid_out_m
        lengths.append(readings.paid_out_m)
    assert np.all(np.diff(lengths) > 0.0)  # paid out as the drone flies away
    assert lengths[-1] == pytest.approx(winch_catenary(7.0, 3.0, 1.0, 0.1 * G).paid_out_m)


def test_the_winch_load_cell_reads_the_set_point() -> None:
    """The load cell at the winch reads T_a (the drone's T_a + w h less w h): exact when the
    sensors' errors are off, with its white noise when on (own generator: the length and the
    angle are the same with or without it)."""
    rho, t_a = 0.1, 2.0
    w = rho * G
    position = (5.0, 0.0, -3.0)
    cable = WinchCatenaryCable(t_a, rho, G)
    cable.force_on_drone_ned_n(position, (0, 0, 0))
    exact = GroundSensors(GroundSensorConfig(), "winch_catenary", 1, w)
    assert exact.read(0.0, cable, position, cable.tension_n).winch_tension_n == pytest.approx(t_a)
    assert tension_at_drone_n(t_a, w, 3.0) == pytest.approx(cable.tension_n)
    assert tension_at_drone_n(t_a, 0.0, math.nan) == t_a
    assert math.isnan(tension_at_drone_n(t_a, w, math.nan))
    on = GroundSensorConfig(enabled=True, winch_tension_noise_std_n=0.2, winch_latency_s=0.0)
    sensors = GroundSensors(on, "winch_catenary", 1, w)
    readings = [sensors.read(i * 0.005, cable, position, cable.tension_n) for i in range(20000)]
    tensions = np.array([r.winch_tension_n for r in readings if r.winch_tension_n is not None])
    assert len(tensions) == sum(r.paid_out_m is not None for r in readings) > 900
    assert np.mean(tensions) == pytest.approx(t_a, abs=0.03)
    assert np.std(tensions) == pytest.approx(0.2, rel=0.1)
