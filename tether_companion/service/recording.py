"""Flight recording as MAVLink telemetry logs (.tlog), rotated and bounded in size.

The .tlog format is pymavlink's (and Mission Planner's / QGroundControl's): each record is an
8-byte big-endian unsigned Unix time in microseconds followed by one raw MAVLink frame (v1 or
v2, signature included). Any MAVLink tool opens these files, and ``tether-companion replay``
runs them through the estimation pipeline.

Durability: writes go to a Python buffer and are pushed to the OS with :meth:`TlogWriter.flush`
on every record's arrival once ``flush_interval_s`` has passed; :meth:`TlogWriter.sync`
(``fsync``, slow on SD cards, so the service calls it from a worker thread) makes them survive
a power cut. With both at ~1 s a power cut loses at most about the last second.
"""

from __future__ import annotations

import os
import struct
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from tether_companion.errors import InputError

_STAMP = struct.Struct(">Q")
_RECORD = struct.Struct(">QBBB")
"""A .tlog record's stamp and its frame's first three bytes (magic, payload length, flags)."""
MAVLINK1_MAGIC = 0xFE
MAVLINK2_MAGIC = 0xFD
_MAVLINK2_SIGNED = 0x01
_MAVLINK2_SIGNATURE_LEN = 13
_MAVLINK2_OVERHEAD = 12
"""An unsigned MAVLink 2 frame's bytes besides its payload (10 header, 2 checksum)."""


def frame_length(buffer: bytes | memoryview, start: int = 0) -> int | None:
    """Length [bytes] of the MAVLink frame starting at ``buffer[start]``.

    Returns None when ``buffer[start]`` is not a MAVLink magic byte or the header is cut off.
    """
    if start >= len(buffer):
        return None
    magic = buffer[start]
    if magic == MAVLINK2_MAGIC:
        if start + 3 > len(buffer):
            return None
        length = _MAVLINK2_OVERHEAD + buffer[start + 1]
        if buffer[start + 2] & _MAVLINK2_SIGNED:
            length += _MAVLINK2_SIGNATURE_LEN
        return length
    if magic == MAVLINK1_MAGIC:
        if start + 2 > len(buffer):
            return None
        return 8 + buffer[start + 1]
    return None


@dataclass(frozen=True)
class RecordingLimits:
    """Bounds of the recording (see ``RecordingConfig`` for the user-facing config)."""

    max_file_bytes: int
    max_total_bytes: int
    flush_interval_s: float


class TlogWriter:
    """Append MAVLink frames to rotating .tlog files in a directory.

    Parameters
    ----------
    directory
        Created if missing. Files are named ``tether-YYYYmmdd-HHMMSS-N.tlog`` (UTC).
    limits
        Rotate when a file would exceed ``max_file_bytes``; delete the oldest recordings of
        this writer's naming pattern while the directory's total exceeds ``max_total_bytes``.
    wall_clock_s, monotonic_s
        Time sources (injected for tests): Unix time for the record stamps, monotonic time
        for flush scheduling.

    Notes
    -----
    Thread use: :meth:`write` and :meth:`flush` run on the event loop; :meth:`sync` may run in
    a worker thread; a lock keeps rotation and sync apart.
    """

    PREFIX = "tether-"
    SUFFIX = ".tlog"

    def __init__(
        self,
        directory: str | Path,
        limits: RecordingLimits,
        wall_clock_s: Callable[[], float] = time.time,
        monotonic_s: Callable[[], float] = time.monotonic,
    ) -> None:
        self.directory = Path(directory)
        self.limits = limits
        self._wall_clock_s = wall_clock_s
        self._monotonic_s = monotonic_s
        self._lock = threading.Lock()
        self._file: BinaryIO | None = None
        self._file_bytes = 0
        self._sequence = 0
        self._last_flush_s = monotonic_s()
        self.records = 0
        self.bytes_written = 0
        self.files_deleted = 0
        self.errors = 0
        self.current_path: Path | None = None
        self.directory.mkdir(parents=True, exist_ok=True)
        self._open_new()

    def write(self, frame: bytes, unix_us: int | None = None) -> None:
        """Record one raw MAVLink frame with its Unix time [us] (default: now)."""
        if self._file is None:
            return
        stamp_us = int(self._wall_clock_s() * 1e6) if unix_us is None else unix_us
        record = _STAMP.pack(stamp_us) + frame
        try:
            if self._file_bytes + len(record) > self.limits.max_file_bytes and self._file_bytes > 0:
                self._rotate()
            assert self._file is not None
            self._file.write(record)
        except OSError:
            self.errors += 1  # a full or failing disk must not stop the flight software
            return
        self._file_bytes += len(record)
        self.bytes_written += len(record)
        self.records += 1
        if self._monotonic_s() - self._last_flush_s >= self.limits.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Push buffered records to the operating system (cheap; not yet on disk)."""
        self._last_flush_s = self._monotonic_s()
        if self._file is not None:
            try:
                self._file.flush()
            except OSError:
                self.errors += 1

    def sync(self) -> None:
        """Flush and ``fsync`` the current file so it survives a power cut (slow; any thread)."""
        with self._lock:
            if self._file is None:
                return
            try:
                self._file.flush()
                os.fsync(self._file.fileno())
            except (OSError, ValueError):
                self.errors += 1

    def close(self) -> None:
        """Flush, fsync and close the current file (idempotent)."""
        self.sync()
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None

    def _rotate(self) -> None:
        with self._lock:
            assert self._file is not None
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            self._file = None
            self._open_new()

    def _open_new(self) -> None:
        stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime(self._wall_clock_s()))
        while True:
            self._sequence += 1
            path = self.directory / f"{self.PREFIX}{stamp}-{self._sequence}{self.SUFFIX}"
            if not path.exists():
                break
        self._file = open(path, "wb")  # noqa: SIM115 - owned by this object, closed in close()
        self._file_bytes = 0
        self.current_path = path
        self._enforce_total()

    def _enforce_total(self) -> None:
        """Delete the oldest recordings (never the current one) beyond ``max_total_bytes``."""
        files = sorted(
            (
                p
                for p in self.directory.glob(f"{self.PREFIX}*{self.SUFFIX}")
                if p != self.current_path
            ),
            key=lambda p: p.stat().st_mtime,
        )
        total = sum(p.stat().st_size for p in files)
        while files and total > self.limits.max_total_bytes - self.limits.max_file_bytes:
            oldest = files.pop(0)
            total -= oldest.stat().st_size
            oldest.unlink(missing_ok=True)
            self.files_deleted += 1


def read_tlog(path: str | Path, *, allow_truncated: bool = False) -> Iterator[tuple[int, bytes]]:
    """Yield ``(unix_time_us, raw_frame)`` for every record of a .tlog file.

    Raises
    ------
    InputError
        When the file is missing or unreadable, when a record does not start with a MAVLink
        frame (not a .tlog), or when the last record is cut off (unless ``allow_truncated``,
        in which case the complete records before it are yielded).
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: no such log file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read log file ({exc.strerror})") from None
    if not data:
        raise InputError(f"{path}: the log file is empty")
    offset = 0
    count = 0
    size = len(data)
    stamp_of = _STAMP.unpack_from
    record_of = _RECORD.unpack_from
    while offset < size:
        start = offset + _STAMP.size
        if start + 3 <= size:  # the stamp and the frame's first three bytes in one read
            stamp_us, magic, payload_len, flags = record_of(data, offset)
            if magic == MAVLINK2_MAGIC and not flags & _MAVLINK2_SIGNED:
                length: int | None = _MAVLINK2_OVERHEAD + payload_len  # as frame_length
            else:
                length = frame_length(data, start)
        else:
            if start > size:
                if allow_truncated:
                    return
                raise InputError(
                    f"{path}: truncated at byte {offset} of {size} (cut inside a record header)"
                )
            (stamp_us,) = stamp_of(data, offset)
            length = frame_length(data, start)
        if length is None:
            if start >= size - 1 and allow_truncated:
                return
            raise InputError(
                f"{path}: byte {start} is not the start of a MAVLink frame (record {count}); "
                "not a .tlog file, or corrupted"
            )
        end = start + length
        if end > size:
            if allow_truncated:
                return
            raise InputError(
                f"{path}: truncated: record {count} at byte {offset} needs {length} frame bytes, "
                f"only {size - start} remain "
                "(use --allow-truncated to replay what is complete)"
            )
        yield stamp_us, data[start:end]
        offset = end
        count += 1
