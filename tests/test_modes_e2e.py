"""Tension modes end to end on the emulator over UDP (issue 5, "What it must show" (a)-(c)).

The emulator (an ArduPilot-Copter-like flight controller over the simulator) listens on a
free UDP port on 127.0.0.1. The companion service (:class:`CompanionService`, the shipped
``configs/companion.yaml`` with ``tension_mode`` switched on) connects to it over UDP, as on a
drone: it estimates, publishes, runs the tension filter and the mode logic, and sends GUIDED
targets and LAND. A ground station on a second UDP socket switches the autopilot to GUIDED
and plays the ground events (tug: MAV_CMD_USER_1; winch: MAV_CMD_DO_WINCH). The emulator runs
in this process (asyncio, real time x ``SPEED``) so that the checks can read the simulator's
truth (position, cable tension, armed, landed).
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from scenario_files import reel_in_scenario

from tether_companion.emulator.lockstep import build_controller
from tether_companion.emulator.server import EmulatorServer
from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.mavlink.framing import dialect
from tether_companion.resources import CONFIGS_DIR
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.systemd import SystemdNotifier

pytestmark = pytest.mark.integration

SPEED = 4.0
"""Emulator seconds per wall second."""
FC_SYSTEM, FC_COMPONENT = 1, 1


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


class GroundStation:
    """Commands to the flight controller from a ground station's own UDP socket."""

    def __init__(self, link) -> None:  # noqa: ANN001
        self.link = link

    def command(self, command: int, *params: float) -> None:
        values = [*params, *([0.0] * (7 - len(params)))]
        self.link.send(
            dialect.MAVLink_command_long_message(FC_SYSTEM, FC_COMPONENT, command, 0, *values)
        )

    def guided(self) -> None:
        self.command(dialect.MAV_CMD_DO_SET_MODE, dialect.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)

    def tug(self, force_ned_n: tuple[float, float, float], duration_s: float) -> None:
        self.command(dialect.MAV_CMD_USER_1, *force_ned_n, duration_s)

    def winch(self, rate_mps: float) -> None:
        self.command(dialect.MAV_CMD_DO_WINCH, 1, dialect.WINCH_RATE_CONTROL, 0.0, rate_mps)


async def _fly(
    scenario: str | Path,
    tension_mode: dict,
    script,  # noqa: ANN001 - async callable(ground_station, controller) -> None
    *,
    duration_s: float,
    emulator: dict | None = None,
):
    controller = build_controller(str(scenario), emulator=emulator)
    server = EmulatorServer(controller, [parse_endpoint("udp:127.0.0.1:0", "listen")], speed=SPEED)
    truth = Truth()
    async with server:
        _, port = server.local_address()
        config = load_service_config(
            CONFIGS_DIR / "companion.yaml",
            {
                "link": {"connect": f"udpout:127.0.0.1:{port}"},
                "recording": {"enabled": False},
                "tension_mode": tension_mode,
            },
        )
        service = CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))
        gcs_link = await open_link(
            parse_endpoint(f"udpout:127.0.0.1:{port}", "connect"), system_id=255, component_id=190
        )
        gcs_link.send(dialect.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))  # be heard
        stop = asyncio.Event()

        async def sample_truth() -> None:
            while True:
                sim = controller.sim
                truth.time_s.append(controller.time_s)
                truth.position.append(np.array(sim.body.x[:3]))
                truth.tension_n.append(sim.cable.tension_n)
                truth.armed.append(controller.armed)
                truth.landed.append(sim.landed)
                await asyncio.sleep(0.02)

        async def drain_gcs() -> None:
            while True:
                await gcs_link.recv()

        emulator_task = asyncio.create_task(server.run(duration_s), name="emulator")
        others = [
            asyncio.create_task(service.run(stop), name="service"),
            asyncio.create_task(script(GroundStation(gcs_link), controller), name="script"),
            asyncio.create_task(sample_truth(), name="truth"),
            asyncio.create_task(drain_gcs(), name="gcs-rx"),
        ]
        try:
            # a hang guard, not a speed bound: the emulator, the service and the script share
            # one event loop, which a busy machine slows far below SPEED (the 40 s reel-in took
            # 58-69 s of wall time at load 20-25 with the 17-state filter)
            await asyncio.wait_for(emulator_task, timeout=duration_s / SPEED * 10.0 + 60.0)
        finally:
            stop.set()
            for task in (emulator_task, *others):
                if task is not others[0]:
                    task.cancel()
            await asyncio.wait_for(
                asyncio.gather(emulator_task, *others, return_exceptions=True), timeout=15.0
            )
            await gcs_link.close()
    return controller, service, truth


async def _until(controller, time_s: float) -> None:  # noqa: ANN001
    while controller.time_s < time_s:
        await asyncio.sleep(0.01)


def test_a_tug_moves_the_hovering_drone_along_the_pull_then_it_holds() -> None:
    """Paper winch (4 N) hover at (2, 0, -3) m; a 3 N tug east for 3 s."""

    async def script(gcs: GroundStation, controller) -> None:  # noqa: ANN001
        await _until(controller, 1.0)
        gcs.guided()
        await _until(controller, 6.0)
        gcs.tug((0.0, 3.0, 0.0), 3.0)

    mode = {"enabled": True, "land_on_first_tug": False}
    controller, service, truth = asyncio.run(_fly("hover", mode, script, duration_s=20.0))
    start = truth.between(5.0, 6.0).mean(axis=0)
    end = truth.between(17.0, 20.0)
    moved = end.mean(axis=0) - start
    assert service.state.sent_by_type.get("SET_POSITION_TARGET_LOCAL_NED", 0) > 0
    assert moved[1] > 1.0, moved  # along the pull (east)
    assert abs(moved[2]) < 0.3
    assert np.ptp(end, axis=0).max() < 0.15  # then it holds
    assert controller.armed


TENSION_LIMIT_N = 12.0
"""No tension spike above this while the drone comes down (about 3x the 3.8 N of the hover).
Once it is on the ground the winch, still reeling in, pulls on a landed drone until the
autopilot disarms it: not counted."""


def test_b_winch_reel_in_lands_the_drone_near_the_anchor(tmp_path: Path) -> None:
    async def script(gcs: GroundStation, controller) -> None:  # noqa: ANN001
        await _until(controller, 1.0)
        gcs.guided()
        await _until(controller, 5.0)
        gcs.winch(-0.3)

    mode = {"enabled": True, "land_on_first_tug": True}
    controller, service, truth = asyncio.run(
        _fly(reel_in_scenario(tmp_path, 60.0), mode, script, duration_s=40.0)
    )
    final = controller.sim.body.x[:3]
    assert not controller.armed and controller.sim.landed
    assert math.hypot(final[0], final[1]) < 1.0, final
    flying = [
        f for f, a, g in zip(truth.tension_n, truth.armed, truth.landed, strict=True) if a and not g
    ]
    assert max(flying) < TENSION_LIMIT_N, max(flying)
    modes = service.session.modes
    assert modes.land_commands > 0 and modes.modes.fallback_lands == 0  # landed by the tether
    assert controller.mode.name == "LAND"


def test_c_estimate_lost_mid_landing_still_lands(tmp_path: Path) -> None:
    """The IMU stream stops at 12 s (mid-descent) and the winch stops: the service stops the
    drone, then hands over to the autopilot's LAND, which lands and disarms."""

    async def script(gcs: GroundStation, controller) -> None:  # noqa: ANN001
        await _until(controller, 1.0)
        gcs.guided()
        await _until(controller, 5.0)
        gcs.winch(-0.3)
        await _until(controller, 12.0)
        gcs.winch(0.0)

    emulator = {"faults": {"outages": [{"stream": "RAW_IMU", "start_s": 12.0, "duration_s": 60.0}]}}
    mode = {"enabled": True, "land_on_first_tug": True}
    controller, service, truth = asyncio.run(
        _fly(reel_in_scenario(tmp_path, 60.0), mode, script, duration_s=40.0, emulator=emulator)
    )
    heights = {round(t): -p[2] for t, p in zip(truth.time_s, truth.position, strict=True)}
    assert heights[12] > 1.0  # it really was mid-landing when the estimate went
    modes = service.session.modes
    assert modes.modes.fallback_lands == 1 and modes.land_commands > 0  # handed over to LAND
    assert controller.mode.name == "LAND"
    assert not controller.armed and controller.sim.landed
