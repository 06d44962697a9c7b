"""MAVLink 2 message signing: sign outgoing frames, verify incoming ones (pure, no I/O).

The scheme (MAVLink 2 "Message Signing", mavlink.io/en/guide/message_signing.html):

* a signed frame has bit 0x01 (``MAVLINK_IFLAG_SIGNED``) set in its incompatibility flags and
  13 more bytes after the CRC: ``link_id`` (1 byte), ``timestamp`` (48-bit little-endian, in
  10 us units since 2015-01-01 00:00:00 UTC) and ``signature`` (6 bytes);
* ``signature`` is the first 6 bytes of ``SHA-256(secret_key + header + payload + CRC + link_id
  + timestamp)``, where the header starts at the 0xFD marker and the 32-byte secret key is
  shared by every signing party;
* a receiver keeps the last timestamp of each stream ``(system id, component id, link id)``:
  a frame whose timestamp is not newer than its stream's last one is a replay; a frame that
  opens a new stream is refused when its timestamp is more than one minute behind the
  receiver's own timestamp (so a recorded frame of a stream the receiver has not seen since
  its start cannot be replayed later);
* each party's own timestamp is the largest of its clock, the last one it sent plus one and
  the newest it accepted, so it never goes back even without a wall clock.

:class:`SignatureVerifier` returns why a frame was refused (:data:`UNSIGNED`,
:data:`BAD_SIGNATURE`, :data:`REPLAY`, :data:`STALE_STREAM`, :data:`MALFORMED`); the caller
decides what a refusal means (``security.signing``, see :mod:`tether_companion.mavlink.trust`).
:func:`sign_frame` turns any unsigned MAVLink 2 frame into a signed one.

Example
-------
>>> key = bytes(range(32))
>>> signer = Signer(key, link_id=1, clock_s=lambda: 1.7e9)
>>> verifier = SignatureVerifier(key, clock_s=lambda: 1.7e9)
>>> from tether_companion.mavlink.framing import FrameEncoder, dialect
>>> frame = FrameEncoder(1, 1).encode(dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3))
>>> signed = signer.sign(frame)
>>> verifier.check(signed) is None
True
>>> verifier.check(signed)  # the same frame again
'replay'
"""

from __future__ import annotations

import hashlib
import os
import stat
import struct
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as dialect

from tether_companion.config import ConfigError

__all__ = [
    "BAD_SIGNATURE",
    "EPOCH_2015_UNIX_S",
    "KEY_BYTES",
    "MALFORMED",
    "NEW_STREAM_WINDOW",
    "REPLAY",
    "SIGNATURE_BLOCK_BYTES",
    "STALE_STREAM",
    "UNSIGNED",
    "SignatureVerifier",
    "Signer",
    "SigningCounters",
    "is_signed",
    "load_key",
    "sign_frame",
    "signature",
    "timestamp_from_unix_s",
]

KEY_BYTES = 32
"""Length of the shared secret key [bytes]."""
SIGNATURE_BLOCK_BYTES = 13
"""link id (1) + timestamp (6) + signature (6) appended to a signed frame [bytes]."""
EPOCH_2015_UNIX_S = 1420070400
"""2015-01-01 00:00:00 UTC as Unix time [s]: the signing timestamp's zero."""
TICKS_PER_S = 100_000
"""Signing timestamp units per second (10 us each)."""
NEW_STREAM_WINDOW = 60 * TICKS_PER_S
"""A new stream's first timestamp may lag our own by at most this [10 us] (one minute)."""
MAX_TIMESTAMP = (1 << 48) - 1
MAX_STREAMS = 1024
"""Streams remembered (least recently used forgotten); only correctly signed frames add one."""
MAX_KEY_FILE_BYTES = 4096

UNSIGNED = "unsigned"
BAD_SIGNATURE = "bad_signature"
REPLAY = "replay"
STALE_STREAM = "stale_stream"
MALFORMED = "malformed"

_HEADER_V2 = 10
_CRC_BYTES = 2
_IFLAG_SIGNED = dialect.MAVLINK_IFLAG_SIGNED
_STX_V2 = dialect.PROTOCOL_MARKER_V2
_CRC = struct.Struct("<H")
_TIMESTAMP = struct.Struct("<Q")


def timestamp_from_unix_s(unix_s: float) -> int:
    """Signing timestamp [10 us since 2015-01-01 UTC] of Unix time ``unix_s`` [s] (>= 0)."""
    return max(0, min(MAX_TIMESTAMP, int((unix_s - EPOCH_2015_UNIX_S) * TICKS_PER_S)))


def signature(key: bytes, signed_part: bytes | bytearray | memoryview) -> bytes:
    """The 6-byte signature of ``signed_part`` (header .. CRC, link id, timestamp)."""
    digest = hashlib.sha256()
    digest.update(key)
    digest.update(signed_part)
    return digest.digest()[:6]


def is_signed(frame: bytes | bytearray | memoryview) -> bool:
    """True for a MAVLink 2 frame whose incompatibility flags say it carries a signature."""
    return len(frame) > 2 and frame[0] == _STX_V2 and bool(frame[2] & _IFLAG_SIGNED)


def sign_frame(frame: bytes | bytearray, key: bytes, link_id: int, timestamp: int) -> bytes:
    """A signed copy of the unsigned MAVLink 2 ``frame``.

    The signed flag is part of the header, which the CRC covers, so the CRC is recomputed
    (with the message's CRC_EXTRA) before the signature block is appended.

    Raises
    ------
    ValueError
        When ``frame`` is not a complete unsigned MAVLink 2 frame of a known message, or the
        key, link id or timestamp is out of range.
    """
    if len(key) != KEY_BYTES:
        raise ValueError(f"signing key must be {KEY_BYTES} bytes, got {len(key)}")
    if not 0 <= link_id <= 255 or not 0 <= timestamp <= MAX_TIMESTAMP:
        raise ValueError(f"link id {link_id} / timestamp {timestamp} out of range")
    if len(frame) < _HEADER_V2 + _CRC_BYTES or frame[0] != _STX_V2 or frame[2] & _IFLAG_SIGNED:
        raise ValueError("not an unsigned MAVLink 2 frame")
    if len(frame) != _HEADER_V2 + frame[1] + _CRC_BYTES:
        raise ValueError("frame length does not match its payload length")
    msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
    msg_type = dialect.mavlink_map.get(msg_id)
    if msg_type is None:
        raise ValueError(f"unknown message id {msg_id}")
    out = bytearray(frame)
    out[2] |= _IFLAG_SIGNED
    crc = dialect.x25crc(out[1:-_CRC_BYTES])
    crc.accumulate(bytes((msg_type.crc_extra,)))
    _CRC.pack_into(out, len(out) - _CRC_BYTES, crc.crc)
    out.append(link_id)
    out += _TIMESTAMP.pack(timestamp)[:6]
    out += signature(key, out)
    return bytes(out)


def load_key(path: str | Path, *, key_name: str = "security.key_file") -> bytes:
    """Read a 32-byte signing key from ``path`` (raw 32 bytes, or 64 hexadecimal digits).

    The file must be a regular file readable only by its owner: a key others can read is not
    a secret (``chmod 600 FILE``).

    Raises
    ------
    ConfigError
        Naming the file and what is wrong (missing, group/world-accessible, wrong size or
        format).
    """
    path = Path(path)
    try:
        info = os.stat(path)
    except OSError as exc:
        raise ConfigError(
            "", key_name, str(path), f"cannot read the key file ({exc.strerror})"
        ) from None
    if not stat.S_ISREG(info.st_mode):
        raise ConfigError("", key_name, str(path), "the key must be a regular file")
    if info.st_mode & 0o077:
        raise ConfigError(
            "",
            key_name,
            str(path),
            f"the key file is accessible to group/others (mode {stat.S_IMODE(info.st_mode):04o});"
            f" run: chmod 600 {path}",
        )
    if info.st_size > MAX_KEY_FILE_BYTES:
        raise ConfigError("", key_name, str(path), "expected 32 bytes or 64 hex digits")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(
            "", key_name, str(path), f"cannot read the key file ({exc.strerror})"
        ) from None
    if len(data) == KEY_BYTES:
        return data
    text = data.strip()
    try:
        key = bytes.fromhex(text.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) != KEY_BYTES:
        raise ConfigError(
            "",
            key_name,
            str(path),
            f"expected 32 raw bytes or 64 hex digits, got {len(data)} bytes",
        )
    return key


class Signer:
    """Signs outgoing frames of one link with that link's id.

    Parameters
    ----------
    key
        The 32-byte shared secret.
    link_id
        This link's id (0..255), written into every signature block.
    clock_s
        Unix time [s] (injected in tests); the timestamp never goes back even when it does.
    """

    def __init__(self, key: bytes, link_id: int, clock_s: Callable[[], float] = time.time) -> None:
        if len(key) != KEY_BYTES:
            raise ValueError(f"signing key must be {KEY_BYTES} bytes")
        if not 0 <= link_id <= 255:
            raise ValueError(f"link id {link_id} out of 0..255")
        self.key = key
        self.link_id = link_id
        self._clock_s = clock_s
        self.timestamp = 0
        """Last timestamp used [10 us since 2015]."""

    def observe(self, timestamp: int) -> None:
        """Raise our timestamp to one accepted from a peer (the spec's shared time base)."""
        self.timestamp = max(self.timestamp, timestamp)

    def next_timestamp(self) -> int:
        """The timestamp for the next frame: clock, or one more than the last, whichever is
        later."""
        self.timestamp = max(self.timestamp + 1, timestamp_from_unix_s(self._clock_s()))
        return self.timestamp

    def sign(self, frame: bytes | bytearray) -> bytes:
        """A signed copy of the unsigned MAVLink 2 ``frame`` (see :func:`sign_frame`)."""
        return sign_frame(frame, self.key, self.link_id, self.next_timestamp())


@dataclass
class SigningCounters:
    """What a :class:`SignatureVerifier` accepted and refused (monotonic counts)."""

    accepted: int = 0
    unsigned: int = 0
    bad_signature: int = 0
    replay: int = 0
    stale_stream: int = 0
    malformed: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain mapping."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


class SignatureVerifier:
    """Checks signed frames against one key with the spec's timestamp rules.

    Parameters
    ----------
    key
        The 32-byte shared secret.
    clock_s
        Unix time [s]; our own timestamp is never behind it (a machine without a real-time
        clock starts at 2015 and learns the time from the first accepted frame).
    """

    def __init__(self, key: bytes, clock_s: Callable[[], float] = time.time) -> None:
        if len(key) != KEY_BYTES:
            raise ValueError(f"signing key must be {KEY_BYTES} bytes")
        self.key = key
        self._clock_s = clock_s
        self.timestamp = 0
        """Our timestamp: the newest of the clock and every accepted frame [10 us]."""
        self._streams: OrderedDict[tuple[int, int, int], int] = OrderedDict()
        self.counters = SigningCounters()

    def local_timestamp(self) -> int:
        """Our current timestamp [10 us since 2015]."""
        self.timestamp = max(self.timestamp, timestamp_from_unix_s(self._clock_s()))
        return self.timestamp

    def check(self, frame: bytes | bytearray | memoryview) -> str | None:
        """None when ``frame`` (one whole frame, CRC already checked) is correctly signed and
        new; otherwise the reason it is refused (also counted). Accepting updates the stream's
        timestamp, so the same frame checked twice is a replay the second time."""
        counters = self.counters
        if not is_signed(frame):
            counters.unsigned += 1
            return UNSIGNED
        if len(frame) != _HEADER_V2 + frame[1] + _CRC_BYTES + SIGNATURE_BLOCK_BYTES:
            counters.malformed += 1
            return MALFORMED
        block = len(frame) - SIGNATURE_BLOCK_BYTES
        link_id = frame[block]
        timestamp = int.from_bytes(frame[block + 1 : block + 7], "little")
        if signature(self.key, frame[: block + 7]) != bytes(frame[block + 7 :]):
            counters.bad_signature += 1
            return BAD_SIGNATURE
        stream = (frame[5], frame[6], link_id)
        last = self._streams.get(stream)
        if last is not None:
            if timestamp <= last:
                counters.replay += 1
                return REPLAY
        elif timestamp + NEW_STREAM_WINDOW < self.local_timestamp():
            counters.stale_stream += 1
            return STALE_STREAM
        self._streams[stream] = timestamp
        self._streams.move_to_end(stream)
        if len(self._streams) > MAX_STREAMS:
            self._streams.popitem(last=False)
        self.timestamp = max(self.timestamp, timestamp)
        counters.accepted += 1
        return None

    def stream_timestamp(self, system_id: int, component_id: int, link_id: int) -> int | None:
        """Last accepted timestamp of a stream, None when it has not been seen."""
        return self._streams.get((system_id, component_id, link_id))
