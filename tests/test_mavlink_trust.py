"""The trust gate: signing policy, the flight controller's pinned address, protected peers;
and a listening UDP link over real sockets whose reply table strangers cannot churn the
flight controller out of."""

from __future__ import annotations

import asyncio
import random
import socket

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder, FrameParser
from tether_companion.mavlink.signing import SignatureVerifier, Signer, timestamp_from_unix_s
from tether_companion.mavlink.trust import OFF, PREFERRED, REQUIRED, LinkTrust
from tether_companion.mavlink.udp_link import MAX_UDP_PEERS

KEY = bytes(range(1, 33))
NOW_UNIX_S = 1.75e9
FC = ("127.0.0.1", 5760)
OTHER = ("127.0.0.1", 6000)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _heartbeat(encoder: FrameEncoder) -> bytes:
    return encoder.encode(mav.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3))


def _imu(encoder: FrameEncoder, t_us: int = 1) -> bytes:
    return encoder.encode(mav.MAVLink_raw_imu_message(t_us, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0))


def _trust(signing: str, clock: Clock | None = None) -> LinkTrust:
    verifier = SignatureVerifier(KEY, clock_s=lambda: NOW_UNIX_S) if signing != OFF else None
    return LinkTrust(
        signing,
        verifier=verifier,
        fc_ids=(1, 1),
        command_sources=(255,),
        repin_silence_s=2.0,
        monotonic_s=clock or Clock(),
    )


def _signed_encoder(system_id: int = 1, component_id: int = 1, key: bytes = KEY) -> FrameEncoder:
    return FrameEncoder(system_id, component_id, Signer(key, 0, clock_s=lambda: NOW_UNIX_S))


def test_signing_required_admits_only_correctly_signed_new_frames() -> None:
    trust = _trust(REQUIRED)
    good = _imu(_signed_encoder())
    assert trust.admit(good, FC)
    assert not trust.admit(good, FC)  # replay
    assert not trust.admit(_imu(FrameEncoder(1, 1)), FC)  # unsigned
    assert not trust.admit(_imu(_signed_encoder(key=bytes(32))), FC)  # forged
    c = trust.counters
    assert (c.admitted, c.replay, c.unsigned, c.bad_signature) == (1, 1, 1, 1)
    # pymavlink's signed frames pass the gate too
    sender = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    sender.signing.secret_key, sender.signing.sign_outgoing = KEY, True
    sender.signing.timestamp = timestamp_from_unix_s(NOW_UNIX_S) + 10**6
    assert trust.admit(bytes(mav.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(sender)), FC)


def test_signing_preferred_admits_unsigned_but_not_forged() -> None:
    trust = _trust(PREFERRED)
    assert trust.admit(_imu(FrameEncoder(1, 1)), FC)
    assert not trust.admit(_imu(_signed_encoder(key=bytes(32))), FC)
    assert trust.admit(_imu(_signed_encoder()), FC)
    assert trust.counters.bad_signature == 1


def test_the_flight_controller_is_pinned_to_its_first_address() -> None:
    clock = Clock()
    trust = _trust(OFF, clock)
    fc = FrameEncoder(1, 1)
    assert trust.admit(_heartbeat(fc), FC) and trust.fc_source == FC
    # a stranger claiming to be the flight controller is refused, even its heartbeats
    for _ in range(10):
        assert not trust.admit(_imu(fc), OTHER)
        assert not trust.admit(_heartbeat(fc), OTHER)
    assert trust.counters.foreign_source == 20 and trust.fc_source == FC
    # other systems' frames are not the gate's business
    assert trust.admit(_heartbeat(FrameEncoder(255, 190)), OTHER)
    assert trust.protected(FC) and trust.protected(OTHER)  # 255 is a command source
    assert not trust.protected(("127.0.0.1", 9))
    # the real flight controller keeps talking: no move however many heartbeats the other sends
    clock.t = 1.5
    assert trust.admit(_imu(fc), FC)
    clock.t = 3.0
    assert not trust.admit(_heartbeat(fc), OTHER)
    # silent for 2 s, then three heartbeats from a new address: it moved (e.g. a new port)
    clock.t = 4.0
    assert not trust.admit(_imu(fc), OTHER)
    assert not trust.admit(_heartbeat(fc), OTHER)
    assert trust.admit(_heartbeat(fc), OTHER)
    assert trust.fc_source == OTHER and trust.counters.repins == 1
    assert any("moved" in event for event in trust.events)
    assert not trust.admit(_imu(fc), FC)


def _pin_state(trust: LinkTrust) -> tuple:
    return (
        trust.fc_source,
        trust._fc_heard_s,  # noqa: SLF001 - the state the short cut must keep
        trust._candidate,  # noqa: SLF001
        trust._candidate_heartbeats,  # noqa: SLF001
        list(trust.events),
        trust.counters.repins,
    )


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_pinned_address_short_cut_keeps_what_fc_source_ok_does(seed: int) -> None:
    """``admit``'s short cut for the pinned address's frames (no call of ``_fc_source_ok``)
    gives the same verdict and leaves the pin, its heard time, the candidate and the events as
    ``_fc_source_ok`` does, over random frames from four sources (one unknown) and clock steps
    across the repin silence."""
    rng = random.Random(seed)
    clock = Clock()
    fast, reference = _trust(OFF, clock), _trust(OFF, clock)
    fc = FrameEncoder(1, 1)
    sources = (FC, OTHER, ("127.0.0.1", 7000), None)
    for _ in range(3000):
        clock.t += rng.choice((0.0, 0.1, 0.7, 2.5))
        source = rng.choice(sources)
        heartbeat = rng.random() < 0.5
        frame = _heartbeat(fc) if heartbeat else _imu(fc)
        msg_id = mav.MAVLINK_MSG_ID_HEARTBEAT if heartbeat else mav.MAVLINK_MSG_ID_RAW_IMU
        expected = reference._fc_source_ok(source, msg_id)  # noqa: SLF001 - the reference
        assert fast.admit(frame, source) == expected
        assert _pin_state(fast) == _pin_state(reference)
    assert fast.counters.repins > 0  # the sequences move the pin


def test_frame_parser_drops_what_the_gate_refuses_before_decoding() -> None:
    trust = _trust(REQUIRED)
    parser = FrameParser(gate=trust)
    data = _imu(FrameEncoder(1, 1)) + _imu(_signed_encoder(), 7)
    (msg,) = parser.feed(data, FC)
    assert msg.time_usec == 7 and msg.get_type() == "RAW_IMU"
    assert parser.counters.untrusted == 1 and parser.counters.frames_ok == 1


@pytest.mark.integration
def test_strangers_cannot_churn_the_flight_controller_out_of_the_reply_table() -> None:
    """40 strangers on 40 ports send valid frames to a listening link with a trust gate: the
    flight controller's and the ground station's addresses stay in the reply table, so every
    message the link sends reaches them."""

    async def scenario() -> tuple[int, int, list, int]:
        trust = LinkTrust(OFF, fc_ids=(1, 1), command_sources=(255,))
        link = await open_link(
            parse_endpoint("udpin:127.0.0.1:0", "listen"),
            system_id=1,
            component_id=191,
            trust=trust,
        )
        port = link.local_address[1]
        fc = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        strangers = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(40)]
        socks = [fc, gcs, *strangers]
        try:
            for s in socks:
                s.bind(("127.0.0.1", 0))
                s.setblocking(False)
            fc_enc, gcs_enc, stranger_enc = (
                FrameEncoder(1, 1),
                FrameEncoder(255, 190),
                FrameEncoder(42, 1),
            )
            fc.sendto(_heartbeat(fc_enc), ("127.0.0.1", port))
            gcs.sendto(_heartbeat(gcs_enc), ("127.0.0.1", port))
            await asyncio.sleep(0.05)
            for _ in range(20):
                for s in strangers:
                    s.sendto(_heartbeat(stranger_enc), ("127.0.0.1", port))
                await asyncio.sleep(0.005)
            await asyncio.sleep(0.05)
            for i in range(10):
                link.send(mav.MAVLink_raw_imu_message(i, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0))
            await asyncio.sleep(0.05)
            received = []
            for s in (fc, gcs):
                n = 0
                while True:
                    try:
                        s.recvfrom(4096)
                    except BlockingIOError:
                        break
                    n += 1
                received.append(n)
            return received[0], received[1], link.peers, link.counters.peers_evicted
        finally:
            for s in socks:
                s.close()
            await link.close()

    fc_got, gcs_got, peers, evicted = asyncio.run(scenario())
    assert fc_got == 10 and gcs_got == 10
    assert len(peers) == MAX_UDP_PEERS and evicted > 0
