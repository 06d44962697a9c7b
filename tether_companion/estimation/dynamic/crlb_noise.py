"""The noise the dynamic filter's Cramer-Rao bound (:mod:`.crlb`) assumes: the simulator's error
sources mapped onto the filter's model where they have a place in it, the filter's own
settings where they do not.

==============================  =============================================================
model term                      value
==============================  =============================================================
velocity process noise          the accelerometer's true white noise and its vibration (a
(the accelerometer drives it)   sinusoid of amplitude A, taken as white of variance A^2/2),
                                density ``sigma^2 / imu_rate``
force-balance sample            the same variance plus the white equivalent of the forces
                                the model leaves out, per body axis, measured on the flight:
                                the true specific force minus the model's at the true state
                                (quadratic body drag, vertical gusts, the cable's drag,
                                rotor-drag model error), its mean removed (a constant body
                                force is a bias the state has), ``2 sigma^2 tau`` over the
                                fusion interval (``tau`` its autocorrelation's integral to the
                                first zero); the filter's own ``force_residual_m2ps3`` where
                                the flight has too few samples. The filter's value (0.02
                                m^2/s^3 on each axis) was sized the same way from the
                                turbulence (docs/estimation.md)
bias random walk                the simulator's bias walk plus the flight controller's
                                attitude error as a wandering bias: ``(g theta)^2 2 / tau``
wind random walk                Dryden's horizontal gusts at the scenario's intensity:
                                ``2 sigma_uv^2 V / L_uv`` (0 without turbulence: a constant
                                wind)
position, tension, thrust       the filter's (random walks the simulator does not have: its
scale random walks              tension is a winch's control, its thrust scale a battery's
                                sag, both smooth)
rangefinder                     the true noise (its tilt correction, 1-3 %, left out); the
                                terrain's undulation a state of the height
                                (:class:`~.crlb_nuisance.TerrainNoise`: its standard deviation,
                                correlated over ``wavelength / 2 pi`` along the path; was
                                white until crlb14, which averaged a hovering drone's ground
                                away)
heading error                   the simulated flight controller's attitude error's yaw part
                                (:class:`~.crlb_nuisance.HeadingError`: the heading's sigma
                                and time constant, ``heading_error_*``, else
                                ``attitude_error_*``); its roll and pitch parts are the bias
                                walk above)
winch length                    with the scenario's ``ground_station`` errors: at the
                                encoder's reports, the white variance of its step
                                (``resolution^2 / 12``, at least 1 mm squared), its zero
                                offset and scale error unknown constants with their priors
                                (estimated beside the state); without them the filter's
                                told noise every tick (the simulator's length is then exact:
                                with it the bound would be zero along the cable)
cable angle                     the simulated sensor's direction noise (elevation; azimuth
                                over the elevation's cosine) and its step's
                                ``resolution^2 / 12``, at its reports; with the
                                ``ground_station`` errors its azimuth and elevation zero
                                errors unknown constants with their priors
latencies                       left out: a known delay costs a bound no information (the
                                filter does not compensate it: its own loss)
prior                           the filter's priors for what its first second cannot measure
                                (velocity, thrust scale, bias, wind); none on position and
                                tension (100 m, 100 N: the filter takes them from the data,
                                which the bound accumulates from the first tick)
==============================  =============================================================
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.crlb import BoundNoise, Gating
from tether_companion.estimation.dynamic.crlb_nuisance import (
    CalibrationPrior,
    HeadingError,
    TerrainNoise,
)
from tether_companion.estimation.dynamic.noise import process_noise_density
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.wind import DrydenParameters

FloatArray = NDArray[np.float64]

MIN_WINCH_STD_M = 1e-3
"""Smallest white noise [m] the bound gives an encoder with no step (a finite information)."""
UNINFORMED_POSITION_STD_M = 100.0
UNINFORMED_TENSION_STD_N = 100.0
TERRAIN_WAVELENGTH_PER_CORRELATION = 2.0 * math.pi
"""The simulator's terrain (undulations of wavelength ``lambda`` in random directions,
``sim/ground.py``) is correlated as ``J0(2 pi r / lambda)`` along a line, whose integral is
``lambda / 2 pi``: the bound's Gauss-Markov terrain has that correlation length."""
MIN_RESIDUAL_SAMPLES = 50
"""Fewest force-balance samples (1 s at the fusion rate) to measure the residual's density."""


def accel_variance_mps2(scenario: Scenario) -> float:
    """The accelerometer's white noise and vibration per axis [(m/s^2)^2]."""
    sensors = scenario.sensors
    return sensors.accel_noise_std_mps2**2 + 0.5 * sensors.accel_vibration_amplitude_mps2**2


def wind_density_m2ps3(scenario: Scenario) -> float:
    """Random-walk density of the horizontal wind [m^2/s^3]: Dryden's ``2 sigma^2 / tau``,
    ``tau = L / V`` (``V`` the mean wind or the minimum airspeed); 0 without turbulence."""
    wind = scenario.wind
    if wind.turbulence_w20_mps <= 0.0:
        return 0.0
    dryden = DrydenParameters.low_altitude(wind.turbulence_w20_mps, wind.turbulence_height_m)
    airspeed = max(math.hypot(*wind.velocity_ned_m_s[:2]), wind.min_airspeed_mps)
    sigma, length = dryden.sigma_mps[0], dryden.length_m[0]
    return 2.0 * sigma**2 * airspeed / length


def bias_density_m2ps5(scenario: Scenario) -> float:
    """Random-walk density of the accelerometer bias [(m/s^2)^2/s]: the sensor's walk and the
    attitude error's ``g theta`` wandering over its time constant."""
    sensors = scenario.sensors
    walk = sensors.accel_bias_random_walk_mps2_per_sqrt_s**2
    if sensors.attitude_error_std_rad <= 0.0:
        return walk
    tilt = GRAVITY_MPS2 * sensors.attitude_error_std_rad
    return walk + 2.0 * tilt**2 / sensors.attitude_error_time_constant_s


def residual_density_m2ps3(
    residuals_mps2: FloatArray, interval_s: float, fallback: float
) -> tuple[float, float, float]:
    """White-noise density carrying the information of a correlated force residual, per body
    axis [m^2/s^3]: ``2 sigma^2 tau`` of the mean-removed residual (M, 3) sampled every
    ``interval_s`` [s] (``tau`` the integral of its autocorrelation to the first zero crossing;
    gaps between samples ignored); ``fallback`` on every axis with fewer than
    :data:`MIN_RESIDUAL_SAMPLES` samples."""
    if len(residuals_mps2) < MIN_RESIDUAL_SAMPLES:
        return (fallback, fallback, fallback)
    densities = []
    for axis in range(3):
        x = residuals_mps2[:, axis] - residuals_mps2[:, axis].mean()
        power = float(x @ x)
        if power <= 0.0:
            densities.append(0.0)
            continue
        spectrum = np.fft.rfft(x, 2 * len(x))
        correlation = np.fft.irfft(spectrum * np.conj(spectrum))[: len(x)] / power
        negative = np.flatnonzero(correlation < 0.0)
        end = int(negative[0]) if negative.size else len(x)
        tau_s = float(correlation[:end].sum()) * interval_s
        densities.append(2.0 * (power / len(x)) * tau_s)
    return (densities[0], densities[1], densities[2])


def bound_noise(
    scenario: Scenario,
    dynamic: DynamicFilterConfig,
    residual_density: tuple[float, float, float],
    *,
    winch: bool,
    angle: bool,
) -> BoundNoise:
    """The noise of the bound for ``scenario`` (the table above); ``residual_density``: the
    force residual's white equivalent per body axis [m^2/s^3] (:func:`residual_density_m2ps3`);
    ``winch``, ``angle``: whether the measurement set has the winch length, the cable angle
    (the scenario's ``ground_station`` sensor)."""
    imu_step_s = 1.0 / scenario.sensors.imu_rate_hz
    accel_var = accel_variance_mps2(scenario)
    density = process_noise_density(dynamic)[: state.CALIBRATION.start]  # crlb.CalibrationPrior
    density[state.VELOCITY] = accel_var * imu_step_s
    density[state.BIAS] = bias_density_m2ps5(scenario)
    density[state.WIND] = wind_density_m2ps3(scenario)
    interval_s = imu_step_s * dynamic.imu_ticks_per_fusion
    ground = scenario.ground
    initial = dynamic.initial
    prior = np.empty(len(density))
    prior[state.POSITION] = UNINFORMED_POSITION_STD_M
    prior[state.VELOCITY] = initial.velocity_std_mps
    prior[state.TENSION] = UNINFORMED_TENSION_STD_N
    prior[state.SCALE] = initial.thrust_scale_std
    prior[state.BIAS] = initial.accel_bias_std_mps2
    prior[state.WIND] = initial.wind_std_mps
    sensors = scenario.ground_station
    winch_var = dynamic.winch_length_noise_std_m**2
    angle_var = sensors.angle_noise_std_rad**2
    calibration = None
    if sensors.enabled:
        winch_var = max(sensors.winch_resolution_m**2 / 12.0, MIN_WINCH_STD_M**2)
        angle_var += sensors.angle_resolution_rad**2 / 12.0
        calibration = CalibrationPrior(
            winch_offset_std_m=sensors.winch_zero_offset_std_m if winch else 0.0,
            winch_scale_std=sensors.winch_scale_error_std if winch else 0.0,
            elevation_bias_std_rad=sensors.angle_elevation_bias_std_rad if angle else 0.0,
            azimuth_bias_std_rad=sensors.angle_azimuth_bias_std_rad if angle else 0.0,
        )
    return BoundNoise(
        process_density=density,
        prior_std=prior,
        force_balance_var_mps2=(
            accel_var + residual_density[0] / interval_s,
            accel_var + residual_density[1] / interval_s,
            accel_var + residual_density[2] / interval_s,
        ),
        range_var_m2=scenario.sensors.range_noise_std_m**2,
        winch_var_m2=winch_var if winch else None,
        cable_angle_var_rad2=angle_var if angle else None,
        calibration=calibration,
        heading=HeadingError(
            scenario.sensors.attitude_error_std_per_axis_rad()[2],
            scenario.sensors.attitude_error_time_constant_per_axis_s()[2],
        ),
        terrain=TerrainNoise(
            ground.terrain_std_m, ground.terrain_wavelength_m / TERRAIN_WAVELENGTH_PER_CORRELATION
        ),
    )


def filter_gating(
    dynamic: DynamicFilterConfig, config: EstimatorConfig, vehicle: VehicleProfile
) -> Gating:
    """The filter's fusion rules for the bound (:class:`~.crlb.Gating`)."""
    return Gating(
        ticks_per_fusion=dynamic.imu_ticks_per_fusion,
        min_distance_m=config.min_cable_length_m,
        min_thrust_n=dynamic.min_thrust_fraction * vehicle.mass_kg * GRAVITY_MPS2,
    )
