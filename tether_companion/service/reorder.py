"""An adaptive reorder buffer: late samples are put back in time order, at no cost on a clean link.

Over UDP with jitter, a flight controller's 200 Hz streams arrive out of order (a sample sent
5 ms after another can arrive 15 ms before it). Dropping every late sample loses a large share
of them (29 % with 30 ms delay and 20 ms jitter); holding each sample until the newest stamp
seen is ``window_s`` past it and then releasing in stamp order loses only those later than the
window, at the price of ``window_s`` more latency. A fixed window charges that latency to every
link, including the serial and loopback links that never reorder, so the window adapts:

* it starts at 0: every sample is released the moment it arrives;
* reordering is *seen* when a sample arrives older than one of its own stream (same ``kind``)
  already received. Its lateness is how far the newest stamp of any stream is past it (what the
  release horizon is measured from); the window becomes ``MARGIN`` times the largest lateness
  seen in the current and the previous ``PERIOD_S`` of flight-controller time, bounded by
  ``max_window_s``. The sample that revealed the reordering may itself be too late (dropped by
  the caller as out of order); the window then covers the next ones;
* at the end of each period it is recomputed from the last two periods only, so after
  ``PERIOD_S`` to ``2 PERIOD_S`` without reordering it is 0 again.

Different streams' stamps being out of step (ATTITUDE stamped a little ahead of RAW_IMU, as
ArduPilot sends them) is not reordering: only a stream overtaking itself widens the window.
Pure; times are flight-controller seconds.

Example
-------
>>> buffer = ReorderBuffer(max_window_s=0.03)
>>> [s for _, s in buffer.push("imu", 1.000, "a")]  # clean so far: released at once
['a']
>>> buffer.push("imu", 0.995, "b")  # reordering seen (b is too late): the window opens
[]
>>> round(buffer.window_s, 6), buffer.push("imu", 1.005, "c")
(0.00625, [('imu', 'b')])
>>> buffer.push("imu", 1.004, "d"), buffer.push("imu", 1.012, "e")
([], [('imu', 'd'), ('imu', 'c')])
"""

from __future__ import annotations

import heapq
import itertools
import math
from typing import Generic, TypeVar

T = TypeVar("T")

MAX_HELD = 4096
"""Samples held at most (a bound for absurd windows; 400 Hz x 4 streams x 1 s is 1600)."""
MARGIN = 1.25
"""Window over the largest lateness seen: room for a little more than the link has shown."""
PERIOD_S = 5.0
"""Flight-controller seconds per period of the lateness memory (the window forgets after two)."""


class ReorderBuffer(Generic[T]):
    """Holds samples as long as the link's observed reordering needs, releasing them in order.

    Parameters
    ----------
    max_window_s
        Largest window [s] of flight-controller time; 0 releases every sample at once and
        never reorders (a late sample is then the caller's to drop).

    Attributes
    ----------
    window_s
        The current window [s]: how far the newest stamp must be past a sample before it
        is released.
    reordered
        Samples that arrived older than one of their own stream already received.
    widened, narrowed
        Times the window grew (reordering beyond it seen) and shrank (a period ended).
    largest_lateness_s
        The largest lateness ever seen [s] (newest stamp minus a reordered sample's stamp).
    """

    def __init__(self, max_window_s: float) -> None:
        if not 0.0 <= max_window_s < math.inf:
            raise ValueError(f"reorder window must be >= 0 s and finite, got {max_window_s}")
        self.max_window_s = max_window_s
        self.window_s = 0.0
        self.reordered = 0
        self.widened = 0
        self.narrowed = 0
        self.largest_lateness_s = 0.0
        self._heap: list[tuple[float, int, str, T]] = []
        self._order = itertools.count()
        self._newest_s = -math.inf
        self._newest_by_kind: dict[str, float] = {}
        self._period_end_s = -math.inf
        self._lateness_s = 0.0  # largest lateness in the current period
        self._previous_lateness_s = 0.0  # ... and in the one before

    def push(self, kind: str, time_s: float, sample: T) -> list[tuple[str, T]]:
        """Add ``sample`` of ``kind`` stamped ``time_s``; returns what is due, oldest first."""
        if self.max_window_s == 0.0:
            return [(kind, sample)]
        newest = self._newest_s
        if time_s >= newest:
            self._newest_s = newest = time_s
            if time_s >= self._period_end_s:
                self._end_period(time_s)
        by_kind = self._newest_by_kind
        if time_s < by_kind.get(kind, -math.inf):
            self._reordering_seen(newest - time_s)
        else:
            by_kind[kind] = time_s
        heap = self._heap
        if not heap and self.window_s == 0.0:
            return [(kind, sample)]  # the clean link's path: nothing held, nothing to sort
        heapq.heappush(heap, (time_s, next(self._order), kind, sample))
        horizon = newest - self.window_s
        out = []
        while heap and (heap[0][0] <= horizon or len(heap) > MAX_HELD):
            _, _, k, s = heapq.heappop(heap)
            out.append((k, s))
        return out

    def _reordering_seen(self, lateness_s: float) -> None:
        self.reordered += 1
        self.largest_lateness_s = max(self.largest_lateness_s, lateness_s)
        if lateness_s > self._lateness_s:
            self._lateness_s = lateness_s
            wanted = min(self.max_window_s, MARGIN * lateness_s)
            if wanted > self.window_s:
                self.window_s = wanted
                self.widened += 1

    def _end_period(self, time_s: float) -> None:
        """Start a new period at ``time_s``: the window covers the last two periods only."""
        self._previous_lateness_s, self._lateness_s = self._lateness_s, 0.0
        self._period_end_s = time_s + PERIOD_S
        wanted = min(self.max_window_s, MARGIN * self._previous_lateness_s)
        if wanted < self.window_s:
            self.window_s = wanted
            self.narrowed += 1

    def clear(self) -> None:
        """Forget everything held and the stamps (after a flight-controller reboot); what the
        link's reordering was is kept (it is the link's, not the flight controller's)."""
        self._heap.clear()
        self._newest_s = -math.inf
        self._newest_by_kind.clear()
        self._period_end_s = -math.inf

    def __len__(self) -> int:
        return len(self._heap)
