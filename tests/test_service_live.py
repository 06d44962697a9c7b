"""The asyncio service over real sockets on 127.0.0.1 against a scripted flight controller:
stream requests, heartbeat, origin, TIMESYNC, publication rate, reboot recovery, bad bytes on
the wire, and back-off while the flight controller's TCP port refuses."""

from __future__ import annotations

import asyncio
import socket

import numpy as np
import pytest
from paper_filter import with_paper_filter
from rich.console import Console

from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.status import render
from tether_companion.service.synthetic import FakeFlightController, HoverStreams
from tether_companion.service.systemd import SystemdNotifier

pytestmark = pytest.mark.integration
POSITION = np.array([2.0, 1.0, -3.0])


async def _with_service(config, body):
    """Run ``body(service)`` while the service runs; always stop and await it."""
    service = CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))
    stop = asyncio.Event()
    task = asyncio.create_task(service.run(stop), name="service-under-test")
    try:
        await body(service)
    finally:
        stop.set()
        await asyncio.wait_for(task, timeout=10.0)
    return service


def _config(endpoint: str, tmp_path, **sections):
    overrides = {
        "link": {"connect": endpoint, "fc_system_id": 1},
        "recording": {"directory": str(tmp_path / "rec")},
    }
    for key, value in sections.items():
        overrides.setdefault(key, {}).update(value)
    return load_service_config(None, with_paper_filter(overrides))


def test_service_talks_to_a_flight_controller_over_udp(tmp_path) -> None:
    async def scenario() -> tuple:
        fc_link = await open_link(
            parse_endpoint("udpin:127.0.0.1:0", "listen"), system_id=1, component_id=1
        )
        port = fc_link.local_address[1]
        config = _config(
            f"udpout:127.0.0.1:{port}",
            tmp_path,
            origin={"latitude_deg": 47.5, "longitude_deg": 8.25, "altitude_m": 410.0},
        )
        vehicle = load_vehicle_for(config)
        fc = FakeFlightController(
            fc_link, HoverStreams(vehicle, POSITION, 4.0, rng=np.random.default_rng(2)), speed=4.0
        )
        other = FrameEncoder(2, 1)  # another system on the wire (SITL's tether sim is system 2)

        async def body(service: CompanionService) -> None:
            await fc.run(8.0)
            fc.inject += [
                b"\xfd\x09garbage bytes \x00\xff" * 3,
                other.encode(dialect.MAVLink_attitude_message(1, 0.0, 0.0, 0.0, 0, 0, 0)),
            ]
            await fc.run(4.0)
            await asyncio.sleep(2.5)  # the flight controller goes silent: link lost
            assert not service.state.link_up and service.state.link_losses == 1
            fc.reboot()
            await fc.run(8.0)

        try:
            service = await _with_service(config, body)
        finally:
            await fc_link.close()
        return fc, service

    fc, service = asyncio.run(scenario())
    log = fc.log
    # identity: an onboard controller, component 191
    assert log.heartbeats and all(
        h.type == dialect.MAV_TYPE_ONBOARD_CONTROLLER for h in log.heartbeats
    )
    assert {h.get_srcComponent() for h in log.heartbeats} == {191}
    # the four inputs requested at the configured rates, before and after the reboot
    intervals = [
        (int(c.param1), c.param2)
        for c in log.commands
        if c.command == dialect.MAV_CMD_SET_MESSAGE_INTERVAL
    ]
    for msg_id, interval_us in (
        (dialect.MAVLINK_MSG_ID_RAW_IMU, 5000.0),
        (dialect.MAVLINK_MSG_ID_ATTITUDE, 5000.0),
        (dialect.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, 5000.0),
        (dialect.MAVLINK_MSG_ID_DISTANCE_SENSOR, 50000.0),
    ):
        assert intervals.count((msg_id, interval_us)) >= 2
    # the EKF origin after each boot, from the configured ground-station location
    assert len(log.origins) == 2
    assert (log.origins[0].latitude, log.origins[0].longitude, log.origins[0].altitude) == (
        475000000,
        82500000,
        410000,
    )
    # positions: ~30 Hz of FC time, converged, finite, stamped in the FC's time base
    stamps = np.array([v.usec for v in log.vision])
    (reboot_index,) = np.flatnonzero(np.diff(stamps) < 0) + 1  # exactly one step back in time
    before, after = log.vision[:reboot_index], log.vision[reboot_index:]
    assert before[0].usec > 5_000_000 and after[0].usec < 5_000_000
    usec = stamps[:reboot_index]
    assert 25.0 <= (len(usec) - 1) / ((usec[-1] - usec[0]) * 1e-6) <= 31.0
    last = log.vision[-1]
    assert np.linalg.norm(np.array([last.x, last.y, last.z]) - POSITION) < 0.4
    assert all(np.isfinite([v.x, v.y, v.z]).all() for v in log.vision)
    assert after[0].reset_counter > before[-1].reset_counter  # reboot -> reset
    names = {v.name for v in log.named_values}
    assert names == {"TETH_TENS", "TETH_TN", "TETH_TE", "TETH_TD", "TETH_TMAG"}, names
    assert all(np.isfinite(v.value) for v in log.named_values)
    magnitude = [v.value for v in log.named_values if v.name == "TETH_TMAG"]
    assert abs(magnitude[-1] - 4.0) < 0.3  # the filtered tension of the 4 N hover
    assert any("position OK" in t.text for t in log.statustexts)
    # bad bytes and other systems: dropped and counted
    assert service.session.ingest.counters.reboots == 1
    assert service.session.ingest.counters.wrong_system >= 1
    assert service.state.origin_confirmed
    assert service.clock.timesync_rtt_s is not None and service.clock.timesync_rtt_s < 1.0
    # the --status view shows all of it
    console = Console(record=True, width=240)
    console.print(render(service))
    text = console.export_text()
    for fragment in (
        "health: ok",
        "TIMESYNC rtt",
        "imu",
        "published",
        "wrong system",
        "garbage bytes",
        "1-sigma",
        "VISION_POSITION_ESTIMATE",
    ):
        assert fragment in text, fragment


def test_falls_back_to_request_data_stream_when_intervals_are_refused(tmp_path) -> None:
    async def scenario() -> FakeFlightController:
        fc_link = await open_link(
            parse_endpoint("udpin:127.0.0.1:0", "listen"), system_id=1, component_id=1
        )
        config = _config(f"udpout:127.0.0.1:{fc_link.local_address[1]}", tmp_path)
        streams = HoverStreams(load_vehicle_for(config), POSITION, 4.0)
        fc = FakeFlightController(fc_link, streams, speed=4.0, message_interval_supported=False)

        async def body(service: CompanionService) -> None:
            await fc.run(3.0)

        try:
            await _with_service(config, body)
        finally:
            await fc_link.close()
        return fc

    fc = asyncio.run(scenario())
    groups = {m.req_stream_id for m in fc.log.stream_requests}
    assert {dialect.MAV_DATA_STREAM_RAW_SENSORS, dialect.MAV_DATA_STREAM_EXTRA1} <= groups
    assert fc.log.stream_requests[0].req_message_rate == 200
    assert fc.log.vision  # streaming started through the fallback and estimates came back


def test_back_off_while_the_port_refuses_then_connect(tmp_path) -> None:
    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # nothing listens there now: connections are refused

    async def scenario() -> CompanionService:
        config = _config(
            f"tcp:127.0.0.1:{port}", tmp_path, link={"retry_initial_s": 0.05, "retry_max_s": 0.4}
        )
        vehicle = load_vehicle_for(config)

        async def body(service: CompanionService) -> None:
            await asyncio.sleep(1.2)
            failures = service.state.link_open_failures
            assert 3 <= failures <= 12  # 0.05, 0.1, 0.2, 0.4, 0.4, ... s: backing off
            fc_link = await open_link(
                parse_endpoint(f"tcpin:127.0.0.1:{port}", "listen"), system_id=1, component_id=1
            )
            try:
                fc = FakeFlightController(fc_link, HoverStreams(vehicle, POSITION, 4.0), speed=4.0)
                await asyncio.wait_for(
                    _until(lambda: fc_link.counters.connections > 0), timeout=5.0
                )
                await fc.run(3.0)
                assert fc.log.vision and service.state.link_opens == 1
            finally:
                await fc_link.close()
            await asyncio.wait_for(
                _until(lambda: service.state.link_opens >= 1 and service.link is None), 5.0
            )

        return await _with_service(config, body)

    service = asyncio.run(scenario())
    assert service.state.last_error


async def _until(predicate) -> None:
    while not predicate():
        await asyncio.sleep(0.02)


def test_an_unexpected_handler_error_is_counted_not_fatal(tmp_path, capsys) -> None:
    config = _config("udp:127.0.0.1:14550", tmp_path)
    service = CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))
    calls = []

    def broken(msg, local_s=None, kind=None):
        calls.append(msg)
        raise RuntimeError("bug")

    service.session.on_message = broken  # type: ignore[method-assign]
    msg = dialect.MAVLink_attitude_message(1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    msg.pack(dialect.MAVLink(None, 1, 1))
    service._handle_guarded(None, msg)  # type: ignore[arg-type]
    service._handle_guarded(None, msg)  # type: ignore[arg-type]
    assert len(calls) == 2 and service.state.handler_errors == 2
    assert "RuntimeError" in service.state.last_error
    assert capsys.readouterr().err.count("Traceback") == 1  # reported once, not per message
