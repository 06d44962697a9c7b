"""Decoded MAVLink messages to checked SI samples; everything refused is dropped and counted.

Pure and synchronous (the live service and replay share it). For each message:

1. wrong sender: only the configured flight controller's system/component id (and the
   tension sensor's, for its NAMED_VALUE_FLOAT, and the winch's, for its WINCH_STATUS) are
   accepted;
2. type: the flavour's IMU message (ArduPilot RAW_IMU in milli-g, PX4 HIGHRES_IMU in m/s^2),
   ATTITUDE, SERVO_OUTPUT_RAW, downward DISTANCE_SENSOR; anything else is not an input;
3. values: NaN/inf is ``nonfinite``; outside the plausibility bounds is ``absurd``; a
   rangefinder reading outside its valid range is ``out_of_range``; a load cell's tension
   (NAMED_VALUE_FLOAT) is absurd only beyond ``10 * tension.known_tension_n + 1000`` N either
   way: a load cell near zero reads below zero about half the time, and the estimator judges
   such a reading by its noise (the dynamic filter fuses it down to
   ``ground_station.LOAD_CELL_BELOW_ZERO_STDS`` standard deviations below zero; the paper
   filters, whose model takes the tension as a known input, drop a negative one, counted);
4. clock (:class:`~tether_companion.service.fc_time.FcTimeGate`): a stamp far ahead of the
   flight controller's clock model is ``implausible``; one more than a second behind is
   ``out_of_order``, unless SYSTEM_TIME said the flight controller rebooted and the stamps
   agree: then :attr:`IngestCounters.reboots` counts it and the caller restarts;
5. the ground station's sensors, the winch's WINCH_STATUS (``winch.enabled``) and the cable
   angle's DEBUG_VECT (``cable_angle.enabled``), are checked by their own gates
   (:class:`~tether_companion.service.winch.WinchGate`,
   :class:`~tether_companion.service.cable_angle.CableAngleGate`: sender, values, the sensor's
   clock mapped to the flight controller's; drops in their counters by reason) and bypass the
   reorder buffer (their stamp is the mapped one; the estimator fuses them at its own time);
6. the flight controller's landed state, EXTENDED_SYS_STATE (no stamp of its own): stamped
   with the newest believed flight-controller time (``no_fc_time`` before the first), a
   ``landed_state`` outside MAV_LANDED_STATE ``absurd``; it bypasses the reorder buffer;
7. order: samples pass an adaptive reorder buffer (:mod:`~tether_companion.service.reorder`:
   no delay until the link is seen to reorder, then a window covering what it showed, at most
   ``inputs.reorder_window_s``) and leave it in stamp order; per message type the stamp must
   then increase: an equal stamp is a ``duplicate``, an older one (later than the window)
   ``out_of_order``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tether_companion.estimation.optional_core import load
from tether_companion.mavlink.framing import Received
from tether_companion.mavlink.units import (
    DOWNWARD_ORIENTATION,
    Vector3,
    attitude_from_attitude,
    highres_imu_si,
    raw_imu_si,
    servo_outputs,
)
from tether_companion.physics.thrust import COMMAND_UNITS
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.service.cable_angle import (
    MESSAGE,
    CableAngleConfig,
    CableAngleGate,
)
from tether_companion.service.fc_time import ACCEPT, BACKSTEP, IMPLAUSIBLE, REBOOT, FcTimeGate
from tether_companion.service.ingest_types import (  # noqa: F401  (re-exported: ingest's names)
    ATTITUDE,
    CABLE_ANGLE,
    FC_POSITION,
    IMU,
    INPUT_KINDS,
    LANDED,
    LANDED_STATES,
    PWM,
    RANGE,
    SYSTEM_TIME,
    TENSION,
    WINCH,
    FcPosition,
    IngestCounters,
    LandedState,
    Sample,
    TensionReading,
)
from tether_companion.service.input_config import InputLimitsConfig, TensionConfig
from tether_companion.service.link_config import LinkConfig
from tether_companion.service.reorder import ReorderBuffer
from tether_companion.service.winch import WinchConfig, WinchGate

_CORE = load("tether_companion.service._frame_core")
"""The extension whose ``IngestCore`` (``ingest_core.c``) is :attr:`Ingest.core`."""
_UINT32_US = 1 << 32
_NEVER = -math.inf


class Ingest:
    """Turn messages into samples, checking sender, values and time order.

    Parameters
    ----------
    link
        Flavour and the flight controller's ids.
    limits
        Plausibility bounds.
    tension
        Tension-sensor settings (source ``message`` enables NAMED_VALUE_FLOAT decoding).
    n_motors
        Motors in the vehicle profile (SERVO_OUTPUT_RAW channels 1..n).
    command_unit
        What SERVO_OUTPUT_RAW carries (the profile's ``thrust_curve.command_unit``): outputs
        in ``pwm_us`` are checked against ``limits.pwm_min_us/max_us``, any other unit against
        the unit's own range (e.g. 0-65535 for ``raw``).
    winch
        The ``winch`` section (WINCH_STATUS is an input when it is enabled).
    cable_angle
        The ``cable_angle`` section (its DEBUG_VECT is an input when it is enabled).
    """

    def __init__(
        self,
        link: LinkConfig,
        limits: InputLimitsConfig,
        tension: TensionConfig,
        n_motors: int,
        command_unit: str = "pwm_us",
        winch: WinchConfig | None = None,
        cable_angle: CableAngleConfig | None = None,
    ) -> None:
        self.link = link
        self._fc_system_id = link.fc_system_id
        self._fc_component_id = link.fc_component_id
        self.limits = limits
        self._max_force_sq = limits.max_specific_force_mps2**2
        """The IMU check's bound on the squared specific force [m^2/s^4] (limits are frozen)."""
        self._max_rate = limits.max_angular_rate_rad_s
        self._output_range = (
            (limits.pwm_min_us, limits.pwm_max_us)
            if command_unit == "pwm_us"
            else COMMAND_UNITS[command_unit]
        )
        self.tension = tension
        self.n_motors = n_motors
        self.counters = IngestCounters()
        self.clock: FcTimeGate | Any = FcTimeGate()
        """Which stamps are believed; ``clock.latest_fc_s`` is the newest."""
        self.reorder: ReorderBuffer[Sample] | Any = ReorderBuffer(limits.reorder_window_s)
        self._latest_by_kind: dict[str, float] = {}
        self._local_s: float | None = None
        self.core = self._new_core()
        """``ingest_core.c``'s ``IngestCore`` (None: not built, ``TETHER_PURE_PYTHON``, or a
        window not a float): the clock, the reorder buffer and the order check as one object
        in C, bit for bit the Python above and below, which stay the reference. It is then
        :attr:`clock` and :attr:`reorder` (both interfaces) and runs :meth:`receive_input`,
        :meth:`_believed` and :meth:`_ordered` on the same state, the counters and
        ``_latest_by_kind`` included, for the frame path and the message path alike."""
        self._imu_type = "RAW_IMU" if link.autopilot == "ardupilot" else "HIGHRES_IMU"
        self._imu_si = raw_imu_si if self._imu_type == "RAW_IMU" else highres_imu_si
        self._inputs = {
            self._imu_type: (IMU, self._imu),
            "ATTITUDE": (ATTITUDE, self._attitude),
            "SERVO_OUTPUT_RAW": (PWM, self._pwm),
            "DISTANCE_SENSOR": (RANGE, self._range),
            "LOCAL_POSITION_NED": (FC_POSITION, self._fc_position),
        }
        """The flight controller's input messages by name: (kind, decoder)."""
        self._tension_name = (
            tension.message_name.encode("ascii") if tension.source == "message" else None
        )
        self.winch = WinchGate(winch) if winch is not None and winch.enabled else None
        """Checks the winch's WINCH_STATUS (None: not an input)."""
        self.cable_angle = (
            CableAngleGate(cable_angle) if cable_angle is not None and cable_angle.enabled else None
        )
        """Checks the cable-angle sensor's DEBUG_VECT (None: not an input)."""
        self._ground: dict[str, tuple[str, WinchGate | CableAngleGate]] = {}
        """The ground station's sensors by message name: (kind, gate)."""
        if self.winch is not None:
            self._ground["WINCH_STATUS"] = (WINCH, self.winch)
        if self.cable_angle is not None:
            self._ground[MESSAGE] = (CABLE_ANGLE, self.cable_angle)
        self.rebooted = False
        """True right after the message that confirmed a reboot (cleared on the next call)."""

    def _new_core(self) -> Any:
        """The C twin of the clock, reorder buffer and order check, put in their place (see
        :attr:`core`), or None."""
        kind = getattr(_CORE, "IngestCore", None)  # an older build has no IngestCore
        window = self.reorder.max_window_s
        if kind is None or type(window) is not float:
            return None
        gate = self.clock
        core = kind(
            self,
            self.counters,
            self._latest_by_kind,
            window,
            (
                float(gate.backstep_s),
                float(gate.future_tolerance_s),
                float(gate.max_rate),
                float(gate.confirm_span_s),
                float(gate.fallback_s),
                gate.confirmations,
                gate.fallback_samples,
            ),
        )
        self.clock = self.reorder = core
        self.receive_input = core.receive_input  # type: ignore[method-assign]
        self._believed = core.believed  # type: ignore[method-assign]
        self._ordered = core.ordered  # type: ignore[method-assign]
        return core

    def check_bounds(self) -> tuple[float, float, float, float, float, float]:
        """The value checks' bounds (for a twin of the checks): squared specific force
        [m^2/s^4], angular rate [rad/s], lowest and highest motor output (the command unit's),
        shortest and longest range [m]."""
        low, high = self._output_range
        return (
            self._max_force_sq,
            self._max_rate,
            low,
            high,
            self.limits.range_min_m,
            self.limits.range_max_m,
        )

    def from_flight_controller(self, msg: Received) -> bool:
        """Whether ``msg`` was sent by the configured flight controller."""
        return (
            msg.get_srcSystem() == self._fc_system_id
            and msg.get_srcComponent() == self._fc_component_id
        )

    @property
    def latest_fc_s(self) -> float:
        """Newest believed flight-controller stamp [s] (-inf before the first)."""
        return self.clock.latest_fc_s

    def receive(
        self, msg: Received, local_s: float | None = None, kind_name: str | None = None
    ) -> list[Sample]:
        """The checked SI samples ``msg`` releases from the reorder buffer, oldest first.

        ``local_s`` is the local time [s] it arrived at (None in replay: no plausibility check
        against the clock model); ``kind_name`` is ``msg.get_type()`` when the caller has it.
        """
        self._local_s = local_s
        if kind_name is None:
            kind_name = msg.get_type()
        known = self._inputs.get(kind_name)
        if (
            known is not None
            and msg.get_srcSystem() == self._fc_system_id
            and msg.get_srcComponent() == self._fc_component_id
        ):
            # the flight controller's input streams: none of _decode's other cases has their
            # names, so this is its outcome for them, without its tests for the other cases
            kind, decode = known
            return self.receive_input(kind, decode(msg), local_s)
        held = self._decode(msg, kind_name)
        if held is None:
            return []
        kind, sample = held
        if kind is WINCH or kind is CABLE_ANGLE or kind is LANDED:  # stamped here
            self.counters.accepted[kind] += 1  # not reordered
            return [sample]
        return self._ordered(self.reorder.push(kind, sample.time_s, sample))

    def receive_input(
        self, kind: str, sample: Sample | None, local_s: float | None
    ) -> list[Sample]:
        """:meth:`receive` for a message of the flight controller's input streams whose sample
        of ``kind`` the caller has decoded and checked (``None``: dropped by the checks, and
        counted): the message counted, the stamp checked by the clock, then reordered and
        checked for order. ``local_s`` as for :meth:`receive`."""
        self._local_s = local_s
        self.rebooted = False
        self.counters.messages += 1
        if sample is None:
            return []
        time_s = sample.time_s
        verdict = self.clock.check(time_s, local_s)
        if verdict != ACCEPT and not self._believed(verdict):
            return []
        return self._ordered(self.reorder.push(kind, time_s, sample))

    def _ordered(self, released: list[tuple[str, Sample]]) -> list[Sample]:
        """The released samples that pass :meth:`_in_order`."""
        if len(released) == 1:  # the clean link's path (one in, one out)
            kind, sample = released[0]
            return [sample] if self._in_order(kind, sample) else []
        return [s for k, s in released if self._in_order(k, s)]

    def decode(self, msg: Received, local_s: float | None = None) -> Sample | None:
        """The newest sample :meth:`receive` releases for ``msg``, or None (not an input,
        dropped, or still held by the reorder buffer)."""
        released = self.receive(msg, local_s)
        return released[-1] if released else None

    def _decode(self, msg: Received, kind_name: str) -> tuple[str, Sample] | None:
        """(kind, checked sample) carried by ``msg`` (named ``kind_name``) before reordering,
        or None."""
        self.rebooted = False
        counters = self.counters
        counters.messages += 1
        if kind_name == "NAMED_VALUE_FLOAT" and self._tension_name is not None:
            return self._timed(TENSION, self._tension(msg))
        ground = self._ground.get(kind_name) if self._ground else None
        if ground is not None:
            kind, gate = ground
            if not gate.ours(msg):
                counters.wrong_system += 1
                return None
            reading = gate.check(msg, self.clock.latest_fc_s)
            return None if reading is None else (kind, reading)
        if not self.from_flight_controller(msg):
            counters.wrong_system += 1
            return None
        if kind_name == "SYSTEM_TIME":
            self._system_time(msg)
            return None
        if kind_name == "EXTENDED_SYS_STATE":
            return self._landed_state(msg)
        known = self._inputs.get(kind_name)
        if known is None:
            counters.not_input += 1
            return None
        kind, decode = known
        return self._timed(kind, decode(msg))

    # ------------------------------------------------------------------ per message
    def _imu(self, msg: Received) -> ImuSample | None:
        return self.imu_sample(getattr(msg, "id", 0), *self._imu_si(msg))

    def _attitude(self, msg: Received) -> AttitudeSample | None:
        return self.attitude_sample(attitude_from_attitude(msg))

    def _pwm(self, msg: Received) -> PwmSample | None:
        return self.pwm_sample(msg.port, msg.time_usec, servo_outputs(msg, self.n_motors))

    def _range(self, msg: Received) -> RangeSample | None:
        return self.range_sample(
            msg.orientation,
            msg.time_boot_ms,
            msg.current_distance,
            msg.min_distance,
            msg.max_distance,
        )

    # ------------------------------------------------------------------ per input, in values
    # (shared by the messages above and by service.ingest_frames, which reads the same fields
    # straight from the frame's bytes; drops counted here)
    def imu_sample(
        self, imu_id: int, time_s: float, force: Vector3, rate: Vector3
    ) -> ImuSample | None:
        """The checked sample of the flight controller's IMU message: IMU ``imu_id`` (only the
        first, 0, is an input: ArduPilot sends others as SCALED_IMU2/3), FC time [s], specific
        force (FRD) [m/s^2] and body rates [rad/s] in SI scalars."""
        if imu_id != 0:
            self.counters.not_input += 1
            return None
        # checked in scalars, arrays made for a sample kept: numpy's per-call overhead is most
        # of the cost of checking 3-vectors
        fx, fy, fz = force
        p, q, r = rate
        if not math.isfinite(fx + fy + fz + p + q + r):  # NaN/inf in any
            self.counters.nonfinite += 1
            return None
        if (
            fx * fx + fy * fy + fz * fz > self._max_force_sq
            or abs(p) > self._max_rate  # finite: as the largest of the three against it
            or abs(q) > self._max_rate
            or abs(r) > self._max_rate
        ):
            self.counters.absurd += 1
            return None
        return ImuSample(time_s, np.array(force), np.array(rate))

    def attitude_sample(self, sample: AttitudeSample) -> AttitudeSample | None:
        """``sample`` (an ATTITUDE's) if its angles are finite and plausible."""
        if not (
            math.isfinite(sample.roll_rad)
            and math.isfinite(sample.pitch_rad)
            and math.isfinite(sample.yaw_rad)
        ):
            self.counters.nonfinite += 1
            return None
        if (
            abs(sample.roll_rad) > math.pi + 1e-3
            or abs(sample.pitch_rad) > 0.5 * math.pi + 1e-3
            or abs(sample.yaw_rad) > 2.0 * math.pi
        ):
            self.counters.absurd += 1
            return None
        return sample

    def pwm_sample(self, port: int, time_usec: int, outputs: tuple[int, ...]) -> PwmSample | None:
        """The checked sample of a SERVO_OUTPUT_RAW: its ``port``, uint32 ``time_usec`` and
        channels 1..n_motors ``outputs`` as sent."""
        if port != 0:  # channels 9-16 come as port 1; motors are on 1..n of port 0
            self.counters.not_input += 1
            return None
        low, high = self._output_range
        if min(outputs) < low or max(outputs) > high:
            self.counters.absurd += 1
            return None
        return PwmSample(self._unwrap_uint32_us(time_usec), np.array(outputs, dtype=float))

    def range_sample(
        self,
        orientation: int,
        time_boot_ms: int,
        current_cm: int,
        min_cm: int,
        max_cm: int,
    ) -> RangeSample | None:
        """The checked sample of a DISTANCE_SENSOR (its fields as sent: orientation, time
        [ms], current, minimum and maximum distance [cm]); only a downward one is an input."""
        if orientation != DOWNWARD_ORIENTATION:
            self.counters.not_input += 1
            return None
        distance_m = current_cm * 0.01
        in_sensor_range = min_cm <= current_cm <= max_cm
        if (
            not in_sensor_range
            or not self.limits.range_min_m <= distance_m <= self.limits.range_max_m
        ):
            self.counters.out_of_range += 1
            return None
        return RangeSample(time_s=time_boot_ms * 1e-3, distance_m=distance_m)

    def _fc_position(self, msg: Received) -> FcPosition | None:
        position = (float(msg.x), float(msg.y), float(msg.z))
        if not all(math.isfinite(v) for v in position):
            self.counters.nonfinite += 1
            return None
        return FcPosition(time_s=msg.time_boot_ms * 1e-3, position_ned_m=position)

    def _tension(self, msg: Received) -> TensionReading | None:
        name = msg.name if isinstance(msg.name, bytes) else str(msg.name).encode("ascii", "replace")
        if name.rstrip(b"\0") != self._tension_name:
            self.counters.not_input += 1
            return None
        if (
            msg.get_srcSystem() != self.tension.sensor_system_id
            or msg.get_srcComponent() != self.tension.sensor_component_id
        ):
            self.counters.wrong_system += 1
            return None
        value = float(msg.value)
        if not math.isfinite(value):
            self.counters.nonfinite += 1
            return None
        if abs(value) > 10.0 * self.tension.known_tension_n + 1000.0:
            self.counters.absurd += 1
            return None
        return TensionReading(time_s=msg.time_boot_ms * 1e-3, tension_n=value)

    def _system_time(self, msg: Received) -> None:
        verdict = self.clock.on_system_time(msg.time_boot_ms * 1e-3, self._local_s)
        if verdict == IMPLAUSIBLE:
            self.counters.implausible += 1
        else:
            self.counters.accepted[SYSTEM_TIME] += 1

    def _landed_state(self, msg: Received) -> tuple[str, LandedState] | None:
        state = msg.landed_state
        if state not in LANDED_STATES:
            self.counters.absurd += 1
            return None
        time_s = self.clock.latest_fc_s
        if not math.isfinite(time_s):
            self.counters.no_fc_time += 1
            return None
        return LANDED, LandedState(time_s, int(state))

    # ------------------------------------------------------------------ time checks
    def _timed(self, kind: str, sample: Sample | None) -> tuple[str, Sample] | None:
        """The sample if the clock believes its stamp (a confirmed reboot starts afresh)."""
        if sample is None:
            return None
        verdict = self.clock.check(sample.time_s, self._local_s)
        if verdict != ACCEPT and not self._believed(verdict):
            return None
        return kind, sample

    def _believed(self, verdict: str) -> bool:
        """Count a clock verdict other than ``ACCEPT``; whether its sample goes on (a confirmed
        reboot: the stamps and the reorder buffer start afresh)."""
        counters = self.counters
        if verdict == IMPLAUSIBLE:
            counters.implausible += 1
            return False
        if verdict == BACKSTEP:
            counters.out_of_order += 1
            return False
        if verdict == REBOOT:
            counters.reboots += 1
            self.rebooted = True
            self._latest_by_kind.clear()
            self.reorder.clear()
        return True

    def _in_order(self, kind: str, sample: Sample) -> bool:
        """Per message type, stamps must increase after the reorder buffer."""
        t = sample.time_s
        counters = self.counters
        reorder = self.reorder
        counters.reordered = reorder.reordered
        counters.reorder_window_s = reorder.window_s
        counters.reorder_widened = reorder.widened
        latest = self._latest_by_kind
        previous = latest.get(kind, _NEVER)
        if t == previous:
            counters.duplicate += 1
            return False
        if t < previous:
            counters.out_of_order += 1
            return False
        latest[kind] = t
        counters.accepted[kind] += 1
        return True

    def _unwrap_uint32_us(self, time_usec: int) -> float:
        """SERVO_OUTPUT_RAW's uint32 microseconds to seconds near the latest stamp [s]."""
        latest_s = self.clock.latest_fc_s  # read once, without the property
        if not math.isfinite(latest_s):
            return time_usec * 1e-6
        latest_us = latest_s * 1e6
        wraps = round((latest_us - time_usec) / _UINT32_US)
        return (time_usec + (wraps if wraps > 0 else 0) * _UINT32_US) * 1e-6
