"""The bank's fusion of a reading into every member, and the members' evidence of it.

:class:`BankUpdates` is the part of :class:`~tether_companion.estimation.dynamic.bank.
FilterBank` that fuses one sample into all its members (a 3-axis force balance or a scalar:
the projection ``P H^T``, ``S``, the test and gate per member, the gain's update with the
consider states held) and adds each member's tempered log-likelihood of it; the bank's
hypotheses (weights, selection, reduction, mixture) are in ``bank``. Where the ``_member_core``
extension runs, each fusion over the members is one C call (bank_fusion.c), bit for bit the
Python here, which stays the reference and the fallback.

Pure and synchronous.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from itertools import chain

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bank_arrays import (
    EMPTY,
    apply_each,
    each_member,
    finite_and_definite,
    stack_members,
)
from tether_companion.estimation.dynamic.imu_batch import MEMBER_CORE, product
from tether_companion.estimation.dynamic.member import MemberFilter, hold_consider
from tether_companion.estimation.ekf import FUSED, GATED, MeasurementFunction, UpdateResult

FloatArray = NDArray[np.float64]
RowsFunction = Callable[[list[float]], tuple[Sequence[float], Sequence[float]]]
"""``measure(x) -> (h(x) (m,), H (m*n row-major))`` at the state ``x`` (a list)."""

_N = state.N_STATES

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


class BankUpdates:
    """The fusion of a sample into every member of a bank and the members' evidence of it
    (a base of :class:`~tether_companion.estimation.dynamic.bank.FilterBank`, which holds
    the attributes below)."""

    filters: list[MemberFilter]
    """The members."""
    consider: slice | None
    """The states every member holds as consider states."""
    log_weight: list[float]
    """Each member's tempered log-likelihood so far plus its log prior."""

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

    def add_outcomes(self, results: list[UpdateResult], tempering: float) -> None:
        """Add each member's tempered log-likelihood of the sample just fused into every member
        (``results`` in member order; the Gaussian's from each outcome's NIS and the member's
        ``log det S``, :meth:`add_evidence`); nothing with one member left."""
        if len(self.filters) == 1:
            return
        for i, (kf, result) in enumerate(zip(self.filters, results, strict=True)):
            self.add_evidence(i, result.nis, kf.last_log_det_s, tempering)

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
