"""MAVLink over byte streams: a TCP server (every client gets every message), a TCP
client, and a serial port (8N1, raw, no flow control). Writes are buffered by asyncio and
dropped (counted) past :data:`WRITE_BUFFER_LIMIT_BYTES`, so a stalled reader cannot stall
the sender."""

from __future__ import annotations

import asyncio
import contextlib
import os
import termios
from typing import TYPE_CHECKING

from tether_companion.mavlink.framing import FrameEncoder, FrameParser
from tether_companion.mavlink.link import Link
from tether_companion.mavlink.trust import LinkTrust

if TYPE_CHECKING:
    from tether_companion.mavlink.endpoints import Endpoint

WRITE_BUFFER_LIMIT_BYTES = 1 << 20
READ_CHUNK_BYTES = 4096


def termios_speed(baud: int) -> int | None:
    """The termios constant of a standard baud rate, or None (not standard, or <= 0)."""
    return getattr(termios, f"B{baud}", None) if baud > 0 else None


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


class TcpServerLink(Link):
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


class TcpClientLink(Link):
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
    def __init__(self, link: SerialLink) -> None:
        self.link = link

    def data_received(self, data: bytes) -> None:
        self.link._deliver(self.link._parser.feed(data, self.link.endpoint.device))

    def eof_received(self) -> bool:
        self.link._mark_closed()
        return False

    def connection_lost(self, exc: Exception | None) -> None:
        self.link._mark_closed()


class SerialLink(Link):
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
    speed = termios_speed(baud)
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
