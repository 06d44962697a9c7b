"""The bearing window (estimation/dynamic/consistency.py): a steady hover does not tell the
bearing from a cross wind, a circle does; the published covariance is widened only in the
first case."""

from __future__ import annotations

import math

from tether_companion.estimation.dynamic.consistency import BearingWindow

DRAG = 0.3  # m mu of the realistic quad [N s/m]
WIND_STD = 2.0  # m/s
BASE = 0.2  # N


def _window(**kwargs: float) -> BearingWindow:
    settings = dict(
        drag_n_s_per_m=DRAG,
        wind_std_mps=WIND_STD,
        force_std_n=BASE,
        correlation_s=1.0,
        position_walk_m2ps=0.1,
        wind_walk_m2ps3=0.2,
    )
    settings.update(kwargs)
    return BearingWindow(**settings)  # type: ignore[arg-type]


def _across_std_m(window: BearingWindow, distance_m: float, tension_n: float) -> float:
    """The across-cable standard deviation the published term then holds [m]."""
    return distance_m * window.force_std_n / tension_n


def _fly(window: BearingWindow, positions, tension_n: float, duration_s: float, var: float):
    t = 0.0
    while t <= duration_s:
        window.add(t, positions(t), tension_n, (var, 0.0, var))
        t += 0.02


def test_a_steady_hover_keeps_the_bearing_as_unknown_as_the_cross_wind() -> None:
    """4 m out, 2.5 m up, 4 N: the filter claims 0.2 m; the window's across-cable standard
    deviation is at least what the wind prior's drag turns the cable by (m mu sigma_w / k,
    k = T / |p|), and it grows with the wind's random walk."""
    window = _window()
    hover = [4.0, 0.0, -2.5]
    distance = math.dist(hover, (0.0, 0.0, 0.0))
    _fly(window, lambda t: hover, 4.0, 30.0, 0.04)
    prior_bound = DRAG * WIND_STD / (4.0 / distance)
    assert _across_std_m(window, distance, 4.0) >= prior_bound
    assert window.force_std_n > BASE


def test_a_circle_tells_the_wind_and_adds_nothing() -> None:
    """The same pull on a 4 m circle at 1 m/s: the bearing turns, the wind is told apart, and
    the across-cable standard deviation stays within the 0.5 m the position is published at
    (half the hover's at most)."""
    window = _window()
    radius, speed = 4.0, 1.0

    def circle(t: float) -> list[float]:
        angle = speed * t / radius
        return [radius * math.cos(angle), radius * math.sin(angle), -2.5]

    _fly(window, circle, 4.0, 30.0, 0.04)
    distance = math.hypot(radius, 2.5)
    assert _across_std_m(window, distance, 4.0) < 0.4
    hover = _window()
    _fly(hover, lambda t: [4.0, 0.0, -2.5], 4.0, 30.0, 0.04)
    assert window.force_std_n < hover.force_std_n / 2.0


def test_off_without_drag_or_walk_and_forgotten_on_clear() -> None:
    hover = [4.0, 0.0, -2.5]
    for off in (_window(drag_n_s_per_m=0.0), _window(position_walk_m2ps=0.0)):
        assert not off.enabled
        _fly(off, lambda t: hover, 4.0, 10.0, 0.04)
        assert off.force_std_n == BASE
    window = _window()
    _fly(window, lambda t: hover, 4.0, 10.0, 0.04)
    assert window.force_std_n > BASE
    window.clear()
    assert window.force_std_n == BASE


def test_a_cable_angle_tells_the_bearing_in_a_hover() -> None:
    """With a ground-station azimuth (0.02 rad at 4 m: 0.08 m across the cable, 10 Hz) the
    hover's bearing is measured: the window adds nothing to the filter's 0.2 m."""
    window = _window()
    hover = [4.0, 0.0, -2.5]
    t = 0.0
    while t <= 30.0:
        window.add(t, hover, 4.0, (0.04, 0.0, 0.04))
        if round(t / 0.02) % 5 == 0:
            window.add_bearing(4.0 * 0.02)
        t += 0.02
    assert window.force_std_n == BASE


def test_a_hovers_bearing_starts_unknown_whatever_the_filter_claims() -> None:
    """The window's first sample takes the filter's range but not its bearing: in the first
    seconds of a hover (the thrust-scale bank's hypotheses collapsing, the filter claiming
    0.2 m) the across-cable standard deviation is at least the wind prior's turn of the cable
    (the winch alone on the realistic gusty hover published 1.2-1.4 s after taut, the
    window then adding nothing)."""
    hover = [4.0, 0.0, -2.5]
    distance = math.dist(hover, (0.0, 0.0, 0.0))
    prior_bound = DRAG * WIND_STD / (4.0 / distance)
    for seconds in (0.3, 1.5, 3.0):
        window = _window()
        _fly(window, lambda t: hover, 4.0, seconds, 0.04)
        assert _across_std_m(window, distance, 4.0) >= prior_bound


def test_the_floor_applies_at_once_when_the_filter_narrows_between_samples() -> None:
    """The thrust-scale bank's collapse narrows the filter's covariance between two of the
    window's samples (the realistic gusty hover with the winch, seed 42: 0.68 -> 0.46 m across
    at 7.1 s, 1.7 m off): the window's floor applies to the narrowed covariance at once."""
    hover = [4.0, 0.0, -2.5]
    distance = math.dist(hover, (0.0, 0.0, 0.0))
    window = _window()
    _fly(window, lambda t: hover, 4.0, 6.0, 1.0)  # a wide mixture: nothing missing
    wide = window.force_std_n
    window.add(6.01, hover, 4.0, (0.04, 0.0, 0.04))  # within the sample interval
    assert window.force_std_n > wide
    assert _across_std_m(window, distance, 4.0) >= DRAG * WIND_STD / (4.0 / distance)


def test_while_the_thrust_scale_is_unknown_in_a_hover_the_force_tells_nothing() -> None:
    """While several thrust-scale hypotheses run in a hover (``pull_known`` False) the window
    keeps the bearing's prior (a radian at the range) whatever the samples; a cable angle
    still measures it."""
    hover = [4.0, 0.0, -2.5]
    distance = math.dist(hover, (0.0, 0.0, 0.0))
    window = _window()
    t = 0.0
    while t <= 5.0:
        window.add(t, hover, 4.0, (0.04, 0.0, 0.04), pull_known=False)
        t += 0.02
    assert _across_std_m(window, distance, 4.0) >= 4.0  # BEARING_PRIOR_RAD x 4 m
    window.add_bearing(4.0 * 0.02)
    window.add(t, hover, 4.0, (0.04, 0.0, 0.04), pull_known=False)
    assert window.force_std_n == BASE


def test_the_floor_starts_at_the_second_sample() -> None:
    """Its first sample adds nothing (a cable angle tells the bearing within the sample
    interval; the prior's floor in those 0.07 s held the take-off figure-8's angle alone back
    from 1.5 to 2.9 s after taut, tuning seed 1); from the second it holds the prior."""
    hover = [4.0, 0.0, -2.5]
    window = _window()
    window.add(0.0, hover, 4.0, (0.04, 0.0, 0.04), pull_known=False)
    window.add(0.1, hover, 4.0, (0.04, 0.0, 0.04), pull_known=False)
    assert window.force_std_n == BASE
    window.add(0.3, hover, 4.0, (0.04, 0.0, 0.04), pull_known=False)
    assert window.force_std_n > BASE
