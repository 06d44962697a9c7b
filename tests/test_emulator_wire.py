"""The emulator over real UDP on 127.0.0.1 against independent MAVLink stacks.

- MAVSDK (its C++ core) connects, reads position and attitude, arms, takes off to 5 m, flies
  to a point, lands and disarms (emulator in process, 2x speed).
- pymavlink's mavutil sees every stream at its configured rate within 10%, measured in
  emulator time (the emulator runs as a separate ``tether-companion emulate`` process).
- A parameter set by mavutil changes the simulation, seen in the telemetry.
- Garbage and mutated datagrams on one port leave the emulator flying and streaming.

Ports are chosen by the OS (port 0); every process, task and socket is closed at the end.
"""

from __future__ import annotations

import asyncio
import math
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil

from tether_companion.emulator.lockstep import build_controller
from tether_companion.emulator.server import EmulatorServer
from tether_companion.mavlink import geo
from tether_companion.mavlink.endpoints import parse_endpoint
from tether_companion.mavlink.framing import dialect

pytestmark = pytest.mark.integration
PROJECT_ROOT = Path(__file__).resolve().parent.parent
SPEED = 2.0
WALL_TIMEOUT_S = 30.0


# --------------------------------------------------------------------------- helpers


class EmulatorProcess:
    """``tether-companion emulate`` in a child process, listening on OS-chosen UDP ports."""

    def __init__(self, *args: str) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(PROJECT_ROOT), env.get("PYTHONPATH", "")])
        command = [sys.executable, "-m", "tether_companion.cli", "emulate", *args, "--quiet"]
        self.process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
        )
        self.ports: list[int] = []
        self.output: list[str] = []
        deadline = time.monotonic() + WALL_TIMEOUT_S
        assert self.process.stdout is not None
        while time.monotonic() < deadline:
            line = self.process.stdout.readline()
            if not line:
                break
            self.output.append(line)
            bound = re.search(r"\(bound 127\.0\.0\.1:(\d+)\)", line)
            if bound:
                self.ports.append(int(bound.group(1)))
            if "Ctrl-C to stop" in line:
                return
        self.stop()
        raise RuntimeError("emulator did not start:\n" + "".join(self.output))

    def stop(self) -> str:
        """SIGTERM, wait for the clean exit, return everything it printed."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                out, _ = self.process.communicate(timeout=WALL_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.process.kill()
                out, _ = self.process.communicate()
            self.output.append(out or "")
        return "".join(self.output)


@pytest.fixture
def hover_emulator():
    emulator = EmulatorProcess(
        "hover", "--listen", "udp:127.0.0.1:0", "--listen", "udp:127.0.0.1:0", "--speed", str(SPEED)
    )
    try:
        yield emulator
    finally:
        emulator.stop()


def connect(port: int):
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=255, source_component=190, dialect="ardupilotmega"
    )
    gcs.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    gcs.mav.heartbeat_send(dialect.MAV_TYPE_GCS, dialect.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    assert gcs.wait_heartbeat(timeout=WALL_TIMEOUT_S) is not None
    return gcs


def command(gcs, command_id: int, *params: float) -> int:
    values = list(params) + [0.0] * (7 - len(params))
    gcs.mav.command_long_send(1, 1, command_id, 0, *values)
    deadline = time.monotonic() + WALL_TIMEOUT_S
    while time.monotonic() < deadline:
        ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=1.0)
        if ack is not None and ack.command == command_id:
            return ack.result
    raise AssertionError(f"no COMMAND_ACK for {command_id}")


def collect(gcs, emulator_seconds: float) -> list:
    """Every message for ``emulator_seconds`` of emulator time (clock: RAW_IMU.time_usec)."""
    messages, start_us, clock_us = [], None, None
    deadline = time.monotonic() + WALL_TIMEOUT_S
    while time.monotonic() < deadline:
        msg = gcs.recv_match(blocking=True, timeout=1.0)
        if msg is None:
            continue
        if msg.get_type() == "RAW_IMU":
            clock_us = msg.time_usec
            start_us = clock_us if start_us is None else start_us
            if clock_us - start_us >= emulator_seconds * 1e6:
                return messages
        if clock_us is not None:
            messages.append((clock_us * 1e-6, msg))
    raise AssertionError("emulator time did not advance")


# --------------------------------------------------------------------------- mavutil


STAMPED = {
    "RAW_IMU": "time_usec",
    "HIGHRES_IMU": "time_usec",
    "ATTITUDE": "time_boot_ms",
    "DISTANCE_SENSOR": "time_boot_ms",
    "LOCAL_POSITION_NED": "time_boot_ms",
    "GLOBAL_POSITION_INT": "time_boot_ms",
    "SYSTEM_TIME": "time_boot_ms",
    "SERVO_OUTPUT_RAW": "time_usec",
}


def test_mavutil_sees_every_stream_at_its_configured_rate(hover_emulator) -> None:
    gcs = connect(hover_emulator.ports[0])
    try:
        configured = {
            "ATTITUDE": 50.0,
            "SERVO_OUTPUT_RAW": 100.0,
            "DISTANCE_SENSOR": 20.0,
            "SIM_STATE": 25.0,
            "HIGHRES_IMU": 40.0,
            "LOCAL_POSITION_NED": 5.0,
        }
        for name, rate in configured.items():
            msg_id = getattr(dialect, f"MAVLINK_MSG_ID_{name}")
            assert command(gcs, dialect.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / rate) == 0
        expected = {
            "RAW_IMU": 200.0,
            "HEARTBEAT": 1.0,
            "SYS_STATUS": 1.0,
            "EXTENDED_SYS_STATE": 1.0,
            "SYSTEM_TIME": 1.0,
            "GLOBAL_POSITION_INT": 10.0,
            "VFR_HUD": 4.0,
            **configured,
        }
        collect(gcs, 0.5)  # let the new rates take over
        times = defaultdict(list)
        for clock_s, msg in collect(gcs, 6.0):
            field = STAMPED.get(msg.get_type())
            if field is None:
                times[msg.get_type()].append(clock_s)
            else:
                times[msg.get_type()].append(
                    getattr(msg, field) * (1e-6 if field == "time_usec" else 1e-3)
                )
        for name, rate in expected.items():
            stamps = np.array(times[name])
            if name == "SERVO_OUTPUT_RAW":
                stamps = np.unwrap(stamps, period=2**32 * 1e-6)
            measured = (len(stamps) - 1) / (stamps[-1] - stamps[0])
            assert measured == pytest.approx(rate, rel=0.1), name
    finally:
        gcs.close()


def mean_pitch_deg(gcs, seconds: float) -> float:
    pitches = [m.pitch for _, m in collect(gcs, seconds) if m.get_type() == "ATTITUDE"]
    return math.degrees(float(np.mean(pitches)))


def test_parameter_set_by_mavutil_changes_the_simulation(hover_emulator) -> None:
    """TETH_TENSION 4 -> 10 N: hovering 2 m north, 3 m above the anchor, the drone must lean
    further north to hold against the pull: pitch = -atan(0.5547 T / (m g + 0.8321 T))."""
    gcs = connect(hover_emulator.ports[0])
    try:
        weight_n = 1.5 * 9.80665

        def expected(tension_n: float) -> float:
            return -math.degrees(math.atan(0.5547 * tension_n / (weight_n + 0.8321 * tension_n)))

        assert mean_pitch_deg(gcs, 1.0) == pytest.approx(expected(4.0), abs=0.5)
        gcs.mav.param_set_send(1, 1, b"TETH_TENSION", 10.0, dialect.MAV_PARAM_TYPE_REAL32)
        reply = gcs.recv_match(type="PARAM_VALUE", blocking=True, timeout=WALL_TIMEOUT_S)
        assert reply.param_id == "TETH_TENSION" and reply.param_value == 10.0
        collect(gcs, 4.0)  # the position loop's integrator takes up the new pull
        assert mean_pitch_deg(gcs, 1.0) == pytest.approx(expected(10.0), abs=0.5)
    finally:
        gcs.close()


def test_garbage_on_one_port_leaves_the_emulator_flying_and_streaming(hover_emulator) -> None:
    from test_emulator_fuzz import FrameFactory  # the in-process fuzz's frame generator

    observer = connect(hover_emulator.ports[0])
    fuzz = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rng = np.random.default_rng(11)
        factory = FrameFactory(rng)
        names = ["TETH_TENSION", "SIM_WIND_N", "EK3_SRC1_POSXY"]
        address = ("127.0.0.1", hover_emulator.ports[1])
        for i in range(5000):
            frame = factory.encoder.encode(factory.message(names))
            data = factory.mutate(frame) if rng.random() < 0.5 else frame
            fuzz.sendto(
                data + (rng.bytes(int(rng.integers(0, 40))) if i % 3 == 0 else b""), address
            )
            if i % 500 == 0:
                time.sleep(0.01)
        messages = collect(observer, 2.0)
        counts = defaultdict(int)
        for _, msg in messages:
            counts[msg.get_type()] += 1
        assert counts["RAW_IMU"] >= 0.9 * 400 and counts["HEARTBEAT"] >= 1
        positions = [m for _, m in messages if m.get_type() == "LOCAL_POSITION_NED"]
        assert (
            abs(positions[-1].x - 2.0) < 0.5 and abs(positions[-1].z + 3.0) < 0.5
        )  # still hovering
        assert (
            command(observer, dialect.MAV_CMD_REQUEST_MESSAGE, dialect.MAVLINK_MSG_ID_HOME_POSITION)
            == 0
        )
    finally:
        fuzz.close()
        observer.close()
    output = hover_emulator.stop()
    assert hover_emulator.process.returncode == 0, output
    assert "Traceback" not in output


# --------------------------------------------------------------------------- MAVSDK


async def _first(generator, timeout_s: float = WALL_TIMEOUT_S):
    async def first():
        async for item in generator:
            return item

    return await asyncio.wait_for(first(), timeout_s)


async def _mavsdk_flight() -> None:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    controller = build_controller("hover", landed=True)
    endpoint = parse_endpoint("udp:127.0.0.1:0", "listen")
    async with EmulatorServer(controller, [endpoint], speed=SPEED) as emulator:
        runner = asyncio.create_task(emulator.run(), name="emulator")
        try:
            config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
            async with Mavsdk(config) as sdk:
                await sdk.add_any_connection(f"udpout://127.0.0.1:{emulator.local_address()[1]}")
                system = await sdk.first_autopilot(timeout_s=WALL_TIMEOUT_S)
                assert system is not None
                telemetry, action = TelemetryAsync(system), ActionAsync(system)
                position = await _first(telemetry.subscribe_position())
                assert position.latitude_deg == pytest.approx(controller.home.lat_deg, abs=1e-6)
                assert position.relative_altitude_m == pytest.approx(0.0, abs=0.1)
                attitude = await _first(telemetry.subscribe_attitude_euler())
                assert abs(attitude.roll_deg) < 2.0 and abs(attitude.pitch_deg) < 2.0

                await action.set_takeoff_altitude(5.0)
                await action.arm()
                assert await _first(telemetry.subscribe_armed())
                await action.takeoff()
                altitude, deadline = 0.0, time.monotonic() + 60.0
                while altitude <= 4.8 and time.monotonic() < deadline:
                    altitude = (await _first(telemetry.subscribe_position())).relative_altitude_m
                    await asyncio.sleep(0.05)
                assert altitude == pytest.approx(5.0, abs=0.25)

                target = geo.ned_to_geodetic(controller.home, [3.0, 2.0, -5.0])
                await action.goto_location(target.lat_deg, target.lon_deg, target.alt_m, 0.0)
                deadline = time.monotonic() + 60.0
                while time.monotonic() < deadline:
                    position = await _first(telemetry.subscribe_position())
                    reached = geo.geodetic_to_ned(
                        controller.home,
                        geo.Geodetic(
                            position.latitude_deg,
                            position.longitude_deg,
                            position.absolute_altitude_m,
                        ),
                    )
                    if np.linalg.norm(reached - [3.0, 2.0, -5.0]) < 0.2:
                        break
                    await asyncio.sleep(0.05)
                np.testing.assert_allclose(
                    controller.sim.truth.position_ned_m, [3.0, 2.0, -5.0], atol=0.3
                )

                await action.land()
                deadline = time.monotonic() + 90.0
                while time.monotonic() < deadline and await _first(telemetry.subscribe_armed()):
                    await asyncio.sleep(0.05)
                assert not controller.armed and controller.sim.landed
                np.testing.assert_allclose(
                    controller.sim.truth.position_ned_m[:2], [3.0, 2.0], atol=0.3
                )
                assert controller.counters.handler_errors == 0
        finally:
            emulator.stop()
            await runner


def test_mavsdk_connects_arms_takes_off_flies_lands_and_disarms() -> None:
    asyncio.run(asyncio.wait_for(_mavsdk_flight(), 240.0))
