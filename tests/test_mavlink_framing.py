"""MAVLink framing: round trips, resynchronisation and counting of every kind of bad input."""

from __future__ import annotations

import random
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tether_companion.mavlink import framing
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect

INT16 = st.integers(-32768, 32767)


def heartbeat(custom_mode: int = 0) -> dialect.MAVLink_message:
    return dialect.MAVLink_heartbeat_message(2, 3, 0, custom_mode, 4, 3)


def raw_imu(time_usec: int = 1234567, xacc: int = -12) -> dialect.MAVLink_message:
    return dialect.MAVLink_raw_imu_message(time_usec, xacc, 2, -1000, 4, -5, 6, 0, 0, 0, 0, 0)


def frames(n: int, encoder: FrameEncoder | None = None) -> list[bytes]:
    encoder = encoder or FrameEncoder(1, 1)
    return [encoder.encode(raw_imu(time_usec=i)) for i in range(n)]


def test_round_trip_keeps_fields_and_identity() -> None:
    encoder = FrameEncoder(system_id=7, component_id=42)
    parser = FrameParser()
    (msg,) = parser.feed(encoder.encode(raw_imu()))
    assert msg.get_type() == "RAW_IMU"
    assert (msg.get_srcSystem(), msg.get_srcComponent()) == (7, 42)
    assert (msg.time_usec, msg.xacc, msg.zacc, msg.ygyro) == (1234567, -12, -1000, -5)
    assert parser.counters.frames_ok == 1 and parser.counters.errors == 0


def test_byte_by_byte_equals_all_at_once() -> None:
    data = b"".join(frames(20))
    one = FrameParser().feed(data)
    parser = FrameParser()
    split = [m for i in range(len(data)) for m in parser.feed(data[i : i + 1])]
    assert [m.time_usec for m in split] == [m.time_usec for m in one] == list(range(20))
    assert parser.pending_bytes == 0


def test_sequence_number_counts_and_wraps() -> None:
    encoder = FrameEncoder(1, 1)
    parser = FrameParser()
    seqs = [parser.feed(encoder.encode(heartbeat()))[0].get_seq() for _ in range(300)]
    assert seqs[:3] == [0, 1, 2] and seqs[255] == 255 and seqs[256] == 0


def test_garbage_between_frames_is_skipped_and_counted() -> None:
    a, b = frames(2)
    garbage = bytes([0x00, 0x11, 0x55, 0xAA]) * 5
    parser = FrameParser()
    msgs = parser.feed(garbage + a + garbage + b)
    assert [m.time_usec for m in msgs] == [0, 1]
    assert parser.counters.garbage_bytes == 2 * len(garbage)


def test_bad_crc_resynchronises_on_the_next_byte() -> None:
    a, b = frames(2)
    broken = bytearray(a)
    broken[12] ^= 0xFF  # a payload byte
    parser = FrameParser()
    msgs = parser.feed(bytes(broken) + b)
    assert [m.time_usec for m in msgs] == [1]
    assert parser.counters.bad_crc == 1


def test_false_start_marker_does_not_swallow_the_following_frame() -> None:
    # 0xFD claiming a long known payload, right before a good frame: the good frame survives
    (good,) = frames(1)
    fake = bytes([0xFD, 200, 0, 0, 0, 1, 1, 27, 0, 0])
    parser = FrameParser()
    msgs = parser.feed(fake + good + bytes(250))
    assert [m.get_type() for m in msgs] == ["RAW_IMU"]
    assert parser.counters.bad_header == 1  # RAW_IMU is never 200 bytes long


def test_unknown_message_id_is_skipped_whole_and_counted() -> None:
    payload = b"\x01\x02\x03"
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, 0, 1, 1, 0xCDEF, 0xAB)
    unknown = header + payload + b"\x00\x00"
    (good,) = frames(1)
    parser = FrameParser()
    msgs = parser.feed(unknown + good)
    assert [m.get_type() for m in msgs] == ["RAW_IMU"]
    assert parser.counters.unknown_id == 1


def test_unsupported_incompat_flags_are_a_bad_header() -> None:
    (good,) = frames(1)
    bad = bytearray(good)
    bad[2] = 0x02
    parser = FrameParser()
    assert parser.feed(bytes(bad) + good)[0].get_type() == "RAW_IMU"
    assert parser.counters.bad_header == 1


def test_truncated_datagram_is_dropped_not_joined_to_the_next() -> None:
    a, b = frames(2)
    parser = FrameParser()
    assert parser.feed(a[:-3]) == []
    parser.end_datagram()
    assert [m.time_usec for m in parser.feed(b)] == [1]
    parser.end_datagram()
    assert parser.counters.truncated == 1


def test_mavlink1_and_signed_frames_are_accepted() -> None:
    packer = dialect.MAVLink(None, srcSystem=3, srcComponent=1)
    v1 = heartbeat(5).pack(packer, force_mavlink1=True)
    signer = dialect.MAVLink(None, srcSystem=3, srcComponent=1)
    signer.signing.secret_key = bytes(32)
    signer.signing.sign_outgoing = True
    signed = heartbeat(6).pack(signer)
    assert v1[0] == 0xFE and signed[2] & 0x01
    msgs = FrameParser().feed(v1 + signed)
    assert [m.custom_mode for m in msgs] == [5, 6]


def test_encoder_refuses_bad_identity_and_out_of_range_fields() -> None:
    with pytest.raises(ValueError):
        FrameEncoder(0, 1)
    with pytest.raises(struct.error):
        FrameEncoder(1, 1).encode(raw_imu(xacc=40000))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=2000))
def test_random_bytes_never_raise(data: bytes) -> None:
    parser = FrameParser()
    for i in range(0, len(data), 97):
        parser.feed(data[i : i + 97])
    counters = parser.counters.as_dict()
    assert all(v >= 0 for v in counters.values())
    assert counters["bytes_in"] == len(data)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 2**40), INT16, st.binary(max_size=40)), min_size=1, max_size=10
    )
)
def test_frames_survive_marker_free_garbage(items: list[tuple[int, int, bytes]]) -> None:
    encoder = FrameEncoder(1, 1)
    data = b""
    for time_usec, xacc, junk in items:
        junk = junk.replace(b"\xfd", b"\x00").replace(b"\xfe", b"\x00")
        data += junk + encoder.encode(raw_imu(time_usec, xacc))
    msgs = FrameParser().feed(data)
    assert [(m.time_usec, m.xacc) for m in msgs] == [(t, x) for t, x, _ in items]


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_single_corrupted_byte_in_a_datagram_loses_only_that_frame(data: st.DataObject) -> None:
    encoded = frames(5)
    victim = data.draw(st.integers(0, 4))
    offset = data.draw(st.integers(0, len(encoded[victim]) - 1))
    flip = data.draw(st.integers(1, 255))
    broken = bytearray(encoded[victim])
    broken[offset] ^= flip
    encoded[victim] = bytes(broken)
    parser = FrameParser()
    msgs = parser.feed(b"".join(encoded))
    msgs += parser.end_datagram()  # a stray marker may have held back the frames behind it
    times = [m.time_usec for m in msgs]
    assert [t for t in times if t != victim] == [t for t in range(5) if t != victim]
    assert set(times) <= set(range(5))  # never a wrong frame


def test_stray_marker_with_an_impossible_length_is_rejected_at_once() -> None:
    (good,) = frames(1)
    stray = bytes([0xFD, 250, 0, 0, 0, 1, 1, 0, 0, 0])  # HEARTBEAT (id 0) is 9 bytes at most
    parser = FrameParser()
    assert [m.get_type() for m in parser.feed(stray + good)] == ["RAW_IMU"]
    assert parser.counters.bad_header == 1 and parser.pending_bytes == 0


def test_end_of_datagram_recovers_frames_behind_a_stray_marker() -> None:
    (good,) = frames(1)
    stray = bytes([0xFD, 60, 0, 0, 0, 1, 1, 105, 0, 0])  # claims a 72-byte HIGHRES_IMU frame
    parser = FrameParser()
    assert parser.feed(stray + good) == []  # waiting for the rest of the claimed frame
    assert [m.get_type() for m in parser.end_datagram()] == ["RAW_IMU"]
    assert parser.counters.truncated == 1 and parser.pending_bytes == 0


def _crc_mcrf4xx(data: bytes) -> int:
    """CRC-16/MCRF4XX bit by bit (poly 0x1021 reflected, init 0xFFFF): the test's reference."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


def test_checksum_matches_a_bitwise_crc_16_mcrf4xx() -> None:
    rng = random.Random(3)
    for n in range(300):
        covered, extra = bytes(rng.randrange(256) for _ in range(n)), bytes((n % 256,))
        assert framing._checksum(covered, extra) == _crc_mcrf4xx(covered + extra)


class _RefusingGate:
    """A gate that refuses frames whose sequence number is odd, and records what it saw."""

    def __init__(self) -> None:
        self.seen: list[bytes] = []

    def admit(self, frame: bytes | bytearray, source: object) -> bool:
        self.seen.append(bytes(frame))
        return frame[4] % 2 == 0


def _by_bytes(parser: FrameParser) -> FrameParser:
    """``parser`` with its one-frame datagram path turned off (every datagram parsed in the
    buffer, byte by byte where needed)."""
    parser._whole_frame = lambda data, n: None  # type: ignore[method-assign]  # noqa: SLF001
    return parser


def _outcome(parser: FrameParser, datagrams: list[bytes]) -> tuple:
    gate = parser.gate
    out = []
    for data in datagrams:
        out += [(type(m).__name__, bytes(m.get_msgbuf()), m.get_seq()) for m in parser.feed(data)]
        out += [(type(m).__name__, bytes(m.get_msgbuf())) for m in parser.end_datagram()]
    seen = None if gate is None else gate.seen
    return out, parser.counters.as_dict(), seen


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_a_one_frame_datagram_gives_what_the_byte_path_gives(data: st.DataObject) -> None:
    """The whole-frame short cut (an intact MAVLink 2 frame per datagram) returns the same
    messages, counts the same and offers the gate the same frames as the buffer's path, on
    intact, mutated, truncated, extended, MAVLink 1, signed-flagged and unknown-id frames."""
    encoder = FrameEncoder(1, 1)
    messages = [
        raw_imu(i, -i)
        if i % 3
        else heartbeat(i)
        if i % 2
        else dialect.MAVLink_attitude_message(i, 0.1, -0.2, 0.3, 0.0, 0.0, 0.0)
        for i in range(8)
    ]
    datagrams = []
    for msg in messages:
        frame = bytearray(encoder.encode(msg))
        kind = data.draw(st.integers(0, 7))
        if kind == 1:  # one byte flipped
            frame[data.draw(st.integers(0, len(frame) - 1))] ^= data.draw(st.integers(1, 255))
        elif kind == 2:  # cut
            frame = frame[: data.draw(st.integers(0, len(frame) - 1))]
        elif kind == 3:  # junk after it
            frame += data.draw(st.binary(min_size=1, max_size=20))
        elif kind == 4:  # the signed flag and a fake signature
            frame[2] = dialect.MAVLINK_IFLAG_SIGNED
            frame += data.draw(st.binary(min_size=13, max_size=13))
        elif kind == 5:  # an id the dialect does not know
            frame[7:10] = bytes((0xFF, 0xFF, 0x00))
        elif kind == 6:  # a length byte that does not fit the data
            frame[1] = data.draw(st.integers(0, 255))
        datagrams.append(bytes(frame))
    packer = dialect.MAVLink(None, srcSystem=3, srcComponent=1)
    datagrams.append(bytes(heartbeat(5).pack(packer, force_mavlink1=True)))
    packer.signing.secret_key = bytes(32)
    packer.signing.sign_outgoing = True
    datagrams.append(bytes(heartbeat(6).pack(packer)))  # truly signed
    for gated in (False, True):
        fast = FrameParser(gate=_RefusingGate() if gated else None)
        slow = _by_bytes(FrameParser(gate=_RefusingGate() if gated else None))
        assert _outcome(fast, datagrams) == _outcome(slow, datagrams)


def test_the_short_cut_is_taken_for_an_intact_frame() -> None:
    """An intact frame alone in a datagram does not go through the buffer (fails when the
    short cut is removed: the buffer's parse is called)."""
    parser = FrameParser()
    parser._parse = None  # type: ignore[assignment]  # noqa: SLF001 - it must not be called
    (msg,) = parser.feed(frames(1)[0])
    assert msg.time_usec == 0 and parser.counters.frames_ok == 1
