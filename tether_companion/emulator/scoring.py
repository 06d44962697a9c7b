"""Scoring the position estimates a companion sends against the simulator's truth.

Each VISION_POSITION_ESTIMATE or ODOMETRY is matched to the true position at the time it is
stamped with (flight-controller time, linearly interpolated between physics steps), which is
the error that matters to the autopilot's EKF: it fuses the measurement at its timestamp.
The report gives RMSE per axis (NED), horizontal and 3-D, the count, the rate and the age
(arrival time minus timestamp) of the estimates. When an estimate carries its covariance, its
honesty is scored too: how many were off by more than 3 standard deviations on some axis, and
the mean NEES (``e^T P^-1 e``, 3 on average for an honest 3-D Gaussian). Velocities (ODOMETRY,
VISION_SPEED_ESTIMATE) are scored against the true velocity at their stamp (central difference
of the recorded truth over one physics step) as RMSE per axis and 3-D, and, when they carry a
covariance, as the 3-sigma count and mean NEES of the velocity.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

HISTORY_S = 10.0
"""How far back truth is kept for matching [s]; older estimates count as unmatched."""
FUTURE_TOLERANCE_S = 0.005
"""An estimate stamped later than now by more than this is unmatched (wrong time base)."""


class TruthHistory:
    """A ring buffer of (time, position) of the truth, for interpolation at past times.

    Parameters
    ----------
    dt_s
        Spacing of the records [s] (the physics step).
    history_s
        How much to keep [s].
    """

    def __init__(self, dt_s: float, history_s: float = HISTORY_S) -> None:
        self._n = int(math.ceil(history_s / dt_s)) + 2
        self._t = np.full(self._n, math.nan)
        self._p = np.zeros((self._n, 3))
        self._count = 0

    def clear(self) -> None:
        """Forget all records."""
        self._t[:] = math.nan
        self._count = 0

    def record(self, time_s: float, position_ned_m: tuple[float, float, float]) -> None:
        """Append a record; times must increase."""
        i = self._count % self._n
        self._t[i] = time_s
        self._p[i] = position_ned_m
        self._count += 1

    def at(self, time_s: float) -> FloatArray | None:
        """True position at ``time_s`` [m] (linear interpolation), or None outside the buffer."""
        if self._count == 0:
            return None
        newest = (self._count - 1) % self._n
        oldest = 0 if self._count <= self._n else self._count % self._n
        t_new, t_old = self._t[newest], self._t[oldest]
        if not t_old <= time_s <= t_new:
            return None
        order = np.roll(np.arange(self._n), -oldest)[: min(self._count, self._n)]
        times = self._t[order]
        k = int(np.searchsorted(times, time_s))
        if k == 0:
            return self._p[order[0]].copy()
        t0, t1 = times[k - 1], times[k]
        w = 0.0 if t1 == t0 else (time_s - t0) / (t1 - t0)
        return (1.0 - w) * self._p[order[k - 1]] + w * self._p[order[k]]

    def velocity_at(self, time_s: float) -> FloatArray | None:
        """True velocity at ``time_s`` [m/s], NED: the central difference of the interpolated
        positions one record spacing either side (one side at the ends), or None outside."""
        if self._count < 2:
            return None
        newest = (self._count - 1) % self._n
        spacing = self._t[newest] - self._t[(self._count - 2) % self._n]
        if not spacing > 0.0:
            return None
        after = self.at(time_s + spacing)
        before = self.at(time_s - spacing)
        if after is not None and before is not None:
            return (after - before) / (2.0 * spacing)
        here = self.at(time_s)
        if here is None:
            return None
        if after is not None:
            return (after - here) / spacing
        if before is not None:
            return (here - before) / spacing
        return None


@dataclass
class ScoreReport:
    """Accuracy of the received estimates (SI units; ``nan`` when nothing was scored)."""

    scored: int = 0
    received: dict[str, int] = field(default_factory=dict)
    """Estimates received per message type."""
    invalid: int = 0
    """Non-finite positions."""
    unmatched: int = 0
    """Timestamps outside the truth history (future, or older than 10 s): wrong time base."""
    warmup: int = 0
    """Estimates stamped before ``score_start_s``."""
    rmse_m: dict[str, float] = field(default_factory=dict)
    """RMSE per axis (north, east, down), horizontal and 3-D [m]."""
    max_error_m: float = math.nan
    """Largest 3-D error [m]."""
    rate_hz: float = math.nan
    """Scored estimates per second of emulator time."""
    age_ms: dict[str, float] = field(default_factory=dict)
    """Arrival minus timestamp: mean, p50, p95, max [ms]."""
    with_covariance: int = 0
    """Scored estimates that carried a position covariance."""
    beyond_3_sigma: int = 0
    """Of those, estimates with an axis error beyond 3 standard deviations of their own."""
    nees_mean: float = math.nan
    """Mean normalised estimation error squared of those (3 for an honest filter)."""
    velocity_scored: int = 0
    """Velocities scored (ODOMETRY with a velocity, VISION_SPEED_ESTIMATE)."""
    velocity_rmse_m_s: dict[str, float] = field(default_factory=dict)
    """Velocity RMSE per axis (north, east, down) and 3-D [m/s]."""
    velocity_with_covariance: int = 0
    """Scored velocities that carried a covariance."""
    velocity_beyond_3_sigma: int = 0
    """Of those, velocities with an axis error beyond 3 standard deviations of their own."""
    velocity_nees_mean: float = math.nan
    """Mean NEES of those velocities (3 for an honest filter)."""

    def to_json(self, path: str | Path) -> None:
        """Write the report as JSON (NaN written as null)."""
        Path(path).write_text(
            json.dumps(_nan_to_none(asdict(self)), indent=2) + "\n", encoding="utf-8"
        )

    def format_text(self) -> str:
        """A few human-readable lines."""
        kinds = ", ".join(f"{k} {v}" for k, v in sorted(self.received.items())) or "none"
        lines = [
            f"estimates received: {kinds}; scored {self.scored}, invalid {self.invalid}, "
            f"unmatched {self.unmatched}, warm-up {self.warmup}"
        ]
        if self.scored:
            r = self.rmse_m
            lines.append(
                f"RMSE north {r['north']:.3f} m, east {r['east']:.3f} m, down {r['down']:.3f} m, "
                f"horizontal {r['horizontal']:.3f} m, 3-D {r['3d']:.3f} m "
                f"(max {self.max_error_m:.3f} m)"
            )
            a = self.age_ms
            lines.append(
                f"rate {self.rate_hz:.1f} Hz; age mean {a['mean']:.1f} ms, p50 {a['p50']:.1f} ms, "
                f"p95 {a['p95']:.1f} ms, max {a['max']:.1f} ms"
            )
        if self.with_covariance:
            lines.append(
                f"covariance: {self.beyond_3_sigma} of {self.with_covariance} beyond 3 sigma, "
                f"NEES mean {self.nees_mean:.2f} (3 if honest)"
            )
        if self.velocity_scored:
            v = self.velocity_rmse_m_s
            lines.append(
                f"velocity RMSE north {v['north']:.3f} m/s, east {v['east']:.3f} m/s, "
                f"down {v['down']:.3f} m/s, 3-D {v['3d']:.3f} m/s ({self.velocity_scored} scored)"
            )
        if self.velocity_with_covariance:
            lines.append(
                f"velocity covariance: {self.velocity_beyond_3_sigma} of "
                f"{self.velocity_with_covariance} beyond 3 sigma, NEES mean "
                f"{self.velocity_nees_mean:.2f} (3 if honest)"
            )
        return "\n".join(lines)


def _nan_to_none(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _nan_to_none(v) for k, v in value.items()}
    return value


class Scorer:
    """Accumulates errors of received estimates against a :class:`TruthHistory`.

    Parameters
    ----------
    score_start_s
        Estimates stamped (in simulation time) before this are counted as warm-up only.
    """

    def __init__(self, score_start_s: float = 0.0) -> None:
        self.score_start_s = score_start_s
        self._errors: list[tuple[float, float, float]] = []
        self._ages: list[float] = []
        self._arrivals: list[float] = []
        self._nees: list[float] = []
        self._velocity_errors: list[tuple[float, float, float]] = []
        self._velocity_nees: list[float] = []
        self._report = ScoreReport()

    def add(
        self,
        kind: str,
        position_ned_m: FloatArray,
        stamp_sim_s: float,
        arrival_sim_s: float,
        truth: TruthHistory,
        covariance_m2: FloatArray | None = None,
    ) -> None:
        """Score one estimate stamped at ``stamp_sim_s`` that arrived at ``arrival_sim_s``
        (with its (3, 3) position covariance [m^2] when it carried one)."""
        r = self._report
        r.received[kind] = r.received.get(kind, 0) + 1
        if not (np.all(np.isfinite(position_ned_m)) and math.isfinite(stamp_sim_s)):
            r.invalid += 1
            return
        if stamp_sim_s > arrival_sim_s + FUTURE_TOLERANCE_S:
            r.unmatched += 1
            return
        true_position = truth.at(stamp_sim_s)
        if true_position is None:
            r.unmatched += 1
            return
        if stamp_sim_s < self.score_start_s:
            r.warmup += 1
            return
        error = np.asarray(position_ned_m, dtype=float) - true_position
        self._errors.append((float(error[0]), float(error[1]), float(error[2])))
        self._ages.append(arrival_sim_s - stamp_sim_s)
        self._arrivals.append(arrival_sim_s)
        if covariance_m2 is not None:
            self._score_covariance(error, np.asarray(covariance_m2, dtype=float))

    def _score_covariance(self, error: FloatArray, covariance: FloatArray) -> None:
        nees = _consistency(error, covariance)
        if nees is None:
            return
        r = self._report
        r.with_covariance += 1
        r.beyond_3_sigma += int(nees[0])
        if math.isfinite(nees[1]):
            self._nees.append(nees[1])

    def add_velocity(
        self,
        velocity_ned_m_s: FloatArray,
        stamp_sim_s: float,
        arrival_sim_s: float,
        truth: TruthHistory,
        covariance_m2ps2: FloatArray | None = None,
    ) -> None:
        """Score one velocity [m/s] stamped at ``stamp_sim_s`` (after the warm-up only), with
        its (3, 3) NED covariance [m^2/s^2] when it carried one."""
        v = np.asarray(velocity_ned_m_s, dtype=float)
        if not (np.all(np.isfinite(v)) and math.isfinite(stamp_sim_s)):
            return
        if stamp_sim_s > arrival_sim_s + FUTURE_TOLERANCE_S or stamp_sim_s < self.score_start_s:
            return
        true_velocity = truth.velocity_at(stamp_sim_s)
        if true_velocity is None:
            return
        error = v - true_velocity
        self._velocity_errors.append((float(error[0]), float(error[1]), float(error[2])))
        if covariance_m2ps2 is None:
            return
        nees = _consistency(error, np.asarray(covariance_m2ps2, dtype=float))
        if nees is None:
            return
        r = self._report
        r.velocity_with_covariance += 1
        r.velocity_beyond_3_sigma += int(nees[0])
        if math.isfinite(nees[1]):
            self._velocity_nees.append(nees[1])

    def report(self) -> ScoreReport:
        """The report so far."""
        r = self._report
        r.scored = len(self._errors)
        r.nees_mean = float(np.mean(self._nees)) if self._nees else math.nan
        r.velocity_scored = len(self._velocity_errors)
        r.velocity_nees_mean = (
            float(np.mean(self._velocity_nees)) if self._velocity_nees else math.nan
        )
        if self._velocity_errors:
            ms = np.mean(np.array(self._velocity_errors) ** 2, axis=0)
            r.velocity_rmse_m_s = {
                "north": float(math.sqrt(ms[0])),
                "east": float(math.sqrt(ms[1])),
                "down": float(math.sqrt(ms[2])),
                "3d": float(math.sqrt(ms.sum())),
            }
        if not self._errors:
            r.rmse_m = {k: math.nan for k in ("north", "east", "down", "horizontal", "3d")}
            r.age_ms = {k: math.nan for k in ("mean", "p50", "p95", "max")}
            return r
        errors = np.array(self._errors)
        ms = np.mean(errors**2, axis=0)
        r.rmse_m = {
            "north": float(math.sqrt(ms[0])),
            "east": float(math.sqrt(ms[1])),
            "down": float(math.sqrt(ms[2])),
            "horizontal": float(math.sqrt(ms[0] + ms[1])),
            "3d": float(math.sqrt(ms.sum())),
        }
        r.max_error_m = float(np.max(np.linalg.norm(errors, axis=1)))
        span = self._arrivals[-1] - self._arrivals[0]
        r.rate_hz = (len(self._arrivals) - 1) / span if span > 0 else math.nan
        ages_ms = np.array(self._ages) * 1e3
        r.age_ms = {
            "mean": float(np.mean(ages_ms)),
            "p50": float(np.percentile(ages_ms, 50)),
            "p95": float(np.percentile(ages_ms, 95)),
            "max": float(np.max(ages_ms)),
        }
        return r


def _consistency(error: FloatArray, covariance: FloatArray) -> tuple[bool, float] | None:
    """(some axis beyond 3 sigma, NEES ``e^T P^-1 e``) of one error against its covariance;
    None when the covariance is not finite or has a non-positive variance (not scored), the
    NEES ``nan`` when the matrix is singular."""
    variances = np.diag(covariance)
    if not (np.all(np.isfinite(covariance)) and np.all(variances > 0.0)):
        return None
    beyond = bool(np.any(np.abs(error) > 3.0 * np.sqrt(variances)))
    try:
        return beyond, float(error @ np.linalg.solve(covariance, error))
    except np.linalg.LinAlgError:
        return beyond, math.nan
