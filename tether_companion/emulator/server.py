"""The emulator on the wire: a :class:`FlightController` served over MAVLink links in real time.

:class:`EmulatorServer` opens every endpoint, feeds received messages to the flight controller
and sends what it produces, through the link-fault injector. Time runs at ``speed`` times the
wall clock; if the machine cannot keep up, emulator time slips rather than bunching messages
or skipping physics (``counters.slips``), so every timestamp and rate stays right in emulator
time. ``speed = inf`` runs as fast as the machine allows (benchmarks).

Use as an async context manager::

    async with EmulatorServer(controller, [parse_endpoint("udp:127.0.0.1:0", "listen")]) as emu:
        await emu.run(duration_s=10.0)
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import struct
import time
from dataclasses import dataclass

import numpy as np

from tether_companion.emulator.autopilot import FlightController
from tether_companion.emulator.faults import LinkFaults
from tether_companion.mavlink.endpoints import Endpoint, open_link
from tether_companion.mavlink.link import Link, LinkClosed

MAX_LAG_S = 0.1
"""Emulator time may fall this far behind the wall clock (x speed) before it slips [s]."""
MAX_ADVANCE_S = 0.05
"""Longest single advance of emulator time between looks at the network [s]."""
FINE_WAIT_S = 0.0015
"""The last part of each wait is a blocking high-resolution sleep instead of an event-loop
timer [s]: the loop's timers wake up to 1 ms late (epoll's millisecond timeout is rounded
up), which alone would put 1 ms of jitter on a 200 Hz stream. Spinning instead burns CPU and
gets the process preempted on a loaded machine, which is worse."""


@dataclass
class ServerCounters:
    """Real-time health of the server."""

    slips: int = 0
    """Times emulator time was re-anchored because the machine fell behind."""
    encode_errors: int = 0
    """Messages that could not be framed (a field out of its wire range): not sent."""
    handler_errors: int = 0
    """Received messages whose handling raised an unexpected error (dropped; should stay 0)."""
    sleeps: int = 0


class EmulatorServer:
    """Serves a :class:`FlightController` on one or more endpoints (see module docstring).

    Parameters
    ----------
    controller
        The flight controller (its config gives the MAVLink identity).
    endpoints
        Where to listen or connect; each becomes a link with its own stream rates.
    speed
        Emulator seconds per wall-clock second (``inf``: as fast as possible).
    fault_rng
        Generator for link faults (default: seeded from the scenario's seed + 1).
    """

    def __init__(
        self,
        controller: FlightController,
        endpoints: list[Endpoint],
        *,
        speed: float = 1.0,
        fault_rng: np.random.Generator | None = None,
    ) -> None:
        if not (speed > 0.0):
            raise ValueError(f"speed must be > 0, got {speed!r}")
        self.controller = controller
        self.endpoints = list(endpoints)
        self.speed = speed
        self.counters = ServerCounters()
        rng = fault_rng or np.random.default_rng(controller.scenario.seed + 1)
        self.faults = LinkFaults(controller.link_faults, rng)
        self.links: dict[int, Link] = {}
        self._tasks: list[asyncio.Task[None]] = []
        self._stop = asyncio.Event()
        self._wall0 = 0.0
        self._sim0 = 0.0
        self._anchored = False

    async def __aenter__(self) -> EmulatorServer:
        config = self.controller.config
        try:
            for endpoint in self.endpoints:
                link = await open_link(
                    endpoint, system_id=config.system_id, component_id=config.component_id
                )
                link_id = self.controller.add_link()
                self.links[link_id] = link
                self._tasks.append(
                    asyncio.create_task(
                        self._receive(link_id, link), name=f"emulator-rx {endpoint}"
                    )
                )
        except BaseException:
            await self.close()
            raise
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def close(self) -> None:
        """Stop, close every link and wait for the receive tasks. Idempotent."""
        self._stop.set()
        for link in self.links.values():
            await link.close()
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks.clear()

    def stop(self) -> None:
        """Ask :meth:`run` to return (safe from signal handlers)."""
        self._stop.set()

    def local_address(self, index: int = 0) -> tuple[str, int] | None:
        """Bound address of the ``index``-th endpoint (for port 0)."""
        return list(self.links.values())[index].local_address

    # ------------------------------------------------------------------ receive
    async def _receive(self, link_id: int, link: Link) -> None:
        controller = self.controller
        try:
            while True:
                msg = await link.recv()
                try:
                    controller.handle(msg, link_id)
                except Exception:  # noqa: BLE001 - one bad message must not stop the link
                    self.counters.handler_errors += 1
                self._flush()
        except LinkClosed:
            return

    # ------------------------------------------------------------------ send
    def _flush(self) -> None:
        outgoing = self.controller.drain()
        if not outgoing:
            return
        loop = asyncio.get_running_loop()
        links = self.links
        apply = self.faults.apply
        late_s = self._late_s()
        for link_id, msg in outgoing:
            targets = links.values() if link_id is None else (links[link_id],)
            for link in targets:
                try:
                    frame = msg if isinstance(msg, bytes) else link.encoder.encode(msg)
                except (struct.error, ValueError, TypeError):
                    self.counters.encode_errors += 1
                    continue
                for delay_s, data in apply(frame):
                    if delay_s > late_s:
                        wall_delay_s = (delay_s - late_s) / self.speed  # 0 at infinite speed
                        loop.call_later(wall_delay_s, link.send_bytes, data)
                    else:
                        link.send_bytes(data)

    # ------------------------------------------------------------------ time
    def _late_s(self) -> float:
        """How far [s, emulator time] the emulator is behind the wall clock: what it sends now
        should have gone out this long ago, so a link delay counts from then. A stalled
        emulator catching up then does not reorder its burst by more than the jitter (each
        frame would leave at its own time plus its delay; without this, a burst spanning
        100 ms of stamps, all delayed from the same instant, arrived shuffled)."""
        if not self._anchored or math.isinf(self.speed):
            return 0.0
        return max(0.0, self._target_time_s() - self.controller.time_s)

    def _anchor(self) -> None:
        self._wall0 = time.monotonic()
        self._sim0 = self.controller.time_s
        self._anchored = True

    def _target_time_s(self) -> float:
        return self._sim0 + (time.monotonic() - self._wall0) * self.speed

    async def run(self, duration_s: float | None = None) -> None:
        """Run until ``duration_s`` of emulator time have passed (None: until :meth:`stop`)."""
        controller = self.controller
        end_s = math.inf if duration_s is None else controller.time_s + duration_s
        free_running = math.isinf(self.speed)
        self._anchor()
        while not self._stop.is_set() and controller.time_s < end_s - 1e-9:
            now_s = controller.time_s
            step_s = controller.sim.physics_dt_s
            next_s = min(
                max(controller.next_event_s(), now_s + step_s), now_s + MAX_ADVANCE_S, end_s
            )
            if free_running:
                await asyncio.sleep(0)
            else:
                wait_s = (next_s - self._target_time_s()) / self.speed
                if wait_s > 0.0:
                    self.counters.sleeps += 1
                    deadline = time.monotonic() + wait_s
                    # always yield once, so sockets are read even when every wait is short
                    await asyncio.sleep(max(wait_s - FINE_WAIT_S, 0.0))
                    remaining = deadline - time.monotonic()
                    if remaining > 0.0:
                        time.sleep(remaining)  # high-resolution timer, unlike the loop's
                else:
                    if -wait_s * self.speed > MAX_LAG_S:
                        self.counters.slips += 1
                        self._sim0 = controller.time_s
                        self._wall0 = time.monotonic()
                    await asyncio.sleep(0)
            controller.advance_to(next_s)
            self._flush()
