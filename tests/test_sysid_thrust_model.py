"""Thrust-model files and the ThrustInput objects the estimator runs."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from sysid_synthetic import arx_data

from tether_companion.config import ConfigError
from tether_companion.estimation.thrust_input import StaticThrustInput, ThrustInput
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.sysid.structures.arx import ArxOrders, fit_arx
from tether_companion.sysid.structures.base import FitContext
from tether_companion.sysid.structures.static import StaticFit
from tether_companion.sysid.thrust_model import (
    LinearThrust,
    load_thrust_model,
    model_file_mapping,
    save_thrust_model,
)

RANGE = (1000.0, 2000.0)


@pytest.fixture(scope="module")
def arx_fit():
    data = arx_data(np.random.default_rng(2))
    return fit_arx([data], FitContext.from_data([data], RANGE), ArxOrders(2, 2, 1))


@pytest.fixture
def arx_file(tmp_path, arx_fit):
    path = tmp_path / "thrust.yaml"
    save_thrust_model(path, model_file_mapping(arx_fit.to_mapping(), {"fit": 99.0}), "test\nmodel")
    return path


def test_linear_model_round_trip_and_steady_state(arx_file, arx_fit):
    assert arx_file.read_text().startswith("# test\n# model\n")
    thrust = load_thrust_model(arx_file)
    assert isinstance(thrust, LinearThrust) and isinstance(thrust, ThrustInput)
    model = arx_fit.model
    pwm = np.array([1520.0, 1480.0, 1550.0, 1500.0])
    gains = model.b.sum(axis=1) / model.f.sum()
    expected = model.y0_n + gains @ (pwm - model.u0)
    for k in range(50):
        value = thrust.total_thrust_n(pwm, 1.0 + 0.005 * k)
    assert value == pytest.approx(expected, rel=1e-9)


def test_linear_model_follows_its_discrete_simulation(arx_file, arx_fit):
    """PWM changing at the model's sample boundaries, called at 200 Hz: at each boundary the
    output equals the polynomial model simulated at 100 Hz."""
    thrust = load_thrust_model(arx_file)
    rng = np.random.default_rng(9)
    levels = 1500.0 + 40.0 * rng.standard_normal((60, 4))
    levels[:5] = levels[0]
    outputs = []
    for k, pwm in enumerate(levels):
        outputs.append(thrust.total_thrust_n(pwm, 0.01 * k))
        thrust.total_thrust_n(pwm, 0.01 * k + 0.005)
    model = arx_fit.model
    expected = model.y0_n + model.response(levels - model.u0)
    np.testing.assert_allclose(outputs, expected, atol=1e-9)


def test_linear_model_restarts_after_time_jumps(arx_file):
    thrust = load_thrust_model(arx_file)
    hover = np.full(4, 1500.0)
    steady = thrust.total_thrust_n(hover, 5.0)
    thrust.total_thrust_n(np.full(4, 1600.0), 5.02)
    assert thrust.total_thrust_n(hover, 1.0) == pytest.approx(steady)  # back in time
    thrust.total_thrust_n(np.full(4, 1600.0), 1.02)
    assert thrust.total_thrust_n(hover, 9.0) == pytest.approx(steady)  # long pause


def test_linear_model_refuses_bad_pwm(arx_file):
    thrust = load_thrust_model(arx_file)
    with pytest.raises(ValueError):
        thrust.total_thrust_n(np.full(3, 1500.0), 0.0)
    with pytest.raises(ValueError):
        thrust.total_thrust_n(np.array([1500.0, np.nan, 1500.0, 1500.0]), 0.0)
    assert thrust.total_thrust_n(np.full(4, 1000.0), 0.0) >= 0.0


def test_static_model_file_is_a_vehicle_curve(tmp_path):
    curve = ThrustCurve(coefficients_n=(0.01, 0.6, 7.0))
    path = tmp_path / "static.yaml"
    save_thrust_model(path, StaticFit(curve=curve, n_motors=4).to_mapping(), "static")
    thrust = load_thrust_model(path)
    assert isinstance(thrust, StaticThrustInput)
    pwm = np.array([1400.0, 1500.0, 1600.0, 1700.0])
    assert thrust.total_thrust_n(pwm, 0.0) == pytest.approx(float(np.sum(curve.thrust_n(pwm))))


def _mutated(path, **changes):
    data = yaml.safe_load(path.read_text())
    data.update(changes)
    path.write_text(yaml.safe_dump(data))
    return path


def test_bad_model_files(tmp_path, arx_file):
    with pytest.raises(ConfigError, match="file not found"):
        load_thrust_model(tmp_path / "absent.yaml")
    with pytest.raises(ConfigError, match="kind"):
        load_thrust_model(_mutated(arx_file, kind="neural"))
    _mutated(arx_file, kind="linear")
    with pytest.raises(ConfigError, match=r"a = .*stable"):
        load_thrust_model(_mutated(arx_file, a=[[1.2, 0.0], [0.0, 0.5]]))
    with pytest.raises(ConfigError, match="b = .*matrix"):
        load_thrust_model(_mutated(arx_file, a=[[0.5, 0.0], [0.0, 0.5]], b=[[1.0, 2.0]]))
    with pytest.raises(ConfigError, match="sample_time_s"):
        load_thrust_model(_mutated(arx_file, sample_time_s=-0.01))
