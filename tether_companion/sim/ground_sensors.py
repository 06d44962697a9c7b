"""The ground station's sensors on a simulated flight: the winch's paid-out length from a drum
encoder and the cable-angle sensor at the anchor, with the errors real ones have.

The ground station's *events* (tension set-points, winch rates, tugs) are
:mod:`~tether_companion.sim.ground_station`'s; this module reads what its sensors report of the
simulated cable (the scenario's ``ground_station`` section, :class:`GroundSensorConfig`).

Off (``enabled: false``, every scenario but the realistic ones) the sensors are the ones the
scorecard always had: the winch reports the simulator's ``paid_out_m`` exactly at every IMU
tick, and the angle sensor the cable's direction at the anchor at ``angle_rate_hz`` turned by
``angle_noise_std_rad`` per axis (white, the emulator's generator and salt).

On, each flight draws (seeded, from its own generator: switching them on does not change the
flight) and reports (sources of the magnitudes: docs/simulator.md, "The ground station's
sensors"):

* the **winch** at ``winch_rate_hz``: ``offset + (1 + scale) L_0`` quantised to
  ``winch_resolution_m``, of the state ``winch_latency_s`` ago, where ``L_0`` is the cable's
  unstretched length off the drum (the encoder counts the drum's turns: the cable's elastic
  stretch ``T L / EA`` is not in it; the constant-tension cable's ``paid_out_m`` is the
  anchor-to-drone distance, so it is stretched by ``cable_axial_stiffness_n``; the elastic and
  catenary cables' ``paid_out_m`` is already unstretched, their stretch is in the physics;
  the winch catenary's is the length its winch paid out, arc plus the part on the ground, of
  an inextensible cable),
  ``scale`` ~ N(0, ``winch_scale_error_std``) (the drum's effective radius: cable layering,
  wear), ``offset`` ~ N(0, ``winch_zero_offset_std_m``) (where the count was zeroed);
* the winch's **load cell** with each length report: the tension where the cable leaves the
  winch, the drone's less the hanging cable's weight ``w h`` for the heavy models (a catenary's
  tension grows by ``w h`` from the winch to a drone ``h`` above it), of the same state,
  plus white ``winch_tension_noise_std_n`` (its own generator) when on;
* the **cable angle** at ``angle_rate_hz``: the direction at the anchor of the state
  ``angle_latency_s`` ago (the drone's position then, the cable as it is now), turned by
  white ``angle_noise_std_rad`` per axis, plus an azimuth bias ~ N(0,
  ``angle_azimuth_bias_std_rad``) (the sensor's zero against true north) and an elevation
  bias ~ N(0, ``angle_elevation_bias_std_rad``) (its level), each angle quantised to
  ``angle_resolution_rad``.

One implementation for every simulated ground station: the offline bench calls :meth:`read`
at every IMU tick (the schedule above); a time-driven sender (the emulator's WINCH_STATUS and
DEBUG_VECT, the ArduPilot SITL ground station's) calls :meth:`GroundSensors.record` with each
simulated state and :meth:`~GroundSensors.winch_length_m` / :meth:`~GroundSensors.cable_angle_rad`
when its own report is due; the same seed draws the same calibration everywhere.

Pure and synchronous.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from tether_companion.config import spec
from tether_companion.physics.cable import CableModel
from tether_companion.physics.cable_anchor import anchor_direction_ned

ANGLE_SEED_SALT = 250
"""Mixed into the scenario's seed for the angle sensor's white noise (the emulator's salt,
DEBUG_VECT's message id)."""
CALIBRATION_SEED_SALT = 9251
"""Mixed into the scenario's seed for the per-flight calibration errors."""
TENSION_SEED_SALT = 9252
"""Mixed into the scenario's seed for the winch load cell's white noise."""
TIME_TOL_S = 1e-9
"""Times closer than this [s] are the same instant (a tick less a latency, rounded)."""
STRETCHED_PAID_OUT_MODELS = ("constant_tension",)
"""Cable models whose ``paid_out_m`` is the stretched anchor-to-drone distance (the encoder
sees it less the stretch); the others' is the unstretched length."""


@dataclass(frozen=True)
class GroundSensorConfig:
    """The ``ground_station`` section of a scenario: the ground station's sensors' errors."""

    enabled: bool = spec(
        False,
        doc="give the winch encoder and the cable-angle sensor the errors below (false: the "
        "exact length every IMU tick, the angle with white noise only)",
    )
    winch_rate_hz: float = spec(
        10.0, exclusive_minimum=0.0, maximum=200.0, doc="winch length report rate [Hz]"
    )
    winch_scale_error_std: float = spec(
        0.01, minimum=0.0, maximum=0.2, doc="drum encoder's scale error, per flight [1]"
    )
    winch_zero_offset_std_m: float = spec(
        0.1, minimum=0.0, maximum=5.0, doc="drum encoder's zero offset, per flight [m]"
    )
    winch_resolution_m: float = spec(
        0.01, minimum=0.0, maximum=1.0, doc="reported length's step (0: none) [m]"
    )
    winch_latency_s: float = spec(
        0.1, minimum=0.0, maximum=2.0, doc="age of the reported length [s]"
    )
    cable_axial_stiffness_n: float = spec(
        0.0,
        minimum=0.0,
        doc="the cable's axial stiffness EA for the stretch the encoder does not see "
        "(constant_tension cable; 0: none) [N]",
    )
    winch_tension_noise_std_n: float = spec(
        0.2, minimum=0.0, maximum=10.0, doc="winch load cell's white noise [N]"
    )
    angle_rate_hz: float = spec(
        10.0, exclusive_minimum=0.0, maximum=200.0, doc="cable-angle report rate [Hz]"
    )
    angle_noise_std_rad: float = spec(
        0.01, minimum=0.0, maximum=0.5, doc="white direction noise per axis [rad]"
    )
    angle_azimuth_bias_std_rad: float = spec(
        0.026, minimum=0.0, maximum=0.5, doc="azimuth zero against north, per flight [rad]"
    )
    angle_elevation_bias_std_rad: float = spec(
        0.007, minimum=0.0, maximum=0.5, doc="elevation zero (level), per flight [rad]"
    )
    angle_resolution_rad: float = spec(
        0.0015, minimum=0.0, maximum=0.1, doc="reported angles' step (0: none) [rad]"
    )
    angle_latency_s: float = spec(
        0.05, minimum=0.0, maximum=2.0, doc="age of the reported angles [s]"
    )


@dataclass(frozen=True, slots=True)
class Calibration:
    """One flight's calibration errors (drawn once).

    Attributes
    ----------
    winch_scale, winch_offset_m
        The encoder's scale error [1] and zero offset [m].
    azimuth_bias_rad, elevation_bias_rad
        The angle sensor's zero errors [rad].
    """

    winch_scale: float
    winch_offset_m: float
    azimuth_bias_rad: float
    elevation_bias_rad: float


@dataclass(frozen=True, slots=True)
class GroundReadings:
    """What the ground station's sensors report at one IMU tick.

    Attributes
    ----------
    paid_out_m
        The winch's reported length [m]; None between its reports.
    winch_tension_n
        The winch's load cell [N], the tension where the cable leaves the winch, with each
        length report; None between them.
    cable_angle_rad
        The angle sensor's (azimuth from north toward east, elevation up) [rad]; None between
        its reports or while the cable has no direction at the anchor.
    """

    paid_out_m: float | None
    cable_angle_rad: tuple[float, float] | None
    winch_tension_n: float | None = None


class GroundSensors:
    """The winch encoder and the cable-angle sensor of one flight (module docstring).

    Parameters
    ----------
    config
        The scenario's ``ground_station`` section.
    cable_model
        The scenario's ``cable.model`` (whether ``paid_out_m`` is stretched).
    seed
        The scenario's seed.
    cable_weight_n_per_m
        The cable's weight per length [N/m] (0 for the weightless constant-tension line): the
        load cell's tension is the drone's less ``w h``.
    """

    def __init__(
        self,
        config: GroundSensorConfig,
        cable_model: str,
        seed: int,
        cable_weight_n_per_m: float = 0.0,
    ) -> None:
        self.config = config
        self._angle_rng = np.random.default_rng([seed, ANGLE_SEED_SALT])
        self._tension_rng = np.random.default_rng([seed, TENSION_SEED_SALT])
        self._weight_n_per_m = cable_weight_n_per_m
        self._stretched = cable_model in STRETCHED_PAID_OUT_MODELS
        self.calibration = Calibration(0.0, 0.0, 0.0, 0.0)
        if config.enabled:
            scale, offset, azimuth, elevation = np.random.default_rng(
                [seed, CALIBRATION_SEED_SALT]
            ).standard_normal(4)
            self.calibration = Calibration(
                float(scale) * config.winch_scale_error_std,
                float(offset) * config.winch_zero_offset_std_m,
                float(azimuth) * config.angle_azimuth_bias_std_rad,
                float(elevation) * config.angle_elevation_bias_std_rad,
            )
        self._keep_s = (
            max(config.winch_latency_s, config.angle_latency_s) if config.enabled else 0.0
        )
        """How far back the reports look [s] (off: no latency)."""
        self._history: deque[tuple[float, float, tuple[float, float, float], float]] = deque()
        """(time [s], encoder's length [m], position NED [m], tension at the drone [N]) of
        recent states."""
        self._next_winch_s = 0.0
        self._next_angle_s = 0.0

    def read(
        self,
        time_s: float,
        cable: CableModel,
        position_ned_m: tuple[float, float, float],
        tension_n: float,
    ) -> GroundReadings:
        """The reports due at ``time_s`` [s] (called at every IMU tick, in time order) of the
        simulated ``cable`` with the drone at ``position_ned_m`` [m] pulling ``tension_n`` [N]:
        the length every tick when off, at ``winch_rate_hz`` when on; the angle at
        ``angle_rate_hz``."""
        cfg = self.config
        angle_due = time_s >= self._next_angle_s
        if angle_due:
            self._next_angle_s = time_s + 1.0 / cfg.angle_rate_hz
        self.record(time_s, cable.paid_out_m, position_ned_m, tension_n)
        paid_out = tension = None
        if not cfg.enabled or time_s >= self._next_winch_s:
            self._next_winch_s = time_s + 1.0 / cfg.winch_rate_hz
            paid_out = self.winch_length_m(time_s)
            tension = self.winch_tension_n(time_s)
        angle = None
        if angle_due:
            angle = self.cable_angle_rad(time_s, partial(anchor_direction_ned, cable))
        return GroundReadings(paid_out, angle, tension)

    def record(
        self,
        time_s: float,
        paid_out_m: float,
        position_ned_m: tuple[float, float, float],
        tension_n: float,
    ) -> None:
        """Note the simulated cable's state at ``time_s`` [s] (in time order, at least as
        often as the latencies need resolving): its ``paid_out_m`` [m] (the simulator's), the
        drone at ``position_ned_m`` [m] (NED from the anchor) pulling ``tension_n`` [N]."""
        cfg = self.config
        length = paid_out_m
        if cfg.enabled and self._stretched and cfg.cable_axial_stiffness_n > 0.0:
            length /= 1.0 + max(tension_n, 0.0) / cfg.cable_axial_stiffness_n
        history = self._history
        history.append((time_s, length, position_ned_m, tension_n))
        before_s = time_s - self._keep_s  # drop what no report at time_s or later will need
        while len(history) > 1 and history[1][0] <= before_s + TIME_TOL_S:
            history.popleft()

    def winch_length_m(self, time_s: float) -> float:
        """The encoder's report at ``time_s`` [s] of the recorded states [m] (off: the
        latest recorded length, exact)."""
        cfg = self.config
        if not cfg.enabled:
            return self._history[-1][1]
        _, old_length, _, _ = self._at(time_s - cfg.winch_latency_s)
        calibration = self.calibration
        reported = calibration.winch_offset_m + (1.0 + calibration.winch_scale) * old_length
        return _quantised(reported, cfg.winch_resolution_m)

    def winch_tension_n(self, time_s: float) -> float:
        """The winch load cell's report at ``time_s`` [s] of the recorded states [N]: the
        tension at the drone less ``w h`` (never below 0) of the state ``winch_latency_s`` ago,
        plus its white noise (off: the latest state's, exact). Draws from its generator."""
        cfg = self.config
        _, _, position, tension = self._at(time_s - cfg.winch_latency_s if cfg.enabled else time_s)
        at_winch = max(0.0, tension - self._weight_n_per_m * max(0.0, -position[2]))
        if not cfg.enabled:
            return at_winch
        return at_winch + cfg.winch_tension_noise_std_n * float(self._tension_rng.standard_normal())

    def cable_angle_rad(
        self,
        time_s: float,
        direction_at_anchor: Callable[
            [tuple[float, float, float]], tuple[float, float, float] | None
        ],
    ) -> tuple[float, float] | None:
        """The angle sensor's report at ``time_s`` [s] of the recorded states: (azimuth from
        north toward east, elevation up) [rad] of ``direction_at_anchor(position)`` (the
        cable's unit direction at the anchor with the drone at that NED position [m], None
        without one: then None) for the position ``angle_latency_s`` ago (off: the latest,
        with the white noise only). Draws the noise from the sensor's generator."""
        cfg = self.config
        if not cfg.enabled:
            direction = direction_at_anchor(self._history[-1][2])
            return None if direction is None else self._noisy(direction)
        _, _, old_position, _ = self._at(time_s - cfg.angle_latency_s)
        direction = direction_at_anchor(old_position)
        if direction is None:
            return None
        azimuth, elevation = self._noisy(direction)
        calibration = self.calibration
        step = cfg.angle_resolution_rad
        azimuth = _quantised(azimuth + calibration.azimuth_bias_rad, step)
        elevation = _quantised(elevation + calibration.elevation_bias_rad, step)
        return (azimuth + math.pi) % (2.0 * math.pi) - math.pi, elevation

    def _noisy(self, direction: tuple[float, float, float]) -> tuple[float, float]:
        return noisy_angles(direction, self.config.angle_noise_std_rad, self._angle_rng)

    def _at(self, time_s: float) -> tuple[float, float, tuple[float, float, float], float]:
        """The latest recorded tick at or before ``time_s`` [s] (within :data:`TIME_TOL_S`;
        the oldest kept if none)."""
        history = self._history
        for entry in reversed(history):
            if entry[0] <= time_s + TIME_TOL_S:
                return entry
        return history[0]


def noisy_angles(
    direction_ned: tuple[float, float, float], noise_std_rad: float, rng: np.random.Generator
) -> tuple[float, float]:
    """(azimuth from north toward east, elevation up) [rad] of the unit vector
    ``direction_ned`` turned by ``noise_std_rad`` [rad] per axis (across it horizontally and
    vertically): the azimuth's noise is ``noise_std_rad / cos(elevation)``."""
    north, east, down = direction_ned
    elevation = math.atan2(-down, math.hypot(north, east))
    azimuth = math.atan2(east, north)
    across, up = noise_std_rad * rng.standard_normal(2)
    elevation = min(max(elevation + up, -0.5 * math.pi), 0.5 * math.pi)
    azimuth += across / max(math.cos(elevation), 1e-3)
    return (azimuth + math.pi) % (2.0 * math.pi) - math.pi, elevation


def _quantised(value: float, step: float) -> float:
    return round(value / step) * step if step > 0.0 else value
