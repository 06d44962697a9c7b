"""One estimation session: ingest -> tether EKF -> publisher, pure and synchronous.

The live service feeds it the messages it receives, replay feeds it the messages of a .tlog
(or the samples of a dataflash log); both get the same estimates and the same messages to send
for the same input, because nothing here reads a wall clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.pipeline import Estimate, TetherEstimator
from tether_companion.estimation.thrust_input import StaticThrustInput
from tether_companion.mavlink.framing import MAVLinkMessage
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.service.config import ServiceConfig
from tether_companion.service.ingest import Ingest, Sample, TensionReading
from tether_companion.service.publish import Publication, Publisher
from tether_companion.service.thrust import MotorLagThrustInput


@dataclass
class Step:
    """What one input produced: messages to send and the publication record, if any."""

    messages: list[MAVLinkMessage] = field(default_factory=list)
    publication: Publication | None = None
    estimate: Estimate | None = None


class EstimationSession:
    """Ingest, estimator and publisher for one configuration.

    Parameters
    ----------
    config
        The service configuration (estimator kind, tension source, limits, publication).
    vehicle
        The vehicle profile (mass, thrust curve, motor count).
    """

    def __init__(self, config: ServiceConfig, vehicle: VehicleProfile) -> None:
        self.config = config
        self.vehicle = vehicle
        self.ingest = Ingest(config.link, config.inputs, config.tension, vehicle.n_motors)
        self.publisher = Publisher(
            config.publish, has_tension_state=config.estimator.kind == "four_state"
        )
        self.estimator = self._new_estimator()
        self.attitude: AttitudeSample | None = None
        self.last_estimate: Estimate | None = None
        self._held_range: RangeSample | None = None
        self._static_thrust = StaticThrustInput(vehicle)
        self._static_thrust_n = math.nan
        self._idle_thrust_n = config.publish.idle_thrust_fraction * vehicle.mass_kg * GRAVITY_MPS2
        self.boots = 0
        """Flight-controller reboots seen (each restarts the estimator)."""

    def restart(self) -> None:
        """Start a fresh estimator run (after a flight-controller reboot)."""
        self.boots += 1
        self.estimator = self._new_estimator()
        self.publisher.restart()
        self.attitude = None
        self.last_estimate = None
        self._held_range = None

    def _new_estimator(self) -> TetherEstimator:
        identified = self.config.estimator.thrust_model is not None  # the estimator loads it
        lag = self.config.thrust_dynamics == "motor_lag" and not identified
        thrust = MotorLagThrustInput(self.vehicle) if lag else None
        return TetherEstimator(self.config.estimator, self.vehicle, thrust)

    def on_message(self, msg: MAVLinkMessage) -> Step:
        """Process one received message (any sender, any type)."""
        sample = self.ingest.decode(msg)
        if self.ingest.rebooted:
            self.restart()
        if sample is None:
            return Step()
        return self.on_sample(sample)

    def on_sample(self, sample: Sample) -> Step:
        """Process one checked sample (from :meth:`on_message` or a dataflash log).

        The IMU drives the filter's time. A rangefinder sample stamped after the latest IMU tick
        (DISTANCE_SENSOR carries milliseconds, RAW_IMU microseconds, and streams interleave) is
        held and fused right after the first IMU tick that reaches its time, as offline, where
        a range sample is handed over after the IMU sample of the same instant; fusing it at
        once would move the filter ahead of the next IMU sample and make the pipeline drop it.
        """
        estimator = self.estimator
        if isinstance(sample, ImuSample):
            return self._tick(sample)
        if isinstance(sample, AttitudeSample):
            self.attitude = sample
            estimator.on_attitude(sample)
        elif isinstance(sample, PwmSample):
            estimator.on_pwm(sample)
            self._static_thrust_n = self._static_thrust.total_thrust_n(sample.pwm_us, sample.time_s)
        elif isinstance(sample, RangeSample):
            if estimator.time_s >= sample.time_s:  # nan (no IMU yet) compares False: held
                estimator.on_range(sample)
            else:
                self._held_range = sample
        elif isinstance(sample, TensionReading):
            estimator.set_known_tension_n(sample.tension_n, sample.time_s)
        return Step()

    def _tick(self, sample: ImuSample) -> Step:
        estimator = self.estimator
        if self.config.tension.source == "config":
            estimator.set_known_tension_n(self.config.tension.known_tension_n, sample.time_s)
        health = estimator.health
        stale_before = health.stale_attitude + health.stale_pwm + health.stale_tension
        estimate = estimator.on_imu(sample)
        held = self._held_range
        if held is not None and estimator.time_s >= held.time_s:
            self._held_range = None
            estimator.on_range(held)
        if estimate is None:
            return Step()
        health = estimator.health
        stale = health.stale_attitude + health.stale_pwm + health.stale_tension > stale_before
        self.last_estimate = estimate
        messages, publication = self.publisher.on_estimate(
            estimate,
            self.attitude,
            inputs_stale=stale,
            motors_idle=self._static_thrust_n < self._idle_thrust_n,
        )
        return Step(messages=messages, publication=publication, estimate=estimate)
