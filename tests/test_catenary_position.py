"""Position from tension and catenary (Martins 2019 section 6): estimator and geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.config import ConfigError, from_mapping
from tether_companion.estimation.catenary_position import (
    INCONSISTENT,
    KNOWN_LENGTH,
    LOWEST_POINT_AT_ANCHOR,
    NO_LENGTH,
    NO_TENSION,
    OK,
    STALE_TENSION,
    UNOBSERVABLE,
    WEAK_PULL,
    CatenaryPositionConfig,
    CatenaryPositionEstimator,
    force_from_position_ned_n,
    position_from_force_ned_m,
    position_jacobian,
)
from tether_companion.estimation.tension_budget import BUDGET_COLUMNS
from tether_companion.estimation.tension_kf import TensionEstimate, TensionHealth
from tether_companion.physics.cable import CatenaryCable, ElasticCable
from tether_companion.physics.catenary import solve_known_length, solve_lowest_point_at_anchor
from tether_companion.physics.catenary_forces import end_tensions, force_on_drone_ned_n

W = 0.05 * 9.80665  # N/m


def _estimate(force, time_s=1.0, last_update_s=1.0, variance=0.01, factor=None):
    extra = {} if factor is None else {"consider_factor_n": np.asarray(factor, dtype=float)}
    return TensionEstimate(
        time_s=time_s,
        tension_ned_n=np.asarray(force, dtype=float),
        variance_n2=variance,
        last_update_s=last_update_s,
        observation_ned_n=np.asarray(force, dtype=float),
        updated=True,
        health=TensionHealth(),
        **extra,
    )


def _sim_cable(length_m):
    """The simulator's catenary cable (independent implementation, ground contact), made
    practically inextensible."""
    elastic = ElasticCable(length_m, 1e9, 0.0, W / 9.80665)
    return CatenaryCable(elastic, W / 9.80665)


@pytest.mark.parametrize(
    "position",
    [
        (4.0, 0.0, -3.0),
        (2.0, -3.0, -1.0),
        (-3.0, 2.5, -6.0),
        (0.5, 0.2, -4.5),
    ],
)
@pytest.mark.parametrize("slack", [1.001, 1.04, 1.3])
def test_known_length_free_cable_round_trip(position, slack):
    """Thesis case 2 (anchor above the lowest point, free curve) inverts exactly; with the
    anchor on the ground the same holds whenever the lowest point is behind the anchor."""
    p = np.array(position)
    length = slack * np.linalg.norm(p)
    force = force_on_drone_ned_n(p, length, W)
    got = position_from_force_ned_m(force, KNOWN_LENGTH, W, length, anchor_on_ground=False)
    assert np.allclose(got, p, atol=1e-7)
    if solve_known_length(math.hypot(p[0], p[1]), -p[2], length).s1_m >= 0.0:
        got = position_from_force_ned_m(force, KNOWN_LENGTH, W, length, anchor_on_ground=True)
        assert np.allclose(got, p, atol=1e-7)


@pytest.mark.parametrize(
    ("position", "length"),
    [((4.0, 0.0, -3.0), 6.5), ((3.0, 3.0, -2.0), 5.5), ((-1.0, 0.0, -5.0), 5.8)],
)
def test_known_length_grounded_cable_against_simulator_cable(position, length):
    """A slack cable lying on the ground near the anchor: the estimator's grounded branch
    inverts the simulator's CatenaryCable force (written independently)."""
    p = np.array(position)
    cable = _sim_cable(length)
    force = np.array(cable.force_on_drone_ned_n(p, np.zeros(3)))
    assert length >= solve_lowest_point_at_anchor(math.hypot(*p[:2]), -p[2]).length_m
    got = position_from_force_ned_m(force, KNOWN_LENGTH, W, length, anchor_on_ground=True)
    assert np.allclose(got, p, atol=1e-6)
    # the thesis' free case 2 (anchor above the lowest point) would misplace it
    free = position_from_force_ned_m(force, KNOWN_LENGTH, W, length, anchor_on_ground=False)
    assert np.linalg.norm(free - p) > 0.1


def test_known_length_taut_cable_against_simulator_cable():
    p = np.array([4.0, 0.0, -3.0])
    cable = _sim_cable(5.2)
    force = np.array(cable.force_on_drone_ned_n(p, np.zeros(3)))
    got = position_from_force_ned_m(force, KNOWN_LENGTH, W, 5.2)
    assert np.allclose(got, p, atol=1e-5)


def test_lowest_point_at_anchor_round_trip():
    p = np.array([3.0, -4.0, -2.0])
    curve = solve_lowest_point_at_anchor(5.0, 2.0)
    t = end_tensions(curve, W)
    pull = t.horizontal_n
    force = np.array([-pull * 3.0 / 5.0, pull * 4.0 / 5.0, -t.on_drone_vertical_n])
    got = position_from_force_ned_m(force, LOWEST_POINT_AT_ANCHOR, W)
    assert np.allclose(got, p, atol=1e-9)


def test_vertical_takeoff_limits():
    """No horizontal pull: straight above the anchor (eqs. 63-64, 70-71)."""
    got = position_from_force_ned_m(np.array([0.0, 0.0, 2.0 * W]), LOWEST_POINT_AT_ANCHOR, W)
    assert np.allclose(got, [0.0, 0.0, -2.0])
    got = position_from_force_ned_m(np.array([0.0, 0.0, 3.0 * W]), KNOWN_LENGTH, W, 5.0, False)
    assert np.allclose(got, [0.0, 0.0, -1.0])  # z = |s2| - |s1| = 3 - 2


def test_grounded_cable_without_horizontal_pull_is_unobservable():
    """Enough cable to lie on the ground and rise straight up: the pull is vertical and says
    nothing about where the drone is horizontally."""
    p = np.array([3.0, 3.0, -2.0])
    cable = _sim_cable(8.0)
    force = np.array(cable.force_on_drone_ned_n(p, np.zeros(3)))
    assert math.hypot(force[0], force[1]) == 0.0
    est = CatenaryPositionEstimator(CatenaryPositionConfig(weight_per_length_n_per_m=W))
    est.set_paid_out_length_m(8.0, 1.0)
    assert est.on_tension(_estimate(force)).status == UNOBSERVABLE


def _sensitivity(force, length, weight, h):
    """Position sensitivities [m per unit input] to the force axes, the length and the weight
    per length, by central differences of step ``h`` (relative for length and weight)."""

    def pos(f=force, length_m=length, w=weight):
        return position_from_force_ned_m(f, KNOWN_LENGTH, w, length_m)

    cols = [(pos(f=force + h * e) - pos(f=force - h * e)) / (2 * h) for e in np.eye(3)]
    cols.append(
        (pos(length_m=length * (1 + h)) - pos(length_m=length * (1 - h))) / (2 * h * length)
    )
    cols.append((pos(w=weight * (1 + h)) - pos(w=weight * (1 - h))) / (2 * h * weight))
    return np.column_stack(cols)


@pytest.mark.parametrize(
    ("force", "case", "length", "on_ground"),
    [
        ((-3.0, 1.0, 2.0), KNOWN_LENGTH, 5.0, True),  # free, lowest point behind the anchor
        ((-0.3, 0.1, 0.5), KNOWN_LENGTH, 7.0, True),  # grounded: lies on the ground, rises
        ((-0.3, 0.1, 0.5), KNOWN_LENGTH, 7.0, False),  # the same force, free case 2
        ((-2.0, -1.0, -0.5), KNOWN_LENGTH, 4.0, False),  # drone below the anchor
        ((0.4, -0.2, 3.0), KNOWN_LENGTH, 6.0, True),  # steep and heavy
        ((-1.0, 0.5, 0.7), LOWEST_POINT_AT_ANCHOR, math.nan, True),
    ],
)
def test_position_jacobian_is_the_finite_difference_of_the_geometry(force, case, length, on_ground):
    """The closed-form Jacobian (force, length, weight) against central differences of
    position_from_force_ned_m (step 1e-6 relative: truncation and rounding ~1e-8)."""
    f = np.array(force)

    def pos(f=f, length_m=length, w=W):
        return position_from_force_ned_m(f, case, w, length_m, on_ground)

    h = 1e-6
    step = h * np.linalg.norm(f)
    cols = [(pos(f=f + step * e) - pos(f=f - step * e)) / (2 * step) for e in np.eye(3)]
    if case == KNOWN_LENGTH:
        cols.append(
            (pos(length_m=length * (1 + h)) - pos(length_m=length * (1 - h))) / (2 * h * length)
        )
    else:
        cols.append(np.zeros(3))
    cols.append((pos(w=W * (1 + h)) - pos(w=W * (1 - h))) / (2 * h * W))
    numeric = np.column_stack(cols)
    analytic = position_jacobian(f, case, W, length, on_ground)
    np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-7 * np.abs(numeric).max())


def test_position_jacobian_is_continuous_where_the_cable_leaves_the_ground():
    """At s2 = L the grounded and the free branch meet with equal first derivatives."""
    length = 6.0
    on_branch = np.array([-0.5, 0.3, W * length])
    below = position_jacobian(on_branch * [1, 1, 1 - 1e-9], KNOWN_LENGTH, W, length)
    above = position_jacobian(on_branch * [1, 1, 1 + 1e-9], KNOWN_LENGTH, W, length)
    np.testing.assert_allclose(below, above, rtol=1e-6, atol=1e-6)


def test_position_jacobian_needs_a_horizontal_pull():
    with pytest.raises(ValueError, match="horizontal pull"):
        position_jacobian(np.array([0.0, 0.0, 2.0]), KNOWN_LENGTH, W, 5.0)


def test_weak_pull_against_its_uncertainty_is_withheld_with_its_position():
    """The same geometry published with a small force error, weak_pull with an error across
    the pull as large as 0.4 of the pull (max_azimuth_std_rad 0.35); still a position, with
    its covariance inflated by r^2 horizontally (for scoring). No horizontal pull at all:
    weak_pull without a position."""
    p = np.array([4.0, 1.0, -3.0])
    length = 5.1
    est = CatenaryPositionEstimator(
        CatenaryPositionConfig(case=KNOWN_LENGTH, weight_per_length_n_per_m=W)
    )
    est.set_paid_out_length_m(length, 0.5)
    force = force_on_drone_ned_n(p, length, W)
    horizontal = math.hypot(force[0], force[1])
    across = np.array([-force[1], force[0], 0.0]) / horizontal
    factor = np.zeros((3, BUDGET_COLUMNS))
    factor[:, 1] = 0.1 * horizontal * across
    ok = est.on_tension(_estimate(force, variance=1e-6, factor=factor))
    assert ok.status == OK and ok.azimuth_std_rad == pytest.approx(0.1, rel=1e-3)
    factor[:, 1] *= 4.0
    weak = est.on_tension(_estimate(force, variance=1e-6, factor=factor))
    assert weak.status == WEAK_PULL and not weak.valid
    assert np.allclose(weak.position_ned_m, p, atol=1e-6)
    lateral = across @ weak.covariance_m2 @ across  # r s_psi, plus r on each horizontal axis
    r = math.hypot(4.0, 1.0)
    assert lateral == pytest.approx((r * 0.4) ** 2 + r**2, rel=0.02)
    none = est.on_tension(_estimate([0.0, 0.0, 3.0]))  # hangs straight down: w L = 2.5 N
    assert none.status == WEAK_PULL and not np.isfinite(none.position_ned_m).any()


@pytest.mark.parametrize(
    ("force", "length"),
    [
        ((-0.8, 0.0, 0.3), 7.0),  # 5.2 m of 7 on the ground: the range barely moves at F ...
        ((-2.0, 0.5, 0.2), 5.0),  # ... and a nearly flat cable: the height barely moves
    ],
)
def test_covariance_counts_the_curvature_the_jacobian_misses(force, length):
    """Force errors of 0.1 N per axis on geometries that curve over that range: the Jacobian
    alone gives a NEES of hundreds (measured: 1620 and 9279), the covariance with the
    linearisation's residual a NEES of 3 +- 0.3 over 4000 draws (the draws the geometry
    cannot explain, < 3 %, left out)."""
    rng = np.random.default_rng(1)
    sigma_f = 0.1
    cfg = CatenaryPositionConfig(
        weight_per_length_n_per_m=0.164,
        length_std_m=1e-6,
        weight_per_length_rel_std=1e-6,
        min_position_std_m=1e-4,
    )
    est = CatenaryPositionEstimator(cfg)
    est.set_paid_out_length_m(length, 1.0)
    f = np.array(force)
    out = est.on_tension(_estimate(f, variance=sigma_f**2))
    assert out.status == OK
    errors = []
    for _ in range(4000):
        try:
            drawn = position_from_force_ned_m(
                f + sigma_f * rng.standard_normal(3), KNOWN_LENGTH, 0.164, length
            )
        except ValueError:
            continue
        errors.append(drawn - out.position_ned_m)
    err = np.array(errors)
    assert len(err) > 3880

    def mean_nees(covariance):
        return float(np.einsum("ij,ij->i", err, np.linalg.solve(covariance, err.T).T).mean())

    jacobian = position_jacobian(f, KNOWN_LENGTH, 0.164, length)[:, :3]
    assert mean_nees(sigma_f**2 * jacobian @ jacobian.T + 1e-8 * np.eye(3)) > 100.0
    assert mean_nees(out.covariance_m2) == pytest.approx(3.0, abs=0.3)


def test_estimator_outputs_position_and_covariance():
    """P = s_T^2 J_f J_f^T + s_L^2 j_L j_L^T + (s_w w)^2 j_w j_w^T + s_min^2 I, with the
    Jacobians checked against a coarser independent difference."""
    p = np.array([4.0, 1.0, -3.0])
    length = 5.1
    cfg = CatenaryPositionConfig(case=KNOWN_LENGTH, weight_per_length_n_per_m=W)
    est = CatenaryPositionEstimator(cfg)
    assert solve_known_length(math.hypot(4.0, 1.0), 3.0, length).s1_m > 0.0  # free hanging
    est.set_paid_out_length_m(length, 0.5)
    force = force_on_drone_ned_n(p, length, W)
    out = est.on_tension(_estimate(force))
    assert out.valid and np.allclose(out.position_ned_m, p, atol=1e-6)
    cov = out.covariance_m2
    assert np.array_equal(cov, cov.T)
    jac = _sensitivity(force, length, W, 1e-3)
    scale = np.diag([0.1, 0.1, 0.1, cfg.length_std_m, cfg.weight_per_length_rel_std * W])
    expected = jac @ scale**2 @ jac.T + cfg.min_position_std_m**2 * np.eye(3)
    np.testing.assert_allclose(cov, expected, rtol=2e-3, atol=1e-8)


@pytest.mark.parametrize(
    ("force", "length", "variance"),
    [
        # measured on realistic-low-tension (seed 1): a 3.2 m cable almost all on the ground,
        # the drone's range pinned at L by the geometry; the force-only covariance had a
        # smallest eigenvalue 1e-11 of its largest (negative NEES after rounding)
        ((0.06308302, 0.03633717, 0.00406604), 3.2069294601828564, 0.0103),
        ((0.5, -0.2, 0.05), 6.0, 1e-4),  # grounded, nearly slack
        ((0.0, 0.0, 0.4), 3.0, 1e-4),  # hanging straight down: no horizontal pull ...
    ],
)
def test_covariance_is_positive_definite_where_the_force_alone_pins_a_direction(
    force, length, variance
):
    w = 0.163771055
    est = CatenaryPositionEstimator(
        CatenaryPositionConfig(case=KNOWN_LENGTH, weight_per_length_n_per_m=w)
    )
    est.set_paid_out_length_m(length, 1.0)
    out = est.on_tension(_estimate(force, variance=variance))
    if out.status == UNOBSERVABLE:  # ... is refused when the cable lies on the ground
        assert force[0] == force[1] == 0.0
        return
    # the measured case's pull (0.073 N) is as weak as its error (0.1 N): weak_pull, its
    # position and covariance given all the same
    assert out.status == (WEAK_PULL if variance > 1e-3 else OK)
    cov = out.covariance_m2
    assert np.array_equal(cov, cov.T)
    np.linalg.cholesky(cov)  # positive definite
    eig = np.linalg.eigvalsh(cov)
    assert eig[0] >= est.config.min_position_std_m**2 * (1 - 1e-9)
    force_only = _sensitivity(np.asarray(force), length, w, 1e-5)[:, :3]
    force_eig = np.linalg.eigvalsh(variance * force_only @ force_only.T)
    assert force_eig[0] < 1e-6 * force_eig[2]  # what the old J Sigma J^T was: near singular


@pytest.mark.parametrize(
    ("position", "length"),
    [((4.0, 1.0, -3.0), 5.1), ((3.0, 3.0, -2.0), 5.5), ((2.0, 1.0, -1.0), 2.5)],
)
def test_covariance_is_consistent_with_monte_carlo_of_its_inputs(position, length):
    """Force (white part and consider budget), length and weight drawn from the distributions
    the estimator assumes (small enough for the linearisation): the positions' NEES against
    its covariance averages 3 (4000 draws: sd of the mean 0.04) and the sample covariance
    matches it."""
    rng = np.random.default_rng(11)
    cfg = CatenaryPositionConfig(
        case=KNOWN_LENGTH,
        weight_per_length_n_per_m=W,
        length_std_m=0.01,
        weight_per_length_rel_std=0.01,
        min_position_std_m=1e-4,
    )
    force = force_on_drone_ned_n(np.array(position), length, W)
    sigma_f = 0.001
    factor = 0.002 * rng.standard_normal((3, BUDGET_COLUMNS))  # the tension's consider budget
    est = CatenaryPositionEstimator(cfg)
    est.set_paid_out_length_m(length, 1.0)
    out = est.on_tension(_estimate(force, variance=sigma_f**2, factor=factor))
    assert out.valid
    draws = 4000
    samples = np.empty((draws, 3))
    for i in range(draws):
        samples[i] = position_from_force_ned_m(
            force + sigma_f * rng.standard_normal(3) + factor @ rng.standard_normal(BUDGET_COLUMNS),
            KNOWN_LENGTH,
            W * (1 + cfg.weight_per_length_rel_std * rng.standard_normal()),
            length + cfg.length_std_m * rng.standard_normal(),
        ) + cfg.min_position_std_m * rng.standard_normal(3)
    err = samples - out.position_ned_m
    values = np.einsum("ij,ij->i", err, np.linalg.solve(out.covariance_m2, err.T).T)
    assert float(values.mean()) == pytest.approx(3.0, abs=0.15)
    sample_cov = np.cov(err.T)
    scale = np.sqrt(np.diag(out.covariance_m2))
    np.testing.assert_allclose(
        sample_cov / np.outer(scale, scale),
        out.covariance_m2 / np.outer(scale, scale),
        atol=0.08,
    )


def test_estimator_refuses_bad_inputs():
    cfg = CatenaryPositionConfig(
        case=KNOWN_LENGTH, weight_per_length_n_per_m=W, max_tension_age_s=0.3, max_length_age_s=2.0
    )
    est = CatenaryPositionEstimator(cfg)
    good = force_on_drone_ned_n(np.array([3.0, 0.0, -3.0]), 5.0, W)
    assert est.on_tension(_estimate([math.nan, 0.0, 1.0])).status == NO_TENSION
    assert est.on_tension(_estimate(good, time_s=2.0, last_update_s=1.0)).status == STALE_TENSION
    est.set_paid_out_length_m(5.0, 0.0)
    assert est.on_tension(_estimate(good, time_s=3.0, last_update_s=3.0)).status == NO_LENGTH
    est.set_paid_out_length_m(-1.0, 3.0)
    est.set_paid_out_length_m(math.nan, 3.0)
    assert est.rejected >= 2 and est.length_m == 5.0
    est.set_paid_out_length_m(5.0, 3.0)
    assert est.on_tension(_estimate(good, time_s=3.0, last_update_s=3.0)).valid
    # cable pulling the drone up with the anchor on the ground: geometry cannot explain it
    out = est.on_tension(_estimate([-1.0, 0.0, -2.0], time_s=3.0, last_update_s=3.0))
    assert out.status == INCONSISTENT and not np.isfinite(out.position_ned_m).any()
    case1 = CatenaryPositionEstimator(CatenaryPositionConfig(case=LOWEST_POINT_AT_ANCHOR))
    assert case1.on_tension(_estimate([-1.0, 0.0, -0.5])).status == INCONSISTENT


@pytest.mark.parametrize(
    ("key", "value"),
    [("weight_per_length_n_per_m", 0.0), ("case", "both"), ("max_tension_age_s", -1.0)],
)
def test_config_bad_values(key, value):
    with pytest.raises(ConfigError):
        from_mapping(CatenaryPositionConfig, {key: value}, source="catenary.yaml")


@pytest.mark.parametrize(
    ("position", "length"),
    [
        ((4.0, 0.0, -3.0), 5.2),  # free hanging, lowest point behind the anchor
        ((3.0, 3.0, -2.0), 5.5),  # partly on the ground
        ((-1.0, 0.0, -5.0), 5.8),
        ((3.0, 3.0, -2.0), 8.0),  # on the ground, then straight up
        ((2.0, 1.0, -1.0), 2.5),
    ],
)
def test_forward_force_matches_simulator_cable_and_inverts(position, length):
    p = np.array(position)
    want = np.array(_sim_cable(length).force_on_drone_ned_n(p, np.zeros(3)))
    got = force_from_position_ned_n(p, length, W)
    assert np.allclose(got, want, atol=1e-7)
    if math.hypot(got[0], got[1]) > 0.0:
        assert np.allclose(position_from_force_ned_m(got, KNOWN_LENGTH, W, length), p, atol=1e-6)


def test_forward_force_bad_geometry():
    with pytest.raises(ValueError, match="chord"):
        force_from_position_ned_n(np.array([3.0, 0.0, -4.0]), 4.9, W)
    with pytest.raises(ValueError, match="above the ground"):
        force_from_position_ned_n(np.array([3.0, 0.0, 1.0]), 6.0, W)
