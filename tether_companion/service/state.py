"""What the live service shows about itself: :class:`ServiceState` (the ``--status`` view,
systemd's STATUS line and the journal read it; the service updates it)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from tether_companion.service.ingest import INPUT_KINDS

RATE_WINDOW_S = 1.0
"""Local time over which the shown rates are counted [s]."""


@dataclass
class ServiceState:
    """What the status view and systemd STATUS show (updated by the service)."""

    link_text: str = "starting"
    link_up: bool = False
    link_opens: int = 0
    link_open_failures: int = 0
    link_losses: int = 0
    last_error: str = ""
    fc_autopilot: int | None = None
    fc_armed: bool = False
    origin_sent: int = 0
    origin_confirmed: bool = False
    rates_hz: dict[str, float] = field(
        default_factory=lambda: dict.fromkeys((*INPUT_KINDS, "published"), 0.0)
    )
    ages_s: dict[str, float] = field(default_factory=dict)
    """Local seconds since each requested stream was last accepted."""
    sent_by_type: dict[str, int] = field(default_factory=dict)
    received: int = 0
    handler_errors: int = 0
    _rate_counts: dict[str, int] = field(default_factory=dict, repr=False)
    _rate_time_s: float = field(default=-math.inf, repr=False)

    def update_rates(self, now_s: float, counts: dict[str, int]) -> bool:
        """``rates_hz`` from cumulative ``counts`` at local time ``now_s`` [s], at most once per
        ``RATE_WINDOW_S``; whether they were updated."""
        elapsed = now_s - self._rate_time_s
        if elapsed < RATE_WINDOW_S:
            return False
        if math.isfinite(self._rate_time_s):
            for key, value in counts.items():
                self.rates_hz[key] = (value - self._rate_counts.get(key, value)) / elapsed
        self._rate_counts = counts
        self._rate_time_s = now_s
        return True
