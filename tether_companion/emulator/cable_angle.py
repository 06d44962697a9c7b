"""The ground station's cable-angle sensor, emulated: DEBUG_VECT from the simulated cable.

A real sensor at the anchor (an encoder gimbal the cable runs through, or a camera looking up
the cable) reports the direction in which the cable leaves the anchor, at ~10 Hz, from its own
system/component id, stamped in its own clock; the autopilot routes the frames unchanged to
the companion. :class:`EmulatedCableAngle` does that from the simulator's cable
(:func:`~tether_companion.physics.cable_anchor.anchor_direction_ned`: the catenary's tangent at
the anchor, the straight line for a weightless cable) in the service's convention
(:mod:`~tether_companion.service.cable_angle`: ``x`` azimuth from north toward east, ``y``
elevation up, [rad]). Its errors and rate are the offline simulator's sensor
(:class:`~tether_companion.sim.ground_sensors.GroundSensors`, the scenario's ``ground_station``
section): off, a white direction noise ``angle_noise_std_rad`` per axis (so the azimuth's is
that over cos(elevation)); on, as the realistic scenarios have it, also the per-flight azimuth
and elevation biases, the latency and the encoder's steps. Its draws come from the sensors'
own generators (seeded from the scenario's seed): switching it on does not change the flight.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

from tether_companion.config import spec
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.physics.cable_anchor import anchor_direction_ned
from tether_companion.sim.ground_sensors import GroundSensors
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator


@dataclass(frozen=True)
class EmulatedCableAngleConfig:
    """The ``emulator.cable_angle`` section: a cable-angle sensor sending DEBUG_VECT (its rate
    and errors: the scenario's ``ground_station`` section)."""

    enabled: bool = spec(False, doc="send the cable's direction at the anchor as DEBUG_VECT")
    system_id: int = spec(255, minimum=1, maximum=255, doc="the sensor's MAVLink system id")
    component_id: int = spec(
        dialect.MAV_COMP_ID_PERIPHERAL,
        minimum=0,
        maximum=255,
        doc="its component id (158: peripheral)",
    )
    message_name: str = spec("CABLE_ANG", doc="DEBUG_VECT name (1-10 characters)")


class EmulatedCableAngle:
    """Builds the sensor's DEBUG_VECT frames (see the module docstring).

    Parameters
    ----------
    config
        The ``emulator.cable_angle`` section.
    scenario
        The simulated world (its ``ground_station`` rate).
    sensors
        The ground station's sensors of this flight (shared with the winch).
    unix_time_at_start_s
        UNIX time of simulation time 0 [s]: the sensor stamps in UNIX time (its own clock).
    """

    def __init__(
        self,
        config: EmulatedCableAngleConfig,
        scenario: Scenario,
        sensors: GroundSensors,
        unix_time_at_start_s: float,
    ) -> None:
        self.config = config
        self._encoder = FrameEncoder(config.system_id, config.component_id)
        self._sensors = sensors
        self._name = config.message_name.encode("ascii")
        self._unix0_s = unix_time_at_start_s
        self.period_s = 1.0 / scenario.ground_station.angle_rate_hz
        self.next_s = 0.0
        """Simulation time of the next report [s]."""
        self.sent = 0

    def frame(self, sim: Simulator) -> bytes | None:
        """The next DEBUG_VECT frame, measured now (the sensors have recorded the state now;
        None while the cable has no direction: released, or the drone at the anchor);
        schedules the one after."""
        self.next_s = sim.time_s + self.period_s
        angle = self._sensors.cable_angle_rad(sim.time_s, partial(anchor_direction_ned, sim.cable))
        if angle is None:
            return None
        azimuth, elevation = angle
        msg = dialect.MAVLink_debug_vect_message(
            self._name, int((self._unix0_s + sim.time_s) * 1e6), azimuth, elevation, 0.0
        )
        self.sent += 1
        return self._encoder.encode(msg)
