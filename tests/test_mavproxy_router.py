"""The service behind MAVProxy (from PyPI), the router a companion computer often runs: the
flight controller (our emulator, its own process) is MAVProxy's master, the service one of its
outputs, all over real UDP sockets on 127.0.0.1.

What must hold through a router that is not ours: the flight controller is believed from the
router's address (its frames are relayed, not sent by the flight controller itself), the
stream-rate requests and the EKF origin reach the flight controller and are answered, the
ground station's winch and cable-angle frames relayed with the flight controller's arrive and
are fused, and the flight controller receives the estimates at the publication rate, stamped
in its own time base, with honest covariances.

A ground station (pymavlink's mavutil) on the flight controller's other port commands the
tension modes: the autopilot routes the command to the link it has seen the companion on
(the emulator routes as ArduPilot does: tether_companion/emulator/routing.py), MAVProxy
relays it, and the answer finds its way back; a stranger's command is DENIED the same way."""

from __future__ import annotations

import asyncio
import contextlib
import os
import subprocess
import sys
from pathlib import Path

import pytest
from pymavlink import mavutil
from udp_ports import free_udp_port

from tether_companion.mavlink.framing import dialect
from tether_companion.mavlink.link import Link
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.emulator_process import EmulatorProcess
from tether_companion.service.ingest import WINCH
from tether_companion.service.mode_command import TENSION_MODE_COMMAND
from tether_companion.service.security import NOT_A_COMMAND_SOURCE
from tether_companion.service.systemd import SystemdNotifier

pytestmark = pytest.mark.integration

MAVPROXY = pytest.importorskip(
    "MAVProxy", reason="MAVProxy is a test dependency: pip install -e '.[test]' installs it"
)

FLIGHT_S = 20.0
COMMAND_AT_S = 10.0
"""When the ground stations send their commands [s of wall time after the service starts]."""
COMPANION = (1, 191)


def _mavproxy(master_port: int, out_port: int, state_dir: Path) -> subprocess.Popen[bytes]:
    """MAVProxy without its interactive shell and default modules, asking no stream rates of
    its own (``--streamrate=-1``: the service asks for the rates it needs), connecting to the
    flight controller and listening for the service."""
    args = [
        sys.executable, "-m", "MAVProxy.mavproxy",
        f"--master=udpout:127.0.0.1:{master_port}",
        f"--out=udpin:127.0.0.1:{out_port}",
        "--daemon", "--non-interactive", "--streamrate=-1", "--default-modules=",
        f"--state-basedir={state_dir}",
    ]  # fmt: skip
    log = (state_dir / "mavproxy.out").open("wb")
    return subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, cwd=state_dir)


def _ask_tension_modes(port: int, system_id: int) -> int | None:
    """A ground station with ``system_id`` on the flight controller's ``port`` asks the
    companion to enable its tension modes; returns the companion's COMMAND_ACK result (None:
    no answer within 5 s)."""
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=system_id, source_component=190
    )
    try:
        gcs.mav.heartbeat_send(dialect.MAV_TYPE_GCS, dialect.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        for _ in range(5):  # once a second until the companion answers
            gcs.mav.command_long_send(*COMPANION, TENSION_MODE_COMMAND, 0, 1, 0, 0, 0, 0, 0, 0)
            ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=1.0)
            while ack is not None and (ack.get_srcSystem(), ack.get_srcComponent()) != COMPANION:
                ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=1.0)
            if ack is not None:
                return int(ack.result)
        return None
    finally:
        gcs.close()


async def _fly_behind_mavproxy(
    emulator: EmulatorProcess, state_dir: Path, overrides: dict
) -> tuple[CompanionService, list[Link], dict[int, int | None]]:
    """Emulator -> MAVProxy -> service until the emulator's flight ends, with ground stations
    (system 255, then a stranger 77) on the emulator's second port asking for the tension
    modes; returns the service, the links it served (kept while open: the service drops its
    link when it stops) and each ground station's answer."""
    async with emulator:
        assert emulator.port is not None
        out_port = free_udp_port()
        router = _mavproxy(emulator.port, out_port, state_dir)
        try:
            link = {"connect": f"udpout:127.0.0.1:{out_port}"}
            config = load_service_config(None, {**overrides, "link": link})
            service = CompanionService(
                config, load_vehicle_for(config), notifier=SystemdNotifier({})
            )
            stop = asyncio.Event()
            task = asyncio.create_task(service.run(stop), name="service")
            flight = asyncio.create_task(emulator.wait(), name="emulator")
            links: list[Link] = []
            answers: dict[int, int | None] = {}
            commands = asyncio.create_task(asyncio.sleep(COMMAND_AT_S))
            async with asyncio.timeout(FLIGHT_S + 60.0):
                while not flight.done():
                    if service.link is not None and service.link not in links:
                        links.append(service.link)
                    if commands.done() and not answers:
                        for system_id in (255, 77):
                            answers[system_id] = await asyncio.to_thread(
                                _ask_tension_modes, emulator.ports[1], system_id
                            )
                    await asyncio.sleep(0.2)
            assert flight.result() == 0
            stop.set()
            await asyncio.wait_for(task, timeout=10.0)
        finally:
            router.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                router.wait(timeout=10.0)
            if router.poll() is None:
                router.kill()
                router.wait()
    return service, links, answers


def test_service_behind_mavproxy_router(tmp_path: Path) -> None:
    """The paper's circle (4 N) with the ground station's winch and cable angle, the default
    dynamic filter with both, every frame through MAVProxy both ways."""
    emulator = EmulatorProcess(
        "paper-circle",
        duration_s=FLIGHT_S,
        score_path=tmp_path / "score.json",
        extra_args=("--winch", "--cable-angle", "--listen", "udp:127.0.0.1:0"),
    )
    overrides = {
        "winch": {"enabled": True},
        "cable_angle": {"enabled": True},
        "recording": {"enabled": False},
    }
    service, links, answers = asyncio.run(_fly_behind_mavproxy(emulator, tmp_path, overrides))
    router_log = (tmp_path / "mavproxy.out").read_text(errors="replace")
    assert "Detected vehicle 1:1" in router_log, router_log

    # the flight controller believed from the router's address, nothing refused
    (link,) = links
    trust = link.trust
    assert trust is not None and trust.fc_source is not None
    assert trust.fc_source[1] != emulator.port  # the router's socket, not the emulator's
    assert trust.counters.foreign_source == 0, trust.counters

    # the ground stations' commands routed by the autopilot and relayed by MAVProxy
    assert answers == {255: dialect.MAV_RESULT_ACCEPTED, 77: dialect.MAV_RESULT_DENIED}
    assert service.session.modes.modes.enabled
    assert service.session.commands_refused.keys() == {NOT_A_COMMAND_SOURCE}

    # the service's requests answered through the router
    assert service.state.origin_confirmed
    session = service.session
    assert session.ingest.counters.accepted[WINCH] >= 10.0 * (FLIGHT_S - 10.0)
    assert session.estimator.health.winch_fused >= 5.0 * (FLIGHT_S - 10.0)

    # what the flight controller received: published for most of the flight, at the rate,
    # in its time base, none beyond 3 sigma of its covariance
    score = emulator.score()
    print(  # the numbers docs/emulator.md quotes (pytest -s)
        f"via {trust.fc_source}: scored {score['scored']} at {score['rate_hz']:.1f} Hz, "
        f"horizontal RMSE {score['rmse_m']['horizontal']:.3f} m, "
        f"{score['beyond_3_sigma']} beyond 3 sigma, NEES {score['nees_mean']:.2f}; "
        f"winch accepted {session.ingest.counters.accepted[WINCH]}, "
        f"fused {session.estimator.health.winch_fused}"
    )
    assert score["invalid"] == 0 and score["unmatched"] == 0, score
    assert score["rate_hz"] >= 25.0, score
    assert score["scored"] >= 25.0 * (FLIGHT_S - 15.0), score
    assert score["beyond_3_sigma"] <= 0.01 * score["scored"], score
    assert score["rmse_m"]["horizontal"] <= 0.3, score
    assert os.path.exists(tmp_path / "mav.tlog")  # MAVProxy's own log of the relayed traffic
