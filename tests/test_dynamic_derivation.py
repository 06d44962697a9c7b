"""The generated models of the dynamic filter: regenerated text, Jacobians against finite
differences, and the force balance against the paper's independent straight-cable model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic import models as models_module
from tether_companion.estimation.tether_models import FourStateModel
from tether_companion.frames import rotation_ned_to_body
from tether_companion.physics.cable import CableConfig, make_cable

sympy = pytest.importorskip("sympy", reason="sympy (test extra) derives the models")
from tether_companion.estimation.dynamic.derivation import derive  # noqa: E402

ROTATION_MODELS = {
    "force_balance_straight",
    "force_balance_catenary",
    "force_balance_grounded",
    "accel_straight",
    "accel_catenary",
    "accel_grounded",
}
PROCESS_MODELS = {
    "force_balance_straight",
    "force_balance_catenary",
    "force_balance_grounded",
    "inertial",
}
ALL_MODELS = [name for name, *_ in derive.models()]
NO_CALIBRATION = [0.0] * (state.N_STATES - state.CALIBRATION.start)
"""The ground station's calibration states at zero (a perfect winch and angle sensor)."""


def test_regenerating_gives_the_committed_file() -> None:
    text = derive.OUTPUT.read_text()
    if f"sympy {sympy.__version__}." not in text:
        pytest.skip(
            f"generated.py was written by another sympy version than {sympy.__version__}; "
            "printing may differ (the finite-difference tests still check the content)"
        )
    assert derive.generate_source() == text, (
        "generated.py is out of date: run python -m "
        "tether_companion.estimation.dynamic.derivation.derive"
    )


def test_regenerating_gives_the_committed_c_file() -> None:
    text = derive.OUTPUT_C.read_text()
    if f"(sympy {sympy.__version__})" not in text:
        pytest.skip(
            f"generated_core.c was written by another sympy version than {sympy.__version__}"
        )
    assert derive.generate_c_source() == text, (
        "generated_core.c is out of date: run python -m "
        "tether_companion.estimation.dynamic.derivation.derive"
    )


def _random_case(rng: np.random.Generator, name: str) -> tuple[list, list, list]:
    x = np.empty(state.N_STATES)
    direction = rng.normal(size=3)
    direction[2] = -abs(direction[2]) - 0.3
    x[state.POSITION] = direction / np.linalg.norm(direction) * rng.uniform(1.0, 20.0)
    x[state.VELOCITY] = rng.normal(scale=2.0, size=3)
    x[state.TENSION] = rng.uniform(0.5, 15.0)
    x[state.SCALE] = rng.uniform(0.8, 1.2)
    x[state.BIAS] = rng.normal(scale=0.2, size=3)
    x[state.WIND] = rng.normal(scale=3.0, size=2)
    x[state.CALIBRATION] = rng.normal(scale=(0.1, 0.01, 0.01, 0.03))
    rotation = rotation_ned_to_body(*rng.uniform(-0.6, 0.6, size=2), rng.uniform(-3, 3))
    if name == "inertial":
        u = [*rotation.ravel(), *rng.normal(scale=3.0, size=3)]
    elif name in ROTATION_MODELS:
        u = [*rotation.ravel(), rng.uniform(5.0, 30.0)]
    elif name == "height_above_ground":
        u = [rng.uniform(-1.0, 3.0)]
    else:
        u = []
    # weight per length: a catenary parameter w |p| / (2 T_ch) up to about 3
    c = [rng.uniform(0.5, 3.0), rng.uniform(0.0, 0.6), rng.uniform(0.01, 1.0)]
    return list(x), u, c


@pytest.mark.parametrize("name", ALL_MODELS)
def test_jacobian_matches_central_differences(name: str) -> None:
    rng = np.random.default_rng(sum(map(ord, name)))
    function = getattr(generated, name)
    for _ in range(20):
        x, u, c = _random_case(rng, name)
        values, jac = function(x, u, c)
        rows = slice(3, 6) if name in PROCESS_MODELS else slice(0, len(values))
        jacobian = np.array(jac, dtype=float).reshape(-1, state.N_STATES)
        numeric = np.empty_like(jacobian)
        for j in range(state.N_STATES):
            step = 1e-6 * max(1.0, abs(x[j]))
            plus, minus = list(x), list(x)
            plus[j] += step
            minus[j] -= step
            numeric[:, j] = (
                np.array(function(plus, u, c)[0])[rows] - np.array(function(minus, u, c)[0])[rows]
            ) / (2 * step)
        np.testing.assert_allclose(jacobian, numeric, rtol=1e-5, atol=1e-6, err_msg=name)


def test_straight_cable_accelerometer_is_the_papers_model() -> None:
    rng = np.random.default_rng(7)
    for _ in range(20):
        x, u, c = _random_case(rng, "accel_straight")
        x[state.SCALE], x[8:11], c[1], c[2] = 1.0, [0.0, 0.0, 0.0], 0.0, 0.0
        rotation = np.array(u[:9]).reshape(3, 3)
        ours, _ = generated.accel_straight(x, u, c)
        paper = FourStateModel(c[0]).accel(np.array([*x[0:3], x[state.TENSION]]), rotation, u[9])[0]
        np.testing.assert_allclose(ours, paper, rtol=1e-12, atol=1e-12)


def test_force_balance_is_the_rotated_specific_force_plus_gravity() -> None:
    """Formulation (a)'s acceleration equals R^T (accelerometer model - bias) + g, and (b)'s
    equals it when fed that specific force: the two formulations share one physics."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, u, c = _random_case(rng, "force_balance_catenary")
        rotation = np.array(u[:9]).reshape(3, 3)
        accel, _ = generated.accel_catenary(x, u, c)
        specific = np.array(accel) - np.array(x[8:11])
        expected = rotation.T @ specific + np.array([0.0, 0.0, 9.80665])
        xdot, _ = generated.force_balance_catenary(x, u, c)
        np.testing.assert_allclose(xdot[3:6], expected, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(xdot[0:3], x[3:6])
        ins, _ = generated.inertial(x, [*u[:9], *accel], c)
        np.testing.assert_allclose(ins[3:6], expected, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize(
    ("span_m", "height_m", "length_m", "weight_n_per_m"),
    [
        (5.0, 3.0, 7.0, 0.98),  # heavy and deep sag, 5.6 N at the drone
        (5.0, 3.0, 5.9, 0.98),  # heavy, nearly taut
        (5.0, 3.0, 7.0, 0.164),  # light, deep sag, 0.9 N
        (8.0, -1.0, 9.0, 0.5),  # the drone below the anchor
        (0.3, 6.0, 6.2, 0.3),  # nearly vertical
    ],
)
def test_catenary_models_match_the_simulators_catenary(
    span_m: float, height_m: float, length_m: float, weight_n_per_m: float
) -> None:
    """Force at the drone, its size, the arc length and the angle at the anchor against
    physics/catenary.py (an independent solver: known length, Newton on the parameter)."""
    from tether_companion.physics.catenary import solve_known_length
    from tether_companion.physics.catenary_forces import end_tensions

    curve = solve_known_length(span_m, height_m, length_m)
    ends = end_tensions(curve, weight_n_per_m)
    bearing = 0.7
    p = np.array([span_m * math.cos(bearing), span_m * math.sin(bearing), -height_m])
    x = [
        *p,
        0,
        0,
        0,
        ends.horizontal_n * np.linalg.norm(p) / span_m,
        1.0,
        0,
        0,
        0,
        0,
        0,
        *NO_CALIBRATION,
    ]
    mass = 1.5
    c = [mass, 0.0, weight_n_per_m]
    xdot, _ = generated.force_balance_catenary(x, [*np.eye(3).ravel(), 0.0], c)
    force = mass * (np.array(xdot[3:6]) - np.array([0.0, 0.0, 9.80665]))
    expected = np.array(
        [
            -ends.horizontal_n * math.cos(bearing),
            -ends.horizontal_n * math.sin(bearing),
            -ends.on_drone_vertical_n,  # that one is up positive
        ]
    )
    np.testing.assert_allclose(force, expected, rtol=1e-9, atol=1e-9)
    (tension,), _ = generated.tension_catenary(x, [], c)
    assert tension == pytest.approx(ends.drone_n, rel=1e-9)
    (length,), _ = generated.winch_length_catenary(x, [], c)
    assert length == pytest.approx(length_m, rel=1e-9)
    (elevation, azimuth), _ = generated.cable_angle_catenary(x, [], c)
    assert elevation == pytest.approx(math.atan2(ends.on_anchor_vertical_n, ends.horizontal_n))
    assert azimuth == pytest.approx(bearing)


def test_the_straight_line_is_the_catenarys_taut_limit() -> None:
    x = [3.0, 4.0, -12.0, 0, 0, 0, 5.0, 1.0, 0, 0, 0, 0, 0, *NO_CALIBRATION]
    light = [1.5, 0.0, 1e-7]
    for name in ("tension", "winch_length", "cable_angle"):
        straight, _ = getattr(generated, f"{name}_straight")(x, [], light)
        catenary, _ = getattr(generated, f"{name}_catenary")(x, [], light)
        np.testing.assert_allclose(catenary, straight, rtol=1e-6, err_msg=name)
    (length,), _ = generated.winch_length_straight(x, [], light)
    assert length == pytest.approx(13.0)


def _cable_force_n(models: models_module.CableModels, x: list, c: list) -> np.ndarray:
    """The cable's force on the drone, NED [N], read from formulation (a) with no thrust."""
    xdot, _ = models.force_balance(x, [*np.eye(3).ravel(), 0.0], c)
    return c[0] * (np.array(xdot[3:6]) - np.array([0.0, 0.0, 9.80665]))


@pytest.mark.parametrize(
    ("span_m", "height_m", "length_m", "density_kg_per_m"),
    [
        (6.5, 3.0, 7.5, 0.0167),  # the realistic sagging circle's far side: 0.15 m on the ground
        (4.5, 3.0, 7.0, 0.0167),  # 1.3 m on the ground
        (5.0, 3.0, 7.0, 0.1),  # heavy
        (6.0, 1.0, 6.5, 0.1),  # low: most of it on the ground
    ],
)
def test_a_cable_resting_on_the_ground_matches_the_simulators(
    span_m: float, height_m: float, length_m: float, density_kg_per_m: float
) -> None:
    """Where the free catenary would dip below the anchor the filter's models (the switch in
    models.py) are the simulator's cable lying on the anchor's level from the anchor to a
    touchdown point (physics/cable.py: touchdown solved by bracketing, the rise by
    physics/catenary.py): force at the drone, its size, the paid-out length, the flat angle."""
    cable = make_cable(
        CableConfig(
            model="catenary",
            length_m=length_m,
            linear_density_kg_per_m=density_kg_per_m,
            stiffness_n_per_m=100.0,
        )
    )
    bearing = -2.0
    p = np.array([span_m * math.cos(bearing), span_m * math.sin(bearing), -height_m])
    expected = np.array(cable.force_components(*p, 0.0, 0.0, 0.0))
    pull = math.hypot(expected[0], expected[1])
    x = [*p, 0, 0, 0, pull * np.linalg.norm(p) / span_m, 1.0, 0, 0, 0, 0, 0, *NO_CALIBRATION]
    c = [1.5, 0.0, density_kg_per_m * 9.80665]
    assert models_module.rests_on_ground(x, c)
    cable_models = models_module.CATENARY
    np.testing.assert_allclose(_cable_force_n(cable_models, x, c), expected, rtol=1e-8)
    (tension,), _ = cable_models.tension(x, [], c)
    assert tension == pytest.approx(cable.tension_n, rel=1e-8)
    (length,), _ = cable_models.winch_length(x, [], c)
    assert length == pytest.approx(length_m, rel=1e-8)
    (elevation, azimuth), _ = cable_models.cable_angle(x, [], c)
    assert elevation == 0.0
    assert azimuth == pytest.approx(bearing)
    # the free catenary at the same tension misses the length by more than the winch's
    # 5 cm noise: the error this model removed (the filter pulled its tension to match)
    (free_length,), _ = generated.winch_length_catenary(x, [], c)
    assert free_length - length_m > 0.05


def test_the_free_and_the_grounded_cable_meet_where_the_lowest_point_is_the_anchor() -> None:
    """At the switch (the free curve's lowest point at the anchor, touchdown at the anchor)
    both variants give the same values, and the same Jacobians for the force, the tension and
    the length: no jump for the filter. The anchor's elevation has a kink there (it stays 0
    while the cable lies on the ground), so only its value is compared."""
    from tether_companion.physics.catenary import solve_lowest_point_at_anchor
    from tether_companion.physics.catenary_forces import end_tensions

    span, height, weight = 5.0, 3.0, 0.5
    curve = solve_lowest_point_at_anchor(span, height)
    pull = end_tensions(curve, weight).horizontal_n
    p = np.array([span, 0.0, -height])
    x = [*p, 0.2, -0.1, 0.0, pull * np.linalg.norm(p) / span, 1.0, 0, 0, 0, 0, 0, *NO_CALIBRATION]
    c = [1.5, 0.2, weight]
    u_rotation = [*rotation_ned_to_body(0.1, -0.2, 0.5).ravel(), 14.0]
    for name, u in (
        ("force_balance", u_rotation),
        ("accel", u_rotation),
        ("tension", []),
        ("winch_length", []),
        ("cable_angle", []),
    ):
        free_value, free_jac = getattr(generated, f"{name}_catenary")(x, u, c)
        ground_value, ground_jac = getattr(generated, f"{name}_grounded")(x, u, c)
        np.testing.assert_allclose(ground_value, free_value, atol=1e-6, err_msg=name)
        if name != "cable_angle":
            np.testing.assert_allclose(ground_jac, free_jac, atol=1e-4, err_msg=name)


@pytest.mark.parametrize("cable", ["straight", "catenary", "grounded"])
def test_the_calibration_states_enter_the_readings_as_the_sensors_apply_them(cable):
    """The winch reads ``offset + (1 + scale) L`` and the angle sensor the angles plus its
    zero errors (``sim/ground_sensors.py``); the other models do not read them."""
    p = [4.0, 1.0, -2.0] if cable != "grounded" else [6.5, 0.5, -1.0]
    x = [*p, 0.3, -0.2, 0.1, 3.0, 1.0, 0, 0, 0, 0, 0, *NO_CALIBRATION]
    c = [1.5, 0.2, 0.3 if cable != "straight" else 0.0]
    calibrated = list(x)
    calibrated[state.WINCH_OFFSET : state.AZIMUTH_ZERO + 1] = [0.1, 0.02, 0.007, -0.026]
    length = getattr(generated, f"winch_length_{cable}")
    assert length(calibrated, (), c)[0][0] == pytest.approx(0.1 + 1.02 * length(x, (), c)[0][0])
    angle = getattr(generated, f"cable_angle_{cable}")
    (el, az), (el_cal, az_cal) = angle(x, (), c)[0], angle(calibrated, (), c)[0]
    assert (el_cal, az_cal) == pytest.approx((el + 0.007, az - 0.026))
    rotation = [*np.eye(3).ravel(), 15.0]
    for name in (f"accel_{cable}", f"tension_{cable}"):
        model = getattr(generated, name)
        u = rotation if name.startswith("accel") else ()
        value, jac = model(calibrated, u, c)
        assert value == model(x, u, c)[0]
        assert not np.reshape(jac, (-1, state.N_STATES))[:, state.CALIBRATION].any()
