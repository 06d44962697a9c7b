"""asyncio MAVLink links over UDP, TCP and serial ports.

An endpoint is written as text on the command line or in a config file and parsed with
:func:`parse_endpoint`:

=============================== ==========================================================
``udp:HOST:PORT``               UDP; listens with ``--listen``, sends to HOST:PORT with
                                ``--connect`` (the role comes from the flag)
``udpin:HOST:PORT``             UDP, always listening (replies to every peer heard from)
``udpout:HOST:PORT``            UDP, always sending to HOST:PORT
``tcp:HOST:PORT``               TCP server with ``--listen``, client with ``--connect``
``tcpin:HOST:PORT``             TCP server (every connected client gets every message)
``tcpout:HOST:PORT``            TCP client
``serial:/dev/ttyX:BAUD``       a serial port, 8N1, raw, no flow control
=============================== ==========================================================

``PORT`` 0 when listening picks a free port (see :attr:`Link.local_address`); tests use it.

:func:`open_link` turns an :class:`Endpoint` into a :class:`Link`: ``await link.recv()`` gives
the next decoded message, ``link.send(msg)`` frames and sends one, ``await link.close()``
releases everything. Each link counts what it sends, drops and rejects
(:class:`LinkCounters`, and :class:`~tether_companion.mavlink.framing.FramingCounters` for
input). Sending never blocks: a UDP datagram goes to the kernel at once, a TCP or serial
write is buffered by asyncio and dropped (and counted) once the buffer exceeds 1 MiB, so a
stalled reader cannot stall the caller.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import termios
from collections import OrderedDict
from dataclasses import dataclass, fields
from typing import Literal

from tether_companion.config import ConfigError
from tether_companion.mavlink.framing import (
    FrameEncoder,
    FrameParser,
    FramingCounters,
    MAVLinkMessage,
)
from tether_companion.mavlink.signing import Signer
from tether_companion.mavlink.trust import LinkTrust

Role = Literal["listen", "connect"]
Transport = Literal["udp", "tcp", "serial"]

_SCHEMES: dict[str, tuple[Transport, Role | None]] = {
    "udp": ("udp", None),
    "udpin": ("udp", "listen"),
    "udpout": ("udp", "connect"),
    "tcp": ("tcp", None),
    "tcpin": ("tcp", "listen"),
    "tcpout": ("tcp", "connect"),
    "serial": ("serial", "connect"),
}
_FORMS = (
    "expected udp:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, "
    "tcpin:HOST:PORT, tcpout:HOST:PORT or serial:/dev/DEVICE:BAUD"
)
MAX_UDP_PEERS = 16
"""A listening UDP link replies to at most this many peers: the flight controller's pinned
address and the ground stations' (:meth:`LinkTrust.protected`) are kept, strangers take the
other places, the least recently heard evicted first."""
WRITE_BUFFER_LIMIT_BYTES = 1 << 20
UDP_BUFFER_BYTES = 1 << 21
"""Receive buffer asked for on UDP sockets (the kernel caps it at net.core.rmem_max)."""
UDP_MAX_DATAGRAM = 65535
MAX_DATAGRAMS_PER_READ = 256
"""Datagrams read per readiness before other callbacks get their turn."""
READ_CHUNK_BYTES = 4096
DEFAULT_RX_QUEUE = 4096


@dataclass(frozen=True)
class Endpoint:
    """Where and how to open a MAVLink link (see the module docstring for the text forms)."""

    transport: Transport
    role: Role
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0
    text: str = ""

    def __str__(self) -> str:
        if self.transport == "serial":
            return f"serial:{self.device}:{self.baud}"
        scheme = {"udp": ("udpin", "udpout"), "tcp": ("tcpin", "tcpout")}[self.transport]
        return f"{scheme[0] if self.role == 'listen' else scheme[1]}:{self.host}:{self.port}"


def parse_endpoint(text: str, role: Role, *, key: str | None = None) -> Endpoint:
    """Parse an endpoint string; ``role`` is the flag it came from (listen or connect).

    ``udp:`` and ``tcp:`` take the role; ``udpin:``/``tcpin:`` always listen,
    ``udpout:``/``tcpout:`` always connect; ``serial:`` is a device.

    Parameters
    ----------
    text
        The endpoint as written by the user.
    role
        ``"listen"`` or ``"connect"``.
    key
        Name of the flag or config key, for error messages (default ``--listen`` /
        ``--connect``).

    Raises
    ------
    ConfigError
        Naming the key, the text and the accepted forms, for anything malformed: unknown
        scheme, missing or non-numeric port, port out of 0..65535 (0 only when listening),
        empty host, unsupported baud rate.
    """
    key = key or f"--{role}"
    if role not in ("listen", "connect"):
        raise ValueError(f"role must be 'listen' or 'connect', got {role!r}")
    if not isinstance(text, str) or ":" not in text:
        raise ConfigError("", key, text, _FORMS)
    scheme, _, rest = text.partition(":")
    scheme = scheme.strip().lower()
    if scheme not in _SCHEMES:
        raise ConfigError("", key, text, f"unknown scheme {scheme!r}; {_FORMS}")
    transport, fixed_role = _SCHEMES[scheme]
    if transport == "serial":
        device, sep, baud_text = rest.rpartition(":")
        if not sep or not device.startswith("/"):
            raise ConfigError("", key, text, "expected serial:/dev/DEVICE:BAUD")
        baud = _parse_int(baud_text, key, text, "BAUD")
        if _termios_speed(baud) is None:
            raise ConfigError("", key, text, f"baud rate {baud} is not a standard rate")
        return Endpoint("serial", "connect", device=device, baud=baud, text=text)
    effective_role: Role = fixed_role or role
    host, sep, port_text = rest.rpartition(":")
    host = host.strip().strip("[]")
    if not sep or not host:
        raise ConfigError("", key, text, f"missing host or port; {_FORMS}")
    port = _parse_int(port_text, key, text, "PORT")
    lowest = 0 if effective_role == "listen" else 1
    if not lowest <= port <= 65535:
        raise ConfigError("", key, text, f"port must be {lowest}..65535")
    return Endpoint(transport, effective_role, host=host, port=port, text=text)


def _parse_int(value: str, key: str, text: str, what: str) -> int:
    try:
        return int(value.strip(), 10)
    except ValueError:
        raise ConfigError("", key, text, f"{what} must be an integer; {_FORMS}") from None


def _termios_speed(baud: int) -> int | None:
    return getattr(termios, f"B{baud}", None) if baud > 0 else None


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


_CLOSED = object()


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

    # -- receiving -------------------------------------------------------------------------

    async def recv(self) -> MAVLinkMessage:
        """The next received message, waiting for one.

        Raises
        ------
        LinkClosed
            Once the link is closed and every queued message has been read.
        """
        item = await self._queue.get()
        if item is _CLOSED:
            self._queue.put_nowait(_CLOSED)  # wake every other reader too
            raise LinkClosed(f"{self.endpoint} closed")
        return item  # type: ignore[return-value]

    def recv_nowait(self) -> MAVLinkMessage | None:
        """A queued message or None, without waiting (raises LinkClosed when closed)."""
        try:
            item = self._queue.get_nowait()
        except asyncio.QueueEmpty:
            return None
        if item is _CLOSED:
            self._queue.put_nowait(_CLOSED)
            raise LinkClosed(f"{self.endpoint} closed")
        return item  # type: ignore[return-value]

    def __aiter__(self) -> Link:
        return self

    async def __anext__(self) -> MAVLinkMessage:
        try:
            return await self.recv()
        except LinkClosed:
            raise StopAsyncIteration from None

    def _deliver(self, messages: list[MAVLinkMessage]) -> None:
        if self._closed:
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
            self._queue.put_nowait(_CLOSED)

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


async def open_link(
    endpoint: Endpoint,
    *,
    system_id: int,
    component_id: int,
    rx_queue_size: int = DEFAULT_RX_QUEUE,
    trust: LinkTrust | None = None,
    signer: Signer | None = None,
) -> Link:
    """Open ``endpoint`` and return a running :class:`Link`.

    Parameters
    ----------
    endpoint
        From :func:`parse_endpoint`.
    system_id, component_id
        The identity this side sends as.
    rx_queue_size
        Received messages held for :meth:`Link.recv`; the oldest is dropped beyond it.
    trust
        Decides which received frames are believed (signatures, the flight controller's
        address; :mod:`tether_companion.mavlink.trust`); None believes every intact frame.
    signer
        Signs every sent frame (MAVLink 2 signing) when given.

    Raises
    ------
    OSError
        When the socket cannot be bound, the TCP server refuses (ConnectionRefusedError) or
        the serial device cannot be opened; the message names the endpoint.
    """
    encoder = FrameEncoder(system_id, component_id, signer)
    try:
        if endpoint.transport == "udp":
            return await _UdpLink.open(endpoint, encoder, rx_queue_size, trust)
        if endpoint.transport == "tcp" and endpoint.role == "listen":
            return await _TcpServerLink.open(endpoint, encoder, rx_queue_size, trust)
        if endpoint.transport == "tcp":
            return await _TcpClientLink.open(endpoint, encoder, rx_queue_size, trust)
        return await _SerialLink.open(endpoint, encoder, rx_queue_size, trust)
    except OSError as exc:
        raise type(exc)(exc.errno, f"{endpoint}: {exc.strerror or exc}") from exc


# --- UDP ------------------------------------------------------------------------------------


class _UdpLink(Link):
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
        sock = self._sock
        if sock is None:
            return
        for _ in range(MAX_DATAGRAMS_PER_READ):
            try:
                data, addr = sock.recvfrom(UDP_MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. ICMP port unreachable reported on a connected socket
                self.counters.send_errors += 1
                continue
            self._datagram(data, addr)

    def _datagram(self, data: bytes, addr: tuple[str, int]) -> None:
        messages = self._parser.feed(data, addr)
        messages += self._parser.end_datagram()
        if messages and self.endpoint.role == "listen":
            if addr in self._peers:
                self._peers.move_to_end(addr)
            else:
                self.counters.connections += 1
                self._peers[addr] = None
                if len(self._peers) > MAX_UDP_PEERS:
                    self._evict_peer()
        self._deliver(messages)

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


# --- TCP ------------------------------------------------------------------------------------


class _StreamPeer:
    """One TCP connection: its own parser (a stream) feeding the link's queue."""

    def __init__(self, link: Link, reader: asyncio.StreamReader, writer: asyncio.StreamWriter):
        self.link = link
        self.reader = reader
        self.writer = writer
        self.parser = FrameParser(link.framing, link.trust)
        peer = writer.get_extra_info("peername")
        self.source = tuple(peer[:2]) if isinstance(peer, tuple) else peer

    async def pump(self) -> None:
        try:
            while True:
                data = await self.reader.read(READ_CHUNK_BYTES)
                if not data:
                    return
                self.link._deliver(self.parser.feed(data, self.source))
        except (ConnectionError, OSError):
            return
        finally:
            self.writer.close()

    def write(self, frame: bytes) -> bool:
        transport = self.writer.transport
        if transport.is_closing():
            return False
        if transport.get_write_buffer_size() > WRITE_BUFFER_LIMIT_BYTES:
            self.link.counters.send_dropped += 1
            return False
        self.writer.write(frame)
        return True


class _TcpServerLink(Link):
    """TCP server: every connected client receives every message; all clients are heard."""

    def __init__(
        self,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> None:
        super().__init__(endpoint, encoder, rx_queue_size, trust)
        self._server: asyncio.Server | None = None
        self._peers: dict[_StreamPeer, asyncio.Task[None]] = {}

    @classmethod
    async def open(
        cls,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> Link:
        link = cls(endpoint, encoder, rx_queue_size, trust)
        link._server = await asyncio.start_server(link._accept, endpoint.host, endpoint.port)
        return link

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self._closed:
            writer.close()
            return
        peer = _StreamPeer(self, reader, writer)
        self.counters.connections += 1
        task = asyncio.current_task()
        assert task is not None
        self._peers[peer] = task
        try:
            await peer.pump()
        except asyncio.CancelledError:
            # asyncio's stream server inspects this task's result; end it normally
            return
        finally:
            self._peers.pop(peer, None)

    def _write(self, frame: bytes) -> int:
        if not self._peers:
            self.counters.send_no_peer += 1
            return 0
        return sum(peer.write(frame) for peer in list(self._peers))

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._server is None or not self._server.sockets:
            return None
        return self._server.sockets[0].getsockname()[:2]

    async def close(self) -> None:
        self._mark_closed()
        if self._server is not None:
            self._server.close()
        tasks = list(self._peers.values())
        for peer in list(self._peers):
            peer.writer.close()  # the peer's reader sees EOF and its pump returns
        if tasks:
            _, pending = await asyncio.wait(tasks, timeout=1.0)
            for task in pending:
                task.cancel()
        if self._server is not None:
            await self._server.wait_closed()


class _TcpClientLink(Link):
    """TCP client: one connection; the link closes when the server goes away."""

    def __init__(
        self,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> None:
        super().__init__(endpoint, encoder, rx_queue_size, trust)
        self._peer: _StreamPeer | None = None
        self._task: asyncio.Task[None] | None = None

    @classmethod
    async def open(
        cls,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> Link:
        link = cls(endpoint, encoder, rx_queue_size, trust)
        reader, writer = await asyncio.open_connection(endpoint.host, endpoint.port)
        link._peer = _StreamPeer(link, reader, writer)
        link.counters.connections = 1
        link._task = asyncio.create_task(link._run(), name=f"mavlink-tcp-client {endpoint}")
        return link

    async def _run(self) -> None:
        assert self._peer is not None
        try:
            await self._peer.pump()
        finally:
            self._mark_closed()

    def _write(self, frame: bytes) -> int:
        return int(self._peer is not None and self._peer.write(frame))

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._peer is None:
            return None
        return self._peer.writer.get_extra_info("sockname")[:2]

    async def close(self) -> None:
        self._mark_closed()
        if self._peer is not None:
            self._peer.writer.close()
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._task


# --- serial ---------------------------------------------------------------------------------


class _SerialReader(asyncio.Protocol):
    def __init__(self, link: _SerialLink) -> None:
        self.link = link

    def data_received(self, data: bytes) -> None:
        self.link._deliver(self.link._parser.feed(data, self.link.endpoint.device))

    def eof_received(self) -> bool:
        self.link._mark_closed()
        return False

    def connection_lost(self, exc: Exception | None) -> None:
        self.link._mark_closed()


class _SerialLink(Link):
    """A serial port in raw 8N1 mode at the endpoint's baud rate (termios, no pyserial)."""

    def __init__(
        self,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> None:
        super().__init__(endpoint, encoder, rx_queue_size, trust)
        self._parser = FrameParser(self.framing, trust)
        self._read_transport: asyncio.ReadTransport | None = None
        self._write_transport: asyncio.WriteTransport | None = None

    @classmethod
    async def open(
        cls,
        endpoint: Endpoint,
        encoder: FrameEncoder,
        rx_queue_size: int,
        trust: LinkTrust | None = None,
    ) -> Link:
        link = cls(endpoint, encoder, rx_queue_size, trust)
        fd = os.open(endpoint.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            _configure_raw(fd, endpoint.baud)
            write_fd = os.dup(fd)
        except termios.error as exc:  # e.g. /dev/null: not a terminal
            os.close(fd)
            errno_, text = (exc.args + (0, ""))[:2]
            raise OSError(errno_, f"not a serial port ({text})") from None
        except OSError:
            os.close(fd)
            raise
        loop = asyncio.get_running_loop()
        read_file = os.fdopen(fd, "rb", buffering=0)
        write_file = os.fdopen(write_fd, "wb", buffering=0)
        try:
            link._read_transport, _ = await loop.connect_read_pipe(
                lambda: _SerialReader(link), read_file
            )
            link._write_transport, _ = await loop.connect_write_pipe(asyncio.Protocol, write_file)
        except Exception:
            read_file.close()
            write_file.close()
            raise
        link.counters.connections = 1
        return link

    def _write(self, frame: bytes) -> int:
        transport = self._write_transport
        if transport is None or transport.is_closing():
            return 0
        if transport.get_write_buffer_size() > WRITE_BUFFER_LIMIT_BYTES:
            self.counters.send_dropped += 1
            return 0
        transport.write(frame)
        return 1

    async def close(self) -> None:
        self._mark_closed()
        for transport in (self._read_transport, self._write_transport):
            if transport is not None:
                transport.close()


def _configure_raw(fd: int, baud: int) -> None:
    """Raw 8N1, no flow control, non-canonical, at ``baud`` (as cfmakeraw does)."""
    speed = _termios_speed(baud)
    if speed is None:
        raise OSError(0, f"unsupported baud rate {baud}")
    iflag, oflag, cflag, lflag, _, _, cc = termios.tcgetattr(fd)
    iflag &= ~(
        termios.IGNBRK
        | termios.BRKINT
        | termios.PARMRK
        | termios.ISTRIP
        | termios.INLCR
        | termios.IGNCR
        | termios.ICRNL
        | termios.IXON
        | termios.IXOFF
        | termios.IXANY
    )
    oflag &= ~termios.OPOST
    lflag &= ~(termios.ECHO | termios.ECHONL | termios.ICANON | termios.ISIG | termios.IEXTEN)
    cflag &= ~(termios.CSIZE | termios.PARENB | termios.CSTOPB | termios.CRTSCTS)
    cflag |= termios.CS8 | termios.CREAD | termios.CLOCAL
    cc[termios.VMIN] = 1
    cc[termios.VTIME] = 0
    termios.tcsetattr(fd, termios.TCSANOW, [iflag, oflag, cflag, lflag, speed, speed, cc])
