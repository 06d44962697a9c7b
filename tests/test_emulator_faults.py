"""Link faults (drop, duplicate, corrupt, delay) on the emulator's output, and reboots."""

from __future__ import annotations

import asyncio
import socket

import numpy as np
import pytest

from tether_companion.emulator.faults import LinkFaults, LinkFaultSettings
from tether_companion.emulator.lockstep import LockstepPeer, build_controller
from tether_companion.emulator.server import EmulatorServer
from tether_companion.mavlink.endpoints import parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect

FRAME = FrameEncoder(1, 1).encode(dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3))


def test_no_faults_pass_frames_untouched() -> None:
    faults = LinkFaults(LinkFaultSettings(), np.random.default_rng(0))
    assert faults.apply(FRAME) == [(0.0, FRAME)]


def test_fault_rates_match_their_probabilities() -> None:
    settings = LinkFaultSettings(0.2, 0.1, 0.3, 0.01, 0.02)
    faults = LinkFaults(settings, np.random.default_rng(1))
    n = 20_000
    out = [faults.apply(FRAME) for _ in range(n)]
    dropped = sum(1 for copies in out if not copies)
    doubled = sum(1 for copies in out if len(copies) == 2)
    sent = [c for copies in out for c in copies]
    corrupted = [data for _, data in sent if data != FRAME]
    assert dropped / n == pytest.approx(0.2, abs=0.015)
    assert doubled / (n - dropped) == pytest.approx(0.1, abs=0.015)
    assert len(corrupted) / len(sent) == pytest.approx(0.3, abs=0.015)
    assert all(len(data) == len(FRAME) and data[0] == FRAME[0] for data in corrupted)
    assert FrameParser().feed(b"".join(corrupted)) == []  # every corruption is caught
    delays = np.array([delay for delay, _ in sent])
    assert delays.min() >= 0.01 and delays.max() <= 0.03 + 1e-12
    assert faults.counters.dropped == dropped and faults.counters.corrupted == len(corrupted)


def test_faults_on_the_wire_and_changed_by_parameter() -> None:
    """Over UDP: 20% drop, 10% duplicates, 10% corrupted; then EMU_DROP_PCT 0 stops the drops."""

    async def main() -> None:
        controller = build_controller(
            "hover",
            emulator={
                "stream_rates_hz": {"RAW_IMU": 200},
                "faults": {
                    "drop_probability": 0.2,
                    "duplicate_probability": 0.1,
                    "corrupt_probability": 0.1,
                    "delay_ms": 5.0,
                },
            },
        )
        sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sink.bind(("127.0.0.1", 0))
        sink.setblocking(False)
        datagrams: list[bytes] = []

        def drain() -> None:  # read as they come: a small kernel buffer must not drop any
            while True:
                try:
                    datagrams.append(sink.recv(1024))
                except BlockingIOError:
                    return

        loop = asyncio.get_running_loop()
        loop.add_reader(sink.fileno(), drain)
        endpoint = parse_endpoint("udp:127.0.0.1:0", "listen")
        async with EmulatorServer(controller, [endpoint], speed=4.0) as server:
            hello = FrameEncoder(255, 190).encode(
                dialect.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)
            )
            sink.sendto(hello, server.local_address())
            await asyncio.sleep(0.05)
            await server.run(4.0)
            await asyncio.sleep(0.1)  # delayed frames still in flight
            parser = FrameParser()
            imu = []
            for data in datagrams:
                imu += [m.time_usec for m in parser.feed(data) if m.get_type() == "RAW_IMU"]
                parser.end_datagram()
            sent = 4.0 * 200 + 1
            unique = len(set(imu))
            # a sample arrives intact at least once: not dropped, and one copy not corrupted
            intact = 0.8 * (0.9 * 0.9 + 0.1 * (1.0 - 0.1 * 0.1))
            assert unique / sent == pytest.approx(intact, abs=0.06)
            assert len(imu) > unique  # duplicates arrived
            assert (
                parser.counters.bad_crc + parser.counters.bad_header + parser.counters.garbage_bytes
                > 0
            )
            assert server.faults.counters.delayed > 0
            why = controller.params.set("EMU_DROP_PCT", 0.0)
            assert why is None and controller.link_faults.drop_probability == 0.0
            dropped_before = server.faults.counters.dropped
            await server.run(1.0)
            assert server.faults.counters.dropped == dropped_before
        loop.remove_reader(sink.fileno())
        sink.close()

    asyncio.run(main())


def test_reboot_command_restarts_the_clock_and_forgets_the_origin() -> None:
    fc = build_controller("hover", landed=True, emulator={"navigation": "vision"})
    gcs = LockstepPeer(fc)
    gcs.send(dialect.MAVLink_set_gps_global_origin_message(1, 322828000, -1067478000, 1200000, 0))
    assert fc.origin is not None
    gcs.advance(3.0)
    assert gcs.command(dialect.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1) == dialect.MAV_RESULT_ACCEPTED
    assert fc.origin is None and fc.counters.reboots == 1 and fc.boot_time_s == 0.0
    assert any(t.startswith("ArduCopter V4.5.0") for t in gcs.texts())
    gcs.received.clear()
    gcs.advance(0.5)
    stamps = [m.time_usec for m in gcs.received if m.get_type() == "RAW_IMU"]
    assert stamps[0] == 0 and stamps[-1] == 500_000
