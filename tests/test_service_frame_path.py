"""The live UDP link's input frames straight to samples (issue 12) against the generic path.

A listening :class:`UdpLink` whose receiver brings a ``take`` (the session's
``FrameIngest.take``) delivers the flight controller's intact unsigned input frames as bytes,
after its trust gate, and the service turns them into samples without a message object
(:meth:`CompanionService.handle_frame`). Property: fed the same datagrams, from the same
addresses at the same times, a service on that path and one on the generic path (parser,
message, :meth:`CompanionService.handle_message`) send the same frames, record the same
publications and count the same (framing, trust, ingest, service state), on a hover with
hostile datagrams mixed in: the flight controller's frames from a stranger's address, cut and
bit-flipped frames, duplicates, MAVLink 1, another IMU message, a stranger's commands.
"""

from __future__ import annotations

import numpy as np
import pytest
from hot_path_cost import SOURCE, _datagrams  # type: ignore[import-not-found]

from tether_companion.mavlink.endpoints import parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.mavlink.trust import LinkTrust
from tether_companion.mavlink.udp_link import UdpLink
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.ingest_frames import FrameIngest
from tether_companion.service.mode_command import TENSION_MODE_COMMAND

STRANGER = ("127.0.0.1", 40001)


class _Clock:
    now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


class _RecordingLink(UdpLink):
    """A listening UDP link without a socket: datagrams are handed in, frames sent recorded."""

    def __init__(self, trust: LinkTrust) -> None:
        super().__init__(
            parse_endpoint("udpin:127.0.0.1:0", "listen"), FrameEncoder(1, 191), 64, trust
        )
        self.sent: list[tuple[tuple[str, int], bytes]] = []

    def receive(self, data: bytes, addr: tuple[str, int]) -> None:
        """What a readiness of the socket does with one datagram."""
        self._deliver(self._datagram(data, addr))

    def _write(self, frame: bytes) -> int:
        self.sent += [(addr, frame) for addr in self._peers]
        return len(self._peers)


class _Service:
    """A service fed datagrams through a recording link, on the frame path or not."""

    def __init__(self, frame_path: bool) -> None:
        overrides = {"recording": {"enabled": False}, "publish": {"on_unhealthy": "inflate"}}
        config = load_service_config(None, overrides)
        self.clock = _Clock()
        self.service = CompanionService(config, load_vehicle_for(config), monotonic_s=self.clock)
        self.publications: list = []
        self.service._on_publication = self.publications.append  # noqa: SLF001
        self.link = _RecordingLink(LinkTrust(fc_ids=(1, 1), monotonic_s=self.clock))
        self.service._send_now_to(self.link)  # noqa: SLF001 - as _serve wires it
        service, link = self.service, self.link

        def receive(items: list) -> None:
            for item in items:
                service._handle_guarded(link, item)  # noqa: SLF001 - _serve's receiver
            self.kinds += [type(item) for item in items]

        self.kinds: list[type] = []
        take = service.session.frames.take if frame_path else None
        self.link.set_receiver(receive, take)

    def feed(self, data: bytes, addr: tuple[str, int], now_s: float) -> None:
        self.clock.now_s = now_s
        self.link.receive(data, addr)

    def outcome(self) -> dict:
        service, link = self.service, self.link
        session = service.session
        return {
            "sent": link.sent,
            "publications": self.publications,
            "framing": link.framing.as_dict(),
            "trust": link.trust.counters.as_dict(),
            "ingest": session.ingest.counters,
            "publisher": session.publisher.counters,
            "received": service.state.received,
            "handler_errors": service.state.handler_errors,
            "peers": link.peers,
        }


def _hostile_feed(seconds: float) -> list[tuple[float, bytes, tuple[str, int]]]:
    """The bench's hover datagrams from the flight controller, with hostile ones mixed in."""
    rng = np.random.default_rng(7)
    feed: list[tuple[float, bytes, tuple[str, int]]] = []
    stranger = FrameEncoder(200, 1)
    for k, (t, data) in enumerate(_datagrams(200.0, seconds)):
        local = t - 4.0
        feed.append((local, data, SOURCE))
        if k % 97 == 5:  # the flight controller's frame from a stranger's address
            feed.append((local, data, STRANGER))
        if k % 89 == 3:  # the same frame again: a duplicate (or a replay)
            feed.append((local, data, SOURCE))
        if k % 53 == 7:  # a bit flipped (bad checksum) or the frame cut short
            bad = bytearray(data)
            if k % 2:
                bad[int(rng.integers(1, len(bad)))] ^= 1 << int(rng.integers(0, 8))
            else:
                bad = bad[: int(rng.integers(1, len(bad)))]
            feed.append((local, bytes(bad), SOURCE))
        if k % 211 == 11:  # a stranger's mode command, a MAVLink 1 IMU frame, another IMU
            command = dialect.MAVLink_command_long_message(
                1, 191, TENSION_MODE_COMMAND, 0, 1, 0, 0, 0, 0, 0, 0
            )
            feed.append((local, stranger.encode(command), STRANGER))
            imu = dialect.MAVLink_raw_imu_message(int(t * 1e6), 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0)
            v1 = imu.pack(dialect.MAVLink(None, 1, 1), force_mavlink1=True)
            feed.append((local, bytes(v1), SOURCE))
            scaled = dialect.MAVLink_scaled_imu2_message(
                int(t * 1e3), 0, 0, -1000, 0, 0, 0, 0, 0, 0
            )
            feed.append((local, FrameEncoder(1, 1).encode(scaled), SOURCE))
    return feed


def _mavlink1(data: bytes) -> bool:
    return data[0] == dialect.PROTOCOL_MARKER_V1


@pytest.mark.parametrize("seconds", [6.0])
def test_frame_path_sends_and_counts_what_the_message_path_does(seconds: float) -> None:
    fast, generic = _Service(frame_path=True), _Service(frame_path=False)
    for local, data, addr in _hostile_feed(seconds):
        fast.feed(data, addr, local)
        generic.feed(data, addr, local)
    assert fast.outcome() == generic.outcome()
    assert bytes in fast.kinds and bytes not in generic.kinds  # the frame path was taken
    assert fast.link.trust.counters.foreign_source > 0  # and the gate refused on it
    assert len(fast.publications) > 100
    assert fast.service.state.handler_errors == 0


def test_take_accepts_only_intact_unsigned_input_frames_from_the_flight_controller() -> None:
    config = load_service_config(None, {"recording": {"enabled": False}})
    session_frames = CompanionService(config, load_vehicle_for(config)).session.frames
    assert isinstance(session_frames, FrameIngest)
    take = session_frames.take
    imu = dialect.MAVLink_raw_imu_message(5_000_000, 1, 2, -1000, 3, 4, 5, 6, 7, 8, 9, 10)
    frame = FrameEncoder(1, 1).encode(imu)
    assert take(frame)
    assert not take(FrameEncoder(2, 1).encode(imu))  # another system
    assert not take(FrameEncoder(1, 2).encode(imu))  # another component
    assert not take(bytes(imu.pack(dialect.MAVLink(None, 1, 1), force_mavlink1=True)))
    assert not take(frame[:-1]) and not take(frame + b"\0")  # cut, or more than one frame
    flipped = bytearray(frame)
    flipped[12] ^= 4
    assert not take(bytes(flipped))  # bad checksum
    signed = bytearray(frame)
    signed[2] = dialect.MAVLINK_IFLAG_SIGNED
    assert not take(bytes(signed))  # signed (or any incompatibility flag): the generic path
    heartbeat = FrameEncoder(1, 1).encode(dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3))
    assert not take(heartbeat)  # not an input stream
