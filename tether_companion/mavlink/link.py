"""The link every transport implements: a queue of received messages, sending, counters,
closing (see :mod:`tether_companion.mavlink.endpoints` for opening one)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

from tether_companion.mavlink.framing import (
    FrameEncoder,
    FramingCounters,
    MAVLinkMessage,
    Received,
)
from tether_companion.mavlink.trust import LinkTrust

if TYPE_CHECKING:
    from tether_companion.mavlink.endpoints import Endpoint

DEFAULT_RX_QUEUE = 4096
"""Received messages held for :meth:`Link.recv` by default."""


class LinkClosed(ConnectionError):
    """The link was closed (by :meth:`Link.close` or by the peer); no more messages."""


@dataclass
class LinkCounters:
    """Output-side and queue counters of a :class:`Link` (input framing is counted apart)."""

    frames_out: int = 0
    bytes_out: int = 0
    send_no_peer: int = 0
    """Frames not sent because a listening link had heard from no peer yet."""
    send_dropped: int = 0
    """Frames dropped because the write buffer (TCP, serial) or socket buffer (UDP) was full."""
    send_errors: int = 0
    """Errors reported by the socket (e.g. ICMP port unreachable on UDP)."""
    rx_overflow: int = 0
    """Received messages dropped (oldest first) because nobody read the queue."""
    connections: int = 0
    """Peers heard (UDP listen) or clients accepted (TCP server) so far."""
    peers_evicted: int = 0
    """Peers a listening UDP link stopped replying to to make room for a new one."""

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain mapping."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


CLOSED = object()
Delivered = Received | bytes
"""An item of a received batch: a decoded message, or the bytes of one intact frame a
receiver's ``take`` accepted (see :meth:`Link.set_receiver`)."""


class Link:
    """A bidirectional MAVLink link; create with :func:`open_link`.

    Attributes
    ----------
    endpoint
        What was opened.
    encoder
        Frames outgoing messages as this link's system/component with its own sequence.
    counters
        Output and queue counters.
    framing
        Input counters (garbage, bad CRC, unknown ids, ...), summed over all peers.
    trust
        The gate every intact frame passes before it is decoded (None: all believed).
    """

    def __init__(
        self,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> None:
        self.endpoint = endpoint
        self.encoder = encoder
        self.counters = LinkCounters()
        self.framing = FramingCounters()
        self.trust = trust
        self._queue: asyncio.Queue[object] = asyncio.Queue(maxsize=rx_queue_size)
        self._closed = False
        self._receiver: Callable[[list[Delivered]], None] | None = None
        self._take: Callable[[bytes], bool] | None = None

    def set_receiver(
        self,
        receiver: Callable[[list[Delivered]], None] | None,
        take: Callable[[bytes], bool] | None = None,
    ) -> None:
        """Hand every received batch to ``receiver(items)`` at once, inside the transport's
        own callback, instead of queueing it for :meth:`recv` (None: queue again).

        No queue and no task switch per batch: the lowest latency and CPU, for a consumer
        that never blocks (the service). Messages queued before stay for :meth:`recv`, which
        still raises :class:`LinkClosed` once the link closes.

        ``take(datagram) -> bool`` (datagram transports; others ignore it) says which
        datagrams are exactly one intact frame the receiver decodes itself: such a datagram
        is offered to the trust gate as any frame is (refused: counted ``untrusted``, not
        delivered), counted as the parser counts a frame, and delivered as its ``bytes`` in
        the batch, in arrival order among the messages. ``take`` must only check the bytes
        (the gate has not seen them yet).
        """
        self._receiver = receiver
        self._take = take if receiver is not None else None

    # -- receiving -------------------------------------------------------------------------

    async def recv(self) -> MAVLinkMessage:
        """The next received message, waiting for one.

        Raises
        ------
        LinkClosed
            Once the link is closed and every queued message has been read.
        """
        item = await self._queue.get()
        if item is CLOSED:
            self._queue.put_nowait(CLOSED)  # wake every other reader too
            raise LinkClosed(f"{self.endpoint} closed")
        return item  # type: ignore[return-value]

    def recv_nowait(self) -> MAVLinkMessage | None:
        """A queued message or None, without waiting (raises LinkClosed when closed)."""
        try:
            item = self._queue.get_nowait()
        except asyncio.QueueEmpty:
            return None
        if item is CLOSED:
            self._queue.put_nowait(CLOSED)
            raise LinkClosed(f"{self.endpoint} closed")
        return item  # type: ignore[return-value]

    def __aiter__(self) -> Link:
        return self

    async def __anext__(self) -> MAVLinkMessage:
        try:
            return await self.recv()
        except LinkClosed:
            raise StopAsyncIteration from None

    def _deliver(self, messages: list[Delivered]) -> None:
        if self._closed or not messages:
            return
        if self._receiver is not None:
            self._receiver(messages)
            return
        for msg in messages:
            if self._queue.full():
                self._queue.get_nowait()
                self.counters.rx_overflow += 1
            self._queue.put_nowait(msg)

    def _mark_closed(self) -> None:
        if not self._closed:
            self._closed = True
            if self._queue.full():
                self._queue.get_nowait()
                self.counters.rx_overflow += 1
            self._queue.put_nowait(CLOSED)

    # -- sending ---------------------------------------------------------------------------

    def send(self, msg: MAVLinkMessage) -> None:
        """Frame ``msg`` and send it to every peer of the link (never blocks)."""
        self.send_bytes(self.encoder.encode(msg))

    def send_bytes(self, frame: bytes) -> None:
        """Send already framed bytes (used by fault injection to send corrupted frames)."""
        if self._closed:
            return
        sent = self._write(frame)
        self.counters.frames_out += sent
        self.counters.bytes_out += sent * len(frame)

    def _write(self, frame: bytes) -> int:
        """Write to the transport; returns to how many peers it went."""
        raise NotImplementedError

    # -- lifecycle -------------------------------------------------------------------------

    @property
    def closed(self) -> bool:
        """True once closed locally or by the peer."""
        return self._closed

    @property
    def local_address(self) -> tuple[str, int] | None:
        """(host, port) the link is bound to, or None (serial)."""
        return None

    async def close(self) -> None:
        """Close the transport and wake readers with :class:`LinkClosed`. Idempotent."""
        self._mark_closed()

    async def __aenter__(self) -> Link:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()
