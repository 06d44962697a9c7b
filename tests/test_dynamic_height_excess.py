"""The rangefinder innovations' excess in the published covariance: without a winch length the
filter's range is its height carried along the cable's direction, so a height error the
innovations show moves the drone along the line from the anchor (issue 10: never published
beyond 3 sigma of its own covariance; the realistic 0.5 N circle with the angle alone, tuning
seed 2, published 0.75 m short of the range at 0.22 m with the height 0.5 m off)."""

from __future__ import annotations

import math

import numpy as np
from status_settings import NO_DRAG_RULE as SETTINGS

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.mixture import MixtureValues, ProcessNoise
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.position_information import height_excess
from tether_companion.estimation.dynamic.published import TickSource

POSITION = (1.75, 0.0, -1.25)
"""The 0.5 N circle's estimate at 11.5 s (tuning seed 2): the truth was (2.5, 0, -1.77), on
the same line from the anchor (the cable angle's elevation held it; the height did not)."""


def _upper(m: np.ndarray) -> tuple[float, ...]:
    return (m[0, 0], m[0, 1], m[0, 2], m[1, 1], m[1, 2], m[2, 2])


def _published(excess_m2: float, winch: bool) -> np.ndarray:
    x = np.zeros(state.N_STATES)
    x[:3] = POSITION
    x[state.TENSION] = 0.5
    x[state.SCALE] = 1.0
    p = np.eye(state.N_STATES) * 0.06**2
    constants = ModelConstants(1.5, 0.3, 0.0)
    noise = ProcessNoise(np.eye(state.N_STATES) * 1e-6)
    source = TickSource(MixtureValues(x, p), None, noise, constants, SETTINGS, excess_m2,
                        winch, 0.0, None, 1, None, None, False, False)  # fmt: skip
    return source.values().covariance


def test_a_height_error_without_a_length_moves_the_drone_along_the_line_from_the_anchor() -> None:
    n, e, d = POSITION
    v = 0.36**2
    term = np.array(height_excess(POSITION, v, range_held=False))
    # a height error dd moves the drone by p dd / d: the covariance of that
    u = np.array(POSITION) / d
    assert np.allclose(term, _upper(v * np.outer(u, u)))
    assert math.isclose(term[5], v)  # the height's own variance
    # the truth (2.5, 0, -1.77) is within 3 sigma along the range; it was not with the
    # height's variance on the down axis alone (0.06 m own, 0.36 m excess)
    along_sd = math.sqrt(0.06**2 + term[0])
    assert abs(2.5 - n) < 3.0 * along_sd
    assert abs(2.5 - n) > 3.0 * 0.06


def test_a_fused_length_holds_the_range() -> None:
    v = 0.1
    assert height_excess(POSITION, v, range_held=True) == (0.0, 0.0, 0.0, 0.0, 0.0, v)
    assert height_excess(POSITION, 0.0, range_held=False) == (0.0,) * 6


def test_a_cable_near_the_horizontal_is_capped_at_ten_times() -> None:
    term = height_excess((5.0, 0.0, -0.01), 1.0, range_held=False)
    assert math.isclose(term[0], (5.0 / (0.1 * math.hypot(5.0, 0.01))) ** 2)
    assert term[5] == 1.0 and all(math.isfinite(t) for t in term)


def test_the_published_covariance_carries_it() -> None:
    v = 0.36**2
    none = _published(0.0, winch=False)
    without = _published(v, winch=False)
    ratio = POSITION[0] / POSITION[2]
    # along the range (north here) the height's error times rho / |d| = 1.4, down itself
    assert math.isclose(without[0, 0] - none[0, 0], v * ratio * ratio, rel_tol=1e-9)
    assert math.isclose(without[2, 2] - none[2, 2], v, rel_tol=1e-9)
    assert without[0, 2] - none[0, 2] < 0.0  # farther out is higher up (down negative)
    # with the winch's length the range is held: down only
    length_none = _published(0.0, winch=True)
    length = _published(v, winch=True)
    assert math.isclose(length[0, 0], length_none[0, 0], rel_tol=1e-12)
    assert math.isclose(length[2, 2] - length_none[2, 2], v, rel_tol=1e-9)
