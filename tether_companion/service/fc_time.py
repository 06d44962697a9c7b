"""Which flight-controller stamps to believe: implausible stamps, backsteps and reboots.

Every input sample carries the flight controller's time since boot. One sample must not be
able to move that clock: a stamp of 2^63 us would make every later genuine sample look old,
and one stamped in the past must not restart the estimator. :class:`FcTimeGate` decides, per
stamp, from the stamps it has believed and the local time they arrived at:

* **implausible**: further ahead of the clock model than ``future_tolerance_s``: dropped, the
  clock does not move. The model is the newest believed stamp plus ``max_rate`` times the
  local time elapsed since it arrived (the flight controller's clock runs at the local rate,
  but an emulator at 4x speed, or a burst after a stalled link, runs faster for a while).
  A genuine jump (the link, or our own loop, was stalled while the flight controller's clock
  went on; the datagrams from before and after are then handled within microseconds) is
  believed once ``confirmations`` stamps that agree with each other and arrive over at least
  ``confirm_span_s`` of local time have all been ahead, with no stamp of the old clock between
  them: one datagram cannot do that;
* **backstep**: more than ``backstep_s`` behind the newest believed stamp: dropped (counted as
  out of order by the caller), unless it confirms a reboot;
* **reboot**: believed only on the flight controller's own evidence: a SYSTEM_TIME whose
  ``time_boot_ms`` went back by more than ``backstep_s`` (a *claim*, cancelled by any later
  stamp that continues the old clock), then ``confirmations`` backstepped input stamps that
  agree with the claimed clock and arrive over at least ``confirm_span_s`` of local time (so
  one datagram holding a SYSTEM_TIME and a few samples cannot do it). A flight controller
  that never sends SYSTEM_TIME is believed to have rebooted once its stamps have all been
  backstepped for ``fallback_s`` of local time: only a silent old clock allows that, which is
  what a reboot looks like.

Without local times (replay of a log), the plausibility and span checks are skipped and the
fallback counts ``fallback_samples`` instead.
"""

from __future__ import annotations

import math

ACCEPT = "accept"
IMPLAUSIBLE = "implausible"
BACKSTEP = "backstep"
REBOOT = "reboot"

REBOOT_BACKSTEP_S = 1.0
"""A stamp this far [s] behind the newest is a backstep (less: out of order, by the caller)."""
FUTURE_TOLERANCE_S = 0.5
"""A stamp this far [s] ahead of the clock model is implausible."""
MAX_RATE = 10.0
"""The flight controller's stamps may advance up to this many times faster than local time."""
REBOOT_CONFIRMATIONS = 3
CONFIRM_SPAN_S = 0.01
FALLBACK_S = 2.0
FALLBACK_SAMPLES = 400


class FcTimeGate:
    """The believed flight-controller clock (see the module docstring).

    Parameters
    ----------
    backstep_s, future_tolerance_s
        Thresholds [s] of a backstep and of an implausible (future) stamp.
    confirmations, confirm_span_s
        Backstepped input stamps agreeing with a SYSTEM_TIME claim, over at least this much
        local time [s], that confirm a reboot.
    fallback_s, fallback_samples
        Without a claim: consecutive backsteps for this long [s of local time] (or this many,
        without local times) also mean a reboot.
    """

    def __init__(
        self,
        *,
        backstep_s: float = REBOOT_BACKSTEP_S,
        future_tolerance_s: float = FUTURE_TOLERANCE_S,
        max_rate: float = MAX_RATE,
        confirmations: int = REBOOT_CONFIRMATIONS,
        confirm_span_s: float = CONFIRM_SPAN_S,
        fallback_s: float = FALLBACK_S,
        fallback_samples: int = FALLBACK_SAMPLES,
    ) -> None:
        self.backstep_s = backstep_s
        self.future_tolerance_s = future_tolerance_s
        self.max_rate = max_rate
        self.confirmations = confirmations
        self.confirm_span_s = confirm_span_s
        self.fallback_s = fallback_s
        self.fallback_samples = fallback_samples
        self.reset()

    def reset(self) -> None:
        """Forget the clock (a new boot: the next stamp anchors it)."""
        self.latest_fc_s = -math.inf
        """Newest believed stamp [s]."""
        self._latest_local_s: float | None = None
        self._claim: tuple[float, float | None] | None = None
        self._confirm_local_s: list[float | None] = []
        self._backsteps = 0
        self._first_backstep_local_s: float | None = None
        self._ahead: list[tuple[float, float]] = []
        """(stamp, local time) of consecutive implausible stamps that agree with each other."""

    def _implausible(self, fc_s: float, local_s: float | None) -> bool:
        if local_s is None or self._latest_local_s is None:
            return False
        elapsed = local_s - self._latest_local_s
        if not elapsed > 0.0:  # max(0.0, elapsed) without the builtin's call (nan too: 0.0)
            elapsed = 0.0
        return fc_s > self.latest_fc_s + self.max_rate * elapsed + self.future_tolerance_s

    def on_system_time(self, fc_s: float, local_s: float | None) -> str:
        """A SYSTEM_TIME's ``time_boot_ms`` [s]: a reboot claim when it went back."""
        if not math.isfinite(self.latest_fc_s):
            return ACCEPT
        if self._implausible(fc_s, local_s):
            return IMPLAUSIBLE
        if fc_s < self.latest_fc_s - self.backstep_s:
            self._claim = (fc_s, local_s)
            self._confirm_local_s = []
            return BACKSTEP
        self._claim = None  # the old clock goes on
        return ACCEPT

    def check(self, fc_s: float, local_s: float | None) -> str:
        """Verdict on an input stamp [s] received at local time ``local_s`` [s] (or None)."""
        if self._implausible(fc_s, local_s):
            assert local_s is not None  # no plausibility check without local times
            if not self._jump_confirmed(fc_s, local_s):
                return IMPLAUSIBLE
        if self._ahead:  # a run of stamps ahead ends (no new list per stamp otherwise)
            self._ahead = []
        if fc_s < self.latest_fc_s - self.backstep_s:
            return self._backstep(fc_s, local_s)
        self._claim = None
        self._backsteps = 0
        self._first_backstep_local_s = None
        if fc_s >= self.latest_fc_s:
            self.latest_fc_s = fc_s
            self._latest_local_s = local_s
        return ACCEPT

    def _jump_confirmed(self, fc_s: float, local_s: float) -> bool:
        """Whether ``fc_s``, ahead of the model, completes a run of agreeing stamps ahead."""
        if self._ahead:
            first_fc_s, first_local_s = self._ahead[0]
            elapsed = local_s - first_local_s
            agrees = (
                first_fc_s - self.backstep_s
                <= fc_s
                <= first_fc_s + self.max_rate * elapsed + self.future_tolerance_s
            )
            if not agrees:
                self._ahead = []
        self._ahead.append((fc_s, local_s))
        return len(self._ahead) >= self.confirmations and self._spans([t for _, t in self._ahead])

    def _backstep(self, fc_s: float, local_s: float | None) -> str:
        if self._backsteps == 0:
            self._first_backstep_local_s = local_s
        self._backsteps += 1
        if self._claim is not None and self._agrees_with_claim(fc_s, local_s):
            self._confirm_local_s.append(local_s)
            if len(self._confirm_local_s) >= self.confirmations and self._spans(
                self._confirm_local_s
            ):
                return self._rebooted(fc_s, local_s)
        elif self._fallback_due(local_s):
            return self._rebooted(fc_s, local_s)
        return BACKSTEP

    def _agrees_with_claim(self, fc_s: float, local_s: float | None) -> bool:
        assert self._claim is not None
        claim_fc_s, claim_local_s = self._claim
        if fc_s < claim_fc_s - self.backstep_s:
            return False
        if local_s is None or claim_local_s is None:
            return True
        return fc_s <= claim_fc_s + (local_s - claim_local_s) + self.future_tolerance_s

    def _spans(self, local_times: list[float | None]) -> bool:
        if any(t is None for t in local_times):
            return True
        return max(local_times) - min(local_times) >= self.confirm_span_s  # type: ignore[type-var]

    def _fallback_due(self, local_s: float | None) -> bool:
        if local_s is None or self._first_backstep_local_s is None:
            return self._backsteps >= self.fallback_samples
        return local_s - self._first_backstep_local_s >= self.fallback_s

    def _rebooted(self, fc_s: float, local_s: float | None) -> str:
        self.reset()
        self.latest_fc_s = fc_s
        self._latest_local_s = local_s
        return REBOOT
