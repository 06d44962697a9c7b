"""A small reorder buffer: late samples within a window are put back in time order.

Over UDP with jitter, a flight controller's 200 Hz streams arrive out of order (a sample sent
5 ms after another can arrive 15 ms before it). Dropping every late sample loses a large share
of them (29 % with 30 ms delay and 20 ms jitter); holding each sample until the newest stamp
seen is ``window_s`` past it and then releasing in stamp order loses only those later than the
window, at the price of ``window_s`` more latency. Pure; times are flight-controller seconds.

Example
-------
>>> buffer = ReorderBuffer(window_s=0.01)
>>> buffer.push("imu", 1.000, "a"), buffer.push("imu", 0.995, "b")
([], [])
>>> [s for _, s in buffer.push("imu", 1.010, "c")]
['b', 'a']
"""

from __future__ import annotations

import heapq
import itertools
from typing import Generic, TypeVar

T = TypeVar("T")

MAX_HELD = 4096
"""Samples held at most (a bound for absurd windows; 200 Hz x 4 streams x 1 s is 800)."""


class ReorderBuffer(Generic[T]):
    """Holds samples for ``window_s`` of flight-controller time and releases them in order.

    Parameters
    ----------
    window_s
        How far [s] the newest stamp must be past a sample before it is released; 0 releases
        every sample at once (no reordering).
    """

    def __init__(self, window_s: float) -> None:
        if not window_s >= 0.0:
            raise ValueError(f"reorder window must be >= 0 s, got {window_s}")
        self.window_s = window_s
        self._heap: list[tuple[float, int, str, T]] = []
        self._order = itertools.count()
        self._newest_s = float("-inf")
        self.reordered = 0
        """Samples that arrived older than one already received and were put back in order."""

    def push(self, kind: str, time_s: float, sample: T) -> list[tuple[str, T]]:
        """Add ``sample`` of ``kind`` stamped ``time_s``; returns what is due, oldest first."""
        if self.window_s == 0.0:
            return [(kind, sample)]
        if time_s < self._newest_s:
            self.reordered += 1
        else:
            self._newest_s = time_s
        heapq.heappush(self._heap, (time_s, next(self._order), kind, sample))
        horizon = self._newest_s - self.window_s
        out = []
        heap = self._heap
        while heap and (heap[0][0] <= horizon or len(heap) > MAX_HELD):
            _, _, k, s = heapq.heappop(heap)
            out.append((k, s))
        return out

    def clear(self) -> None:
        """Forget everything held (after a flight-controller reboot)."""
        self._heap.clear()
        self._newest_s = float("-inf")

    def __len__(self) -> int:
        return len(self._heap)
