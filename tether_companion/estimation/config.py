"""Settings of the tether EKF, loaded from YAML; the defaults are the paper's (section 6).

Interpretations of the paper's numbers (argued in ``docs/estimation.md``):

* Process noise: the paper adds ``Q = 5e-3 I`` once per 200 Hz step (eq. 31), i.e. a
  random-walk spectral density of ``5e-3 / 0.005 s = 1 m^2/s`` (``N^2/s`` for the tension).
  ``process_noise.form: per_step`` reads the values as per-step variances at
  ``process_noise.step_s``; ``spectral_density`` reads them as ``Q_c`` directly.
* Accelerometer noise: the paper writes ``sigma_acc^2 = 0.01 m/s^2`` while its measurement is
  in units of g. ``accel_noise.unit: mps2_squared`` reads 0.01 as (m/s^2)^2 (sigma 0.1 m/s^2),
  ``g_squared`` as g^2 (sigma 0.98 m/s^2).
* Initial tension: the paper gives none (its ``x0`` has three components); by default the
  4-state filter takes it from the first IMU tick, as the magnitude of the specific force
  that thrust does not explain (``|m R^T a - R^T (0, 0, -T)|``).
* Initial state: the paper's ``x0 = (1.5, 2.5, 1.5)`` is a drone 1.5 m *above* the anchor;
  in NED that is ``p_d = -1.5`` m.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tether_companion.config import ConfigError, load_yaml, spec
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.observability import ObservabilityConfig
from tether_companion.resources import CONFIGS_DIR

FloatArray = NDArray[np.float64]

DEFAULT_CONFIG_PATH: Path = CONFIGS_DIR / "estimator.yaml"


@dataclass(frozen=True)
class ProcessNoise:
    """Random-walk process noise of the state (paper: ``Q = 5e-3 I`` per 200 Hz step)."""

    form: str = spec(
        "per_step",
        choices=("per_step", "spectral_density"),
        doc="per_step: variances added per step_s (eq. 31); spectral_density: Q_c [unit^2/s]",
    )
    step_s: float = spec(0.005, exclusive_minimum=0.0, doc="step the per_step values refer to [s]")
    position_m2: tuple[float, float, float] = spec(
        (5e-3, 5e-3, 5e-3), minimum=0.0, doc="north, east, down position noise [m^2 or m^2/s]"
    )
    tension_n2: float = spec(5e-3, minimum=0.0, doc="tension noise (4-state) [N^2 or N^2/s]")

    def density(self, kind: str) -> FloatArray:
        """Spectral density ``Q_c`` for the model ``kind``, shape (n, n) [unit^2/s]."""
        values = list(self.position_m2) + ([self.tension_n2] if kind == "four_state" else [])
        scale = 1.0 / self.step_s if self.form == "per_step" else 1.0
        return np.diag(np.asarray(values) * scale)


_DEFAULT_ACCEL_VARIANCE = 0.01
_DEFAULT_ALTIMETER_VARIANCE_M2 = 0.1


@dataclass(frozen=True)
class AccelNoise:
    """Accelerometer white-noise variance per axis, with its unit made explicit."""

    variance: float = spec(
        _DEFAULT_ACCEL_VARIANCE, exclusive_minimum=0.0, doc="variance per axis, in `unit`"
    )
    unit: str = spec(
        "mps2_squared",
        choices=("mps2_squared", "g_squared"),
        doc="mps2_squared: (m/s^2)^2; g_squared: g^2 (the paper's R is in g units)",
    )

    std_mps2: float | None = spec(
        None,
        exclusive_minimum=0.0,
        doc="standard deviation per axis [m/s^2], as datasheets give it (replaces variance "
        "and unit; the convention of every sensor-noise key: tension_filter.accel_noise_std_mps2)",
    )

    def __post_init__(self) -> None:
        if self.std_mps2 is not None and self.variance == _DEFAULT_ACCEL_VARIANCE:
            object.__setattr__(self, "variance", self.std_mps2**2)
            object.__setattr__(self, "unit", "mps2_squared")

    def validate(self) -> None:
        """A standard deviation and a variance are two answers to one question."""
        if self.std_mps2 is not None and self.variance != self.std_mps2**2:
            raise ConfigError("", "std_mps2", self.std_mps2, "give either std_mps2 or variance")

    @property
    def variance_mps2_sq(self) -> float:
        """Variance in SI [(m/s^2)^2]."""
        return self.variance * (GRAVITY_MPS2**2 if self.unit == "g_squared" else 1.0)


@dataclass(frozen=True)
class Gate:
    """Chi-square innovation gate."""

    probability: float = spec(
        0.9999,
        exclusive_minimum=0.0,
        maximum=1.0,
        doc="gate probability mass; 1.0 disables the gate",
    )
    max_consecutive_rejections: int = spec(
        5, minimum=0, doc="after this many rejections in a row the next sample is fused (0: never)"
    )


@dataclass(frozen=True)
class Staleness:
    """How old the latest auxiliary sample may be when an IMU tick uses it [s]."""

    attitude_s: float = spec(0.05, exclusive_minimum=0.0, doc="attitude vs IMU time [s]")
    pwm_s: float = spec(0.05, exclusive_minimum=0.0, doc="PWM vs IMU time [s]")
    range_s: float = spec(0.05, exclusive_minimum=0.0, doc="rangefinder sample vs filter time [s]")
    tension_s: float = spec(
        0.5, exclusive_minimum=0.0, doc="known tension (3-state) vs IMU time [s]"
    )
    max_gap_s: float = spec(
        1.0, exclusive_minimum=0.0, doc="a longer gap between IMU ticks resets the filter [s]"
    )


@dataclass(frozen=True)
class Rangefinder:
    """Valid range of the downward rangefinder (readings outside are dropped)."""

    min_m: float = spec(0.05, minimum=0.0, doc="shortest valid reading along the sensor axis [m]")
    max_m: float = spec(
        40.0, exclusive_minimum=0.0, doc="longest valid reading along the sensor axis [m]"
    )
    max_tilt_rad: float = spec(
        0.7,
        exclusive_minimum=0.0,
        maximum=1.5,
        doc="readings at larger tilt (from vertical) are dropped [rad]",
    )
    offset_frd_m: tuple[float, float, float] = spec(
        (0.0, 0.0, 0.0),
        minimum=-5.0,
        maximum=5.0,
        doc="sensor mounting point from the centre of mass, body FRD [m]",
    )


@dataclass(frozen=True)
class GroundStation:
    """Where the tether's anchor is relative to the ground the rangefinder sees."""

    anchor_height_m: float = spec(
        0.0,
        minimum=-100.0,
        maximum=100.0,
        doc="anchor (winch outlet) height above the ground under the drone [m] (tripod, truck)",
    )
    terrain_std_m: float = spec(
        0.0,
        minimum=0.0,
        maximum=2.0,
        doc="unevenness of the ground under the flight: standard deviation of its height about"
        " the anchor's ground level [m]; the rangefinder's height is off by the ground's under"
        " the drone, which a hover does not average away (dynamic filter: added to the"
        " published height variance, less what the drone's motion averages:"
        " terrain_correlation_m)",
    )
    terrain_correlation_m: float = spec(
        1.0,
        exclusive_minimum=0.0,
        maximum=1000.0,
        doc="distance over which the ground's height stays correlated [m] (the integral of its"
        " correlation along a line; undulations of wavelength L: L / 2 pi): a drone moving"
        " over more ground than this within the height's memory averages terrain_std_m down"
        " (dynamic filter)",
    )


ESTIMATOR_KINDS = ("four_state", "three_state", "dynamic")
"""``kind``: the paper's 4-state (position and tension) and 3-state (tension known) EKFs, and
the 17-state dynamic filter (``estimation/dynamic``)."""
ESTIMATOR_KIND_DOC = (
    "four_state / three_state: the paper's random-walk EKF; dynamic: the 17-state filter with "
    "velocity, thrust scale, accelerometer bias and wind (the service's dynamic_filter section; "
    "docs/estimation.md)"
)


@dataclass(frozen=True)
class EstimatorConfig:
    """Everything the tether EKF needs beyond the vehicle profile (defaults: the paper's)."""

    kind: str = spec("four_state", choices=ESTIMATOR_KINDS, doc=ESTIMATOR_KIND_DOC)
    process_noise: ProcessNoise = spec(default_factory=ProcessNoise, doc="random-walk Q")
    accel_noise: AccelNoise = spec(default_factory=AccelNoise, doc="accelerometer R")
    altimeter_noise_variance_m2: float = spec(
        _DEFAULT_ALTIMETER_VARIANCE_M2, exclusive_minimum=0.0, doc="altimeter R [m^2]"
    )
    altimeter_noise_std_m: float | None = spec(
        None,
        exclusive_minimum=0.0,
        doc="altimeter standard deviation [m] (replaces altimeter_noise_variance_m2)",
    )
    initial_position_ned_m: tuple[float, float, float] = spec(
        (1.5, 2.5, -1.5), doc="x0 position, NED relative to the anchor [m]"
    )
    initial_tension_n: float | None = spec(
        None, minimum=0.0, doc="x0 tension (4-state) [N]; null: measured from the first IMU tick"
    )
    initial_position_variance_m2: tuple[float, float, float] = spec(
        (1.0, 1.0, 1.0), exclusive_minimum=0.0, doc="P0 diagonal, position [m^2]"
    )
    initial_tension_variance_n2: float = spec(
        1.0, exclusive_minimum=0.0, doc="P0 diagonal, tension [N^2]"
    )
    gate: Gate = spec(default_factory=Gate, doc="innovation gate")
    staleness: Staleness = spec(default_factory=Staleness, doc="time-alignment bounds")
    rangefinder: Rangefinder = spec(
        default_factory=Rangefinder, doc="rangefinder validity and mounting"
    )
    ground_station: GroundStation = spec(
        default_factory=GroundStation, doc="anchor height for the altimeter model"
    )
    min_cable_length_m: float = spec(
        0.3, exclusive_minimum=0.0, doc="no accelerometer update closer than this to the anchor [m]"
    )
    thrust_model: str | None = spec(
        None, doc="YAML of an identified thrust model (None: static curve)"
    )
    observability: ObservabilityConfig = spec(
        default_factory=ObservabilityConfig,
        doc="covariance growth along the cable while no height is measured",
    )

    def __post_init__(self) -> None:
        std = self.altimeter_noise_std_m
        if std is not None and self.altimeter_noise_variance_m2 == _DEFAULT_ALTIMETER_VARIANCE_M2:
            object.__setattr__(self, "altimeter_noise_variance_m2", std * std)

    def validate(self) -> None:
        """Cross-field checks."""
        std = self.altimeter_noise_std_m
        if std is not None and self.altimeter_noise_variance_m2 != std * std:
            raise ConfigError(
                "",
                "altimeter_noise_std_m",
                std,
                "give either altimeter_noise_std_m or altimeter_noise_variance_m2",
            )
        if self.rangefinder.max_m <= self.rangefinder.min_m:
            raise ConfigError(
                "",
                "rangefinder.max_m",
                self.rangefinder.max_m,
                f"must be > rangefinder.min_m ({self.rangefinder.min_m})",
            )

    @property
    def n(self) -> int:
        """State dimension."""
        return 4 if self.kind == "four_state" else 3

    def x0(self) -> FloatArray:
        """Initial state, shape (n,)."""
        values = list(self.initial_position_ned_m)
        if self.kind == "four_state":
            values.append(0.0 if self.initial_tension_n is None else self.initial_tension_n)
        return np.asarray(values, dtype=float)

    def p0(self) -> FloatArray:
        """Initial covariance, shape (n, n)."""
        values = list(self.initial_position_variance_m2)
        if self.kind == "four_state":
            values.append(self.initial_tension_variance_n2)
        return np.diag(np.asarray(values, dtype=float))

    def q_density(self) -> FloatArray:
        """Process noise spectral density ``Q_c``, shape (n, n)."""
        return self.process_noise.density(self.kind)


def load_estimator_config(path: str | Path | None = None) -> EstimatorConfig:
    """Load an :class:`EstimatorConfig` from YAML (default: ``configs/estimator.yaml``).

    Raises
    ------
    ConfigError
        When the file is missing or a key is unknown, mistyped or out of range.
    """
    return load_yaml(EstimatorConfig, DEFAULT_CONFIG_PATH if path is None else path)
