"""Scoring of the SITL flights (pure functions; no SITL needed)."""

from __future__ import annotations

import math

import numpy as np

from tether_companion.ardupilot_sitl.scoring import (
    TRACE_COLUMNS,
    score_phase,
    settle_time,
    trace_of,
)
from tether_companion.ardupilot_sitl.telemetry import EKF_FLAG_POS_HORIZ_ABS, Sample


def _sample(
    t: float, truth, ekf3=None, ours=None, ratio=0.1, flags=EKF_FLAG_POS_HORIZ_ABS, age=0.02
):
    truth = np.asarray(truth, dtype=float)
    return Sample(
        wall_s=t,
        fc_s=t,
        truth_ned_m=truth,
        fc_ned_m=truth if ekf3 is None else np.asarray(ekf3, dtype=float),
        vision_ned_m=np.full(3, np.nan) if ours is None else np.asarray(ours, dtype=float),
        vision_age_s=math.nan if ours is None else age,
        ekf_pos_ratio=ratio,
        ekf_flags=flags,
        mode=4,
        armed=True,
    )


def test_score_phase_measures_each_error_horizontally() -> None:
    target = np.array([6.0, 0.0, -4.0])
    samples = [
        _sample(0.0, [6.3, 0.4, -4.0], ekf3=[6.0, 0.0, -4.0], ours=[6.0, 0.0, -3.0], ratio=0.2),
        _sample(1.0, [6.0, 0.0, -4.0], ekf3=[6.0, 0.0, -4.0], ours=[6.0, 0.0, -4.0], ratio=0.4,
                flags=0),
    ]  # fmt: skip
    score = score_phase("hold", samples, lambda _t, _p: target)
    assert score.samples == 2 and score.duration_s == 1.0
    assert math.isclose(score.truth_to_target_max_m, 0.5)
    assert math.isclose(score.truth_to_target_rms_m, math.sqrt(0.25 / 2))
    assert math.isclose(score.ekf3_error_max_m, 0.5)
    assert math.isclose(score.ours_error_max_m, 0.5)  # horizontal only: the 1 m height is not
    assert math.isclose(score.ours_error_3d_rms_m, math.sqrt((0.25 + 1.0) / 2))
    assert math.isclose(score.test_ratio_max, 0.4) and math.isclose(score.test_ratio_mean, 0.3)
    assert score.position_lost_samples == 1


def test_score_phase_without_our_estimate_is_nan_not_zero() -> None:
    score = score_phase("boot", [_sample(0.0, [0, 0, 0])], lambda _t, p: p)
    assert math.isnan(score.ours_error_rms_m) and score.truth_to_target_max_m == 0.0
    empty = score_phase("none", [], lambda _t, p: p)
    assert empty.samples == 0 and math.isnan(empty.truth_to_target_max_m)


def test_a_stale_estimate_is_counted_not_scored() -> None:
    """While the service withholds, the autopilot's last VISION_POSITION_ESTIMATE stands still
    and the drone flies on: that is no error of an estimate of now."""
    samples = [
        _sample(0.0, [6.0, 0.0, -4.0], ours=[6.1, 0.0, -4.0]),
        _sample(1.0, [6.0, 1.0, -4.0], ours=[6.1, 0.0, -4.0], age=1.0),
    ]
    score = score_phase("circle", samples, lambda _t, p: p)
    assert math.isclose(score.ours_error_max_m, 0.1)
    assert score.ours_stale_samples == 1
    fresh = score_phase("circle", samples[:1], lambda _t, p: p)
    assert fresh.ours_stale_samples == 0


def test_settle_time_is_the_last_excursion_after_the_switch() -> None:
    target = np.zeros(3)
    track = [0.5, 0.4, 0.1, 0.35, 0.1, 0.05, 0.0]
    samples = [_sample(10.0 + i, [x, 0.0, 0.0]) for i, x in enumerate(track)]
    assert settle_time(samples, target, 10.0) == 3.0
    assert settle_time(samples[4:], target, 10.0) == 0.0
    assert math.isnan(settle_time([*samples, _sample(20.0, [1.0, 0, 0])], target, 10.0))


def test_trace_has_one_row_per_sample() -> None:
    trace = trace_of([_sample(0.0, [1, 2, 3], ours=[1, 2, 2])])
    assert trace.shape == (1, len(TRACE_COLUMNS))
    assert trace[0, TRACE_COLUMNS.index("ours_d")] == 2.0
