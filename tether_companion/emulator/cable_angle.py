"""The ground station's cable-angle sensor, emulated: DEBUG_VECT from the simulated cable.

A real sensor at the anchor (an encoder gimbal the cable runs through, or a camera looking up
the cable) reports the direction in which the cable leaves the anchor, at ~10 Hz, from its own
system/component id, stamped in its own clock; the autopilot routes the frames unchanged to
the companion. :class:`EmulatedCableAngle` does that from the simulator's cable
(:func:`~tether_companion.physics.cable_anchor.anchor_direction_ned`: the catenary's tangent at
the anchor, the straight line for a weightless cable) in the service's convention
(:mod:`~tether_companion.service.cable_angle`: ``x`` azimuth from north toward east, ``y``
elevation up, [rad]). Its noise is a direction noise (each reading's direction turned by
``noise_std_rad`` per axis, so the azimuth's is that over cos(elevation)), from its own
generator (seeded from the scenario's seed): switching it on does not change the flight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tether_companion.config import spec
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.physics.cable_anchor import anchor_direction_ned
from tether_companion.sim.ground_sensors import ANGLE_SEED_SALT, noisy_angles
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator


@dataclass(frozen=True)
class EmulatedCableAngleConfig:
    """The ``emulator.cable_angle`` section: a cable-angle sensor sending DEBUG_VECT."""

    enabled: bool = spec(False, doc="send the cable's direction at the anchor as DEBUG_VECT")
    system_id: int = spec(255, minimum=1, maximum=255, doc="the sensor's MAVLink system id")
    component_id: int = spec(
        dialect.MAV_COMP_ID_PERIPHERAL,
        minimum=0,
        maximum=255,
        doc="its component id (158: peripheral)",
    )
    message_name: str = spec("CABLE_ANG", doc="DEBUG_VECT name (1-10 characters)")
    rate_hz: float = spec(10.0, exclusive_minimum=0.0, maximum=200.0, doc="report rate [Hz]")
    noise_std_rad: float = spec(
        0.01, minimum=0.0, maximum=0.5, doc="direction noise per axis [rad]"
    )


class EmulatedCableAngle:
    """Builds the sensor's DEBUG_VECT frames (see the module docstring).

    Parameters
    ----------
    config
        The ``emulator.cable_angle`` section.
    scenario
        The simulated world (its seed).
    unix_time_at_start_s
        UNIX time of simulation time 0 [s]: the sensor stamps in UNIX time (its own clock).
    """

    def __init__(
        self, config: EmulatedCableAngleConfig, scenario: Scenario, unix_time_at_start_s: float
    ) -> None:
        self.config = config
        self._encoder = FrameEncoder(config.system_id, config.component_id)
        self._rng = np.random.default_rng([scenario.seed, ANGLE_SEED_SALT])
        self._name = config.message_name.encode("ascii")
        self._unix0_s = unix_time_at_start_s
        self.period_s = 1.0 / config.rate_hz
        self.next_s = 0.0
        """Simulation time of the next report [s]."""
        self.sent = 0

    def frame(self, sim: Simulator) -> bytes | None:
        """The next DEBUG_VECT frame, measured now (None while the cable has no direction:
        released, or the drone at the anchor); schedules the one after."""
        self.next_s = sim.time_s + self.period_s
        direction = anchor_direction_ned(sim.cable, tuple(sim.position_ned_m))
        if direction is None:
            return None
        azimuth, elevation = noisy_angles(direction, self.config.noise_std_rad, self._rng)
        msg = dialect.MAVLink_debug_vect_message(
            self._name, int((self._unix0_s + sim.time_s) * 1e6), azimuth, elevation, 0.0
        )
        self.sent += 1
        return self._encoder.encode(msg)
