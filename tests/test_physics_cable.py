"""Cable models: direction, magnitude, slack, spring, damper, weight, winch, catenary."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics import catenary, catenary_forces
from tether_companion.physics.cable import (
    CableConfig,
    CatenaryCable,
    ConstantTensionCable,
    ElasticCable,
    NoCable,
    make_cable,
)

G = GRAVITY_MPS2
positions = st.tuples(
    st.floats(-20.0, 20.0), st.floats(-20.0, 20.0), st.floats(-20.0, -0.1)
).filter(lambda p: math.dist(p, (0.0, 0.0, 0.0)) > 0.1)


@given(positions, st.one_of(st.just(0.0), st.floats(1e-3, 20.0)))
def test_constant_tension_pulls_toward_anchor_with_set_magnitude(
    position: tuple[float, float, float], tension: float
) -> None:
    cable = ConstantTensionCable(tension)
    force = cable.force_on_drone_ned_n(position, (1.0, -2.0, 0.5))
    assert np.linalg.norm(force) == pytest.approx(tension, rel=1e-12, abs=1e-12)
    assert cable.tension_n == tension
    if tension > 0.0:
        unit = np.asarray(position) / np.linalg.norm(position)
        assert force / tension == pytest.approx(-unit, rel=1e-12, abs=1e-12)
    assert cable.paid_out_m == pytest.approx(math.dist(position, (0, 0, 0)))


def test_constant_tension_is_zero_at_anchor_and_after_release() -> None:
    cable = ConstantTensionCable(4.0)
    assert cable.force_components(0.0, 0.0, 0.0, 0.0, 0.0, 0.0) == (0.0, 0.0, 0.0)
    assert cable.tension_n == 0.0
    cable.set_tension_n(7.0)
    assert cable.force_on_drone_ned_n((0.0, 0.0, -2.0), (0, 0, 0)) == pytest.approx([0, 0, 7.0])
    cable.release()
    assert cable.force_components(1.0, 2.0, -3.0, 0.0, 0.0, 0.0) == (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match=">= 0"):
        cable.set_tension_n(-1.0)
    with pytest.raises(ValueError, match=">= 0"):
        cable.set_tension_n(math.nan)


def test_elastic_slack_line_carries_only_the_lifted_weight() -> None:
    density = 0.02
    cable = ElasticCable(10.0, 100.0, 5.0, density)
    position = (3.0, 0.0, -4.0)  # 5 m < 10 m paid out
    force = cable.force_on_drone_ned_n(position, (0.0, 0.0, -3.0))
    weight = density * G * 5.0
    assert cable.tension_n == pytest.approx(weight)
    assert force == pytest.approx(-weight * np.array(position) / 5.0)


def test_elastic_taut_line_is_spring_plus_damper_plus_full_weight() -> None:
    density, k, c = 0.0167, 100.0, 5.0
    cable = ElasticCable(5.0, k, c, density)
    position = np.array([3.0, 0.0, -4.2])
    distance = float(np.linalg.norm(position))
    unit = position / distance
    velocity = 0.3 * unit + np.array([0.0, 1.0, 0.0])  # 0.3 m/s outward along the chord
    force = cable.force_on_drone_ned_n(position, velocity)
    expected = k * (distance - 5.0) + c * 0.3 + density * G * 5.0
    assert cable.tension_n == pytest.approx(expected, rel=1e-12)
    assert force == pytest.approx(-expected * unit, rel=1e-12)


def test_elastic_damper_never_pushes() -> None:
    cable = ElasticCable(5.0, 100.0, 50.0, 0.0)
    position = np.array([0.0, 0.0, -5.01])  # stretched 1 cm: spring 1 N
    force = cable.force_on_drone_ned_n(position, (0.0, 0.0, 2.0))  # moving in fast
    assert cable.tension_n == 0.0
    assert force == pytest.approx([0.0, 0.0, 0.0])


def test_winch_pays_out_and_reels_in_within_limits() -> None:
    cable = ElasticCable(5.0, 100.0, 5.0, 0.01, min_length_m=4.0, spool_length_m=6.0)
    cable.set_winch_rate_mps(0.5)
    for _ in range(100):
        cable.advance(0.01)
    assert cable.paid_out_m == pytest.approx(5.5)
    for _ in range(300):
        cable.advance(0.01)
    assert cable.paid_out_m == 6.0
    cable.set_winch_rate_mps(-1.0)
    for _ in range(500):
        cable.advance(0.01)
    assert cable.paid_out_m == 4.0
    with pytest.raises(ValueError, match="finite"):
        cable.set_winch_rate_mps(math.inf)
    with pytest.raises(ValueError, match="no tension set-point"):
        cable.set_tension_n(3.0)


def test_no_cable_is_free_flight() -> None:
    cable = NoCable()
    assert cable.force_components(1.0, 2.0, -3.0, 0.0, 0.0, 0.0) == (0.0, 0.0, 0.0)
    assert cable.tension_n == 0.0


def _catenary(length_m: float, stiffness: float = 100.0, density: float = 0.05) -> CatenaryCable:
    return CatenaryCable(ElasticCable(length_m, stiffness, 5.0, density), density)


def test_stiff_catenary_matches_the_inextensible_catenary_solution() -> None:
    cable = _catenary(5.2, stiffness=1e9)
    position = (4.0, 0.0, -3.0)
    force = cable.force_on_drone_ned_n(position, (0.0, 0.0, 0.0))
    expected = catenary_forces.force_on_drone_ned_n(position, 5.2, 0.05 * G)
    assert force == pytest.approx(expected, rel=1e-6)
    curve = catenary.solve_known_length(4.0, 3.0, 5.2)
    assert cable.tension_n == pytest.approx(
        catenary_forces.end_tensions(curve, 0.05 * G).drone_n, rel=1e-6
    )
    # the horizontal pull points at the anchor, the vertical one is down
    assert force[0] < 0.0 and force[1] == 0.0 and force[2] > 0.0


def test_catenary_stretch_balances_its_tension() -> None:
    cable = _catenary(5.2, stiffness=50.0)
    cable.force_components(4.0, 0.0, -3.0, 0.0, 0.0, 0.0)
    assert cable.stretch_m == pytest.approx(cable.tension_n / 50.0, rel=1e-6)
    inextensible = catenary_forces.end_tensions(
        catenary.solve_known_length(4.0, 3.0, 5.2), 0.05 * G
    )
    assert cable.tension_n < inextensible.drone_n  # stretched, it sags more and pulls less


def test_catenary_goes_over_smoothly_into_the_taut_line() -> None:
    cable = _catenary(5.0, stiffness=100.0)
    elastic = ElasticCable(5.0, 100.0, 5.0, 0.05)
    tensions = []
    for chord in np.linspace(4.9, 5.3, 81):
        unit = np.array([0.8, 0.0, -0.6])
        cable.force_on_drone_ned_n(chord * unit, (0, 0, 0))
        tensions.append(cable.tension_n)
    steps = np.diff(tensions)
    assert np.all(steps > 0.0)  # pulling away always raises the tension
    assert np.max(steps) < 0.6  # no jump (k * 5 mm = 0.5 N per step when taut)
    # far into the taut regime it is the elastic line (within the cable weight's share)
    cable.force_on_drone_ned_n(5.3 * unit, (0, 0, 0))
    elastic.force_on_drone_ned_n(5.3 * unit, (0, 0, 0))
    assert cable.tension_n == pytest.approx(elastic.tension_n, abs=0.05 * G * 5.0)


def test_catenary_cable_lying_on_the_ground_hangs_from_the_drone() -> None:
    density = 0.05
    cable = _catenary(20.0, density=density)
    force = cable.force_on_drone_ned_n((3.0, 4.0, -2.0), (0, 0, 0))
    # 20 m >= X + H = 7 m: the cable hangs straight down from the drone, the rest lies
    assert force == pytest.approx([0.0, 0.0, density * G * 2.0])
    # a shorter cable touches the ground part-way: some horizontal pull, less than free
    cable = _catenary(5.5, density=density)
    force = cable.force_on_drone_ned_n((4.0, 0.0, -2.0), (0, 0, 0))
    case1 = catenary.solve_lowest_point_at_anchor(4.0, 2.0)
    assert 5.5 > case1.length_m  # a free catenary would dip below the ground
    assert -force[0] > 0.0
    assert -force[0] < density * G * case1.a_m  # less pull than with no cable on the ground
    assert force[2] > 0.0
    assert np.linalg.norm(force) == pytest.approx(cable.tension_n, rel=1e-12)


def test_catenary_on_the_ground_pulls_only_when_stretched() -> None:
    cable = _catenary(5.0)
    assert cable.force_components(4.0, 0.0, 0.0, 0.0, 0.0, 0.0) == (0.0, 0.0, 0.0)
    force = cable.force_on_drone_ned_n((5.1, 0.0, 0.0), (0, 0, 0))
    assert force == pytest.approx([-100.0 * 0.1, 0.0, 0.0])


@settings(max_examples=40, deadline=None)
@given(positions, st.floats(1.0, 30.0))
def test_catenary_force_is_finite_and_never_pushes(
    position: tuple[float, float, float], length: float
) -> None:
    cable = _catenary(length)
    force = cable.force_on_drone_ned_n(position, (0.1, 0.2, 0.3))
    assert np.all(np.isfinite(force))
    assert force[2] >= -1e-9 or np.dot(force, position) < 0.0  # pulls down or toward the anchor
    assert cable.tension_n >= 0.0
    assert np.linalg.norm(force) == pytest.approx(cable.tension_n, rel=1e-6, abs=1e-9)


def test_make_cable_builds_each_model() -> None:
    assert isinstance(make_cable(CableConfig(model="constant_tension")), ConstantTensionCable)
    assert isinstance(make_cable(CableConfig(model="elastic")), ElasticCable)
    assert isinstance(make_cable(CableConfig(model="catenary")), CatenaryCable)
    assert isinstance(make_cable(CableConfig(model="none")), NoCable)
    with pytest.raises(ValueError, match="linear density"):
        make_cable(CableConfig(model="catenary", linear_density_kg_per_m=0.0))
