"""``bench emulator``: real-time streaming quality and the fastest emulation speed.

1. Jitter: starts ``tether-companion emulate`` (hover, real time, every default stream on) in
   a separate process and receives its UDP stream in this process with kernel receive
   timestamps (SO_TIMESTAMPNS where available). For RAW_IMU (200 Hz, 5 ms nominal) it prints
   the period's p50/p99/max and the jitter |period - 5 ms| at p50/p99/max. Target: jitter p99
   under 2 ms on an idle 2-core machine.
2. Speed: runs the emulator in this process as fast as it can (``speed = inf``) with every
   default stream built, framed and sent over UDP to a listening socket, and prints emulator
   seconds per wall second (the largest usable ``--speed``), messages per second, then checks
   a paced run at ``--speed 10`` for clock slips. Target: >= 10x.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time

import numpy as np

from tether_companion.emulator.lockstep import build_controller
from tether_companion.emulator.server import EmulatorServer
from tether_companion.mavlink.endpoints import parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.resources import PROJECT_ROOT

HELP = "Emulator: 200 Hz RAW_IMU period jitter (separate process) and the fastest --speed."

_RAW_IMU_ID = dialect.MAVLINK_MSG_ID_RAW_IMU
_SO_TIMESTAMPNS = getattr(
    socket, "SO_TIMESTAMPNS", 35 if sys.platform.startswith("linux") else None
)
"""Kernel receive timestamps in ns (Linux value 35; Python 3.11 does not export the name)."""
_NOMINAL_PERIOD_MS = 5.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Durations and output format."""
    parser.add_argument(
        "--jitter-seconds", type=float, default=20.0, help="jitter capture length [s]"
    )
    parser.add_argument(
        "--speed-seconds", type=float, default=60.0, help="emulator seconds of the speed run [s]"
    )
    parser.add_argument("--scenario", default="hover", help="scenario (default hover)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON only")


def _start_emulator(scenario: str) -> tuple[subprocess.Popen[str], int]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(PROJECT_ROOT), env.get("PYTHONPATH", "")])
    command = [sys.executable, "-m", "tether_companion.cli", "emulate", scenario]
    command += ["--listen", "udp:127.0.0.1:0", "--quiet"]
    process = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
    )
    assert process.stdout is not None
    port = None
    for line in process.stdout:
        found = re.search(r"\(bound 127\.0\.0\.1:(\d+)\)", line)
        port = int(found.group(1)) if found else port
        if "Ctrl-C to stop" in line:
            break
    if port is None:
        process.kill()
        raise RuntimeError("the emulator did not start")
    return process, port


def _stop(process: subprocess.Popen[str]) -> str:
    process.send_signal(signal.SIGTERM)
    try:
        out, _ = process.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    return out or ""


def measure_jitter(scenario: str, seconds: float) -> dict[str, float]:
    """Receive RAW_IMU from a separate emulator process; period and jitter statistics [ms]."""
    process, port = _start_emulator(scenario)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stamps_ns: list[int] = []
    kernel = _SO_TIMESTAMPNS is not None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        if kernel:
            try:
                sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
            except OSError:
                kernel = False
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(1.0)
        hello = FrameEncoder(255, 190).encode(dialect.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
        sock.sendto(hello, ("127.0.0.1", port))
        time.sleep(1.0)  # let start-up settle before measuring
        sock.setblocking(False)
        while True:  # drop the backlog queued meanwhile: its arrival times mean nothing
            try:
                sock.recv(512)
            except BlockingIOError:
                break
        sock.settimeout(1.0)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            data, ancillary, _, _ = sock.recvmsg(512, 64)
            if (
                len(data) < 10
                or data[0] != 0xFD
                or (data[7] | data[8] << 8 | data[9] << 16) != _RAW_IMU_ID
            ):
                continue
            stamp = time.monotonic_ns()
            for level, kind, payload in ancillary:
                if kernel and level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS:
                    sec, nsec = struct.unpack("qq", payload[:16])
                    stamp = sec * 1_000_000_000 + nsec
            stamps_ns.append(stamp)
    finally:
        sock.close()
        _stop(process)
    periods_ms = np.diff(np.array(stamps_ns, dtype=np.int64)) * 1e-6
    jitter_ms = np.abs(periods_ms - _NOMINAL_PERIOD_MS)
    return {
        "samples": int(periods_ms.size),
        "rate_hz": float(1e3 / periods_ms.mean()),
        "period_p50_ms": float(np.percentile(periods_ms, 50)),
        "period_p99_ms": float(np.percentile(periods_ms, 99)),
        "period_max_ms": float(periods_ms.max()),
        "jitter_p50_ms": float(np.percentile(jitter_ms, 50)),
        "jitter_p99_ms": float(np.percentile(jitter_ms, 99)),
        "jitter_max_ms": float(jitter_ms.max()),
        "kernel_timestamps": kernel,
    }


async def _timed_run(scenario: str, speed: float, emulator_seconds: float) -> dict[str, float]:
    controller = build_controller(scenario)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setblocking(False)
    try:
        async with EmulatorServer(
            controller, [parse_endpoint("udp:127.0.0.1:0", "listen")], speed=speed
        ) as server:
            hello = FrameEncoder(255, 190).encode(
                dialect.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)
            )
            sink.sendto(hello, server.local_address())
            while not server.links[0].peers:  # type: ignore[attr-defined]
                await asyncio.sleep(0.001)
            link = server.links[0]
            frames_before = link.counters.frames_out
            started = time.perf_counter()
            await server.run(emulator_seconds)
            wall_s = time.perf_counter() - started
            frames = link.counters.frames_out - frames_before
            return {
                "emulator_s": emulator_seconds,
                "wall_s": wall_s,
                "speed": emulator_seconds / wall_s,
                "messages_per_s": frames / wall_s,
                "slips": server.counters.slips,
            }
    finally:
        sink.close()


def run(args: argparse.Namespace) -> int:
    """Measure and print."""
    jitter = measure_jitter(args.scenario, args.jitter_seconds)
    fastest = asyncio.run(_timed_run(args.scenario, math.inf, args.speed_seconds))
    paced = asyncio.run(_timed_run(args.scenario, 10.0, min(args.speed_seconds, 30.0)))
    results = {"jitter": jitter, "max_speed": fastest, "speed_10x": paced}
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(
        f"RAW_IMU at 200 Hz from a separate emulator process, {jitter['samples']} periods "
        f"({'kernel' if jitter['kernel_timestamps'] else 'user-space'} receive timestamps):"
    )
    print(
        f"  rate {jitter['rate_hz']:.2f} Hz; period p50 {jitter['period_p50_ms']:.3f} ms, "
        f"p99 {jitter['period_p99_ms']:.3f} ms, max {jitter['period_max_ms']:.3f} ms"
    )
    print(
        f"  jitter |period - 5 ms|: p50 {jitter['jitter_p50_ms']:.3f} ms, "
        f"p99 {jitter['jitter_p99_ms']:.3f} ms (target < 2 ms), "
        f"max {jitter['jitter_max_ms']:.3f} ms"
    )
    print(
        f"free-running with every default stream framed and sent: {fastest['speed']:.1f}x "
        f"real time (target >= 10x), {fastest['messages_per_s']:.0f} messages/s, "
        f"{fastest['emulator_s']:.0f} emulator s in {fastest['wall_s']:.2f} s"
    )
    print(f"paced at --speed 10: {paced['speed']:.2f}x achieved, {paced['slips']} clock slips")
    return 0
