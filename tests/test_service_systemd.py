"""sd_notify: READY/WATCHDOG/STATUS/STOPPING over a fake NOTIFY_SOCKET, in-process and as a
real ``tether-companion run`` process stopped by SIGTERM."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tether_companion.resources import PROJECT_ROOT
from tether_companion.service.systemd import SystemdNotifier


@pytest.fixture
def notify_socket(tmp_path: Path):
    """A unix datagram socket standing in for systemd's NOTIFY_SOCKET."""
    path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(0.2)
    yield path, sock
    sock.close()


def _read_all(sock: socket.socket, until_s: float, stop_when=None) -> list[str]:
    messages: list[str] = []
    while time.monotonic() < until_s:
        try:
            messages.append(sock.recv(4096).decode())
        except TimeoutError:
            continue
        if stop_when is not None and stop_when(messages):
            break
    return messages


def test_notifier_sends_each_kind(notify_socket) -> None:
    path, sock = notify_socket
    notifier = SystemdNotifier({"NOTIFY_SOCKET": str(path), "WATCHDOG_USEC": "3000000"})
    assert notifier.enabled and notifier.watchdog_interval_s == pytest.approx(1.5)
    notifier.ready(status="up")
    notifier.watchdog()
    notifier.status("line one\nline two")
    notifier.stopping()
    notifier.close()
    got = [sock.recv(4096).decode() for _ in range(4)]
    assert got == ["READY=1\nSTATUS=up", "WATCHDOG=1", "STATUS=line one line two", "STOPPING=1"]


def test_notifier_without_socket_is_a_no_op() -> None:
    notifier = SystemdNotifier({})
    notifier.ready()
    notifier.watchdog()
    assert not notifier.enabled and notifier.sent == 0 and notifier.watchdog_interval_s is None


def test_abstract_socket_address_and_foreign_watchdog_pid() -> None:
    name = f"tether-test-{os.getpid()}-{time.monotonic_ns()}"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(b"\0" + name.encode())
    sock.settimeout(1.0)
    try:
        env = {"NOTIFY_SOCKET": "@" + name, "WATCHDOG_USEC": "1000000", "WATCHDOG_PID": "1"}
        notifier = SystemdNotifier(env)
        assert notifier.watchdog_interval_s is None  # the watchdog is meant for PID 1, not us
        notifier.ready()
        assert sock.recv(100) == b"READY=1"
        notifier.close()
    finally:
        sock.close()


def test_notifier_counts_errors_when_systemd_is_gone(tmp_path: Path) -> None:
    notifier = SystemdNotifier({"NOTIFY_SOCKET": str(tmp_path / "missing.sock")})
    notifier.ready()
    assert notifier.errors == 1 and notifier.sent == 0
    notifier.close()


@pytest.mark.integration
def test_service_process_notifies_ready_watchdog_and_stops_on_sigterm(
    notify_socket, tmp_path: Path
) -> None:
    """`tether-companion run` under a fake systemd: READY=1, WATCHDOG=1 every ~WatchdogSec/2,
    clean exit 0 on SIGTERM with STOPPING=1 and the recording closed."""
    path, sock = notify_socket
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # a silent "flight controller"
    peer.bind(("127.0.0.1", 0))
    port = peer.getsockname()[1]
    env = dict(
        os.environ, NOTIFY_SOCKET=str(path), WATCHDOG_USEC="200000", PYTHONPATH=str(PROJECT_ROOT)
    )
    record_dir = tmp_path / "rec"
    cmd = [
        sys.executable,
        "-m",
        "tether_companion.cli",
        "run",
        "--connect",
        f"udp:127.0.0.1:{port}",
    ]
    cmd += ["--record-dir", str(record_dir)]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 30.0
        messages = _read_all(sock, deadline, lambda m: sum(x == "WATCHDOG=1" for x in m) >= 5)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
        messages += _read_all(sock, time.monotonic() + 1.0, lambda m: "STOPPING=1" in m)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        peer.close()
    assert proc.returncode == 0, err.decode()
    assert messages[0].startswith("READY=1")
    assert sum(m == "WATCHDOG=1" for m in messages) >= 5
    assert "STOPPING=1" in messages
    assert any(m.startswith("STATUS=") for m in messages)
    recordings = list(record_dir.glob("*.tlog"))
    assert len(recordings) == 1 and recordings[0].stat().st_size > 0  # heartbeats were recorded


UNIT = PROJECT_ROOT / "configs" / "tether-companion.service"


def _unit_settings() -> dict[str, list[str]]:
    settings: dict[str, list[str]] = {}
    for line in UNIT.read_text().splitlines():
        if "=" in line and not line.startswith(("#", "[")):
            key, _, value = line.partition("=")
            settings.setdefault(key.strip(), []).append(value.strip())
    return settings


def test_unit_file_is_a_sandboxed_notify_service() -> None:
    from tether_companion.service.config import load_service_config

    unit = _unit_settings()
    assert unit["Type"] == ["notify"] and unit["Restart"] == ["on-failure"]
    assert unit["WatchdogSec"] == ["10s"] and unit["User"] == ["tether-companion"]
    for key, value in (
        ("NoNewPrivileges", "yes"),
        ("ProtectSystem", "strict"),
        ("ProtectHome", "yes"),
        ("PrivateTmp", "yes"),
        ("CapabilityBoundingSet", ""),
        ("SupplementaryGroups", "dialout"),
    ):
        assert unit[key] == [value], key
    shipped = load_service_config(PROJECT_ROOT / "configs" / "companion.yaml")
    assert shipped.recording.directory.startswith(unit["ReadWritePaths"][0])
    assert any(shipped.link.connect.split(":")[1] in allow for allow in unit["DeviceAllow"])


@pytest.mark.skipif(
    subprocess.run(["which", "systemd-analyze"], capture_output=True).returncode != 0,
    reason="systemd-analyze is not installed on this machine",
)
def test_systemd_analyze_security_rates_the_unit_ok(tmp_path: Path) -> None:
    unit = tmp_path / "tether-companion.service"
    unit.write_text(UNIT.read_text())
    result = subprocess.run(
        ["systemd-analyze", "security", "--offline=yes", "--no-pager", str(unit)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    last = result.stdout.strip().splitlines()[-1]
    assert "Overall exposure level" in last, result.stdout + result.stderr
    exposure = float(last.split(":")[1].split()[0])
    assert exposure <= 2.0, last  # systemd calls < 2 "OK"; an unsandboxed service scores 9.6
