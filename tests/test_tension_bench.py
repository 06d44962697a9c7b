"""``bench tension`` helpers: metrics, equilibrium readings, and the figs 5-7 behaviour."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.bench.tension import (
    equilibrium_readings,
    settling_time_s,
    steady_std,
    synthetic_metrics,
)
from tether_companion.cli import main
from tether_companion.estimation.tension_kf import (
    TensionFilterConfig,
    observe_tension_ned_n,
)
from tether_companion.frames import rotation_body_to_ned
from tether_companion.physics.vehicle import VehicleProfile

VEHICLE = VehicleProfile()


def test_settling_time_and_std_on_a_known_signal():
    times = np.arange(0.0, 10.0, 0.01)
    reference = np.where(times >= 2.0, 1.0, 0.0)
    estimate = np.where(times >= 2.0, 1.0 - np.exp(-(times - 2.0) / 0.5), 0.0)
    # exp(-t/0.5) < 0.05 after t = 0.5 ln 20 = 1.498 s
    assert settling_time_s(times, reference, estimate, 2.0, 0.05) == pytest.approx(1.5, abs=0.011)
    assert settling_time_s(times, reference, reference + 1.0, 2.0, 0.05) == math.inf
    alternating = np.where(np.arange(times.size) % 2 == 0, 1.0, -1.0)
    assert steady_std(times, np.where(times >= 5.0, alternating, 9.0), 5.0) == pytest.approx(1.0)


def test_equilibrium_readings_observe_the_cable_force():
    cable = np.array([-2.0, 1.0, 3.0])
    f_body, roll, pitch, thrust = equilibrium_readings(VEHICLE, cable)
    rotation = rotation_body_to_ned(roll, pitch, 0.0)
    assert np.allclose(observe_tension_ned_n(f_body, rotation, thrust, VEHICLE.mass_kg), cable)


def test_derivative_model_settles_faster_with_less_noise_at_the_defaults():
    """Martins figs 6-7, qualitatively, with the shipped defaults on the synthetic step."""
    base = TensionFilterConfig()
    constant = synthetic_metrics(base.__class__(model="constant"), VEHICLE, 1.0, seed=3)
    derivative = synthetic_metrics(base.__class__(model="derivative"), VEHICLE, 1.0, seed=3)
    assert derivative[0] < constant[0]
    assert derivative[1] < constant[1]


def test_cli_bench_tension_synthetic(capsys):
    assert main(["bench", "tension", "--source", "synthetic"]) == 0
    out = capsys.readouterr().out
    assert "constant" in out and "derivative" in out and "settling" in out


def test_cli_bench_tension_bad_argument(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["bench", "tension", "--step-n", "abc"])
    assert exit_info.value.code == 2
