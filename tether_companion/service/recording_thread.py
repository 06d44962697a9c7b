"""The recording off the hot path: frames are queued in memory, a thread writes them.

A :class:`~tether_companion.service.recording.TlogWriter` writes, rotates (fsync, directory
scan, unlink) and fsyncs; on an SD card any of these can take tens to hundreds of
milliseconds, and a write waits for a sync holding the writer's lock. Done inline, that time is
taken from the estimate the autopilot is waiting for. :class:`RecorderThread` takes a frame
with its arrival time in a few microseconds (a deque append) and hands the I/O to one thread,
which pushes what is queued to the operating system every ``drain_interval_s`` (so a
``kill -9`` loses at most that much) and fsyncs every ``sync_interval_s``. When the disk cannot
keep up, frames beyond ``max_pending_bytes`` are dropped and counted, never the estimate.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from tether_companion.config import ConfigError
from tether_companion.service.recording import RecordingLimits, TlogWriter

if TYPE_CHECKING:
    from tether_companion.service.config import RecordingConfig

DRAIN_INTERVAL_S = 0.02
MAX_PENDING_BYTES = 8 << 20


class RecorderThread:
    """Queue frames for a :class:`TlogWriter` and write them from a thread.

    Parameters
    ----------
    writer
        The recording (owned from now on: closed by :meth:`close`).
    sync_interval_s
        fsync period [s] (``recording.flush_interval_s``).
    drain_interval_s
        How often queued frames are written [s].
    max_pending_bytes
        Queued bytes beyond which new frames are dropped (counted in :attr:`dropped`).
    wall_clock_s
        Unix time [s] stamped on each frame when it is queued.
    """

    def __init__(
        self,
        writer: TlogWriter,
        sync_interval_s: float,
        *,
        drain_interval_s: float = DRAIN_INTERVAL_S,
        max_pending_bytes: int = MAX_PENDING_BYTES,
        wall_clock_s: Callable[[], float] = time.time,
    ) -> None:
        self.writer = writer
        self.sync_interval_s = sync_interval_s
        self.drain_interval_s = drain_interval_s
        self.max_pending_bytes = max_pending_bytes
        self._wall_clock_s = wall_clock_s
        self._queue: deque[tuple[int, bytes]] = deque()
        self._pending_bytes = 0
        self.dropped = 0
        """Frames not recorded because the queue was full (a disk slower than the link)."""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="recording", daemon=True)
        self._thread.start()

    def write(self, frame: bytes) -> None:
        """Queue one raw frame with the current Unix time (never blocks on I/O)."""
        if self._pending_bytes + len(frame) > self.max_pending_bytes:
            self.dropped += 1
            return
        self._queue.append((int(self._wall_clock_s() * 1e6), frame))
        self._pending_bytes += len(frame)  # a race with the thread's decrement only skews the bound

    def _drain(self) -> None:
        queue = self._queue
        writer = self.writer
        written = 0
        while queue:
            stamp_us, frame = queue.popleft()
            writer.write(frame, unix_us=stamp_us)
            written += len(frame)
        self._pending_bytes -= written
        writer.flush()

    def _run(self) -> None:
        next_sync = time.monotonic() + self.sync_interval_s
        while not self._stop.wait(self.drain_interval_s):
            self._drain()
            if time.monotonic() >= next_sync:
                next_sync = time.monotonic() + self.sync_interval_s
                self.writer.sync()

    def close(self) -> None:
        """Stop the thread, write what is queued, fsync and close (call from a worker thread
        or at exit: it waits for the disk)."""
        self._stop.set()
        self._thread.join()
        self._drain()
        self.writer.close()


def open_recorder(rec: RecordingConfig) -> RecorderThread | None:
    """The recorder the ``recording`` section asks for (None when disabled).

    Raises
    ------
    ConfigError
        When the directory cannot be created or written (naming ``recording.directory``).
    """
    if not rec.enabled:
        return None
    limits = RecordingLimits(
        max_file_bytes=int(rec.max_file_mb * 2**20),
        max_total_bytes=int(rec.max_total_mb * 2**20),
        flush_interval_s=rec.flush_interval_s,
    )
    try:
        return RecorderThread(TlogWriter(rec.directory, limits), rec.flush_interval_s)
    except OSError as exc:
        raise ConfigError(
            "", "recording.directory", rec.directory, f"cannot write there ({exc.strerror or exc})"
        ) from None
