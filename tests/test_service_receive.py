"""The service's receive path over a real UDP socket: every datagram of one socket readiness
parsed first, then handed to the service as one batch inside the read callback (no queue, no
task switch); a fatal error found while handling stops serving; a closed link ends it."""

from __future__ import annotations

import asyncio

import pytest

from tether_companion.config import ConfigError
from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.mavlink.framing import dialect
from tether_companion.mavlink.link import LinkClosed
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.systemd import SystemdNotifier


async def _pair():
    rx = await open_link(
        parse_endpoint("udpin:127.0.0.1:0", "listen"), system_id=1, component_id=191
    )
    port = rx.local_address[1]
    tx = await open_link(
        parse_endpoint(f"udpout:127.0.0.1:{port}", "connect"), system_id=1, component_id=1
    )
    return rx, tx


def _service() -> CompanionService:
    config = load_service_config(None, {"recording": {"enabled": False}})
    return CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))


def test_datagrams_are_handled_in_the_read_callback_and_a_fatal_error_stops_serving() -> None:
    async def scenario() -> list[int]:
        service = _service()
        rx, tx = await _pair()
        handled: list[int] = []

        def handle(link, msg, now_s):  # type: ignore[no-untyped-def]
            handled.append(msg.custom_mode)
            if msg.custom_mode == 4:
                service._fatal = ConfigError("", "vehicle", "x", "bad parameters")

        service.handle_message = handle  # type: ignore[method-assign]
        serving = asyncio.create_task(service._serve(rx))
        await asyncio.sleep(0.05)
        for mode in range(4):  # one burst: read in one readiness, handled as one batch
            tx.send(dialect.MAVLink_heartbeat_message(2, 3, 0, mode, 4, 3))
        await asyncio.sleep(0.1)
        assert not serving.done()
        tx.send(dialect.MAVLink_heartbeat_message(2, 3, 0, 4, 4, 3))
        with pytest.raises(ConfigError, match="bad parameters"):
            await asyncio.wait_for(serving, 2.0)
        assert rx._receiver is None  # back to queueing once serving stopped
        await tx.close()
        await rx.close()
        return handled

    handled = asyncio.run(scenario())
    assert handled == [0, 1, 2, 3, 4]


def test_a_closed_link_ends_serving_with_link_closed() -> None:
    async def scenario() -> None:
        service = _service()
        rx, tx = await _pair()
        serving = asyncio.create_task(service._serve(rx))
        tx.send(dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3))
        await asyncio.sleep(0.1)
        assert service.state.received == 1
        await rx.close()
        with pytest.raises(LinkClosed):
            await asyncio.wait_for(serving, 2.0)
        await tx.close()

    asyncio.run(scenario())
