"""Scoring of the ArduPilot SITL flights: per-phase errors of the truth against its target,
of EKF3 and of our estimate against the truth, the settle time and the trace (pure functions
of the ground station's samples; no SITL needed)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from tether_companion.ardupilot_sitl.telemetry import EKF_FLAG_POS_HORIZ_ABS, Sample

TRACE_COLUMNS = (
    "fc_s", "truth_n", "truth_e", "truth_d", "ekf3_n", "ekf3_e", "ekf3_d",
    "ours_n", "ours_e", "ours_d", "test_ratio", "mode", "yaw_error_rad", "ours_age_s",
)  # fmt: skip
SETTLE_BAND_M = 0.3
"""Horizontal distance from the target inside which the hold counts as settled [m]."""
FRESH_ESTIMATE_S = 0.3
"""Our estimate is scored against the truth only while the last VISION_POSITION_ESTIMATE is at
most this old (autopilot time; the service sends at 30 Hz while it publishes): a withheld
stretch leaves the last one standing, and the drone flies on from it [s]."""


@dataclass
class PhaseScore:
    """Errors over one phase [m] (horizontal unless named 3-D), from SIM_STATE samples."""

    name: str
    duration_s: float
    samples: int
    truth_to_target_max_m: float
    truth_to_target_rms_m: float
    ekf3_error_rms_m: float
    ekf3_error_max_m: float
    ours_error_rms_m: float
    ours_error_max_m: float
    ours_error_3d_rms_m: float
    test_ratio_mean: float
    test_ratio_max: float
    position_lost_samples: int
    """Samples whose EKF_STATUS_REPORT lacked 'horizontal absolute position OK'."""
    ours_stale_samples: int = 0
    """Samples with no estimate of ours at most FRESH_ESTIMATE_S old (withheld, or none yet):
    left out of the ``ours_*`` errors."""
    yaw_error_max_deg: float = math.nan
    """Largest |ATTITUDE yaw - SIM_STATE yaw| [deg]: the heading our estimate is rotated by."""


@dataclass
class FlightResult:
    """A flight's scores and what the autopilot said."""

    name: str
    phases: list[PhaseScore] = field(default_factory=list)
    settle_s: float = math.nan
    """Autopilot seconds after the source switch until the truth stays within SETTLE_BAND_M."""
    failsafes: list[str] = field(default_factory=list)
    autopilot_texts: list[str] = field(default_factory=list)
    companion_texts: list[str] = field(default_factory=list)
    completed: bool = False
    stopped_at: str = ""
    """Why the flight stopped early ('' when it completed)."""
    companion_exit: int | None = None
    trace: np.ndarray = field(default_factory=lambda: np.empty((0, len(TRACE_COLUMNS))))
    """Every SIM_STATE sample: autopilot time [s], truth NED, EKF3 NED, ours NED [m], EKF3's
    horizontal position test ratio, mode, EKF3's yaw error [rad] (TRACE_COLUMNS)."""

    def phase(self, name: str) -> PhaseScore:
        """The phase called ``name``."""
        for phase in self.phases:
            if phase.name == name:
                return phase
        raise KeyError(name)


def _horizontal(v: np.ndarray) -> np.ndarray:
    return np.linalg.norm(v[..., :2], axis=-1)


def score_phase(
    name: str, samples: list[Sample], target: Callable[[float, np.ndarray], np.ndarray]
) -> PhaseScore:
    """Score ``samples`` against ``target(fc_time_s, truth_ned_m) -> NED [m]`` (the point
    the drone should be at: fixed for a hold, the nearest point of the path for a circle)."""
    if not samples:
        nan = math.nan
        return PhaseScore(name, 0.0, 0, nan, nan, nan, nan, nan, nan, nan, nan, nan, 0)
    truth = np.array([s.truth_ned_m for s in samples])
    goal = np.array([target(s.fc_s, s.truth_ned_m) for s in samples])
    ekf3 = np.array([s.fc_ned_m for s in samples])
    ours = np.array([s.vision_ned_m for s in samples])
    ages = np.array([s.vision_age_s for s in samples])
    ratio = np.array([s.ekf_pos_ratio for s in samples])
    to_target = _horizontal(truth - goal)
    ekf3_err = _horizontal(ekf3 - truth)
    ours_err = _horizontal(ours - truth)
    ours_3d = np.linalg.norm(ours - truth, axis=1)
    finite = np.isfinite(ours_err) & (ages <= FRESH_ESTIMATE_S)
    return PhaseScore(
        name=name,
        duration_s=samples[-1].fc_s - samples[0].fc_s,
        samples=len(samples),
        truth_to_target_max_m=float(np.max(to_target)),
        truth_to_target_rms_m=_rms(to_target),
        ekf3_error_rms_m=_rms(ekf3_err),
        ekf3_error_max_m=float(np.nanmax(ekf3_err)),
        ours_error_rms_m=_rms(ours_err[finite]) if finite.any() else math.nan,
        ours_error_max_m=float(np.max(ours_err[finite])) if finite.any() else math.nan,
        ours_error_3d_rms_m=_rms(ours_3d[finite]) if finite.any() else math.nan,
        test_ratio_mean=float(np.nanmean(ratio)) if np.isfinite(ratio).any() else math.nan,
        test_ratio_max=float(np.nanmax(ratio)) if np.isfinite(ratio).any() else math.nan,
        position_lost_samples=sum(not (s.ekf_flags & EKF_FLAG_POS_HORIZ_ABS) for s in samples),
        yaw_error_max_deg=_max_abs_deg([s.yaw_error_rad for s in samples]),
        ours_stale_samples=int(np.count_nonzero(~finite)),
    )


def _max_abs_deg(values: list[float]) -> float:
    finite = np.abs(np.array(values, dtype=float))
    finite = finite[np.isfinite(finite)]
    return float(np.degrees(finite.max())) if finite.size else math.nan


def trace_of(samples: list[Sample]) -> np.ndarray:
    """The samples as an array with TRACE_COLUMNS."""
    rows = [
        [
            s.fc_s,
            *s.truth_ned_m,
            *s.fc_ned_m,
            *s.vision_ned_m,
            s.ekf_pos_ratio,
            s.mode,
            s.yaw_error_rad,
            s.vision_age_s,
        ]
        for s in samples
    ]
    return np.array(rows, dtype=float).reshape(-1, len(TRACE_COLUMNS))


def _rms(values: np.ndarray) -> float:
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def settle_time(samples: list[Sample], target: np.ndarray, start_fc_s: float) -> float:
    """Autopilot seconds from ``start_fc_s`` until the truth stays within SETTLE_BAND_M of
    ``target`` horizontally for the rest of ``samples`` (nan if it never does)."""
    if not samples:
        return math.nan
    outside = [s.fc_s for s in samples if _horizontal(s.truth_ned_m - target) > SETTLE_BAND_M]
    if not outside:
        return 0.0
    if outside[-1] >= samples[-1].fc_s:
        return math.nan
    return max(0.0, outside[-1] - start_fc_s)
