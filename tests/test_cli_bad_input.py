"""Every bad command line and configuration ends with exit code 2 and one line (no usage
block, no traceback), each bounded by a timeout; a link that cannot open says why at once and
retries; a huge or endless config file is refused before it is read."""

from __future__ import annotations

import asyncio
import os
import select
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tether_companion.cli import main

KEY_HEX = bytes(range(32)).hex()


def _file(tmp: Path, name: str, content: str | bytes, mode: int | None = None) -> str:
    path = tmp / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    if mode is not None:
        os.chmod(path, mode)
    return str(path)


# (case id, config YAML or None, extra argv, fragments the one line must hold)
# "{config}" in argv or fragments is the config file's path, "{tmp}" the test's directory.
CONFIG_CASES = [
    ("link-list", "link: [1, 2]", [], ["link", "mapping"]),
    ("link-int", "link: 5", [], ["link = 5", "mapping"]),
    ("recording-off-string", "recording: 'off'", [], ["recording = 'off'", "mapping"]),
    ("deep-list", "[" * 5000 + "]" * 5000, [], ["nested too deeply"]),
    ("deep-map", "a: {" * 3000 + "}" * 3000, [], ["{config}"]),
    ("unclosed-brace", "link: {connect: udp:127.0.0.1:5", [], ["not valid YAML"]),
    ("tab-indent", "link:\n\tconnect: x\n", [], ["not valid YAML"]),
    ("top-list", "- 1\n- 2\n", [], ["mapping"]),
    ("top-scalar", "hello\n", [], ["mapping"]),
    ("unknown-top", "linc: {}\n", [], ["linc", "unknown key"]),
    ("unknown-nested", "link: {conect: x}\n", [], ["link.conect", "unknown key"]),
    ("sysid-0", "link: {fc_system_id: 0}\n", [], ["link.fc_system_id = 0", ">= 1"]),
    ("kind", "estimator: {kind: dynamc}\n", [], ["estimator.kind = 'dynamc'", "'dynamic'"]),
    (
        "dynamic-formulation",
        "estimator: {kind: dynamic}\ndynamic_filter: {formulation: ukf}\n",
        [],
        ["dynamic_filter.formulation = 'ukf'", "'inertial'"],
    ),
    (
        "dynamic-noise-negative",
        "dynamic_filter: {accel_noise_std_mps2: -0.1}\n",
        [],
        ["dynamic_filter.accel_noise_std_mps2 = -0.1", "> 0"],
    ),
    (
        "dynamic-hypotheses",
        "dynamic_filter: {initial: {thrust_scale_hypotheses: 40}}\n",
        [],
        ["dynamic_filter.initial.thrust_scale_hypotheses = 40", "<= 15"],
    ),
    (
        "dynamic-unknown",
        "dynamic_filter: {noise: {velocity: 1.0}}\n",
        [],
        ["dynamic_filter.noise.velocity", "unknown key"],
    ),
    (
        "dynamic-known-tension",
        "estimator: {kind: dynamic}\ntension: {source: config}\n",
        [],
        ["tension.source = 'config'", "dynamic"],
    ),
    (
        "dynamic-anchor-twice",
        "dynamic_filter: {anchor_height_m: 2.0}\n",
        [],
        ["dynamic_filter.anchor_height_m", "unknown key"],
    ),
    (
        "terrain-negative",
        "estimator: {ground_station: {terrain_std_m: -0.05}}\n",
        [],
        ["estimator.ground_station.terrain_std_m = -0.05", ">= 0"],
    ),
    (
        "terrain-nan",
        "estimator: {ground_station: {terrain_std_m: .nan}}\n",
        [],
        ["estimator.ground_station.terrain_std_m"],
    ),
    (
        "terrain-text",
        "estimator: {ground_station: {terrain_std_m: bumpy}}\n",
        [],
        ["estimator.ground_station.terrain_std_m = 'bumpy'"],
    ),
    (
        "rest-height-negative",
        "dynamic_filter: {rest_height_m: -0.1}\n",
        [],
        ["dynamic_filter.rest_height_m = -0.1", ">= 0"],
    ),
    (
        "rest-height-text",
        "dynamic_filter: {rest_height_m: legs}\n",
        [],
        ["dynamic_filter.rest_height_m = 'legs'"],
    ),
    (
        "rest-velocity-zero",
        "dynamic_filter: {rest_velocity_std_mps: 0}\n",
        [],
        ["dynamic_filter.rest_velocity_std_mps = 0", "> 0"],
    ),
    (
        "rest-height-std-nan",
        "dynamic_filter: {rest_height_std_m: .nan}\n",
        [],
        ["dynamic_filter.rest_height_std_m"],
    ),
    (
        "terrain-correlation-zero",
        "estimator: {ground_station: {terrain_correlation_m: 0}}\n",
        [],
        ["estimator.ground_station.terrain_correlation_m = 0", "> 0"],
    ),
    (
        "terrain-correlation-nan",
        "estimator: {ground_station: {terrain_correlation_m: .nan}}\n",
        [],
        ["estimator.ground_station.terrain_correlation_m"],
    ),
    (
        "terrain-correlation-text",
        "estimator: {ground_station: {terrain_correlation_m: wavy}}\n",
        [],
        ["estimator.ground_station.terrain_correlation_m = 'wavy'"],
    ),
    (
        "learn-calibration-text",
        "dynamic_filter: {learn_calibration: maybe}\n",
        [],
        ["dynamic_filter.learn_calibration = 'maybe'", "true or false"],
    ),
    (
        "winch-tension-walk-zero",
        "dynamic_filter: {noise: {winch_tension_n2ps: 0}}\n",
        [],
        ["dynamic_filter.noise.winch_tension_n2ps = 0", "> 0"],
    ),
    (
        "winch-speed",
        "winch: {enabled: true, max_speed_mps: -1}\n",
        [],
        ["winch.max_speed_mps = -1", "> 0"],
    ),
    ("winch-tension", "tension: {source: winch}\n", [], ["tension.source = 'winch'", "winch"]),
    ("sysid-256", "link: {fc_system_id: 256}\n", [], ["link.fc_system_id = 256"]),
    ("sysid-text", "link: {fc_system_id: one}\n", [], ["link.fc_system_id", "integer"]),
    ("sysid-float", "link: {fc_system_id: 1.5}\n", [], ["link.fc_system_id", "integer"]),
    ("heartbeat-nan", "link: {heartbeat_hz: .nan}\n", [], ["link.heartbeat_hz", "finite"]),
    ("heartbeat-inf", "link: {heartbeat_hz: .inf}\n", [], ["link.heartbeat_hz", "finite"]),
    ("autopilot", "link: {autopilot: inav}\n", [], ["link.autopilot", "'ardupilot'"]),
    ("connect-int", "link: {connect: 5}\n", [], ["link.connect", "string"]),
    ("connect-word", "link: {connect: nope}\n", [], ["link.connect", "expected"]),
    ("connect-empty", "link: {connect: ''}\n", [], ["link.connect"]),
    ("backoff-order", "link: {retry_initial_s: 5, retry_max_s: 1}\n", [], ["retry_max_s"]),
    ("timeout-0", "link: {link_timeout_s: 0}\n", [], ["link.link_timeout_s", "> 0"]),
    ("rate-500", "publish: {rate_hz: 500}\n", [], ["publish.rate_hz = 500", "<= 200"]),
    ("covariance", "publish: {covariance: maybe}\n", [], ["publish.covariance", "'ekf'"]),
    ("name-long", "publish: {tension_name: WAYTOOLONGNAME}\n", [], ["publish.tension_name"]),
    ("unhealthy", "publish: {on_unhealthy: panic}\n", [], ["publish.on_unhealthy"]),
    ("rec-total", "recording: {max_file_mb: 10, max_total_mb: 15}\n", [], ["max_total_mb"]),
    ("bool-text", "publish: {statustext: 'yes'}\n", [], ["publish.statustext", "true or false"]),
    ("rec-flush", "recording: {flush_interval_s: 60}\n", [], ["recording.flush_interval_s"]),
    ("pwm-order", "inputs: {pwm_min_us: 900, pwm_max_us: 800}\n", [], ["pwm_max_us"]),
    ("reorder-neg", "inputs: {reorder_window_s: -1}\n", [], ["inputs.reorder_window_s"]),
    ("reorder-big", "inputs: {reorder_window_s: 5}\n", [], ["inputs.reorder_window_s", "<= 0.2"]),
    ("imu-rate", "streams: {imu_hz: 5}\n", [], ["streams.imu_hz", ">= 10"]),
    ("latitude", "origin: {latitude_deg: 91}\n", [], ["origin.latitude_deg"]),
    ("watchdog", "watchdog_interval_s: -1\n", [], ["watchdog_interval_s"]),
    ("vehicle", "vehicle: no-such-vehicle\n", [], ["vehicle"]),
    ("msg-name", "tension: {message_name: ''}\n", [], ["tension.message_name"]),
    ("three-state", "estimator: {kind: three_state}\n", [], ["tension.source"]),
    ("signing-word", "security: {signing: maybe}\n", [], ["security.signing", "'required'"]),
    ("signing-no-key", "security: {signing: required}\n", [], ["security.key_file"]),
    (
        "key-missing",
        "security: {signing: required, key_file: /nonexistent/key}\n",
        [],
        ["security.key_file", "/nonexistent/key"],
    ),
    (
        "key-world-readable",
        "security: {signing: required, key_file: '{tmp}/key644'}\n",
        [],
        ["security.key_file", "chmod 600"],
    ),
    (
        "key-short",
        "security: {signing: preferred, key_file: '{tmp}/keyshort'}\n",
        [],
        ["security.key_file", "64 hex"],
    ),
    ("sources-scalar", "security: {command_sources: 255}\n", [], ["security.command_sources"]),
    ("sources-0", "security: {command_sources: [0]}\n", [], ["security.command_sources[0]"]),
    ("link-id", "security: {link_id: 300}\n", [], ["security.link_id"]),
    (
        "install-udp",
        "link: {connect: 'udp:127.0.0.1:14550'}\n"
        "security: {signing: required, key_file: k, install_key: true}\n",
        [],
        ["security.install_key", "serial"],
    ),
    ("install-off", "security: {install_key: true}\n", [], ["security.install_key"]),
    ("not-utf8", b"link: {connect: \xff\xfe}\n", [], ["UTF-8"]),
    ("huge", "# padding\n" * 200_000, [], ["too large"]),
    ("empty-connect-flag", "", ["--connect", ""], ["link.connect"]),
]

ARGV_CASES = [
    ("no-command", [], ["required"]),
    ("unknown-command", ["fly"], ["invalid choice"]),
    ("run-bogus-flag", ["run", "--bogus"], ["unrecognized arguments: --bogus", "--help"]),
    ("run-autopilot", ["run", "--autopilot", "inav"], ["--autopilot", "invalid choice"]),
    ("run-connect-missing", ["run", "--connect"], ["--connect", "expected one argument"]),
    ("connect-no-port", ["run", "--connect", "udp:127.0.0.1"], ["udp:127.0.0.1"]),
    ("connect-port-word", ["run", "--connect", "udp:127.0.0.1:x"], ["PORT must be an integer"]),
    ("connect-port-big", ["run", "--connect", "udp:127.0.0.1:70000"], ["65535"]),
    ("connect-port-0", ["run", "--connect", "udpout:127.0.0.1:0"], ["port must be 1..65535"]),
    ("connect-scheme", ["run", "--connect", "ftp:host:21"], ["unknown scheme 'ftp'"]),
    ("serial-relative", ["run", "--connect", "serial:ttyS0:57600"], ["serial:/dev/DEVICE"]),
    ("serial-baud", ["run", "--connect", "serial:/dev/ttyS0:12345"], ["baud rate 12345"]),
    ("serial-baud-word", ["run", "--connect", "serial:/dev/ttyS0:fast"], ["BAUD"]),
    ("tcp-no-host", ["run", "--connect", "tcp::5760"], ["missing host"]),
    ("config-missing", ["run", "--config", "/nonexistent/c.yaml"], ["file not found"]),
    ("config-dir", ["run", "--config", "{tmp}"], ["not a regular file"]),
    ("config-dev-zero", ["run", "--config", "/dev/zero"], ["/dev/zero", "not a regular file"]),
    ("replay-missing", ["replay", "/nonexistent/x.tlog", "--out", "{tmp}/o.csv"], ["no such"]),
    ("replay-kind", ["replay", "{tmp}/notes.txt", "--out", "{tmp}/o.csv"], ["unknown log kind"]),
    ("emulate-bogus", ["emulate", "--bogus"], ["unrecognized arguments"]),
    ("emulate-speed", ["emulate", "--speed", "fast"], ["--speed", "invalid float"]),
    ("simulate-bogus", ["simulate", "x.yaml", "--frobnicate"], ["unrecognized arguments"]),
    ("simulate-no-scenario", ["simulate"], ["required: scenario"]),
    ("bench-bogus", ["bench", "--bogus"], ["bench"]),
]


@pytest.fixture
def workdir(tmp_path: Path) -> Path:
    _file(tmp_path, "key644", KEY_HEX, 0o644)
    _file(tmp_path, "keyshort", "abcd", 0o600)
    _file(tmp_path, "notes.txt", "not a log")
    return tmp_path


def _one_line_exit_2(argv: list[str], capsys) -> str:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse exits from inside parse_args
        code = exc.code
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert code == 2, (code, captured.err)
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err and captured.out == ""
    return lines[0]


@pytest.mark.timeout(30)
@pytest.mark.parametrize(
    ("yaml_text", "extra", "fragments"),
    [case[1:] for case in CONFIG_CASES],
    ids=[case[0] for case in CONFIG_CASES],
)
def test_bad_config_exits_2_with_one_line(workdir, capsys, yaml_text, extra, fragments) -> None:
    if isinstance(yaml_text, str):
        yaml_text = yaml_text.replace("{tmp}", str(workdir))
    config = _file(workdir, "companion.yaml", yaml_text)
    line = _one_line_exit_2(["run", "--config", config, "--no-record", *extra], capsys)
    if "{config}" not in fragments and yaml_text:
        assert config in line, line  # the file is named
    for fragment in fragments:
        assert fragment.replace("{config}", config) in line, line


@pytest.mark.timeout(30)
@pytest.mark.parametrize(
    ("argv", "fragments"),
    [case[1:] for case in ARGV_CASES],
    ids=[case[0] for case in ARGV_CASES],
)
def test_bad_command_line_exits_2_with_one_line(workdir, capsys, argv, fragments) -> None:
    line = _one_line_exit_2([a.replace("{tmp}", str(workdir)) for a in argv], capsys)
    for fragment in fragments:
        assert fragment in line, line


def test_the_table_has_at_least_60_cases() -> None:
    assert len(CONFIG_CASES) + len(ARGV_CASES) >= 60


# --- real processes ----------------------------------------------------------------------


def _cli(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "tether_companion.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        **kwargs,
    )


@pytest.mark.integration
@pytest.mark.timeout(60)
def test_dev_zero_config_is_refused_by_a_real_process_without_reading_it() -> None:
    proc = _cli("run", "--config", "/dev/zero", "--no-record")
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 2 and out == b""
    assert err.decode().strip().splitlines() == [
        "tether-companion run: error: /dev/zero: <top level> = <missing>: not a regular file"
    ]


def _until_line(proc: subprocess.Popen, needle: str, timeout_s: float) -> tuple[str, float]:
    """The first stderr line holding ``needle`` and how long it took [s]."""
    start = time.monotonic()
    assert proc.stderr is not None
    fd = proc.stderr.fileno()
    seen = ""
    while time.monotonic() - start < timeout_s:
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            seen += os.read(fd, 4096).decode("utf-8", "replace")
            for line in seen.splitlines():
                if needle in line:
                    return line, time.monotonic() - start
    raise AssertionError(f"no {needle!r} within {timeout_s} s; stderr: {seen!r}")


@pytest.mark.integration
@pytest.mark.timeout(90)
def test_links_that_cannot_open_say_why_at_once_then_retry(tmp_path) -> None:
    """A serial path that is no serial port (/dev/null: termios refuses it) and a UDP port
    already in use: the running service names the cause, keeps retrying (saying it once, not
    per retry) and stops cleanly on SIGTERM (the 2 s bound: the next test)."""
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    port = busy.getsockname()[1]
    try:
        for connect, cause in (
            ("serial:/dev/null:921600", "not a serial port"),
            (f"udpin:127.0.0.1:{port}", "Address already in use"),
        ):
            proc = _cli("run", "--connect", connect, "--no-record")
            try:
                line, _ = _until_line(proc, "cannot open", 30.0)
                assert cause in line and "retrying with back-off" in line, line
                time.sleep(2.0)  # more retries (0.5 s, 1 s, ...) are not reported again
                assert proc.poll() is None  # still running
                proc.send_signal(signal.SIGTERM)
                _, err_bytes = proc.communicate(timeout=20)
                err = err_bytes.decode("utf-8", "replace")
                assert proc.returncode == 0, err
                assert "Traceback" not in err and err.count("cannot open") == 0, err
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.communicate()
    finally:
        busy.close()


def test_an_open_that_hangs_is_reported_within_two_seconds(capsys) -> None:
    """An open that never completes (an unanswered TCP connect, a name lookup that hangs)
    counts as failed after LINK_OPEN_TIMEOUT_S and is said on stderr."""
    from tether_companion.service.app import CompanionService
    from tether_companion.service.config import load_service_config, load_vehicle_for
    from tether_companion.service.link_supervisor import LINK_OPEN_TIMEOUT_S
    from tether_companion.service.systemd import SystemdNotifier

    started: list[float] = []

    async def hang():
        started.append(time.monotonic())
        await asyncio.sleep(3600.0)

    config = load_service_config(None, {"recording": {"enabled": False}})
    service = CompanionService(
        config, load_vehicle_for(config), notifier=SystemdNotifier({}), open_link_fn=hang
    )

    async def scenario() -> float:
        stop = asyncio.Event()
        task = asyncio.create_task(service.run(stop))
        while service.state.link_open_failures == 0:
            await asyncio.sleep(0.01)
        elapsed = time.monotonic() - started[0]  # from the start of the first attempt
        stop.set()
        await asyncio.wait_for(task, 10.0)
        return elapsed

    elapsed = asyncio.run(scenario())
    # ``started`` is stamped inside the open, which a loaded loop runs a little after the
    # timeout's clock began (measured 12 ms under the full suite at load 10)
    assert LINK_OPEN_TIMEOUT_S - 0.1 <= elapsed < LINK_OPEN_TIMEOUT_S + 1.0
    err = capsys.readouterr().err
    assert err.count("cannot open") == 1 and "no answer within 2 s" in err, err


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    ("connect", "cause"),
    [
        ("udpin:192.0.2.1:14550", "Cannot assign requested address"),  # not this machine's
        ("udpout:no-such-host.invalid:14550", "cannot resolve the host"),
        ("tcpout:127.0.0.1:9", "Connect call failed"),  # nobody listens on port 9
    ],
    ids=["non-local-bind", "unresolvable-host", "tcp-refused"],
)
def test_links_that_cannot_open_are_named_with_their_cause(capsys, connect, cause) -> None:
    from tether_companion.service.app import CompanionService
    from tether_companion.service.config import load_service_config, load_vehicle_for
    from tether_companion.service.systemd import SystemdNotifier

    config = load_service_config(
        None, {"link": {"connect": connect}, "recording": {"enabled": False}}
    )
    service = CompanionService(config, load_vehicle_for(config), notifier=SystemdNotifier({}))

    async def scenario() -> None:
        stop = asyncio.Event()
        task = asyncio.create_task(service.run(stop))
        while service.state.link_open_failures < 2:  # retried, and said only once
            await asyncio.sleep(0.01)
        stop.set()
        await asyncio.wait_for(task, 10.0)

    asyncio.run(scenario())
    lines = [line for line in capsys.readouterr().err.splitlines() if "cannot open" in line]
    assert len(lines) == 1 and cause in lines[0] and connect in lines[0], lines
