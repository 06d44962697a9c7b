"""Which received frames a link believes: signatures, the flight controller's address, peers.

One :class:`LinkTrust` per link decides, for every frame whose checksum is good and *before*
it is decoded (so every decoder path, pymavlink's or a fast one, sees only admitted frames):

1. **Signing** (``security.signing``): ``off`` admits every frame unchecked; ``preferred``
   admits unsigned frames but refuses a signed one whose signature or timestamp is wrong;
   ``required`` refuses every frame that is not correctly signed, except an unsigned
   COMMAND_LONG, which is let through so that the session can answer it COMMAND_ACK DENIED
   (:func:`tether_companion.service.security.command_refusal` refuses every unsigned command
   then). Refusals are counted by reason (:class:`TrustCounters`, the reasons of
   :mod:`tether_companion.mavlink.signing`).
2. **The flight controller's address**: frames carrying the flight controller's system and
   component id are believed from one source address only, the first one they came from
   on this link. From any other address they are refused (``foreign_source``); the pin moves
   only when the pinned address has been silent for ``repin_silence_s`` and the new address
   has sent ``REPIN_HEARTBEATS`` HEARTBEATs since: a flight controller that restarted on a new
   port gets through after a few seconds, a single spoofed datagram never does.
3. **Protected peers**: the pinned flight controller's address and the addresses that sent
   admitted frames from the configured ground stations (``security.command_sources``) are
   :meth:`LinkTrust.protected`; a listening UDP link never evicts them from its reply table
   for strangers.

Pure and synchronous; time comes from the ``monotonic_s`` callable.

The gate's interface, as :class:`~tether_companion.mavlink.framing.FrameParser` calls it, is
``admit(frame, source) -> bool`` with ``frame`` one whole frame (bytes, checksum good,
signature included) and ``source`` the transport's address of its sender (UDP ``(host, port)``,
a TCP peer's address, a serial device path, or None when unknown).
"""

from __future__ import annotations

import math
import struct
import time
from collections import OrderedDict
from collections.abc import Callable, Collection, Hashable
from dataclasses import dataclass, fields
from typing import Protocol

from pymavlink.dialects.v20 import ardupilotmega as dialect

from tether_companion.mavlink.signing import SignatureVerifier, Signer, is_signed

OFF = "off"
PREFERRED = "preferred"
REQUIRED = "required"
SIGNING_MODES = (OFF, PREFERRED, REQUIRED)
REPIN_HEARTBEATS = 3
"""HEARTBEATs the flight controller's new address must send before it is believed."""
MAX_PROTECTED_SOURCES = 8
"""Ground-station addresses remembered as protected (oldest forgotten first)."""
_STX_V1 = dialect.PROTOCOL_MARKER_V1
_HEARTBEAT_ID = dialect.MAVLINK_MSG_ID_HEARTBEAT
_COMMAND_LONG_ID = dialect.MAVLINK_MSG_ID_COMMAND_LONG
_IDS_V2 = struct.Struct("<BBI")
"""A MAVLink 2 frame's system, component and message id (bytes 5-10: a whole frame, with its
checksum, is at least 12 bytes)."""


class FrameGate(Protocol):
    """What a frame parser asks before decoding a frame (see the module docstring)."""

    def admit(self, frame: bytes | bytearray, source: Hashable | None) -> bool:
        """True to decode and deliver ``frame`` from ``source``; False drops it."""
        ...


@dataclass
class TrustCounters:
    """Frames a :class:`LinkTrust` admitted and refused, by reason (monotonic counts)."""

    admitted: int = 0
    unsigned_commands: int = 0
    """Unsigned COMMAND_LONGs let through with signing required, to be answered DENIED."""
    unsigned: int = 0
    """Unsigned frames refused with signing required."""
    bad_signature: int = 0
    """Signed with another key, or altered in transit."""
    replay: int = 0
    """Timestamp not newer than the last of its stream (system, component, link id)."""
    stale_stream: int = 0
    """A new stream's first timestamp more than a minute behind ours."""
    malformed: int = 0
    """A signed frame whose length does not hold a signature block."""
    foreign_source: int = 0
    """The flight controller's ids from an address other than its pinned one."""
    repins: int = 0
    """Times the flight controller's address moved (after silence and HEARTBEATs)."""

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain mapping."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @property
    def refused(self) -> int:
        """Every refused frame."""
        return (
            self.unsigned
            + self.bad_signature
            + self.replay
            + self.stale_stream
            + self.malformed
            + self.foreign_source
        )


class LinkTrust:
    """The trust decision of one link (see the module docstring).

    Parameters
    ----------
    signing
        ``off``, ``preferred`` or ``required``.
    verifier
        Checks signatures (needed unless ``signing`` is ``off``).
    signer
        This link's signer, if it signs: its timestamp follows every accepted frame's, as the
        spec asks.
    fc_ids
        The flight controller's (system id, component id), whose address is pinned.
    command_sources
        Ground-station system ids whose addresses are protected peers.
    repin_silence_s
        The pinned address must have been silent this long [s] before another replaces it.
    monotonic_s
        Local clock [s].
    """

    def __init__(
        self,
        signing: str = OFF,
        *,
        verifier: SignatureVerifier | None = None,
        signer: Signer | None = None,
        fc_ids: tuple[int, int] = (1, 1),
        command_sources: Collection[int] = (),
        repin_silence_s: float = 2.0,
        monotonic_s: Callable[[], float] = time.monotonic,
    ) -> None:
        if signing not in SIGNING_MODES:
            raise ValueError(f"signing must be one of {SIGNING_MODES}, got {signing!r}")
        if signing != OFF and verifier is None:
            raise ValueError(f"signing {signing!r} needs a verifier (a key)")
        self.signing = signing
        self.verifier = verifier
        self.signer = signer
        self.fc_ids = fc_ids
        self.command_sources = frozenset(command_sources)
        self.repin_silence_s = repin_silence_s
        self._monotonic_s = monotonic_s
        self.counters = TrustCounters()
        self.fc_source: Hashable | None = None
        """Address the flight controller is believed from (None until first heard)."""
        self._fc_heard_s = -math.inf
        self._candidate: Hashable | None = None
        self._candidate_heartbeats = 0
        self._ground_stations: OrderedDict[Hashable, None] = OrderedDict()
        self.events: list[str] = []
        """Log lines of address changes (the service prints and clears them)."""

    def admit(self, frame: bytes | bytearray, source: Hashable | None) -> bool:
        """True when ``frame`` from ``source`` is believed (counted either way)."""
        counters = self.counters
        if frame[0] == _STX_V1:
            system, component, msg_id = frame[3], frame[4], frame[5]
        else:  # one read, not five indexings: the 24-bit id, the payload's first byte above it
            system, component, msg_id = _IDS_V2.unpack_from(frame, 5)
            msg_id &= 0xFFFFFF
        if self.signing != OFF and ((signed := is_signed(frame)) or self.signing == REQUIRED):
            if signed or msg_id != _COMMAND_LONG_ID:
                assert self.verifier is not None
                reason = self.verifier.check(frame)
                if reason is not None:
                    setattr(counters, reason, getattr(counters, reason) + 1)  # same names
                    return False
                if self.signer is not None:
                    self.signer.observe(self.verifier.timestamp)
            else:
                counters.unsigned_commands += 1
        if (system, component) == self.fc_ids:
            fc_source = self.fc_source
            if fc_source is not None and source == fc_source and not self._candidate_heartbeats:
                # the usual frame: what _fc_source_ok does for the pinned address with no
                # candidate (heartbeats are 0 only while the candidate is None), without a call
                self._fc_heard_s = self._monotonic_s()
            elif not self._fc_source_ok(source, msg_id):
                counters.foreign_source += 1
                return False
        if system in self.command_sources and source is not None:
            self._ground_stations[source] = None
            self._ground_stations.move_to_end(source)
            if len(self._ground_stations) > MAX_PROTECTED_SOURCES:
                self._ground_stations.popitem(last=False)
        counters.admitted += 1
        return True

    def _fc_source_ok(self, source: Hashable | None, msg_id: int) -> bool:
        now = self._monotonic_s()
        if self.fc_source is None or source == self.fc_source:
            if self.fc_source is None:
                self.fc_source = source
                self.events.append(f"flight controller heard from {_show(source)}")
            self._fc_heard_s = now
            self._candidate, self._candidate_heartbeats = None, 0
            return True
        if msg_id != _HEARTBEAT_ID:
            return False
        if source != self._candidate:
            self._candidate, self._candidate_heartbeats = source, 0
        self._candidate_heartbeats += 1
        silent = now - self._fc_heard_s >= self.repin_silence_s
        if silent and self._candidate_heartbeats >= REPIN_HEARTBEATS:
            self.events.append(
                f"flight controller moved from {_show(self.fc_source)} to {_show(source)} "
                f"({self._candidate_heartbeats} HEARTBEATs after {now - self._fc_heard_s:.1f} s "
                "of silence)"
            )
            self.fc_source = source
            self._fc_heard_s = now
            self._candidate, self._candidate_heartbeats = None, 0
            self.counters.repins += 1
            return True
        return False

    def protected(self, source: Hashable) -> bool:
        """Whether ``source`` is the flight controller's or a ground station's address."""
        return source == self.fc_source or source in self._ground_stations


def _show(source: Hashable | None) -> str:
    if isinstance(source, tuple) and len(source) >= 2:
        return f"{source[0]}:{source[1]}"
    return "an unknown address" if source is None else str(source)
