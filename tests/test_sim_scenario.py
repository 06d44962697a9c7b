"""Scenario files: built-ins load, variants by replace, bad files refused with a clear error."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from tether_companion.config import ConfigError
from tether_companion.resources import SCENARIOS_DIR
from tether_companion.sim.scenario import (
    Scenario,
    load_scenario,
    resolve_scenario_path,
    scenario_from_mapping,
)

BUILT_INS = sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml"))


def test_every_built_in_scenario_loads() -> None:
    assert {"paper-circle", "hover", "elastic-hover", "catenary-hover", "waypoints"} <= set(
        BUILT_INS
    )
    for name in BUILT_INS:
        assert isinstance(load_scenario(name), Scenario)


def test_paper_scenario_is_the_papers_section_6() -> None:
    s = load_scenario("paper-circle")
    assert s.duration_s == 60.0
    assert s.cable.model == "constant_tension" and s.cable.tension_n == 4.0
    assert s.trajectory.kind == "circle"
    assert (s.trajectory.radius_m, s.trajectory.speed_mps) == (2.5, 1.0)
    assert s.sensors.imu_rate_hz == s.sensors.range_rate_hz == 200.0
    assert s.sensors.accel_noise_std_mps2**2 == pytest.approx(0.01)
    assert s.sensors.range_noise_std_m**2 == pytest.approx(0.1)
    assert s.physics_rate_hz >= 500.0


def test_variants_are_made_with_replace() -> None:
    base = load_scenario("paper-circle")
    strong = replace(base, cable=replace(base.cable, tension_n=10.0))
    assert strong.cable.tension_n == 10.0 and base.cable.tension_n == 4.0
    assert strong.trajectory == base.trajectory


def test_a_relative_vehicle_path_resolves_against_the_scenario_file(tmp_path: Path) -> None:
    (tmp_path / "quad.yaml").write_text("name: mine\nmass_kg: 1.2\n")
    (tmp_path / "s.yaml").write_text("vehicle: quad.yaml\n")
    scenario = load_scenario(tmp_path / "s.yaml")
    assert Path(scenario.vehicle) == (tmp_path / "quad.yaml").resolve()


def test_a_mapping_is_read_as_if_from_its_file(tmp_path: Path) -> None:
    (tmp_path / "quad.yaml").write_text("name: mine\nmass_kg: 1.2\n")
    path = tmp_path / "both.yaml"
    scenario = scenario_from_mapping({"vehicle": "quad.yaml", "duration_s": 5.0}, path)
    assert Path(scenario.vehicle) == (tmp_path / "quad.yaml").resolve()
    assert scenario.duration_s == 5.0
    absent = scenario_from_mapping({"vehicle": "other.yaml"}, path)
    assert absent.vehicle == "other.yaml"  # left as written: the vehicle loader reports it
    with pytest.raises(ConfigError) as info:
        scenario_from_mapping({"seed": -1}, path)
    assert info.value.source == str(path) and info.value.key == "seed"


def test_built_in_names_resolve_to_their_files(tmp_path: Path) -> None:
    assert resolve_scenario_path("hover") == SCENARIOS_DIR / "hover.yaml"
    assert resolve_scenario_path(tmp_path / "any.yaml") == tmp_path / "any.yaml"
    with pytest.raises(ConfigError, match="no such built-in"):
        resolve_scenario_path("no-such-scenario")


BAD = [
    ("duratoin_s: 10\n", "duratoin_s", "unknown key"),
    ("cable: {tension_n: -1}\n", "cable.tension_n", ">= 0"),
    ("cable: {model: rope}\n", "cable.model", "one of"),
    ("cable: {tension_n: four}\n", "cable.tension_n", "must be a number"),
    ("cable: {model: elastic, length_m: 200}\n", "cable.length_m", "within"),
    ("sensors: {accel_noise_std_mps2: -0.1}\n", "sensors.accel_noise_std_mps2", ">= 0"),
    ("sensors: {imu_rate_hz: 0}\n", "sensors.imu_rate_hz", "> 0"),
    ("sensors: {range_min_m: 5, range_max_m: 1}\n", "sensors.range_max_m", "> range_min_m"),
    ("trajectory: {kind: circle, radius_m: 0}\n", "trajectory.radius_m", "> 0"),
    (
        "trajectory: {kind: circle, mean_altitude_m: 1, altitude_amplitude_m: 2}\n",
        "trajectory.altitude_amplitude_m",
        "above ground",
    ),
    ("trajectory: {kind: waypoints}\n", "trajectory.waypoints_ned_m", "at least one"),
    ("trajectory: {kind: hover, position_ned_m: [0, 0]}\n", "trajectory.position_ned_m", "3 items"),
    ("physics_rate_hz: 0\n", "physics_rate_hz", ">= 500"),
    ("physics_rate_hz: 400\n", "physics_rate_hz", ">= 500"),
    ("physics_rate_hz: 1000\ncontroller: {rate_hz: 300}\n", "controller.rate_hz", "divide"),
    ("seed: 1.5\n", "seed", "integer"),
    ("duration_s: .nan\n", "duration_s", "finite"),
    ("events: [{time_s: 1, kind: tug}]\n", "events[0].force_ned_n", "required"),
    ("events: [{time_s: 1, kind: release, tension_n: 3}]\n", "events[0].tension_n", "not used"),
    (
        "cable: {model: elastic}\nevents: [{time_s: 1, kind: set_tension, tension_n: 3}]\n",
        "events[0].kind",
        "constant_tension",
    ),
    ("duration_s: 5\nevents: [{time_s: 9, kind: release}]\n", "events[0].time_s", "duration_s"),
    ("controller: {max_tilt_deg: 95}\n", "controller.max_tilt_deg", "<= 80"),
    ("wind: {velocity_ned_m_s: [1, 2, x]}\n", "wind.velocity_ned_m_s[2]", "number"),
    ("initial: {airborne: yes please}\n", "initial.airborne", "true or false"),
    ("trajectory: {kind: none}\n", "initial.position_ned_m", "down must be < 0"),
]


@pytest.mark.parametrize(("text", "key", "fragment"), BAD)
def test_bad_scenario_is_refused_naming_file_key_value_and_allowed(
    tmp_path: Path, text: str, key: str, fragment: str
) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    error = info.value
    assert error.source == str(path)
    assert error.key == key
    assert fragment in error.allowed
    assert str(path) in str(error) and key in str(error)


def test_unknown_name_missing_file_and_broken_yaml_are_config_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such built-in"):
        load_scenario("no-such-scenario")
    with pytest.raises(ConfigError, match="file not found"):
        load_scenario(tmp_path / "absent.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("cable: {model: [\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_scenario(broken)
    listing = tmp_path / "list.yaml"
    listing.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="mapping"):
        load_scenario(listing)


def test_bad_vehicle_is_reported_when_the_simulator_loads_it(tmp_path: Path) -> None:
    from tether_companion.sim.simulator import Simulator

    (tmp_path / "heavy.yaml").write_text("mass_kg: -1.5\n")
    (tmp_path / "s.yaml").write_text("vehicle: heavy.yaml\n")
    with pytest.raises(ConfigError, match="mass_kg"):
        Simulator(load_scenario(tmp_path / "s.yaml"))
