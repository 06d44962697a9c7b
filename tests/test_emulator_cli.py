"""``tether-companion emulate``: bad arguments and config give exit code 2 and a clear message;
a short real run prints and writes the score; a scenario's ``emulator:`` section is read."""

from __future__ import annotations

import json
import socket
import textwrap
import threading
from pathlib import Path

import pytest
from udp_ports import free_udp_port

from tether_companion.cli import main
from tether_companion.config import ConfigError
from tether_companion.emulator.config import load_emulator_scenario
from tether_companion.emulator.lockstep import build_controller
from tether_companion.mavlink.estimates import PoseEstimate, vision_position_estimate_message
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--listen", "udp:127.0.0.1"], "--listen = 'udp:127.0.0.1': missing host or port"),
        (["--connect", "carrier-pigeon:1:2"], "unknown scheme"),
        (["--speed", "0"], "--speed = 0.0: must be > 0"),
        (["--duration", "-1"], "--duration = -1.0: must be > 0"),
        (["--rate", "RAW_IMU"], "--rate = 'RAW_IMU': expected MSG=HZ"),
        (["--rate", "RAW_IMU=fast"], "expected MSG=HZ"),
        (["--rate", "NOT_A_STREAM=5"], "stream_rates_hz.NOT_A_STREAM"),
        (
            ["--rate", "RAW_IMU=5000"],
            "stream_rates_hz.RAW_IMU = 5000.0: must be a number >= 0.0 and <= 1000.0",
        ),
        (["--param", "MOT_SPIN_MIN"], "--param = 'MOT_SPIN_MIN': expected NAME=VALUE"),
        (["--param", "MOT_SPIN_MIN=low"], "expected NAME=VALUE"),
        (["--param", "NOT_A_PARAM=1"], "parameters.NOT_A_PARAM"),
        (["--drop", "1.5"], "faults.drop_probability = 1.5"),
        (["--outage", "ATTITUDE:1"], "--outage = 'ATTITUDE:1': expected STREAM:START_S:DURATION_S"),
        (["--outage", "NOPE:1:2"], "faults.outages[0].stream = 'NOPE'"),
        (["--range-out", "1:zero"], "DURATION_S must be a number"),
        (["--reboot-at", "-3"], "faults.reboots_s[0] = -3.0"),
        (["--sysid", "0"], "system_id = 0"),
        (["--seed", "-1"], "--seed = -1: must be >= 0"),
        (["no-such-scenario"], "no such built-in file"),
    ],
)
def test_bad_arguments_exit_2_with_a_clear_message(args, fragment, capsys) -> None:
    assert main(["emulate", *args]) == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err
    assert err.startswith("tether-companion emulate: error: ")


def test_port_in_use_is_a_clean_error(capsys) -> None:
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    try:
        port = busy.getsockname()[1]
        assert (
            main(["emulate", "hover", "--listen", f"udp:127.0.0.1:{port}", "--duration", "1"]) == 1
        )
        assert "Address already in use" in capsys.readouterr().err
    finally:
        busy.close()


def test_short_run_prints_and_writes_the_score(tmp_path: Path, capsys) -> None:
    out = tmp_path / "score.json"
    args = ["emulate", "hover", "--listen", "udp:127.0.0.1:0", "--connect", "udpout:127.0.0.1:9"]
    args += ["--duration", "1", "--speed", "10", "--quiet", "--score-out", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "udpin:127.0.0.1:0 (bound 127.0.0.1:" in printed and "udpout:127.0.0.1:9" in printed
    assert "estimates received: none; scored 0" in printed
    score = json.loads(out.read_text())
    assert score["scored"] == 0 and score["rmse_m"]["3d"] is None


def test_scenario_file_with_an_emulator_section(tmp_path: Path) -> None:
    path = tmp_path / "faulty.yaml"
    path.write_text(
        textwrap.dedent(
            """
            duration_s: 20
            trajectory: {kind: hover, position_ned_m: [1.0, 0.0, -2.0]}
            emulator:
              navigation: vision
              stream_rates_hz: {RAW_IMU: 100, SIM_STATE: 0}
              faults:
                drop_probability: 0.1
                outages: [{stream: ATTITUDE, start_s: 5, duration_s: 1}]
            """
        )
    )
    scenario, config = load_emulator_scenario(path)
    assert scenario.trajectory.position_ned_m == (1.0, 0.0, -2.0)
    assert config.navigation == "vision" and config.stream_rates_hz["RAW_IMU"] == 100
    assert config.faults.outages[0].stream == "ATTITUDE"
    controller = build_controller(str(path))
    assert controller.vision_navigation and controller.link_faults.drop_probability == 0.1
    path.write_text("emulator:\n  faults: {drop_probabilty: 0.1}\n")
    with pytest.raises(
        ConfigError, match=r"faulty.yaml: emulator.faults.drop_probabilty = 0.1: unknown key"
    ):
        load_emulator_scenario(path)
    path.write_text("emulator:\n  navigation: gps\n")
    with pytest.raises(
        ConfigError, match="emulator.navigation = 'gps': must be one of 'truth', 'vision'"
    ):
        load_emulator_scenario(path)
    path.write_text("duration_s: -1\nemulator: {}\n")
    with pytest.raises(ConfigError, match="faulty.yaml: duration_s = -1"):
        load_emulator_scenario(path)


def test_estimates_sent_during_a_run_are_scored(tmp_path: Path, capsys) -> None:
    """A companion sends the hover point, 10 cm north of it, stamped with the emulator's clock."""
    out = tmp_path / "score.json"
    port = free_udp_port()
    result: dict[str, int] = {}
    args = ["emulate", "hover", "--listen", f"udp:127.0.0.1:{port}", "--duration", "4", "--quiet"]
    args += ["--score-out", str(out), "--score-start", "0.5"]
    runner = threading.Thread(target=lambda: result.setdefault("code", main(args)))
    runner.start()
    companion = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    companion.settimeout(0.5)
    encoder, parser = FrameEncoder(1, 197), FrameParser()
    address = ("127.0.0.1", port)
    sent = 0
    try:
        companion.sendto(
            encoder.encode(dialect.MAVLink_heartbeat_message(18, 8, 0, 0, 0, 3)), address
        )
        while runner.is_alive() and sent < 40:
            try:
                data = companion.recv(1024)
            except (TimeoutError, ConnectionRefusedError):
                companion.sendto(
                    encoder.encode(dialect.MAVLink_heartbeat_message(18, 8, 0, 0, 0, 3)), address
                )
                continue
            for msg in parser.feed(data):
                if msg.get_type() == "ATTITUDE" and msg.time_boot_ms % 50 == 0:  # 20 Hz
                    pose = PoseEstimate(
                        msg.time_boot_ms * 1e-3, [2.1, 0.0, -3.0], (0.0, 0.0, 0.0), None, 0
                    )
                    companion.sendto(
                        encoder.encode(vision_position_estimate_message(pose)), address
                    )
                    sent += 1
            parser.end_datagram()
    finally:
        companion.close()
        runner.join(30)
    assert result.get("code") == 0
    score = json.loads(out.read_text())
    assert score["scored"] + score["warmup"] == sent >= 30
    assert score["rmse_m"]["north"] == pytest.approx(0.1, abs=0.01)  # hover at (2, 0, -3)
    assert "RMSE north" in capsys.readouterr().out
