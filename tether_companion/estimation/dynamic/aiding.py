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
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bank import FilterBank, log_det_innovation
from tether_companion.estimation.dynamic.bank_updates import LIKELIHOOD_TEMPERING, RowsFunction
from tether_companion.estimation.dynamic.imu_batch import product
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.truncation import (
    log_probability_within,
    pseudo_measurement,
)
from tether_companion.estimation.ekf import (
    FUSED,
    GATED,
    NONFINITE,
    MeasurementFunction,
    UpdateResult,
    chi2_threshold,
)

FloatArray = NDArray[np.float64]

_threshold = functools.lru_cache(maxsize=32)(chi2_threshold)


def at_reading_time(measure: MeasurementFunction, latency_s: float) -> MeasurementFunction:
    """``measure`` of a reading taken ``latency_s`` [s] before it is fused: evaluated at the
    position ``p - latency_s v`` (the drone's then, to first order), with that position's
    Jacobian. A ground-station report 0.1 s old on the take-off's radial legs (1.5-2 m/s) is
    otherwise 0.15-0.2 m off the present length, three to four times the winch's told noise:
    gated, then the range drifts (realistic take-off, tuning seed 3). ``latency_s`` 0:
    ``measure`` itself.

    The velocity is taken as known: the Jacobian gets no ``-latency_s dh/dp`` velocity
    columns. With them a late position reading corrects the velocity, and where the velocity
    is still poorly known and the model far from linear (a start on a wrong bearing at low
    tension) those corrections fed the error: four held-out flights (seeds 21-30) diverged or
    published beyond 3 sigma with them and none without. What this leaves out of the
    innovation's covariance, ``latency_s^2 H Pvv H^T``, is below 1e-4 m^2 (0.01 m) once the
    velocity's standard deviation is below 0.1 m/s, against the winch's told 0.05 m."""
    if latency_s == 0.0:
        return measure

    def delayed(xs: FloatArray) -> tuple[FloatArray, FloatArray]:
        back = xs.copy()
        back[state.POSITION] -= latency_s * xs[state.VELOCITY]
        return measure(back)

    return delayed


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
    _last_jacobian: FloatArray | Sequence[float] = field(
        default_factory=lambda: np.zeros((0, 0)), repr=False
    )
    _last_prior: FloatArray | Sequence[float] = field(
        default_factory=lambda: np.zeros((0, 0)), repr=False
    )
    _last_noise: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)

    @property
    def last_innovation_variance(self) -> FloatArray:
        """Diagonal of the last innovation covariance ``H P H^T + R``, shape (m,) (computed
        when asked: the filter does not need it; the scalar path keeps ``H`` and ``P`` as the
        flat lists it had)."""
        noise = np.atleast_2d(self._last_noise)
        m = noise.shape[0]
        h_jac = np.asarray(self._last_jacobian, dtype=float)
        if h_jac.size == 0:
            return np.zeros(0)
        h_jac = h_jac.reshape(m, -1)
        n = h_jac.shape[1]
        prior = np.asarray(self._last_prior, dtype=float).reshape(n, n)
        return (product(h_jac, prior) * h_jac).sum(axis=1) + np.diag(noise)

    def skip(self, reason: str) -> None:
        """Count a sample the module did not offer to the filter, with why."""
        self.skipped += 1
        self.skipped_by_reason[reason] = self.skipped_by_reason.get(reason, 0) + 1
        self.last_fused = False


def _record(status: AidStatus, result: UpdateResult, time_s: float) -> bool:
    """Count ``result`` in ``status``; whether it was fused."""
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


def fuse_force_balance(
    bank: FilterBank,
    name: str,
    status: AidStatus,
    z: Sequence[float],
    measure: RowsFunction,
    r_variance: float,
    time_s: float,
) -> bool:
    """:func:`fuse` for a 3-axis measurement with ``R = r_variance I`` through the bank's
    stacked update (:meth:`FilterBank.update_force_balance`): ``measure(x)`` gives
    ``(h(x) (3,), H (39, row-major))`` at the state as a list ``x``."""
    best = bank.best
    results, jacobians, priors = bank.update_force_balance(
        name, z, measure, r_variance, bank.force_balance_tempering
    )
    return _record_bank(bank, best, name, status, results, jacobians, priors, r_variance, time_s)


def _record_bank(
    bank: FilterBank,
    best: MemberFilter,
    name: str,
    status: AidStatus,
    results: list[UpdateResult],
    jacobians: Sequence[FloatArray | Sequence[float]],
    priors: list[FloatArray],
    r_variance: float,
    time_s: float,
    log_likelihoods: Sequence[float] | None = None,
) -> bool:
    """Record the best member's outcome of a sample fused into every member (``best`` the
    best member before it) in ``status``, after adding the members' ``log_likelihoods`` of it
    when given (divided by :data:`LIKELIHOOD_TEMPERING`; the Gaussian's of each outcome the
    bank's update adds itself, :meth:`FilterBank.add_outcomes`); whether it was fused into the
    best member."""
    filters = bank.filters
    if len(filters) == 1:
        best_index = 0  # the best member before the update is the one member
    else:
        best_index = next(i for i, kf in enumerate(filters) if kf is best)
        if log_likelihoods is not None:
            for i, result in enumerate(results):
                if math.isfinite(result.nis):  # fused or gated: the prior's, as the Gaussian's
                    bank.add_evidence(i, -2.0 * log_likelihoods[i], 0.0, LIKELIHOOD_TEMPERING)
    best_result = results[best_index]
    if math.isfinite(best_result.nis):
        m = len(best.sensors[name].innovation)
        status.last_innovation = best.sensors[name].last_innovation
        status._last_jacobian, status._last_prior = jacobians[best_index], priors[best_index]
        status._last_noise = _noise(r_variance, m)
        threshold = _threshold(best.gate_probability, m)
        status.last_test_ratio = best_result.nis / threshold if math.isfinite(threshold) else 0.0
    return _record(status, best_result, time_s)


@functools.lru_cache(maxsize=8)
def _noise(r_variance: float, m: int) -> FloatArray:
    """``R = r_variance I`` (m, m) (shared: read only)."""
    return r_variance * np.eye(m)


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
    the best member's outcome in ``status`` (a scalar through the bank's stacked update,
    :meth:`FilterBank.update_scalar`).

    Returns whether the sample was fused into the best member.
    """
    best = bank.best
    if z.size == 1:
        r_variance = float(r[0, 0])
        results, jacobians, priors = bank.update_scalar(
            name, float(z[0]), measure, r_variance, tempering=LIKELIHOOD_TEMPERING
        )
        return _record_bank(
            bank, best, name, status, results, jacobians, priors, r_variance, time_s
        )
    best_index = 0 if bank.decided else bank.update_others(name, z, measure, r)
    kf = bank.filters[best_index]
    jacobians: list[FloatArray] = []
    priors: list[FloatArray] = []

    def measure_and_keep(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        value, h_jac = measure(x)
        jacobians.append(h_jac)
        priors.append(kf.P)
        return value, h_jac

    result = kf.update(name, z, measure_and_keep, r)
    if not bank.decided and jacobians:
        log_det_s = log_det_innovation(priors[0], jacobians[0], r)
        bank.add_evidence(best_index, result.nis, log_det_s)
    if math.isfinite(result.nis):
        status.last_innovation = kf.sensors[name].last_innovation
        status._last_jacobian, status._last_prior, status._last_noise = jacobians[0], priors[0], r
        threshold = _threshold(kf.gate_probability, z.size)
        status.last_test_ratio = result.nis / threshold if math.isfinite(threshold) else 0.0
    return _record(status, result, time_s)


def fuse_bound(
    bank: FilterBank,
    name: str,
    status: AidStatus,
    bound: float,
    measure: MeasurementFunction,
    r_variance: float,
    time_s: float,
) -> bool:
    """Fuse the upper bound ``h(x) + v <= bound`` (``v ~ N(0, r_variance)``; ``measure(x)``
    gives ``(h(x) (1,), H (1, n))``) into every member as its prior truncated to it
    (:mod:`~tether_companion.estimation.dynamic.truncation`: each member's own pseudo update,
    gated on its NIS like any scalar), each member's weight by the probability of the bound
    under its prior; record the best member's outcome in ``status``. Returns whether it was
    fused into the best member."""
    best = bank.best
    within: list[float] = []

    def pseudo(innovation: float, variance: float) -> tuple[float, float]:
        within.append(log_probability_within(innovation, variance))
        return pseudo_measurement(innovation, variance)

    results, jacobians, priors = bank.update_scalar(name, bound, measure, r_variance, pseudo)
    return _record_bank(
        bank,
        best,
        name,
        status,
        results,
        jacobians,
        priors,
        r_variance,
        time_s,
        log_likelihoods=within,
    )
