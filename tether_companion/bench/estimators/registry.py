"""What the scorecard needs from an estimator, and the registry of estimator kinds.

An *estimator kind* is anything that can ride along a simulated flight: the scorecard
(``tether-companion bench estimators``) flies a scenario once and hands every kind the same
samples, in time order, through the :class:`FlightEstimator` methods. At each IMU tick the
kind returns a :class:`TickOutput` (or ``None`` when it has nothing this tick) that the
scorecard compares with the simulator's truth.

A kind registers itself with :func:`register` in a *provider* module listed in
:data:`PROVIDERS`; :func:`kinds` imports the providers on first use. To add an estimator::

    # tether_companion/estimation/dynamic/scorecard.py (say)
    from tether_companion.bench.estimators.registry import EstimatorKind, register

    register(EstimatorKind(name="dynamic", label="dynamic EKF", build=_build, ...))

and add the module's dotted path to :data:`PROVIDERS` (one line).
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.config import EstimatorConfig
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.sim.scenario import Scenario

FloatArray = NDArray[np.float64]

KNOWN_TENSION = "known_tension"
UNKNOWN_TENSION = "unknown_tension"
CRLB_MODELS = (KNOWN_TENSION, UNKNOWN_TENSION)
"""Which posterior Cramer-Rao bound an estimator is compared with: the position-only bound
(tension given by a load cell) or the position + tension bound (see ``estimation/crlb.py``)."""

PROVIDERS: tuple[str, ...] = (
    "tether_companion.bench.estimators.builtin",
    "tether_companion.estimation.dynamic.scorecard",
)
"""Modules that call :func:`register` when imported, one per line."""


@dataclass(frozen=True, slots=True)
class GroundStation:
    """What the ground station knows at ``time_s`` [s]: handed to every kind each IMU tick.

    Attributes
    ----------
    time_s
        Flight-controller time [s].
    tension_n
        Load-cell reading of the cable tension at the drone end [N] (the simulator's truth).
    paid_out_m
        Cable length paid out as the winch reports it [m]; None between its reports
        (:mod:`~tether_companion.sim.ground_sensors`: exact at every tick unless the scenario's
        ``ground_station`` errors are on).
    cable_angle_rad
        The cable-angle sensor's (azimuth from north toward east, elevation up) of the cable
        where it leaves the anchor [rad], with its errors; None between its reports or when
        the cable has no direction there.
    winch_tension_n
        The winch's load cell [N]: the tension where the cable leaves the winch, with its
        errors; None between its reports.
    """

    time_s: float
    tension_n: float
    paid_out_m: float | None
    cable_angle_rad: tuple[float, float] | None = None
    winch_tension_n: float | None = None


_NAN3 = np.full(3, math.nan)
_NAN33 = np.full((3, 3), math.nan)


@dataclass(frozen=True, slots=True)
class TickOutput:
    """One estimator's output at an IMU tick (SI units, NED from the anchor).

    Attributes
    ----------
    position_ned_m
        Position estimate, shape (3,) [m].
    position_covariance_m2
        Its covariance, shape (3, 3) [m^2]; ``nan`` when the kind has none.
    published
        Whether the service would send this position to the flight controller now.
    tension_n, tension_variance_n2
        Tension estimate [N] and its variance [N^2] (``nan`` when the kind has none).
    velocity_ned_mps, velocity_covariance_m2ps2
        Velocity estimate, shape (3,) [m/s] and covariance (3, 3) [m^2/s^2] (``nan`` if none).
    """

    position_ned_m: FloatArray
    position_covariance_m2: FloatArray
    published: bool
    tension_n: float = math.nan
    tension_variance_n2: float = math.nan
    velocity_ned_mps: FloatArray = field(default_factory=lambda: _NAN3)
    velocity_covariance_m2ps2: FloatArray = field(default_factory=lambda: _NAN33)


class FlightEstimator(Protocol):
    """The samples of a flight, in time order (samples due at one instant: attitude, PWM,
    range, ground station, then IMU)."""

    def on_attitude(self, sample: AttitudeSample) -> None:
        """The flight controller's attitude."""

    def on_pwm(self, sample: PwmSample) -> None:
        """The motor outputs."""

    def on_range(self, sample: RangeSample) -> None:
        """A downward rangefinder reading."""

    def on_ground_station(self, station: GroundStation) -> None:
        """The ground station's load cell and winch (every IMU tick, before ``on_imu``)."""

    def on_imu(self, sample: ImuSample) -> TickOutput | None:
        """Tick at the IMU rate; the estimate now, or ``None`` when there is none."""


@dataclass(frozen=True, slots=True)
class FlightContext:
    """What a kind may know before the flight: the scenario (for ground-station facts such
    as the cable's weight) and the *nominal* vehicle profile (not the simulator's truth)."""

    scenario: Scenario
    vehicle: VehicleProfile
    gravity_mps2: float

    def estimator_config(self, base: EstimatorConfig) -> EstimatorConfig:
        """``base`` with what a user measures and writes into ``estimator:`` for this set-up:
        the anchor's height above the ground (``ground_station.anchor_height_m`` [m], the
        scenario's mean ground level; the terrain's undulation is not known, its standard
        deviation is: ``ground_station.terrain_std_m``, and the distance over which it stays
        correlated: ``ground_station.terrain_correlation_m``, the undulations' wavelength over
        2 pi) and the rangefinder's mounting point (``rangefinder.offset_frd_m``, body FRD
        [m])."""
        ground = self.scenario.ground
        return dataclasses.replace(
            base,
            ground_station=dataclasses.replace(
                base.ground_station,
                anchor_height_m=ground.anchor_height_m,
                terrain_std_m=ground.terrain_std_m,
                terrain_correlation_m=ground.terrain_wavelength_m / (2.0 * math.pi),
            ),
            rangefinder=dataclasses.replace(
                base.rangefinder, offset_frd_m=self.scenario.sensors.range_offset_frd_m
            ),
        )


@dataclass(frozen=True)
class EstimatorKind:
    """An estimator the scorecard can run.

    Attributes
    ----------
    name
        Short key used on the command line and in JSON (``ekf-4s``).
    label
        Column header in the tables.
    build
        Makes a fresh estimator for one flight.
    crlb_model
        One of :data:`CRLB_MODELS`.
    has_velocity, has_tension
        Whether its velocity / tension is scored.
    description
        One sentence for ``--help`` and the docs.
    own_bound
        The posterior CRLB of the kind's own model along a flight (``(context, record)`` to
        the bound's diagonal at every IMU tick, shape (N, >= 3), position [m^2] first), shown
        beside the random-walk bound; ``None``: none.
    """

    name: str
    label: str
    build: Callable[[FlightContext], FlightEstimator]
    crlb_model: str
    has_velocity: bool
    has_tension: bool
    description: str
    own_bound: Callable[[FlightContext, Any], FloatArray] | None = None

    def __post_init__(self) -> None:
        if self.crlb_model not in CRLB_MODELS:
            raise ValueError(f"crlb_model must be one of {CRLB_MODELS}, got {self.crlb_model!r}")


_KINDS: dict[str, EstimatorKind] = {}
_loaded = False


def register(kind: EstimatorKind) -> EstimatorKind:
    """Add ``kind`` to the registry (its name must be new); returns it."""
    if kind.name in _KINDS and _KINDS[kind.name] is not kind:
        raise ValueError(f"estimator kind {kind.name!r} is already registered")
    _KINDS[kind.name] = kind
    return kind


def kinds() -> dict[str, EstimatorKind]:
    """Every registered kind by name, in registration order (providers imported once)."""
    global _loaded
    if not _loaded:
        for module in PROVIDERS:
            importlib.import_module(module)
        _loaded = True
    return dict(_KINDS)
