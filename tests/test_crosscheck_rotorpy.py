"""Our physics against rotorpy's (PyPI ``rotorpy``, code we did not write).

Bounds and why the two differ are written in docs/simulator.md, "rotorpy cross-check".
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

pytest.importorskip(
    "rotorpy", reason="rotorpy is not installed: pip install 'tether-companion[crosscheck]'"
)

from tether_companion.bench.estimators.tasks import FlightTask, score_flight  # noqa: E402
from tether_companion.crosscheck.rotorpy_sim import (  # noqa: E402
    FLIP,
    RotorpySimulator,
    hover_thrust_per_rotor_n,
    require_rotorpy,
    rotorpy_params,
)
from tether_companion.physics.rigid_body import RigidBody  # noqa: E402
from tether_companion.physics.vehicle import load_vehicle  # noqa: E402
from tether_companion.sim.scenario import load_scenario  # noqa: E402
from tether_companion.sim.simulator import Simulator  # noqa: E402

GRAVITY = 9.80665


def _vehicle():
    """realistic-quad: rotor drag mu 0.2 1/s, body drag B 17 kg/m^2 (ArduPilot's models)."""
    return load_vehicle("realistic-quad")


def _our_drag_body_n(vehicle, body_velocity_frd, thrust_per_motor_n):
    """Our rigid body's non-thrust force at level attitude, no wind, FRD [N]."""
    body = RigidBody(vehicle, gravity_mps2=GRAVITY)
    n = vehicle.n_motors
    body.set_state(
        [0.0, 0.0, -5.0, *body_velocity_frd, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        + [thrust_per_motor_n] * n
    )
    specific = np.array(body.specific_force_body_mps2())
    return vehicle.mass_kg * specific + np.array((0.0, 0.0, n * thrust_per_motor_n))


def _rotorpy_drag_body_n(vehicle, body_velocity_frd, thrust_per_motor_n):
    """rotorpy's non-thrust force (rotor H force, inflow, parasitic drag; its translational
    lift taken out) FRD [N], and its parasitic part alone."""
    params = rotorpy_params(vehicle, GRAVITY)
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


@pytest.mark.parametrize("velocity", [(1.0, 0.0, 0.0), (0.0, -2.0, 0.0), (3.0, 0.0, 0.0)])
def test_drag_force_equals_ours_along_a_body_axis_at_the_hover_rotor_speed(velocity):
    """Horizontal air speed along body x or y, rotors at the hover speed: rotorpy's rotor drag
    ``-n w k_d v`` and parasitic drag ``-|v| c_D v`` equal our ``-m mu v`` and
    ``-rho v|v| m / (2 B)`` (that is how k_d and c_D are set: this checks the frames, signs
    and units of the mapping)."""
    vehicle = _vehicle()
    hover = hover_thrust_per_rotor_n(vehicle, GRAVITY)
    ours = _our_drag_body_n(vehicle, velocity, hover)
    theirs, _ = _rotorpy_drag_body_n(vehicle, velocity, hover)
    assert np.linalg.norm(ours) > 0.2
    np.testing.assert_allclose(theirs, ours, atol=1e-9)


@pytest.mark.parametrize("velocity", [(1.2, 1.2, 0.0), (1.0, 0.5, 0.0), (0.8, 0.0, 0.5)])
def test_drag_force_differs_off_axis_by_the_quadratic_law_only(velocity):
    """Off the body axes our body drag is per axis (``v_x |v_x|``, ArduPilot's
    EK3_DRAG_BCOEF_X/Y) and rotorpy's uses the norm (``v_x |v|``, with the vertical speed in
    it); the rotor drag still agrees exactly, and the total within 15 % up to 1.7 m/s."""
    vehicle = _vehicle()
    hover = hover_thrust_per_rotor_n(vehicle, GRAVITY)
    ours = _our_drag_body_n(vehicle, velocity, hover)
    theirs, parasitic = _rotorpy_drag_body_n(vehicle, velocity, hover)
    v = np.asarray(velocity)
    k = 0.5 * 1.225 / vehicle.ballistic_coefficient_kg_per_m2 * vehicle.mass_kg
    ours_parasitic = -k * v * np.abs(v) * np.array((1.0, 1.0, 0.0))
    np.testing.assert_allclose(theirs - parasitic, ours - ours_parasitic, atol=1e-9)
    assert np.linalg.norm(theirs - ours) <= 0.15 * np.linalg.norm(ours)


def test_rotor_drag_grows_with_rotor_speed_where_ours_does_not():
    """rotorpy's H force is ``-w k_d v`` per rotor: at 1.44x the hover thrust the rotors
    turn 1.2x faster and drag 1.2x harder; our rotor drag ``-m mu v`` does not depend on
    thrust."""
    vehicle = _vehicle()
    hover = hover_thrust_per_rotor_n(vehicle, GRAVITY)
    velocity = (1.0, 0.0, 0.0)
    theirs_hover, parasitic = _rotorpy_drag_body_n(vehicle, velocity, hover)
    theirs_high, _ = _rotorpy_drag_body_n(vehicle, velocity, 1.44 * hover)
    assert (theirs_high - parasitic)[0] == pytest.approx(1.2 * (theirs_hover - parasitic)[0])
    assert _our_drag_body_n(vehicle, velocity, 1.44 * hover)[0] == pytest.approx(
        _our_drag_body_n(vehicle, velocity, hover)[0]
    )


SHORT_S = 8.0


def _short(name: str, seed: int = 1):
    return dataclasses.replace(load_scenario(name), duration_s=SHORT_S, seed=seed)


def test_specific_force_and_path_agree_in_flight():
    """Both airframes fly the realistic circle (drag, gusts, thrust error, battery sag: the
    same draws) with the same controller and cable: the noise-free specific force differs by
    < 0.1 m/s^2 RMS per axis and the paths by < 0.1 m over 8 s."""
    scenario = _short("realistic-circle")
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
    assert np.all(rms < 0.1), rms
    assert max(path_diff) < 0.1


def test_estimator_scores_within_1_5x_on_both():
    """The 4-state EKF on the realistic circle flown by each airframe (same seed, same
    sensor noise draws): horizontal and vertical RMSE within a factor 1.5 of each other."""
    scenario = _short("realistic-circle", seed=3)
    scores = {
        simulator: score_flight(
            FlightTask("realistic-circle", scenario, ("ekf-4s",), 3.0, 0.5, simulator)
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
        RotorpySimulator(load_scenario("realistic-takeoff-figure8"))
