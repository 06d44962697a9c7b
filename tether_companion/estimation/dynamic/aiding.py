"""One measurement fusion with its status record (PX4 EKF2's ``aid_sources`` pattern).

Each sensor module (``aid_*.py``) decides when to fuse, forms the measurement and hands it to
:func:`fuse`, which runs the filter's gated Joseph-form update
(:meth:`~tether_companion.estimation.ekf.ExtendedKalmanFilter.update`) on every member of
the :class:`~tether_companion.estimation.dynamic.bank.FilterBank` and records what
happened in that sensor's :class:`AidStatus`: innovation and its variance, test ratio, fused
or why not, the time of the last fusion, and counters.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.ekf import (
    FUSED,
    GATED,
    NONFINITE,
    MeasurementFunction,
    chi2_threshold,
)

FloatArray = NDArray[np.float64]

_threshold = functools.lru_cache(maxsize=32)(chi2_threshold)


@dataclass(slots=True)
class AidStatus:
    """What one measurement source did (monotonic counters and the last sample's numbers).

    Attributes
    ----------
    fused, gated, nonfinite, singular, skipped
        Samples fused; rejected by the innovation gate; rejected as NaN/inf; rejected with a
        non-positive-definite innovation covariance; not offered to the filter (the module's
        own conditions, counted by reason in ``skipped_by_reason``).
    last_innovation
        ``z - h(x)`` of the last sample that reached the gate, shape (m,).
    last_innovation_variance
        Diagonal of its innovation covariance ``H P H^T + R``, shape (m,) (a property).
    last_test_ratio
        NIS over the gate threshold (``> 1``: gated; 0 when the gate is off).
    last_fused
        Whether the last sample offered was fused.
    last_fused_time_s
        Filter time of the last fusion [s] (``nan`` before the first).
    """

    fused: int = 0
    gated: int = 0
    nonfinite: int = 0
    singular: int = 0
    skipped: int = 0
    skipped_by_reason: dict[str, int] = field(default_factory=dict)
    last_innovation: FloatArray = field(default_factory=lambda: np.zeros(0))
    last_test_ratio: float = math.nan
    last_fused: bool = False
    last_fused_time_s: float = math.nan
    _last_jacobian: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    _last_prior: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    _last_noise: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)

    @property
    def last_innovation_variance(self) -> FloatArray:
        """Diagonal of the last innovation covariance ``H P H^T + R``, shape (m,) (computed
        when asked: the filter does not need it)."""
        h_jac = self._last_jacobian
        if h_jac.size == 0:
            return np.zeros(0)
        return ((h_jac @ self._last_prior) * h_jac).sum(axis=1) + np.diag(self._last_noise)

    def skip(self, reason: str) -> None:
        """Count a sample the module did not offer to the filter, with why."""
        self.skipped += 1
        self.skipped_by_reason[reason] = self.skipped_by_reason.get(reason, 0) + 1
        self.last_fused = False


def fuse(
    bank: FilterBank,
    name: str,
    status: AidStatus,
    z: FloatArray,
    measure: MeasurementFunction,
    r: FloatArray,
    time_s: float,
) -> bool:
    """Fuse ``z`` (shape (m,)) with noise ``r`` (m, m) into every member of ``bank``; record
    the best member's outcome in ``status``.

    Returns whether the sample was fused into the best member.
    """
    if not bank.decided:
        bank.update_others(name, z, measure, r)
    kf = bank.best
    p_before = kf.P
    jacobians: list[FloatArray] = []

    def measure_and_keep(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        value, h_jac = measure(x)
        jacobians.append(h_jac)
        return value, h_jac

    result = kf.update(name, z, measure_and_keep, r)
    if not bank.decided:
        bank.add_best_nis(result.nis)
    if math.isfinite(result.nis):
        status.last_innovation = kf.sensors[name].last_innovation
        status._last_jacobian, status._last_prior, status._last_noise = jacobians[0], p_before, r
        threshold = _threshold(kf.gate_probability, z.size)
        status.last_test_ratio = result.nis / threshold if math.isfinite(threshold) else 0.0
    status.last_fused = result.status == FUSED
    if result.status == FUSED:
        status.fused += 1
        status.last_fused_time_s = time_s
    elif result.status == GATED:
        status.gated += 1
    elif result.status == NONFINITE:
        status.nonfinite += 1
    else:
        status.singular += 1
    return status.last_fused
