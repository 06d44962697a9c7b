"""The thrust-scale filter bank: mixture moments, selection, collapse, dropping members."""

from __future__ import annotations

import numpy as np

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.aiding import AidStatus, fuse
from tether_companion.estimation.dynamic.bank import (
    MERGE_DISTANCE_M,
    FilterBank,
    log_det_innovation,
)
from tether_companion.estimation.ekf import ExtendedKalmanFilter

N = state.N_STATES


def _member(offset: float) -> ExtendedKalmanFilter:
    x = np.zeros(N)
    x[state.POSITION] = (2.0 + offset, 0.0, -2.0)
    return ExtendedKalmanFilter(x, np.eye(N) * 0.01, np.zeros((N, N)))


def _direct(xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    jac = np.zeros((1, N))
    jac[0, 0] = 1.0
    return np.array((xs[0],)), jac


def test_mixture_covariance_holds_the_spread_between_members() -> None:
    bank = FilterBank([_member(-0.5), _member(0.5)], start_s=0.0, max_bank_s=30.0)
    mean, cov = bank.mixture()
    assert mean[0] == 2.0
    assert cov[0, 0] == 0.01 + 0.25  # own variance + spread
    np.testing.assert_allclose(cov, cov.T)


def test_the_mixture_is_kept_while_every_member_holds_the_same_arrays() -> None:
    """The moments are reused while each member's state and covariance are the same objects
    and the weights the same, and recomputed when either array of one member is replaced, a
    member holds its values as lists (the scalar path), or a weight moves."""
    left, right = _member(-0.5), _member(0.5)
    bank = FilterBank([left, right], start_s=0.0, max_bank_s=30.0)
    mean, cov = bank.mixture()
    assert all(a is b for a, b in zip(bank.mixture(), (mean, cov), strict=True))
    right.P = right.P * 2.0  # the covariance alone replaced
    _, cov2 = bank.mixture()
    assert cov2[0, 0] == 0.5 * (0.01 + 0.02) + 0.25
    right.x = right.x + 1.0  # the state alone replaced
    mean3, cov3 = bank.mixture()
    assert mean3[0] == 2.5
    right._lists()  # the same values as lists: no array to compare, recomputed equal
    mean4, cov4 = bank.mixture()
    assert mean4 is not mean3
    assert mean4.tobytes() == mean3.tobytes() and cov4.tobytes() == cov3.tobytes()
    assert bank.mixture()[0] is mean4
    bank.log_weight[0] -= 1.0
    assert bank.mixture()[0][0] > 2.5


def test_the_member_the_data_favour_is_kept() -> None:
    bank = FilterBank([_member(-0.5), _member(0.0), _member(0.5)], start_s=0.0, max_bank_s=30.0)
    for k in range(400):
        best = bank.update_others("x", np.array((2.5,)), _direct, np.array([[0.01]]))
        result = bank.filters[best].update("x", np.array((2.5,)), _direct, np.array([[0.01]]))
        bank.add_evidence(best, result.nis, 0.0)
        bank.maybe_decide(0.1 * k)
    assert bank.decided
    assert bank.best.x[0] > 2.4


def test_undecided_bank_collapses_to_its_moments() -> None:
    bank = FilterBank([_member(-0.5), _member(0.5)], start_s=0.0, max_bank_s=30.0)
    mean, cov = bank.mixture()
    bank.maybe_decide(31.0)
    assert bank.decided
    np.testing.assert_allclose(bank.best.x, mean)
    np.testing.assert_allclose(bank.best.P, cov)
    assert bank.best.resets == 0


def test_members_far_away_or_not_finite_are_dropped() -> None:
    far, nan_member = _member(0.0), _member(0.0)
    far.x = far.x.copy()
    far.x[0] = 5000.0
    nan_member.x = nan_member.x.copy()
    nan_member.x[1] = np.nan
    bank = FilterBank([_member(0.0), far, nan_member], start_s=0.0, max_bank_s=30.0)
    bank.drop_unhealthy(1000.0)
    assert bank.decided and bank.best.x[0] == 2.0


def test_a_wide_member_pays_for_its_width() -> None:
    """Same mean, same innovations: the member whose covariance is metres wide explains them
    no better and loses weight through ``log det S`` (its NIS alone is the smaller)."""
    narrow, wide = _member(0.0), _member(0.0)
    wide.P = np.eye(N) * 25.0
    bank = FilterBank([narrow, wide], start_s=0.0, max_bank_s=30.0)
    for _ in range(20):
        best = bank.update_others("x", np.array((2.05,)), _direct, np.array([[0.01]]))
        kf = bank.filters[best]
        log_det_s = log_det_innovation(kf.P, _direct(kf.x)[1], np.array([[0.01]]))
        result = kf.update("x", np.array((2.05,)), _direct, np.array([[0.01]]))
        bank.add_evidence(best, result.nis, log_det_s)
    weights = bank.weights()
    assert weights[0] > weights[1]


def _across(offset_m: float) -> ExtendedKalmanFilter:
    """A member at (2, offset, -2): another bearing from the anchor."""
    kf = _member(0.0)
    kf.x = kf.x.copy()
    kf.x[1] = offset_m
    return kf


def test_a_bearing_the_data_reject_is_dropped_without_confirming_the_other() -> None:
    """Two bearings: the other one's weight falls below DROP_WEIGHT and it goes (before
    MIN_BANK_S: rejection needs no waiting); that a far bearing is wrong does not make the
    one left right (the 2 N circle: 1 m off across the cable after its ring was rejected)."""
    bank = FilterBank(
        [_member(0.0), _across(1.5)], 0.0, 30.0, log_priors=[0.0, -2.0], bearings=[0, 1]
    )
    bank.maybe_decide(0.1)
    assert not bank.bearing_confirmed and len(bank.filters) == 2  # prior 0.12: kept
    bank.log_weight[1] = -6.0  # the data's verdict: weight 0.25 %
    bank.maybe_decide(0.2)
    assert bank.decided and not bank.bearing_confirmed and bank.best.x[1] == 0.0


def test_a_bearing_that_converged_to_the_best_is_dropped_and_confirms_it() -> None:
    """Started elsewhere, brought within MERGE_DISTANCE_M of the best by the data: the same
    bearing, whatever its weight; the data, not the start, chose it."""
    bank = FilterBank(
        [_member(0.0), _across(MERGE_DISTANCE_M * 0.9)],
        0.0,
        30.0,
        log_priors=[0.0, -0.1],
        bearings=[0, 1],
    )
    bank.maybe_decide(0.1)
    assert bank.decided and bank.bearing_confirmed


def test_bearings_left_undecided_collapse_unconfirmed() -> None:
    """A steady hover does not tell the bearings apart: the bank collapses by time and the
    bearing is not confirmed (the mixture's spread stays in the collapsed covariance)."""
    bank = FilterBank(
        [_member(0.0), _across(1.5)], 0.0, 6.0, log_priors=[0.0, -0.5], bearings=[0, 1]
    )
    _, cov = bank.mixture()
    bank.maybe_decide(6.5)
    assert bank.decided and not bank.bearing_confirmed
    assert bank.best.P[1, 1] == cov[1, 1] > 0.4  # the bearings' spread


def test_thrust_members_of_one_bearing_do_not_confirm_it() -> None:
    bank = FilterBank([_member(-0.5), _member(0.5)], 0.0, 30.0)
    bank.log_weight[1] = -10.0
    bank.maybe_decide(3.5)
    assert bank.decided and not bank.bearing_confirmed


def _both(xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """North and east position: a two-row reading (the cable angle's path through
    :func:`aiding.fuse`)."""
    jac = np.zeros((2, N))
    jac[0, 0] = jac[1, 1] = 1.0
    return np.array((xs[0], xs[1])), jac


def test_a_sample_that_makes_another_member_the_best_is_fused_once_into_each() -> None:
    """The best member (by a little) explains a two-row sample far worse than the other: the
    other's evidence makes it the best before the best is fused. Each member still takes the
    sample once, as a lone filter would (the best was re-read after the others' update: the
    new best took the sample twice and the old one never, paper circle seed 2 at 3 s)."""
    first, second = _member(-0.5), _member(0.5)
    bank = FilterBank([first, second], start_s=0.0, max_bank_s=30.0)
    bank.log_weight[0] += 0.1
    assert bank.best is first
    z, r = np.array((2.5, 0.0)), np.eye(2) * 0.01
    alone = [_member(-0.5), _member(0.5)]
    for kf in alone:
        kf.update("xy", z, _both, r)
    fuse(bank, "xy", AidStatus(), z, _both, r, 0.0)
    assert bank.best is second  # the evidence moved the weights
    for member, reference in zip(bank.filters, alone, strict=True):
        np.testing.assert_allclose(member.x, reference.x, atol=1e-12)
        np.testing.assert_allclose(member.P, reference.P, atol=1e-12)
