"""MAVLink framing: bytes to messages and back, with no I/O.

Messages are pymavlink's ``ardupilotmega`` dialect classes (which include ``common``); frames
are MAVLink 2 on output and MAVLink 1 or 2 on input. The parser is written for hostile input:
it never raises on bad bytes, it resynchronises one byte after a start marker whose frame
fails its checksum (so a stray 0xFD in garbage cannot swallow the good frame behind it), and
it counts everything it throws away in :class:`FramingCounters`.

Why not pymavlink's own ``MAVLink.parse_char``: on a bad checksum it raises and discards the
whole claimed frame (up to 280 bytes), and it keeps no per-cause counts. Here pymavlink still
decodes the payload (``MAVLink.decode``) once the frame is known to be intact, except for the
estimators' input streams, which :class:`~tether_companion.mavlink.fastdecode.FastDecoder`
turns into :class:`~tether_companion.mavlink.fastdecode.HotRecord` s (the same fields, the
part of the message interface receivers use) from precompiled layouts (``fast=False`` turns
that off: pymavlink objects for every message).

Example
-------
>>> enc = FrameEncoder(system_id=1, component_id=1)
>>> data = enc.encode(dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3))
>>> parser = FrameParser()
>>> [m.get_type() for m in parser.feed(data)]
['HEARTBEAT']
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

from fastcrc.crc16 import mcrf4xx
from pymavlink.dialects.v20 import ardupilotmega as dialect

from tether_companion.mavlink.fastdecode import FastDecoder, HotRecord
from tether_companion.mavlink.fastencode import FastEncoder

if TYPE_CHECKING:
    from tether_companion.mavlink.signing import Signer
    from tether_companion.mavlink.trust import FrameGate

__all__ = [
    "FrameEncoder",
    "FrameParser",
    "FramingCounters",
    "MAVLinkMessage",
    "Received",
    "dialect",
]

MAVLinkMessage = dialect.MAVLink_message
"""Base class of every decoded message (``msg.get_type()``, ``msg.get_srcSystem()``, ...)."""
Received = MAVLinkMessage | HotRecord
"""What a :class:`FrameParser` returns: pymavlink's message, or for the hot input streams a
record with the same fields and ``get_type()``, ``get_srcSystem()``, ``get_srcComponent()``,
``get_seq()``, ``get_msgbuf()``."""

_STX_V1 = dialect.PROTOCOL_MARKER_V1
_STX_V2 = dialect.PROTOCOL_MARKER_V2
_HEADER_V1 = dialect.HEADER_LEN_V1
_HEADER_V2 = dialect.HEADER_LEN_V2
_SIGNATURE_LEN = dialect.MAVLINK_SIGNATURE_BLOCK_LEN
_IFLAG_SIGNED = dialect.MAVLINK_IFLAG_SIGNED
_CRC_LEN = 2
_MESSAGE_TYPES = dialect.mavlink_map
_KNOWN = {
    msg_id: (cls.unpacker.size, bytes((cls.crc_extra,))) for msg_id, cls in _MESSAGE_TYPES.items()
}
"""Each known message's largest payload (all fields incl. extensions) [bytes] and the byte its
checksum ends with (its ``crc_extra``)."""
_MAX_BUFFER_BYTES = 1 << 16
"""A stream parser never holds more than this many unparsed bytes (a frame is <= 280)."""


def _checksum(covered: bytes | bytearray, extra: bytes) -> int:
    """MAVLink's CRC-16/MCRF4XX of ``covered`` (header after the marker, payload) then the
    message's ``crc_extra`` byte: fastcrc's C function (pymavlink's own dependency), called
    directly instead of through a pymavlink ``x25crc`` object per frame."""
    return mcrf4xx(extra, mcrf4xx(covered, 0xFFFF))


@dataclass
class FramingCounters:
    """What a :class:`FrameParser` accepted and threw away (monotonic counts)."""

    bytes_in: int = 0
    """Bytes fed."""
    frames_ok: int = 0
    """Frames with a valid checksum that decoded to a known message."""
    garbage_bytes: int = 0
    """Bytes skipped while looking for a start marker (incl. the marker of a bad frame)."""
    bad_crc: int = 0
    """Frames of a known message id whose checksum did not match."""
    bad_header: int = 0
    """Start markers followed by unsupported incompatibility flags, or by a payload length
    larger than the message id allows."""
    unknown_id: int = 0
    """Complete frames whose message id the dialect does not define (skipped whole). With no
    checksum to check, such a frame is believed only when a start marker (or the end of the
    data) follows it; otherwise its first byte counts as garbage and parsing resumes after it."""
    bad_payload: int = 0
    """Intact frames pymavlink could not turn into a message."""
    truncated: int = 0
    """Datagrams (UDP) that ended inside a frame: a cut frame or a stray start marker."""
    untrusted: int = 0
    """Intact frames the link's gate refused (signature, sender address; see
    :mod:`tether_companion.mavlink.trust` for the reasons)."""

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain mapping (for status views and JSON)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @property
    def errors(self) -> int:
        """Everything rejected: bad checksums, headers, payloads, unknown ids, truncations."""
        return self.bad_crc + self.bad_header + self.unknown_id + self.bad_payload + self.truncated


class FrameParser:
    """Incremental MAVLink 1/2 frame parser for a byte stream or a sequence of datagrams.

    Feed it bytes as they arrive with :meth:`feed`; it returns the complete messages and keeps
    any partial frame for the next call. For datagram transports call :meth:`end_datagram`
    after each datagram: a frame never spans two UDP datagrams, so a leftover is truncated.

    With a ``gate`` (:class:`~tether_companion.mavlink.trust.FrameGate`), every intact frame is
    offered to ``gate.admit(frame, source)`` before it is decoded, and dropped (counted as
    ``untrusted``) when refused: signatures and sender addresses are checked there. Without
    one, signed frames are decoded without checking the signature.

    With ``fast`` (the default) the hot input messages of admitted frames are decoded by a
    :class:`~tether_companion.mavlink.fastdecode.FastDecoder` into records (same fields, same
    counts; ``record.to_message()`` gives pymavlink's object).
    """

    def __init__(
        self,
        counters: FramingCounters | None = None,
        gate: FrameGate | None = None,
        *,
        fast: bool = True,
    ) -> None:
        self._buf = bytearray()
        self._decoder = dialect.MAVLink(None)
        self._fast = FastDecoder() if fast else None
        self.counters = FramingCounters() if counters is None else counters
        """Counts of what was accepted and dropped; pass one object to several parsers (one
        per TCP client of a server, say) to total them."""
        self.gate = gate
        self._source: Hashable | None = None

    def feed(
        self, data: bytes | bytearray | memoryview, source: Hashable | None = None
    ) -> list[Received]:
        """Add ``data`` (sent by ``source``: an address, for the gate) and return every message
        completed by it, in order."""
        n = len(data)
        self.counters.bytes_in += n
        self._source = source
        if not self._buf and n > _HEADER_V2 and data[0] == _STX_V2:
            whole = self._whole_frame(data, n)
            if whole is not None:
                return whole
        self._buf += data
        return self._parse()

    def _whole_frame(self, data: bytes | bytearray | memoryview, n: int) -> list[Received] | None:
        """What :meth:`_parse` returns for ``data`` in an empty buffer when ``data`` is exactly
        one intact MAVLink 2 frame of a known id (a datagram's usual content, and a .tlog
        record's), with the same counts; None, with nothing counted, for anything else
        (:meth:`_parse` then takes it byte by byte).

        The same tests as :meth:`_parse`'s on a buffer that holds one whole frame, without
        its loop and buffer: once the checksum holds, the frame is offered to the gate and
        decoded exactly as there."""
        incompat = data[2]
        if incompat & ~_IFLAG_SIGNED:
            return None
        length = data[1]
        signature_len = _SIGNATURE_LEN if incompat else 0
        if n != _HEADER_V2 + length + _CRC_LEN + signature_len:
            return None
        msg_id = data[7] | (data[8] << 8) | (data[9] << 16)
        known = _KNOWN.get(msg_id)
        if known is None or length > known[0]:
            return None
        end = n - signature_len - _CRC_LEN
        if _checksum(data[1:end], known[1]) != data[end] | (data[end + 1] << 8):
            return None
        frame = bytearray(data)
        counters = self.counters
        if self.gate is not None and not self.gate.admit(frame, self._source):
            counters.untrusted += 1
            return []
        layout = None if self._fast is None else self._fast.layouts.get(msg_id)
        msg: Received
        if layout is not None:
            msg = layout.record_of(frame, _HEADER_V2, end, data[5], data[6], data[4])
        else:
            try:
                msg = self._decoder.decode(frame)
            except Exception:  # noqa: BLE001 - pymavlink raises assorted errors on odd payloads
                counters.bad_payload += 1
                return []
        counters.frames_ok += 1
        return [msg]

    def _parse(self) -> list[Received]:
        """Frames in the buffer; an incomplete one stays for the next call."""
        out: list[Received] = []
        buf = self._buf
        pos = 0
        counters = self.counters
        fast = self._fast
        n = len(buf)
        while pos < n:
            stx = buf[pos]
            if stx != _STX_V2 and stx != _STX_V1:
                nxt = _next_marker(buf, pos + 1)
                counters.garbage_bytes += nxt - pos
                pos = nxt
                continue
            if stx == _STX_V2:
                if n - pos < 3:
                    break
                incompat = buf[pos + 2]
                if incompat & ~_IFLAG_SIGNED:
                    counters.bad_header += 1
                    counters.garbage_bytes += 1
                    pos += 1
                    continue
                header_len = _HEADER_V2
                frame_len = header_len + buf[pos + 1] + _CRC_LEN
                if incompat & _IFLAG_SIGNED:
                    frame_len += _SIGNATURE_LEN
                if n - pos < header_len:
                    break
                msg_id = buf[pos + 7] | (buf[pos + 8] << 8) | (buf[pos + 9] << 16)
            else:
                if n - pos < 2:
                    break
                header_len = _HEADER_V1
                frame_len = header_len + buf[pos + 1] + _CRC_LEN
                if n - pos < header_len:
                    break
                msg_id = buf[pos + 5]
                incompat = 0
            known = _KNOWN.get(msg_id)
            if known is not None and buf[pos + 1] > known[0]:
                # longer than the message can be: a stray marker, known without waiting
                counters.bad_header += 1
                counters.garbage_bytes += 1
                pos += 1
                continue
            if n - pos < frame_len:
                break
            if known is None:
                # No checksum to verify: take it as a frame only if the next frame (or the end
                # of the data) follows where its length says; otherwise it is a stray marker.
                end = pos + frame_len
                if end == n or buf[end] == _STX_V2 or buf[end] == _STX_V1:
                    counters.unknown_id += 1
                    pos = end
                else:
                    counters.garbage_bytes += 1
                    pos += 1
                continue
            signature_len = _SIGNATURE_LEN if incompat & _IFLAG_SIGNED else 0
            crc_end = pos + frame_len - signature_len
            crc = _checksum(buf[pos + 1 : crc_end - _CRC_LEN], known[1])
            if crc != buf[crc_end - 2] | (buf[crc_end - 1] << 8):  # little-endian on the wire
                counters.bad_crc += 1
                counters.garbage_bytes += 1
                pos += 1
                continue
            frame = buf[pos : pos + frame_len]
            if self.gate is not None and not self.gate.admit(frame, self._source):
                counters.untrusted += 1
                pos += frame_len
                continue
            msg: Received
            if fast is not None and msg_id in fast.layouts:
                msg = fast.decode(frame, signature_len)
            else:
                try:
                    msg = self._decoder.decode(frame)
                except Exception:  # noqa: BLE001 - pymavlink raises assorted errors on odd payloads
                    counters.bad_payload += 1
                    pos += frame_len
                    continue
            counters.frames_ok += 1
            out.append(msg)
            pos += frame_len
        del buf[:pos]
        if len(buf) > _MAX_BUFFER_BYTES:  # cannot happen with valid lengths; belt and braces
            counters.garbage_bytes += len(buf)
            buf.clear()
        return out

    def end_datagram(self) -> list[Received]:
        """Close the datagram just fed; returns frames recovered behind a false start marker.

        A frame never spans two UDP datagrams, so bytes left waiting for "the rest of a frame"
        are a truncated frame or a stray start marker (counted once as ``truncated``). The
        parser drops the first byte and looks again, so a good frame behind a stray marker in
        the same datagram is not lost.
        """
        out: list[Received] = []
        if self._buf:
            self.counters.truncated += 1
        while self._buf:
            del self._buf[0]
            self.counters.garbage_bytes += 1
            out.extend(self._parse())
        return out

    @property
    def pending_bytes(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buf)


def _next_marker(buf: bytearray, start: int) -> int:
    """Index of the next MAVLink start marker at or after ``start`` (``len(buf)`` if none)."""
    i2 = buf.find(_STX_V2, start)
    i1 = buf.find(_STX_V1, start)
    if i2 < 0:
        return i1 if i1 >= 0 else len(buf)
    if i1 < 0:
        return i2
    return min(i1, i2)


class FrameEncoder:
    """Packs messages into MAVLink 2 frames as one system/component, counting the sequence.

    One encoder per link: the sequence number is per channel, as on a flight controller.

    Parameters
    ----------
    system_id, component_id
        Identity written into every frame's header (1..255).
    signer
        Signs every frame (MAVLink 2 signing) when given.
    """

    def __init__(self, system_id: int, component_id: int, signer: Signer | None = None) -> None:
        if not (1 <= system_id <= 255 and 0 <= component_id <= 255):
            raise ValueError(f"system_id {system_id} / component_id {component_id} out of range")
        self._packer = dialect.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._fast = FastEncoder()
        self.frames_out = 0
        self.signer = signer

    @property
    def factory(self) -> dialect.MAVLink:
        """pymavlink's message constructors (``encoder.factory.heartbeat_encode(...)``)."""
        return self._packer

    @property
    def system_id(self) -> int:
        """This encoder's MAVLink system id."""
        return self._packer.srcSystem

    @property
    def component_id(self) -> int:
        """This encoder's MAVLink component id."""
        return self._packer.srcComponent

    def encode(self, msg: MAVLinkMessage) -> bytes:
        """One MAVLink 2 frame holding ``msg`` (pymavlink's bytes, made by
        :class:`~tether_companion.mavlink.fastencode.FastEncoder`); advances the sequence number.

        Raises
        ------
        struct.error
            When a field does not fit its wire type (callers convert and saturate first,
            see :mod:`tether_companion.mavlink.units`).
        """
        packer = self._packer
        frame = self._fast.frame(msg, packer.seq, packer.srcSystem, packer.srcComponent)
        packer.seq = (packer.seq + 1) & 0xFF
        self.frames_out += 1
        if self.signer is not None:
            return self.signer.sign(frame)
        return frame
