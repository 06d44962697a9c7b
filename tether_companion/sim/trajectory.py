"""Reference trajectories for offline runs: set-points as a function of time (NED, anchor origin).

Kinds (the ``trajectory`` section of a scenario):

- ``hover``: hold ``position_ned_m``.
- ``circle``: the paper's orbit (Al-Radaideh & Sun 2021, section 6): radius ``radius_m`` about
  ``center_ne_m`` at constant speed ``speed_mps``, starting due north of the centre and
  turning clockwise seen from above (north to east); the altitude above the anchor varies as
  ``h(t) = mean_altitude_m + altitude_amplitude_m sin(2 pi t / altitude_period_s)``.
  Velocity and acceleration feed-forward are the exact derivatives.
- ``waypoints``: straight legs between ``waypoints_ned_m`` at ``speed_mps``, pausing
  ``dwell_s`` at each, holding the last one.
- ``none``: no trajectory; the vehicle holds where it is until someone sends set-points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.config import ConfigError, spec
from tether_companion.sim.controller import Setpoint

TRAJECTORY_KINDS: tuple[str, ...] = ("hover", "circle", "waypoints", "none")


@dataclass(frozen=True)
class TrajectoryConfig:
    """The ``trajectory`` section of a scenario (SI units, NED, anchor at the origin)."""

    kind: str = spec("hover", choices=TRAJECTORY_KINDS, doc="trajectory kind")
    position_ned_m: tuple[float, float, float] = spec((0.0, 0.0, -2.0), doc="hover position [m]")
    radius_m: float = spec(2.5, exclusive_minimum=0.0, doc="circle radius [m]")
    speed_mps: float = spec(
        1.0, exclusive_minimum=0.0, maximum=20.0, doc="speed along the path [m/s]"
    )
    center_ne_m: tuple[float, float] = spec((0.0, 0.0), doc="circle centre (north, east) [m]")
    mean_altitude_m: float = spec(
        2.0, exclusive_minimum=0.0, doc="circle mean height above the anchor [m]"
    )
    altitude_amplitude_m: float = spec(
        0.5, minimum=0.0, doc="circle altitude sinusoid amplitude [m]"
    )
    altitude_period_s: float = spec(
        20.0, exclusive_minimum=0.0, doc="circle altitude sinusoid period [s]"
    )
    waypoints_ned_m: tuple[tuple[float, float, float], ...] = spec((), doc="waypoints, NED [m]")
    dwell_s: float = spec(0.0, minimum=0.0, doc="pause at each waypoint [s]")
    yaw_deg: float = spec(
        0.0, minimum=-180.0, maximum=180.0, doc="heading held along the trajectory [deg]"
    )

    def validate(self) -> None:
        """Trajectories must stay above the ground plane."""
        if self.kind == "hover" and self.position_ned_m[2] > 0.0:
            raise ConfigError(
                "", "position_ned_m", self.position_ned_m, "down must be <= 0 (above ground)"
            )
        if self.kind == "circle" and self.altitude_amplitude_m >= self.mean_altitude_m:
            raise ConfigError(
                "",
                "altitude_amplitude_m",
                self.altitude_amplitude_m,
                f"must be < mean_altitude_m ({self.mean_altitude_m}) to stay above ground",
            )
        if self.kind == "waypoints":
            if not self.waypoints_ned_m:
                raise ConfigError(
                    "", "waypoints_ned_m", self.waypoints_ned_m, "at least one waypoint is needed"
                )
            for i, point in enumerate(self.waypoints_ned_m):
                if point[2] > 0.0:
                    raise ConfigError(
                        "", f"waypoints_ned_m[{i}]", point, "down must be <= 0 (above ground)"
                    )


class Trajectory:
    """Set-points of a :class:`TrajectoryConfig` as a function of time [s]."""

    def __init__(self, config: TrajectoryConfig) -> None:
        self.config = config
        self._yaw_rad = math.radians(config.yaw_deg)
        self._legs: list[
            tuple[float, float, tuple[float, float, float], tuple[float, float, float]]
        ] = []
        if config.kind == "waypoints":
            self._build_legs()

    def _build_legs(self) -> None:
        """Legs (start time, duration, start point, velocity) including dwell at each waypoint."""
        c = self.config
        t = 0.0
        points = c.waypoints_ned_m
        for a, b in zip(points, points[1:], strict=False):
            t += c.dwell_s
            length = math.dist(a, b)
            duration = length / c.speed_mps
            velocity = (
                tuple((bi - ai) / duration for ai, bi in zip(a, b, strict=True))
                if duration > 0
                else (0.0,) * 3
            )
            self._legs.append((t, duration, a, velocity))  # type: ignore[arg-type]
            t += duration

    def setpoint_at(self, time_s: float) -> Setpoint:
        """The set-point at ``time_s`` (position, velocity and acceleration feed-forward, yaw)."""
        c = self.config
        if c.kind == "hover":
            return Setpoint(c.position_ned_m, (0.0, 0.0, 0.0), None, self._yaw_rad)
        if c.kind == "circle":
            return self._circle(time_s)
        if c.kind == "waypoints":
            return self._waypoints(time_s)
        return Setpoint()

    def _circle(self, t: float) -> Setpoint:
        c = self.config
        radius = c.radius_m
        omega = c.speed_mps / radius
        angle = omega * t
        ca, sa = math.cos(angle), math.sin(angle)
        w_alt = 2.0 * math.pi / c.altitude_period_s
        amp = c.altitude_amplitude_m
        sh, ch = math.sin(w_alt * t), math.cos(w_alt * t)
        position = (
            c.center_ne_m[0] + radius * ca,
            c.center_ne_m[1] + radius * sa,
            -(c.mean_altitude_m + amp * sh),
        )
        velocity = (-radius * omega * sa, radius * omega * ca, -amp * w_alt * ch)
        acceleration = (
            -radius * omega * omega * ca,
            -radius * omega * omega * sa,
            amp * w_alt * w_alt * sh,
        )
        return Setpoint(position, velocity, acceleration, self._yaw_rad)

    def _waypoints(self, t: float) -> Setpoint:
        points = self.config.waypoints_ned_m
        for start, duration, origin, velocity in self._legs:
            if t < start:
                return Setpoint(origin, (0.0, 0.0, 0.0), None, self._yaw_rad)
            if t < start + duration:
                s = t - start
                position = tuple(o + v * s for o, v in zip(origin, velocity, strict=True))
                return Setpoint(position, velocity, None, self._yaw_rad)  # type: ignore[arg-type]
        return Setpoint(points[-1], (0.0, 0.0, 0.0), None, self._yaw_rad)
