"""The dynamic filter's status says ``learning`` when only the thrust scale and the wind (what a
steady hover does not observe) keep the position from being published, ``weak_pull``
otherwise."""

from __future__ import annotations

import numpy as np

from tether_companion.estimation.dynamic.observability import HoverUnknowns, _explained_2x2, assess
from tether_companion.estimation.dynamic.output import LEARNING, OK, WEAK_PULL


def _status(horizontal: np.ndarray, unknowns: HoverUnknowns | None) -> tuple[str, str]:
    covariance = np.eye(3) * 0.01
    covariance[:2, :2] = horizontal
    return assess(
        initialised_reason=None,
        reset_reason=None,
        on_ground="",
        inputs_stale=False,
        tension_n=16.0,
        slack_tension_n=0.2,
        position_covariance_m2=covariance,
        max_horizontal_std_m=0.5,
        hover_unknowns=unknowns,
    )


def _unknowns(cross: np.ndarray, hypotheses: int = 1) -> HoverUnknowns:
    return HoverUnknowns(
        scale=1.008,
        wind_ne_mps=np.array([-0.1, 0.5]),
        covariance=np.diag([0.015**2, 2.0**2, 2.0**2]),
        position_cross=cross,
        hypotheses=hypotheses,
    )


def test_a_range_unknown_only_through_thrust_scale_and_wind_is_learning() -> None:
    # north std 1.0 m: 0.6 m from a thrust scale of std 0.015 (40 m per unit of scale), 0.78 m
    # from a north wind of std 2 m/s (0.39 s), 0.1 m of its own
    cross = np.array([[40.0 * 0.015**2, 0.39 * 4.0, 0.0], [0.0, 0.0, 0.0]])
    horizontal = np.diag([0.6**2 + 0.78**2 + 0.1**2, 0.04])
    status, reason = _status(horizontal, _unknowns(cross))
    assert status == LEARNING
    assert "thrust scale 1.008 +- 0.015, wind (-0.1, 0.5) +- 2.0 m/s" in reason
    # the same spread unrelated to them: the pull is too weak
    assert _status(horizontal, _unknowns(np.zeros((2, 3))))[0] == WEAK_PULL
    assert _status(horizontal, None)[0] == WEAK_PULL
    # the thrust scale alone does not explain enough: weak_pull
    scale_only = cross.copy()
    scale_only[0, 1] = 0.0
    assert _status(horizontal, _unknowns(scale_only))[0] == WEAK_PULL
    # while the bank still runs several thrust hypotheses, their spread is the thrust scale's
    status, reason = _status(horizontal, _unknowns(np.zeros((2, 3)), hypotheses=4))
    assert status == LEARNING and "4 thrust hypotheses" in reason
    assert _status(np.diag([0.04, 0.04]), _unknowns(cross)) == (OK, "")


def test_the_explained_part_equals_the_schur_complement_numpy_solves() -> None:
    """``X C^-1 X^T`` by the scalar Cholesky equals numpy's solve on random covariances of
    the thrust scale and the wind (scales 1e-4 to 4, as in flight); a covariance that is not
    positive definite explains nothing."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        joint = rng.normal(size=(5, 8)) * np.array([1.0, 1.0, 0.015, 2.0, 2.0])[:, None]
        full = joint @ joint.T / 8.0
        covariance, cross = full[2:, 2:], full[:2, 2:]
        expected = cross @ np.linalg.solve(covariance, cross.T)
        got = _explained_2x2(covariance.tolist(), cross.tolist())
        assert got is not None
        assert np.allclose(got, [expected[0, 0], expected[0, 1], expected[1, 1]], rtol=1e-9)
    indefinite = np.diag([1.0, -1.0, 1.0]).tolist()
    assert _explained_2x2(indefinite, np.ones((2, 3)).tolist()) is None
