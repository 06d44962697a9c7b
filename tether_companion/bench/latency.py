"""``bench latency``: IMU arrival -> VISION_POSITION_ESTIMATE latency and CPU use of the service.

The service runs as its own process (``tether-companion run``, the shipped configuration) and
this process plays the flight controller over real UDP on 127.0.0.1: RAW_IMU at ``--imu-rate``
(200 Hz by default), ATTITUDE and SERVO_OUTPUT_RAW at 200 Hz and DISTANCE_SENSOR at 20 Hz of a
hovering tethered drone (the default streams of issue 12), in real time. A
VISION_POSITION_ESTIMATE carries the ``time_usec`` of the IMU sample it was computed at, so
each one is matched to the moment that RAW_IMU left here; the latency is its arrival back
here minus that send time (both loopback hops, the service's decode + EKF + encode, and this
process's own wake-up: an upper bound on the service's share). CPU is the service process's
user + system time over the measurement window from ``/proc/PID/stat``, as a share of one core.

The service runs with ``publish.on_unhealthy: inflate``: in this steady hover the dynamic
filter (the default estimator) cannot tell the thrust scale from the cable's vertical pull and
withholds its position for as long as the hover lasts; inflate sends it anyway, marked with
the inflated variance, after the same computation, so every estimator has a latency to
measure (the paper's filters are healthy in the hover and send as usual).

Floors, measured in the same run with the same datagrams and as many seconds as the service
(absolute figures on a shared machine swing 3x from run to run; the ratios are what to read):

* bare receiver (CPU and latency floor): a process that only receives the datagrams with a
  plain asyncio ``DatagramProtocol`` and answers every n-th RAW_IMU (n: IMU rate over the
  publication rate, as the service publishes) with a pre-built VISION_POSITION_ESTIMATE
  carrying its ``time_usec`` (read from the frame bytes: no framing,
  no decoding, no estimator), run for half the duration just before the service and half
  just after it, so that a load that drifts during the run moves the floor as it moves the
  service (both halves are printed; the ratio is to their time-weighted mean);
* link echo: the same answer through this project's link stack (framing, pymavlink decode
  of every message), no estimator.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from rich.console import Console
from rich.table import Table

from tether_companion.config import ConfigError
from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.mavlink.framing import dialect
from tether_companion.resources import CONFIGS_DIR, PROJECT_ROOT
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.synthetic import FakeFlightController, HoverStreams

HELP = "Latency from IMU arrival to VISION_POSITION_ESTIMATE, and service CPU at 200/400 Hz input."
WARMUP_S = 3.0
OTHER_STREAMS_HZ = 200.0
"""ATTITUDE and SERVO_OUTPUT_RAW rate [Hz] (the issue's default streams)."""
RANGE_HZ = 20.0
"""DISTANCE_SENSOR rate [Hz]."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``bench latency``."""
    parser.add_argument(
        "--duration", type=float, default=30.0, help="measured seconds (default 30)"
    )
    parser.add_argument(
        "--publish-hz",
        type=float,
        default=None,
        help="VISION_POSITION_ESTIMATE rate (default: the config's 30 Hz)",
    )
    parser.add_argument(
        "--config", default=str(CONFIGS_DIR / "companion.yaml"), help="service YAML"
    )
    parser.add_argument("--seed", type=int, default=1, help="accelerometer noise seed")
    parser.add_argument(
        "--imu-rate",
        type=float,
        default=200.0,
        help="RAW_IMU rate [Hz]: 200 (default) or a multiple of it, e.g. 400",
    )


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print the table."""
    if not args.duration > 0:
        raise ConfigError("", "--duration", args.duration, "must be > 0")
    multiple = args.imu_rate / OTHER_STREAMS_HZ
    if not (1 <= multiple <= 10 and multiple == round(multiple)):
        raise ConfigError("", "--imu-rate", args.imu_rate, "must be 200, 400, ... up to 2000 Hz")
    result = asyncio.run(_measure(args))
    _print(result, args)
    return 0


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def _measure(args: argparse.Namespace) -> dict:
    data = yaml.safe_load(Path(args.config).read_text()) or {}
    if args.publish_hz is not None:
        data.setdefault("publish", {})["rate_hz"] = args.publish_hz
    data.setdefault("publish", {})["on_unhealthy"] = "inflate"  # see the module docstring
    config = load_service_config(args.config)  # validates the file as given
    vehicle = load_vehicle_for(config)
    publish_hz = args.publish_hz if args.publish_hz is not None else config.publish.rate_hz
    every = str(max(1, round(args.imu_rate / publish_hz)))  # the floors answer as often
    trip = {"vehicle": vehicle, "seed": args.seed, "imu_hz": args.imu_rate}
    bare_command = [sys.executable, "-m", "tether_companion.bench.latency", "--bare", every]
    half_s = args.duration / 2.0
    bare_before = await _round_trip(bare_command, duration_s=half_s, **trip)
    with tempfile.TemporaryDirectory(prefix="tether-bench-") as scratch:
        config_path = Path(scratch) / "companion.yaml"
        config_path.write_text(yaml.safe_dump(data))
        service = [
            sys.executable,
            "-m",
            "tether_companion.cli",
            "run",
            "--config",
            str(config_path),
        ]
        service += ["--no-record", "--connect"]
        result = await _round_trip(service, duration_s=args.duration, **trip)
    bare_after = await _round_trip(bare_command, duration_s=half_s, **trip)
    floor = await _round_trip(
        [sys.executable, "-m", "tether_companion.bench.latency", "--echo", every],
        duration_s=args.duration,
        **trip,
    )
    result["floor_ms"] = floor["latency_ms"]
    result["floor_cpu_share"] = floor["cpu_share"]
    halves = (bare_before, bare_after)
    result["bare_ms"] = np.concatenate([half["latency_ms"] for half in halves])
    result["bare_cpu_halves"] = tuple(half["cpu_share"] for half in halves)
    result["bare_cpu_share"] = sum(h["cpu_share"] * h["wall_s"] for h in halves) / sum(
        h["wall_s"] for h in halves
    )
    return result


async def _round_trip(
    command: list[str], *, vehicle, duration_s: float, seed: int, imu_hz: float
) -> dict:
    """Play the flight controller for ``command`` + ``udp:127.0.0.1:PORT`` and time the replies."""
    fc_link = await open_link(
        parse_endpoint("udpin:127.0.0.1:0", "listen"), system_id=1, component_id=1
    )
    port = fc_link.local_address[1]
    pythonpath = os.pathsep.join(filter(None, (str(PROJECT_ROOT), os.environ.get("PYTHONPATH"))))
    peer = await asyncio.create_subprocess_exec(
        *command, f"udp:127.0.0.1:{port}",
        env=dict(os.environ, PYTHONPATH=pythonpath),
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        streams = HoverStreams(
            vehicle,
            np.array([2.0, 1.0, -3.0]),
            4.0,
            rng=np.random.default_rng(seed),
            imu_hz=imu_hz,
            attitude_hz=OTHER_STREAMS_HZ,
            servo_hz=OTHER_STREAMS_HZ,
            range_hz=RANGE_HZ,
        )
        fc = FakeFlightController(fc_link, streams, speed=1.0)
        await fc.run(WARMUP_S)
        cpu0, wall0, first_usec = _cpu_seconds(peer.pid), time.monotonic(), int(fc.time_s * 1e6)
        await fc.run(duration_s)
        cpu1, wall1 = _cpu_seconds(peer.pid), time.monotonic()
    finally:
        peer.terminate()
        _, err = await peer.communicate()
        await fc_link.close()
    latencies = [
        arrival - fc.imu_sent_s[usec]
        for usec, arrival in fc.log.vision_arrival_s.items()
        if usec >= first_usec and usec in fc.imu_sent_s
    ]
    return {
        "latency_ms": np.array(latencies) * 1e3,
        "imu_sent": sum(1 for usec in fc.imu_sent_s if usec >= first_usec),
        "cpu_share": (cpu1 - cpu0) / (wall1 - wall0),
        "wall_s": wall1 - wall0,
        "rate_hz": len(latencies) / (wall1 - wall0),
        "service_err": err.decode(errors="replace")[-500:],
    }


async def _echo(endpoint: str, every: int) -> None:
    """The link-stack peer: answer every ``every``-th RAW_IMU at once with a
    VISION_POSITION_ESTIMATE (no decoding to SI, no EKF), as a process of its own like the
    service."""
    link = await open_link(parse_endpoint(endpoint, "connect"), system_id=1, component_id=191)
    link.send(dialect.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
    link.send(
        dialect.MAVLink_command_long_message(
            1, 1, dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 27.0, 5000.0, 0, 0, 0, 0, 0
        )
    )
    count = 0
    zeros = [0.0] * 21
    while True:
        msg = await link.recv()
        if msg.get_type() == "RAW_IMU":
            count += 1
            if count % every == 0:
                link.send(
                    dialect.MAVLink_vision_position_estimate_message(
                        msg.time_usec, 0, 0, 0, 0, 0, 0, zeros, 0
                    )
                )


class _BareEcho(asyncio.DatagramProtocol):
    """The floor: receive datagrams, answer every ``every``-th RAW_IMU with a pre-built
    estimate."""

    def __init__(self, every: int) -> None:
        self.transport: asyncio.DatagramTransport | None = None
        self.count = 0
        self.every = every
        self.encoder = dialect.MAVLink(None, srcSystem=1, srcComponent=191)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        heartbeat = dialect.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)
        self.transport.sendto(heartbeat.pack(self.encoder))
        start_streams = dialect.MAVLink_command_long_message(
            1, 1, dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 27.0, 5000.0, 0, 0, 0, 0, 0
        )  # the flight controller streams once asked, as for the service
        self.transport.sendto(start_streams.pack(self.encoder))

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        # a MAVLink 2 RAW_IMU (id 27) starts its payload with time_usec (uint64) at byte 10
        if len(data) >= 18 and data[0] == 0xFD and data[7] == 27 and data[8] == 0:
            self.count += 1
            if self.count % self.every == 0:
                time_usec = int.from_bytes(data[10:18], "little")
                reply = dialect.MAVLink_vision_position_estimate_message(
                    time_usec, 0, 0, 0, 0, 0, 0, _ZEROS, 0
                )
                assert self.transport is not None
                self.transport.sendto(reply.pack(self.encoder))


_ZEROS = [0.0] * 21


async def _bare(endpoint: str, every: int) -> None:
    """Run :class:`_BareEcho` against ``udp:HOST:PORT`` until killed."""
    host, port = endpoint.split(":")[1:]
    loop = asyncio.get_running_loop()
    await loop.create_datagram_endpoint(lambda: _BareEcho(every), remote_addr=(host, int(port)))
    await asyncio.Event().wait()


def _print(result: dict, args: argparse.Namespace) -> None:
    console = Console()
    lat = result["latency_ms"]
    table = Table(
        title=f"service latency and CPU ({args.imu_rate:g} Hz IMU, attitude and servo "
        f"{OTHER_STREAMS_HZ:g} Hz, range {RANGE_HZ:g} Hz over UDP loopback, real time)"
    )
    for column in ("measure", "value", "target"):
        table.add_column(column)
    table.add_row("IMU messages sent (measured window)", f"{result['imu_sent']}", "")
    table.add_row(
        "VISION_POSITION_ESTIMATE received", f"{lat.size} ({result['rate_hz']:.1f} Hz)", ""
    )
    if lat.size:
        p50, p90, p99 = np.percentile(lat, [50, 90, 99])
        table.add_row("latency p50 (IMU sent -> estimate back)", f"{p50:.3f} ms", "")
        table.add_row("latency p90", f"{p90:.3f} ms", "")
        table.add_row("latency p99", f"{p99:.3f} ms", "")
        table.add_row("latency max", f"{lat.max():.3f} ms", "")
    bare, floor = result["bare_ms"], result["floor_ms"]
    if bare.size:
        b50, b99 = np.percentile(bare, [50, 99])
        table.add_row(
            "floor: bare asyncio UDP echo p50 / p99",
            f"{b50:.3f} / {b99:.3f} ms ({bare.size} replies)",
            "",
        )
        if lat.size:
            extra = np.percentile(lat, 99) - b99
            table.add_row("service p99 - bare echo p99", f"{extra:.3f} ms", "<= 0.3 ms")
    if floor.size:
        f50, f99 = np.percentile(floor, [50, 99])
        table.add_row(
            "peer: link-stack echo p50 / p99",
            f"{f50:.3f} / {f99:.3f} ms ({floor.size} replies)",
            "",
        )
    cpu, bare_cpu = result["cpu_share"], result["bare_cpu_share"]
    cpu_target = "<= 5 %" if args.imu_rate <= OTHER_STREAMS_HZ else "<= 10 %"
    table.add_row("service CPU (user + system)", f"{100 * cpu:.1f} % of one core", cpu_target)
    before, after = result["bare_cpu_halves"]
    table.add_row(
        "floor: bare receiver CPU (before / after the service)",
        f"{100 * bare_cpu:.1f} % of one core ({100 * before:.1f} / {100 * after:.1f})",
        "",
    )
    table.add_row(
        "peer: link-stack echo CPU", f"{100 * result['floor_cpu_share']:.1f} % of one core", ""
    )
    table.add_row(
        "service CPU / bare receiver CPU",
        f"{cpu / bare_cpu:.1f}x" if bare_cpu > 0 else "n/a",
        "<= 3x",
    )
    table.add_row("measured window", f"{result['wall_s']:.1f} s after {WARMUP_S:g} s warm-up", "")
    load = os.getloadavg()[0]
    table.add_row("machine load average (1 min) / cores", f"{load:.1f} / {os.cpu_count()}", "")
    console.print(table)
    if not lat.size:
        console.print(f"[red]no estimates came back[/red]; service stderr: {result['service_err']}")


if __name__ == "__main__":
    # the floors' peers: python -m tether_companion.bench.latency --bare|--echo EVERY ENDPOINT
    peer = _bare if sys.argv[1] == "--bare" else _echo
    asyncio.run(peer(sys.argv[3], int(sys.argv[2])))
