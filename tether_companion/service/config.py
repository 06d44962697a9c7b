"""Typed configuration of the companion service (``configs/companion.yaml``).

Every section is a frozen dataclass validated by :mod:`tether_companion.config`: an unknown key
or a value out of range stops the service at start with a message naming the file, the key,
the value and what is allowed (exit code 2). ``docs/config-reference.md`` lists every key
(generated with :func:`config_reference`: ``python -m tether_companion.service.config``).

This module holds the whole file (:class:`ServiceConfig`, its cross-section checks, loading);
the larger sections live beside what reads them (``publish_config.py``, ``input_config.py``,
``link_config.py``, ``winch.py``, ``cable_angle.py``, ``vehicle_fetch.py``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from tether_companion.config import ConfigError, describe, from_mapping, read_yaml, spec
from tether_companion.estimation.catenary_position import CatenaryPositionConfig
from tether_companion.estimation.config import (
    ESTIMATOR_KIND_DOC,
    ESTIMATOR_KINDS,
    EstimatorConfig,
)
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.tension_kf import TensionFilterConfig
from tether_companion.modes.config import TensionModeConfig
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.service.cable_angle import CableAngleConfig
from tether_companion.service.input_config import InputLimitsConfig, TensionConfig
from tether_companion.service.link_config import (
    LinkConfig,
    OriginConfig,
    SecurityConfig,
    StreamsConfig,
)
from tether_companion.service.publish_config import PublishConfig
from tether_companion.service.vehicle_fetch import (
    FROM_AUTOPILOT,
    AutopilotVehicleConfig,
    require_mass,
)
from tether_companion.service.winch import WinchConfig

EKF = "ekf"
CATENARY = "catenary"
DYNAMIC = "dynamic"
"""``estimator.kind`` of the dynamic filter."""


@dataclass(frozen=True)
class ServiceEstimatorConfig(EstimatorConfig):
    """The service's ``estimator`` section: :class:`EstimatorConfig` with the dynamic filter as
    its default kind. The paper's EKFs (``four_state``, ``three_state``) stay selectable and
    remain the default of ``EstimatorConfig`` itself (``simulate``, ``bench paper``); the
    dynamic filter is the service's because it publishes only what its covariance supports
    on realistic flights, where the paper's filter publishes positions metres off at a
    claimed 0.1 m (docs/estimation.md, "In the service")."""

    kind: str = spec(
        DYNAMIC,
        choices=ESTIMATOR_KINDS,
        doc=ESTIMATOR_KIND_DOC + "; the service's default is dynamic",
    )


@dataclass(frozen=True)
class PositionSourceConfig:
    """Which estimator's position goes to the flight controller, and what runs beside it."""

    source: str = spec(
        EKF,
        choices=(EKF, CATENARY),
        doc="ekf: the tether EKF (estimator section); catenary: the tension filter "
        "(tension_filter) through the catenary (catenary section), Martins 2019 section 6",
    )
    catenary_beside: bool = spec(
        False,
        doc="with source ekf: also run the catenary estimator, shown in --status and sent as "
        "NAMED_VALUE_FLOAT TETH_CN/CE/CD (publish.filtered_rate_hz)",
    )

    @property
    def runs_catenary(self) -> bool:
        """Whether the catenary estimator runs (published or beside)."""
        return self.source == CATENARY or self.catenary_beside


@dataclass(frozen=True)
class RecordingConfig:
    """The .tlog flight recording."""

    enabled: bool = spec(True, doc="record received and sent MAVLink to .tlog files")
    directory: str = spec("/var/lib/tether-companion/recordings", doc="where the .tlog files go")
    max_file_mb: float = spec(64.0, minimum=0.1, doc="rotate to a new file beyond this size [MiB]")
    max_total_mb: float = spec(
        2048.0, minimum=0.2, doc="delete the oldest recordings beyond this total [MiB]"
    )
    flush_interval_s: float = spec(
        1.0,
        exclusive_minimum=0.0,
        maximum=10.0,
        doc="flush + fsync period: at most this much is lost on a power cut [s]",
    )

    def validate(self) -> None:
        """The total must hold at least two files (the current one and one finished)."""
        if self.max_total_mb < 2 * self.max_file_mb:
            raise ConfigError(
                "",
                "max_total_mb",
                self.max_total_mb,
                f"must be >= 2 * max_file_mb ({2 * self.max_file_mb})",
            )


@dataclass(frozen=True)
class ServiceConfig:
    """The whole companion configuration (one YAML file)."""

    vehicle: str = spec(
        "default-quad",
        doc="vehicle profile: a name in configs/vehicles/, a YAML path (relative to this "
        "file's folder; docs/vehicle-reference.md lists its keys), or from_autopilot",
    )
    autopilot_vehicle: AutopilotVehicleConfig = spec(
        default_factory=AutopilotVehicleConfig,
        doc="vehicle: from_autopilot (the profile from the flight controller's parameters)",
    )
    link: LinkConfig = spec(default_factory=LinkConfig)
    streams: StreamsConfig = spec(default_factory=StreamsConfig)
    origin: OriginConfig = spec(default_factory=OriginConfig)
    inputs: InputLimitsConfig = spec(default_factory=InputLimitsConfig)
    estimator: ServiceEstimatorConfig = spec(default_factory=ServiceEstimatorConfig)
    dynamic_filter: DynamicFilterConfig = spec(
        default_factory=DynamicFilterConfig,
        doc="the dynamic filter's own settings (estimator.kind dynamic; the anchor height is "
        "estimator.ground_station.anchor_height_m)",
    )
    thrust_dynamics: str = spec(
        "motor_lag",
        choices=("motor_lag", "static"),
        doc="motor_lag: static curve through the profile's motor_time_constant_s "
        "(needed when the autopilot flies on the estimate); static: the paper's map; "
        "ignored when estimator.thrust_model names an identified model",
    )
    tension: TensionConfig = spec(default_factory=TensionConfig)
    winch: WinchConfig = spec(
        default_factory=WinchConfig,
        doc="the ground station's winch (WINCH_STATUS): paid-out length and tension",
    )
    cable_angle: CableAngleConfig = spec(
        default_factory=CableAngleConfig,
        doc="the ground station's cable-angle sensor (DEBUG_VECT): azimuth and elevation of "
        "the cable at the anchor",
    )
    publish: PublishConfig = spec(default_factory=PublishConfig)
    tension_mode: TensionModeConfig = spec(
        default_factory=TensionModeConfig, doc="tension-following and landing by the tether"
    )
    tension_filter: TensionFilterConfig = spec(
        default_factory=TensionFilterConfig,
        doc="tension Kalman filter the modes act on (and the catenary estimator's input)",
    )
    position: PositionSourceConfig = spec(
        default_factory=PositionSourceConfig, doc="which position is published"
    )
    catenary: CatenaryPositionConfig = spec(
        default_factory=CatenaryPositionConfig,
        doc="position from the filtered tension and the catenary (position.source catenary)",
    )
    recording: RecordingConfig = spec(default_factory=RecordingConfig)
    security: SecurityConfig = spec(default_factory=SecurityConfig)
    watchdog_interval_s: float = spec(
        0.0,
        minimum=0.0,
        doc="WATCHDOG=1 period when systemd gives no WATCHDOG_USEC [s] (0 = only when asked)",
    )

    def validate(self) -> None:
        """The 3-state estimator needs a tension source; the 4-state one estimates it. The EKF
        and the tension filter share one input-alignment stage, so one pair of staleness
        bounds."""
        stale = self.estimator.staleness
        for key, value, bound in (
            ("attitude_staleness_s", self.tension_filter.attitude_staleness_s, stale.attitude_s),
            ("pwm_staleness_s", self.tension_filter.pwm_staleness_s, stale.pwm_s),
        ):
            if value != bound:
                raise ConfigError(
                    "",
                    f"tension_filter.{key}",
                    value,
                    f"must equal estimator.staleness ({bound} s): the service aligns the inputs "
                    "once for the EKF and the tension filter",
                )
        if self.security.install_key and not self.link.connect.startswith("serial:"):
            raise ConfigError(
                "",
                "security.install_key",
                True,
                f"only over a serial link (link.connect is {self.link.connect!r}): SETUP_SIGNING "
                "carries the key in clear",
            )
        require_mass(self.vehicle, self.autopilot_vehicle)
        kind = self.estimator.kind
        if kind == "three_state" and self.tension.source == "estimate":
            raise ConfigError(
                "",
                "tension.source",
                self.tension.source,
                "must be 'config' or 'message' with estimator.kind three_state",
            )
        if kind == "four_state" and self.tension.source != "estimate":
            raise ConfigError(
                "",
                "tension.source",
                self.tension.source,
                "must be 'estimate' with estimator.kind four_state",
            )
        if kind == DYNAMIC and self.tension.source == "config":
            raise ConfigError(
                "",
                "tension.source",
                self.tension.source,
                "must be 'estimate', 'message' (a load cell) or 'winch' with estimator.kind "
                "dynamic",
            )
        if self.tension.source == "winch" and not self.winch.enabled:
            raise ConfigError(
                "", "tension.source", "winch", "needs winch.enabled: true (WINCH_STATUS read)"
            )
        if self.cable_angle.max_age_s > self.estimator.staleness.tension_s:
            raise ConfigError(
                "",
                "cable_angle.max_age_s",
                self.cable_angle.max_age_s,
                f"must be at most estimator.staleness.tension_s ({stale.tension_s} s)",
            )


def load_service_config(path: str | Path | None, overrides: dict | None = None) -> ServiceConfig:
    """Read the service YAML (or use defaults when ``path`` is None) and apply overrides.

    Parameters
    ----------
    path
        YAML file; None means every default.
    overrides
        Nested mapping merged over the file's content (e.g. ``{"link": {"connect": ...}}`` from
        the command line) before validation.

    Raises
    ------
    ConfigError
        On a missing file, bad YAML, an unknown key or an out-of-range value.
    """
    data: dict = {} if path is None else _plain(read_yaml(path))
    if path is not None:
        data = _vehicle_beside_config(data, Path(path))
    source = str(path) if path is not None else "<defaults>"
    for section, values in (overrides or {}).items():
        if isinstance(values, dict):
            current = data.get(section)
            if current is not None and not isinstance(current, dict):
                raise ConfigError(source, section, current, "must be a mapping of keys to values")
            merged = dict(current or {})
            merged.update(values)
            data[section] = merged
        else:
            data[section] = values
    return from_mapping(ServiceConfig, data, source=source)


def load_vehicle_for(config: ServiceConfig) -> VehicleProfile:
    """The vehicle profile the config names (ConfigError naming ``vehicle`` when missing).

    With ``vehicle: from_autopilot`` this is the profile used until the flight controller's
    parameters are read: the fallback if one is given, else the base profile at the given
    mass (the service holds its inputs until the parameters arrive).
    """
    if config.vehicle == FROM_AUTOPILOT:
        settings = config.autopilot_vehicle
        if settings.fallback is not None:
            return _load_named(settings.fallback, "autopilot_vehicle.fallback")
        base = _load_named(settings.base, "autopilot_vehicle.base")
        return dataclasses.replace(base, mass_kg=settings.mass_kg)
    return _load_named(config.vehicle, "vehicle")


def _load_named(name: str, key: str) -> VehicleProfile:
    try:
        return load_vehicle(name)
    except ConfigError as exc:
        raise ConfigError(
            exc.source, f"{key}{'.' + exc.key if exc.key else ''}", exc.value, exc.allowed
        ) from None


def config_reference() -> str:
    """Markdown table of every key of :class:`ServiceConfig` (for docs/config-reference.md)."""
    lines = ["| key | type | default | meaning |", "| --- | --- | --- | --- |"]
    for key, type_name, default, text in describe(ServiceConfig):
        lines.append(f"| `{key}` | {type_name} | `{default}` | {text.replace('|', '/')} |")
    return "\n".join(lines) + "\n"


def _vehicle_beside_config(data: dict, path: Path) -> dict:
    """A relative profile path in ``vehicle:`` is taken from the config file's folder (a
    built-in name has no suffix and stays as it is)."""
    vehicle = data.get("vehicle")
    if isinstance(vehicle, str) and Path(vehicle).suffix and not Path(vehicle).is_absolute():
        return {**data, "vehicle": str(path.parent / vehicle)}
    return data


def _plain(data: object) -> dict:
    return dict(data) if isinstance(data, dict) else dict(data or {})  # type: ignore[arg-type]


if __name__ == "__main__":  # python -m tether_companion.service.config > table for the docs
    print(config_reference(), end="")
