"""One estimation session: ingest -> estimators -> publisher, pure and synchronous.

The live service feeds it the messages it receives, replay feeds it the messages of a .tlog
(or the samples of a dataflash log); both get the same estimates and the same messages to send
for the same input, because nothing here reads a wall clock.

Estimators, all fed the same samples:

* the tether EKF, always: the paper's 3- or 4-state filter
  (:class:`~tether_companion.estimation.pipeline.TetherEstimator`) or, with ``estimator.kind:
  dynamic``, the dynamic filter
  (:class:`~tether_companion.estimation.dynamic.estimator.DynamicTetherEstimator`: position,
  velocity, thrust scale, accelerometer bias, wind), whose own observability status decides
  the published health (:func:`~tether_companion.service.health.dynamic_health`);
* the tension Kalman filter, owned by the tension modes (:class:`TensionModeSession`), always:
  its force on the drone is published as NAMED_VALUE_FLOAT (``publish.filtered_rate_hz``);
* the catenary position estimator
  (:class:`~tether_companion.estimation.catenary_position.CatenaryPositionEstimator`) on the
  filtered tension, when ``position.source`` is ``catenary`` (then its position is what
  VISION_POSITION_ESTIMATE carries) or ``position.catenary_beside`` is set. The paid-out length
  is ``catenary.default_length_m`` (case 2, ``known_length``), or none is needed (case 1).

The ground station's winch (``winch.enabled``, :mod:`~tether_companion.service.winch`) feeds
the EKF its paid-out length and, with ``tension.source: winch``, its tension; its cable-angle
sensor (``cable_angle.enabled``, :mod:`~tether_companion.service.cable_angle`) the cable's
direction at the anchor. The flight controller's landed state (EXTENDED_SYS_STATE) gives the
dynamic filter an on-ground sign of its own (ON_GROUND: on the ground, position withheld).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.alignment import InputAligner
from tether_companion.estimation.catenary_position import (
    CatenaryPosition,
    CatenaryPositionEstimator,
)
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.output import NavigationEstimate
from tether_companion.estimation.estimate import Estimate
from tether_companion.estimation.pipeline import TetherEstimator, default_thrust_input
from tether_companion.estimation.tension_kf import TensionEstimate
from tether_companion.estimation.thrust_input import (
    MotorLagThrustInput,
    ThrustInput,
)
from tether_companion.mavlink.battery import BATTERY_MESSAGES, battery_voltage_v
from tether_companion.mavlink.framing import MAVLinkMessage
from tether_companion.modes.session import TensionModeSession
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.service.cable_angle import CableAngleFeed, CableAngleReading
from tether_companion.service.catenary_source import CATENARY_UNAVAILABLE, CatenaryEstimate
from tether_companion.service.config import CATENARY, DYNAMIC, ServiceConfig
from tether_companion.service.health import dynamic_health, stale_counts, stale_input_health
from tether_companion.service.ingest import (
    FcPosition,
    Ingest,
    LandedState,
    Sample,
    TensionReading,
)
from tether_companion.service.ingest_frames import FrameIngest
from tether_companion.service.mode_command import addressed_to_us, answer_mode_command
from tether_companion.service.publish import Publication, Publisher
from tether_companion.service.winch import WinchFeed, WinchReading

MODE_TICK_S = 0.02
"""Period of the tension modes' logic [s of flight-controller time] (50 Hz)."""
HEIGHT_STALE_S = 0.5
"""A rangefinder height or FC position older than this [s] is not handed to the modes."""


@dataclass(slots=True)
class Step:
    """What one input produced: messages to send and the publication record, if any."""

    messages: list[MAVLinkMessage] = field(default_factory=list)
    publication: Publication | None = None
    estimate: Estimate | NavigationEstimate | None = None


class EstimationSession:
    """Ingest, estimator and publisher for one configuration.

    Parameters
    ----------
    config
        The service configuration (estimator kind, tension source, limits, publication).
    vehicle
        The vehicle profile (mass, thrust curve, motor count).
    messages
        False when nobody reads the messages to send (replay): the publisher builds none, the
        tension modes do not run, and their tension filter runs only when the catenary
        estimator needs it. The publication records are the same.
    """

    def __init__(
        self, config: ServiceConfig, vehicle: VehicleProfile, *, messages: bool = True
    ) -> None:
        self.config = config
        self.vehicle = vehicle
        self.messages = messages
        self.ingest = Ingest(
            config.link,
            config.inputs,
            config.tension,
            vehicle.n_motors,
            vehicle.thrust_curve.command_unit,
            config.winch,
            config.cable_angle,
        )
        self.frames = FrameIngest(self.ingest)
        """The flight controller's input frames straight to samples (a live UDP link's
        admitted frames: :meth:`on_frame`)."""
        self.catenary_source = config.position.source == CATENARY
        """The published position is the catenary estimator's (else the EKF's)."""
        self.dynamic = config.estimator.kind == DYNAMIC
        """The EKF is the dynamic filter (it says itself when its position is observable)."""
        self.publisher = Publisher(
            config.publish,
            has_tension_state=self.catenary_source or config.estimator.kind != "three_state",
            messages=messages,
        )
        self.aligner = self._new_aligner()
        """Time alignment shared by the EKF and the tension filter: each attitude and PWM
        sample is converted (rotation, thrust) once."""
        self.estimator = self._new_estimator()
        self.winch = WinchFeed(
            config.winch,
            config.tension.source == "winch",
            config.dynamic_filter.cable_weight_n_per_m,
            uses_length=self.dynamic,
        )
        """Hands the winch's readings to the EKF."""
        self.cable_angle = CableAngleFeed(config.cable_angle, uses_angle=self.dynamic)
        """Hands the cable-angle sensor's readings to the EKF."""
        self.catenary = self._new_catenary()
        self.last_catenary: CatenaryPosition | None = None
        """The catenary estimator's latest output (None: not running, or nothing yet)."""
        self.attitude: AttitudeSample | None = None
        self.last_estimate: Estimate | NavigationEstimate | None = None
        self._idle_thrust_n = config.publish.idle_thrust_fraction * vehicle.mass_kg * GRAVITY_MPS2
        self.modes = self._new_modes()
        """Tension-following and landing, fed the same samples; acts only when enabled
        (``tension_mode.enabled``, ``run --tension-mode`` or a ground-station command)."""
        self._height_m = math.nan
        self._height_time_s = -math.inf
        self._fc_position: FcPosition | None = None
        self._next_mode_tick_s = -math.inf
        self.boots = 0
        """Flight-controller reboots seen (each restarts the estimator)."""
        self.commands_refused: dict[str, int] = {}
        """Commands to this component answered DENIED for their sender, by reason."""
        self._feeds_tension = messages or config.position.runs_catenary
        """Whether the tension modes' filter runs (with messages, or for the catenary
        estimator)."""
        self._handlers: dict[type, Callable[[Any], Step]] = {
            ImuSample: self._on_imu,
            AttitudeSample: self._on_attitude,
            PwmSample: self._on_pwm,
            RangeSample: self._on_range,
            TensionReading: self._on_tension_reading,
            FcPosition: self._on_fc_position,
            WinchReading: self._on_winch,
            CableAngleReading: self._on_cable_angle,
            LandedState: self._on_landed_state,
        }
        """The handler of each sample type: one dict lookup per sample, not a chain of
        ``isinstance`` tests."""
        self.send_now: Callable[[list[MAVLinkMessage]], None] | None = None
        """Where the live service wants messages the moment they exist (None: in each
        :class:`Step`, as replay reads them). Set, every sample's messages go there in the
        order they are made and the steps carry none; an IMU tick's estimate goes out before
        its publication record is made and before the tension filter and the modes run (they
        do not change it), so the flight controller's latency does not wait for the
        book-keeping."""
        self._tension_first = self.catenary_source
        """The published position needs this tick's tension (the catenary estimator's): the
        tension filter runs before the EKF's tick, not after the estimate is sent."""

    def restart(self) -> None:
        """Start a fresh estimator run (after a flight-controller reboot)."""
        self.boots += 1
        self.aligner = self._new_aligner()
        self.estimator = self._new_estimator()
        self.publisher.restart()
        self.catenary = self._new_catenary()
        self.last_catenary = None
        self.attitude = None
        self.last_estimate = None
        enabled = self.modes.modes.enabled
        self.modes = self._new_modes()
        self.modes.modes.set_enabled(enabled)
        self._next_mode_tick_s = -math.inf

    def _new_aligner(self) -> InputAligner:
        """One alignment stage for both estimators, with one thrust input: the identified model
        of ``estimator.thrust_model`` if set, else motor lag when ``thrust_dynamics`` asks for
        it, else the static curve."""
        config = self.config
        estimator = config.estimator
        if estimator.thrust_model is None and config.thrust_dynamics == "motor_lag":
            thrust: ThrustInput = MotorLagThrustInput(self.vehicle)
        else:
            thrust = default_thrust_input(estimator, self.vehicle)
        stale = estimator.staleness
        return InputAligner(stale.attitude_s, stale.pwm_s, thrust)

    def _new_modes(self) -> TensionModeSession:
        config = self.config
        return TensionModeSession(
            config.tension_mode,
            config.tension_filter,
            self.vehicle,
            config.link.fc_system_id,
            config.link.fc_component_id,
            aligner=self.aligner,
        )

    def on_fc_heartbeat(self, base_mode: int, custom_mode: int) -> None:
        """The flight controller's HEARTBEAT (armed flag and flight mode, for the modes)."""
        self.modes.on_heartbeat(base_mode, custom_mode)

    def _new_estimator(self) -> TetherEstimator | DynamicTetherEstimator:
        estimator = self.config.estimator
        if self.dynamic:
            return DynamicTetherEstimator(
                estimator, self.vehicle, self.config.dynamic_filter, aligner=self.aligner
            )
        return TetherEstimator(estimator, self.vehicle, aligner=self.aligner)

    def _new_catenary(self) -> CatenaryPositionEstimator | None:
        if not self.config.position.runs_catenary:
            return None
        return CatenaryPositionEstimator(self.config.catenary)

    def on_message(
        self, msg: MAVLinkMessage, local_s: float | None = None, kind: str | None = None
    ) -> Step:
        """Process one received message (any sender, any type) that arrived at local time
        ``local_s`` [s] (None in replay: stamps are not checked against the clock model);
        ``kind`` is ``msg.get_type()`` when the caller has it."""
        if kind is None:
            kind = msg.get_type()
        if kind == "COMMAND_LONG" and addressed_to_us(msg, self.config.link):
            reply = answer_mode_command(
                msg, self.config.security, self.modes.modes, self.commands_refused
            )
            return Step(messages=[reply])
        if kind in BATTERY_MESSAGES and self.ingest.from_flight_controller(msg):
            self.on_battery_voltage_v(battery_voltage_v(msg))
        return self.on_received(self.ingest.receive(msg, local_s, kind))

    def on_frame(self, frame: bytes, local_s: float | None = None) -> Step | None:
        """Process one intact, admitted frame of the flight controller's input streams that
        :meth:`FrameIngest.take <tether_companion.service.ingest_frames.FrameIngest.take>`
        accepted, as :meth:`on_message` processes the message decoded from it; None for a
        frame of one motor-output sample, or of one attitude sample when no mode tick is due
        (it makes no message, publication or estimate: the step :meth:`on_sample` would give
        is empty)."""
        samples = self.frames.samples(frame, local_s)
        if len(samples) == 1 and not self.ingest.rebooted:  # the usual frame: one sample
            sample = samples[0]
            kind = type(sample)
            if kind is PwmSample:
                self._feed_pwm(sample)
                return None
            if kind is AttitudeSample and (
                not self.messages or sample.time_s < self._next_mode_tick_s
            ):  # what _on_attitude does when _mode_tick returns no messages
                self._feed_attitude(sample)
                return None
            return self.on_sample(sample)
        return self.on_received(samples)

    def on_received(self, samples: list[Sample]) -> Step:
        """Process the samples the ingest just released for one message (its
        :meth:`~tether_companion.service.ingest.Ingest.receive`, or
        :class:`~tether_companion.service.ingest_frames.FrameIngest` for a frame): a reboot
        the message confirmed restarts the estimation first."""
        if self.ingest.rebooted:
            self.restart()
        if len(samples) == 1:
            return self.on_sample(samples[0])
        return self._on_samples(samples)

    def _on_samples(self, samples: list[Sample]) -> Step:
        step = Step()
        for sample in samples:
            out = self.on_sample(sample)
            step.messages += out.messages
            if out.publication is not None:
                step.publication = out.publication
            if out.estimate is not None:
                step.estimate = out.estimate
        return step

    def on_battery_voltage_v(self, voltage_v: float) -> None:
        """The flight controller's battery voltage [V]: the thrust input scales each motor
        command by it as the autopilot's compensation assumes (profile ``battery``)."""
        setter = getattr(self.aligner.thrust_input, "set_battery_voltage_v", None)
        if setter is not None:
            setter(voltage_v)

    def on_sample(self, sample: Sample) -> Step:
        """Process one checked sample (from :meth:`on_message` or a dataflash log).

        Every sample goes to the estimators as it arrives: the pipeline aligns the streams (its
        clock moves only with the IMU; a rangefinder sample is fused at the filter's time). The
        tension modes' filter (when it runs: with messages, or for the catenary estimator) is
        fed each attitude and PWM sample before the EKF, each IMU sample after the EKF's tick
        and its publication (before them when the published position is the catenary
        estimator's, which needs the tick's tension); then the modes' logic (with messages).
        """
        step = self._handlers[type(sample)](sample)
        send_now = self.send_now
        if send_now is not None and step.messages:
            send_now(step.messages)
            step.messages = []
        return step

    def _on_imu(self, sample: ImuSample) -> Step:
        if sample.time_s > self.winch.deadline_s:  # the winch fell silent
            self.winch.expire(self.estimator)
        if self._tension_first:
            tension = self._tension_tick(sample)
            step = self._tick(sample, tension)
        else:  # the estimate first (sent at once with send_now), then the tension filter
            step = self._tick(sample, None)
            send_now = self.send_now
            if send_now is not None and step.messages:
                send_now(step.messages)
                step.messages = []
            tension = self._tension_tick(sample)
        if self.messages:
            if tension is not None:
                step.messages += self.publisher.on_filtered(tension, self.last_catenary)
            step.messages += self._mode_tick(sample.time_s)
        return step

    def _tension_tick(self, sample: ImuSample) -> TensionEstimate | None:
        """The tension filter's IMU tick (when it runs) and the catenary position on it."""
        if not self._feeds_tension:
            return None
        tension = self.modes.on_imu(sample)
        if tension is not None and self.catenary is not None:
            self.last_catenary = self.catenary.on_tension(tension)
        return tension

    def _on_attitude(self, sample: AttitudeSample) -> Step:
        self._feed_attitude(sample)
        # Step(messages) positional: a class called with a keyword builds a dict
        return Step(self._mode_tick(sample.time_s)) if self.messages else Step()

    def _feed_attitude(self, sample: AttitudeSample) -> None:
        """The attitude to the modes' tension filter (when it runs) and the EKF."""
        if self._feeds_tension:  # the modes' tension filter itself (the modes only pass it on)
            self.modes.estimator.on_attitude(sample)
        self.attitude = sample
        self.estimator.on_attitude(sample)

    def _on_pwm(self, sample: PwmSample) -> Step:
        self._feed_pwm(sample)
        return Step()

    def _feed_pwm(self, sample: PwmSample) -> None:
        """The motor outputs to the modes' tension filter (when it runs) and the EKF."""
        if self._feeds_tension:
            self.modes.estimator.on_pwm(sample)
        self.estimator.on_pwm(sample)

    def _on_range(self, sample: RangeSample) -> Step:
        self.estimator.on_range(sample)
        if self.messages and self.attitude is not None:  # the modes' height above ground
            tilt = math.cos(self.attitude.roll_rad) * math.cos(self.attitude.pitch_rad)
            self._height_m, self._height_time_s = sample.distance_m * tilt, sample.time_s
        return Step()

    def _on_tension_reading(self, sample: TensionReading) -> Step:
        self.estimator.set_known_tension_n(sample.tension_n, sample.time_s)
        return Step()

    def _on_winch(self, sample: WinchReading) -> Step:
        last = self.last_estimate
        self.winch.on_reading(sample, self.estimator, None if last is None else last.position_ned_m)
        return Step()

    def _on_cable_angle(self, sample: CableAngleReading) -> Step:
        self.cable_angle.on_reading(sample, self.estimator)
        return Step()

    def _on_landed_state(self, sample: LandedState) -> Step:
        """The autopilot's landed state: the dynamic filter's independent on-ground sign (the
        paper's filters have none)."""
        estimator = self.estimator
        if isinstance(estimator, DynamicTetherEstimator):
            estimator.set_autopilot_landed(sample.on_ground, sample.time_s)
        return Step()

    def _on_fc_position(self, sample: FcPosition) -> Step:
        if self.messages:  # the modes' targets are in the flight controller's frame
            self._fc_position = sample
        return Step()

    def _mode_tick(self, t: float) -> list[MAVLinkMessage]:
        """Run the tension modes' logic at ``MODE_TICK_S`` on IMU and ATTITUDE stamps
        ``t`` [s] (either keeps it running when the other stream stops); their filter is fed
        already.

        The height above ground is the tilt-corrected rangefinder when it is fresh, else the
        flight controller's own height above its EKF origin (``-z`` of LOCAL_POSITION_NED; the
        service puts the origin at the anchor, so this is the height above the anchor's
        ground), else unknown (a landing then hands over to the autopilot's LAND)."""
        if t < self._next_mode_tick_s:
            return []
        self._next_mode_tick_s = t + MODE_TICK_S
        # targets are in the flight controller's frame: its own belief, which navigates on our
        # estimate when it has no other source (the raw estimate would carry a tug's bias)
        fc = self._fc_position
        fc_fresh = fc is not None and abs(t - fc.time_s) <= HEIGHT_STALE_S
        position = np.array(fc.position_ned_m) if fc_fresh else np.full(3, math.nan)
        if t - self._height_time_s <= HEIGHT_STALE_S:
            height_m = self._height_m
        else:
            height_m = -position[2]  # nan when the FC position is missing or stale too
        return self.modes.tick(t, position, height_m)

    def _tick(self, sample: ImuSample, tension: TensionEstimate | None) -> Step:
        """One IMU tick: the EKF's estimate, and the publisher fed the chosen source's."""
        estimator = self.estimator
        if self.config.tension.source == "config":
            estimator.set_known_tension_n(self.config.tension.known_tension_n, sample.time_s)
        health = estimator.health
        stale_before = stale_counts(health)
        near_anchor_before = health.near_anchor
        estimate = estimator.on_imu(sample)
        if estimate is not None:
            self.last_estimate = estimate
        # the estimators' own thrust input, converted once per PWM sample by the aligner
        motors_idle = self.aligner.thrust_n < self._idle_thrust_n
        messages: list[MAVLinkMessage] = []
        publication = None
        if not self.catenary_source and estimate is not None:
            stale = stale_input_health(stale_before, stale_counts(estimator.health))
            unavailable = None
            if isinstance(estimate, NavigationEstimate):
                near_anchor = estimator.health.near_anchor > near_anchor_before
                unavailable = dynamic_health(
                    estimate, self.config.publish.short_cable_m, near_anchor
                )
            messages, publication = self.publisher.on_estimate(
                estimate,
                self.attitude,
                inputs_stale=stale,
                motors_idle=motors_idle,
                unavailable=unavailable,
                send_now=self.send_now,
            )
        elif self.catenary_source and tension is not None and self.last_catenary is not None:
            catenary = self.last_catenary
            messages, publication = self.publisher.on_estimate(
                CatenaryEstimate.of(catenary, tension),
                self.attitude,
                inputs_stale=not tension.updated,
                motors_idle=motors_idle,
                unavailable=CATENARY_UNAVAILABLE.get(catenary.status),
                send_now=self.send_now,
            )
        return Step(messages, publication, estimate)  # positional: no keywords' dict a tick
