"""A tick the pull rule withholds carries the bearing's ambiguity in its published covariance
(estimation/dynamic/bearing_ambiguity.py; issue 10: the covariance grows to say what the data
cannot tell; the realistic 0.5 N circle with the winch's length, tuning seeds 1-3, had NEES
6, 88 and 456 while withheld)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bearing_ambiguity import bearing_ambiguity
from tether_companion.estimation.dynamic.mixture import MixtureValues, ProcessNoise
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.estimation.dynamic.output import OK, WEAK_PULL
from tether_companion.estimation.dynamic.published import StatusSettings, TickSource

DRAG_PER_WIND = 0.3
"""``m mu`` of the realistic quad [N s/m] (1.5 kg, 0.2 /s)."""
SETTINGS = StatusSettings(
    slack_tension_n=0.2,
    max_horizontal_std_m=0.5,
    winch_length_noise_std_m=0.05,
    pull_per_wind_n_s_per_m=4.0 * DRAG_PER_WIND,
    wind_std_mps=2.0,
    drag_per_wind_n_s_per_m=DRAG_PER_WIND,
)


NO_TERM = dataclasses.replace(SETTINGS, drag_per_wind_n_s_per_m=0.0)


def test_the_ring_moments_are_the_wrapped_bearing_errors() -> None:
    rng = np.random.default_rng(3)
    rho, pull, drag = 2.5, 0.5, 0.6
    nn, ne, ee = bearing_ambiguity(rho, 0.0, pull, drag)
    theta = rng.normal(scale=drag / pull, size=200_000)
    along, across = rho * (np.cos(theta) - 1.0), rho * np.sin(theta)
    assert math.isclose(nn, float(np.mean(along**2)), rel_tol=0.02)
    assert math.isclose(ee, float(np.mean(across**2)), rel_tol=0.02)
    assert ne == 0.0
    # small angles: across rho s, along nothing to first order
    nn, _, ee = bearing_ambiguity(0.0, rho, 100.0, 1.0)
    assert math.isclose(nn, (rho * 0.01) ** 2, rel_tol=1e-3) and ee < 1e-7
    # no pull: the whole circle (the drone may be on the far side, 2 rho off)
    nn, _, ee = bearing_ambiguity(rho, 0.0, 0.0, drag)
    assert math.isclose(nn, 1.5 * rho * rho) and math.isclose(ee, 0.5 * rho * rho)
    assert bearing_ambiguity(0.0, 0.0, 1.0, 1.0) == (0.0, 0.0, 0.0)
    assert bearing_ambiguity(rho, 0.0, 1.0, 0.0) == (0.0, 0.0, 0.0)


def _tick(tension_n: float, settings: StatusSettings = SETTINGS) -> TickSource:
    """The 0.5 N circle with the winch's length, tuning seed 1 at 9 s: the filter 2.5 m out,
    2 m up, own horizontal sd 0.13 m, a wind estimate of (0.8, 0.6) m/s."""
    x = np.zeros(state.N_STATES)
    x[:3] = (2.5, 0.0, -2.0)
    x[state.TENSION] = tension_n
    x[state.SCALE] = 1.0
    x[state.WIND] = (0.8, 0.6)
    p = np.eye(state.N_STATES) * 0.13**2
    constants = ModelConstants(1.5, 0.2, 0.0)
    noise = ProcessNoise(np.eye(state.N_STATES) * 1e-6)
    return TickSource(MixtureValues(x, p), None, noise, constants, settings, 0.0, True,
                      0.0, None, 1, None, None, False, False)  # fmt: skip


def test_a_tick_withheld_for_its_weak_pull_says_the_bearing_is_unknown() -> None:
    weak = _tick(1.62)
    assert weak.status() == WEAK_PULL
    covariance = weak.values().covariance
    # the truth was 0.87 m short along the range and 1.49 m across it
    along, across = 0.87, 1.49
    assert along < 3.0 * math.sqrt(covariance[0, 0])
    assert across < 3.0 * math.sqrt(covariance[1, 1])
    # the same tick without the term: 0.13 m, the truth 11 sigma across
    bare = _tick(1.62, NO_TERM).values().covariance
    assert across > 3.0 * math.sqrt(bare[1, 1])


def test_a_tick_the_pull_fixes_keeps_its_covariance() -> None:
    strong = _tick(40.0)
    without = _tick(40.0, NO_TERM)
    assert strong.status() == OK
    assert np.array_equal(strong.values().covariance, without.values().covariance)
