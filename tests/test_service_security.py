"""The service's security: command sources, signing keys in the configuration, and the live
service with signing required against a signed flight controller, spoofers and a pymavlink
ground station over real sockets on 127.0.0.1."""

from __future__ import annotations

import asyncio
import os
import socket
import time

import numpy as np
import pytest
from paper_filter import with_paper_filter
from pymavlink import mavutil

from tether_companion.cli import main
from tether_companion.config import ConfigError
from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.mavlink.signing import SignatureVerifier, Signer
from tether_companion.mavlink.trust import REQUIRED, LinkTrust
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.mode_command import TENSION_MODE_COMMAND
from tether_companion.service.security import NOT_A_COMMAND_SOURCE, UNSIGNED_COMMAND
from tether_companion.service.session import EstimationSession
from tether_companion.service.synthetic import FakeFlightController, HoverStreams
from tether_companion.service.systemd import SystemdNotifier

KEY = bytes(range(7, 39))
POSITION = np.array([2.0, 1.0, -3.0])


def _key_file(tmp_path, mode: int = 0o600):
    path = tmp_path / "signing.key"
    path.write_bytes(KEY.hex().encode())
    os.chmod(path, mode)
    return path


def _command(encoder: FrameEncoder, enable: float, landing: float = 0.0):
    frame = encoder.encode(
        dialect.MAVLink_command_long_message(
            1, 191, TENSION_MODE_COMMAND, 0, enable, landing, 0, 0, 0, 0, 0
        )
    )
    (msg,) = FrameParser().feed(frame)
    return msg


def test_mode_commands_only_from_the_configured_ground_stations() -> None:
    config = load_service_config(None, {"security": {"command_sources": [255, 250]}})
    session = EstimationSession(config, load_vehicle_for(config))
    (ack,) = session.on_message(_command(FrameEncoder(42, 190), 1.0, 1.0)).messages
    assert ack.result == dialect.MAV_RESULT_DENIED and not session.modes.modes.enabled
    assert not session.modes.modes.landing_flag
    (ack,) = session.on_message(_command(FrameEncoder(1, 1), 1.0)).messages  # not even the FC
    assert ack.result == dialect.MAV_RESULT_DENIED
    assert session.commands_refused == {NOT_A_COMMAND_SOURCE: 2}
    (ack,) = session.on_message(_command(FrameEncoder(250, 190), 1.0)).messages
    assert ack.result == dialect.MAV_RESULT_ACCEPTED and session.modes.modes.enabled
    # addressed to the sender (MAVLink's COMMAND_ACK target): an autopilot routes it there
    assert (ack.target_system, ack.target_component) == (250, 190)


def test_with_signing_required_an_unsigned_command_is_denied(tmp_path) -> None:
    config = load_service_config(
        None, {"security": {"signing": "required", "key_file": str(_key_file(tmp_path))}}
    )
    session = EstimationSession(config, load_vehicle_for(config))
    (ack,) = session.on_message(_command(FrameEncoder(255, 190), 1.0)).messages
    assert ack.result == dialect.MAV_RESULT_DENIED and not session.modes.modes.enabled
    signed = FrameEncoder(255, 190, Signer(KEY, 0))
    (ack,) = session.on_message(_command(signed, 1.0)).messages
    assert ack.result == dialect.MAV_RESULT_ACCEPTED and session.modes.modes.enabled
    assert session.commands_refused == {UNSIGNED_COMMAND: 1}


def test_signing_config_errors_name_the_key_and_the_fix(tmp_path) -> None:
    with pytest.raises(ConfigError, match="security.key_file"):
        load_service_config(None, {"security": {"signing": "required"}})
    with pytest.raises(ConfigError, match="security.install_key.*serial"):
        load_service_config(
            None,
            {
                "link": {"connect": "udp:127.0.0.1:14550"},
                "security": {"signing": "required", "key_file": "k", "install_key": True},
            },
        )
    config = load_service_config(
        None,
        {"security": {"signing": "required", "key_file": str(_key_file(tmp_path, 0o644))}},
    )
    with pytest.raises(ConfigError, match="chmod 600"):
        CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))


def test_run_with_a_world_readable_key_exits_2_with_one_line(tmp_path, capsys) -> None:
    config = tmp_path / "c.yaml"
    key = _key_file(tmp_path, 0o644)
    config.write_text(f"security:\n  signing: required\n  key_file: {key}\n")
    assert main(["run", "--config", str(config), "--no-record"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "chmod 600" in err[0] and "security.key_file" in err[0]


def _mavlink2_connection(address: str):
    """A pymavlink ground station (255/190) speaking MAVLink 2 from its first frame (mavutil
    starts in MAVLink 1, which cannot sign, unless MAVLINK20 is set when the dialect loads)."""
    before = os.environ.get("MAVLINK20")
    os.environ["MAVLINK20"] = "1"
    try:
        mavutil.set_dialect("ardupilotmega")
        return mavutil.mavlink_connection(address, source_system=255, source_component=190)
    finally:
        if before is None:
            del os.environ["MAVLINK20"]
        mavutil.set_dialect("ardupilotmega")


class _Spoofer:
    """A stranger on 127.0.0.1 sending frames to the service's listening port."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = port

    def send(self, frame: bytes) -> None:
        self.sock.sendto(frame, ("127.0.0.1", self.port))


@pytest.mark.integration
def test_signing_required_live_spoofers_change_nothing(tmp_path) -> None:
    """The service listens (udpin) with signing required; a signed flight controller streams a
    hover; spoofers send timestamp bombs and reboot-like stamps as the flight controller
    (unsigned and forged-signed), replay the flight controller's own signed frames and send
    mode commands; a pymavlink ground station with the key commands the tension modes.
    0 spoofed frames reach the estimator, 0 restarts, positions every ~33 ms throughout."""

    async def scenario():
        config = load_service_config(
            None,
            with_paper_filter(
                {
                    "link": {"connect": "udpin:127.0.0.1:0", "fc_system_id": 1},
                    "recording": {"enabled": False},
                    "security": {"signing": "required", "key_file": str(_key_file(tmp_path))},
                }
            ),
        )
        service = CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))
        stop = asyncio.Event()
        task = asyncio.create_task(service.run(stop), name="service-under-test")
        while service.link is None:
            await asyncio.sleep(0.01)
        port = service.link.local_address[1]
        fc_signer = Signer(KEY, link_id=1)
        fc_link = await open_link(
            parse_endpoint(f"udpout:127.0.0.1:{port}", "connect"),
            system_id=1,
            component_id=1,
            signer=fc_signer,
            trust=LinkTrust(REQUIRED, verifier=SignatureVerifier(KEY), fc_ids=(1, 191)),
        )
        sent: list[bytes] = []
        send_bytes = fc_link.send_bytes

        def capture(frame: bytes) -> None:
            sent.append(frame)
            send_bytes(frame)

        fc_link.send_bytes = capture  # type: ignore[method-assign]
        vehicle = load_vehicle_for(config)
        fc = FakeFlightController(
            fc_link, HoverStreams(vehicle, POSITION, 4.0, rng=np.random.default_rng(3)), speed=2.0
        )
        spoof = _Spoofer(port)
        fake_fc = FrameEncoder(1, 1)
        forger = FrameEncoder(1, 1, Signer(bytes(32), link_id=1))
        stranger = FrameEncoder(42, 190)

        def bombs() -> None:
            for enc in (fake_fc, forger):
                spoof.send(
                    enc.encode(
                        dialect.MAVLink_raw_imu_message(2**63, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0)
                    )
                )
                spoof.send(
                    enc.encode(
                        dialect.MAVLink_raw_imu_message(1000, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0)
                    )
                )
                spoof.send(enc.encode(dialect.MAVLink_system_time_message(0, 10)))
                spoof.send(enc.encode(dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3)))
            for frame in sent[-40:]:
                spoof.send(frame)  # replays of the real flight controller's signed frames
            spoof.send(
                stranger.encode(
                    dialect.MAVLink_command_long_message(
                        1, 191, TENSION_MODE_COMMAND, 0, 1, 1, 0, 0, 0, 0, 0
                    )
                )
            )

        gcs = _mavlink2_connection(f"udpout:127.0.0.1:{port}")
        gcs.setup_signing(KEY, sign_outgoing=True, link_id=2)
        trust = service.link.trust
        try:
            await fc.run(6.0)
            for _ in range(20):
                bombs()
                await fc.run(0.25)
            gcs.mav.command_long_send(1, 191, TENSION_MODE_COMMAND, 0, 1, 0, 0, 0, 0, 0, 0)
            await fc.run(1.0)
            acks = []
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline and not acks:
                msg = gcs.recv_match(type="COMMAND_ACK", blocking=False)
                if msg is not None:
                    acks.append(msg)
                else:
                    await asyncio.sleep(0.02)
        finally:
            gcs.close()
            spoof.sock.close()
            stop.set()
            await asyncio.wait_for(task, timeout=10.0)
            await fc_link.close()
        return service, fc, acks, trust.counters

    service, fc, acks, gate = asyncio.run(scenario())
    # every spoofed frame refused at the gate, by reason; the stranger's commands let through
    # unsigned only to be answered DENIED
    assert gate.unsigned == 20 * 4 and gate.bad_signature == 20 * 4
    assert gate.replay + gate.foreign_source == 20 * 40 and gate.replay > 0
    assert gate.unsigned_commands == 20
    session = service.session
    assert session.boots == 0 and session.ingest.counters.reboots == 0
    assert session.ingest.counters.out_of_order == 0  # no bomb moved the clock
    stamps = np.array([v.usec for v in fc.log.vision]) * 1e-6
    assert len(stamps) > 200 and np.all(np.diff(stamps) > 0)
    assert np.diff(stamps).max() < 0.1, np.diff(stamps).max()  # uninterrupted (FC time)
    last = fc.log.vision[-1]
    assert np.linalg.norm(np.array([last.x, last.y, last.z]) - POSITION) < 0.4
    # the pymavlink ground station's signed command was accepted, its ACK signed with our key
    assert acks and acks[0].result == dialect.MAV_RESULT_ACCEPTED and acks[0].get_signed()
    assert session.modes.modes.enabled
    assert session.commands_refused == {NOT_A_COMMAND_SOURCE: 20}  # each stranger's, DENIED


class _CapturingLink:
    """Just enough of a Link for CompanionService.housekeep: frames what is sent."""

    def __init__(self) -> None:
        self.encoder = FrameEncoder(1, 191)
        self.frames: list[bytes] = []
        self.trust = None

    def send_bytes(self, frame: bytes) -> None:
        self.frames.append(frame)


def test_install_key_sends_setup_signing_once_per_flight_controller_boot(tmp_path) -> None:
    config = load_service_config(
        None,
        {
            "link": {"connect": "serial:/dev/ttyAMA0:921600"},
            "recording": {"enabled": False},
            "security": {
                "signing": "required",
                "key_file": str(_key_file(tmp_path)),
                "install_key": True,
            },
        },
    )
    service = CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))
    link = _CapturingLink()
    service._fc_heard_s = 10.0  # the flight controller is present
    for t in (10.0, 10.1, 10.2):
        service.housekeep(link, t)  # type: ignore[arg-type]
    setups = [
        m for f in link.frames for m in FrameParser().feed(f) if m.get_type() == "SETUP_SIGNING"
    ]
    assert len(setups) == 1
    assert bytes(setups[0].secret_key) == KEY and setups[0].target_system == 1
    assert setups[0].initial_timestamp > 0
