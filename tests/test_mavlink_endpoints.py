"""Endpoint strings and asyncio links over real UDP/TCP sockets on 127.0.0.1 and a pty."""

from __future__ import annotations

import asyncio
import os
import socket

import pytest
from pymavlink import mavutil
from udp_ports import free_udp_port

from tether_companion.config import ConfigError
from tether_companion.mavlink.endpoints import Endpoint, open_link, parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.mavlink.link import LinkClosed

TIMEOUT_S = 5.0


def heartbeat(custom_mode: int = 0) -> dialect.MAVLink_message:
    return dialect.MAVLink_heartbeat_message(6, 8, 0, custom_mode, 4, 3)


@pytest.mark.parametrize(
    ("text", "role", "expected"),
    [
        ("udp:127.0.0.1:14550", "listen", Endpoint("udp", "listen", "127.0.0.1", 14550)),
        ("udp:127.0.0.1:14550", "connect", Endpoint("udp", "connect", "127.0.0.1", 14550)),
        ("udpin:0.0.0.0:0", "connect", Endpoint("udp", "listen", "0.0.0.0", 0)),
        ("udpout:localhost:14551", "listen", Endpoint("udp", "connect", "localhost", 14551)),
        ("tcp:127.0.0.1:5760", "listen", Endpoint("tcp", "listen", "127.0.0.1", 5760)),
        ("tcp:10.0.0.2:5760", "connect", Endpoint("tcp", "connect", "10.0.0.2", 5760)),
        ("tcpin:127.0.0.1:5760", "connect", Endpoint("tcp", "listen", "127.0.0.1", 5760)),
        ("TCPOUT:127.0.0.1:5760", "listen", Endpoint("tcp", "connect", "127.0.0.1", 5760)),
        (
            "serial:/dev/ttyAMA0:921600",
            "connect",
            Endpoint("serial", "connect", device="/dev/ttyAMA0", baud=921600),
        ),
    ],
)
def test_parse_endpoint_accepts(text: str, role: str, expected: Endpoint) -> None:
    parsed = parse_endpoint(text, role)  # type: ignore[arg-type]
    assert (
        parsed.transport,
        parsed.role,
        parsed.host,
        parsed.port,
        parsed.device,
        parsed.baud,
    ) == (
        expected.transport,
        expected.role,
        expected.host,
        expected.port,
        expected.device,
        expected.baud,
    )
    assert parsed.text == text


@pytest.mark.parametrize(
    ("text", "role", "fragment"),
    [
        ("", "listen", "expected udp:HOST:PORT"),
        ("127.0.0.1:14550", "listen", "unknown scheme"),
        ("udp::14550", "listen", "missing host"),
        ("udp:127.0.0.1", "connect", "missing host or port"),
        ("udp:127.0.0.1:abc", "listen", "PORT must be an integer"),
        ("udp:127.0.0.1:70000", "listen", "port must be 0..65535"),
        ("udpout:127.0.0.1:0", "listen", "port must be 1..65535"),
        ("tcp:127.0.0.1:-1", "listen", "port must be"),
        ("serial:ttyUSB0:57600", "connect", "serial:/dev/DEVICE:BAUD"),
        ("serial:/dev/ttyUSB0:12345", "connect", "not a standard rate"),
        ("serial:/dev/ttyUSB0", "connect", "serial:/dev/DEVICE:BAUD"),
        ("http://x:1", "connect", "unknown scheme"),
    ],
)
def test_parse_endpoint_refuses_with_a_clear_message(text: str, role: str, fragment: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_endpoint(text, role)  # type: ignore[arg-type]
    message = str(info.value)
    assert fragment in message and f"--{role}" in message and repr(text) in message


def test_parse_endpoint_names_a_config_key() -> None:
    with pytest.raises(ConfigError, match=r"^link\.connect = 'nope'"):
        parse_endpoint("nope", "connect", key="link.connect")


def test_udp_listen_learns_peers_and_counts_garbage() -> None:
    async def main() -> None:
        server = await open_link(
            parse_endpoint("udp:127.0.0.1:0", "listen"), system_id=1, component_id=1
        )
        port = server.local_address[1]
        server.send(heartbeat())  # nobody heard yet
        assert server.counters.send_no_peer == 1
        client = await open_link(
            parse_endpoint(f"udp:127.0.0.1:{port}", "connect"), system_id=255, component_id=190
        )
        junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            junk.sendto(b"\x00garbage\xfd\x09", ("127.0.0.1", port))
            client.send(heartbeat(7))
            msg = await asyncio.wait_for(server.recv(), TIMEOUT_S)
            assert (msg.get_srcSystem(), msg.custom_mode) == (255, 7)
            assert server.peers == [client.local_address]  # the junk sender is not a peer
            assert server.framing.garbage_bytes == 10 and server.framing.truncated == 1
            server.send(heartbeat(9))
            reply = await asyncio.wait_for(client.recv(), TIMEOUT_S)
            assert (reply.get_srcSystem(), reply.custom_mode) == (1, 9)
            assert server.counters.frames_out == 1 and server.counters.connections == 1
        finally:
            junk.close()
            await client.close()
            await server.close()
        with pytest.raises(LinkClosed):
            await server.recv()

    asyncio.run(main())


def test_udp_connect_to_nobody_counts_errors_and_keeps_going() -> None:
    async def main() -> None:
        port = free_udp_port()  # nobody listens there now
        link = await open_link(
            parse_endpoint(f"udpout:127.0.0.1:{port}", "connect"), system_id=1, component_id=1
        )
        try:
            for _ in range(5):
                link.send(heartbeat())
                await asyncio.sleep(0.01)
            assert link.counters.frames_out == 5 and not link.closed
        finally:
            await link.close()

    asyncio.run(main())


def test_tcp_server_serves_every_client_and_clients_see_close() -> None:
    async def main() -> None:
        server = await open_link(
            parse_endpoint("tcp:127.0.0.1:0", "listen"), system_id=1, component_id=1
        )
        port = server.local_address[1]
        clients = [
            await open_link(
                parse_endpoint(f"tcp:127.0.0.1:{port}", "connect"), system_id=255, component_id=c
            )
            for c in (190, 191)
        ]
        try:
            for client in clients:
                client.send(heartbeat(client.encoder.component_id))
            got = {
                (await asyncio.wait_for(server.recv(), TIMEOUT_S)).get_srcComponent()
                for _ in clients
            }
            assert got == {190, 191}
            server.send(heartbeat(3))
            for client in clients:
                assert (await asyncio.wait_for(client.recv(), TIMEOUT_S)).custom_mode == 3
            await server.close()
            for client in clients:
                with pytest.raises(LinkClosed):
                    await asyncio.wait_for(client.recv(), TIMEOUT_S)
        finally:
            for client in clients:
                await client.close()
            await server.close()

    asyncio.run(main())


def test_tcp_connect_refused_is_an_os_error_naming_the_endpoint() -> None:
    async def main() -> None:
        probe = socket.socket()
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
        probe.close()
        with pytest.raises(ConnectionRefusedError, match=f"tcpout:127.0.0.1:{port}"):
            await open_link(
                parse_endpoint(f"tcp:127.0.0.1:{port}", "connect"), system_id=1, component_id=1
            )

    asyncio.run(main())


def test_serial_link_over_a_pty() -> None:
    async def main() -> None:
        master, slave = os.openpty()
        link = await open_link(
            parse_endpoint(f"serial:{os.ttyname(slave)}:115200", "connect"),
            system_id=1,
            component_id=1,
        )
        try:
            frame = FrameEncoder(9, 1).encode(heartbeat(4))
            os.write(master, b"noise" + frame[:5])
            await asyncio.sleep(0.02)
            os.write(master, frame[5:])  # the stream reassembles a frame split in two writes
            msg = await asyncio.wait_for(link.recv(), TIMEOUT_S)
            assert (msg.get_srcSystem(), msg.custom_mode) == (9, 4)
            assert link.framing.garbage_bytes == 5
            link.send(heartbeat(5))
            await asyncio.sleep(0.05)
            echoed = os.read(master, 512)
            assert echoed[0] == 0xFD and len(echoed) == len(FrameEncoder(1, 1).encode(heartbeat(5)))
        finally:
            await link.close()
            os.close(master)
            os.close(slave)

    asyncio.run(main())


def test_serial_missing_device_is_an_os_error() -> None:
    async def main() -> None:
        with pytest.raises(FileNotFoundError, match="/dev/does-not-exist"):
            await open_link(
                parse_endpoint("serial:/dev/does-not-exist:57600", "connect"),
                system_id=1,
                component_id=1,
            )

    asyncio.run(main())


def test_pymavlink_mavutil_interoperates() -> None:
    """An independent stack (pymavlink's mavutil, blocking, in a thread) talks to a link."""

    async def main() -> None:
        server = await open_link(
            parse_endpoint("udp:127.0.0.1:0", "listen"), system_id=1, component_id=1
        )
        port = server.local_address[1]
        gcs = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=255, dialect="ardupilotmega"
        )
        try:
            gcs.mav.heartbeat_send(6, 8, 0, 0, 0)
            msg = await asyncio.wait_for(server.recv(), TIMEOUT_S)
            assert msg.get_type() == "HEARTBEAT" and msg.get_srcSystem() == 255
            server.send(dialect.MAVLink_heartbeat_message(2, 3, 81, 4, 4, 3))
            received = await asyncio.to_thread(
                gcs.recv_match, type="HEARTBEAT", blocking=True, timeout=TIMEOUT_S
            )
            assert (
                received is not None and received.custom_mode == 4 and received.get_srcSystem() == 1
            )
        finally:
            gcs.close()
            await server.close()

    asyncio.run(main())


def test_udp_link_drains_a_burst_in_one_loop_turn() -> None:
    """A busy loop gets few turns: each readiness must read every queued datagram, not one."""

    async def main() -> None:
        link = await open_link(
            parse_endpoint("udp:127.0.0.1:0", "listen"), system_id=1, component_id=1
        )
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            encoder = FrameEncoder(9, 1)
            for i in range(200):
                sender.sendto(encoder.encode(heartbeat(i)), link.local_address)
            for _ in range(3):  # a few loop turns, far fewer than 200
                await asyncio.sleep(0)
            received = []
            while (msg := link.recv_nowait()) is not None:
                received.append(msg.custom_mode)
            assert received == list(range(200))
        finally:
            sender.close()
            await link.close()

    asyncio.run(main())
