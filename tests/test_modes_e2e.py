"""Tension modes end to end on the emulator over UDP (issue 5, "What it must show" (a)-(c)).

The emulator (an ArduPilot-Copter-like flight controller over the simulator) listens on a
free UDP port on 127.0.0.1; a companion connects to it over UDP, decodes RAW_IMU, ATTITUDE,
SERVO_OUTPUT_RAW, DISTANCE_SENSOR, LOCAL_POSITION_NED and HEARTBEAT, runs the tension filter
and the mode logic (:class:`~tether_companion.modes.session.TensionModeSession`) and sends
GUIDED targets and LAND back. Ground-station events go to the emulator as MAVLink commands
over the same link (tug: MAV_CMD_USER_1; winch: MAV_CMD_DO_WINCH). The emulator runs in this
process (asyncio, real time x ``SPEED``) so the test can read the simulator's truth (position,
cable tension, armed) for its checks.

The companion here is the minimal loop around the mode session (position from the flight
controller's LOCAL_POSITION_NED, navigation on truth); the service embeds the same session.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from tether_companion.emulator.lockstep import build_controller
from tether_companion.emulator.server import EmulatorServer
from tether_companion.estimation.tension_kf import TensionFilterConfig
from tether_companion.mavlink import units
from tether_companion.mavlink.endpoints import LinkClosed, open_link, parse_endpoint
from tether_companion.mavlink.framing import dialect
from tether_companion.modes.config import TensionModeConfig
from tether_companion.modes.session import TensionModeSession

pytestmark = pytest.mark.integration

SPEED = 4.0
"""Emulator seconds per wall second."""
FC_SYSTEM, FC_COMPONENT = 1, 1
TICK_PERIOD_S = 0.02
"""The mode logic runs at 50 Hz of flight-controller time, on whatever timestamped message
arrives (not only on IMU samples: a lost IMU stream must still be noticed)."""


@dataclass
class Truth:
    """What the test samples from the simulator while it runs."""

    time_s: list[float] = field(default_factory=list)
    position: list[np.ndarray] = field(default_factory=list)
    tension_n: list[float] = field(default_factory=list)
    armed: list[bool] = field(default_factory=list)
    landed: list[bool] = field(default_factory=list)

    def between(self, t0: float, t1: float) -> np.ndarray:
        return np.array(
            [p for t, p in zip(self.time_s, self.position, strict=True) if t0 <= t <= t1]
        )


class Companion:
    """A minimal companion: decodes the FC's streams into the mode session, sends its output."""

    def __init__(self, link, session: TensionModeSession, n_motors: int) -> None:  # noqa: ANN001
        self.link = link
        self.session = session
        self.n_motors = n_motors
        self.position = np.full(3, math.nan)
        self.height_m = math.nan
        self.cos_tilt = 1.0
        self.fc_time_s = -math.inf
        self.next_tick_s = -math.inf
        self.sent_kinds: list[str] = []

    async def run(self) -> None:
        with contextlib.suppress(LinkClosed, asyncio.CancelledError):
            while True:
                self.handle(await self.link.recv())

    def handle(self, msg) -> None:  # noqa: ANN001
        if msg.get_srcSystem() != FC_SYSTEM:
            return
        kind = msg.get_type()
        session = self.session
        if kind == "HEARTBEAT":
            session.on_heartbeat(msg.base_mode, msg.custom_mode)
        elif kind == "ATTITUDE":
            sample = units.attitude_from_attitude(msg)
            self.cos_tilt = math.cos(sample.roll_rad) * math.cos(sample.pitch_rad)
            session.on_attitude(sample)
            self._tick(sample.time_s)
        elif kind == "SERVO_OUTPUT_RAW":
            session.on_pwm(units.pwm_from_servo_output_raw(msg, self.n_motors))
        elif kind == "LOCAL_POSITION_NED":
            self.position = np.array([msg.x, msg.y, msg.z])
        elif kind == "DISTANCE_SENSOR":
            reading = units.range_from_distance_sensor(msg)
            self.height_m = reading.distance_m * self.cos_tilt if reading else math.nan
        elif kind == "RAW_IMU":
            sample = units.imu_from_raw_imu(msg)
            session.on_imu(sample)
            self._tick(sample.time_s)

    def _tick(self, fc_time_s: float) -> None:
        self.fc_time_s = max(self.fc_time_s, fc_time_s)
        if self.fc_time_s < self.next_tick_s:
            return
        self.next_tick_s = self.fc_time_s + TICK_PERIOD_S
        for out in self.session.tick(self.fc_time_s, self.position, self.height_m):
            self.sent_kinds.append(out.get_type())
            self.link.send(out)

    def command(self, command: int, *params: float) -> None:
        values = [*params, *([0.0] * (7 - len(params)))]
        self.link.send(
            dialect.MAVLink_command_long_message(FC_SYSTEM, FC_COMPONENT, command, 0, *values)
        )


async def _fly(
    scenario: str | Path,
    mode_config: TensionModeConfig,
    script,  # noqa: ANN001 - async callable(companion, controller) -> None
    *,
    duration_s: float,
    emulator: dict | None = None,
):
    controller = build_controller(str(scenario), emulator=emulator)
    server = EmulatorServer(controller, [parse_endpoint("udp:127.0.0.1:0", "listen")], speed=SPEED)
    truth = Truth()
    async with server:
        _, port = server.local_address()
        link = await open_link(
            parse_endpoint(f"udpout:127.0.0.1:{port}", "connect"), system_id=1, component_id=191
        )
        session = TensionModeSession(
            mode_config, TensionFilterConfig(), controller.sim.vehicle, FC_SYSTEM, FC_COMPONENT
        )
        companion = Companion(link, session, controller.sim.vehicle.n_motors)
        link.send(dialect.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))  # let the FC know us
        tasks = [
            asyncio.create_task(server.run(duration_s), name="emulator"),
            asyncio.create_task(companion.run(), name="companion"),
            asyncio.create_task(script(companion, controller), name="script"),
        ]

        async def sample_truth() -> None:
            while True:
                sim = controller.sim
                truth.time_s.append(controller.time_s)
                truth.position.append(np.array(sim.body.x[:3]))
                truth.tension_n.append(sim.cable.tension_n)
                truth.armed.append(controller.armed)
                truth.landed.append(sim.landed)
                await asyncio.sleep(0.02)

        sampler = asyncio.create_task(sample_truth(), name="truth")
        try:
            await asyncio.wait_for(tasks[0], timeout=duration_s / SPEED * 3.0 + 30.0)
        finally:
            for task in (*tasks, sampler):
                task.cancel()
            await asyncio.gather(*tasks, sampler, return_exceptions=True)
            await link.close()
    return controller, companion, truth


async def _until(controller, time_s: float) -> None:  # noqa: ANN001
    while controller.time_s < time_s:
        await asyncio.sleep(0.01)


def _set_guided(companion: Companion) -> None:
    companion.command(dialect.MAV_CMD_DO_SET_MODE, dialect.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)


def test_a_tug_moves_the_hovering_drone_along_the_pull_then_it_holds() -> None:
    """Paper winch (4 N) hover at (2, 0, -3) m; a 3 N tug east for 3 s."""

    async def script(companion: Companion, controller) -> None:  # noqa: ANN001
        await _until(controller, 1.0)
        _set_guided(companion)
        await _until(controller, 6.0)
        companion.command(dialect.MAV_CMD_USER_1, 0.0, 3.0, 0.0, 3.0)

    config = TensionModeConfig(enabled=True, land_on_first_tug=False)
    controller, companion, truth = asyncio.run(_fly("hover", config, script, duration_s=20.0))
    start = truth.between(5.0, 6.0).mean(axis=0)
    end = truth.between(17.0, 20.0)
    moved = end.mean(axis=0) - start
    assert moved[1] > 1.0, moved  # along the pull (east)
    assert abs(moved[2]) < 0.3
    assert np.ptp(end, axis=0).max() < 0.15  # then it holds
    assert controller.armed and "SET_POSITION_TARGET_LOCAL_NED" in companion.sent_kinds


def _reel_in_scenario(tmp_path: Path) -> Path:
    """Hover 5 m up, 1 m from the anchor, on an elastic line just past taut."""
    length = math.hypot(1.0, 5.0) - 0.03
    path = tmp_path / "reel-in.yaml"
    path.write_text(
        f"""
duration_s: 60.0
seed: 21
physics_rate_hz: 1000
vehicle: default-quad
cable: {{model: elastic, length_m: {length:.4f}, stiffness_n_per_m: 100.0,
        damping_n_s_per_m: 5.0, linear_density_kg_per_m: 0.0167, min_length_m: 0.2}}
trajectory: {{kind: hover, position_ned_m: [1.0, 0.0, -5.0]}}
initial: {{airborne: true}}
""",
        encoding="utf-8",
    )
    return path


TENSION_LIMIT_N = 12.0
"""No tension spike above this while the drone comes down (about 3x the 3.8 N of the hover).
Once it is on the ground the winch, still reeling in, pulls on a landed drone until the
autopilot disarms it: not counted."""


def _winch(companion: Companion, rate_mps: float) -> None:
    companion.command(dialect.MAV_CMD_DO_WINCH, 1, dialect.WINCH_RATE_CONTROL, 0.0, rate_mps)


def test_b_winch_reel_in_lands_the_drone_near_the_anchor(tmp_path: Path) -> None:
    async def script(companion: Companion, controller) -> None:  # noqa: ANN001
        await _until(controller, 1.0)
        _set_guided(companion)
        await _until(controller, 5.0)
        _winch(companion, -0.3)

    config = TensionModeConfig(enabled=True, land_on_first_tug=True)
    controller, companion, truth = asyncio.run(
        _fly(_reel_in_scenario(tmp_path), config, script, duration_s=40.0)
    )
    final = controller.sim.body.x[:3]
    assert not controller.armed and controller.sim.landed
    assert math.hypot(final[0], final[1]) < 1.0, final
    flying = [
        f for f, a, g in zip(truth.tension_n, truth.armed, truth.landed, strict=True) if a and not g
    ]
    assert max(flying) < TENSION_LIMIT_N, max(flying)
    assert "COMMAND_LONG" in companion.sent_kinds  # the LAND hand-over


def test_c_estimate_lost_mid_landing_still_lands(tmp_path: Path) -> None:
    """The IMU stream stops at 12 s (mid-descent) and the winch stops: the companion stops
    the drone, then hands over to the autopilot's LAND, which lands and disarms."""

    async def script(companion: Companion, controller) -> None:  # noqa: ANN001
        await _until(controller, 1.0)
        _set_guided(companion)
        await _until(controller, 5.0)
        _winch(companion, -0.3)
        await _until(controller, 12.0)
        _winch(companion, 0.0)

    emulator = {"faults": {"outages": [{"stream": "RAW_IMU", "start_s": 12.0, "duration_s": 60.0}]}}
    config = TensionModeConfig(enabled=True, land_on_first_tug=True)
    controller, companion, truth = asyncio.run(
        _fly(_reel_in_scenario(tmp_path), config, script, duration_s=40.0, emulator=emulator)
    )
    heights = {round(t): -p[2] for t, p in zip(truth.time_s, truth.position, strict=True)}
    assert heights[12] > 1.0  # it really was mid-landing when the estimate went
    assert companion.session.modes.state in ("fallback_land", "inactive")
    assert "COMMAND_LONG" in companion.sent_kinds  # the LAND hand-over
    assert not controller.armed and controller.sim.landed
