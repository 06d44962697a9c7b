"""The publisher: rate in FC time, covariance layout, never NaN, reset_counter, health texts."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.estimation.estimate import Estimate, EstimatorHealth
from tether_companion.estimation.observability import RANGEFINDER
from tether_companion.mavlink import estimates
from tether_companion.mavlink.units import urt_to_covariance
from tether_companion.samples import AttitudeSample
from tether_companion.service.estimate_messages import STATUSTEXT_PREFIX, EstimateMessages
from tether_companion.service.health import (
    CONVERGING,
    DIVERGED,
    HEALTH_STATES,
    NO_RANGE,
    OK,
    SLACK,
    STALE,
    STALE_PWM,
    health_text,
)
from tether_companion.service.publish import Publisher, _farther_than
from tether_companion.service.publish_config import PublishConfig

ATTITUDE = AttitudeSample(0.0, 0.05, -0.1, 1.2)
HEALTH_VALUES = tuple(
    getattr(EstimatorHealth(), f.name) for f in dataclasses.fields(EstimatorHealth)
)
P_GOOD = np.array(
    [[0.04, 0.01, 0.0, 0.0], [0.01, 0.03, 0.0, 0.0], [0.0, 0.0, 0.02, 0.0], [0.0, 0.0, 0.0, 0.01]]
)


def _estimate(
    t: float,
    position=(2.0, 1.0, -3.0),
    tension=4.0,
    covariance=P_GOOD,
    resets=0,
    missing_input=None,
) -> Estimate:
    return Estimate(
        time_s=t,
        position_ned_m=np.array(position, dtype=float),
        tension_n=tension,
        covariance=np.array(covariance, dtype=float),
        reset_counter=resets,
        accel_fused=True,
        health_values=HEALTH_VALUES,
        missing_input=missing_input,
    )


def _feed(publisher: Publisher, estimates, attitude=ATTITUDE, **kw):
    sent = []
    for e in estimates:
        messages, _ = publisher.on_estimate(e, attitude, **kw)
        sent += messages
    return sent


def _of(messages, kind):
    return [m for m in messages if m.get_type() == kind]


def test_rate_is_exact_in_fc_time_from_200hz_ticks() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0, rate_hz=30.0), has_tension_state=True)
    sent = _feed(publisher, [_estimate(5.0 + k * 0.005) for k in range(2000)])  # 10 s
    vision = _of(sent, "VISION_POSITION_ESTIMATE")
    assert len(vision) in (300, 301)
    usec = np.array([m.usec for m in vision])
    assert np.all(np.diff(usec) <= 35_000) and usec[0] == 5_000_000
    named = _of(sent, "NAMED_VALUE_FLOAT")
    assert (
        len(named) in (100, 101)
        and named[0].name == "TETH_TENS"
        and named[0].value == pytest.approx(4.0)
    )


def test_message_carries_fc_attitude_and_ekf_covariance() -> None:
    publisher = Publisher(
        PublishConfig(settle_s=0.0, attitude_variance_rad2=0.5), has_tension_state=True
    )
    (vision,) = _of(_feed(publisher, [_estimate(7.25)]), "VISION_POSITION_ESTIMATE")
    assert vision.usec == 7_250_000
    assert (vision.x, vision.y, vision.z) == pytest.approx((2.0, 1.0, -3.0))
    assert (vision.roll, vision.pitch, vision.yaw) == pytest.approx((0.05, -0.1, 1.2))
    cov = vision.covariance
    assert len(cov) == 21
    assert (cov[0], cov[1], cov[6], cov[11]) == pytest.approx(
        (0.04, 0.01, 0.03, 0.02)
    )  # x-x, x-y, y-y, z-z
    assert (cov[15], cov[18], cov[20]) == pytest.approx((0.5, 0.5, 0.5))  # roll, pitch, yaw
    assert all(math.isfinite(c) for c in cov)
    full = urt_to_covariance(cov)
    assert np.all(np.linalg.eigvalsh(full) > 0)


def test_unknown_covariance_mode_marks_nan_in_first_entry_only() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0, covariance="unknown"), has_tension_state=True)
    (vision,) = _of(_feed(publisher, [_estimate(1.0)]), "VISION_POSITION_ESTIMATE")
    assert math.isnan(vision.covariance[0]) and all(c == 0.0 for c in vision.covariance[1:])
    assert all(
        math.isfinite(v)
        for v in (vision.x, vision.y, vision.z, vision.roll, vision.pitch, vision.yaw)
    )


def test_never_nan_and_withheld_when_unhealthy() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0), has_tension_state=True)
    nan_pos = _estimate(1.0, position=(math.nan, 0.0, -2.0))
    sent = _feed(publisher, [nan_pos])
    assert not _of(sent, "VISION_POSITION_ESTIMATE") and publisher.health == DIVERGED
    inflate = Publisher(PublishConfig(settle_s=0.0, on_unhealthy="inflate"), has_tension_state=True)
    assert not _of(_feed(inflate, [nan_pos]), "VISION_POSITION_ESTIMATE")  # inflate, but never NaN


def test_converging_then_ok_then_diverged_with_statustext() -> None:
    publisher = Publisher(
        PublishConfig(settle_s=0.0, max_position_variance_m2=0.5), has_tension_state=True
    )
    wide = np.diag([0.9, 0.9, 0.9, 1.0])
    sent = _feed(publisher, [_estimate(1.0, covariance=wide)])
    assert publisher.health == CONVERGING and not _of(sent, "VISION_POSITION_ESTIMATE")
    sent = _feed(publisher, [_estimate(2.0)])
    assert publisher.health == OK and len(_of(sent, "VISION_POSITION_ESTIMATE")) == 1
    assert [m.text for m in _of(sent, "STATUSTEXT")] == ["TETHER: position OK"]
    sent = _feed(publisher, [_estimate(3.0, covariance=wide)])
    assert publisher.health == DIVERGED and not _of(sent, "VISION_POSITION_ESTIMATE")
    (text,) = _of(sent, "STATUSTEXT")
    assert text.severity == 4 and "diverged" in text.text


def test_every_health_statustext_is_whole_within_mavlinks_50_characters() -> None:
    """STATUSTEXT carries 50 characters: a health's words cut there would reach the ground
    station truncated ("... no positi")."""
    for health in HEALTH_STATES:
        words = STATUSTEXT_PREFIX + health_text(health)
        assert len(words) <= 50, words
        assert EstimateMessages.statustext(health).text == words


def test_slack_tether_stops_or_inflates() -> None:
    stop = Publisher(PublishConfig(settle_s=0.0, slack_tension_n=0.3), has_tension_state=True)
    assert not _of(_feed(stop, [_estimate(1.0, tension=0.1)]), "VISION_POSITION_ESTIMATE")
    assert stop.health == SLACK
    inflate = Publisher(
        PublishConfig(settle_s=0.0, on_unhealthy="inflate", inflated_variance_m2=50.0),
        has_tension_state=True,
    )
    (vision,) = _of(_feed(inflate, [_estimate(1.0, tension=0.1)]), "VISION_POSITION_ESTIMATE")
    assert (vision.covariance[0], vision.covariance[6], vision.covariance[11]) == (50.0, 50.0, 50.0)
    three_state = Publisher(
        PublishConfig(settle_s=0.0), has_tension_state=False
    )  # known tension: no slack test
    assert _of(_feed(three_state, [_estimate(1.0, tension=0.1)]), "VISION_POSITION_ESTIMATE")


def test_stale_inputs_and_missing_attitude_withhold() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0), has_tension_state=True)
    assert not _of(
        _feed(publisher, [_estimate(1.0)], inputs_stale=True), "VISION_POSITION_ESTIMATE"
    )
    assert publisher.health == STALE
    publisher = Publisher(PublishConfig(settle_s=0.0), has_tension_state=True)
    assert not _of(_feed(publisher, [_estimate(1.0)], attitude=None), "VISION_POSITION_ESTIMATE")


def test_reset_counter_on_estimator_reset_jump_pause_and_restart() -> None:
    publisher = Publisher(
        PublishConfig(settle_s=0.0, rate_hz=10.0, jump_m=1.0), has_tension_state=True
    )
    t = [1.0]

    def publish(**kw) -> int:
        t[0] += 0.1
        (vision,) = _of(_feed(publisher, [_estimate(t[0], **kw)]), "VISION_POSITION_ESTIMATE")
        return vision.reset_counter

    assert publish() == 0
    assert publish(position=(2.1, 1.0, -3.0)) == 0  # 10 cm: no reset
    assert publish(position=(3.5, 1.0, -3.0)) == 1  # 1.4 m jump
    assert publish(position=(3.5, 1.0, -3.0), resets=1) == 2  # the estimator restarted
    t[0] += 2.0
    assert publish(position=(3.5, 1.0, -3.0), resets=1) == 3  # resumed after a pause
    publisher.restart()
    assert publish(position=(3.5, 1.0, -3.0)) == 4  # flight-controller reboot
    publisher.reset_counter = 255
    assert publish(position=(9.5, 1.0, -3.0)) == 0  # uint8 wraps


def test_config_names_key_value_and_range() -> None:
    from tether_companion.config import ConfigError, from_mapping

    with pytest.raises(ConfigError, match=r"rate_hz = 500.*<= 200"):
        from_mapping(PublishConfig, {"rate_hz": 500})
    with pytest.raises(ConfigError, match=r"tension_name = 'WAY_TOO_LONG_NAME'.*10 characters"):
        from_mapping(PublishConfig, {"tension_name": "WAY_TOO_LONG_NAME"})
    assert dataclasses.replace(PublishConfig(), rate_hz=50.0).rate_hz == 50.0


def test_first_position_only_after_settling() -> None:
    publisher = Publisher(PublishConfig(settle_s=1.0, rate_hz=10.0), has_tension_state=True)
    sent = _feed(publisher, [_estimate(5.0 + k * 0.1) for k in range(10)])  # healthy for 0.9 s
    assert not _of(sent, "VISION_POSITION_ESTIMATE") and publisher.health == CONVERGING
    sent = _feed(publisher, [_estimate(6.0)])
    assert len(_of(sent, "VISION_POSITION_ESTIMATE")) == 1 and publisher.health == OK


def test_odometry_option_carries_pose_and_marks_velocity_unknown() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0, odometry=True), has_tension_state=True)
    sent = _feed(publisher, [_estimate(2.0)])
    (odometry,) = _of(sent, "ODOMETRY")
    (vision,) = _of(sent, "VISION_POSITION_ESTIMATE")
    assert odometry.time_usec == vision.usec and (odometry.x, odometry.z) == pytest.approx(
        (2.0, -3.0)
    )
    assert odometry.frame_id == 1  # MAV_FRAME_LOCAL_NED
    assert all(math.isnan(v) for v in (odometry.vx, odometry.vy, odometry.vz))
    assert math.isnan(odometry.velocity_covariance[0])
    assert odometry.pose_covariance[0] == pytest.approx(0.04)


def test_motors_idle_withholds_the_position() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0), has_tension_state=True)
    assert not _of(_feed(publisher, [_estimate(1.0)], motors_idle=True), "VISION_POSITION_ESTIMATE")
    assert publisher.health == "motors_idle"
    assert _of(_feed(publisher, [_estimate(2.0)]), "VISION_POSITION_ESTIMATE")


def test_flapping_health_is_announced_at_most_once_a_second() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0), has_tension_state=True)
    sent = []
    for k in range(200):  # 1 s at 200 Hz, stale every other tick
        messages, _ = publisher.on_estimate(
            _estimate(10.0 + k * 0.005), ATTITUDE, inputs_stale=k % 2 == 1
        )
        sent += messages
    texts = [m.text for m in _of(sent, "STATUSTEXT")]
    assert texts == ["TETHER: position OK"] and publisher.counters.health_changes == 200
    messages, _ = publisher.on_estimate(_estimate(11.01), ATTITUDE, inputs_stale=True)
    assert [m.text for m in _of(messages, "STATUSTEXT")] == ["TETHER: inputs stale, no estimate"]


@dataclasses.dataclass(frozen=True)
class _MovingEstimate:
    """An estimator output with a velocity state (what the service reads of it)."""

    time_s: float
    position_ned_m: np.ndarray
    tension_n: float
    covariance: np.ndarray
    reset_counter: int
    velocity_ned_mps: np.ndarray
    velocity_covariance_m2ps2: np.ndarray

    @property
    def position_covariance_m2(self) -> np.ndarray:
        return self.covariance[:3, :3]


def test_velocity_goes_out_in_odometry_and_vision_speed_estimate_never_nan() -> None:
    config = PublishConfig(
        settle_s=0.0, odometry=True, odometry_frame="local_frd", speed_estimate=True
    )
    publisher = Publisher(config, has_tension_state=True)
    velocity_cov = np.diag([0.01, 0.02, 0.005])
    moving = _MovingEstimate(
        2.0, np.array([2.0, 1.0, -3.0]), 4.0, P_GOOD, 0, np.array([0.6, -0.8, 0.1]), velocity_cov
    )
    sent = _feed(publisher, [moving])
    (odometry,) = _of(sent, "ODOMETRY")
    (speed,) = _of(sent, "VISION_SPEED_ESTIMATE")
    assert odometry.frame_id == 20 and odometry.child_frame_id == 12  # LOCAL_FRD, BODY_FRD
    back = estimates.velocity_from_odometry(odometry)
    assert back is not None
    np.testing.assert_allclose(back.velocity_ned_m_s, [0.6, -0.8, 0.1], atol=1e-6)
    np.testing.assert_allclose(back.covariance, velocity_cov, atol=1e-7)
    assert speed.usec == odometry.time_usec and (speed.x, speed.y, speed.z) == pytest.approx(
        (0.6, -0.8, 0.1)
    )
    assert speed.covariance[0] == pytest.approx(0.01) and speed.covariance[4] == pytest.approx(0.02)
    # a non-finite velocity is never sent: ODOMETRY marks it unknown, no VISION_SPEED_ESTIMATE
    bad = dataclasses.replace(moving, time_s=3.0, velocity_ned_mps=np.array([math.nan, 0, 0]))
    sent = _feed(publisher, [bad])
    (odometry,) = _of(sent, "ODOMETRY")
    assert not _of(sent, "VISION_SPEED_ESTIMATE")
    assert math.isnan(odometry.vx) and math.isnan(odometry.velocity_covariance[0])
    # the paper's filters have no velocity: nothing to send
    assert not _of(_feed(publisher, [_estimate(4.0)]), "VISION_SPEED_ESTIMATE")


def test_stale_input_health_names_the_input() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0), has_tension_state=True)
    sent = _feed(publisher, [_estimate(1.0)], inputs_stale=STALE_PWM)
    assert not _of(sent, "VISION_POSITION_ESTIMATE")
    assert publisher.health == STALE_PWM
    assert any("motor outputs stale" in m.text for m in _of(sent, "STATUSTEXT"))


def test_variance_grown_for_a_missing_rangefinder_is_no_range_health() -> None:
    publisher = Publisher(PublishConfig(settle_s=0.0), has_tension_state=True)
    grown = np.diag([0.3, 0.2, 0.9, 0.01])
    lost = _estimate(1.0, covariance=grown, missing_input=RANGEFINDER)
    sent = _feed(publisher, [lost])
    assert not _of(sent, "VISION_POSITION_ESTIMATE") and publisher.health == NO_RANGE
    assert any("rangefinder" in m.text for m in _of(sent, "STATUSTEXT"))
    publisher = Publisher(PublishConfig(settle_s=0.0), has_tension_state=True)
    _feed(publisher, [_estimate(1.0, covariance=grown)])  # same variance, no reason known
    assert publisher.health == CONVERGING


def test_the_jump_test_in_floats_is_numpy_norms_verdict_also_at_the_bound() -> None:
    """The publisher's jump test reads the positions as floats; where the distance is within
    its rounding of ``jump_m`` numpy's norm decides, so the verdict is the former one."""
    rng = np.random.default_rng(7)
    for _ in range(2000):
        a = rng.normal(scale=5.0, size=3)
        b = a + rng.normal(size=3)
        norm = float(np.linalg.norm(a - b))
        # bounds far from, next to and exactly at the distance
        for bound in (0.5 * norm, norm, np.nextafter(norm, 0.0), np.nextafter(norm, 9.0)):
            verdict = _farther_than(tuple(a.tolist()), tuple(b.tolist()), float(bound))
            assert verdict == (norm > bound)
    nan = (math.nan, 0.0, 0.0)
    assert _farther_than(nan, (0.0, 0.0, 0.0), 1.0) == (float(np.linalg.norm(np.array(nan))) > 1.0)
