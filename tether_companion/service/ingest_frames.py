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

Where the optional extension ``_frame_core`` is built (``frame_core.c``), the test, the fields'
read and the frame's checked sample (the message's units and ``Ingest``'s value checks, the
sample object, or the reason of a drop) are one C call each, bit for bit this module's Python
and ``Ingest``'s checks, which stay the reference (``TETHER_PURE_PYTHON=1`` runs them;
``tests/test_frame_core.py`` compares the two).

Pure and synchronous.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Callable
from operator import itemgetter

import numpy as np
from fastcrc.crc16 import mcrf4xx

from tether_companion.estimation.optional_core import load
from tether_companion.mavlink.fastdecode import layout_of
from tether_companion.mavlink.framing import FrameParser, dialect
from tether_companion.mavlink.units import (
    DOWNWARD_ORIENTATION,
    MILLI_G_TO_MPS2,
    MILLI_RAD_TO_RAD,
)
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
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
"""A message's fields, ``(code, value, ...)`` as :meth:`FrameIngest.fields` gives them, to its
checked sample (None: dropped, counted)."""


_CONVERSIONS = ("RAW_IMU", "HIGHRES_IMU", "ATTITUDE", "SERVO_OUTPUT_RAW", "DISTANCE_SENSOR")
"""The messages ``frame_reader.c``'s ``Reader`` converts, by its conversion number."""
_IMU_FIELDS = ("time_usec", "xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "id")
_CORE = load("tether_companion.service._frame_core")
"""``frame_core.c``: :meth:`FrameIngest.take`, :meth:`FrameIngest.fields` and the frame's
checked sample (``Reader``) in one C call each (None: not built, or ``TETHER_PURE_PYTHON``)."""


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
        """msg id -> (its layout, crc_extra byte, code, its fields' picker)."""
        self._kinds: list[tuple[str, Convert]] = []
        """code -> (kind, convert)."""
        self._spec = b""
        """The table's entries for ``frame_core.c`` (see there)."""
        self._conversions = b""
        """Per code, ``frame_reader.c``'s conversion of the message (0 RAW_IMU ... 4
        DISTANCE_SENSOR)."""
        if ingest.link.autopilot == "ardupilot":
            self._add("RAW_IMU", IMU, self._raw_imu)
        else:
            self._add("HIGHRES_IMU", IMU, self._highres_imu)
        self._add("ATTITUDE", ATTITUDE, self._attitude)
        self._add("SERVO_OUTPUT_RAW", PWM, self._servo_output_raw)
        self._add("DISTANCE_SENSOR", RANGE, self._distance_sensor)
        self._read: Callable[[bytes | bytearray], tuple | None] = self._read_fields
        """``frame -> None | (kind, sample, dropped)``: None for a frame :meth:`take` refuses,
        else the frame's input kind and its checked sample, or None and the reason it was
        dropped, when that is not counted yet (C's ``Reader.read``; the Python reference's
        checks count their drops themselves)."""
        if _CORE is not None and 0 <= self._system <= 255 and 0 <= self._component <= 255:
            spec = bytes((self._system, self._component, len(self._kinds))) + self._spec
            self.take = functools.partial(_CORE.take, spec)  # type: ignore[method-assign]
            self.fields = functools.partial(_CORE.fields, spec)  # type: ignore[method-assign]
            bounds = (MILLI_G_TO_MPS2, MILLI_RAD_TO_RAD, *ingest.check_bounds())
            fills = getattr(_CORE, "READER_FILLS", 0)  # an older build: the Python reads
            if fills and 1 <= ingest.n_motors <= 16 and all(float(b) == b for b in bounds):
                reader = _CORE.Reader(
                    spec,
                    self._conversions,
                    tuple(kind for kind, _ in self._kinds),
                    (*map(float, bounds), ingest.n_motors, DOWNWARD_ORIENTATION),
                    ingest.clock,
                    (ImuSample, AttitudeSample, PwmSample, RangeSample),
                    np.empty,  # filled in C: the arrays np.array of the values makes
                )
                self._read = reader.read
                if ingest.core is not None:  # read, drop counted, receive_input: one C call
                    ingest.core.set_reader(reader)
                    self.samples = ingest.core.samples  # type: ignore[method-assign]

    def _add(
        self, name: str, kind: str, make: Callable[[], tuple[Convert, tuple[str, ...]]]
    ) -> None:
        """Message ``name`` of input ``kind``: ``make()`` gives its convert and the names of
        the fields it takes."""
        layout = layout_of(name)
        convert, names = make()
        code = len(self._kinds)
        self._conversions += bytes((_CONVERSIONS.index(name),))
        self._kinds.append((kind, convert))
        picked = [layout.wire_index[field] for field in names]
        crc_extra = bytes((layout.crc_extra,))
        self._table[layout.msg_id] = (layout, crc_extra, code, itemgetter(*picked))
        offsets, types = layout.wire_offsets, layout.wire_formats
        self._spec += struct.pack(
            "<IBBBB", layout.msg_id, layout.crc_extra, layout.size, code, len(picked)
        )
        self._spec += b"".join(bytes((offsets[i], ord(types[i]))) for i in picked)

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
        read = self._read(frame)
        if read is None:
            return None
        counters = parser.counters
        counters.bytes_in += len(frame)
        counters.frames_ok += 1
        return self._received(read, local_s)

    def take(self, frame: bytes | bytearray) -> bool:
        """Whether ``frame`` (a whole datagram or record, starting a frame) is exactly one
        intact unsigned MAVLink 2 frame of an input stream from the flight controller: length
        and ``crc_extra`` checksum checked, nothing counted or changed. Only the configuration
        is read (the flavour's messages, the flight controller's ids). (The Python reference;
        an instance runs ``frame_core.c``'s twin where it is built.)"""
        return self._entry(frame) is not None

    def fields(self, frame: bytes | bytearray) -> tuple | None:
        """``(code, value, ...)``: the fields the sample of a frame :meth:`take` accepts is made
        of (its convert's, as the message's wire-order ``struct`` unpacks them; a truncated
        MAVLink 2 payload padded with zeros), after the code of its table entry; ``None`` for a
        frame :meth:`take` refuses. (The Python reference, as :meth:`take`.)"""
        entry = self._entry(frame)
        if entry is None:
            return None
        layout, _, code, pick = entry
        return (code, *pick(layout.flat_of(frame, _HEADER_V2, len(frame) - _CRC_LEN)))

    def _entry(self, frame: bytes | bytearray) -> tuple | None:
        """:meth:`take`'s verdict: the frame's entry of the table (layout, ``crc_extra``,
        code, fields' picker) when it takes the frame, else None."""
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
        message the parser would decode from it; the framing counts are the caller's. (The
        Python reference; with ``Reader`` and ``Ingest.core`` built, an instance runs
        ``IngestCore.samples``: the read, the drop's count and ``receive_input`` in one C
        call.)"""
        return self._received(self._read(frame), local_s)  # type: ignore[arg-type]

    def _received(self, read: tuple, local_s: float | None) -> list[Sample]:
        """The samples :meth:`_read`'s ``(kind, sample, dropped)`` releases through the
        ingest (a drop not counted yet counted under its reason)."""
        kind, sample, dropped = read
        if dropped is not None:
            counters = self._ingest.counters
            setattr(counters, dropped, getattr(counters, dropped) + 1)
        return self._ingest.receive_input(kind, sample, local_s)

    def _read_fields(self, frame: bytes | bytearray) -> tuple | None:
        """:attr:`_read`'s Python reference: the frame's fields through its convert and the
        ingest's check (which counts a drop itself)."""
        fields = self.fields(frame)
        if fields is None:
            return None
        kind, convert = self._kinds[fields[0]]
        return kind, convert(fields), None

    # ------------------------------------------------------------------ per message
    # each: the sample's convert, taking (code, value, ...) as fields() gives them, and the
    # names of those values (pymavlink's field names)
    def _raw_imu(self) -> tuple[Convert, tuple[str, ...]]:
        """RAW_IMU (milli-g, milli-rad/s, ``time_usec``), as ``units.raw_imu_si``."""
        check = self._ingest.imu_sample
        g, rad = MILLI_G_TO_MPS2, MILLI_RAD_TO_RAD

        def convert(f: tuple) -> Sample | None:
            _, t, ax, ay, az, gx, gy, gz, imu_id = f
            return check(imu_id, t * 1e-6, (ax * g, ay * g, az * g), (gx * rad, gy * rad, gz * rad))

        return convert, _IMU_FIELDS

    def _highres_imu(self) -> tuple[Convert, tuple[str, ...]]:
        """HIGHRES_IMU (m/s^2, rad/s, ``time_usec``; floats on the wire), as
        ``units.highres_imu_si``."""
        check = self._ingest.imu_sample

        def convert(f: tuple) -> Sample | None:
            _, t, ax, ay, az, gx, gy, gz, imu_id = f
            return check(imu_id, t * 1e-6, (ax, ay, az), (gx, gy, gz))

        return convert, _IMU_FIELDS

    def _attitude(self) -> tuple[Convert, tuple[str, ...]]:
        """ATTITUDE, as ``units.attitude_from_attitude``."""
        check = self._ingest.attitude_sample

        def convert(f: tuple) -> Sample | None:
            _, t, roll, pitch, yaw = f
            return check(AttitudeSample(t * 1e-3, roll, pitch, yaw))

        return convert, ("time_boot_ms", "roll", "pitch", "yaw")

    def _servo_output_raw(self) -> tuple[Convert, tuple[str, ...]]:
        """SERVO_OUTPUT_RAW's port, ``time_usec`` and channels 1..n_motors."""
        check = self._ingest.pwm_sample

        def convert(f: tuple) -> Sample | None:
            return check(f[1], f[2], f[3:])

        channels = tuple(f"servo{i + 1}_raw" for i in range(self._ingest.n_motors))
        return convert, ("port", "time_usec", *channels)

    def _distance_sensor(self) -> tuple[Convert, tuple[str, ...]]:
        """DISTANCE_SENSOR's orientation, time and distances [cm]."""
        check = self._ingest.range_sample

        def convert(f: tuple) -> Sample | None:
            _, orientation, t, current, low, high = f
            return check(orientation, t, current, low, high)

        names = ("orientation", "time_boot_ms", "current_distance", "min_distance", "max_distance")
        return convert, names
