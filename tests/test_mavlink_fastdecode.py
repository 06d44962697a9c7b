"""The fast decoder of the hot input streams against pymavlink's decoder (issue 12).

Property: for every frame, the parser with the fast decoder and the parser with pymavlink's
return the same messages (for the hot streams a record: every field bit for bit pymavlink's,
the sender ids, sequence and frame bytes too, and ``to_message()`` pymavlink's own object) and
the same counts (same verdict for every rejected frame).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from tether_companion.mavlink.fastdecode import (
    HOT_MESSAGES,
    FastDecoder,
    HotRecord,
    MessageLayout,
    record_class,
)
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.synthetic import HoverStreams

HOT_IDS = [getattr(dialect, f"MAVLINK_MSG_ID_{name}") for name in HOT_MESSAGES]
OTHER_IDS = [
    dialect.MAVLINK_MSG_ID_HEARTBEAT,
    dialect.MAVLINK_MSG_ID_SCALED_IMU2,
    dialect.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    dialect.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT,
    dialect.MAVLINK_MSG_ID_STATUSTEXT,
]


def _bits(value):
    """``value`` with every float replaced by its IEEE bytes (bit-identity; NaN == NaN)."""
    if isinstance(value, float):
        return ("f64", struct.pack("<d", value))
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, tuple(_bits(v) for v in value))
    return value


def _state(msg) -> tuple:
    """Everything a pymavlink message object holds (its header's attributes included), bit
    for bit."""
    attrs = dict(vars(msg))
    header = vars(attrs.pop("_header"))
    return type(msg), header, {key: _bits(value) for key, value in attrs.items()}


def _received(msg) -> tuple:
    """What a receiver reads of a message or record: type, sender, sequence, frame bytes and
    every field by name, bit for bit."""
    names = type(msg).fieldnames if not isinstance(msg, HotRecord) else msg._fields[:-4]
    return (
        msg.get_type(),
        msg.get_srcSystem(),
        msg.get_srcComponent(),
        msg.get_seq(),
        bytes(msg.get_msgbuf()),
        {name: _bits(getattr(msg, name)) for name in names},
    )


def _same(fast, slow) -> bool:
    """A fast-decoded record reads as pymavlink's message and converts to it; any other
    message is pymavlink's on both sides."""
    if not isinstance(fast, HotRecord):
        return _state(fast) == _state(slow)
    assert list(fast._fields[:-4]) == type(slow).fieldnames
    return _received(fast) == _received(slow) and _state(fast.to_message()) == _state(slow)


def _decode_both(datagrams: list[bytes]) -> tuple[list, list, dict, dict]:
    """Both parsers on the same datagrams; their counts must agree after every datagram."""
    fast, slow = FrameParser(fast=True), FrameParser(fast=False)
    out_fast, out_slow = [], []
    for data in datagrams:
        out_fast += fast.feed(data) + fast.end_datagram()
        out_slow += slow.feed(data) + slow.end_datagram()
        assert fast.counters == slow.counters, data.hex()
        assert len(out_fast) == len(out_slow), data.hex()
    return out_fast, out_slow, fast.counters.as_dict(), slow.counters.as_dict()


def _assert_same(datagrams: list[bytes]) -> list:
    out_fast, out_slow, counts_fast, counts_slow = _decode_both(datagrams)
    assert counts_fast == counts_slow
    assert len(out_fast) == len(out_slow)
    for a, b in zip(out_fast, out_slow, strict=True):
        assert _same(a, b)
    return out_fast


def _crc(frame: bytes, msg_id: int) -> bytes:
    crc = dialect.x25crc(frame[1:])
    crc.accumulate(bytes((dialect.mavlink_map[msg_id].crc_extra,)))
    return struct.pack("<H", crc.crc)


def _frame(rng: np.random.Generator, msg_id: int, version: int, length: int) -> bytes:
    """A frame with a good checksum around ``length`` random payload bytes."""
    payload = rng.integers(0, 256, length, dtype=np.uint8).tobytes()
    seq, sysid, compid = (int(v) for v in rng.integers(0, 256, 3))
    if version == 1:
        head = bytes((dialect.PROTOCOL_MARKER_V1, length, seq, sysid, compid, msg_id))
        body = head + payload
        return body + _crc(body, msg_id)
    signed = rng.random() < 0.2
    incompat = dialect.MAVLINK_IFLAG_SIGNED if signed else 0
    head = bytes(
        (dialect.PROTOCOL_MARKER_V2, length, incompat, int(rng.integers(0, 256)), seq, sysid)
    ) + bytes((compid, msg_id & 0xFF, (msg_id >> 8) & 0xFF, msg_id >> 16))
    body = head + payload
    signature = rng.integers(0, 256, 13, dtype=np.uint8).tobytes() if signed else b""
    return body + _crc(body, msg_id) + signature


def _random_good_frame(rng: np.random.Generator) -> bytes:
    msg_id = int(rng.choice(HOT_IDS)) if rng.random() < 0.8 else int(rng.choice(OTHER_IDS))
    full = dialect.mavlink_map[msg_id].unpacker.size
    version = 1 if rng.random() < 0.25 and msg_id < 256 else 2
    if version == 1:
        length = int(rng.integers(1, full + 1)) if rng.random() < 0.1 else full
        length = min(length, full)
    else:  # MAVLink 2: truncated trailing zeros, down to one byte
        length = int(rng.integers(1, full + 1))
    return _frame(rng, msg_id, version, length)


def _mutated(rng: np.random.Generator, frame: bytes) -> bytes:
    data = bytearray(frame)
    kind = rng.integers(0, 5)
    if kind == 0:  # flip bits
        for _ in range(int(rng.integers(1, 4))):
            data[int(rng.integers(0, len(data)))] ^= 1 << int(rng.integers(0, 8))
    elif kind == 1:  # cut
        data = data[: int(rng.integers(0, len(data)))]
    elif kind == 2:  # wrong length byte
        data[1] = int(rng.integers(0, 256))
    elif kind == 3:  # wrong message id (v1: byte 5, v2: byte 7)
        data[5 if data[0] == dialect.PROTOCOL_MARKER_V1 else 7] = int(rng.integers(0, 256))
    else:  # garbage in front and behind
        data = bytearray(rng.integers(0, 256, int(rng.integers(1, 8)), dtype=np.uint8)) + data
        data += bytes((dialect.PROTOCOL_MARKER_V2,))
    return bytes(data)


def _flight_frames(seconds: float, version: int) -> list[bytes]:
    config = load_service_config(None, {"recording": {"enabled": False}})
    vehicle = load_vehicle_for(config)
    streams = HoverStreams(vehicle, np.array([2.0, 1.0, -3.0]), 4.0, rng=np.random.default_rng(3))
    encoder = FrameEncoder(1, 1)
    mav1 = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = []
    for k in range(int(seconds * 200)):
        for msg in streams.messages(20.0 + k * 0.005, k):
            frames.append(
                encoder.encode(msg) if version == 2 else msg.pack(mav1, force_mavlink1=True)
            )
    return frames


@pytest.mark.parametrize("version", [1, 2])
def test_recorded_flight_decodes_identically(version: int) -> None:
    frames = _flight_frames(5.0, version)
    messages = _assert_same(frames)
    assert all(isinstance(m, HotRecord) for m in messages)
    types = {m.get_type() for m in messages}
    assert {"RAW_IMU", "ATTITUDE", "SERVO_OUTPUT_RAW", "DISTANCE_SENSOR"} <= types
    assert len(messages) == len(frames)
    # one stream of many frames per feed (TCP/serial) as well as datagrams
    _assert_same([b"".join(frames)])


def test_px4_highres_imu_decodes_identically() -> None:
    factory = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = dialect.MAVLink_highres_imu_message(
        123456789,
        0.1,
        -0.2,
        -9.8,
        0.01,
        0.02,
        -0.03,
        0.2,
        0.0,
        0.4,
        1013.0,
        0.0,
        12.0,
        25.0,
        0x3F,
        0,
    )
    messages = _assert_same([msg.pack(factory)])
    assert messages[0].xacc == pytest.approx(0.1) and messages[0].fields_updated == 0x3F


def test_fuzzed_frames_decode_identically(rng: np.random.Generator) -> None:
    frames = [_random_good_frame(rng) for _ in range(3000)]
    messages = _assert_same(frames)
    assert len(messages) == len(frames)  # every frame had a good checksum
    assert {m.get_type() for m in messages} >= set(HOT_MESSAGES)


def _verdict_run(rng: np.random.Generator, n_frames: int) -> dict:
    """Random and mutated frames, in datagrams of 1-4 frames; returns the counts."""
    datagrams = []
    total = 0
    while total < n_frames:
        parts = []
        for _ in range(int(rng.integers(1, 5))):
            draw = rng.random()
            if draw < 0.4:
                parts.append(_random_good_frame(rng))
            elif draw < 0.9:
                parts.append(_mutated(rng, _random_good_frame(rng)))
            else:
                parts.append(
                    rng.integers(0, 256, int(rng.integers(1, 60)), dtype=np.uint8).tobytes()
                )
        total += len(parts)
        datagrams.append(b"".join(parts))
    out_fast, out_slow, counts_fast, counts_slow = _decode_both(datagrams)
    assert counts_fast == counts_slow
    assert all(_same(a, b) for a, b in zip(out_fast, out_slow, strict=True))
    return counts_fast


def test_fuzz_verdicts_agree_frame_by_frame(rng: np.random.Generator) -> None:
    """2e4 random and mutated frames in the default run (1e5 in the slow-marked test)."""
    counts = _verdict_run(rng, 20_000)
    for reason in ("bad_crc", "bad_header", "unknown_id", "truncated", "garbage_bytes"):
        assert counts[reason] > 0, reason  # every rejection path was exercised
    assert counts["frames_ok"] > 5000


@pytest.mark.slow
def test_fuzz_verdicts_agree_on_1e5_frames() -> None:
    counts = _verdict_run(np.random.default_rng(2026), 100_000)
    assert counts["frames_ok"] > 25_000


def test_layouts_come_from_the_dialect() -> None:
    decoder = FastDecoder()
    assert sorted(decoder.layouts) == sorted(HOT_IDS)
    servo = decoder.layouts[dialect.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW]
    assert servo.crc_extra == dialect.MAVLink_servo_output_raw_message.crc_extra
    with pytest.raises(ValueError, match="char fields"):
        MessageLayout(dialect.MAVLink_statustext_message)
    record = record_class(dialect.MAVLink_raw_imu_message)
    assert record._fields[:-4] == tuple(dialect.MAVLink_raw_imu_message.fieldnames)
    assert record.msgname == "RAW_IMU" and record.msg_id == dialect.MAVLINK_MSG_ID_RAW_IMU


class _RefuseAttitude:
    """A link-trust gate that refuses every ATTITUDE frame (and remembers what it saw)."""

    def __init__(self) -> None:
        self.seen: list[int] = []

    def admit(self, frame, source) -> bool:
        msg_id = frame[5] if frame[0] == dialect.PROTOCOL_MARKER_V1 else frame[7]
        self.seen.append(msg_id)
        return msg_id != dialect.MAVLINK_MSG_ID_ATTITUDE


def test_the_trust_gate_sees_every_frame_before_the_fast_decoder() -> None:
    frames = _flight_frames(0.5, 2)
    gate = _RefuseAttitude()
    parser = FrameParser(gate=gate, fast=True)
    messages = [m for f in frames for m in parser.feed(f) + parser.end_datagram()]
    assert len(gate.seen) == len(frames)
    assert "ATTITUDE" not in {m.get_type() for m in messages}
    assert parser.counters.untrusted == gate.seen.count(dialect.MAVLINK_MSG_ID_ATTITUDE) > 0


def test_wire_offsets_read_every_item_of_every_dialect_message() -> None:
    """A layout's byte offsets and format characters (what the C frame reader reads a field
    at) give, for every message of the dialect a layout is made for (no ``char`` fields),
    exactly the items its ``struct`` unpacks, arrays one item per element."""
    rng = np.random.default_rng(7)
    checked = 0
    for message_class in dialect.mavlink_map.values():
        try:
            layout = MessageLayout(message_class)
        except ValueError:  # char fields: not fast-decoded
            continue
        payload = rng.integers(0, 256, layout.size, dtype=np.uint8).tobytes()
        items = layout.unpacker.unpack(payload)
        assert len(layout.wire_offsets) == len(layout.wire_formats) == len(items)
        for item, offset, code in zip(items, layout.wire_offsets, layout.wire_formats, strict=True):
            (read,) = struct.unpack_from("<" + code, payload, offset)
            assert read == item or (read != read and item != item)
        checked += 1
    assert checked > 100
