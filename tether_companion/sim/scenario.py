"""Scenarios: everything an offline or emulated run needs, loaded from validated YAML.

A scenario file (``sitl/scenarios/NAME.yaml``) has the top-level keys of :class:`Scenario`;
each section is a frozen dataclass, so variants are made with :func:`dataclasses.replace`::

    base = load_scenario("paper-circle")
    strong = replace(base, cable=replace(base.cable, tension_n=10.0))

Unknown keys, wrong types and out-of-range values raise
:class:`tether_companion.config.ConfigError` naming the file, the key, the value and what is
allowed. Every key is listed in docs/simulator.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tether_companion.config import ConfigError, from_mapping, read_yaml, spec
from tether_companion.physics.cable import TENSION_CONTROLLED_MODELS, CableConfig
from tether_companion.resources import SCENARIOS_DIR, builtin_path
from tether_companion.sim.controller import ControllerConfig
from tether_companion.sim.events import Event
from tether_companion.sim.ground import GroundConfig
from tether_companion.sim.ground_sensors import GroundSensorConfig
from tether_companion.sim.propulsion import PropulsionConfig
from tether_companion.sim.sensors import SensorConfig
from tether_companion.sim.trajectory import TrajectoryConfig
from tether_companion.sim.wind import WindConfig

MIN_PHYSICS_RATE_HZ = 500.0
REALISTIC_SCENARIOS: tuple[str, ...] = (
    "realistic-circle",
    "realistic-takeoff-figure8",
    "realistic-gusty-hover",
    "realistic-low-tension",
    "realistic-sagging-hover",
    "realistic-sagging-circle",
    "realistic-heavy-sagging-hover",
    "realistic-yaw-sweep",
)
"""Built-in scenarios with every real-world error source on (docs/simulator.md)."""
WINCH_SAG_SCENARIOS: tuple[str, ...] = (
    "realistic-winch-light-circle-5n",
    "realistic-winch-light-hover-1n",
    "realistic-winch-light-figure8-1n",
    "realistic-winch-heavy-hover-5n",
    "realistic-winch-heavy-circle-1n",
    "realistic-winch-heavy-figure8-5n",
)
"""Built-in realistic scenarios on a constant-tension winch with a heavy cable
(``cable.model: winch_catenary``): issue 10's sagging cables, 0.0167 and 0.1 kg/m, 5 and 1 N at
the anchor, hover, circle and figure-8; not in ``bench estimators``' default list (name them with
``--scenario``)."""


@dataclass(frozen=True)
class HomeConfig:
    """The ``home`` section: where the tether anchor is on Earth (for MAVLink)."""

    latitude_deg: float = spec(32.2828, minimum=-90.0, maximum=90.0, doc="anchor latitude [deg]")
    longitude_deg: float = spec(
        -106.7478, minimum=-180.0, maximum=180.0, doc="anchor longitude [deg]"
    )
    altitude_m: float = spec(1200.0, minimum=-500.0, maximum=9000.0, doc="anchor altitude AMSL [m]")


@dataclass(frozen=True)
class InitialConfig:
    """The ``initial`` section: how the run starts.

    ``airborne: true`` starts armed at the trajectory's first set-point (at ``position_ned_m``
    for trajectory kind ``none``), moving with it, the attitude, the motors and the
    controller's integrators trimmed against gravity and the cable. ``airborne: false`` starts
    landed at ``position_ned_m`` (its down is forced to 0), armed only if ``armed`` is true.
    """

    airborne: bool = spec(True, doc="start in trimmed flight at the trajectory's start")
    position_ned_m: tuple[float, float, float] = spec(
        (0.0, 0.0, 0.0),
        doc="start position when landed (down ignored) or airborne with trajectory none [m]",
    )
    armed: bool = spec(True, doc="armed at the start (a landed start may wait for arm())")
    yaw_deg: float = spec(0.0, minimum=-180.0, maximum=180.0, doc="initial heading [deg]")


@dataclass(frozen=True)
class Scenario:
    """A complete simulation set-up (see docs/simulator.md for every key)."""

    duration_s: float = spec(60.0, exclusive_minimum=0.0, maximum=86400.0, doc="run length [s]")
    seed: int = spec(0, minimum=0, doc="seed of the simulator's random generator")
    physics_rate_hz: float = spec(
        1000.0, minimum=MIN_PHYSICS_RATE_HZ, maximum=20000.0, doc="RK4 integration rate [Hz]"
    )
    vehicle: str = spec("default-quad", doc="vehicle profile: built-in name or YAML path")
    cable: CableConfig = spec(default_factory=CableConfig, doc="tether model")
    sensors: SensorConfig = spec(default_factory=SensorConfig, doc="sensor rates and noise")
    trajectory: TrajectoryConfig = spec(
        default_factory=TrajectoryConfig, doc="reference trajectory"
    )
    controller: ControllerConfig = spec(default_factory=ControllerConfig, doc="cascaded controller")
    wind: WindConfig = spec(default_factory=WindConfig, doc="mean wind and Dryden turbulence")
    propulsion: PropulsionConfig = spec(
        default_factory=PropulsionConfig, doc="thrust-map scale error and battery sag"
    )
    ground: GroundConfig = spec(
        default_factory=GroundConfig, doc="anchor height above the ground, terrain"
    )
    ground_station: GroundSensorConfig = spec(
        default_factory=GroundSensorConfig,
        doc="errors of the ground station's winch encoder and cable-angle sensor",
    )
    events: tuple[Event, ...] = spec((), doc="timed ground-station events")
    home: HomeConfig = spec(default_factory=HomeConfig, doc="anchor location")
    initial: InitialConfig = spec(default_factory=InitialConfig, doc="initial condition")

    def validate(self) -> None:
        """Cross-section checks: controller rate divides the physics rate; events fit the cable."""
        steps = self.physics_rate_hz / self.controller.rate_hz
        if abs(steps - round(steps)) > 1e-9 or round(steps) < 1:
            raise ConfigError(
                "",
                "controller.rate_hz",
                self.controller.rate_hz,
                f"must divide physics_rate_hz ({self.physics_rate_hz}) into whole steps",
            )
        self._validate_above_ground()
        start = self.initial.position_ned_m
        if self.initial.airborne and self.trajectory.kind == "none" and start[2] >= 0.0:
            raise ConfigError(
                "",
                "initial.position_ned_m",
                start,
                "down must be < 0 to start airborne without a trajectory (or airborne: false)",
            )
        for i, event in enumerate(self.events):
            if event.kind == "set_tension" and self.cable.model not in TENSION_CONTROLLED_MODELS:
                raise ConfigError(
                    "",
                    f"events[{i}].kind",
                    event.kind,
                    f"'set_tension' needs cable.model one of {TENSION_CONTROLLED_MODELS} "
                    f"(got {self.cable.model!r})",
                )
            if event.time_s > self.duration_s:
                raise ConfigError(
                    "",
                    f"events[{i}].time_s",
                    event.time_s,
                    f"must be <= duration_s ({self.duration_s})",
                )

    def _validate_above_ground(self) -> None:
        """Hover points and waypoints lie above the mean ground (``anchor_height_m`` below)."""
        ground = self.ground.anchor_height_m
        trajectory = self.trajectory
        allowed = f"down must be <= {ground} (above the ground, ground.anchor_height_m below)"
        if trajectory.kind == "hover" and trajectory.position_ned_m[2] > ground:
            raise ConfigError("", "trajectory.position_ned_m", trajectory.position_ned_m, allowed)
        if trajectory.kind in ("waypoints", "figure8"):
            for i, point in enumerate(trajectory.waypoints_ned_m):
                if point[2] > ground:
                    raise ConfigError("", f"trajectory.waypoints_ned_m[{i}]", point, allowed)

    @property
    def controller_steps(self) -> int:
        """Physics steps per controller update."""
        return round(self.physics_rate_hz / self.controller.rate_hz)


def resolve_scenario_path(path_or_name: str | Path) -> Path:
    """The file of a scenario: ``path_or_name`` itself, or a built-in name's YAML file.

    Raises
    ------
    ConfigError
        When it has no suffix, is no file and names no built-in scenario.
    """
    path = Path(path_or_name)
    if not path.suffix and not path.is_file():
        try:
            path = builtin_path(SCENARIOS_DIR, str(path_or_name))
        except FileNotFoundError as exc:
            raise ConfigError(str(path_or_name), "", str(path_or_name), str(exc)) from None
    return path


MAX_BASE_DEPTH = 8
"""How many ``base:`` scenarios may stand behind one another."""


def _merged(base: Mapping[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``changes`` laid over it, section by section (mappings merge, rest replace)."""
    out = dict(base)
    for key, value in changes.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


def _with_base(data: Mapping[str, Any], path: Path, depth: int = 0) -> Mapping[str, Any]:
    """Resolve a ``base: NAME`` key: the named scenario's keys with this file's laid over."""
    if "base" not in data:
        return data
    base_name = data["base"]
    if not isinstance(base_name, str) or not base_name:
        raise ConfigError(str(path), "base", base_name, "a scenario name or YAML path")
    if depth >= MAX_BASE_DEPTH:
        raise ConfigError(str(path), "base", base_name, f"at most {MAX_BASE_DEPTH} levels of base")
    base_path = Path(base_name)
    if base_path.suffix and not base_path.is_absolute():
        base_path = path.parent / base_path
    base_path = resolve_scenario_path(base_path if base_path.suffix else base_name)
    base = _with_base(read_yaml(base_path), base_path, depth + 1)
    return _merged(base, {k: v for k, v in data.items() if k != "base"})


def scenario_from_mapping(data: Mapping[str, Any], path: Path) -> Scenario:
    """``data`` validated as a :class:`Scenario`, as if read from the file ``path``.

    A relative ``vehicle`` path is resolved against the file's folder. ``base: NAME`` takes
    another scenario's keys and lays this file's over them, section by section. For loaders
    of files that hold more than a scenario (the emulator's section): they pass the rest.

    Raises
    ------
    ConfigError
        When any key is unknown, mistyped or out of range (naming ``path``).
    """
    data = _with_base(data, path)
    vehicle = data.get("vehicle")
    if isinstance(vehicle, str) and Path(vehicle).suffix and (path.parent / vehicle).is_file():
        data = {**data, "vehicle": str((path.parent / vehicle).resolve())}
    return from_mapping(Scenario, data, source=str(path))


def load_scenario(path_or_name: str | Path) -> Scenario:
    """Load a scenario by built-in name (``sitl/scenarios/NAME.yaml``) or file path.

    A relative ``vehicle`` path in the file is resolved against the file's folder.

    Raises
    ------
    ConfigError
        When the file is missing or not YAML, or any key is unknown, mistyped or out of range.
    """
    path = resolve_scenario_path(path_or_name)
    return scenario_from_mapping(read_yaml(path), path)
