"""The spoof suite without signing, over real sockets on 127.0.0.1: the service listens
(udpin), the flight controller connects to it, and strangers on other ports send timestamp
bombs, spoofed reboots and out-of-order streams as the flight controller, mode commands, and
a flood of peers for the reply table. No datagram interrupts the positions for 0.1 s, no
stranger's command is accepted, the flight controller keeps receiving every estimate."""

from __future__ import annotations

import asyncio
import socket

import numpy as np
import pytest
from paper_filter import with_paper_filter

from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.mode_command import TENSION_MODE_COMMAND
from tether_companion.service.security import NOT_A_COMMAND_SOURCE
from tether_companion.service.synthetic import FakeFlightController, HoverStreams
from tether_companion.service.systemd import SystemdNotifier

pytestmark = pytest.mark.integration
POSITION = np.array([2.0, 1.0, -3.0])
ROUNDS = 20


def _imu(t_us: int) -> dialect.MAVLink_message:
    return dialect.MAVLink_raw_imu_message(t_us, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0)


def test_unsigned_spoofers_on_other_ports_interrupt_nothing() -> None:
    async def scenario():
        config = load_service_config(
            None,
            with_paper_filter(
                {
                    "link": {"connect": "udpin:127.0.0.1:0", "fc_system_id": 1},
                    "recording": {"enabled": False},
                }
            ),
        )
        service = CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))
        stop = asyncio.Event()
        task = asyncio.create_task(service.run(stop), name="service-under-test")
        while service.link is None:
            await asyncio.sleep(0.01)
        port = service.link.local_address[1]
        trust = service.link.trust
        fc_link = await open_link(
            parse_endpoint(f"udpout:127.0.0.1:{port}", "connect"), system_id=1, component_id=1
        )
        fc = FakeFlightController(
            fc_link,
            HoverStreams(load_vehicle_for(config), POSITION, 4.0, rng=np.random.default_rng(4)),
            speed=2.0,
        )
        spoofers = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(40)]
        for s in spoofers:
            s.bind(("127.0.0.1", 0))
        as_fc, stranger = FrameEncoder(1, 1), FrameEncoder(42, 190)

        def attack() -> None:
            ahead_us = int((fc.time_s + 0.003) * 1e6)
            datagrams = [
                as_fc.encode(_imu(2**63)),  # timestamp bomb
                as_fc.encode(dialect.MAVLink_system_time_message(0, 100))  # a "reboot"
                + b"".join(as_fc.encode(_imu(100_000 + 5000 * i)) for i in range(5)),
                b"".join(as_fc.encode(_imu(ahead_us + 5000 * i)) for i in range(10)),
                stranger.encode(
                    dialect.MAVLink_command_long_message(
                        1, 191, TENSION_MODE_COMMAND, 0, 1, 1, 0, 0, 0, 0, 0
                    )
                ),
            ]
            for i, s in enumerate(spoofers):  # the reply-table flood: 40 ports
                s.sendto(datagrams[i % len(datagrams)], ("127.0.0.1", port))

        try:
            await fc.run(6.0)
            for _ in range(ROUNDS):
                attack()
                await fc.run(0.25)
            await fc.run(1.0)
        finally:
            for s in spoofers:
                s.close()
            stop.set()
            await asyncio.wait_for(task, timeout=10.0)
            await fc_link.close()
        return service, fc, trust.counters

    service, fc, gate = asyncio.run(scenario())
    session = service.session
    assert session.boots == 0 and session.ingest.counters.reboots == 0
    assert session.ingest.counters.implausible == 0  # refused before: wrong address
    # 40 ports x 20 rounds: 3 of every 4 datagrams claim the flight controller
    assert gate.foreign_source == ROUNDS * 10 * (1 + 6 + 10)
    assert not session.modes.modes.enabled and not session.modes.modes.landing_flag
    assert session.commands_refused == {NOT_A_COMMAND_SOURCE: ROUNDS * 10}
    stamps = np.array([v.usec for v in fc.log.vision]) * 1e-6
    assert len(stamps) > 200 and np.all(np.diff(stamps) > 0)
    assert np.diff(stamps).max() < 0.1, np.diff(stamps).max()
    last = fc.log.vision[-1]
    assert np.linalg.norm(np.array([last.x, last.y, last.z]) - POSITION) < 0.4
