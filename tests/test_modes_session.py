"""The tension modes' MAVLink glue: encoding of actions, heartbeat decoding, rate limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.bench.tension import equilibrium_readings
from tether_companion.estimation.tension_kf import TensionFilterConfig
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.modes.config import TensionModeConfig
from tether_companion.modes.session import (
    COPTER_LAND,
    POSITION_ONLY_MASK,
    VELOCITY_ONLY_MASK,
    TensionModeSession,
    action_messages,
    copter_mode_name,
)
from tether_companion.modes.tension_following import (
    LAND,
    NOTHING,
    POSITION_TARGET,
    VELOCITY_TARGET,
    ModeAction,
)
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

VEHICLE = VehicleProfile()
ARMED = dialect.MAV_MODE_FLAG_SAFETY_ARMED | dialect.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


def _round_trip(messages):
    encoder, parser = FrameEncoder(255, 191), FrameParser()
    out = []
    for msg in messages:
        out.extend(parser.feed(encoder.encode(msg)))
    assert parser.counters.errors == 0
    return out


def test_velocity_position_and_land_messages_on_the_wire():
    (vel,) = _round_trip(
        action_messages(
            ModeAction(VELOCITY_TARGET, velocity_ned_m_s=np.array([0.1, -0.2, 0.3])), 1, 1, 1234
        )
    )
    assert vel.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert (vel.target_system, vel.target_component, vel.time_boot_ms) == (1, 1, 1234)
    assert (
        vel.coordinate_frame == dialect.MAV_FRAME_LOCAL_NED and vel.type_mask == VELOCITY_ONLY_MASK
    )
    assert (vel.vx, vel.vy, vel.vz) == pytest.approx((0.1, -0.2, 0.3))
    (pos,) = _round_trip(
        action_messages(
            ModeAction(POSITION_TARGET, position_ned_m=np.array([2.0, 1.0, -3.0])), 1, 1, 0
        )
    )
    assert pos.type_mask == POSITION_ONLY_MASK and (pos.x, pos.y, pos.z) == (2.0, 1.0, -3.0)
    (land,) = _round_trip(action_messages(ModeAction(LAND), 7, 1, 0))
    assert land.get_type() == "COMMAND_LONG" and land.command == dialect.MAV_CMD_DO_SET_MODE
    assert land.param2 == COPTER_LAND == 9 and land.target_system == 7
    assert action_messages(ModeAction(NOTHING), 1, 1, 0) == []


def test_never_encodes_a_nonfinite_target():
    with pytest.raises(ValueError, match="non-finite"):
        action_messages(
            ModeAction(VELOCITY_TARGET, velocity_ned_m_s=np.array([math.nan, 0, 0])), 1, 1, 0
        )


def test_mode_names():
    assert copter_mode_name(4) == "GUIDED" and copter_mode_name(9) == "LAND"
    assert copter_mode_name(250) == "MODE250"


def _feed(session, t, cable):
    f_body, roll, pitch, thrust = equilibrium_readings(VEHICLE, cable)
    pwm = VEHICLE.thrust_curve.pwm_for_thrust(np.full(4, thrust / 4.0))
    session.on_attitude(AttitudeSample(t, roll, pitch, 0.0))
    session.on_pwm(PwmSample(t, np.asarray(pwm, dtype=float)))
    session.on_imu(ImuSample(t, f_body, np.zeros(3)))


def test_session_follows_a_tug_with_rate_limited_targets_and_lands():
    session = TensionModeSession(
        TensionModeConfig(enabled=True, land_on_first_tug=True),
        TensionFilterConfig(),
        VEHICLE,
        1,
        1,
    )
    session.on_heartbeat(ARMED, 4)
    position = np.array([2.0, 0.0, -3.0])
    base = np.array([-2.0, 0.0, 3.0]) * 4.0 / math.sqrt(13.0)
    sent = []
    for k in range(600):  # 3 s at 200 Hz: 1 s quiet, then a downward pull
        t = k * 0.005
        cable = base + (np.array([0.0, 0.0, 3.0]) if t >= 1.0 else 0.0)
        _feed(session, t, cable)
        sent.extend((t, m) for m in session.tick(t, position, 3.0))
    assert session.modes.landing_flag
    times = [t for t, _ in sent]
    assert times and times[0] > 1.0
    assert all(b - a >= 0.1 - 1e-9 for a, b in zip(times, times[1:], strict=False))
    assert all(m.type_mask == VELOCITY_ONLY_MASK and m.vz > 0.0 for _, m in sent[1:])
    # low: LAND, repeated once a second until the heartbeat says LAND
    lands = []
    for k in range(600, 1000):
        t = k * 0.005
        _feed(session, t, base)
        lands.extend(
            t
            for m in session.tick(t, np.array([2.0, 0.0, -0.3]), 0.3)
            if m.get_type() == "COMMAND_LONG"
        )
    assert len(lands) == 2 and lands[1] - lands[0] == pytest.approx(1.0)
    session.on_heartbeat(ARMED, 9)
    assert session.tick(5.0, np.array([2.0, 0.0, -0.3]), 0.3) == []
    assert session.flight_mode == "LAND"
