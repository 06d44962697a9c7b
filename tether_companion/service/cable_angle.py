"""The ground station's cable-angle sensor as an input: MAVLink DEBUG_VECT (common.xml, id 250).

A sensor at the anchor (an encoder gimbal the cable runs through, or a camera looking up the
cable) measures the direction in which the cable leaves the anchor: its azimuth and elevation.
MAVLink has no message for it; the convention here is a standard message a ground station can
send, whose fields the flight controllers leave alone (ArduPilot ignores an inbound DEBUG_VECT;
PX4 copies it into a debug topic nothing acts on):

* ``name`` (char[10]): ``cable_angle.message_name`` (default ``CABLE_ANG``), telling the
  reading from other debug vectors of the same component;
* ``time_usec`` [us]: the sensor's own clock (UNIX time or time since its boot);
* ``x``: azimuth [rad], the cable's horizontal direction from the anchor toward the drone,
  from true north, positive toward east (NED: ``atan2(east, north)``), any value in
  [-2 pi, 2 pi];
* ``y``: elevation [rad], up from the horizontal at the anchor, in [-pi/2, pi/2] (negative: a
  sagging cable that leaves the anchor downward);
* ``z``: not used (send 0 or NaN).

The angles are of the cable's tangent where it leaves the anchor, not of the straight line to
the drone: the dynamic filter's model is the catenary's direction there
(:mod:`~tether_companion.estimation.dynamic.aid.cable_angle`).

:class:`CableAngleGate` (used by :class:`~tether_companion.service.ingest.Ingest`) turns an
admitted frame into a :class:`CableAngleReading` or a drop counted by reason
(:class:`CableAngleCounters`): the sender, clock and silence checks every ground sensor shares
(:mod:`~tether_companion.service.ground_sensor`), the name, finite values, the ranges above; the
configured calibration offsets are added (azimuth wrapped to [-pi, pi)).

:class:`CableAngleFeed` (used by :class:`~tether_companion.service.session.EstimationSession`)
hands accepted readings to the dynamic filter (``on_cable_angle``, with ``noise_std_rad``)
unless the cable is steeper than ``max_elevation_rad`` (the azimuth of a vertical cable is not
defined) or the reading is more than ``max_age_s`` from the filter's time (``stale``: the
filter fuses it at its own time). The paper's 3-/4-state filters have no angle input: the
readings are checked and counted, and :attr:`CableAngleFeed.note` says so once.

Pure and synchronous.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.config import ConfigError, spec
from tether_companion.frames import wrap_pi
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.service.ground_sensor import GroundCounters, GroundFeed, GroundGate

MESSAGE = "DEBUG_VECT"
"""The MAVLink message carrying the cable angle."""
PERIPHERAL_COMPONENT_ID = dialect.MAV_COMP_ID_PERIPHERAL
"""MAV_COMP_ID_PERIPHERAL (158): the sensor's default component id."""
MAX_AZIMUTH_RAD = 2.0 * math.pi
"""A sent azimuth beyond +-this [rad] is out of range."""


@dataclass(frozen=True)
class CableAngleConfig:
    """The ground station's cable-angle sensor (DEBUG_VECT), an input of the dynamic filter."""

    enabled: bool = spec(
        False,
        doc="read the cable's azimuth and elevation at the anchor from DEBUG_VECT: fused by "
        "the dynamic filter (estimator.kind dynamic; the paper filters ignore it)",
    )
    system_id: int = spec(
        255, minimum=1, maximum=255, doc="system id the sensor sends from (the ground station's)"
    )
    component_id: int = spec(
        PERIPHERAL_COMPONENT_ID,
        minimum=0,
        maximum=255,
        doc="component id the sensor sends from (MAV_COMP_ID_PERIPHERAL = 158)",
    )
    message_name: str = spec("CABLE_ANG", doc="DEBUG_VECT name of the readings (1-10 ASCII)")
    noise_std_rad: float = spec(
        0.01,
        exclusive_minimum=0.0,
        maximum=0.5,
        doc="the sensor's white direction noise, one standard deviation per axis (the azimuth's"
        " is this over cos(elevation)): an encoder gimbal on a strumming cable, ~0.6 degrees;"
        " its calibration errors are the *_calibration_std_rad below [rad]",
    )
    azimuth_offset_rad: float = spec(
        0.0,
        minimum=-math.pi,
        maximum=math.pi,
        doc="added to the sent azimuth: the sensor's zero against true north (calibration) [rad]",
    )
    elevation_offset_rad: float = spec(
        0.0,
        minimum=-0.5,
        maximum=0.5,
        doc="added to the sent elevation: the sensor's zero against the horizontal [rad]",
    )
    azimuth_calibration_std_rad: float = spec(
        0.026,
        minimum=0.0,
        maximum=0.5,
        doc="how well azimuth_offset_rad is known (the sensor's alignment to true north: 1-2"
        " degrees with a compass): the prior of the dynamic filter's azimuth-zero state [rad]",
    )
    elevation_calibration_std_rad: float = spec(
        0.007,
        minimum=0.0,
        maximum=0.5,
        doc="how well elevation_offset_rad is known (the sensor's levelling: 0.3-0.5 degrees"
        " with a bubble level): the prior of the dynamic filter's elevation-zero state [rad]",
    )
    max_elevation_rad: float = spec(
        1.4,
        exclusive_minimum=0.0,
        maximum=0.5 * math.pi,
        doc="steeper readings are not fused (the azimuth of a vertical cable is not defined) [rad]",
    )
    max_delay_s: float = spec(
        0.3,
        exclusive_minimum=0.0,
        maximum=5.0,
        doc="a reading arriving this much later than the fastest delivery seen is dropped [s]",
    )
    max_age_s: float = spec(
        0.25,
        exclusive_minimum=0.0,
        maximum=5.0,
        doc="a reading further than this from the filter's time is not fused (stale); at most "
        "estimator.staleness.tension_s [s]",
    )
    timeout_s: float = spec(
        1.0,
        exclusive_minimum=0.0,
        maximum=60.0,
        doc="no reading accepted for this long (flight-controller time): the sensor is stale, "
        "its clock offset and checks restart [s]",
    )

    def validate(self) -> None:
        """DEBUG_VECT names are 1 to 10 ASCII characters."""
        if not (1 <= len(self.message_name) <= 10 and self.message_name.isascii()):
            raise ConfigError(
                "", "message_name", self.message_name, "must be 1 to 10 ASCII characters"
            )


@dataclass(frozen=True, slots=True)
class CableAngleReading:
    """One accepted cable angle, calibrated, SI units.

    Attributes
    ----------
    time_s
        Flight-controller time [s] (the sensor's stamp mapped, see
        :mod:`~tether_companion.service.ground_sensor`).
    elevation_rad
        Up from the horizontal where the cable leaves the anchor [rad].
    azimuth_rad
        From north toward east, in [-pi, pi) [rad].
    """

    time_s: float
    elevation_rad: float
    azimuth_rad: float


@dataclass
class CableAngleCounters(GroundCounters):
    """DEBUG_VECT readings of the cable angle received and dropped, by reason (monotonic;
    --status shows them); the sender and clock reasons are :class:`GroundCounters`'."""

    wrong_name: int = 0
    """A DEBUG_VECT from the sensor's ids with another name."""
    nonfinite: int = 0
    """Azimuth or elevation NaN or infinite."""
    out_of_range: int = 0
    """Elevation beyond +-pi/2 (also after the offset) or azimuth beyond +-2 pi."""


def _name(msg: MAVLinkMessage) -> str:
    """DEBUG_VECT's name as text (pymavlink gives str; bytes are decoded, NULs stripped)."""
    name = msg.name
    if isinstance(name, bytes):
        name = name.decode("ascii", "replace")
    return name.rstrip("\0")


class CableAngleGate(GroundGate):
    """Checks DEBUG_VECT messages and maps their stamps (see the module docstring)."""

    counters: CableAngleCounters

    def __init__(self, config: CableAngleConfig) -> None:
        super().__init__(config, CableAngleCounters())
        self.config = config

    def ours(self, msg: MAVLinkMessage) -> bool:  # the name too
        """Whether a DEBUG_VECT is the sensor's (wrong sender or name counted); False without
        a count for another component's differently named vector (other traffic)."""
        named = _name(msg) == self.config.message_name
        if (msg.get_srcSystem(), msg.get_srcComponent()) != self.ids:
            if named:
                self.counters.wrong_sender += 1
            return False
        if not named:
            self.counters.wrong_name += 1
            return False
        return True

    def check(self, msg: MAVLinkMessage, arrival_fc_s: float) -> CableAngleReading | None:
        """The reading of the sensor's DEBUG_VECT that arrived when the flight controller's
        newest stamp was ``arrival_fc_s`` [s], or None (counted by reason)."""
        counters = self.counters
        config = self.config
        if not self.begin(arrival_fc_s):
            return None
        azimuth = float(msg.x)
        elevation = float(msg.y)
        if not (math.isfinite(azimuth) and math.isfinite(elevation)):
            counters.nonfinite += 1
            return None
        calibrated = elevation + config.elevation_offset_rad
        half_pi = 0.5 * math.pi
        if abs(azimuth) > MAX_AZIMUTH_RAD or max(abs(elevation), abs(calibrated)) > half_pi:
            counters.out_of_range += 1
            return None
        sensor_s = msg.time_usec * 1e-6
        time_s = self.fc_time(sensor_s, arrival_fc_s)
        if time_s is None:
            return None
        self.accept(sensor_s, arrival_fc_s)
        return CableAngleReading(time_s, calibrated, wrap_pi(azimuth + config.azimuth_offset_rad))


class CableAngleFeed(GroundFeed[CableAngleReading]):
    """Hands accepted cable angles to the dynamic filter (see the module docstring).

    Parameters
    ----------
    config
        The ``cable_angle`` section.
    uses_angle
        Whether the estimator takes a cable angle (the dynamic filter does, the paper's
        filters do not: then :attr:`note` says so once).
    """

    def __init__(self, config: CableAngleConfig, uses_angle: bool) -> None:
        super().__init__(config.timeout_s)
        self.config = config
        self.uses_angle = uses_angle
        self.near_vertical = 0
        """Readings not fused because the cable was steeper than ``max_elevation_rad``."""
        self.stale_readings = 0
        """Readings not fused because they were more than ``max_age_s`` from the filter's time."""
        self.note = (
            "cable_angle: the paper's filters (estimator.kind three_state/four_state) have no "
            "cable-angle input; DEBUG_VECT is read and counted, the angle not used"
            if config.enabled and not uses_angle
            else ""
        )
        """Said once at start (the service logs it): the estimator does not use the angle."""

    def on_reading(self, reading: CableAngleReading, estimator: object) -> None:
        """Feed ``reading`` to ``estimator`` (its ``time_s`` is the filter's time [s])."""
        if reading.time_s > self.deadline_s:
            self.silence()
        self.received(reading, reading.time_s)
        if not self.uses_angle:
            return
        if reading.elevation_rad > self.config.max_elevation_rad:
            self.near_vertical += 1
            return
        filter_s = float(estimator.time_s)  # type: ignore[attr-defined]
        if math.isfinite(filter_s) and abs(reading.time_s - filter_s) > self.config.max_age_s:
            self.stale_readings += 1
            return
        config = self.config
        estimator.on_cable_angle(  # type: ignore[attr-defined]
            reading.elevation_rad,
            reading.azimuth_rad,
            reading.time_s,
            config.noise_std_rad,
            (config.elevation_calibration_std_rad, config.azimuth_calibration_std_rad),
        )
