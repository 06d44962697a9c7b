"""The dynamic filter's status names the thrust scale when it alone keeps the position from
being published, and the weak pull otherwise."""

from __future__ import annotations

import numpy as np

from tether_companion.estimation.dynamic.observability import ThrustScaleKnowledge, assess
from tether_companion.estimation.dynamic.output import OK, THRUST_SCALE, WEAK_PULL


def _status(horizontal: np.ndarray, knowledge: ThrustScaleKnowledge | None) -> tuple[str, str]:
    covariance = np.eye(3) * 0.01
    covariance[:2, :2] = horizontal
    return assess(
        initialised_reason=None,
        reset_reason=None,
        on_ground=False,
        inputs_stale=False,
        tension_n=4.0,
        slack_tension_n=0.2,
        position_covariance_m2=covariance,
        max_horizontal_std_m=0.5,
        thrust_scale=knowledge,
    )


def test_a_range_unknown_only_through_the_thrust_scale_is_thrust_scale() -> None:
    # north std 1 m, all of it from a thrust scale of std 0.05 (20 m per unit of scale)
    cross = np.array([20.0 * 0.05**2, 0.0])
    horizontal = np.diag([1.0, 0.04]) + np.diag([1e-4, 0.0])
    one = ThrustScaleKnowledge(1.04, 0.05**2, cross, hypotheses=1)
    status, reason = _status(horizontal, one)
    assert status == THRUST_SCALE
    assert "thrust scale not learned yet (1.040 +- 0.050)" in reason
    # the same spread with no correlation to the thrust scale: the pull is too weak
    unrelated = ThrustScaleKnowledge(1.04, 0.05**2, np.zeros(2), hypotheses=1)
    assert _status(horizontal, unrelated)[0] == WEAK_PULL
    assert _status(horizontal, None)[0] == WEAK_PULL
    # while the bank still runs several hypotheses, their spread is the thrust scale's
    bank = ThrustScaleKnowledge(1.04, 0.05**2, np.zeros(2), hypotheses=4)
    status, reason = _status(horizontal, bank)
    assert status == THRUST_SCALE and "4 hypotheses" in reason
    assert _status(np.diag([0.04, 0.04]), bank) == (OK, "")
