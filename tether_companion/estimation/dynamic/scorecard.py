"""The dynamic filter as ``bench estimators`` kinds (provider module of the scorecard registry).

* ``dynamic``: :class:`~tether_companion.estimation.dynamic.estimator.DynamicTetherEstimator`
  with the IMU, attitude, PWM and rangefinder only (the paper 4-state filter's inputs), the
  simulated cable's weight per length (:func:`simulated_cable_weight_n_per_m`) and anchor
  height above the ground (ground-station facts), default :class:`DynamicFilterConfig` otherwise;
* ``dynamic-winch``: the same, also given the winch's paid-out length each tick (the ground
  station's report; the cable model then uses that length and the length is fused);
* ``dynamic-angle``, ``dynamic-winch-angle``: ``dynamic`` / ``dynamic-winch`` also given the
  ground station's cable angle at the anchor (the simulated sensor of
  :mod:`~tether_companion.sim.ground_sensors`, with the scenario's ``ground_station`` errors),
  fused with the service's default ``cable_angle`` section (:data:`ANGLE_CONFIG`: the noise
  and calibration it tells the filter).

Published: the estimate's status is ``ok`` (:attr:`NavigationEstimate.observable`).

Each is compared with the posterior CRLB of its own model and measurement set
(:func:`own_model_bound`: IMU force balance and rangefinder; with the winch length too) beside
the paper's random-walk bound.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from tether_companion.bench.estimators.registry import (
    UNKNOWN_TENSION,
    EstimatorKind,
    FlightContext,
    GroundStation,
    TickOutput,
    register,
)
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.config import DynamicFilterConfig, drag_per_s
from tether_companion.estimation.dynamic.crlb import (
    TrueTrack,
    force_balance_at_truth,
    posterior_bound,
)
from tether_companion.estimation.dynamic.crlb_noise import (
    bound_noise,
    filter_gating,
    residual_density_m2ps3,
)
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.physics.cable import cable_weight_n_per_m
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.service.cable_angle import CableAngleConfig

if TYPE_CHECKING:  # flight.py imports the registry, which imports this provider
    from tether_companion.bench.estimators.flight import FlightRecord

FloatArray = NDArray[np.float64]


ANGLE_CONFIG = CableAngleConfig()
"""What the filter is told of the cable-angle sensor: the service's defaults."""
ANGLE_CALIBRATION = (
    ANGLE_CONFIG.elevation_calibration_std_rad,
    ANGLE_CONFIG.azimuth_calibration_std_rad,
)
"""The calibration errors it is told of, (elevation, azimuth) [rad]."""


def simulated_cable_weight_n_per_m(context: FlightContext) -> float:
    """The weight per length [N/m] of the cable the scenario's simulator flies: what a user
    would configure for that cable (0 for the weightless constant-tension line; telling the
    filter 0.164 N/m there bent its cable model by ``w |p| / (2 T)``: 4 degrees at 4 N and
    3 m, 9 degrees for the take-off's 3 N at 5 m)."""
    return cable_weight_n_per_m(context.scenario.cable, context.gravity_mps2)


def filter_config(context: FlightContext) -> DynamicFilterConfig:
    """The dynamic filter's settings for the scenario: the defaults, the cable's weight and the
    ground station's latencies as its data sheet would give them (the scenario's
    ``ground_station`` section; 0 with it off, where the simulated sensors report the present
    state)."""
    stations = context.scenario.ground_station
    return dataclasses.replace(
        DynamicFilterConfig(),
        cable_weight_n_per_m=simulated_cable_weight_n_per_m(context),
        winch_latency_s=stations.winch_latency_s if stations.enabled else 0.0,
        cable_angle_latency_s=stations.angle_latency_s if stations.enabled else 0.0,
    )


def own_model_bound(
    context: FlightContext,
    record: FlightRecord,
    *,
    winch: bool,
    angle: bool,
    held: Mapping[int, int | None] | None = None,
    start_tick: int = 0,
) -> FloatArray:
    """The posterior CRLB of the filter's 13-state model along ``record``'s truth with the
    kind's measurements (:mod:`~tether_companion.estimation.dynamic.crlb`: force balance and
    rangefinder; ``winch``: the paid-out length at the encoder's reports; ``angle``: the cable
    angle at the sensor's reports; each with the scenario's ``ground_station`` errors, its
    calibration errors estimated beside the state: :func:`~.crlb_noise.bound_noise`),
    diagonal (N, 13). ``held``, ``start_tick``: as
    :func:`~tether_companion.estimation.dynamic.crlb.posterior_bound` (calibration errors held
    as consider states; the recursion's first tick)."""
    dynamic = filter_config(context)
    vehicle = context.vehicle
    constants = ModelConstants(
        vehicle.mass_kg, drag_per_s(dynamic, vehicle), dynamic.cable_weight_n_per_m
    )
    track = TrueTrack(
        specific_force_body_mps2=record.specific_force_body_mps2,
        angle_seen=record.angle_seen,
        winch_seen=record.winch_seen,
        time_s=record.time_s,
        position_ned_m=record.position_ned_m,
        velocity_ned_mps=record.velocity_ned_mps,
        euler_rad=record.euler_rad,
        thrust_n=record.thrust_n,
        cable_force_ned_n=record.cable_force_ned_n,
        wind_ned_mps=record.wind_ned_mps,
        range_seen=record.range_seen,
    )
    gating = filter_gating(dynamic, context.estimator_config(EstimatorConfig()), vehicle)
    force_balance = force_balance_at_truth(track, constants, gating)
    interval_s = dynamic.imu_ticks_per_fusion / context.scenario.sensors.imu_rate_hz
    residual = residual_density_m2ps3(
        force_balance.residuals_mps2, interval_s, dynamic.noise.force_residual_m2ps3
    )
    noise = bound_noise(context.scenario, dynamic, residual, winch=winch, angle=angle)
    return posterior_bound(
        track, constants, noise, gating, force_balance, held=held, start_tick=start_tick
    )


class DynamicKind:
    """:class:`DynamicTetherEstimator` as a :class:`FlightEstimator`.

    Parameters
    ----------
    context
        The scenario (cable weight per length) and the nominal vehicle profile.
    use_winch
        Whether the ground station's paid-out length is given to the filter.
    use_angle
        Whether the ground station's cable angle is given to the filter.
    use_tension
        Whether the winch's load cell is given to the filter
        (:meth:`~.estimator.DynamicTetherEstimator.set_winch_tension_n`: the tension where the
        cable leaves the winch), its noise the scenario's
        ``ground_station.winch_tension_noise_std_n`` (what the winch's data sheet would say).
    """

    def __init__(
        self,
        context: FlightContext,
        use_winch: bool,
        use_angle: bool = False,
        use_tension: bool = False,
    ) -> None:
        dynamic = filter_config(context)
        stations = context.scenario.ground_station
        if use_tension and stations.enabled and stations.winch_tension_noise_std_n > 0.0:
            dynamic = dataclasses.replace(
                dynamic, load_cell_noise_std_n=stations.winch_tension_noise_std_n
            )
        config = context.estimator_config(EstimatorConfig())  # anchor height, rangefinder mounting
        self._estimator = DynamicTetherEstimator(config, context.vehicle, dynamic)
        self._use_winch = use_winch
        self._use_angle = use_angle
        self._use_tension = use_tension

    @property
    def estimator(self) -> DynamicTetherEstimator:
        """The filter (read after a flight: its calibration's release, its counters)."""
        return self._estimator

    @property
    def measurements(self) -> tuple[bool, bool]:
        """Whether it is given the winch's length and the cable angle: the own bound's
        measurement set (:func:`own_model_bound`'s ``winch``, ``angle``)."""
        return self._use_winch, self._use_angle

    def on_attitude(self, sample: AttitudeSample) -> None:
        self._estimator.on_attitude(sample)

    def on_pwm(self, sample: PwmSample) -> None:
        self._estimator.on_pwm(sample)

    def on_range(self, sample: RangeSample) -> None:
        self._estimator.on_range(sample)

    def on_ground_station(self, station: GroundStation) -> None:
        if self._use_winch and station.paid_out_m is not None:
            self._estimator.set_paid_out_length_m(station.paid_out_m, station.time_s)
        if self._use_tension and station.winch_tension_n is not None:
            self._estimator.set_winch_tension_n(station.winch_tension_n, station.time_s)
        angle = station.cable_angle_rad
        if self._use_angle and angle is not None:
            azimuth, elevation = angle
            self._estimator.on_cable_angle(
                elevation, azimuth, station.time_s, ANGLE_CONFIG.noise_std_rad, ANGLE_CALIBRATION
            )

    def on_imu(self, sample: ImuSample) -> TickOutput | None:
        """The tick's estimate; ``None`` (no estimate: not scored) while the filter has no
        state yet (``initialising``: its placeholder zeros with an "unknown" covariance are
        not a position, and scored they made a late start look metres off while their NEES
        claimed nothing)."""
        estimate = self._estimator.on_imu(sample)
        if estimate is None or not self._estimator.initialised:
            return None
        return TickOutput(
            position_ned_m=estimate.position_ned_m,
            position_covariance_m2=estimate.position_covariance_m2,
            published=estimate.observable,
            tension_n=estimate.tension_n,
            tension_variance_n2=estimate.tension_variance_n2,
            velocity_ned_mps=estimate.velocity_ned_mps,
            velocity_covariance_m2ps2=estimate.velocity_covariance_m2ps2,
        )


register(
    EstimatorKind(
        name="dynamic",
        label="dynamic",
        build=lambda context: DynamicKind(context, use_winch=False),
        crlb_model=UNKNOWN_TENSION,
        has_velocity=True,
        has_tension=True,
        description="issue-10 dynamic EKF (velocity, thrust scale, bias, wind), IMU+PWM+range",
        own_bound=lambda context, record: own_model_bound(
            context, record, winch=False, angle=False
        ),
    )
)
register(
    EstimatorKind(
        name="dynamic-winch",
        label="dynamic+winch",
        build=lambda context: DynamicKind(context, use_winch=True),
        crlb_model=UNKNOWN_TENSION,
        has_velocity=True,
        has_tension=True,
        description="the dynamic EKF also given the winch's paid-out length",
        own_bound=lambda context, record: own_model_bound(context, record, winch=True, angle=False),
    )
)
register(
    EstimatorKind(
        name="dynamic-winch-angle-tension",
        label="dynamic+winch+angle+tension",
        build=lambda context: DynamicKind(
            context, use_winch=True, use_angle=True, use_tension=True
        ),
        own_bound=lambda context, record: own_model_bound(context, record, winch=True, angle=True),
        crlb_model=UNKNOWN_TENSION,
        has_velocity=True,
        has_tension=True,
        description="the dynamic+winch+angle kind also given the winch's load cell (the "
        "tension where the cable leaves the winch)",
    )
)
for _name, _label, _winch in (
    ("dynamic-angle", "dynamic+angle", False),
    ("dynamic-winch-angle", "dynamic+winch+angle", True),
):
    register(
        EstimatorKind(
            name=_name,
            label=_label,
            build=lambda context, w=_winch: DynamicKind(context, use_winch=w, use_angle=True),
            own_bound=lambda context, record, w=_winch: own_model_bound(
                context, record, winch=w, angle=True
            ),
            crlb_model=UNKNOWN_TENSION,
            has_velocity=True,
            has_tension=True,
            description=f"the {_label.replace('+angle', '')} kind also given the ground "
            "station's cable angle at the anchor (10 Hz)",
        )
    )
