"""The tension observation's error budget (estimation/tension_budget.py) measured back: drag
against the simulator's drag law, the whole consider covariance against eq. 50 evaluated on
readings with drawn thrust-map, drag, bias and attitude errors, and the estimator's output."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_tension_kf import _feed, _hover_samples

from tether_companion.estimation.tension_budget import (
    BUDGET_COLUMNS,
    TensionErrorBudget,
    drag_force_std_n,
)
from tether_companion.estimation.tension_kf import (
    TensionEstimator,
    TensionFilterConfig,
    observe_tension_ned_values,
)
from tether_companion.frames import rotation_body_to_ned
from tether_companion.physics.aerodynamics import drag_accel_body_mps2
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle

REALISTIC = load_vehicle("realistic-quad")  # rotor drag 0.2 1/s, B = 17 kg/m^2, 1.5 kg


@pytest.mark.parametrize("air_speed_std_mps", [0.3, 1.5, 5.0])
@pytest.mark.parametrize("legacy_linear", [0.0, 0.4])
def test_drag_force_std_is_the_second_moment_of_the_drag_law(air_speed_std_mps, legacy_linear):
    """s_D against the simulator's drag law (physics/aerodynamics.py) on 200000 Gaussian air
    speeds, plus the legacy linear drag c v: within 1 % (the sampling sd of an RMS of a
    heavy-tailed v|v| term at 200000 draws is ~0.3 %)."""
    vehicle = dataclasses.replace(REALISTIC, drag_coefficient_n_s_per_m=legacy_linear)
    rng = np.random.default_rng(5)
    v = air_speed_std_mps * rng.standard_normal(200_000)
    ax, _ = drag_accel_body_mps2(
        v, np.zeros_like(v), vehicle.rotor_drag_per_s, vehicle.ballistic_coefficient_kg_per_m2
    )
    force = vehicle.mass_kg * ax - legacy_linear * v
    assert drag_force_std_n(vehicle, air_speed_std_mps) == pytest.approx(
        float(np.sqrt(np.mean(force**2))), rel=0.01
    )
    assert drag_force_std_n(VehicleProfile(), air_speed_std_mps) == 0.0  # no drag in profile


def test_consider_covariance_is_the_error_of_eq_50_under_drawn_errors():
    """Readings of a drone with a cable force F_c made from drawn errors (thrust map 5 %, air
    speed 1.5 m/s per body-horizontal axis through the realistic drag law, accelerometer bias
    0.1 m/s^2, attitude error 0.02 rad per axis), turned back into a force by eq. 50 with the
    modelled thrust and the erroneous attitude: the error's sample covariance (20000 draws)
    equals (m s_b)^2 I + G G^T within 5 % of its scale."""
    rng = np.random.default_rng(17)
    m = REALISTIC.mass_kg
    config = TensionFilterConfig(
        thrust_scale_std=0.05,
        air_speed_std_mps=1.5,
        accel_bias_std_mps2=0.1,
        attitude_error_std_rad=0.02,
    )
    budget = config.error_budget(REALISTIC)
    roll, pitch, yaw = 0.2, -0.1, 0.7
    rotation = rotation_body_to_ned(roll, pitch, yaw)
    cable = np.array([-3.0, 1.0, 2.0])
    thrust_model = 16.0
    draws = 20_000
    errors = np.empty((draws, 3))
    for i in range(draws):
        thrust = thrust_model * (1.0 + config.thrust_scale_std * rng.standard_normal())
        air = config.air_speed_std_mps * rng.standard_normal(2)
        ax, ay = drag_accel_body_mps2(
            air[0], air[1], REALISTIC.rotor_drag_per_s, REALISTIC.ballistic_coefficient_kg_per_m2
        )
        drag_body = m * np.array([ax, ay, 0.0])
        bias = config.accel_bias_std_mps2 * rng.standard_normal(3)
        f_body = (np.array([0.0, 0.0, -thrust]) + rotation.T @ cable + drag_body) / m + bias
        tilt = Rotation.from_rotvec(config.attitude_error_std_rad * rng.standard_normal(3))
        believed = rotation @ tilt.as_matrix()  # the FC's attitude, body to NED
        observed = observe_tension_ned_values(f_body.tolist(), believed.T.tolist(), thrust_model, m)
        errors[i] = np.array(observed) - cable
    g = np.array(budget.factor(rotation.T.tolist(), thrust_model, cable.tolist())).reshape(
        3, BUDGET_COLUMNS
    )
    expected = budget.bias_force_std_n**2 * np.eye(3) + g @ g.T
    sample = errors.T @ errors / draws  # zero-mean errors: second moment
    scale = np.sqrt(np.diag(expected))
    np.testing.assert_allclose(
        sample / np.outer(scale, scale), expected / np.outer(scale, scale), atol=0.05
    )
    assert np.allclose(errors.mean(axis=0), 0.0, atol=3.0 * scale.max() / math.sqrt(draws) + 0.01)


def test_estimator_reports_its_budget_beside_the_filters_variance(rng):
    """Before the first observation no budget; after it the covariance is the filter's white
    noise plus (m s_b)^2 I plus G G^T at the current attitude and thrust, the magnitude's
    variance its projection on the force."""
    config = TensionFilterConfig()
    est = TensionEstimator(config, REALISTIC)
    cable = np.array([-3.0, 1.0, 2.5])
    out = None
    for k in range(400):
        out = _feed(est, *_hover_samples(k * 0.005, cable, rng, 0.1, vehicle=REALISTIC))
    assert out is not None and out.valid
    budget = TensionErrorBudget.of(REALISTIC, 0.05, 1.5, 0.1, 0.005)
    assert est.budget == budget
    g = out.consider_factor_n
    assert g.shape == (3, BUDGET_COLUMNS) and np.abs(g).max() > 0.1
    expected = (out.variance_n2 + (REALISTIC.mass_kg * 0.1) ** 2) * np.eye(3) + g @ g.T
    np.testing.assert_allclose(out.covariance_ned_n2, expected, rtol=1e-12)
    u = out.tension_ned_n / out.magnitude_n
    assert out.magnitude_variance_n2 == pytest.approx(float(u @ expected @ u), rel=1e-12)
    # the thrust column is s_T T_hat along body down: about 5 % of the hover thrust
    thrust_column = g[:, 0]
    hover = np.linalg.norm(np.array([0.0, 0.0, REALISTIC.mass_kg * 9.80665]) + cable)
    assert np.linalg.norm(thrust_column) == pytest.approx(0.05 * hover, rel=0.02)
