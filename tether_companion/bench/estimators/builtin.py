"""The estimators of today as scorecard kinds: the paper's EKFs and the catenary estimator.

* ``ekf-4s``: :class:`~tether_companion.estimation.pipeline.TetherEstimator`, 4-state
  (position + unknown tension), ``configs/estimator.yaml`` with the scenario's anchor height
  above the ground and rangefinder mounting offset (:meth:`FlightContext.estimator_config`);
* ``ekf-3s``: the same with the 3-state model, given the load cell's tension;
* ``catenary``: the tension filter (derivative model) and the catenary position estimator
  (known length: the winch's paid-out length, anchor on the ground, the scenario's cable
  weight per length).

Published: what the service would send (:func:`~tether_companion.service.health.assess_health`
with the default publish settings is ``ok``; for the catenary, a valid position, i.e. not
``weak_pull``, that ``assess_health`` passes, as the service's session judges it).
"""

from __future__ import annotations

import dataclasses
import math

from tether_companion.bench.estimators.registry import (
    KNOWN_TENSION,
    UNKNOWN_TENSION,
    EstimatorKind,
    FlightContext,
    GroundStation,
    TickOutput,
    register,
)
from tether_companion.estimation.catenary_position import (
    KNOWN_LENGTH,
    CatenaryPositionConfig,
    CatenaryPositionEstimator,
)
from tether_companion.estimation.config import load_estimator_config
from tether_companion.estimation.pipeline import TetherEstimator
from tether_companion.estimation.tension_kf import TensionEstimator, TensionFilterConfig
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.service.health import OK, assess_health
from tether_companion.service.publish_config import PublishConfig
from tether_companion.service.session import CatenaryEstimate


class PaperEkf:
    """The paper's 3- or 4-state EKF as a :class:`FlightEstimator`."""

    def __init__(self, context: FlightContext, kind: str) -> None:
        config = context.estimator_config(dataclasses.replace(load_estimator_config(), kind=kind))
        self._estimator = TetherEstimator(config, context.vehicle)
        self._has_tension_state = kind == "four_state"
        self._publish = PublishConfig()
        self._ever_ok = False

    def on_attitude(self, sample: AttitudeSample) -> None:
        self._estimator.on_attitude(sample)

    def on_pwm(self, sample: PwmSample) -> None:
        self._estimator.on_pwm(sample)

    def on_range(self, sample: RangeSample) -> None:
        self._estimator.on_range(sample)

    def on_ground_station(self, station: GroundStation) -> None:
        if not self._has_tension_state:
            self._estimator.set_known_tension_n(station.tension_n, station.time_s)

    def on_imu(self, sample: ImuSample) -> TickOutput | None:
        estimate = self._estimator.on_imu(sample)
        if estimate is None:
            return None
        health = assess_health(estimate, self._publish, self._has_tension_state, self._ever_ok)
        self._ever_ok |= health == OK
        covariance = estimate.covariance
        return TickOutput(
            position_ned_m=estimate.position_ned_m,
            position_covariance_m2=estimate.position_covariance_m2,
            published=health == OK,
            tension_n=estimate.tension_n,
            tension_variance_n2=float(covariance[3, 3]) if covariance.shape[0] > 3 else math.nan,
        )


class TensionCatenary:
    """Tension filter + catenary position estimator (known length) as a :class:`FlightEstimator`."""

    def __init__(self, context: FlightContext) -> None:
        cable = context.scenario.cable
        weight = cable.linear_density_kg_per_m * context.gravity_mps2
        defaults = CatenaryPositionConfig()
        self._tension = TensionEstimator(TensionFilterConfig(), context.vehicle)
        self._publish = PublishConfig()
        self._ever_ok = False
        self._catenary = CatenaryPositionEstimator(
            CatenaryPositionConfig(
                case=KNOWN_LENGTH,
                weight_per_length_n_per_m=(
                    weight if weight > 0.0 else defaults.weight_per_length_n_per_m
                ),
                anchor_on_ground=True,
            )
        )

    def on_attitude(self, sample: AttitudeSample) -> None:
        self._tension.on_attitude(sample)

    def on_pwm(self, sample: PwmSample) -> None:
        self._tension.on_pwm(sample)

    def on_range(self, sample: RangeSample) -> None:
        """The catenary estimator does not use the rangefinder."""

    def on_ground_station(self, station: GroundStation) -> None:
        if station.paid_out_m is not None:
            self._catenary.set_paid_out_length_m(station.paid_out_m, station.time_s)

    def on_imu(self, sample: ImuSample) -> TickOutput | None:
        tension = self._tension.on_imu(sample)
        if tension is None:
            return None
        position = self._catenary.on_tension(tension)
        published = False
        if position.valid:
            estimate = CatenaryEstimate.of(position, tension)
            published = assess_health(estimate, self._publish, True, self._ever_ok) == OK
            self._ever_ok |= published
        return TickOutput(
            position_ned_m=position.position_ned_m,
            position_covariance_m2=position.covariance_m2,
            published=published,
            tension_n=tension.magnitude_n if tension.valid else math.nan,
            tension_variance_n2=tension.magnitude_variance_n2,
        )


register(
    EstimatorKind(
        name="ekf-4s",
        label="EKF 4-state",
        build=lambda context: PaperEkf(context, "four_state"),
        crlb_model=UNKNOWN_TENSION,
        has_velocity=False,
        has_tension=True,
        description="the paper's 4-state EKF (position + tension), configs/estimator.yaml",
    )
)
register(
    EstimatorKind(
        name="ekf-3s",
        label="EKF 3-state",
        build=lambda context: PaperEkf(context, "three_state"),
        crlb_model=KNOWN_TENSION,
        has_velocity=False,
        has_tension=False,
        description="the paper's 3-state EKF given the load cell's tension",
    )
)
register(
    EstimatorKind(
        name="catenary",
        label="catenary",
        build=TensionCatenary,
        crlb_model=UNKNOWN_TENSION,
        has_velocity=False,
        has_tension=True,
        description="tension KF + catenary position (known paid-out length, anchor on the ground)",
    )
)
