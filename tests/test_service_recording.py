"""The .tlog recording: pymavlink-readable, rotated, bounded, durable; truncation detected."""

from __future__ import annotations

from pathlib import Path

import pytest
from pymavlink import mavutil

from tether_companion.errors import InputError
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.service.recording import RecordingLimits, TlogWriter, frame_length, read_tlog

LIMITS = RecordingLimits(max_file_bytes=10_000, max_total_bytes=35_000, flush_interval_s=1.0)


class FakeClock:
    def __init__(self) -> None:
        self.t = 1_700_000_000.0

    def __call__(self) -> float:
        return self.t


def _frames(n: int) -> list[bytes]:
    enc = FrameEncoder(1, 1)
    return [
        enc.encode(dialect.MAVLink_attitude_message(i, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0))
        for i in range(n)
    ]


def test_pymavlink_reads_what_we_write(tmp_path: Path) -> None:
    clock = FakeClock()
    writer = TlogWriter(tmp_path, LIMITS, wall_clock_s=clock, monotonic_s=clock)
    frames = _frames(20)
    for frame in frames:
        clock.t += 0.005
        writer.write(frame)
    writer.close()
    path = writer.current_path
    assert path is not None
    conn = mavutil.mavlink_connection(str(path))  # an independent reader of the format
    got = []
    while (msg := conn.recv_match(type="ATTITUDE")) is not None:
        got.append((msg.time_boot_ms, msg._timestamp))
    conn.close()
    assert [g[0] for g in got] == list(range(20))
    assert got[0][1] == pytest.approx(1_700_000_000.005, abs=1e-5)  # Unix time stamps
    assert [f for _, f in read_tlog(path)] == frames


def test_rotation_and_total_bound(tmp_path: Path) -> None:
    clock = FakeClock()
    writer = TlogWriter(tmp_path, LIMITS, wall_clock_s=clock, monotonic_s=clock)
    frames = _frames(2000)
    record = 8 + len(frames[-1])
    assert all(len(f) + 8 == record for f in frames[256:])  # MAVLink 2 trims trailing zeros
    for frame in frames[256:]:  # 1744 records of ~36 bytes: far over the 35 kB bound
        clock.t += 0.01
        writer.write(frame)
    writer.close()
    files = sorted(tmp_path.glob("*.tlog"))
    sizes = [f.stat().st_size for f in files]
    assert max(sizes) <= LIMITS.max_file_bytes
    assert sum(sizes) <= LIMITS.max_total_bytes
    assert writer.files_deleted > 0 and len(files) >= 2
    for f in files:  # every kept file is complete and readable on its own
        assert len(list(read_tlog(f))) * record == f.stat().st_size


def test_flush_interval_pushes_data_to_the_os(tmp_path: Path) -> None:
    clock = FakeClock()
    writer = TlogWriter(tmp_path, LIMITS, wall_clock_s=clock, monotonic_s=clock)
    frames = _frames(300)[256:259]
    size = 8 + len(frames[0])
    writer.write(frames[0])
    assert writer.current_path.stat().st_size == 0  # still buffered in Python
    clock.t += 1.0
    writer.write(frames[1])  # the flush interval has passed: flushed
    assert writer.current_path.stat().st_size == 2 * size
    writer.write(frames[2])
    writer.sync()
    assert writer.current_path.stat().st_size == 3 * size
    writer.close()
    writer.close()  # idempotent


def test_read_tlog_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such log file"):
        list(read_tlog(tmp_path / "nope.tlog"))
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        list(read_tlog(empty))
    junk = tmp_path / "junk.tlog"
    junk.write_bytes(b"\x00" * 8 + b"hello world, not mavlink")
    with pytest.raises(InputError, match="not the start of a MAVLink frame"):
        list(read_tlog(junk))
    clock = FakeClock()
    writer = TlogWriter(tmp_path / "rec", LIMITS, wall_clock_s=clock, monotonic_s=clock)
    for frame in _frames(5):
        writer.write(frame)
    writer.close()
    data = writer.current_path.read_bytes()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[:-10])
    with pytest.raises(InputError, match="truncated"):
        list(read_tlog(cut))
    assert len(list(read_tlog(cut, allow_truncated=True))) == 4


def test_frame_length_of_v1_v2_and_signed() -> None:
    frame = _frames(1)[0]
    assert frame_length(frame) == len(frame)
    signed = bytes([0xFD, 3, 0x01]) + bytes(20)
    assert frame_length(signed) == 12 + 3 + 13
    assert frame_length(bytes([0xFE, 9])) == 17
    assert frame_length(b"\x00abc") is None
    assert frame_length(bytes([0xFD])) is None
