"""The flight controller's input streams straight from frame bytes to checked samples.

:class:`FrameIngest` takes one intact, unsigned MAVLink 2 frame of the flight controller's
input streams (its IMU message, ATTITUDE, SERVO_OUTPUT_RAW, DISTANCE_SENSOR) and gives what
:class:`~tether_companion.mavlink.framing.FrameParser` followed by
:meth:`Ingest.receive <tether_companion.service.ingest.Ingest.receive>` gives for it, without
the message object in between: one function per message unpacks the fields it reads with the
dialect's own wire-order ``struct`` (MAVLink 2's truncated trailing zeros padded back, as
pymavlink does) and hands them to the same checks (``Ingest.imu_sample``...) and the same
clock, reorder and order steps (``Ingest.receive_input``). Everything else, a frame that is
not exactly one such frame (signed, another sender, another message, a bad length or
checksum, bytes waiting in the parser), is left to the caller's generic path (``None``), which
counts it under its own reasons. ``.tlog`` replay runs on it (a record is one frame); the
tests check it gives the generic path's samples bit for bit and the same counts, frame by
frame, on recorded and fuzzed frames.

The live service's UDP link runs on it too, in two halves: the link asks :meth:`FrameIngest.take`
whether a datagram is such a frame, puts it through its trust gate (signatures, the flight
controller's pinned address) and counts it as its parser would, in arrival order; the service
then turns each admitted frame into samples with :meth:`FrameIngest.samples`.

Pure and synchronous.
"""

from __future__ import annotations

import operator
import struct
from collections.abc import Callable

from fastcrc.crc16 import mcrf4xx

from tether_companion.mavlink.fastdecode import MessageLayout, layout_of
from tether_companion.mavlink.framing import FrameParser, dialect
from tether_companion.mavlink.units import MILLI_G_TO_MPS2, MILLI_RAD_TO_RAD
from tether_companion.samples import AttitudeSample
from tether_companion.service.ingest import ATTITUDE, IMU, PWM, RANGE, Ingest, Sample

__all__ = ["FrameIngest"]

_STX_V2 = dialect.PROTOCOL_MARKER_V2
_HEADER_V2 = dialect.HEADER_LEN_V2
_CRC_LEN = 2
_FRONT = struct.Struct("<BBB2xBBI")
"""A MAVLink 2 frame's first 11 bytes in one read, not one index per byte (CPython 3.11 does
not specialise indexing bytes): STX, payload length, incompatibility flags, (compatibility
flags, sequence), system, component, and the 24-bit message id with the payload's first byte
above it."""
_CHECKSUM = struct.Struct("<H")

Convert = Callable[[tuple], Sample | None]
"""A message's unpacked wire-order fields to its checked sample (None: dropped, counted)."""


def _fields(layout: MessageLayout, *names: str) -> list[int]:
    """Indices of ``names`` among the message's unpacked wire-order items (scalar fields)."""
    return [layout.wire_index[name] for name in names]


class FrameIngest:
    """Frames of the flight controller's input streams to checked samples, through ``ingest``.

    Parameters
    ----------
    ingest
        The session's :class:`~tether_companion.service.ingest.Ingest` (its flavour, flight
        controller ids, motor count, checks and counters).
    parser
        The frame parser the caller feeds every other frame to, for :meth:`receive`: an intact
        frame taken there is counted in its
        :class:`~tether_companion.mavlink.framing.FramingCounters` as it would count it
        (``bytes_in``, ``frames_ok``). It must have no gate (signatures and sender addresses
        are the gate's to check). None: only :meth:`take` and :meth:`samples` are used (the
        caller gates and counts them: a live link, see
        :meth:`~tether_companion.mavlink.link.Link.set_receiver`).

    Raises
    ------
    ValueError
        For a parser with a gate.
    """

    def __init__(self, ingest: Ingest, parser: FrameParser | None = None) -> None:
        if parser is not None and parser.gate is not None:
            raise ValueError("FrameIngest bypasses the parser: not for a gated link")
        self._ingest = ingest
        self._parser = parser
        self._system = ingest.link.fc_system_id
        self._component = ingest.link.fc_component_id
        self._table: dict[int, tuple] = {}
        """msg id -> (its layout, crc_extra byte, kind, convert)."""
        if ingest.link.autopilot == "ardupilot":
            self._add("RAW_IMU", IMU, self._raw_imu)
        else:
            self._add("HIGHRES_IMU", IMU, self._highres_imu)
        self._add("ATTITUDE", ATTITUDE, self._attitude)
        self._add("SERVO_OUTPUT_RAW", PWM, self._servo_output_raw)
        self._add("DISTANCE_SENSOR", RANGE, self._distance_sensor)

    def _add(self, name: str, kind: str, make: Callable[[MessageLayout], Convert]) -> None:
        layout = layout_of(name)
        self._table[layout.msg_id] = (layout, bytes((layout.crc_extra,)), kind, make(layout))

    def receive(self, frame: bytes | bytearray, local_s: float | None) -> list[Sample] | None:
        """The samples ``frame`` releases, as ``Ingest.receive`` gives them for the message the
        parser would decode from it (received at local time ``local_s`` [s], or None), when
        ``frame`` is exactly one intact unsigned MAVLink 2 frame of an input stream from the
        flight controller; ``None`` (nothing counted or changed) for anything else: feed it
        to the parser then."""
        parser = self._parser
        if parser is None:
            raise ValueError("FrameIngest.receive needs the parser it falls back to")
        if parser.pending_bytes:
            return None
        entry = self._entry(frame)
        if entry is None:
            return None
        counters = parser.counters
        counters.bytes_in += len(frame)
        counters.frames_ok += 1
        layout, _, kind, convert = entry  # as samples(), without its second look-up
        values = layout.flat_of(frame, _HEADER_V2, len(frame) - _CRC_LEN)
        return self._ingest.receive_input(kind, convert(values), local_s)

    def take(self, frame: bytes | bytearray) -> bool:
        """Whether ``frame`` (a whole datagram or record, starting a frame) is exactly one
        intact unsigned MAVLink 2 frame of an input stream from the flight controller: length
        and ``crc_extra`` checksum checked, nothing counted or changed. Only the configuration
        is read (the flavour's messages, the flight controller's ids)."""
        return self._entry(frame) is not None

    def _entry(self, frame: bytes | bytearray) -> tuple | None:
        """:meth:`take`'s verdict: the frame's entry of the table (layout, ``crc_extra``,
        kind, convert) when it takes the frame, else None."""
        n = len(frame)
        if n <= _HEADER_V2:
            return None
        stx, length, incompat, system, component, msg_id = _FRONT.unpack_from(frame)
        if stx != _STX_V2 or incompat:
            return None
        entry = self._table.get(msg_id & 0xFFFFFF)
        if entry is None or system != self._system or component != self._component:
            return None
        end = n - _CRC_LEN
        if end != _HEADER_V2 + length or length > entry[0].size:
            return None
        if mcrf4xx(entry[1], mcrf4xx(frame[1:end], 0xFFFF)) != _CHECKSUM.unpack_from(frame, end)[0]:
            return None
        return entry

    def samples(self, frame: bytes | bytearray, local_s: float | None) -> list[Sample]:
        """The samples a frame :meth:`take` accepted releases (received at local time
        ``local_s`` [s], or None), counted by the ingest as ``Ingest.receive`` counts the
        message the parser would decode from it; the framing counts are the caller's."""
        layout, _, kind, convert = self._table[_FRONT.unpack_from(frame)[5] & 0xFFFFFF]
        values = layout.flat_of(frame, _HEADER_V2, len(frame) - _CRC_LEN)
        return self._ingest.receive_input(kind, convert(values), local_s)

    # ------------------------------------------------------------------ per message
    def _raw_imu(self, layout: MessageLayout) -> Convert:
        """RAW_IMU (milli-g, milli-rad/s, ``time_usec``), as ``units.raw_imu_si``."""
        t, ax, ay, az, gx, gy, gz, imu_id = _fields(
            layout, "time_usec", "xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "id"
        )
        check = self._ingest.imu_sample
        g, rad = MILLI_G_TO_MPS2, MILLI_RAD_TO_RAD

        def convert(f: tuple) -> Sample | None:
            return check(
                f[imu_id],
                f[t] * 1e-6,
                (f[ax] * g, f[ay] * g, f[az] * g),
                (f[gx] * rad, f[gy] * rad, f[gz] * rad),
            )

        return convert

    def _highres_imu(self, layout: MessageLayout) -> Convert:
        """HIGHRES_IMU (m/s^2, rad/s, ``time_usec``; floats on the wire), as
        ``units.highres_imu_si``."""
        t, ax, ay, az, gx, gy, gz, imu_id = _fields(
            layout, "time_usec", "xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "id"
        )
        check = self._ingest.imu_sample

        def convert(f: tuple) -> Sample | None:
            return check(f[imu_id], f[t] * 1e-6, (f[ax], f[ay], f[az]), (f[gx], f[gy], f[gz]))

        return convert

    def _attitude(self, layout: MessageLayout) -> Convert:
        """ATTITUDE, as ``units.attitude_from_attitude``."""
        t, roll, pitch, yaw = _fields(layout, "time_boot_ms", "roll", "pitch", "yaw")
        check = self._ingest.attitude_sample

        def convert(f: tuple) -> Sample | None:
            return check(AttitudeSample(f[t] * 1e-3, f[roll], f[pitch], f[yaw]))

        return convert

    def _servo_output_raw(self, layout: MessageLayout) -> Convert:
        """SERVO_OUTPUT_RAW's port, ``time_usec`` and channels 1..n_motors."""
        channels = _fields(layout, *(f"servo{i + 1}_raw" for i in range(self._ingest.n_motors)))
        outputs = operator.itemgetter(*channels, channels[0])  # a tuple for one motor too
        port, t = _fields(layout, "port", "time_usec")
        check = self._ingest.pwm_sample

        def convert(f: tuple) -> Sample | None:
            return check(f[port], f[t], outputs(f)[:-1])

        return convert

    def _distance_sensor(self, layout: MessageLayout) -> Convert:
        """DISTANCE_SENSOR's orientation, time and distances [cm]."""
        orientation, t, current, low, high = _fields(
            layout,
            "orientation",
            "time_boot_ms",
            "current_distance",
            "min_distance",
            "max_distance",
        )
        check = self._ingest.range_sample

        def convert(f: tuple) -> Sample | None:
            return check(f[orientation], f[t], f[current], f[low], f[high])

        return convert
