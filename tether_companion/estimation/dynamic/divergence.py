"""When the dynamic filter has diverged and must start again from fresh data.

Three signs, each with the reason the estimator reports (``filter restarted: <reason>``):

* a prediction that leaves every member's state or covariance non-finite, or reaches the
  point where the cable model is undefined (the position at the anchor, no tension):
  :func:`step_bank`;
* the accelerometer's force balance gated for :data:`DIVERGED_AFTER_S` in a row:
  :class:`GatedAccelerometer`;
* a position farther than :data:`MAX_DISTANCE_M` from the anchor: :func:`too_far`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from operator import attrgetter

from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.models import UNDEFINED

DIVERGED_AFTER_S = 1.0
"""Accelerometer innovations gated this long in a row [s]: the filter has diverged."""
MAX_DISTANCE_M = 1000.0
"""A position farther than this from the anchor [m] is a divergence."""
_RESETS = attrgetter("resets")


class GatedAccelerometer:
    """How long the accelerometer's force balance has been gated in a row."""

    def __init__(self) -> None:
        self._since_s = math.nan

    def clear(self) -> None:
        """Nothing gated (a fusion, or a new bank)."""
        self._since_s = math.nan

    def gated(self, time_s: float) -> None:
        """A force balance gated at filter time ``time_s`` [s]."""
        if math.isnan(self._since_s):
            self._since_s = time_s

    def diverged(self, time_s: float) -> str | None:
        """The restart reason when gated for :data:`DIVERGED_AFTER_S` by ``time_s`` [s]."""
        if not math.isnan(self._since_s) and time_s - self._since_s >= DIVERGED_AFTER_S:
            return f"accelerometer innovations gated for {DIVERGED_AFTER_S:g} s"
        return None


def step_bank(bank: FilterBank, step: Callable[[FilterBank], None]) -> str | None:
    """Run a prediction ``step`` on ``bank`` and drop the members it reset; the restart
    reason when it reset all of them or the cable model is undefined, else ``None``."""
    resets_before = list(map(_RESETS, bank.filters))
    try:
        step(bank)
    except UNDEFINED:  # at the anchor, or zero tension: the cable model is undefined
        return "position at the anchor or no tension"
    resets_after = list(map(_RESETS, bank.filters))
    if resets_after == resets_before:  # the usual step: no member reset (no lists per member)
        return None
    reset = [after != r for after, r in zip(resets_after, resets_before, strict=True)]
    if all(reset):
        return "state or covariance not finite"
    if any(reset):  # drop the members that restarted
        bank.keep([i for i, r in enumerate(reset) if not r])
    return None


def too_far(x: list[float]) -> str | None:
    """The restart reason when the state's position ``x[0:3]`` (NED from the anchor [m]) is
    beyond :data:`MAX_DISTANCE_M`, else ``None``."""
    if x[0] * x[0] + x[1] * x[1] + x[2] * x[2] > MAX_DISTANCE_M**2:
        return f"position beyond {MAX_DISTANCE_M:g} m"
    return None
