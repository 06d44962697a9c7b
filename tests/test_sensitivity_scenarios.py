"""The sensitivity scenarios (sitl/scenarios/sensitivity/, issue 10): the realistic circle with
the thrust map exact and no accelerometer bias, and variants that each change only the error
named in their file name (docs/estimation.md, "Sensitivity to the thrust map and the
accelerometer bias")."""

from __future__ import annotations

from dataclasses import replace

import pytest

from tether_companion.resources import SCENARIOS_DIR
from tether_companion.sim.scenario import Scenario, load_scenario

FOLDER = SCENARIOS_DIR / "sensitivity"


def _load(name: str) -> Scenario:
    return load_scenario(FOLDER / f"{name}.yaml")


def test_the_reference_is_the_realistic_circle_with_the_map_exact_and_no_accel_bias() -> None:
    exact = _load("circle-exact")
    circle = load_scenario("realistic-circle")
    assert exact.propulsion.exact and not circle.propulsion.exact
    assert exact.sensors.accel_bias_mps2 == (0.0, 0.0, 0.0)
    assert exact.sensors.accel_turn_on_bias_std_mps2 == 0.0
    assert exact.sensors.accel_bias_random_walk_mps2_per_sqrt_s == 0.0
    # every other error source of the realistic circle stays on
    unchanged = replace(
        circle,
        propulsion=exact.propulsion,
        sensors=replace(
            circle.sensors,
            accel_turn_on_bias_std_mps2=0.0,
            accel_bias_random_walk_mps2_per_sqrt_s=0.0,
        ),
    )
    assert exact == unchanged


BIAS = 0.15
VARIANTS = {
    "circle-map10": (4.0, 1.1, 0.0),
    "circle-bias15": (4.0, 1.0, BIAS),
    "circle-map10-bias15": (4.0, 1.1, BIAS),
    "circle-1n-exact": (1.0, 1.0, 0.0),
    "circle-0p5n-exact": (0.5, 1.0, 0.0),
    **{f"circle-1n-bias{round(b * 100):02d}": (1.0, 1.0, b) for b in (0.05, 0.1, 0.15, 0.3)},
    **{f"circle-0p5n-bias{round(b * 100):02d}": (0.5, 1.0, b) for b in (0.05, 0.1, 0.15, 0.3)},
}


CALM = {
    f"circle-calm-{t}-{v}": (tension_n, 1.0, bias)
    for t, tension_n in (("1n", 1.0), ("0p5n", 0.5))
    for v, bias in (("exact", 0.0), ("bias30", 0.3))
}


@pytest.mark.parametrize("name", sorted(VARIANTS) + sorted(CALM))
def test_each_variant_changes_only_what_its_name_says(name: str) -> None:
    tension_n, thrust_scale, bias = {**VARIANTS, **CALM}[name]
    exact = _load("circle-exact")
    expected = replace(
        exact,
        cable=replace(exact.cable, tension_n=tension_n),
        propulsion=replace(exact.propulsion, thrust_scale=thrust_scale),
        sensors=replace(exact.sensors, accel_bias_mps2=(bias, bias, bias)),
    )
    if name in CALM:
        assert exact.wind.velocity_ned_m_s != (0.0, 0.0, 0.0) and exact.wind.turbulence_w20_mps > 0
        expected = replace(
            expected,
            wind=replace(exact.wind, velocity_ned_m_s=(0.0, 0.0, 0.0), turbulence_w20_mps=0.0),
        )
    assert _load(name) == expected


def test_every_file_in_the_folder_is_checked() -> None:
    names = {p.stem for p in FOLDER.glob("*.yaml")}
    assert names == set(VARIANTS) | set(CALM) | {"circle-exact"}
