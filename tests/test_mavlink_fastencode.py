"""The fast encoder of outgoing frames against pymavlink's ``pack`` (issue 12): the same bytes
for every message of the dialect, on random field values (zeros included, so that MAVLink 2's
trailing-zero truncation is exercised down to an all-zero payload)."""

from __future__ import annotations

import numpy as np
import pytest

from tether_companion.mavlink.fastencode import FastEncoder
from tether_companion.mavlink.framing import FrameEncoder, dialect

_INT_RANGES = {
    "int8_t": (-128, 127),
    "uint8_t": (0, 255),
    "uint8_t_mavlink_version": (0, 255),
    "int16_t": (-32768, 32767),
    "uint16_t": (0, 65535),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
    "uint64_t": (0, 2**64 - 1),
}


def _value(rng: np.random.Generator, kind: str, zero: bool):
    if kind == "char":
        return b"" if zero else bytes(rng.integers(32, 127, int(rng.integers(0, 5))).tolist())
    if zero:
        return 0.0 if kind in ("float", "double") else 0
    if kind in ("float", "double"):
        return float(rng.normal(scale=1e3))
    low, high = _INT_RANGES[kind]
    return int(rng.integers(low, high, endpoint=True, dtype=np.uint64 if low == 0 else np.int64))


def _random_message(rng: np.random.Generator, cls: type, zero_share: float):
    args = []
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    for name, kind in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        length = lengths[name]
        if length and kind != "char":
            args.append([_value(rng, kind, rng.random() < zero_share) for _ in range(length)])
        else:
            args.append(_value(rng, kind, rng.random() < zero_share))
    return cls(*args)


@pytest.mark.parametrize("zero_share", [0.0, 0.5, 1.0])
def test_every_message_frames_as_pymavlink_does(rng: np.random.Generator, zero_share) -> None:
    fast = FastEncoder()
    for seq, cls in enumerate(sorted(dialect.mavlink_map.values(), key=lambda c: c.id)):
        mav = dialect.MAVLink(None, srcSystem=int(rng.integers(1, 256)), srcComponent=7)
        mav.seq = seq & 0xFF
        for _ in range(3):
            msg = _random_message(rng, cls, zero_share)
            expected = msg.pack(mav)
            assert fast.frame(msg, mav.seq, mav.srcSystem, 7) == expected, cls.msgname


def test_the_frame_encoder_counts_the_sequence_as_pymavlink() -> None:
    encoder = FrameEncoder(3, 191)
    mav = dialect.MAVLink(None, srcSystem=3, srcComponent=191)
    for k in range(300):
        msg = dialect.MAVLink_named_value_float_message(k, b"TETH_TN", 0.5 * k)
        assert encoder.encode(msg) == msg.pack(mav)
        mav.seq = (mav.seq + 1) & 0xFF
