"""CPU per message of the service's hot path, warm and interleaved (a measuring tool, not a test).

The bench's default streams (``bench latency``: RAW_IMU at ``--imu-rate``, ATTITUDE and
SERVO_OUTPUT_RAW at 200 Hz, DISTANCE_SENSOR at 20 Hz, SYSTEM_TIME at 5 Hz) are framed once,
then run through the service's frame parser and an :class:`EstimationSession` twice, in one
process, best of ``--repeat``:

* warm: every datagram parsed first, then every message handed to the session (each stage's
  code stays in the CPU's caches);
* interleaved: datagram by datagram, parse then session, as the live service does one flight-
  controller tick at a time (the per-type costs are printed for this pass); with
  ``--sleep-ms`` the process sleeps that long after each tick, as the live service waits for
  the next one (CPU time only is counted: what sleeping costs is the caches it loses).

Run: ``python tests/hot_path_cost.py [--imu-rate 200] [--seconds 20] [--repeat 3]
[--sleep-ms 0] [--estimator four_state|three_state|dynamic]`` (default: the service's default
estimator; fix it to compare code before and after a change of default).
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

import numpy as np

from tether_companion.bench.latency import OTHER_STREAMS_HZ, RANGE_HZ
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.session import EstimationSession
from tether_companion.service.synthetic import HoverStreams

SOURCE = ("127.0.0.1", 14550)


def _datagrams(imu_hz: float, seconds: float) -> list[tuple[float, bytes]]:
    config = load_service_config(None)
    streams = HoverStreams(
        load_vehicle_for(config),
        np.array([2.0, 1.0, -3.0]),
        4.0,
        rng=np.random.default_rng(1),
        imu_hz=imu_hz,
        attitude_hz=OTHER_STREAMS_HZ,
        servo_hz=OTHER_STREAMS_HZ,
        range_hz=RANGE_HZ,
    )
    encoder = FrameEncoder(1, 1)
    out = []
    for k in range(int(seconds * imu_hz)):
        t = 5.0 + k / imu_hz
        if k % round(imu_hz / 5) == 0:
            out.append((t, encoder.encode(dialect.MAVLink_system_time_message(0, round(t * 1e3)))))
        out += [(t, encoder.encode(m)) for m in streams.messages(t, k)]
    return out


def _session(estimator: str | None) -> EstimationSession:
    overrides: dict = {"recording": {"enabled": False}}
    if estimator is not None:
        overrides["estimator"] = {"kind": estimator}
    config = load_service_config(None, overrides)
    return EstimationSession(config, load_vehicle_for(config))


def _warm(datagrams: list[tuple[float, bytes]], estimator: str | None) -> tuple[float, float]:
    parser, session = FrameParser(), _session(estimator)
    t0 = time.process_time()
    messages = [(t, m) for t, d in datagrams for m in parser.feed(d, SOURCE)]
    t1 = time.process_time()
    for t, msg in messages:
        session.on_message(msg, t - 4.0)
    return t1 - t0, time.process_time() - t1


def _interleaved(
    datagrams: list[tuple[float, bytes]], sleep_s: float, estimator: str | None
) -> dict[str, float]:
    parser, session = FrameParser(), _session(estimator)
    clock = time.thread_time
    spent: dict[str, float] = defaultdict(float)
    tick_s = datagrams[0][0]
    for t, data in datagrams:
        if sleep_s and t != tick_s:
            tick_s = t
            time.sleep(sleep_s)
        t0 = clock()
        messages = parser.feed(data, SOURCE)
        t1 = clock()
        spent["parse"] += t1 - t0
        for msg in messages:
            session.on_message(msg, t - 4.0)
            t2 = clock()
            spent[msg.get_type()] += t2 - t1
            t1 = t2
    return spent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--imu-rate", type=float, default=200.0)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--sleep-ms", type=float, default=0.0)
    parser.add_argument("--estimator", choices=("four_state", "three_state", "dynamic"))
    args = parser.parse_args()
    datagrams = _datagrams(args.imu_rate, args.seconds)
    n = len(datagrams)
    counts: dict[str, int] = defaultdict(int)
    for _, msg in ((t, m) for t, d in datagrams for m in FrameParser().feed(d, SOURCE)):
        counts[msg.get_type()] += 1
    warm = min((_warm(datagrams, args.estimator) for _ in range(args.repeat)), key=sum)
    passes = [
        _interleaved(datagrams, 1e-3 * args.sleep_ms, args.estimator) for _ in range(args.repeat)
    ]
    cold = min(passes, key=lambda spent: sum(spent.values()))
    share = 100.0 / args.seconds
    print(
        f"{n} messages in {args.seconds:g} s of flight ({n / args.seconds:.0f}/s), best of "
        f"{args.repeat}; CPU per message [us] and share of one core at real time [%]"
    )
    print(
        f"warm        parse {1e6 * warm[0] / n:6.1f} us  session {1e6 * warm[1] / n:6.1f} us"
        f"  total {share * sum(warm):5.2f} %"
    )
    interleaved = sum(cold.values())
    print(
        f"interleaved{f' + {args.sleep_ms:g} ms sleeps' if args.sleep_ms else ''} parse "
        f"{1e6 * cold['parse'] / n:6.1f} us  session "
        f"{1e6 * (interleaved - cold['parse']) / n:6.1f} us  total {share * interleaved:5.2f} %"
    )
    for kind in sorted(counts, key=lambda k: -cold[k]):
        print(f"  {kind:18s} x{counts[kind]:6d}  {1e6 * cold[kind] / counts[kind]:6.1f} us each")


if __name__ == "__main__":
    main()
