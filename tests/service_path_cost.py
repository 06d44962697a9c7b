"""CPU of the live service's receive path per flight-controller tick, and from an IMU message to
its VISION_POSITION_ESTIMATE (a measuring tool, not a test).

The bench's default streams (``bench latency``: RAW_IMU, ATTITUDE and SERVO_OUTPUT_RAW at
200 Hz, DISTANCE_SENSOR at 20 Hz, SYSTEM_TIME at 5 Hz; ``tests/hot_path_cost.py``'s
generator) go through what the service's read callback runs: a listening ``UdpLink`` (no
socket) takes each datagram as its readiness does, with the service's receiver and its input
frames' ``take`` (``--generic``: without, every datagram through the frame parser and
:meth:`CompanionService.handle_message`; a tree without ``take`` is measured so), the trust
gate, then :meth:`CompanionService._handle_guarded` per message or frame with the service's
``send_now`` wiring (``publish.on_unhealthy: inflate``, as the bench, so the hovering dynamic
filter publishes at 30 Hz), into a link that only counts frames. No sockets, no event loop.

Ticks are handed over ``--batch`` at a time with a sleep of ``--sleep-ms`` per tick in the
batch before each batch (as the live service sleeps between wake-ups; 0: no sleep, warm), and
the thread's CPU time (``CLOCK_THREAD_CPUTIME_ID``, so other processes' time is not counted)
is read around each batch and from the start of each published tick's RAW_IMU to its
VISION_POSITION_ESTIMATE's frame. The first fifth of the flight (start-up, the filter's
initialisation) is left out.

With ``--bytecodes N`` it counts instead, load-independently, the Python bytecodes executed
per tick over ``N`` ticks after the first fifth (``sys.settrace`` opcode events; numpy's and
other C code's instructions are not in it: callgrind counts those), by function: its own and
inclusive of what it calls, with its calls per tick.

Run: ``python tests/service_path_cost.py [--seconds 20] [--sleep-ms 0] [--batch 1]
[--repeat 2] [--generic] [--bytecodes 1000 [--top 40]]``; with ``PYTHONPATH=TREE`` to
measure another tree's code (one that has no ``send_now`` is measured without it).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections import Counter
from types import FrameType

from hot_path_cost import SOURCE, _datagrams  # type: ignore[import-not-found]

from tether_companion.mavlink.endpoints import parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.mavlink.trust import LinkTrust
from tether_companion.mavlink.udp_link import UdpLink
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for

_VPE = dialect.MAVLINK_MSG_ID_VISION_POSITION_ESTIMATE
_RAW_IMU = dialect.MAVLINK_MSG_ID_RAW_IMU


class _CountingLink:
    """The service's link, reduced to framing and the CPU time of the last estimate sent."""

    def __init__(self) -> None:
        self.encoder = FrameEncoder(1, 191)
        self.frames = 0
        self.estimate_sent_ns = 0
        self.imu_start_ns = 0

    def send_bytes(self, frame: bytes) -> None:
        self.frames += 1
        if frame[7] == _VPE:
            self.estimate_sent_ns = time.thread_time_ns()


class _BytecodeCounter:
    """Bytecodes executed by function (own, and inclusive of the functions it calls)."""

    def __init__(self) -> None:
        self.own: Counter[str] = Counter()
        self.inclusive: Counter[str] = Counter()
        self.calls: Counter[str] = Counter()

    @staticmethod
    def _name(frame: FrameType) -> str:
        code = frame.f_code
        return f"{code.co_filename.rsplit('tether_companion/', 1)[-1]}:{code.co_name}"

    def trace(self, frame: FrameType, event: str, arg: object):  # noqa: ANN205 - settrace's
        if event == "call":
            frame.f_trace_opcodes = True
            self.calls[self._name(frame)] += 1
            return self._opcode
        return None

    def _opcode(self, frame: FrameType, event: str, arg: object):  # noqa: ANN202 - settrace's
        if event == "opcode":
            self.own[self._name(frame)] += 1
            seen = set()
            caller: FrameType | None = frame
            while caller is not None:
                name = self._name(caller)
                if name not in seen:
                    seen.add(name)
                    self.inclusive[name] += 1
                caller = caller.f_back
        return self._opcode


def _receiving_link(service: CompanionService, link: _CountingLink, generic: bool) -> UdpLink:
    """A listening UDP link without a socket, wired to the service as ``_serve`` wires it
    (its receiver noting each RAW_IMU's start time on ``link``)."""
    udp = UdpLink(parse_endpoint("udpin:127.0.0.1:0", "listen"), FrameEncoder(1, 191), 64)
    udp.trust = LinkTrust(fc_ids=(1, 1))
    udp._parser.gate = udp.trust  # noqa: SLF001 - as UdpLink builds it with a trust
    handle = service._handle_guarded  # noqa: SLF001 - the read callback's call

    def receive(items: list) -> None:
        for item in items:
            if item[7] == _RAW_IMU if type(item) is bytes else item.get_type() == "RAW_IMU":
                link.imu_start_ns = time.thread_time_ns()
            handle(link, item)

    frames = getattr(service.session, "frames", None)
    take = None if generic or frames is None else frames.take
    if take is None:
        udp.set_receiver(receive)
    else:
        udp.set_receiver(receive, take)
    return udp


def _one_flight(
    seconds: float,
    sleep_s: float,
    batch: int,
    count: tuple[_BytecodeCounter, int] | None = None,
    generic: bool = False,
) -> tuple[list[int], list[float]]:
    """(IMU -> estimate CPU [ns] of each published tick, CPU per tick [ns] of each batch);
    with ``count`` = (counter, ticks) the bytecodes of that many ticks after the skipped
    start are counted instead of timed."""
    overrides = {"recording": {"enabled": False}, "publish": {"on_unhealthy": "inflate"}}
    config = load_service_config(None, overrides)
    service = CompanionService(config, load_vehicle_for(config))
    link = _CountingLink()
    wire = getattr(service, "_send_now_to", None)
    if wire is not None:
        wire(link)
    udp = _receiving_link(service, link, generic)
    ticks: dict[float, list[bytes]] = {}
    for t, data in _datagrams(200.0, seconds):
        ticks.setdefault(t, []).append(data)
    per_tick = list(ticks.values())
    skip = len(per_tick) // 5
    to_estimate: list[int] = []
    tick_cpu: list[float] = []
    for first in range(0, len(per_tick), batch):
        chunk = per_tick[first : first + batch]
        if count is not None and first in (skip, skip + count[1]):
            sys.settrace(count[0].trace if first == skip else None)
        if sleep_s:
            time.sleep(sleep_s * len(chunk))
        start = time.thread_time_ns()
        for datagrams in chunk:
            sent = link.estimate_sent_ns
            udp._deliver([m for data in datagrams for m in udp._datagram(data, SOURCE)])  # noqa: SLF001
            if first >= skip and link.estimate_sent_ns != sent:
                to_estimate.append(link.estimate_sent_ns - link.imu_start_ns)
        if first >= skip:
            tick_cpu.append((time.thread_time_ns() - start) / len(chunk))
    return to_estimate, tick_cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--sleep-ms", type=float, default=0.0)
    parser.add_argument("--batch", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--generic", action="store_true", help="no input frames' take")
    parser.add_argument("--bytecodes", type=int, default=0, help="count over this many ticks")
    parser.add_argument("--top", type=int, default=40)
    args = parser.parse_args()
    if args.bytecodes:
        counter = _BytecodeCounter()
        _one_flight(args.seconds, 0.0, 1, (counter, args.bytecodes), args.generic)
        sys.settrace(None)
        ticks = args.bytecodes
        print(f"{sum(counter.own.values()) / ticks:.0f} bytecodes per tick ({ticks} ticks)")
        for title, table in (("own", counter.own), ("inclusive", counter.inclusive)):
            print(f"--- {title}: bytecodes per tick, calls per tick, function")
            for name, n in table.most_common(args.top):
                print(f"{n / ticks:8.1f} {counter.calls[name] / ticks:6.2f} {name}")
        return
    for _ in range(args.repeat):
        to_estimate, tick_cpu = _one_flight(
            args.seconds, 1e-3 * args.sleep_ms, args.batch, generic=args.generic
        )
        deciles = statistics.quantiles(to_estimate, n=10)
        print(
            f"IMU -> estimate CPU p50 {1e-3 * statistics.median(to_estimate):6.1f} us, "
            f"p90 {1e-3 * deciles[-1]:6.1f} us ({len(to_estimate)} published ticks); "
            f"CPU per tick {1e-3 * statistics.fmean(tick_cpu):6.1f} us = "
            f"{2e-5 * statistics.fmean(tick_cpu):5.2f} % of a core at 200 Hz "
            f"(batch {args.batch}, sleep {args.sleep_ms:g} ms per tick"
            f"{', generic' if args.generic else ''})"
        )


if __name__ == "__main__":
    main()
