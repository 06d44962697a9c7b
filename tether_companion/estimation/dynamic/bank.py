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
decide.

Pure and synchronous.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from itertools import chain
from operator import attrgetter, is_

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import bank_reduction, state
from tether_companion.estimation.dynamic.bank_arrays import (
    EMPTY,
    apply_each,
    each_member,
    finite_and_definite,
    log_det_innovation,
    stack_members,
    sum_all,
)
from tether_companion.estimation.dynamic.imu_batch import MEMBER_CORE, ImuBatch, product
from tether_companion.estimation.dynamic.member import MemberFilter, hold_consider
from tether_companion.estimation.ekf import FUSED, GATED, MeasurementFunction, UpdateResult

FloatArray = NDArray[np.float64]
RowsFunction = Callable[[list[float]], tuple[Sequence[float], Sequence[float]]]
"""``measure(x) -> (h(x) (m,), H (m*n row-major))`` at the state ``x`` (a list)."""

_N = state.N_STATES

SELECT_WEIGHT = 0.99
"""Posterior weight at which one member is kept and the others dropped."""
MIN_BANK_S = 3.0
"""Shortest time the members run side by side [s]."""
LIKELIHOOD_TEMPERING = 20.0
"""Each sample's log-likelihood is divided by this: the innovations of consecutive IMU ticks
are not independent (motor lag, unmodelled forces and the FC's attitude error last tens of
milliseconds to seconds), and counting 200 of them per second as independent evidence made
the bank pick a member within seconds in a steady hover, where the thrust scale is not
observable at all (a member 1.6-2 m off published at 3.2 sigma in the service's closed loop).
A force-balance sample that sums ``k`` IMU ticks (``imu_ticks_per_fusion``) carries the
evidence of ``k`` ticks, so it is divided by ``LIKELIHOOD_TEMPERING / k``
(:attr:`FilterBank.force_balance_tempering`): the evidence per second does not depend on how
the ticks are batched (with ``k = 4`` and the full 20 the bank saw a quarter of it and
collapsed by time, undecided, with a member far off still weighing 20-50 %)."""
DROP_WEIGHT = 0.01
"""Posterior weight below which a member of a bearing other than the best member's is
dropped (the data reject that bearing; that does not confirm the best one: on the realistic
2 N circle, tuning seed 4, the ring's far bearings were rejected while the best was 1.0-1.2 m
off across the cable at 0.4-0.5 m)."""
MERGE_DISTANCE_M = 0.3
"""A bearing hypothesis whose members are all this close to the best member, horizontally
[m], has converged to its bearing and is dropped (started elsewhere, the data brought it
there)."""


class FilterBank:
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
            step = batch.step()
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

    def update_force_balance(
        self,
        sensor: str,
        z: Sequence[float],
        measure: RowsFunction,
        r_variance: float,
        tempering: float | None = None,
    ) -> tuple[list[UpdateResult], list[Sequence[float]], list[FloatArray]]:
        """Fuse a 3-axis measurement ``z`` with ``R = r_variance I`` into every member
        (``measure(x)`` gives ``(h(x) (3,), H (39, row-major))`` at a state list): ``P H^T``,
        ``H P H^T``, the gain and ``P - K (P H^T)^T`` for all members in stacked arrays, the
        3x3 ``S``, NIS and gate per member in scalars
        (:meth:`~tether_companion.estimation.dynamic.member.MemberFilter.test_force_balance`).
        With ``tempering``, each member's evidence of the sample is added
        (:meth:`add_outcomes`). Returns each member's outcome, Jacobian and prior covariance.

        Where ``_member_core`` runs, all of it is one C call (:data:`FUSE_FORCE_BALANCE`, bit
        for bit this code with the extension's member functions), which hands back here
        whatever it does not take (before changing anything)."""
        filters = self.filters
        if FUSE_FORCE_BALANCE is not None:
            hold = self.consider
            start, stop, _ = (_HOLD_NONE if hold is None else hold).indices(_N)
            done = FUSE_FORCE_BALANCE(
                filters, sensor, z, measure, r_variance, start, stop, EMPTY, UpdateResult, FUSED,
                GATED, None if tempering is None else self.log_weight, tempering,
            )  # fmt: skip
            if done is not None:
                return done  # type: ignore[no-any-return]
        members = len(filters)
        priors = [kf.P for kf in filters]
        innovations = []
        jacobians = []
        z0, z1, z2 = z
        for kf in filters:
            value, jacobian = measure(kf.x_values())
            innovations.append((z0 - value[0], z1 - value[1], z2 - value[2]))
            jacobians.append(jacobian)
        projected = project_each(priors, jacobians, 3)
        if projected is None:  # numpy: all members stacked
            p = stack_members(priors)
            h_jac = np.fromiter(chain.from_iterable(jacobians), float, members * 3 * _N)
            h_jac = h_jac.reshape(p.shape[:-2] + (3, _N))
            pht = product(p, h_jac.swapaxes(-1, -2))
            s_values = product(h_jac, pht).reshape(members, 9).tolist()
        else:
            phts, s_values = projected
        results: list[UpdateResult | None] = []
        chosen = []
        for i, kf in enumerate(filters):
            result, solved = kf.test_force_balance(sensor, innovations[i], s_values[i], r_variance)
            results.append(result)
            if result is None:
                chosen.append((i, solved))
        if chosen and projected is not None:  # member by member, in C
            for i, solved in chosen:
                kf = filters[i]
                x, p_new, checked = self._gain_update(
                    kf.x, priors[i], phts[i], solved[1:10], solved[10:]
                )
                results[i] = kf.accept_update(sensor, solved[0], x, p_new, checked=checked)
        elif chosen:
            index = [i for i, _ in chosen]
            if len(index) < members:
                p, pht = p[index], pht[index]
            one = p.ndim == 2
            s_inv = np.array([solved[1:10] for _, solved in chosen]).reshape(p.shape[:-2] + (3, 3))
            w = np.array([solved[10:] for _, solved in chosen])
            prior_xs = stack_members([filters[i].x for i in index])
            xs, ps, checked = self._gain_numpy(prior_xs, p, pht, s_inv, w[0] if one else w)
            for (i, solved), x, p_new in zip(
                chosen, each_member(xs, one), each_member(ps, one), strict=True
            ):
                results[i] = filters[i].accept_update(sensor, solved[0], x, p_new, checked=checked)
        if tempering is not None:
            self.add_outcomes(results, tempering)  # type: ignore[arg-type]
        return results, jacobians, priors  # type: ignore[return-value]

    def _gain_update(
        self,
        x: FloatArray,
        p: FloatArray,
        pht: FloatArray,
        s_inv: Sequence[float],
        w: Sequence[float],
    ) -> tuple[FloatArray, FloatArray, bool]:
        """One member's update with the gain ``K = P H^T S^-1``: ``x + P H^T w`` (``w = S^-1
        y``), ``P - K (P H^T)^T`` made exactly symmetric, the consider states held, and whether
        both are finite and the covariance positive definite: in C
        (``MEMBER_CORE.update``), or, where it does not take them, :meth:`_gain_numpy`.
        ``pht`` is ``P H^T`` (n, m), ``s_inv`` ``S^-1`` (m*m, row-major), ``w`` (m)."""
        hold = self.consider
        start, stop, _ = (_HOLD_NONE if hold is None else hold).indices(len(x))
        x_new, p_new = EMPTY(x.shape), EMPTY(p.shape)
        checked = MEMBER_CORE.update(  # type: ignore[union-attr]
            x, p, pht, s_inv, w, start, stop, x_new, p_new
        )
        if checked is not None:
            return x_new, p_new, checked
        m = len(w)
        return self._gain_numpy(x, p, pht, np.array(s_inv).reshape(m, m), np.array(w))

    def _gain_numpy(
        self, prior_xs: FloatArray, p: FloatArray, pht: FloatArray, s_inv: FloatArray, w: FloatArray
    ) -> tuple[FloatArray, FloatArray, bool]:
        """The update of stacked members (or one member's arrays) with ``K = P H^T S^-1``
        (numpy; the reference of ``MEMBER_CORE.update``): states ``x + P H^T w``, covariances
        ``P - K (P H^T)^T`` made exactly symmetric, the consider states held, and whether all
        are finite and positive definite. ``pht`` (..., n, m), ``s_inv`` (..., m, m), ``w``
        (..., m)."""
        xs = prior_xs + apply_each(pht, w)
        ps = p - product(product(pht, s_inv), pht.swapaxes(-1, -2))
        ps = ps + ps.swapaxes(-1, -2)  # a new array: no copy of the overlapping operand
        ps *= 0.5
        if self.consider is not None:
            hold_consider(xs, ps, prior_xs, p, self.consider)
        return xs, ps, finite_and_definite(xs, ps)

    def update_scalar(
        self,
        sensor: str,
        z: float,
        measure: MeasurementFunction,
        r_variance: float,
        pseudo: Callable[[float, float], tuple[float, float]] | None = None,
        tempering: float | None = None,
    ) -> tuple[list[UpdateResult], list[FloatArray], list[FloatArray]]:
        """Fuse a scalar measurement ``z`` with noise ``r_variance`` into every member
        (``measure(x)`` gives ``(h(x) (1,), H (1, n))`` at a state array): ``P h``, the gain
        ``K = P h / s`` and ``P - K (P h)^T`` for all members in stacked arrays, the test and
        gate per member
        (:meth:`~tether_companion.estimation.dynamic.member.MemberFilter.test_scalar`).
        ``pseudo``, when given, maps each member's innovation ``y`` and ``s = H P H^T + R`` to
        the pair the update and its test use instead (an upper bound's truncation,
        :func:`~tether_companion.estimation.dynamic.truncation.pseudo_measurement`).
        With ``tempering``, each member's evidence of the sample is added
        (:meth:`add_outcomes`). Returns each member's outcome, Jacobian and prior covariance.

        Without ``pseudo``, where ``_member_core`` runs, all of it is one C call
        (:data:`FUSE_SCALAR`, as :meth:`update_force_balance`)."""
        filters = self.filters
        if FUSE_SCALAR is not None and pseudo is None:
            hold = self.consider
            start, stop, _ = (_HOLD_NONE if hold is None else hold).indices(_N)
            done = FUSE_SCALAR(
                filters, sensor, z, measure, r_variance, start, stop, EMPTY, UpdateResult, FUSED,
                GATED, None if tempering is None else self.log_weight, tempering,
            )  # fmt: skip
            if done is not None:
                return done  # type: ignore[no-any-return]
        priors = [kf.P for kf in filters]
        innovations = []
        jacobians = []
        for kf in filters:
            value, jacobian = measure(kf.x)
            innovations.append(z - float(value[0]))
            jacobians.append(jacobian)
        projected = project_each(priors, jacobians, 1)
        if projected is None:  # numpy: all members stacked
            p = stack_members(priors)
            rows = np.array(jacobians).reshape(p.shape[:-2] + (_N,))
            pht = apply_each(p, rows)
            s_values = ((pht * rows).sum(axis=-1) + r_variance).reshape(-1).tolist()
        else:
            phts = projected[0]
            s_values = [s[0] + r_variance for s in projected[1]]
        if pseudo is not None:
            pairs = [pseudo(y, s) for y, s in zip(innovations, s_values, strict=True)]
            innovations = [y for y, _ in pairs]
            s_values = [s for _, s in pairs]
        results: list[UpdateResult | None] = [
            kf.test_scalar(sensor, y, s)
            for kf, y, s in zip(filters, innovations, s_values, strict=True)
        ]
        index = [i for i, result in enumerate(results) if result is None]
        if index and projected is not None:  # member by member, in C
            for i in index:
                kf, s, y = filters[i], s_values[i], innovations[i]
                x, p_new, checked = self._gain_update(
                    kf.x, priors[i], phts[i], (1.0 / s,), (y / s,)
                )
                results[i] = kf.accept_update(sensor, y * y / s, x, p_new, checked=checked)
        elif index:
            if len(index) < len(filters):
                p, pht = p[index], pht[index]
            one = p.ndim == 2
            s_and_y = np.array([(s_values[i], innovations[i]) for i in index])
            s_and_y = s_and_y[0] if one else s_and_y
            gain = pht / s_and_y[..., :1]
            prior_xs = stack_members([filters[i].x for i in index])
            xs = prior_xs + gain * s_and_y[..., 1:]
            ps = p - gain[..., :, None] * pht[..., None, :]
            ps = ps + ps.swapaxes(-1, -2)  # a new array: no copy of the overlapping operand
            ps *= 0.5
            if self.consider is not None:
                hold_consider(xs, ps, prior_xs, p, self.consider)
            checked = finite_and_definite(xs, ps)
            for i, x, p_new in zip(index, each_member(xs, one), each_member(ps, one), strict=True):
                nis = innovations[i] * innovations[i] / s_values[i]
                results[i] = filters[i].accept_update(sensor, nis, x, p_new, checked=checked)
        if tempering is not None:
            self.add_outcomes(results, tempering)  # type: ignore[arg-type]
        return results, jacobians, priors  # type: ignore[return-value]

    def update_others(
        self, name: str, z: FloatArray, measure: MeasurementFunction, r: FloatArray
    ) -> None:
        """Fuse into every member but the best (the caller fuses the best with its status
        record) and add each member's log-likelihood of the sample."""
        best = self.best
        for i, kf in enumerate(self.filters):
            if kf is not best:
                log_det_s = log_det_innovation(kf.P, measure(kf.x)[1], r)
                result = kf.update(name, z, measure, r)
                self.add_evidence(i, result.nis, log_det_s)

    def add_outcomes(self, results: list[UpdateResult], tempering: float) -> None:
        """Add each member's tempered log-likelihood of the sample just fused into every member
        (``results`` in member order; the Gaussian's from each outcome's NIS and the member's
        ``log det S``, :meth:`add_evidence`); nothing with one member left."""
        if len(self.filters) == 1:
            return
        for i, (kf, result) in enumerate(zip(self.filters, results, strict=True)):
            self.add_evidence(i, result.nis, kf.last_log_det_s, tempering)

    def add_best_nis(self, nis: float, log_det_s: float) -> None:
        """The best member's NIS and ``log det S`` of the sample just fused."""
        self.add_evidence(self._best_index(), nis, log_det_s)

    def add_evidence(
        self,
        index: int,
        nis: float,
        log_det_s: float,
        tempering: float = LIKELIHOOD_TEMPERING,
    ) -> None:
        """Add member ``index``'s tempered Gaussian log-likelihood of one sample,
        ``-(NIS + log det S) / 2`` over ``tempering`` (the ``2 pi`` term is the same for
        every member); nothing when either is not finite (rejected sample)."""
        value = nis + log_det_s
        if math.isfinite(value):
            self.log_weight[index] -= 0.5 * value / tempering

    def drop_unhealthy(self, max_distance_m: float) -> None:
        """Drop members whose state is not finite or farther than ``max_distance_m``."""
        if len(self.filters) == 1:  # nothing to choose between: the caller restarts
            return
        limit = max_distance_m**2
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
        w = self.weights()
        best = int(np.argmax(w))
        if w[best] >= SELECT_WEIGHT:
            self.keep([best])  # other bearings rejected: not confirmed
        elif elapsed >= self.max_bank_s:
            self._reduce(w.tolist())

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


def project_each(
    priors: list[FloatArray], jacobians: Sequence[Sequence[float] | FloatArray], m: int
) -> tuple[list[FloatArray], list[Sequence[float]]] | None:
    """Each member's ``P H^T`` (n, m) and ``H P H^T`` (m*m, row-major) in C
    (``MEMBER_CORE.project``), or None (numpy then) when the extension does not run or does not
    take a member's arrays (``H`` (m*n) a list or tuple of numbers or a (m, n) float array)."""
    if MEMBER_CORE is None:
        return None
    phts, s_values = [], []
    for p, h_jac in zip(priors, jacobians, strict=True):
        pht = EMPTY((p.shape[0], m))
        s = MEMBER_CORE.project(p, h_jac, pht)
        if s is None:
            return None
        phts.append(pht)
        s_values.append(s)
    return phts, s_values


_X_ARRAY = attrgetter("_xa")
"""A member's state array as it holds it (None while it holds a list): what ``x`` returns when
it is not None, read without the property (:meth:`FilterBank.mixture`'s identity check)."""
_P_ARRAY = attrgetter("_pa")
"""A member's covariance array as it holds it (None while it holds a list)."""
_HOLD_NONE = slice(0, 0)
"""No consider state (``MEMBER_CORE.update``'s hold range)."""
FUSE_FORCE_BALANCE: Callable[..., tuple[list[UpdateResult], list, list[FloatArray]] | None] | None
FUSE_FORCE_BALANCE = getattr(MEMBER_CORE, "fuse_force_balance", None)
"""``_member_core.fuse_force_balance`` (bank_fusion.c) where the extension runs: the whole of
:meth:`FilterBank.update_force_balance` over the members (model, projection, ``S``'s test and
inverse, the gate and its counts, the gain's update, keeping it) bit for bit, None (nothing
changed) where it does not take the members (the Python above then runs). None without the
extension, ``TETHER_PURE_PYTHON=1``, or an extension built before it."""
FUSE_SCALAR: Callable[..., tuple[list[UpdateResult], list, list[FloatArray]] | None] | None
FUSE_SCALAR = getattr(MEMBER_CORE, "fuse_scalar", None)
"""``_member_core.fuse_scalar`` (bank_fusion.c): :meth:`FilterBank.update_scalar` without
``pseudo`` over the members in one call, as :data:`FUSE_FORCE_BALANCE`."""
