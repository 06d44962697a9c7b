"""The start's velocity standard error over held readings (circle22): the window fit's per-tick
positions hold the latest rangefinder height, so its slope's noise is that of ~20 readings,
not of ~200 independent ticks (realistic-circle seed 42: the fit's vertical velocity 1.5 m/s
off at a stated 0.40 m/s)."""

from __future__ import annotations

import numpy as np

from tether_companion.estimation.dynamic.start_angle import held_slope_se, quadratic_fit

TICKS = 200
HELD = 10  # 200 Hz ticks per 20 Hz reading
NOISE_M = 0.25


def _window() -> tuple[np.ndarray, np.ndarray]:
    times = np.arange(TICKS) * 0.005 - (TICKS - 1) * 0.005  # the last tick at 0
    readings = np.arange(TICKS) // HELD
    return times, readings


def test_held_slope_se_matches_the_monte_carlo_spread_of_the_slope() -> None:
    times, readings = _window()
    rng = np.random.default_rng(7)
    truth = np.stack((0.3 * times, -0.13 * times, 2.0 + 0.0 * times), axis=1)
    slopes, predicted = [], []
    for _ in range(1500):
        noise = rng.normal(0.0, NOISE_M, (readings.max() + 1, 3))[readings]
        _, slope, slope_se, _ = quadratic_fit(times, truth + noise)
        slopes.append(slope - (0.3, -0.13, 0.0))
        predicted.append(held_slope_se(times, readings, slope_se))
    spread = np.std(np.array(slopes), axis=0)
    typical = np.sqrt(np.mean(np.array(predicted) ** 2, axis=0))
    np.testing.assert_allclose(typical, spread, rtol=0.12)


def test_one_reading_per_tick_leaves_the_standard_error_as_it_is() -> None:
    times, _ = _window()
    se = np.array((0.1, 0.2, 0.3))
    np.testing.assert_allclose(held_slope_se(times, np.arange(TICKS), se), se, rtol=1e-12)


def test_held_readings_widen_the_slope_about_the_square_root_of_the_hold() -> None:
    times, readings = _window()
    ratio = held_slope_se(times, readings, np.ones(3))[0]
    assert 2.5 < ratio < 3.6  # sqrt(10) = 3.16 for white noise held 10 ticks
