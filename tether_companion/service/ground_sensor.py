"""What the ground station's sensors share: their sender check, their clock, their silence.

The winch (WINCH_STATUS, :mod:`~tether_companion.service.winch`) and the cable-angle sensor
(DEBUG_VECT, :mod:`~tether_companion.service.cable_angle`) are MAVLink components of their own,
stamping in their own clock (UNIX time or time since their boot), not the flight controller's.
For both:

* only frames from the configured system/component id are theirs (:meth:`GroundGate.ours`;
  the link's signing policy has applied before, as to every frame);
* their stamp is mapped to flight-controller time by the least-delay offset model the service
  keeps for the flight controller's own clock (:class:`~tether_companion.service.clock.FcClock`,
  the sensor's stamps against their arrival), the arrival being the flight controller's newest
  believed stamp (live and in replay alike): :meth:`GroundGate.fc_time`;
* a stamp equal to the last accepted one is a ``duplicate``, an older one ``out_of_order``
  (older by more than :data:`SENSOR_REBOOT_S`: the sensor restarted its clock, start afresh),
  one delivered more than ``max_delay_s`` later than the fastest delivery seen is ``late``;
  before the flight controller's first stamp there is nothing to map to (``no_fc_time``);
* nothing accepted for ``timeout_s`` of flight-controller time: the sensor is stale, its clock
  offset and the checks that compare with the last reading start afresh
  (:meth:`GroundGate.begin`); the feed (:class:`GroundFeed`) forgets its last reading.

Pure and synchronous.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar, Generic, Protocol, TypeVar

from tether_companion.mavlink.framing import MAVLinkMessage
from tether_companion.service.clock import FcClock

SENSOR_REBOOT_S = 10.0
"""A sensor's clock going back more than this [s] is a restart of the sensor (state reset)."""
OFFSET_DRIFT = 1e-3
"""How fast [s/s] a sensor-to-FC clock offset may drift (FcClock's drift allowance)."""
Reading = TypeVar("Reading")


class GroundTiming(Protocol):
    """The timing settings a ground sensor's config section has."""

    system_id: int
    component_id: int
    max_delay_s: float
    timeout_s: float


@dataclass
class GroundCounters:
    """A ground sensor's messages accepted and dropped, by reason (monotonic counts).

    Subclasses add their own content reasons; :attr:`NOT_DROPPED` names the counters that are
    not drops of the sensor's readings."""

    NOT_DROPPED: ClassVar[tuple[str, ...]] = ("accepted", "wrong_sender")

    accepted: int = 0
    wrong_sender: int = 0
    """From a system/component other than the configured one."""
    duplicate: int = 0
    out_of_order: int = 0
    """The sensor's stamp equal to / older than the last accepted one's."""
    late: int = 0
    """Delivered more than ``max_delay_s`` later than the fastest delivery seen."""
    no_fc_time: int = 0
    """Before the flight controller's first stamp (nothing to map the sensor's time to)."""

    @property
    def dropped(self) -> int:
        """Readings from the sensor refused for their content or time."""
        return sum(getattr(self, f.name) for f in fields(self) if f.name not in self.NOT_DROPPED)

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain mapping."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


class GroundGate:
    """Sender, clock and silence checks of one ground sensor (see the module docstring).

    Parameters
    ----------
    config
        The sensor's section (ids, ``max_delay_s``, ``timeout_s``).
    counters
        Where the drops are counted (the sensor's :class:`GroundCounters` subclass).
    """

    def __init__(self, config: GroundTiming, counters: GroundCounters) -> None:
        self.ids = (config.system_id, config.component_id)
        self.counters = counters
        self._max_delay_s = config.max_delay_s
        self._timeout_s = config.timeout_s
        self._clock = FcClock(OFFSET_DRIFT)
        """The sensor's clock against the arrivals' flight-controller time."""
        self.last_sensor_s = math.nan
        """The sensor's stamp of the last accepted reading [s] (nan: none since the start,
        a silence or a restart of the sensor)."""
        self._last_accepted_fc_s = -math.inf

    def ours(self, msg: MAVLinkMessage) -> bool:
        """Whether ``msg`` carries the configured sensor's ids (counted otherwise)."""
        if (msg.get_srcSystem(), msg.get_srcComponent()) == self.ids:
            return True
        self.counters.wrong_sender += 1
        return False

    def begin(self, arrival_fc_s: float) -> bool:
        """Whether a reading that arrived when the flight controller's newest stamp was
        ``arrival_fc_s`` [s] can be checked (``no_fc_time`` counted otherwise); after a silence
        of ``timeout_s`` the clock and the last reading are forgotten first."""
        if not math.isfinite(arrival_fc_s):
            self.counters.no_fc_time += 1
            return False
        if arrival_fc_s - self._last_accepted_fc_s > self._timeout_s:
            self._forget()
        return True

    def fc_time(self, sensor_s: float, arrival_fc_s: float) -> float | None:
        """The flight-controller time [s] of a reading stamped ``sensor_s`` [s] by the sensor,
        or None (``duplicate``, ``out_of_order`` or ``late``, counted)."""
        counters = self.counters
        previous = self.last_sensor_s
        if not math.isnan(previous):
            if sensor_s == previous:
                counters.duplicate += 1
                return None
            if sensor_s < previous:
                if previous - sensor_s <= SENSOR_REBOOT_S:
                    counters.out_of_order += 1
                    return None
                self._forget()  # the sensor restarted its clock
        clock = self._clock
        clock.observe(sensor_s, arrival_fc_s)
        offset = clock.offset_s(arrival_fc_s)  # sensor - FC time of the least-delayed reading
        assert offset is not None  # just observed
        if offset - (sensor_s - arrival_fc_s) > self._max_delay_s:
            counters.late += 1
            return None
        return sensor_s - offset

    def accept(self, sensor_s: float, arrival_fc_s: float) -> None:
        """Count a reading stamped ``sensor_s`` [s] that passed every check."""
        self.last_sensor_s = sensor_s
        self._last_accepted_fc_s = arrival_fc_s
        self.counters.accepted += 1

    def _forget(self) -> None:
        self._clock.reset()
        self.last_sensor_s = math.nan
        self._last_accepted_fc_s = -math.inf


class GroundFeed(Generic[Reading]):
    """The last reading a ground sensor handed on, and its silences.

    Parameters
    ----------
    timeout_s
        A sensor silent this long [s of flight-controller time] is stale.
    """

    def __init__(self, timeout_s: float) -> None:
        self._timeout_s = timeout_s
        self.deadline_s = math.inf
        """Flight-controller time [s] after which the sensor is stale (inf: not fed)."""
        self.last: Reading | None = None
        """The latest reading handed on (None: none yet, or stale)."""
        self.timeouts = 0
        """Times the sensor went stale (nothing accepted for ``timeout_s``)."""

    @property
    def stale(self) -> bool:
        """Whether the sensor was fed before and has been silent for ``timeout_s`` since."""
        return self.last is None and self.timeouts > 0

    def received(self, reading: Reading, time_s: float) -> None:
        """Note ``reading`` at flight-controller time ``time_s`` [s]."""
        self.last = reading
        self.deadline_s = time_s + self._timeout_s

    def silence(self) -> None:
        """The sensor fell silent (the flight-controller time passed :attr:`deadline_s`)."""
        self.deadline_s = math.inf
        self.last = None
        self.timeouts += 1
