"""The flight controller's clock as seen from the companion: offset model and reboot detection.

Every input sample carries the flight controller's time since boot. The companion keeps an
estimate of ``fc_time = local_monotonic + offset`` so that it can tell how old the latest
sample is in the flight controller's time base, answer the flight controller's TIMESYNC
requests in that base (PX4 converts our stamps with the offset it learns that way; stamping
in its own base makes that offset ~0), and notice a reboot.

Offset from streamed stamps: a message stamped ``t_fc`` arrives at local ``t_rx`` after a
transport delay ``d >= 0``, so ``t_fc - t_rx = offset - d <= offset``: the largest recent
sample is the least-delayed one (the same idea as ArduPilot's JitterCorrection). We keep the
running maximum and let it decay slowly (``drift_allowance``) so crystal drift between the two
clocks cannot freeze it. A TIMESYNC round trip gives ``offset = t_fc + rtt / 2 - t_now`` and,
when fresh, is used as a floor.

Reboots are detected on the stamps alone (:mod:`tether_companion.service.ingest`), which then
calls :meth:`FcClock.reset`.
"""

from __future__ import annotations

import math


class FcClock:
    """Estimate of the flight controller's clock relative to the local monotonic clock.

    Parameters
    ----------
    drift_allowance
        Rate [s/s] at which the offset estimate decays when no new maximum arrives (covers
        clock drift; 1e-4 = 100 ppm, well above a crystal's).
    """

    def __init__(self, drift_allowance: float = 1e-4) -> None:
        self.drift_allowance = drift_allowance
        self.reset()

    def reset(self) -> None:
        """Forget everything (after a reboot or a new link)."""
        self._offset_s: float | None = None
        self._offset_local_s = 0.0
        self.timesync_offset_s: float | None = None
        self.timesync_rtt_s: float | None = None

    @property
    def synchronised(self) -> bool:
        """True once at least one stamp has been seen since the last reset."""
        return self._offset_s is not None

    def observe(self, fc_time_s: float, local_s: float) -> None:
        """Feed one flight-controller stamp [s] received at local monotonic time [s]: the
        offset ``fc - local`` [s] is the largest seen, decayed at ``drift_allowance``."""
        sample = fc_time_s - local_s
        current = self.offset_s(local_s)
        if current is None or sample > current:
            self._offset_s = sample
            self._offset_local_s = local_s
        elif current < self._offset_s:  # keep the decayed value as the new anchor
            self._offset_s = current
            self._offset_local_s = local_s

    def observe_timesync(
        self, fc_time_s: float, sent_local_s: float, received_local_s: float
    ) -> None:
        """Feed a TIMESYNC reply: flight-controller time at the echo, our send and receive times."""
        rtt = received_local_s - sent_local_s
        if rtt < 0.0:
            return
        self.timesync_rtt_s = rtt
        self.timesync_offset_s = fc_time_s + 0.5 * rtt - received_local_s

    def fc_now_s(self, local_s: float) -> float | None:
        """Estimated flight-controller time [s] at local time ``local_s``, None before sync."""
        offset = self.offset_s(local_s)
        return None if offset is None else local_s + offset

    def offset_s(self, local_s: float) -> float | None:
        """Current offset ``fc - local`` [s], None before the first stamp."""
        if self._offset_s is None:
            return None
        decayed = self._offset_s - self.drift_allowance * max(0.0, local_s - self._offset_local_s)
        if self.timesync_offset_s is not None:
            decayed = max(decayed, self.timesync_offset_s)
        return decayed

    def age_s(self, fc_time_s: float, local_s: float) -> float:
        """How old [s] a sample stamped ``fc_time_s`` is now (inf before sync)."""
        now = self.fc_now_s(local_s)
        return math.inf if now is None else max(0.0, now - fc_time_s)
