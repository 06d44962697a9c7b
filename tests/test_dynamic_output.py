"""The dynamic filter's output type: views, and that the service's publisher reads it."""

from __future__ import annotations

import numpy as np

from tether_companion.estimation.dynamic.output import (
    OK,
    STATUSES,
    WEAK_PULL,
    NavigationEstimate,
)
from tether_companion.service.health import OK as PUBLISH_OK
from tether_companion.service.health import assess_health
from tether_companion.service.publish import Publisher
from tether_companion.service.publish_config import PublishConfig


def _estimate(status: str = OK, position_variance: float = 0.01) -> NavigationEstimate:
    a = np.arange(36.0).reshape(6, 6) * 1e-4
    cov = a @ a.T + np.diag([position_variance] * 3 + [0.02] * 3)
    return NavigationEstimate(
        time_s=12.5,
        position_ned_m=np.array([1.0, 2.0, -3.0]),
        velocity_ned_mps=np.array([0.1, -0.2, 0.0]),
        position_velocity_covariance=cov,
        tension_n=4.0,
        tension_variance_n2=0.05,
        reset_counter=0,
        status=status,
        reason="" if status == OK else "horizontal pull 0.3 N too weak",
        accel_fused=True,
        thrust_scale=1.02,
        accel_bias_body_mps2=np.zeros(3),
        wind_ne_mps=np.zeros(2),
        health_values=(),
    )


def test_views_are_the_blocks_of_the_joint_covariance() -> None:
    est = _estimate()
    cov = est.position_velocity_covariance
    np.testing.assert_array_equal(est.position_covariance_m2, cov[:3, :3])
    np.testing.assert_array_equal(est.velocity_covariance_m2ps2, cov[3:, 3:])
    four = est.covariance
    assert four.shape == (4, 4)
    np.testing.assert_array_equal(four[:3, :3], cov[:3, :3])
    assert four[3, 3] == est.tension_variance_n2
    assert est.observable
    assert not _estimate(WEAK_PULL).observable
    assert STATUSES[0] == OK and len(set(STATUSES)) == len(STATUSES)


def test_the_publisher_reads_it_like_the_paper_filters_estimate() -> None:
    config = PublishConfig()
    assert assess_health(_estimate(), config, True, ever_ok=True) == PUBLISH_OK
    huge = _estimate(position_variance=config.max_position_variance_m2 * 2)
    assert assess_health(huge, config, True, ever_ok=True) != PUBLISH_OK
    publisher = Publisher(config, has_tension_state=True)
    _, publication = publisher.on_estimate(_estimate(), None)
    assert publication is None  # no attitude yet: withheld, not a crash
