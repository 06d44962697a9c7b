"""What ingest gives and counts: the input kinds' names, the readings it makes that are not
estimator samples (a load cell's tension, the flight controller's position and landed state),
the union of its samples, and its drop counters (:mod:`~tether_companion.service.ingest`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tether_companion.mavlink.framing import dialect
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.service.cable_angle import CableAngleReading
from tether_companion.service.winch import WinchReading

IMU = "imu"
ATTITUDE = "attitude"
PWM = "pwm"
RANGE = "range"
TENSION = "tension"
FC_POSITION = "fc_position"
SYSTEM_TIME = "system_time"
"""The flight controller's SYSTEM_TIME: no sample, the evidence of its reboots."""
WINCH = "winch"
"""The ground station's WINCH_STATUS (service/winch.py)."""
CABLE_ANGLE = "cable_angle"
"""The ground station's cable angle, DEBUG_VECT (service/cable_angle.py)."""
LANDED = "landed_state"
"""The flight controller's landed state, EXTENDED_SYS_STATE."""
INPUT_KINDS = (
    IMU,
    ATTITUDE,
    PWM,
    RANGE,
    TENSION,
    FC_POSITION,
    SYSTEM_TIME,
    WINCH,
    CABLE_ANGLE,
    LANDED,
)
LANDED_STATES = frozenset(range(5))
"""MAV_LANDED_STATE: UNDEFINED, ON_GROUND, IN_AIR, TAKEOFF, LANDING (common.xml)."""


@dataclass(frozen=True, slots=True)
class TensionReading:
    """A measured cable tension from a load cell [N] at flight-controller time [s]."""

    time_s: float
    tension_n: float


@dataclass(frozen=True, slots=True)
class FcPosition:
    """The flight controller's own position belief (LOCAL_POSITION_NED), NED [m], at FC time [s].

    Not an estimator input: the tension modes send GUIDED targets in this frame.
    """

    time_s: float
    position_ned_m: tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class LandedState:
    """The flight controller's landed state (EXTENDED_SYS_STATE.landed_state, a
    MAV_LANDED_STATE) at flight-controller time [s] (the newest stamp when it arrived)."""

    time_s: float
    landed_state: int

    @property
    def on_ground(self) -> bool:
        """ON_GROUND: the autopilot's land detector says landed. TAKEOFF and LANDING are sent
        for a whole climb or descent (ArduCopter, PX4): in the air."""
        return self.landed_state == dialect.MAV_LANDED_STATE_ON_GROUND


Sample = (
    ImuSample
    | AttitudeSample
    | PwmSample
    | RangeSample
    | TensionReading
    | FcPosition
    | WinchReading
    | CableAngleReading
    | LandedState
)


@dataclass
class IngestCounters:
    """Why messages were dropped (monotonic counts; shown by --status)."""

    messages: int = 0
    wrong_system: int = 0
    not_input: int = 0
    nonfinite: int = 0
    absurd: int = 0
    out_of_range: int = 0
    duplicate: int = 0
    out_of_order: int = 0
    implausible: int = 0
    """Stamps far ahead of the flight controller's clock model (e.g. a spoofed 2^63 us)."""
    reordered: int = 0
    """Samples that arrived older than one of their own stream (the link reordered them; put
    back in order when the reorder window covered them, else dropped as ``out_of_order``)."""
    reorder_window_s: float = 0.0
    """The reorder buffer's current window [s] (0 until the link is seen to reorder)."""
    reorder_widened: int = 0
    """Times the reorder window grew to cover reordering beyond it."""
    no_fc_time: int = 0
    """Messages without a stamp of their own (EXTENDED_SYS_STATE) before the flight
    controller's first believed stamp: no time to put them at."""
    reboots: int = 0
    accepted: dict[str, int] = field(default_factory=lambda: dict.fromkeys(INPUT_KINDS, 0))

    @property
    def dropped(self) -> int:
        """Inputs refused for their content or time (not counting other systems' traffic)."""
        return (
            self.nonfinite
            + self.absurd
            + self.out_of_range
            + self.duplicate
            + self.out_of_order
            + self.implausible
            + self.no_fc_time
        )
