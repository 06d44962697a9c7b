"""The service beside an emulated flight controller in lock-step (no sockets, no wall clock),
and the truth to score what it sent (not collected: no ``test_`` prefix)."""

from __future__ import annotations

import heapq
import itertools

import numpy as np

from tether_companion.emulator.autopilot import FlightController
from tether_companion.emulator.faults import LinkFaults
from tether_companion.emulator.lockstep import LockstepPeer
from tether_companion.mavlink.framing import FrameEncoder, FrameParser
from tether_companion.resources import CONFIGS_DIR
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config
from tether_companion.service.systemd import SystemdNotifier


class LockstepLink:
    """The service's side of a lock-step link: frames go straight into the emulator (and,
    decoded, into ``sent`` when ``record`` is set)."""

    def __init__(
        self, peer: LockstepPeer, system_id: int, component_id: int, record: bool = False
    ) -> None:
        self.peer = peer
        self.encoder = FrameEncoder(system_id, component_id)
        self.sent: list = []
        self.boot_offsets_s: list[float] = []
        """Per message in ``sent``: emulator time minus flight-controller boot time when it was
        sent (FC stamp + offset = emulator time, across reboots)."""
        self._parser = FrameParser() if record else None

    def send_bytes(self, frame: bytes) -> None:
        self.peer.send_bytes(frame)
        if self._parser is not None:
            decoded = self._parser.feed(frame)
            self.sent.extend(decoded)
            controller = self.peer.controller
            offset = controller.time_s - controller.boot_time_s
            self.boot_offsets_s.extend([offset] * len(decoded))


class LockstepService:
    """The service (shipped configuration plus ``overrides``) beside an emulated flight
    controller, on the controller's clock: :meth:`advance` runs the emulator 5 ms, :meth:`serve`
    hands the service what arrived and runs its housekeeping every 50 ms.

    With ``link_seed`` set, the emulator's link faults (its configuration's drop, duplicate,
    corrupt, delay and jitter, as :class:`~tether_companion.emulator.server.EmulatorServer`
    applies them on UDP) act on every frame to the service: a delayed frame is handed over
    at the first :meth:`serve` at or after its arrival time, a corrupted one reaches the
    service's parser (and fails its checksum there)."""

    def __init__(
        self,
        controller: FlightController,
        overrides: dict,
        record: bool = False,
        link_seed: int | None = None,
    ) -> None:
        config = load_service_config(
            CONFIGS_DIR / "companion.yaml",
            {"link": {"connect": "udp:127.0.0.1:14550"}, "recording": {"enabled": False}}
            | overrides,
        )
        self.controller = controller
        self.peer = LockstepPeer(controller, config.link.system_id, config.link.component_id)
        self.link = LockstepLink(self.peer, config.link.system_id, config.link.component_id, record)
        self.service = CompanionService(
            config,
            controller.sim.vehicle,
            notifier=SystemdNotifier({}),
            monotonic_s=lambda: controller.time_s,
        )
        self._read = 0
        self.link_faults = (
            LinkFaults(controller.link_faults, np.random.default_rng(link_seed))
            if link_seed is not None
            else None
        )
        self._in_flight: list[tuple[float, int, bytes]] = []
        self._order = itertools.count()
        self.parser = FrameParser()
        """The service's parser of what the link faults let through (its counters)."""
        self._next_housekeeping_s = 0.0
        self._record = record
        self.truth_time_s: list[float] = []
        self.truth_position_ned_m: list[tuple[float, float, float]] = []
        """The true position after every :meth:`advance` when recording (emulator time)."""

    def advance(self) -> float:
        """Run the emulator 5 ms; returns its time [s]."""
        self.peer.advance(0.005)
        if self._record:
            self.truth_time_s.append(self.controller.time_s)
            self.truth_position_ned_m.append(tuple(self.controller.sim.position_ned_m))
        return self.controller.time_s

    def serve(self) -> None:
        """The service handles every message received so far; housekeeping when due."""
        t = self.controller.time_s
        received = self.peer.received
        faults = self.link_faults
        while self._read < len(received):
            msg = received[self._read]
            self._read += 1
            if faults is None:
                self.service.handle_message(self.link, msg, t)  # type: ignore[arg-type]
                continue
            for delay_s, frame in faults.apply(bytes(msg.get_msgbuf())):
                heapq.heappush(self._in_flight, (t + delay_s, next(self._order), frame))
        while self._in_flight and self._in_flight[0][0] <= t:
            _, _, frame = heapq.heappop(self._in_flight)
            for msg in self.parser.feed(frame) + self.parser.end_datagram():
                self.service.handle_message(self.link, msg, t)  # type: ignore[arg-type]
        if t >= self._next_housekeeping_s:
            self.service.housekeep(self.link, t)  # type: ignore[arg-type]
            self._next_housekeeping_s += 0.05


def published_errors(lockstep: LockstepService, kind: str = "VISION_POSITION_ESTIMATE") -> dict:
    """Errors of every ``kind`` message the service sent (recording on) against the truth.

    Returns a dict of arrays: ``time_s`` (emulator time of the stamp), ``error_m`` (n, 3) NED,
    ``sigma_m`` (n, 3) (square roots of the sent covariance's position diagonal) and
    ``z`` (n, 3) = |error| / sigma per axis. Estimates stamped outside the recorded truth are
    left out.
    """
    times = np.asarray(lockstep.truth_time_s)
    truth = np.asarray(lockstep.truth_position_ned_m)
    rows = []
    for msg, offset in zip(lockstep.link.sent, lockstep.link.boot_offsets_s, strict=True):
        if msg.get_type() != kind:
            continue
        stamp = (msg.usec if kind == "VISION_POSITION_ESTIMATE" else msg.time_usec) * 1e-6
        t = stamp + offset
        if not times.size or not times[0] <= t <= times[-1]:
            continue
        true = [np.interp(t, times, truth[:, k]) for k in range(3)]
        cov = msg.covariance if kind == "VISION_POSITION_ESTIMATE" else msg.pose_covariance
        position = (msg.x, msg.y, msg.z)
        error = (p - q for p, q in zip(position, true, strict=True))
        rows.append((t, *error, cov[0], cov[6], cov[11]))
    data = np.array(rows).reshape(-1, 7)
    sigma = np.sqrt(data[:, 4:7])
    return {
        "time_s": data[:, 0],
        "error_m": data[:, 1:4],
        "sigma_m": sigma,
        "z": np.abs(data[:, 1:4]) / sigma,
    }
