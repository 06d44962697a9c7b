"""``EstimationSession.send_now``: the live service gets each message the moment it exists, the
estimate of an IMU tick before the tension filter's book-keeping of that tick, and the
messages, their order and the publications are those of the steps replay reads."""

from __future__ import annotations

import numpy as np
import pytest

from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.session import EstimationSession
from tether_companion.service.synthetic import HoverStreams

IMU_HZ = 200.0


def _messages(seconds: float) -> list[tuple[float, object]]:
    """The bench's hover streams (RAW_IMU, ATTITUDE, SERVO_OUTPUT_RAW at 200 Hz, the
    rangefinder at 20 Hz, SYSTEM_TIME at 5 Hz), framed and parsed as the service receives them."""
    config = load_service_config(None)
    streams = HoverStreams(
        load_vehicle_for(config),
        np.array([2.0, 1.0, -3.0]),
        4.0,
        rng=np.random.default_rng(3),
        imu_hz=IMU_HZ,
        attitude_hz=IMU_HZ,
        servo_hz=IMU_HZ,
    )
    encoder, parser = FrameEncoder(1, 1), FrameParser()
    out = []
    for k in range(int(seconds * IMU_HZ)):
        t = 5.0 + k / IMU_HZ
        sent = streams.messages(t, k)
        if k % 40 == 0:
            sent.insert(0, dialect.MAVLink_system_time_message(0, round(t * 1e3)))
        out += [(t, msg) for m in sent for msg in parser.feed(encoder.encode(m))]
    return out


def _session(overrides: dict) -> EstimationSession:
    config = load_service_config(None, {"recording": {"enabled": False}, **overrides})
    return EstimationSession(config, load_vehicle_for(config))


@pytest.mark.parametrize(
    "overrides",
    [
        {"estimator": {"kind": "dynamic"}, "publish": {"on_unhealthy": "inflate"}},
        {"estimator": {"kind": "four_state"}},
        {"estimator": {"kind": "four_state"}, "position": {"catenary_beside": True}},
    ],
    ids=["dynamic-inflate", "four-state", "four-state-catenary-beside"],
)
def test_send_now_sends_what_the_steps_carry_in_the_same_order(overrides: dict) -> None:
    encoder, live_encoder = FrameEncoder(1, 191), FrameEncoder(1, 191)  # each its own sequence
    replay, live = _session(overrides), _session(overrides)
    live_frames: list[bytes] = []
    live.send_now = lambda messages: live_frames.extend(live_encoder.encode(m) for m in messages)
    replay_frames: list[bytes] = []
    replay_pubs, live_pubs = [], []
    for t, msg in _messages(3.0):
        step = replay.on_message(msg, t - 4.0)
        replay_frames += [encoder.encode(m) for m in step.messages]
        replay_pubs.append(step.publication)
        live_step = live.on_message(msg, t - 4.0)
        assert live_step.messages == []
        live_pubs.append(live_step.publication)
    kinds = {f[7] for f in replay_frames}
    assert dialect.MAVLINK_MSG_ID_VISION_POSITION_ESTIMATE in kinds
    assert dialect.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT in kinds
    assert live_frames == replay_frames
    assert live_pubs == replay_pubs


def test_the_estimate_goes_out_before_the_tension_filter_runs_on_its_tick() -> None:
    session = _session({"estimator": {"kind": "four_state"}})
    seen: list[tuple[int, float]] = []  # (VPE usec, the tension filter's newest tick then)

    def send_now(messages: list) -> None:
        for m in messages:
            if m.get_type() == "VISION_POSITION_ESTIMATE":
                tension = session.modes.tension
                seen.append((m.usec, -1.0 if tension is None else tension.time_s))

    session.send_now = send_now
    for t, msg in _messages(3.0):
        session.on_message(msg, t - 4.0)
    assert len(seen) > 10
    for usec, tension_s in seen:
        assert tension_s < usec * 1e-6 - 1e-4  # still at the previous IMU tick
    assert session.modes.tension is not None  # and it did run after
