"""The undecided thrust-scale bank at max_bank_s: collapsed only where one Gaussian represents
its members (bank_reduction.py: the chord sagitta against each member's chord variance)."""

from __future__ import annotations

import math

import numpy as np

from tether_companion.estimation.dynamic import bank_reduction, state
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.ekf import ExtendedKalmanFilter

N = state.N_STATES
RADIUS_M = 4.0
"""The members' distance from the anchor [m] (the light 5 N circle's ~3.5-4 m)."""


def _at(bearing_deg: float, sd_m: float = 0.1, elevation_deg: float = 60.0) -> ExtendedKalmanFilter:
    """A member at ``bearing_deg`` / ``elevation_deg`` [deg], ``RADIUS_M`` from the anchor, each
    state's sd ``sd_m`` (a winch-measured chord: 0.1 m, drag21's members)."""
    b, e = math.radians(bearing_deg), math.radians(elevation_deg)
    x = np.zeros(N)
    x[state.POSITION] = RADIUS_M * np.array(
        (math.cos(e) * math.cos(b), math.cos(e) * math.sin(b), -math.sin(e))
    )
    return ExtendedKalmanFilter(x, np.eye(N) * sd_m**2, np.zeros((N, N)))


def _bank(members: list[ExtendedKalmanFilter], weights: list[float]) -> FilterBank:
    return FilterBank(members, 0.0, 6.0, log_priors=[math.log(w) for w in weights])


def test_the_sagitta_is_the_chord_the_linearisation_misses() -> None:
    """``r = |p| - u_m . p = |p| (1 - cos delta)``, over ``u^T P u``."""
    mean = _at(0.0).x
    member = _at(40.0, sd_m=0.2)
    (nis,) = bank_reduction.chord_nis(mean[:3].tolist(), [bank_reduction.chord(member.x, member.P)])
    # both at 60 deg elevation: the angle between them from the anchor
    cos_delta = float(mean[:3] @ member.x[:3]) / RADIUS_M**2
    sagitta = RADIUS_M * (1.0 - cos_delta)
    assert math.isclose(nis, sagitta**2 / 0.04, rel_tol=1e-12)


def test_members_far_apart_in_bearing_are_not_collapsed_at_max_bank_s() -> None:
    """drag21's seed 6: +130 and +31 deg at 0.60 / 0.40, radial sd 0.1 m; one Gaussian at their
    moments would be a drone inside the sphere by ~0.6 m: the bank runs on, the mixture
    published (the old rule collapsed it to +89 +- 49 deg)."""
    bank = _bank([_at(130.0), _at(31.0)], [0.6, 0.4])
    mean, cov = bank.mixture()
    bank.maybe_decide(6.5)
    assert len(bank.filters) == 2 and not bank.decided
    np.testing.assert_array_equal(bank.filters[0].x, _at(130.0).x)  # untouched
    published_mean, published_cov = bank.mixture()
    np.testing.assert_allclose(published_mean, mean)
    np.testing.assert_allclose(published_cov, cov)


def test_members_that_agree_still_collapse_to_their_moments() -> None:
    """Bearings 7 deg apart (the 4 N circle's collapses): the sagitta is ~1 cm at 0.1 m."""
    bank = _bank([_at(30.0), _at(37.0), _at(33.0)], [0.5, 0.3, 0.2])
    mean, cov = bank.mixture()
    bank.maybe_decide(6.5)
    assert bank.decided
    np.testing.assert_allclose(bank.best.x, mean, atol=1e-12)
    np.testing.assert_allclose(bank.best.P, cov, atol=1e-12)
    assert bank.best.resets == 0


def test_a_negligible_member_is_dropped_and_the_agreeing_rest_collapse() -> None:
    """A far member below DROP_WEIGHT (0.5 %) does not hold the bank open; the collapse is the
    moments of the members left (renormalised)."""
    near, near2, far = _at(30.0), _at(34.0), _at(150.0)
    expected = bank_reduction.moments([0.6, 0.395], [near.x, near2.x], [near.P, near2.P])
    bank = _bank([near, near2, far], [0.6, 0.395, 0.005])
    bank.maybe_decide(6.5)
    assert bank.decided
    np.testing.assert_allclose(bank.best.x, expected[0], atol=1e-12)
    np.testing.assert_allclose(bank.best.P, expected[1], atol=1e-12)


def test_two_modes_each_merge_and_run_on_with_their_summed_weights() -> None:
    """Two pairs that agree, the pairs 100 deg apart: two members left, each its pair's
    moments, weights summed (0.55 / 0.45)."""
    a1, a2, b1, b2 = _at(30.0), _at(35.0), _at(130.0), _at(134.0)
    expected_a = bank_reduction.moments([0.35, 0.2], [a1.x, a2.x], [a1.P, a2.P])
    bank = _bank([a1, b1, a2, b2], [0.35, 0.25, 0.2, 0.2])
    bank.maybe_decide(6.5)
    assert len(bank.filters) == 2
    np.testing.assert_allclose(bank.weights(), [0.55, 0.45], rtol=1e-12)
    np.testing.assert_allclose(bank.filters[0].x, expected_a[0], atol=1e-12)
    np.testing.assert_allclose(bank.filters[0].P, expected_a[1], atol=1e-12)
    assert bank.filters[0].resets == 0


def test_the_bank_runs_on_until_the_data_decide() -> None:
    """Kept past max_bank_s, the bank still selects a member when the data pass SELECT_WEIGHT,
    and collapses when the members come to agree."""
    bank = _bank([_at(130.0), _at(31.0)], [0.6, 0.4])
    bank.maybe_decide(6.5)
    bank.log_weight[1] -= 10.0
    bank.maybe_decide(7.0)
    assert bank.decided and bank.best.x[1] > 0.0 and bank.best.x[0] < 0.0  # the +130 member
    bank = _bank([_at(130.0), _at(31.0)], [0.6, 0.4])
    bank.maybe_decide(6.5)
    bank.filters[1].x = _at(128.0).x  # the data brought it there
    bank.maybe_decide(7.0)
    assert bank.decided


def test_an_unresolved_chord_lets_far_members_collapse() -> None:
    """No length (the angle alone early): a chord sd of 2 m holds a 100 deg spread."""
    bank = _bank([_at(130.0, sd_m=2.0), _at(31.0, sd_m=2.0)], [0.6, 0.4])
    bank.maybe_decide(6.5)
    assert bank.decided


def test_the_scalar_chord_test_is_the_moments_mean_in_arrays() -> None:
    """The re-test reads each member's chord once and a trial set's mean position only: its
    NIS equal (to rounding) the sagitta computed in arrays at the mixture moments' mean, for
    random members (seeded) across the threshold."""
    rng = np.random.default_rng(7)
    passed = 0
    for _ in range(200):
        members = [
            _at(rng.uniform(-180.0, 180.0), rng.uniform(0.02, 1.0), rng.uniform(10.0, 80.0))
            for _ in range(int(rng.integers(2, 5)))
        ]
        weights = rng.uniform(0.05, 1.0, len(members)).tolist()
        xs, ps = [kf.x for kf in members], [kf.P for kf in members]
        mean = bank_reduction.moments(weights, xs, ps)[0][:3]
        expected = []
        for x, p in zip(xs, ps, strict=True):
            u = x[:3] / np.linalg.norm(x[:3])
            sagitta = np.linalg.norm(x[:3]) - float(mean @ x[:3]) / np.linalg.norm(mean)
            expected.append(sagitta**2 / float(u @ p[:3, :3] @ u))
        chords = [bank_reduction.chord(x, p) for x, p in zip(xs, ps, strict=True)]
        total = sum(weights)
        scalar_mean = [
            sum(w / total * c.position[k] for w, c in zip(weights, chords, strict=True))
            for k in range(3)
        ]
        np.testing.assert_allclose(
            bank_reduction.chord_nis(scalar_mean, chords), expected, rtol=1e-9, atol=1e-12
        )
        represented = all(v <= bank_reduction.threshold() for v in expected)
        threshold = bank_reduction.threshold()
        assert bank_reduction.one_gaussian(weights, chords, threshold) is represented
        passed += represented
    assert 10 < passed < 190  # both outcomes exercised
