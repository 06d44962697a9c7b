"""MAVLink over UDP: listening (replying to every peer heard from) or sending to one
address."""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections import OrderedDict
from typing import TYPE_CHECKING

from tether_companion.mavlink.framing import FrameEncoder, FrameParser
from tether_companion.mavlink.link import Delivered, Link
from tether_companion.mavlink.trust import LinkTrust

if TYPE_CHECKING:
    from tether_companion.mavlink.endpoints import Endpoint

MAX_UDP_PEERS = 16
"""A listening UDP link replies to at most this many peers: the flight controller's pinned
address and the ground stations' (:meth:`LinkTrust.protected`) are kept, strangers take the
other places, the least recently heard evicted first."""
UDP_BUFFER_BYTES = 1 << 21
"""Receive buffer asked for on UDP sockets (the kernel caps it at net.core.rmem_max)."""
UDP_MAX_DATAGRAM = 65535
MAX_DATAGRAMS_PER_READ = 256
"""Datagrams read per readiness before other callbacks get their turn."""


class UdpLink(Link):
    """UDP: listening (reply to every peer heard from) or connected to one address.

    A plain non-blocking socket watched with ``loop.add_reader`` rather than asyncio's
    datagram transport: that transport reads one datagram per event-loop iteration, so a
    busy loop (a 200 Hz x 4-stream flight controller, an EKF, the emulator in the same
    process) falls behind and the kernel drops datagrams. Here every readiness drains the
    socket, up to :data:`MAX_DATAGRAMS_PER_READ`.
    """

    def __init__(
        self,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> None:
        super().__init__(endpoint, encoder, rx_queue_size, trust)
        self._parser = FrameParser(self.framing, trust)
        self._sock: socket.socket | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._peers: OrderedDict[tuple[str, int], None] = OrderedDict()
        self._listening = endpoint.role == "listen"
        """Whether every sender becomes a peer (the endpoint is frozen: read once)."""

    @classmethod
    async def open(
        cls,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> Link:
        link = cls(endpoint, encoder, rx_queue_size, trust)
        loop = asyncio.get_running_loop()
        infos = await loop.getaddrinfo(endpoint.host, endpoint.port, type=socket.SOCK_DGRAM)
        if not infos:
            raise OSError(0, f"cannot resolve {endpoint.host}")
        # IPv4 first: "localhost" must reach a peer bound to 127.0.0.1, as autopilots are
        family, _, _, _, address = min(infos, key=lambda info: info[0] != socket.AF_INET)
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setblocking(False)
            with contextlib.suppress(OSError):  # best effort: the kernel may cap it
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_BUFFER_BYTES)
            if endpoint.role == "listen":
                sock.bind(address)
            else:
                sock.connect(address)
        except OSError:
            sock.close()
            raise
        link._sock, link._loop = sock, loop
        loop.add_reader(sock.fileno(), link._read_ready)
        return link

    def _read_ready(self) -> None:
        """Drain the socket, then deliver everything read as one batch: parsing every datagram
        first and handling the messages after keeps each stage's code warm in the CPU's
        caches (on a loaded machine a cold pass costs several times a warm one)."""
        sock = self._sock
        if sock is None:
            return
        messages: list[Delivered] = []
        for _ in range(MAX_DATAGRAMS_PER_READ):
            try:
                data, addr = sock.recvfrom(UDP_MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # e.g. ICMP port unreachable reported on a connected socket
                self.counters.send_errors += 1
                continue
            messages += self._datagram(data, addr)
        self._deliver(messages)

    def _datagram(self, data: bytes, addr: tuple[str, int]) -> list[Delivered]:
        """The messages of one datagram (its sender becomes a peer of a listening link); a
        datagram the receiver's ``take`` accepts is gated and counted here as the parser
        would (:meth:`FrameParser.feed` of one whole frame) and delivered as its bytes."""
        take = self._take
        messages: list[Delivered]
        if take is not None and take(data):  # the parser holds nothing between datagrams
            framing = self.framing
            framing.bytes_in += len(data)
            if self.trust is not None and not self.trust.admit(data, addr):
                framing.untrusted += 1
                return []
            framing.frames_ok += 1
            messages = [data]
        else:
            parser = self._parser
            messages = parser.feed(data, addr)
            if parser.pending_bytes:
                messages += parser.end_datagram()
        if messages and self._listening:
            peers = self._peers
            if addr in peers:
                peers.move_to_end(addr)
            else:
                self.counters.connections += 1
                self._peers[addr] = None
                if len(self._peers) > MAX_UDP_PEERS:
                    self._evict_peer()
        return messages

    def _evict_peer(self) -> None:
        """Forget the least recently heard peer that is not protected by the trust gate."""
        trust = self.trust
        victim = next(
            (a for a in self._peers if trust is None or not trust.protected(a)),
            next(iter(self._peers)),
        )
        del self._peers[victim]
        self.counters.peers_evicted += 1

    def _write(self, frame: bytes) -> int:
        sock = self._sock
        if sock is None:
            return 0
        if self.endpoint.role == "connect":
            return self._send_to(sock, frame, None)
        if not self._peers:
            self.counters.send_no_peer += 1
            return 0
        return sum(self._send_to(sock, frame, addr) for addr in self._peers)

    def _send_to(self, sock: socket.socket, frame: bytes, addr: tuple[str, int] | None) -> int:
        try:
            if addr is None:
                sock.send(frame)
            else:
                sock.sendto(frame, addr)
        except (BlockingIOError, InterruptedError):
            self.counters.send_dropped += 1
            return 0
        except OSError:
            self.counters.send_errors += 1
            return 0
        return 1

    @property
    def peers(self) -> list[tuple[str, int]]:
        """Addresses a listening link replies to, oldest first."""
        return list(self._peers)

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._sock is None:
            return None
        return self._sock.getsockname()[:2]

    async def close(self) -> None:
        self._mark_closed()
        sock, self._sock = self._sock, None
        if sock is not None:
            if self._loop is not None and not self._loop.is_closed():
                self._loop.remove_reader(sock.fileno())
            sock.close()
