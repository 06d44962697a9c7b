"""Where the estimate's age goes under load: the load test's flight (``test_service_load.py``)
with the service instrumented, the age of each published estimate split into

* ``fc->service``: RAW_IMU sent by the fake flight controller to the service reading its
  datagram (the service process waking up: scheduling);
* ``read->handle``: datagram read to the message handled (the service's event loop);
* ``handle->sent``: handled to its estimate sent (the EKF, and, once the link has been seen to
  reorder, the adaptive reorder window and waiting for the newer sample that releases it);
* ``sent->fc``: sent to the fake flight controller reading it (its own scheduling).

Not a test (no ``test_`` prefix). Run from the repository root::

    python tests/age_breakdown.py [--hogs N] [--flight-s S] [--ordinary]

``--ordinary`` runs the service and the fake flight controller at ordinary priority instead
of the unit's (which needs CAP_SYS_NICE). With ``--service`` it is the instrumented service.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SEGMENTS = ("fc->service", "read->handle", "handle->sent", "sent->fc", "total")


def _instrumented_service(out_path: str, argv: list[str]) -> int:
    """Run the service CLI, recording per-IMU read and handle times, per-estimate send times
    and garbage-collector pauses [s, CLOCK_MONOTONIC] to ``out_path`` at exit."""
    import atexit
    import gc

    from tether_companion import cli
    from tether_companion.mavlink import udp_link
    from tether_companion.service import app

    read: dict[int, float] = {}
    handled: dict[int, float] = {}
    sent: dict[int, float] = {}
    pauses: list[tuple[float, float, int]] = []
    gc_start = [0.0]

    def on_gc(phase: str, info: dict) -> None:
        if phase == "start":
            gc_start[0] = time.monotonic()
        else:
            pauses.append((gc_start[0], time.monotonic() - gc_start[0], info["generation"]))

    gc.callbacks.append(on_gc)
    datagram = udp_link.UdpLink._datagram
    handle = app.CompanionService.handle_message
    send = app.CompanionService._send

    def on_datagram(self, data, addr):  # type: ignore[no-untyped-def]
        now = time.monotonic()
        messages = datagram(self, data, addr)
        for msg in messages:
            if msg.get_type() == "RAW_IMU":
                read.setdefault(msg.time_usec, now)
        return messages

    def on_handle(self, link, msg, now_s):  # type: ignore[no-untyped-def]
        if msg.get_type() == "RAW_IMU":
            handled[msg.time_usec] = time.monotonic()
        return handle(self, link, msg, now_s)

    def on_send(self, link, msg):  # type: ignore[no-untyped-def]
        send(self, link, msg)
        if msg.get_type() == "VISION_POSITION_ESTIMATE":
            sent[msg.usec] = time.monotonic()

    udp_link.UdpLink._datagram = on_datagram  # type: ignore[method-assign]
    app.CompanionService.handle_message = on_handle  # type: ignore[method-assign]
    app.CompanionService._send = on_send  # type: ignore[method-assign]

    def dump() -> None:
        times = os.times()
        Path(out_path).write_text(
            json.dumps(
                {
                    "cpu_s": times.user + times.system,
                    "read": read,
                    "handled": handled,
                    "sent": sent,
                    "gc": pauses,
                }
            )
        )

    atexit.register(dump)
    return cli.main(argv)


def _breakdown(hogs: int, flight_s: float, ordinary: bool) -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from loaded_flight import fly_hover_beside_hogs
    from unit_priority import at_unit_priority, in_own_group_at_unit_priority

    from tether_companion.service.synthetic import FakeFlightController

    tmp = Path(tempfile.mkdtemp(prefix="age-breakdown-"))
    out = tmp / "service.json"

    async def scenario() -> FakeFlightController:
        return await fly_hover_beside_hogs(
            tmp,
            (sys.executable, __file__, "--service", str(out)),
            hogs,
            flight_s,
            None if ordinary else in_own_group_at_unit_priority,
        )

    with contextlib.nullcontext() if ordinary else at_unit_priority():
        fc = asyncio.run(scenario())
    svc = json.loads(out.read_text())
    read, handled, sent = (
        {int(k): v for k, v in svc[key].items()} for key in ("read", "handled", "sent")
    )
    rows = []
    for msg in fc.log.vision:
        u = msg.usec
        if u in fc.imu_sent_s and u in read and u in handled and u in sent:
            t = (fc.imu_sent_s[u], read[u], handled[u], sent[u], fc.log.vision_arrival_s[u])
            rows.append([t[1] - t[0], t[2] - t[1], t[3] - t[2], t[4] - t[3], t[4] - t[0]])
    ages = np.array(rows[30:]) * 1e3
    print(
        f"{len(ages)} estimates, load {os.getloadavg()[0]:.1f}, hogs {hogs}, "
        f"{'ordinary' if ordinary else 'unit'} priority, service CPU {svc['cpu_s']:.1f} s"
    )
    for k, name in enumerate(SEGMENTS):
        p50, p99, p999 = np.percentile(ages[:, k], [50, 99, 99.9])
        print(
            f"  {name:13s} p50 {p50:6.1f}  p99 {p99:6.1f}  p99.9 {p999:6.1f}  "
            f"max {ages[:, k].max():6.1f} ms"
        )
    first_read = min(read.values())
    in_flight = [(d, g) for s, d, g in svc["gc"] if s > first_read]
    longest = max((d for d, _ in in_flight), default=0.0)
    print(f"  garbage collections in flight: {len(in_flight)}, longest {longest * 1e3:.1f} ms")


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--service":
        sys.exit(_instrumented_service(sys.argv[2], sys.argv[3:]))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hogs", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--flight-s", type=float, default=30.0)
    parser.add_argument("--ordinary", action="store_true")
    args = parser.parse_args()
    _breakdown(args.hogs, args.flight_s, args.ordinary)


if __name__ == "__main__":
    main()
