"""Settings of the tension Kalman filter (Martins 2019 section 4) and its YAML loader.

The filter itself, its observation (eq. 50) and the sample-driven estimator are in
:mod:`~tether_companion.estimation.tension_kf`; its consider budget in
:mod:`~tether_companion.estimation.tension_budget`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tether_companion.config import ConfigError, load_yaml, spec
from tether_companion.estimation.tension_budget import TensionErrorBudget
from tether_companion.physics.vehicle import VehicleProfile

FloatArray = NDArray[np.float64]

CONSTANT = "constant"
DERIVATIVE = "derivative"


@dataclass(frozen=True)
class TensionFilterConfig:
    """Settings of the tension Kalman filter (Martins 2019 section 4).

    The process noise is a variance added per filter step (one step per IMU sample), as in
    eq. 44; retune it when the IMU rate changes.
    """

    model: str = spec(
        DERIVATIVE,
        choices=(CONSTANT, DERIVATIVE),
        doc="constant (eqs. 48-49) or derivative (eqs. 51-53) tension model",
    )
    derivative_a: float = spec(
        0.9, minimum=-1.0, maximum=1.0, doc="a of eq. 51: weight of the first difference"
    )
    derivative_b: float = spec(
        0.0, minimum=-1.0, maximum=1.0, doc="b of eq. 51: weight of the second difference"
    )
    constant_process_noise_n2: float = spec(
        1e-4, exclusive_minimum=0.0, doc="constant model: tension variance added per step [N^2]"
    )
    derivative_process_noise_n2: float = spec(
        1e-6,
        exclusive_minimum=0.0,
        doc="derivative model: variance added to the newest tension per step [N^2]",
    )
    accel_noise_std_mps2: float = spec(
        0.1, exclusive_minimum=0.0, doc="accelerometer noise per axis [m/s^2], times mass in R"
    )
    thrust_noise_std_n: float = spec(
        0.1, minimum=0.0, doc="total-thrust error [N], added to R on every axis"
    )
    initial_variance_n2: float = spec(
        25.0, exclusive_minimum=0.0, doc="P0 diagonal at (re)start from an observation [N^2]"
    )
    thrust_scale_std: float = spec(
        0.05,
        minimum=0.0,
        maximum=1.0,
        doc="error budget: relative error of the thrust map (scale error, uncompensated "
        "battery sag; a uniform +-10 percent is 0.058) [-]",
    )
    air_speed_std_mps: float = spec(
        1.5,
        minimum=0.0,
        maximum=30.0,
        doc="error budget: air velocity per body-horizontal axis, wind plus flight speed, "
        "times the profile's drag coefficients [m/s]",
    )
    accel_bias_std_mps2: float = spec(
        0.1,
        minimum=0.0,
        maximum=2.0,
        doc="error budget: accelerometer bias per axis after calibration [m/s^2]",
    )
    attitude_error_std_rad: float = spec(
        0.005,
        minimum=0.0,
        maximum=0.5,
        doc="error budget: the flight controller's attitude error per axis [rad]",
    )
    max_observed_tension_n: float = spec(
        200.0,
        exclusive_minimum=0.0,
        doc="observations with a larger magnitude are rejected as absurd [N]",
    )
    attitude_staleness_s: float = spec(
        0.05, exclusive_minimum=0.0, doc="attitude may be this much older/newer than the IMU [s]"
    )
    pwm_staleness_s: float = spec(
        0.05, exclusive_minimum=0.0, doc="PWM may be this much older/newer than the IMU [s]"
    )
    max_gap_s: float = spec(
        0.5, exclusive_minimum=0.0, doc="a longer gap between observations restarts the filter [s]"
    )

    def validate(self) -> None:
        """The derivative model (eq. 52) must not grow exponentially.

        Its characteristic polynomial factors as ``(z - 1)(z^2 - (a + b) z + b)``: the level
        (root 1) and two roots that must lie in the closed unit disc.
        """
        if self.model == DERIVATIVE:
            roots = np.roots([1.0, -(self.derivative_a + self.derivative_b), self.derivative_b])
            radius = float(np.max(np.abs(roots)))
            if radius > 1.0 + 1e-9:
                raise ConfigError(
                    "",
                    "derivative_b",
                    self.derivative_b,
                    f"with derivative_a = {self.derivative_a} the model of eq. 52 diverges "
                    f"(spectral radius {radius:.4f} > 1); choose a, b with stable roots",
                )

    def transition(self) -> FloatArray:
        """State transition ``A``: ``[[1]]`` (eq. 49) or the 3x3 companion matrix of eq. 52."""
        if self.model == CONSTANT:
            return np.ones((1, 1))
        a, b = self.derivative_a, self.derivative_b
        return np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [b, -(a + 2.0 * b), 1.0 + a + b]])

    def process_noise(self) -> FloatArray:
        """``Q`` per step [N^2]; the derivative model's shift rows are exact (no noise)."""
        if self.model == CONSTANT:
            return np.full((1, 1), self.constant_process_noise_n2)
        return np.diag([0.0, 0.0, self.derivative_process_noise_n2])

    def measurement_variance_n2(self, mass_kg: float) -> float:
        """``R`` per axis [N^2]: accelerometer noise times mass, plus thrust error."""
        return (mass_kg * self.accel_noise_std_mps2) ** 2 + self.thrust_noise_std_n**2

    def error_budget(self, vehicle: VehicleProfile) -> TensionErrorBudget:
        """The consider terms of eq. 50 for ``vehicle`` (mass, drag coefficients)."""
        return TensionErrorBudget.of(
            vehicle,
            self.thrust_scale_std,
            self.air_speed_std_mps,
            self.accel_bias_std_mps2,
            self.attitude_error_std_rad,
        )


def load_tension_filter_config(path: str | Path) -> TensionFilterConfig:
    """Load a :class:`TensionFilterConfig` from YAML (raises ConfigError naming the key)."""
    return load_yaml(TensionFilterConfig, path)
