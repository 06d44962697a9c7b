"""Our physics against rotorpy's (PyPI ``rotorpy``, code we did not write).

Bounds and why the two differ are written in docs/simulator.md, "rotorpy cross-check".
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip(
    "rotorpy", reason="rotorpy is not installed: pip install 'tether-companion[crosscheck]'"
)

from tether_companion.bench.estimators.tasks import FlightTask, score_flight  # noqa: E402
from tether_companion.crosscheck.rotorpy_sim import (  # noqa: E402
    FLIP,
    ROTORPY_GRAVITY_MPS2,
    RotorpySimulator,
    hover_thrust_per_rotor_n,
    require_rotorpy,
    rotorpy_params,
)
from tether_companion.physics.rigid_body import RigidBody  # noqa: E402
from tether_companion.physics.vehicle import load_vehicle  # noqa: E402
from tether_companion.resources import SCENARIOS_DIR, VEHICLES_DIR, builtin_path  # noqa: E402
from tether_companion.sim.scenario import load_scenario  # noqa: E402
from tether_companion.sim.simulator import Simulator  # noqa: E402

DRAG_N_S_PER_M = 0.5
"""The issue's example: default-quad with 0.5 N s/m of linear drag."""


def _drag_vehicle():
    return dataclasses.replace(load_vehicle("default-quad"), drag_coefficient_n_s_per_m=0.5)


def _our_drag_body_n(vehicle, body_velocity_frd, thrust_per_motor_n):
    """Our rigid body's non-thrust force at level attitude, FRD [N]."""
    body = RigidBody(vehicle, gravity_mps2=ROTORPY_GRAVITY_MPS2)
    n = vehicle.n_motors
    body.set_state(
        [0.0, 0.0, -5.0, *body_velocity_frd, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        + [thrust_per_motor_n] * n
    )
    specific = np.array(body.specific_force_body_mps2())
    return vehicle.mass_kg * specific + np.array((0.0, 0.0, n * thrust_per_motor_n))


def _rotorpy_drag_body_n(vehicle, body_velocity_frd, thrust_per_motor_n):
    """rotorpy's non-thrust force (rotor H force, inflow, parasitic drag) FRD [N], and its
    parasitic part alone."""
    params = rotorpy_params(vehicle, DRAG_N_S_PER_M, vehicle.thrust_curve.max_thrust_n)
    multirotor = require_rotorpy()(params)
    speeds = np.full(vehicle.n_motors, math.sqrt(thrust_per_motor_n / params["k_eta"]))
    airspeed_flu = FLIP @ np.asarray(body_velocity_frd, dtype=float)
    force_flu, _ = multirotor.compute_body_wrench(np.zeros(3), speeds, airspeed_flu)
    lift = params["k_h"] * vehicle.n_motors * (airspeed_flu[0] ** 2 + airspeed_flu[1] ** 2)
    thrust = vehicle.n_motors * thrust_per_motor_n + lift
    drag_flu = force_flu - np.array((0.0, 0.0, thrust))
    drag_matrix = np.diag((params["c_Dx"], params["c_Dy"], params["c_Dz"]))
    parasitic_flu = -np.linalg.norm(airspeed_flu) * drag_matrix @ airspeed_flu
    return FLIP @ drag_flu, FLIP @ parasitic_flu


@pytest.mark.parametrize(
    "velocity", [(1.0, 0.0, 0.0), (0.0, -2.0, 0.0), (1.2, 1.2, 0.0), (0.5, 0.0, 0.4)]
)
def test_drag_force_agrees_at_the_hover_rotor_speed(velocity):
    """At the hover rotor speed rotorpy's rotor drag equals our linear drag (that is how
    k_d is set, so this checks frames, signs and units of the mapping); what is left is
    rotorpy's parasitic drag ``-|v| c_D v`` exactly, under 8 % of the drag up to 2 m/s."""
    vehicle = _drag_vehicle()
    hover = hover_thrust_per_rotor_n(vehicle, ROTORPY_GRAVITY_MPS2)
    ours = _our_drag_body_n(vehicle, velocity, hover)
    theirs, parasitic = _rotorpy_drag_body_n(vehicle, velocity, hover)
    np.testing.assert_allclose(ours, -DRAG_N_S_PER_M * np.asarray(velocity), atol=1e-9)
    np.testing.assert_allclose(theirs - parasitic, ours, atol=1e-9)
    assert np.linalg.norm(theirs - ours) <= 0.08 * np.linalg.norm(ours)


def test_rotor_drag_grows_with_rotor_speed_where_ours_does_not():
    """rotorpy's H force is ``-w k_d v`` per rotor: at 1.44x the hover thrust the rotors
    turn 1.2x faster and drag 1.2x harder; our linear drag does not depend on thrust."""
    vehicle = _drag_vehicle()
    hover = hover_thrust_per_rotor_n(vehicle, ROTORPY_GRAVITY_MPS2)
    velocity = (1.0, 0.0, 0.0)
    theirs_hover, parasitic = _rotorpy_drag_body_n(vehicle, velocity, hover)
    theirs_high, _ = _rotorpy_drag_body_n(vehicle, velocity, 1.44 * hover)
    assert (theirs_high - parasitic)[0] == pytest.approx(1.2 * (theirs_hover - parasitic)[0])
    assert _our_drag_body_n(vehicle, velocity, 1.44 * hover)[0] == pytest.approx(
        _our_drag_body_n(vehicle, velocity, hover)[0]
    )


@pytest.fixture(scope="module")
def drag_scenario(tmp_path_factory) -> Path:
    """paper-circle (2.5 m at 1 m/s, 4 N) on default-quad with 0.5 N s/m of drag, 8 s."""
    folder = tmp_path_factory.mktemp("rotorpy")
    profile = yaml.safe_load(builtin_path(VEHICLES_DIR, "default-quad").read_text())
    profile["drag_coefficient_n_s_per_m"] = DRAG_N_S_PER_M
    (folder / "drag-quad.yaml").write_text(yaml.safe_dump(profile))
    scenario = yaml.safe_load(builtin_path(SCENARIOS_DIR, "paper-circle").read_text())
    scenario.update(duration_s=8.0, vehicle="drag-quad.yaml")
    path = folder / "drag-circle.yaml"
    path.write_text(yaml.safe_dump(scenario))
    return path


def test_specific_force_and_path_agree_in_flight(drag_scenario):
    """Both airframes fly the same circle with the same controller and cable: the noise-free
    specific force differs by < 0.05 m/s^2 RMS per axis and the paths by < 0.05 m."""
    scenario = load_scenario(drag_scenario)
    theirs, ours = RotorpySimulator(scenario), Simulator(scenario)
    force_diff, path_diff = [], []
    for k in range(1, int(scenario.duration_s * 100) + 1):
        t = k * 0.01
        theirs.advance_to(t)
        ours.advance_to(t)
        a, b = theirs.truth, ours.truth
        force_diff.append(a.specific_force_body_mps2 - b.specific_force_body_mps2)
        path_diff.append(np.linalg.norm(a.position_ned_m - b.position_ned_m))
    rms = np.sqrt(np.mean(np.square(force_diff), axis=0))
    assert np.all(rms < 0.05), rms
    assert max(path_diff) < 0.05


def test_estimator_scores_within_1_5x_on_both(drag_scenario):
    """The 4-state EKF on the same flight flown by each airframe (same seed, same sensor
    noise draws): horizontal and vertical RMSE within a factor 1.5 of each other."""
    scenario = dataclasses.replace(load_scenario(drag_scenario), seed=3)
    scores = {
        simulator: score_flight(
            FlightTask("drag-circle", scenario, ("ekf-4s",), 3.0, 0.5, simulator)
        ).kinds["ekf-4s"]
        for simulator in ("ours", "rotorpy")
    }
    for key in ("sq_horizontal_m2", "sq_vertical_m2"):
        ours = math.sqrt(getattr(scores["ours"], key) / scores["ours"].estimated)
        theirs = math.sqrt(getattr(scores["rotorpy"], key) / scores["rotorpy"].estimated)
        assert 1.0 / 1.5 <= theirs / ours <= 1.5, (key, ours, theirs)


def test_a_ground_start_is_refused_with_a_clear_message():
    from tether_companion.errors import InputError

    with pytest.raises(InputError, match="airborne starts only"):
        RotorpySimulator(load_scenario("waypoints"))
