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
- ``figure8``: fly the ``waypoints_ned_m`` legs (take-off and the way out), then ``loops``
  figure-eights (a lemniscate of Gerono, ``n = c_n + (r/2) sin 2a``, ``e = c_e + r sin a``, at
  the last waypoint's height, about the last waypoint, ``a`` growing so the mean speed is
  ``speed_mps``), then the legs back in reverse order (the way home and the landing).
- ``none``: no trajectory; the vehicle holds where it is until someone sends set-points.

``yaw_rate_deg_s`` turns the heading at a constant rate from ``yaw_deg`` (a yaw sweep).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.config import ConfigError, spec
from tether_companion.sim.controller import Setpoint

TRAJECTORY_KINDS: tuple[str, ...] = ("hover", "circle", "waypoints", "figure8", "none")
_LEMNISCATE_PERIMETER_PER_R = 6.0972
"""Perimeter of the lemniscate of Gerono of half-width r, in units of r (numerical)."""


_Leg = tuple[float, float, tuple[float, float, float], tuple[float, float, float]]
"""A straight leg: start time [s], duration [s], start point NED [m], velocity NED [m/s]."""


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
    yaw_rate_deg_s: float = spec(
        0.0, minimum=-90.0, maximum=90.0, doc="heading rate from yaw_deg on (yaw sweep) [deg/s]"
    )
    loops: int = spec(2, minimum=1, maximum=1000, doc="figure-eights flown (figure8)")

    def validate(self) -> None:
        """Trajectories must stay above the ground plane."""
        if self.kind == "circle" and self.altitude_amplitude_m >= self.mean_altitude_m:
            raise ConfigError(
                "",
                "altitude_amplitude_m",
                self.altitude_amplitude_m,
                f"must be < mean_altitude_m ({self.mean_altitude_m}) to stay above ground",
            )
        if self.kind in ("waypoints", "figure8"):
            if not self.waypoints_ned_m:
                raise ConfigError(
                    "", "waypoints_ned_m", self.waypoints_ned_m, "at least one waypoint is needed"
                )


class Trajectory:
    """Set-points of a :class:`TrajectoryConfig` as a function of time [s]."""

    def __init__(self, config: TrajectoryConfig) -> None:
        self.config = config
        self._yaw_rad = math.radians(config.yaw_deg)
        self._legs: list[_Leg] = []
        self._yaw_rate_rad_s = math.radians(config.yaw_rate_deg_s)
        self._figure8_start_s = math.inf
        self._figure8_end_s = math.inf
        if config.kind == "waypoints":
            self._build_legs(config.waypoints_ned_m, 0.0)
        elif config.kind == "figure8":
            out = self._build_legs(config.waypoints_ned_m, 0.0)
            self._figure8_start_s = out
            omega = config.speed_mps / (_LEMNISCATE_PERIMETER_PER_R * config.radius_m)
            self._figure8_omega = 2.0 * math.pi * omega
            self._figure8_end_s = out + config.loops / omega
            self._return_legs_from = len(self._legs)
            self._build_legs(config.waypoints_ned_m[::-1], self._figure8_end_s)

    def _build_legs(self, points: tuple[tuple[float, float, float], ...], start_s: float) -> float:
        """Append the legs (start time, duration, start point, velocity) through ``points``
        from ``start_s``, with the dwell at each waypoint; the time they end [s]."""
        c = self.config
        t = start_s
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
        return t

    def setpoint_at(self, time_s: float) -> Setpoint:
        """The set-point at ``time_s`` (position, velocity and acceleration feed-forward, yaw)."""
        c = self.config
        if c.kind == "hover":
            return Setpoint(c.position_ned_m, (0.0, 0.0, 0.0), None, self._yaw_at(time_s))
        if c.kind == "circle":
            return self._circle(time_s)
        if c.kind == "waypoints":
            return self._waypoints(time_s, self._legs, c.waypoints_ned_m[-1])
        if c.kind == "figure8":
            return self._figure8(time_s)
        return Setpoint()

    def _yaw_at(self, t: float) -> float:
        yaw = self._yaw_rad + self._yaw_rate_rad_s * t
        return (yaw + math.pi) % (2.0 * math.pi) - math.pi

    def _figure8(self, t: float) -> Setpoint:
        c = self.config
        if t < self._figure8_start_s:
            return self._waypoints(t, self._legs[: self._return_legs_from], c.waypoints_ned_m[-1])
        if t >= self._figure8_end_s:
            return self._waypoints(t, self._legs[self._return_legs_from :], c.waypoints_ned_m[0])
        cn, ce, down = c.waypoints_ned_m[-1]
        r, w = c.radius_m, self._figure8_omega
        a = w * (t - self._figure8_start_s)
        s2, c2, s1, c1 = math.sin(2 * a), math.cos(2 * a), math.sin(a), math.cos(a)
        position = (cn + 0.5 * r * s2, ce + r * s1, down)
        velocity = (r * w * c2, r * w * c1, 0.0)
        acceleration = (-2.0 * r * w * w * s2, -r * w * w * s1, 0.0)
        return Setpoint(position, velocity, acceleration, self._yaw_at(t))

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
        return Setpoint(position, velocity, acceleration, self._yaw_at(t))

    def _waypoints(self, t: float, legs: list[_Leg], last: tuple[float, float, float]) -> Setpoint:
        yaw = self._yaw_at(t)
        for start, duration, origin, velocity in legs:
            if t < start:
                return Setpoint(origin, (0.0, 0.0, 0.0), None, yaw)
            if t < start + duration:
                s = t - start
                position = tuple(o + v * s for o, v in zip(origin, velocity, strict=True))
                return Setpoint(position, velocity, None, yaw)  # type: ignore[arg-type]
        return Setpoint(last, (0.0, 0.0, 0.0), None, yaw)
