"""A bank of filters that differ in their thrust-scale hypothesis, until the data pick one.

Why: the thrust scale ``s`` (thrust map error, battery sag) trades against the cable's
vertical pull, so a 10 % error moves the first position fix by metres; one EKF started with
``s = 1 +- 0.1`` linearises far from the truth and can converge to a wrong, over-confident
state. Each member starts from the same window with a narrow prior around its own ``s``
(spaced so that the truth is within about one prior standard deviation of one member), the
members run side by side on the same measurements, and each accumulates the Gaussian
log-likelihood ``-(NIS + log det S)/2`` of its innovations (tempered:
:data:`LIKELIHOOD_TEMPERING`; without ``log det S`` a member whose covariance is metres wide
was never penalised for it: every innovation is small against it). The published state
is the mixture's mean and covariance (weights from the log-likelihoods; the covariance
includes the spread between members, so it stays honest while they disagree). When one
member's weight passes ``SELECT_WEIGHT`` after ``MIN_BANK_S`` the others are dropped; after
``max_bank_s`` (the config's ``initial.thrust_scale_bank_max_s``) without a decision (a steady
hover gives the thrust scale no information) the members of negligible weight go and those
one Gaussian represents (:mod:`~tether_companion.estimation.dynamic.bank_reduction`) become
one filter holding their moments; members one Gaussian does not represent (far apart in
bearing: one EKF from their moments converges into a wrong mode) run on until the data
decide. The fusion of a sample into every member and the members' evidence of it are
:class:`~tether_companion.estimation.dynamic.bank_updates.BankUpdates` (this class's base).

Pure and synchronous.
"""

from __future__ import annotations

import math
from operator import attrgetter, is_

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import bank_reduction, state
from tether_companion.estimation.dynamic.bank_arrays import (
    EMPTY,
    each_member,
    log_det_innovation,
    stack_members,
    sum_all,
)
from tether_companion.estimation.dynamic.bank_updates import LIKELIHOOD_TEMPERING, BankUpdates
from tether_companion.estimation.dynamic.imu_batch import MEMBER_CORE, ImuBatch, product
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.ekf import MeasurementFunction

FloatArray = NDArray[np.float64]

PREDICT_BATCH = getattr(MEMBER_CORE, "predict_batch", None)
"""``_member_core.predict_batch`` (bank_predict.c) where the extension runs and has it: the
member-by-member loop of :meth:`FilterBank.predict_batch` over every member in one call, bit
for bit; ``None`` where the loop must run (nothing changed)."""
BANK_MIXTURE = getattr(MEMBER_CORE, "bank_mixture", None)
"""``_member_core.bank_mixture`` (bank_mixture.c) where the extension runs and has it:
:meth:`FilterBank.mixture`'s cache test and moments over two or more members in one call, bit
for bit; ``None`` where the Python must run."""
HEALTHY_MEMBERS = getattr(MEMBER_CORE, "bank_healthy_members", None)
"""``_member_core.bank_healthy_members`` (bank_health.c) where the extension runs and has it:
:meth:`FilterBank.drop_unhealthy`'s test over every member in one call (the indices it keeps),
bit for bit; ``None`` where the Python must run."""

SELECT_WEIGHT = 0.99
"""Posterior weight at which one member is kept and the others dropped."""
MIN_BANK_S = 3.0
"""Shortest time the members run side by side [s]."""
DROP_WEIGHT = 0.01
"""Posterior weight below which a member of a bearing other than the best member's is
dropped (the data reject that bearing; that does not confirm the best one: on the realistic
2 N circle, tuning seed 4, the ring's far bearings were rejected while the best was 1.0-1.2 m
off across the cable at 0.4-0.5 m)."""
MERGE_DISTANCE_M = 0.3
"""A bearing hypothesis whose members are all this close to the best member, horizontally
[m], has converged to its bearing and is dropped (started elsewhere, the data brought it
there)."""


class FilterBank(BankUpdates):
    """Members (``MemberFilter``) with log-likelihood weights.

    Parameters
    ----------
    filters
        The members, one per hypothesis (at least one).
    start_s
        Time the bank started [s].
    max_bank_s
        Longest time the members run side by side [s] (:meth:`maybe_decide`).
    ticks_per_force_balance
        IMU ticks summed in one force-balance sample (see :data:`LIKELIHOOD_TEMPERING`).
    log_priors
        Each member's log prior weight (default: equal).
    bearings
        Each member's bearing hypothesis (members of one bearing differ only in the thrust
        scale; default: all one). While members of several bearings run, those of a bearing
        other than the best member's are dropped when their weight falls below
        :data:`DROP_WEIGHT`, and those that converged to it (:data:`MERGE_DISTANCE_M`); when
        every other bearing converged so, :attr:`bearing_confirmed`.
    consider
        The states every member holds as consider (Schmidt) states until :meth:`release`
        (default: the ground station's calibration, ``state.CALIBRATION``; None: none).
    """

    def __init__(
        self,
        filters: list[MemberFilter],
        start_s: float,
        max_bank_s: float,
        ticks_per_force_balance: int = 1,
        log_priors: list[float] | None = None,
        bearings: list[int] | None = None,
        consider: slice | None = state.CALIBRATION,
    ) -> None:
        self.filters = filters
        self.consider = consider
        """The states held as consider states: every update (here, stacked, and the
        members' own) keeps their means and their own covariance block
        (:func:`~tether_companion.estimation.dynamic.member.hold_consider`)."""
        for kf in filters:
            kf.consider = consider
        self.force_balance_tempering = LIKELIHOOD_TEMPERING / ticks_per_force_balance
        """What a force-balance sample's log-likelihood is divided by."""
        self.log_weight = [0.0] * len(filters) if log_priors is None else list(log_priors)
        """Each member's tempered log-likelihood so far plus its log prior (unnormalised;
        Python floats: read every tick)."""
        self.bearings = [0] * len(filters) if bearings is None else list(bearings)
        """Each member's bearing hypothesis."""
        self.bearing_confirmed = False
        """Whether every other bearing hypothesis converged to the best member's (started
        elsewhere, brought there by the data), none rejected and none left by time."""
        self._rejected = False
        """Whether a bearing hypothesis was dropped for its weight."""
        self.start_s = start_s
        self.max_bank_s = max_bank_s
        self._mixture_cache: tuple[list[FloatArray], list[float], tuple[FloatArray, FloatArray]]
        self._mixture_cache = ([], [], (np.zeros(0), np.zeros((0, 0))))
        """The members' arrays and log-likelihoods the last mixture was computed from, and
        it: the members replace their arrays when they change (never in place), so the same
        objects mean the same moments."""

    @property
    def decided(self) -> bool:
        """Whether one member is left."""
        return len(self.filters) == 1

    @property
    def one_bearing(self) -> bool:
        """Whether the members left hold one bearing hypothesis (the thrust-scale
        hypotheses may still run side by side)."""
        bearings = self.bearings
        return bearings.count(bearings[0]) == len(bearings)

    @property
    def best(self) -> MemberFilter:
        """The member with the largest weight."""
        filters = self.filters
        if len(filters) == 1:
            return filters[0]
        return filters[self._best_index()]

    def _best_index(self) -> int:
        ll = self.log_weight
        return ll.index(max(ll))

    def weights(self) -> FloatArray:
        """Normalised posterior weights, shape (members,)."""
        return np.array(self._weight_list())

    def _weight_list(self) -> list[float]:
        """:meth:`weights` as a list of floats."""
        ll = self.log_weight
        top = max(ll)
        w = [math.exp(v - top) for v in ll]
        total = sum(w)
        return [v / total for v in w]

    def keep(self, indices: list[int]) -> None:
        """Keep only the members at ``indices`` (with their log-likelihoods)."""
        self.filters = [self.filters[i] for i in indices]
        self.log_weight = [self.log_weight[i] for i in indices]
        self.bearings = [self.bearings[i] for i in indices]

    def release(self, still_held: slice | None = None) -> None:
        """Let the consider states learn from now on (ordinary states of every member), all
        but ``still_held`` (None: all), which stay consider states."""
        self.consider = still_held
        for kf in self.filters:
            kf.consider = still_held

    def predict(self, dt_s: float, u: list[float]) -> None:
        """Predict every member over ``dt_s`` [s] (``u`` the inputs as floats)."""
        for kf in self.filters:
            kf.predict(dt_s, u)

    def predict_batch(self, batch: ImuBatch, q: FloatArray) -> None:
        """Step every member over the IMU ticks summed in ``batch`` (inertial formulation;
        ``q`` the process noise spectral density (n, n)), all members in stacked arrays."""
        filters = self.filters
        if MEMBER_CORE is not None:  # member by member, in C (imu_batch.MEMBER_CORE)
            step = batch.step()  # every member in one C call, else this loop (its reference)
            if PREDICT_BATCH is not None and PREDICT_BATCH(
                filters, step.phi, step.d_p, step.d_v, q, step.duration_s, EMPTY
            ):
                return
            for kf in filters:
                x = step.step_state(kf.x)
                p, finite = step.step_member_covariance(kf.P, q)
                kf.set_predicted(x, p, healthy=finite and math.isfinite(sum_all(x)))
            return
        xs = batch.step_state(stack_members([kf.x for kf in filters]), q)
        ps = batch.step_covariance(stack_members([kf.P for kf in filters]), q)
        # Phi P Phi^T + T Q stays positive definite: only finiteness is in doubt
        healthy = math.isfinite(sum_all(xs) + sum_all(ps))
        one = len(filters) == 1
        for kf, x, p in zip(filters, each_member(xs, one), each_member(ps, one), strict=True):
            kf.set_predicted(x, p, healthy=healthy)

    def update_others(
        self, name: str, z: FloatArray, measure: MeasurementFunction, r: FloatArray
    ) -> int:
        """Fuse into every member but the best, add each member's log-likelihood of the
        sample, and return the index of the best it left out: the caller fuses that member
        and adds its evidence (:meth:`add_evidence`). Not ``best`` again afterwards: the
        others' evidence can make another member the best, which would then take the sample
        twice while this one never took it (paper circle, seed 2, 3 s: the first member
        stayed 0.19 m from the others after an angle they all moved on)."""
        best_index = self._best_index()
        for i, kf in enumerate(self.filters):
            if i != best_index:
                log_det_s = log_det_innovation(kf.P, measure(kf.x)[1], r)
                result = kf.update(name, z, measure, r)
                self.add_evidence(i, result.nis, log_det_s)
        return best_index

    def drop_unhealthy(self, max_distance_m: float) -> None:
        """Drop members whose state is not finite or farther than ``max_distance_m``."""
        if len(self.filters) == 1:  # nothing to choose between: the caller restarts
            return
        limit = max_distance_m**2
        keep = None if HEALTHY_MEMBERS is None else HEALTHY_MEMBERS(self.filters, limit)
        if keep is None:  # the test's reference (HEALTHY_MEMBERS: the same in one C call)
            keep = []
            for i, kf in enumerate(self.filters):
                x = kf.x_values()
                distance_sq = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
                if math.isfinite(sum(x)) and distance_sq <= limit:
                    keep.append(i)
        if keep and len(keep) < len(self.filters):
            self.keep(keep)

    def mixture(self) -> tuple[FloatArray, FloatArray]:
        """Mean (n,) and covariance (n, n) of the weighted mixture (with one member left,
        that member's own arrays; either way the caller copies what it keeps)."""
        filters = self.filters
        if len(filters) == 1:  # decided: the member's own arrays: read them, do not change them
            kf = filters[0]
            return kf.x, kf.P
        if BANK_MIXTURE is not None:  # the cache's test and the moments in one C call
            cache = BANK_MIXTURE(filters, self.log_weight, self._mixture_cache, EMPTY)
            if cache is not None:
                self._mixture_cache = cache
                return cache[2]  # type: ignore[no-any-return]
        cached_arrays, cached_ll, moments = self._mixture_cache
        if (  # the same objects (identity, in C: this runs at every IMU tick); a member
            # holding its values as lists (``_xa``/``_pa`` None) has no array to be the same
            cached_ll == self.log_weight
            and len(cached_arrays) == 2 * len(filters)
            and all(map(is_, map(_X_ARRAY, filters), cached_arrays[::2]))
            and all(map(is_, map(_P_ARRAY, filters), cached_arrays[1::2]))
        ):
            return moments
        arrays = [a for kf in filters for a in (kf.x, kf.P)]
        if MEMBER_CORE is not None:  # in C (imu_batch.MEMBER_CORE)
            n = filters[0].x.shape[0]
            mean, cov = EMPTY(n), EMPTY((n, n))
            if MEMBER_CORE.mixture(self._weight_list(), arrays[::2], arrays[1::2], mean, cov):
                self._mixture_cache = (arrays, list(self.log_weight), (mean, cov))
                return mean, cov
        w = self.weights()
        xs = np.array([kf.x for kf in self.filters])
        n = xs.shape[1]
        mean = product(w, xs)
        spread = xs - mean
        cov = product(w, np.array([kf.P.ravel() for kf in self.filters])).reshape(n, n)
        cov += product(spread.T * w, spread)
        cov += cov.T
        cov *= 0.5
        self._mixture_cache = (arrays, list(self.log_weight), (mean, cov))
        return mean, cov

    def maybe_decide(self, time_s: float) -> None:
        """Drop the members of rejected bearings (:data:`DROP_WEIGHT`); keep one member when
        its weight passes :data:`SELECT_WEIGHT` (after :data:`MIN_BANK_S`); after
        ``max_bank_s``, reduce the mixture to what the data left undecided (:meth:`_reduce`)."""
        if self.decided:
            return
        bearings = self.bearings
        several = bearings.count(bearings[0]) != len(bearings)
        if several:
            self._drop_rejected_bearings()
            if self.decided:
                return
        elapsed = time_s - self.start_s
        if elapsed < MIN_BANK_S:
            return
        w = self._weight_list()
        top = max(w)
        if top >= SELECT_WEIGHT:
            self.keep([w.index(top)])  # other bearings rejected: not confirmed
        elif elapsed >= self.max_bank_s:
            self._reduce(w)

    def _reduce(self, w: list[float]) -> None:
        """The bank undecided after ``max_bank_s`` (``w`` the normalised weights): the
        members below :data:`DROP_WEIGHT` go (negligible, as the selection drops them), the
        sets one Gaussian represents merge (:func:`~tether_companion.estimation.dynamic.
        bank_reduction.reduce`); one set left is the collapse, else the sets run on until the
        data decide (the published state stays the mixture's)."""
        reduced = bank_reduction.reduce(
            self.filters, self.log_weight, self.bearings, w, DROP_WEIGHT
        )
        if reduced is not None:
            self.filters, self.log_weight, self.bearings = reduced

    def _drop_rejected_bearings(self) -> None:
        """Drop the members of bearings other than the best member's whose weight is below
        :data:`DROP_WEIGHT`, and the bearings whose members all came within
        :data:`MERGE_DISTANCE_M` of the best member; one bearing left, every other one
        converged to it, confirms it."""
        w = self.weights().tolist()
        top = w.index(max(w))
        best = self.bearings[top]
        bn, be = self.filters[top].x_values()[:2]
        near: dict[int, bool] = {}
        for b, kf in zip(self.bearings, self.filters, strict=True):
            n, e = kf.x_values()[:2]
            close = math.hypot(n - bn, e - be) <= MERGE_DISTANCE_M
            near[b] = near.get(b, True) and close
        keep = [
            i
            for i, (b, wi) in enumerate(zip(self.bearings, w, strict=True))
            if b == best or (wi >= DROP_WEIGHT and not near[b])
        ]
        if len(keep) < len(w):
            dropped = set(range(len(w))) - set(keep)
            self._rejected = self._rejected or any(not near[self.bearings[i]] for i in dropped)
            self.keep(keep)
            if all(b == best for b in self.bearings) and not self._rejected:
                self.bearing_confirmed = True


_X_ARRAY = attrgetter("_xa")
"""A member's state array as it holds it (None while it holds a list): what ``x`` returns when
it is not None, read without the property (:meth:`FilterBank.mixture`'s identity check)."""
_P_ARRAY = attrgetter("_pa")
"""A member's covariance array as it holds it (None while it holds a list)."""
