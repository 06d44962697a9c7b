"""The input frames' test and field read in C (``service/frame_core.c``) against its Python
reference (``FrameIngest.take`` / ``FrameIngest.fields`` of the class, ``_entry`` and the
message's ``struct``): the same verdict and the same values (types and float bits) on recorded
frames of both flavours, on frames each check refuses, and on 100,000 random and mutated
frames, half of them with their checksum made good again so that the checks after it run.

The extension is optional (no compiler: the Python reference runs). Its absence fails this
file where it could have been built (a C compiler and the Python headers here) or with
``TETHER_REQUIRE_CORE=1``, as the other extensions' files do.
"""

from __future__ import annotations

import functools
import struct

import numpy as np
import pytest
from optional_extension import import_extension
from test_service_ingest_frames import _hover_frames, _ingest, _odd_messages

from tether_companion.mavlink.framing import FrameEncoder, _checksum, dialect
from tether_companion.service.ingest_frames import FrameIngest

core, pytestmark = import_extension("tether_companion.service._frame_core")

FLAVOURS = ("ardupilot", "px4")


def _bits(values: tuple | None) -> object:
    """Values by type and, for floats, bit pattern (-0.0 != 0.0, NaNs compare)."""
    if values is None:
        return None
    return [(type(v), struct.pack("<d", v) if type(v) is float else v) for v in values]


def _frames(autopilot: str) -> FrameIngest:
    frames = FrameIngest(_ingest(autopilot)[0])
    assert isinstance(frames.take, functools.partial)  # C runs
    assert isinstance(frames.fields, functools.partial)
    return frames


def _same(frames: FrameIngest, frame: bytes | bytearray) -> bool:
    """Asserts C and Python agree on ``frame``; whether it was taken."""
    reference = FrameIngest.fields(frames, frame)
    assert _bits(frames.fields(frame)) == _bits(reference), bytes(frame).hex()
    assert frames.take(frame) is FrameIngest.take(frames, frame) is (reference is not None)
    return reference is not None


def _fix_checksum(data: bytearray, rng: np.random.Generator) -> bytearray:
    """``data`` with its last two bytes the checksum over what it holds as a MAVLink 2 frame
    (the crc_extra of its message id when the dialect knows it, else a random one)."""
    if len(data) < 3:
        return data
    msg_id = data[7] | (data[8] << 8) | (data[9] << 16) if len(data) >= 10 else -1
    known = dialect.mavlink_map.get(msg_id)
    extra = known.crc_extra if known is not None else int(rng.integers(256))
    data[-2:] = struct.pack("<H", _checksum(bytes(data[1:-2]), bytes((extra,))))
    return data


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_recorded_and_refused_frames_agree(autopilot: str) -> None:
    frames = _frames(autopilot)
    recorded = _hover_frames(autopilot, 1.0, seed=3)
    assert all(_same(frames, frame) for frame in recorded)
    for frame in recorded[:8]:  # as bytearray and memoryview too (tlog records, buffers)
        assert _same(frames, bytearray(frame))
        assert frames.fields(memoryview(frame)) == frames.fields(frame)
    taken = 0
    for encoder in (FrameEncoder(1, 1), FrameEncoder(2, 1), FrameEncoder(1, 2)):
        for msg in _odd_messages(8):
            taken += _same(frames, encoder.encode(msg))
    assert 0 < taken < 3 * len(_odd_messages(8))
    v1 = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    msg = dialect.MAVLink_attitude_message(30_000, 0.1, 0.1, 0.1, 0.0, 0.0, 0.0)
    assert not _same(frames, bytes(msg.pack(v1, force_mavlink1=True)))


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_random_and_mutated_frames_agree(autopilot: str) -> None:
    rng = np.random.default_rng(12 if autopilot == "px4" else 11)
    frames = _frames(autopilot)
    recorded = _hover_frames(autopilot, 1.0, seed=5)
    taken = fixed_taken = 0
    for k in range(50_000):
        data = bytearray(recorded[int(rng.integers(len(recorded)))])
        choice = int(rng.integers(9))
        if choice == 1:
            data[rng.integers(len(data))] ^= 1 << int(rng.integers(8))
        elif choice == 2:
            data[rng.integers(len(data))] = int(rng.integers(256))
        elif choice == 3:
            data = data[: int(rng.integers(len(data) + 1))]
        elif choice == 4:  # the payload cut (the sender's trailing zeros) or grown
            cut = int(rng.integers(-3, data[1] + 1))
            data[1] = (data[1] - cut) % 256
            data = data[: 10 + data[1]] + bytes(max(0, 10 + data[1] - len(data))) + b"\0\0"
        elif choice == 5:
            data += bytes(rng.integers(0, 256, int(rng.integers(1, 4)), dtype=np.uint8))
        elif choice == 6:  # a header byte: STX, length, flags, ids, message id
            data[rng.integers(10)] = int(rng.integers(256))
        elif choice == 7:
            data = bytearray(rng.integers(0, 256, int(rng.integers(0, 80)), dtype=np.uint8))
        elif choice == 8:  # random payload bytes (NaN and inf floats, extreme integers)
            for i in range(10, len(data) - 2):
                data[i] = int(rng.integers(256))
        if k % 2:
            data = _fix_checksum(data, rng)
            fixed_taken += _same(frames, bytes(data))
        else:
            taken += _same(frames, bytes(data))
    assert fixed_taken > 5_000 and taken > 2_000  # both verdicts, and the later checks, ran


def test_a_malformed_spec_is_refused() -> None:
    frame = _hover_frames("ardupilot", 0.01, seed=1)[0]
    with pytest.raises(ValueError, match="malformed"):
        core.take(b"\x01\x01", frame)
    with pytest.raises(ValueError, match="malformed"):
        core.fields(b"\x01\x01\x02" + bytes(9), frame)
    with pytest.raises(TypeError):
        core.take(b"\x01\x01\x00")
    assert core.fields(b"\x01\x01\x00", frame) is None  # an empty table takes nothing


def test_pure_python_runs_the_reference(monkeypatch: pytest.MonkeyPatch) -> None:
    import tether_companion.service.ingest_frames as module

    with_c = _frames("ardupilot")
    monkeypatch.setattr(module, "_CORE", None)
    frames = FrameIngest(_ingest("ardupilot")[0])
    assert not isinstance(frames.take, functools.partial)
    frame = _hover_frames("ardupilot", 0.01, seed=1)[0]
    assert frames.fields(frame) == with_c.fields(frame)
