"""External navigation (VISION_POSITION_ESTIMATE / ODOMETRY) as ArduPilot's EKF uses it.

The rules, from ArduPilot's AP_VisualOdom and EKF3 (see the project's field notes):

- external position is used only once an EKF origin exists (SET_GPS_GLOBAL_ORIGIN);
- after a change of ``reset_counter`` the estimates are ignored for 1 s;
- data older than 300 ms means the source is unhealthy (position lost);
- the measurement is stamped in the past; the EKF fuses it at its time and predicts forward
  with the IMU. The emulator stands in for that prediction with the true velocity over the
  measured lag (capped at 250 ms, ArduPilot's largest EKF delay), so a correct but late
  estimate is not punished while a wrong one makes the vehicle drift.

Times are flight-controller (boot) seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.mavlink.estimates import PoseEstimate

FloatArray = NDArray[np.float64]

TIMEOUT_S = 0.3
RESET_IGNORE_S = 1.0
MAX_LAG_S = 0.25


@dataclass
class ExternalNavCounters:
    """What happened to the external position estimates the flight controller received."""

    received: int = 0
    used: int = 0
    ignored_no_origin: int = 0
    ignored_after_reset: int = 0
    ignored_disabled: int = 0
    invalid: int = 0
    resets: int = 0


class ExternalNav:
    """The flight controller's view of an external position source."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget everything (construction, flight-controller reboot)."""
        self.counters = ExternalNavCounters()
        self.origin_set = False
        self.enabled = True
        """False when VISO_TYPE is 0 (no visual odometry configured)."""
        self._position: FloatArray | None = None
        self._euler: tuple[float, float, float] | None = None
        self._stamp_s = 0.0
        self._arrival_s = -math.inf
        self._reset_counter: int | None = None
        self._ignore_until_s = -math.inf

    def on_estimate(self, pose: PoseEstimate, now_s: float) -> bool:
        """Take an estimate received at ``now_s`` [s]; True when it is used for navigation."""
        c = self.counters
        c.received += 1
        p = pose.position_ned_m
        if not (np.all(np.isfinite(p)) and math.isfinite(pose.time_s)):
            c.invalid += 1
            return False
        if not self.enabled:
            c.ignored_disabled += 1
            return False
        if not self.origin_set:
            c.ignored_no_origin += 1
            return False
        if self._reset_counter is not None and pose.reset_counter != self._reset_counter:
            c.resets += 1
            self._ignore_until_s = now_s + RESET_IGNORE_S
        self._reset_counter = pose.reset_counter
        if now_s < self._ignore_until_s:
            c.ignored_after_reset += 1
            return False
        c.used += 1
        self._position = np.array(p, dtype=float)
        self._euler = tuple(float(a) for a in pose.euler_rad)  # type: ignore[assignment]
        self._stamp_s = pose.time_s
        self._arrival_s = now_s
        return True

    def healthy(self, now_s: float) -> bool:
        """True while the last used estimate arrived within the last 300 ms."""
        return self._position is not None and now_s - self._arrival_s <= TIMEOUT_S

    def position_ned_m(self, now_s: float, velocity_ned_m_s: FloatArray) -> FloatArray | None:
        """The navigation position now [m], NED (the estimate moved on by the velocity over its
        lag), or None when unhealthy."""
        if not self.healthy(now_s):
            return None
        assert self._position is not None
        lag_s = min(max(now_s - self._stamp_s, 0.0), MAX_LAG_S)
        return self._position + np.asarray(velocity_ned_m_s) * lag_s

    @property
    def last_euler_rad(self) -> tuple[float, float, float] | None:
        """Roll, pitch, yaw of the last used estimate [rad] (for the arming check)."""
        return self._euler
