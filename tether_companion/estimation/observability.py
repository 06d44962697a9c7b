"""What the estimator cannot see when a sensor goes away, and the covariance that says so.

The accelerometer sees the cable's pull: its direction at the drone and its magnitude. The
direction fixes the drone's bearing from the anchor (two angles) but not its distance along
the cable: the position along ``u = p / |p|`` is observed only by the height (rangefinder).
When the rangefinder stops (out of range, tilted past its limit, stream lost) nothing
measures that direction any more, and the paper's random-walk filters let their estimate drift
along it at roughly the speed they track the drone's motion with (measured: 0.8 m/s on the
paper's circle at 1 m/s) while their covariance there grows only with the random walk's small
``Q``. Published, that is a position several metres off claiming a decimetre.

:class:`RangeWatch` keeps the time of the last fused height and, while it is older than
``range_lost_after_s``, grows the position covariance along the cable so that the standard
deviation there is at least ``unobserved_speed_mps`` times the time since the last height:
``P += v^2 ((t_lost)^2 - (t_lost - dt)^2) u u^T``. The variance then says what the data can
tell (likewise :func:`grow_for_imu_gap` over an IMU outage); the publisher withholds (or
inflates) once it passes ``publish.max_position_variance_m2`` and names the missing input.
A fused height pins the direction again and the Kalman update shrinks the grown variance by
itself.

Pure and synchronous; times are flight-controller seconds, positions NED from the anchor [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.config import spec

FloatArray = NDArray[np.float64]

RANGEFINDER = "rangefinder"
"""Name of the missing input when the height is not measured (Estimate.missing_input)."""


@dataclass(frozen=True)
class ObservabilityConfig:
    """How the covariance grows along directions no sensor observes."""

    range_lost_after_s: float = spec(
        0.3,
        exclusive_minimum=0.0,
        maximum=10.0,
        doc="no height fused for this long = rangefinder lost: the position variance along "
        "the cable grows from then on [s]",
    )
    unobserved_speed_mps: float = spec(
        1.0,
        minimum=0.0,
        maximum=20.0,
        doc="speed at which the position may move unobserved: along the cable without a "
        "height (standard deviation there grows as this times the time since the last "
        "height) and in every direction over an IMU gap [m/s] (0 = no growth, the paper's "
        "filter)",
    )
    imu_gap_s: float = spec(
        0.05,
        exclusive_minimum=0.0,
        maximum=10.0,
        doc="a gap between IMU samples longer than this adds (unobserved_speed_mps * gap)^2 "
        "to every position variance: nothing observed the drone meanwhile [s]",
    )


def grow_for_imu_gap(covariance: FloatArray, gap_s: float, config: ObservabilityConfig) -> bool:
    """Add ``(unobserved_speed_mps * gap_s)^2`` to each position variance (``covariance[:3,
    :3]``, in place) when ``gap_s`` exceeds ``imu_gap_s``: during an IMU outage nothing
    observes the drone, which may have moved that far in any direction (the random walk's
    ``Q dt`` is tuned for 5 ms steps, not for a gap). True when it did."""
    if not gap_s > config.imu_gap_s:
        return False
    growth = (config.unobserved_speed_mps * gap_s) ** 2
    covariance[0, 0] += growth
    covariance[1, 1] += growth
    covariance[2, 2] += growth
    return True


class RangeWatch:
    """The time since the last fused height, and the covariance growth it calls for.

    Parameters
    ----------
    config
        Threshold and growth rate.
    """

    def __init__(self, config: ObservabilityConfig) -> None:
        self.config = config
        self._last_fused_s = math.nan
        self._start_s = math.nan
        self._lost_at: tuple[float, bool] = (math.nan, False)
        """(time [s], :meth:`lost` then): the pipeline asks twice per tick."""

    def reset(self) -> None:
        """Forget everything (filter restart)."""
        self._last_fused_s = math.nan
        self._start_s = math.nan
        self._lost_at = (math.nan, False)

    def on_fused(self, time_s: float) -> None:
        """A height was fused at ``time_s`` [s]."""
        self._last_fused_s = time_s
        self._lost_at = (math.nan, False)

    def unmeasured_s(self, time_s: float) -> float:
        """Seconds since the last fused height (since the first tick when none yet) [s]."""
        if math.isnan(self._start_s):
            self._start_s = time_s
        since = self._start_s if math.isnan(self._last_fused_s) else self._last_fused_s
        elapsed = time_s - since
        return 0.0 if 0.0 > elapsed else elapsed  # max(elapsed, 0.0), nan kept

    def lost(self, time_s: float) -> bool:
        """True when no height was fused for longer than ``range_lost_after_s``."""
        at, lost = self._lost_at
        if at != time_s:  # (nan after a change: never equal)
            lost = self.unmeasured_s(time_s) > self.config.range_lost_after_s
            self._lost_at = (time_s, lost)
        return lost

    def grow(
        self, covariance: FloatArray, position_ned_m: FloatArray, time_s: float, dt_s: float
    ) -> bool:
        """Decouple and grow the covariance along the cable in place for the step ``dt_s``
        ending at ``time_s``; True when the height is lost (whether or not anything changed).

        ``covariance`` is the full state covariance, position block first. While the height is
        lost, the correlations between the position along the cable ``u`` and every other state
        are dropped (``P <- Pi P Pi + (e^T P e) e e^T``, ``e = (u, 0)``, ``Pi = I - e e^T``: the
        sum of two positive semi-definite terms on orthogonal subspaces) so that the
        accelerometer's update, which carries no information along ``u``, cannot move the
        estimate along it through those correlations; then ``v^2 (t^2 - (t - dt)^2)`` is added
        to the variance along ``u`` (``t`` the time since the last height).
        """
        unmeasured = self.unmeasured_s(time_s)
        if unmeasured <= self.config.range_lost_after_s:
            return False
        radius = math.sqrt(float(position_ned_m @ position_ned_m))
        if not radius > 0.0:
            return True
        e = np.zeros(covariance.shape[0])
        e[:3] = position_ned_m / radius
        pe = covariance @ e
        along = float(e @ pe)
        # Pi P Pi = P - e pe^T - pe e^T + along e e^T
        covariance -= np.outer(e, pe) + np.outer(pe, e)
        speed = self.config.unobserved_speed_mps
        before = max(unmeasured - dt_s, 0.0)
        growth = speed * speed * (unmeasured * unmeasured - before * before) if dt_s > 0 else 0.0
        covariance += (2.0 * along + growth) * np.outer(e, e)
        return True
