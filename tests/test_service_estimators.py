"""The service's estimators beside the tether EKF (issue 5 in the live service): the tension
filter's vector and magnitude published as NAMED_VALUE_FLOAT (never NaN), the catenary
position estimator run beside the EKF or as the published source, and the tension modes'
height from the flight controller's LOCAL_POSITION_NED when the rangefinder is absent or
stale. Deterministic MAVLink input (a synthetic hover) through :class:`EstimationSession`."""

from __future__ import annotations

import math

import numpy as np
import pytest
from paper_filter import with_paper_filter
from pymavlink import mavutil

from tether_companion.config import ConfigError
from tether_companion.estimation.catenary_position import (
    INCONSISTENT,
    OK,
    UNOBSERVABLE,
    WEAK_PULL,
    CatenaryPosition,
)
from tether_companion.estimation.tension_kf import TensionEstimate, TensionHealth
from tether_companion.estimation.thrust_input import MotorLagThrustInput
from tether_companion.mavlink.estimates import local_position_ned_message
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.estimate_messages import (
    CATENARY_POSITION_NAMES,
    TENSION_MAGNITUDE_NAME,
    TENSION_VECTOR_NAMES,
)
from tether_companion.service.health import DIVERGED, SLACK
from tether_companion.service.health import WEAK_PULL as HEALTH_WEAK_PULL
from tether_companion.service.publish import Publisher
from tether_companion.service.publish_config import PublishConfig
from tether_companion.service.session import EstimationSession
from tether_companion.service.synthetic import HoverStreams

POSITION = np.array([2.0, 1.0, -3.0])
TENSION_N = 4.0
ARMED_GUIDED = (dialect.MAV_MODE_FLAG_SAFETY_ARMED | dialect.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)


def _tension(time_s: float, force, last_update_s: float | None = None) -> TensionEstimate:
    force = np.asarray(force, dtype=float)
    return TensionEstimate(
        time_s=time_s,
        tension_ned_n=force,
        variance_n2=0.01,
        last_update_s=time_s if last_update_s is None else last_update_s,
        observation_ned_n=force,
        updated=last_update_s is None,
        health=TensionHealth(),
    )


def _named(messages) -> dict[str, list[float]]:
    values: dict[str, list[float]] = {}
    for msg in messages:
        if msg.get_type() == "NAMED_VALUE_FLOAT":
            name = msg.name if isinstance(msg.name, str) else msg.name.decode()
            values.setdefault(name.rstrip("\0"), []).append(msg.value)
    return values


# ---------------------------------------------------------------------------------------------
# the publisher


def test_filtered_tension_named_values_at_their_rate_and_never_nan() -> None:
    publisher = Publisher(PublishConfig(filtered_rate_hz=10.0), has_tension_state=True)
    force = np.array([-1.0, 2.0, 2.0])
    sent = []
    for k in range(400):  # 2 s of 200 Hz ticks
        sent += publisher.on_filtered(_tension(k * 0.005, force))
    values = _named(sent)
    names = [n.decode() for n in (*TENSION_VECTOR_NAMES, TENSION_MAGNITUDE_NAME)]
    assert sorted(values) == sorted(names) and all(len(n) <= 10 for n in names)
    assert all(len(v) == 20 for v in values.values())  # 10 Hz of FC time
    assert values["TETH_TN"][0] == -1.0 and values["TETH_TE"][0] == 2.0
    assert values["TETH_TD"][0] == 2.0 and values["TETH_TMAG"][0] == pytest.approx(3.0)
    assert all(m.time_boot_ms == 0 for m in sent[:4])

    quiet = Publisher(PublishConfig(filtered_rate_hz=10.0), has_tension_state=True)
    assert quiet.on_filtered(_tension(0.0, [math.nan, 0.0, 1.0])) == []  # invalid
    stale = _tension(1.0, force, last_update_s=0.5)  # not updated for 0.5 s > 0.3 s
    assert quiet.on_filtered(stale) == []
    off = Publisher(PublishConfig(filtered_rate_hz=0.0), has_tension_state=True)
    assert off.on_filtered(_tension(0.0, force)) == []


def test_named_values_plot_with_the_documented_pymavlink_expression() -> None:
    """docs/landing.md: MAVProxy's graph / mavgraph.py select one name with a condition."""
    publisher = Publisher(PublishConfig(), has_tension_state=True)
    encoder, parser, latest = FrameEncoder(1, 191), FrameParser(), {}
    seen: dict[str, float] = {}
    for msg in publisher.on_filtered(_tension(0.0, [-1.0, 2.0, 2.0])):
        (decoded,) = parser.feed(encoder.encode(msg))
        mavutil.add_message(latest, decoded.get_type(), decoded)
        for name in ("TETH_TN", "TETH_TMAG"):
            expression = f'NAMED_VALUE_FLOAT.value{{NAMED_VALUE_FLOAT.name=="{name}"}}'
            value = mavutil.evaluate_expression(expression, latest)
            if value is not None:
                seen[name] = value
    assert seen == {"TETH_TN": -1.0, "TETH_TMAG": pytest.approx(3.0)}


def test_catenary_position_named_values_only_when_valid() -> None:
    publisher = Publisher(PublishConfig(), has_tension_state=True)
    good = CatenaryPosition(0.0, np.array([4.0, 0.0, -3.0]), np.eye(3) * 0.01, OK)
    values = _named(publisher.on_filtered(_tension(0.0, [-1.6, 0.0, 2.6]), good))
    assert [values[n.decode()] for n in CATENARY_POSITION_NAMES] == [[4.0], [0.0], [-3.0]]
    assert len(values) == 7
    bad = CatenaryPosition(0.2, np.full(3, math.nan), np.full((3, 3), math.nan), UNOBSERVABLE)
    values = _named(publisher.on_filtered(_tension(0.2, [-1.6, 0.0, 2.6]), bad))
    assert len(values) == 4 and "TETH_CN" not in values


# ---------------------------------------------------------------------------------------------
# the session on a synthetic hover


def _session(overrides: dict) -> EstimationSession:
    config = load_service_config(None, {"recording": {"enabled": False}, **overrides})
    return EstimationSession(config, load_vehicle_for(config))


def _fly(
    session: EstimationSession,
    seconds: float,
    *,
    range_until_s: float = math.inf,
    fc_down_m: float | None = None,
    position_ned_m: np.ndarray = POSITION,
    tension_n: float = TENSION_N,
    published: list | None = None,
    start_s: float = 10.0,
) -> list[tuple[float, object]]:
    """Feed a hover at ``position_ned_m`` (``tension_n`` toward the anchor) through real
    frames; returns the (FC time, message) the session sends. ``range_until_s``:
    DISTANCE_SENSOR stops then (seconds from the start); ``fc_down_m``: LOCAL_POSITION_NED at
    20 Hz with this down; ``published``: gets (publication, EKF estimate) of every publishing
    tick."""
    streams = HoverStreams(
        session.vehicle,
        position_ned_m,
        tension_n,
        rng=np.random.default_rng(3),
        accel_noise_mps2=0.05,
    )
    fc, parser = FrameEncoder(1, 1), FrameParser()
    sent = []
    for k in range(int(seconds * 200)):
        t = start_s + k * 0.005
        messages = streams.messages(t, k)
        if k * 0.005 >= range_until_s:
            messages = [m for m in messages if m.get_type() != "DISTANCE_SENSOR"]
        if fc_down_m is not None and k % 10 == 0:
            fc_position = (POSITION[0], POSITION[1], fc_down_m)
            messages.insert(0, local_position_ned_message(t, fc_position, np.zeros(3)))
        for msg in messages:
            for decoded in parser.feed(fc.encode(msg)):
                step = session.on_message(decoded)
                sent += [(t, out) for out in step.messages]
                if published is not None and step.publication is not None:
                    published.append((step.publication, step.estimate))
    return sent


def test_session_publishes_the_filtered_tension_vector_and_magnitude() -> None:
    session = _session({})
    sent = _fly(session, 5.0)
    values = _named(m for t, m in sent if t >= 12.0)
    expected = -TENSION_N * POSITION / np.linalg.norm(POSITION)  # pulls toward the anchor
    for name, true_n in zip(("TETH_TN", "TETH_TE", "TETH_TD"), expected, strict=True):
        assert len(values[name]) == 30  # 3 s at 10 Hz
        assert np.all(np.abs(np.array(values[name]) - true_n) < 0.2), name
    assert np.all(np.abs(np.array(values["TETH_TMAG"]) - TENSION_N) < 0.2)
    assert "TETH_CN" not in values  # the catenary estimator does not run by default
    assert session.catenary is None


def test_catenary_beside_the_ekf_is_sent_as_named_values_only() -> None:
    """A light cable (weight 0.01 N/m, paid out just longer than the anchor distance) under
    4 N is nearly straight: the catenary position lands near the hover point, and the
    VISION_POSITION_ESTIMATEs still carry the EKF's position."""
    length = float(np.linalg.norm(POSITION)) + 0.01
    catenary = {"weight_per_length_n_per_m": 0.01, "default_length_m": length}
    session = _session(
        with_paper_filter({"position": {"catenary_beside": True}, "catenary": catenary})
    )
    published: list = []
    sent = _fly(session, 20.0, published=published)
    values = _named(m for t, m in sent if t >= 25.0)
    assert len(values["TETH_CN"]) == 50
    for name, true_m in zip(("TETH_CN", "TETH_CE", "TETH_CD"), POSITION, strict=True):
        assert np.all(np.abs(np.array(values[name]) - true_m) < 0.3), (name, values[name][-1])
    assert session.last_catenary is not None and session.last_catenary.valid
    vision = [m for _, m in sent if m.get_type() == "VISION_POSITION_ESTIMATE"]
    assert len(vision) == len(published) > 0
    for msg, (publication, ekf) in zip(vision, published, strict=True):
        assert publication.position_ned_m == pytest.approx(tuple(ekf.position_ned_m))
        assert (msg.x, msg.y, msg.z) == pytest.approx(publication.position_ned_m, abs=1e-5)


def test_catenary_source_publishes_the_catenary_position_with_its_covariance() -> None:
    length = float(np.linalg.norm(POSITION)) + 0.01
    catenary = {"weight_per_length_n_per_m": 0.01, "default_length_m": length}
    session = _session({"position": {"source": "catenary"}, "catenary": catenary})
    published: list = []
    sent = _fly(session, 6.0, published=published)
    vision = [m for _, m in sent if m.get_type() == "VISION_POSITION_ESTIMATE"]
    assert len(vision) == len(published) > 25 * 4.0  # settled within the first 2 s, then 30 Hz
    for msg, (publication, ekf) in zip(vision, published, strict=True):
        position = np.array([msg.x, msg.y, msg.z])
        assert np.all(np.isfinite(position)) and np.linalg.norm(position - POSITION) < 0.3
        assert np.all(np.isfinite(msg.covariance))
        variances = np.array(msg.covariance)[[0, 6, 11]]  # the catenary's, not the EKF's
        np.testing.assert_allclose(variances, publication.position_variance_m2, rtol=1e-5)
        assert not np.allclose(variances, np.diag(ekf.position_covariance_m2), rtol=0.1)
    last = session.last_catenary
    assert last is not None and last.valid
    np.testing.assert_allclose(  # the latest tick's, a few ms after the last publication
        publication.position_variance_m2, np.diag(last.covariance_m2), rtol=0.05
    )


def test_catenary_source_withholds_when_the_geometry_cannot_explain_the_pull() -> None:
    """The drone 1 m below the anchor's level: the cable pulls it up, which no catenary with
    its lowest point at or below the anchor does. The estimator has no position
    (``inconsistent``) and nothing is sent, never NaN."""
    session = _session({"position": {"source": "catenary"}})
    below = np.array([2.0, 1.0, 1.0])
    sent = _fly(session, 3.0, position_ned_m=below, range_until_s=0.0)
    assert not [m for _, m in sent if m.get_type() == "VISION_POSITION_ESTIMATE"]
    assert session.last_catenary is not None and session.last_catenary.status == INCONSISTENT
    assert session.publisher.counters.withheld > 0 and session.publisher.health == DIVERGED


def test_catenary_source_reports_a_slack_cable_as_slack() -> None:
    """Straight above the anchor on 10 m of cable pulling 1 N down (less than the 1.6 N the
    paid-out cable weighs): it lies on the ground and its pull says nothing of where the
    drone is (``unobservable``); the health says slack, and nothing is sent."""
    session = _session({"position": {"source": "catenary"}})
    streams_at = np.array([0.0, 0.0, -3.0])
    sent = _fly(session, 3.0, position_ned_m=streams_at, tension_n=1.0)
    assert not [m for _, m in sent if m.get_type() == "VISION_POSITION_ESTIMATE"]
    assert session.last_catenary is not None and session.last_catenary.status == UNOBSERVABLE
    assert session.publisher.health == SLACK
    texts = [m.text for _, m in sent if m.get_type() == "STATUSTEXT"]
    assert any("slack" in text for text in texts), texts


def test_catenary_source_withholds_a_pull_as_weak_as_its_error() -> None:
    """0.2 N on the nearly straight light cable of the publishing test: the tension's error
    budget across the pull (accelerometer bias 0.1 m/s^2 times the mass, 0.15 N, and the
    filter's noise) makes the pull's direction uncertain by ~0.8 rad, above the 0.35 rad
    bound: ``weak_pull``, nothing sent, the health and its STATUSTEXT say so; the 4 N pull of
    the publishing test is published with the same budget."""
    length = float(np.linalg.norm(POSITION)) + 0.01
    catenary = {"weight_per_length_n_per_m": 0.01, "default_length_m": length}
    session = _session({"position": {"source": "catenary"}, "catenary": catenary})
    sent = _fly(session, 3.0, tension_n=0.2)
    assert not [m for _, m in sent if m.get_type() == "VISION_POSITION_ESTIMATE"]
    last = session.last_catenary
    assert last is not None and last.status == WEAK_PULL
    assert last.azimuth_std_rad > 0.35 and np.all(np.isfinite(last.position_ned_m))
    assert session.publisher.health == HEALTH_WEAK_PULL
    texts = [m.text for _, m in sent if m.get_type() == "STATUSTEXT"]
    assert any("pull too weak" in text for text in texts), texts


def test_position_source_is_validated() -> None:
    with pytest.raises(ConfigError, match="position.source = 'gps': must be one of"):
        load_service_config(None, {"position": {"source": "gps"}})
    with pytest.raises(ConfigError, match="catenary.weight_per_length_n_per_m"):
        load_service_config(None, {"catenary": {"weight_per_length_n_per_m": 0.0}})
    with pytest.raises(ConfigError, match="publish.filtered_rate_hz"):
        load_service_config(None, {"publish": {"filtered_rate_hz": -1.0}})


# ---------------------------------------------------------------------------------------------
# the modes' height


def _landing(**fly) -> tuple[EstimationSession, list[float]]:
    """Armed in GUIDED with a landing requested over a steady hover 3 m up; the FC times of
    the LAND commands the session sends."""
    session = _session({"tension_mode": {"enabled": True}})
    session.on_fc_heartbeat(*ARMED_GUIDED)
    session.modes.modes.request_landing()
    sent = _fly(session, 4.0, **fly)
    lands = [
        t
        for t, m in sent
        if m.get_type() == "COMMAND_LONG" and m.command == dialect.MAV_CMD_DO_SET_MODE
    ]
    return session, lands


def test_landing_height_from_the_fc_position_without_a_rangefinder() -> None:
    session, lands = _landing(range_until_s=0.0, fc_down_m=-3.0)  # 3 m up: keep following
    assert lands == [] and session.modes.modes.fallback_lands == 0
    session, lands = _landing(range_until_s=0.0, fc_down_m=-0.3)  # 0.3 m: below 0.5 m, LAND
    assert lands and session.modes.modes.fallback_lands == 0  # by the tether, not a fallback
    session, lands = _landing(range_until_s=0.0)  # neither: the autopilot's LAND
    assert session.modes.modes.fallback_lands == 1


def test_a_fresh_rangefinder_wins_then_the_fc_position_takes_over_when_it_goes_stale() -> None:
    """The rangefinder (3 m) until 1.5 s, the FC claiming 0.3 m throughout: no LAND while the
    rangefinder is fresh, LAND once it is older than 0.5 s."""
    session, lands = _landing(range_until_s=1.5, fc_down_m=-0.3)
    assert lands and 10.0 + 1.5 < lands[0] <= 10.0 + 1.5 + 0.6
    assert session.modes.modes.fallback_lands == 0


def test_the_ekf_and_the_tension_filter_share_one_alignment_stage() -> None:
    """Each attitude and PWM sample is converted once: both estimators use the session's
    aligner (with the configured thrust dynamics), and a restart gives both a new one."""
    session = _session(with_paper_filter({"thrust_dynamics": "motor_lag"}))
    first = session.aligner
    assert isinstance(first.thrust_input, MotorLagThrustInput)
    assert session.estimator.aligner is first
    assert session.modes.estimator.aligner is first
    published: list = []
    _fly(session, 2.0, published=published)
    assert published, "the EKF published through the shared aligner"
    assert session.modes.tension is not None and session.modes.tension.updated
    session.restart()
    assert session.aligner is not first
    assert session.estimator.aligner is session.aligner
    assert session.modes.estimator.aligner is session.aligner


def test_tension_filter_staleness_must_match_the_estimators() -> None:
    with pytest.raises(ConfigError, match=r"tension_filter\.pwm_staleness_s = 0\.2: must equal"):
        load_service_config(None, {"tension_filter": {"pwm_staleness_s": 0.2}})
