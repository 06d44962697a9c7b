"""MAVSDK against the service with signing required, over UDP on 127.0.0.1.

The ``mavsdk`` Python package (4.x) loads MAVSDK's C library (``libcmavsdk``, MAVSDK v4.1.0);
there is no ``mavsdk_server`` in it. Neither its ``Configuration`` nor any plugin sets a
signing key (the library exports no signing call), so MAVSDK cannot sign and does not check
signatures. What that means with ``security.signing: required``, shown here: MAVSDK reads
our signed frames (and would read forged ones alike), and its commands, unsigned, are answered
COMMAND_ACK DENIED and counted as ``unsigned_command``. A MAVSDK ground station therefore
needs ``preferred`` or ``off`` (docs/security.md)."""

from __future__ import annotations

import asyncio
import json
import os
import socket

import pytest
from udp_ports import free_udp_port

from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.mavlink.signing import Signer
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.mode_command import TENSION_MODE_COMMAND
from tether_companion.service.security import UNSIGNED_COMMAND
from tether_companion.service.systemd import SystemdNotifier

pytestmark = pytest.mark.integration
KEY = bytes(range(40, 72))
MAVSDK_SYSTEM_ID = 245
"""MAVSDK's system id as a ground station (its default)."""
WALL_TIMEOUT_S = 10.0


async def _system(sdk, system_id: int):
    """The MAVSDK system with ``system_id`` once discovered."""
    while True:
        for system in await sdk.get_systems():
            if await system.get_system_id() == system_id:
                return system
        await asyncio.sleep(0.05)


async def _first(generator):
    async for item in generator:
        return item
    return None


def test_mavsdk_reads_signed_frames_unchecked_and_its_unsigned_commands_are_denied(
    tmp_path,
) -> None:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
    from mavsdk.plugins.mavlink_direct import MavlinkMessage

    key_file = tmp_path / "signing.key"
    key_file.write_bytes(KEY)
    os.chmod(key_file, 0o600)
    port = free_udp_port()

    async def scenario():
        sdk_config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(sdk_config) as sdk:
            assert (await sdk.version()).startswith("v4.")
            await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
            config = load_service_config(
                None,
                {
                    "link": {"connect": f"udpout:127.0.0.1:{port}"},
                    "recording": {"enabled": False},
                    "security": {
                        "signing": "required",
                        "key_file": str(key_file),
                        "command_sources": [MAVSDK_SYSTEM_ID],
                    },
                },
            )
            service = CompanionService(
                config, load_vehicle_for(config), notifier=SystemdNotifier({})
            )
            stop = asyncio.Event()
            task = asyncio.create_task(service.run(stop), name="service-under-test")
            try:
                ours = await asyncio.wait_for(_system(sdk, 1), WALL_TIMEOUT_S)
                assert await ours.component_ids() == [191]
                direct = MavlinkDirectAsync(ours)
                heartbeat = await asyncio.wait_for(
                    _first(direct.subscribe_message("HEARTBEAT")), WALL_TIMEOUT_S
                )
                assert heartbeat.component_id == 191  # a signed frame, read
                # a frame signed with the wrong key is read just the same: nothing is checked
                forger = FrameEncoder(7, 1, Signer(bytes(32), link_id=0))
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                    sock.sendto(
                        forger.encode(dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3)),
                        ("127.0.0.1", port),
                    )
                await asyncio.wait_for(_system(sdk, 7), WALL_TIMEOUT_S)
                command = MavlinkMessage(
                    "COMMAND_LONG",
                    0,
                    0,
                    1,
                    191,
                    json.dumps(
                        {
                            "target_system": 1,
                            "target_component": 191,
                            "command": TENSION_MODE_COMMAND,
                            "confirmation": 0,
                            **{f"param{i}": 1.0 if i == 1 else 0.0 for i in range(1, 8)},
                        }
                    ),
                )
                ack = await asyncio.wait_for(direct.send_command(command), WALL_TIMEOUT_S)
                link = service.link
                assert link is not None and link.trust is not None
                gate = link.trust.counters
            finally:
                stop.set()
                await asyncio.wait_for(task, WALL_TIMEOUT_S)
        return service, json.loads(ack.fields_json), gate

    service, ack, gate = asyncio.run(scenario())
    assert ack["command"] == TENSION_MODE_COMMAND
    assert ack["result"] == dialect.MAV_RESULT_DENIED
    # MAVSDK's command sender sends the command again when its ACK is late (a busy machine):
    # each copy is refused, none is obeyed
    refused = service.session.commands_refused
    assert refused.keys() == {UNSIGNED_COMMAND} and refused[UNSIGNED_COMMAND] >= 1, refused
    assert not service.session.modes.modes.enabled
    # its heartbeats dropped; its commands let through only to be refused (MAVSDK also sends
    # its own requests to the systems it found, addressed to others: ignored)
    assert gate.unsigned > 0 and gate.unsigned_commands >= 1
