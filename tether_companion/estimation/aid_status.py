"""What happened to each sensor's samples in an EKF (PX4-style aid-source status) and the
chi-square innovation gate's decision, shared by the paper filters
(:mod:`~tether_companion.estimation.ekf`) and the dynamic filter's members."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

FUSED = "fused"
GATED = "gated"
NONFINITE = "nonfinite"
SINGULAR = "singular"


@dataclass(slots=True)
class SensorStatus:
    """What happened to one sensor's samples (PX4-style aid-source status).

    Attributes
    ----------
    fused, gated, nonfinite, singular
        Counts of samples fused, rejected by the innovation gate, rejected because a value
        was NaN/inf, and rejected because the innovation covariance was not positive definite.
    forced
        Samples fused after ``max_consecutive_rejections`` gate rejections in a row (the gate
        yields so a filter that started far from the truth can still converge).
    consecutive_rejections
        Gate rejections since the last fused sample.
    last_nis
        Normalised innovation squared of the last finite sample (dimensionless).
    innovation
        Innovation ``z - h(x)`` of the last sample that reached the gate (m values, as the
        update had them); read it as the array :attr:`last_innovation`.
    """

    fused: int = 0
    gated: int = 0
    nonfinite: int = 0
    singular: int = 0
    forced: int = 0
    consecutive_rejections: int = 0
    last_nis: float = math.nan
    innovation: Sequence[float] = ()

    @property
    def last_innovation(self) -> FloatArray:
        """Innovation ``z - h(x)`` of the last sample that reached the gate, shape (m,)."""
        return np.array(self.innovation, dtype=float)


@dataclass(frozen=True, slots=True)
class UpdateResult:
    """Outcome of one measurement update: ``status`` is ``fused``, ``gated``, ``nonfinite``
    or ``singular``; ``nis`` is the normalised innovation squared (``nan`` when not computed)."""

    status: str
    nis: float


def chi2_threshold(probability: float, dof: int) -> float:
    """Chi-square gate threshold: NIS values above it are rejected (``inf`` disables the gate)."""
    if probability >= 1.0:
        return math.inf
    # the chi-square quantile as scipy.stats.chi2.ppf computes it, without importing
    # scipy.stats (a second of start-up on a small board); scipy.special itself is imported
    # at the first gate (callers cache the threshold): its array-API layer costs ~0.2 s of
    # start-up, paid here once instead
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(dof / 2.0, probability))


def gate_rejects(status: SensorStatus, nis: float, threshold: float, in_force: float) -> bool:
    """Whether the gate rejects ``nis`` (counted in ``status``); a sample let through only
    because the gate yielded is counted as forced. A NaN NIS passes, as before: the
    update's finite check drops it."""
    if nis > in_force:
        status.consecutive_rejections += 1
        status.gated += 1
        return True
    if nis > threshold:
        status.forced += 1
    return False
