"""The ground station's winch as an input: MAVLink WINCH_STATUS (common.xml, id 9005).

What the message carries (pymavlink's dialect, ``common.xml``):

* ``time_usec`` [us]: the winch's own clock (UNIX time or time since its boot), not the
  flight controller's;
* ``line_length`` [m]: line released (NaN: unknown); ``speed`` [m/s]: + paying out, - reeling
  in (NaN: unknown);
* ``tension`` [**kg**, kilogram-force] on the line at the winch (NaN: unknown); converted here
  with standard gravity to newtons;
* ``voltage``, ``current``, ``temperature``: not used;
* ``status``: ``MAV_WINCH_STATUS_FLAG`` bits HEALTHY (1), FULLY_RETRACTED (2), MOVING (4),
  CLUTCH_ENGAGED (8).

:class:`WinchGate` (used by :class:`~tether_companion.service.ingest.Ingest`) turns an admitted
frame into a :class:`WinchReading` or a drop counted by reason (:class:`WinchCounters`): the
sender, clock and silence checks every ground sensor shares
(:mod:`~tether_companion.service.ground_sensor`: the configured system/component id, the
winch's stamps mapped to flight-controller time, duplicates, order, delay), and its own: finite
values inside the spool, the HEALTHY bit (when required), and no length change faster than
``max_speed_mps`` allows.

:class:`WinchFeed` (used by :class:`~tether_companion.service.session.EstimationSession`)
hands accepted readings to the estimator: the length to ``set_paid_out_length_m`` (the dynamic
filter) while the cable is not steeper than ``min_span_ratio`` (near the vertical the span
``a = sqrt(L^2 - h^2)`` from length and height is ill-conditioned: a length error ``e`` moves
it by ``e L/a``; measured in ArduPilot SITL above the anchor, docs/ardupilot.md), the
tension, when ``tension.source`` is ``winch``, to the dynamic filter's
``set_winch_tension_n`` as the tension where the cable leaves the winch (its model has the
cable's shape, so no height is needed; a winch's tension fused also slows the filter's chord
tension walk to ``noise.winch_tension_n2ps``), and to the paper filters'
``set_known_tension_n`` at the drone: on a cable of weight ``w`` per length the tension grows
by ``w h`` from the winch to a drone ``h`` above it (catenary, or the part resting on the
ground: the same sum). A winch
silent for ``timeout_s`` is stale: its length is forgotten (a restarting filter does not
initialise from it). The paper's 3-/4-state filters have no length input: the length is read,
checked and counted, and :attr:`WinchFeed.note` says once that it is not used.

Pure and synchronous.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

from tether_companion.config import spec
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.physics.cable_winch import tension_at_drone_n
from tether_companion.service.ground_sensor import GroundCounters, GroundFeed, GroundGate

STANDARD_GRAVITY_MPS2 = 9.80665
"""WINCH_STATUS.tension is in kilogram-force: newtons per kg [m/s^2]."""
HEALTHY = dialect.MAV_WINCH_STATUS_HEALTHY
FULLY_RETRACTED = dialect.MAV_WINCH_STATUS_FULLY_RETRACTED
MOVING = dialect.MAV_WINCH_STATUS_MOVING
CLUTCH_ENGAGED = dialect.MAV_WINCH_STATUS_CLUTCH_ENGAGED
WINCH_COMPONENT_ID = dialect.MAV_COMP_ID_WINCH
"""MAV_COMP_ID_WINCH (169)."""
MAX_TENSION_KG = 1000.0
"""A tension beyond this [kgf] either way is not a tether's: the reading's tension is dropped.
A load cell near zero reads slightly below it (its noise): the estimator takes such readings as
measurements down to what its noise explains (dynamic filter: ``ground_station.tension_ok``)."""


@dataclass(frozen=True)
class WinchConfig:
    """The ground station's winch (WINCH_STATUS), an optional input of the dynamic filter."""

    enabled: bool = spec(
        False,
        doc="read WINCH_STATUS: its line length goes to the dynamic filter (estimator.kind "
        "dynamic; the paper filters ignore it), its tension with tension.source winch",
    )
    system_id: int = spec(
        255,
        minimum=1,
        maximum=255,
        doc="system id the winch sends from (the ground station's, or the vehicle's)",
    )
    component_id: int = spec(
        WINCH_COMPONENT_ID,
        minimum=0,
        maximum=255,
        doc="component id the winch sends from (MAV_COMP_ID_WINCH = 169)",
    )
    spool_length_m: float = spec(
        100.0, exclusive_minimum=0.0, doc="line on the drum: a longer line_length is absurd [m]"
    )
    length_offset_m: float = spec(
        0.0,
        doc="subtracted from line_length: line between the winch's counter and the anchor "
        "point (a fairlead, a pulley) the estimator measures from [m]",
    )
    max_speed_mps: float = spec(
        5.0,
        exclusive_minimum=0.0,
        maximum=50.0,
        doc="fastest the line can move: a larger speed, or a length change faster than this "
        "(plus length_tolerance_m), is dropped [m/s]",
    )
    length_tolerance_m: float = spec(
        0.1,
        minimum=0.0,
        doc="length noise and quantisation allowed on top of max_speed_mps between readings [m]",
    )
    max_delay_s: float = spec(
        0.3,
        exclusive_minimum=0.0,
        maximum=5.0,
        doc="a reading arriving this much later than the fastest delivery seen is dropped [s]",
    )
    timeout_s: float = spec(
        1.0,
        exclusive_minimum=0.0,
        maximum=60.0,
        doc="no reading accepted for this long (flight-controller time): the winch is stale, "
        "its length forgotten, its checks restart [s]",
    )
    require_healthy: bool = spec(
        True, doc="drop readings whose status lacks MAV_WINCH_STATUS_HEALTHY"
    )
    min_span_ratio: float = spec(
        0.5,
        minimum=0.0,
        maximum=1.0,
        doc="the length is fused only while the estimate's horizontal span over its distance "
        "from the anchor is at least this: nearer the vertical a length error e moves the "
        "horizontal position by e L/a (2x at 0.5), and the rangefinder gives the height [1]",
    )


@dataclass(frozen=True, slots=True)
class WinchReading:
    """One accepted WINCH_STATUS, SI units.

    Attributes
    ----------
    time_s
        Flight-controller time [s] (the winch's stamp mapped, see :class:`WinchGate`).
    length_m
        Cable paid out from the anchor point (``line_length - length_offset_m``) [m].
    tension_n
        Line tension at the winch [N] (``nan`` when the winch does not know it).
    speed_mps
        Line speed, + paying out [m/s] (``nan``: unknown).
    status
        The MAV_WINCH_STATUS_FLAG bits.
    """

    time_s: float
    length_m: float
    tension_n: float
    speed_mps: float
    status: int


@dataclass
class WinchCounters(GroundCounters):
    """WINCH_STATUS received and dropped, by reason (monotonic counts; --status shows them);
    the sender and clock reasons are :class:`GroundCounters`'."""

    NOT_DROPPED: ClassVar[tuple[str, ...]] = ("accepted", "wrong_sender", "bad_tension")

    no_length: int = 0
    """line_length NaN (the winch does not know it)."""
    nonfinite: int = 0
    """line_length or speed infinite."""
    absurd: int = 0
    """Negative line, longer than the spool, or a speed beyond ``max_speed_mps``."""
    unhealthy: int = 0
    """The HEALTHY bit clear (``require_healthy``)."""
    too_fast: int = 0
    """A length change faster than ``max_speed_mps`` (plus the tolerance) allows."""
    bad_tension: int = 0
    """Tension infinite, negative or beyond ``MAX_TENSION_KG``: the reading is kept without it."""


class WinchGate(GroundGate):
    """Checks WINCH_STATUS messages and maps their stamps (see the module docstring)."""

    counters: WinchCounters

    def __init__(self, config: WinchConfig) -> None:
        super().__init__(config, WinchCounters())
        self.config = config
        self._last_length_m = math.nan

    def check(self, msg: MAVLinkMessage, arrival_fc_s: float) -> WinchReading | None:
        """The reading of a WINCH_STATUS from the winch that arrived when the flight
        controller's newest stamp was ``arrival_fc_s`` [s], or None (counted by reason)."""
        counters = self.counters
        config = self.config
        if not self.begin(arrival_fc_s):
            return None
        line = float(msg.line_length)
        speed = float(msg.speed)
        if math.isnan(line):
            counters.no_length += 1
            return None
        if math.isinf(line) or math.isinf(speed):
            counters.nonfinite += 1
            return None
        if (
            line < 0.0
            or line > config.spool_length_m
            or (not math.isnan(speed) and abs(speed) > config.max_speed_mps)
        ):
            counters.absurd += 1
            return None
        status = int(msg.status)
        if config.require_healthy and not status & HEALTHY:
            counters.unhealthy += 1
            return None
        winch_s = msg.time_usec * 1e-6
        time_s = self.fc_time(winch_s, arrival_fc_s)
        if time_s is None:
            return None
        previous_s = self.last_sensor_s  # nan after a silence or a restart: no speed check
        if not math.isnan(previous_s):
            allowed = config.max_speed_mps * (winch_s - previous_s)
            if abs(line - self._last_length_m) > allowed + config.length_tolerance_m:
                counters.too_fast += 1
                return None
        self._last_length_m = line
        self.accept(winch_s, arrival_fc_s)
        return WinchReading(
            time_s, line - config.length_offset_m, self._tension_n(msg), speed, status
        )

    def _tension_n(self, msg: MAVLinkMessage) -> float:
        tension_kg = float(msg.tension)
        if math.isnan(tension_kg):
            return math.nan
        if math.isinf(tension_kg) or not -MAX_TENSION_KG <= tension_kg <= MAX_TENSION_KG:
            self.counters.bad_tension += 1
            return math.nan
        return tension_kg * STANDARD_GRAVITY_MPS2


class WinchFeed(GroundFeed[WinchReading]):
    """Hands accepted winch readings to an estimator (see the module docstring).

    Parameters
    ----------
    config
        The ``winch`` section.
    use_tension
        ``tension.source`` is ``winch``: the winch's tension is the dynamic filter's winch
        tension, or (the paper's filters) carried to the drone their known tension.
    cable_weight_n_per_m
        The cable's weight per length [N/m] (``dynamic_filter.cable_weight_n_per_m``).
    uses_length
        Whether the estimator takes a paid-out length (the dynamic filter does, the paper's
        filters do not: then :attr:`note` says so once).
    """

    def __init__(
        self,
        config: WinchConfig,
        use_tension: bool,
        cable_weight_n_per_m: float,
        uses_length: bool,
    ) -> None:
        super().__init__(config.timeout_s)
        self.config = config
        self.use_tension = use_tension
        self.weight_n_per_m = cable_weight_n_per_m
        self.uses_length = uses_length
        self.near_vertical = 0
        """Lengths not fused because the cable was nearer the vertical than ``min_span_ratio``."""
        self.note = (
            "winch: the paper's filters (estimator.kind three_state/four_state) have no "
            "paid-out length input; WINCH_STATUS is read and counted, its length not used"
            if config.enabled and not uses_length
            else ""
        )
        """Said once at start (the service logs it): the estimator does not use the length."""

    def on_reading(
        self, reading: WinchReading, estimator: object, position_ned_m: Sequence[float] | None
    ) -> None:
        """Feed ``reading`` to ``estimator``; ``position_ned_m`` is the latest estimate's
        position from the anchor [m] (None before the first): the cable's steepness for the
        length, the drone's height for the tension."""
        self.received(reading, reading.time_s)
        height_m = math.nan if position_ned_m is None else -float(position_ned_m[2])
        if self.uses_length and reading.length_m > 0.0:  # fully retracted: no cable to model
            if self._steep(position_ned_m):
                self.near_vertical += 1
            else:
                estimator.set_paid_out_length_m(reading.length_m, reading.time_s)  # type: ignore[attr-defined]
        if not (self.use_tension and math.isfinite(reading.tension_n)):
            return
        at_winch = getattr(estimator, "set_winch_tension_n", None)
        if at_winch is not None:  # the dynamic filter models the winch's end of the cable
            at_winch(reading.tension_n, reading.time_s)
            return
        at_drone_n = tension_at_drone_n(reading.tension_n, self.weight_n_per_m, height_m)
        if not math.isfinite(at_drone_n):
            return  # a heavy cable's tension at the drone needs the drone's height
        estimator.set_known_tension_n(at_drone_n, reading.time_s)  # type: ignore[attr-defined]

    def _steep(self, position_ned_m: Sequence[float] | None) -> bool:
        """Whether the estimate puts the cable nearer the vertical than ``min_span_ratio``."""
        if position_ned_m is None:
            return False
        north, east, down = (float(v) for v in position_ned_m)
        distance = math.sqrt(north * north + east * east + down * down)
        return distance > 0.0 and math.hypot(north, east) < self.config.min_span_ratio * distance

    def expire(self, estimator: object) -> None:
        """The winch fell silent (called once the flight-controller time passes
        :attr:`deadline_s`): the estimator forgets its length."""
        self.silence()
        constants = getattr(estimator, "constants", None)
        if constants is not None:  # the dynamic filter's cable model: "no length known"
            constants.length_m = math.nan
