"""The typed config loader refuses bad input with a message naming file, key, value, range."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from tether_companion.config import ConfigError, describe, from_mapping, load_yaml, spec
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle


@dataclass(frozen=True)
class Inner:
    rate_hz: float = spec(200.0, exclusive_minimum=0.0, doc="sample rate [Hz]")
    mode: str = spec("a", choices=("a", "b"))


@dataclass(frozen=True)
class Outer:
    mass_kg: float = spec(doc="mass [kg]", exclusive_minimum=0.0)
    count: int = spec(1, minimum=1)
    inner: Inner = spec(default_factory=Inner)
    gains: tuple[float, float, float] = spec((1.0, 2.0, 3.0), minimum=0.0)


def test_valid_mapping_builds_typed_object() -> None:
    cfg = from_mapping(Outer, {"mass_kg": 2, "inner": {"rate_hz": 50}}, source="f.yaml")
    assert cfg.mass_kg == 2.0 and isinstance(cfg.mass_kg, float)
    assert cfg.inner.rate_hz == 50.0 and cfg.inner.mode == "a"


@pytest.mark.parametrize(
    ("data", "key", "fragment"),
    [
        ({"mass_kg": -1}, "mass_kg", "> 0"),
        ({"mass_kg": 1, "masss": 1}, "masss", "unknown key"),
        ({"mass_kg": "heavy"}, "mass_kg", "must be a number"),
        ({"mass_kg": float("nan")}, "mass_kg", "finite"),
        ({"mass_kg": True}, "mass_kg", "must be a number"),
        ({}, "mass_kg", "required"),
        ({"mass_kg": 1, "count": 1.5}, "count", "integer"),
        ({"mass_kg": 1, "inner": {"rate_hz": 0}}, "inner.rate_hz", "> 0"),
        ({"mass_kg": 1, "inner": {"mode": "c"}}, "inner.mode", "one of"),
        ({"mass_kg": 1, "inner": 3}, "inner", "mapping"),
        ({"mass_kg": 1, "gains": [1, 2]}, "gains", "3 items"),
        ({"mass_kg": 1, "gains": [1, -2, 3]}, "gains[1]", ">= 0"),
    ],
)
def test_bad_values_name_file_key_value_and_range(data: dict, key: str, fragment: str) -> None:
    with pytest.raises(ConfigError) as info:
        from_mapping(Outer, data, source="f.yaml")
    message = str(info.value)
    assert message.startswith(f"f.yaml: {key} = ")
    assert fragment in message
    assert info.value.key == key


def test_yaml_file_errors(tmp_path) -> None:
    missing = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError, match="file not found"):
        load_yaml(Outer, missing)
    broken = tmp_path / "broken.yaml"
    broken.write_text("mass_kg: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML at line"):
        load_yaml(Outer, broken)
    scalar = tmp_path / "scalar.yaml"
    scalar.write_text("3\n")
    with pytest.raises(ConfigError, match="mapping"):
        load_yaml(Outer, scalar)


def test_builtin_vehicle_profiles_load_and_can_hover() -> None:
    for name in ("default-quad", "crazyflie"):
        vehicle = load_vehicle(name)
        assert vehicle.thrust_curve.max_thrust_n * vehicle.n_motors > vehicle.mass_kg * 9.80665


def test_vehicle_that_cannot_hover_is_refused() -> None:
    with pytest.raises(ConfigError, match="thrust_curve"):
        from_mapping(VehicleProfile, {"mass_kg": 10.0}, source="heavy.yaml")


def test_describe_lists_nested_keys() -> None:
    keys = [row[0] for row in describe(Outer)]
    assert keys == ["mass_kg", "count", "inner.rate_hz", "inner.mode", "gains"]
