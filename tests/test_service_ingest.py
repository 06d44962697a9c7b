"""Ingest drops and counts bad input (wrong system, NaN, absurd, duplicated, out of order,
garbage bytes) without harming the estimate; reboots are confirmed; the FC clock model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from paper_filter import with_paper_filter

from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.service.clock import FcClock
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.ingest import ATTITUDE, IMU, PWM, RANGE
from tether_companion.service.session import EstimationSession
from tether_companion.service.synthetic import HoverStreams

POSITION = np.array([2.0, 1.0, -3.0])


@pytest.fixture
def config():
    """Ingest's rules message by message: no reorder buffer (tests/test_service_trust.py
    tests it)."""
    return load_service_config(
        None,
        with_paper_filter({"recording": {"enabled": False}, "inputs": {"reorder_window_s": 0.0}}),
    )


def _session(config) -> EstimationSession:
    return EstimationSession(config, load_vehicle_for(config))


def _run(session: EstimationSession, frames: list[bytes]) -> list:
    parser = FrameParser()
    publications = []
    for frame in frames:
        for msg in parser.feed(frame):
            step = session.on_message(msg)
            if step.publication is not None:
                publications.append(step.publication)
    return publications


def _hover_frames(config, seconds: float, seed: int = 7, start_s: float = 10.0) -> list[bytes]:
    vehicle = load_vehicle_for(config)
    streams = HoverStreams(vehicle, POSITION, 4.0, rng=np.random.default_rng(seed))
    fc = FrameEncoder(1, 1)
    frames = []
    for k in range(int(seconds * 200)):
        frames += [fc.encode(m) for m in streams.messages(start_s + k * 0.005, k)]
    return frames


def test_clean_hover_converges(config) -> None:
    session = _session(config)
    publications = _run(session, _hover_frames(config, 20.0))
    last = publications[-1]
    assert np.linalg.norm(np.array(last.position_ned_m) - POSITION) < 0.3
    assert abs(last.tension_n - 4.0) < 0.5
    assert session.ingest.counters.dropped == 0
    assert session.ingest.counters.accepted[IMU] == 4000
    # every IMU sample ticks the filter, every range sample is fused, although DISTANCE_SENSOR's
    # millisecond stamps often land a hair after the microsecond IMU stamp of the same instant
    health = session.estimator.health
    assert health.imu_ticks == 4000 and health.out_of_order == 0 and health.range_fused == 400


def test_bad_input_is_dropped_counted_and_harmless(config) -> None:
    """Garbage bytes, other systems' messages, NaN/absurd values, duplicates and stale
    (out-of-order) copies interleaved with a clean stream give the clean run's estimates."""
    clean = _hover_frames(config, 10.0)
    rng = np.random.default_rng(3)
    other = FrameEncoder(2, 1)  # e.g. SITL's tether simulator, system 2
    fc = FrameEncoder(1, 1)
    dirty: list[bytes] = []
    for i, frame in enumerate(clean):
        dirty.append(frame)
        if i % 50 == 0:
            dirty.append(rng.integers(0, 256, 40, dtype=np.uint8).tobytes())
        if i % 97 == 0:
            dirty.append(
                other.encode(
                    dialect.MAVLink_raw_imu_message(
                        10_000_000 + i, 0, 0, 5000, 0, 0, 0, 0, 0, 0, 0, 0
                    )
                )
            )
        if i % 101 == 0:
            dirty.append(
                fc.encode(dialect.MAVLink_attitude_message(10_000 + i, math.nan, 0.0, 0.0, 0, 0, 0))
            )
        if i % 103 == 0:
            dirty.append(frame)  # duplicated
        if i % 107 == 0 and i > 400:
            dirty.append(clean[i - 300])  # a delayed copy: out of order
        if i % 109 == 0:  # absurd: 30 g on x, in the future (must not become "latest")
            dirty.append(
                fc.encode(
                    dialect.MAVLink_raw_imu_message(
                        99_000_000, 30_000, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
                    )
                )
            )
        if i % 113 == 0:
            dirty.append(
                fc.encode(
                    dialect.MAVLink_servo_output_raw_message(10_000_000, 0, 0, 0, 0, 0, *([0] * 12))
                )
            )
    reference = _run(_session(config), clean)
    session = _session(config)
    result = _run(session, dirty)
    counters = session.ingest.counters
    assert counters.wrong_system > 0 and counters.nonfinite > 0 and counters.absurd > 0
    assert counters.duplicate > 0 and counters.out_of_order > 0 and counters.reboots == 0
    assert session.estimator.health.nonfinite_rejected == 0  # nothing bad reached the EKF
    assert result == reference


def test_reboot_needs_confirmation_then_restarts_the_estimator(config) -> None:
    session = _session(config)
    frames = _hover_frames(config, 3.0, start_s=30.0)
    _run(session, frames)
    resets_before = session.publisher.reset_counter
    fc = FrameEncoder(1, 1)
    one_bad = fc.encode(dialect.MAVLink_attitude_message(1000, 0.0, 0.0, 0.0, 0, 0, 0))
    _run(session, [one_bad])
    assert session.ingest.counters.reboots == 0 and session.ingest.counters.out_of_order == 1
    publications = _run(session, _hover_frames(config, 3.0, start_s=1.0))
    assert session.ingest.counters.reboots == 1 and session.boots == 1
    assert publications and publications[-1].time_usec < 5_000_000
    assert session.publisher.reset_counter > resets_before


def test_servo_time_unwraps_past_uint32(config) -> None:
    session = _session(config)
    fc = FrameEncoder(1, 1)
    t_imu = 5000.0  # 83 minutes after boot: SERVO_OUTPUT_RAW's uint32 us has wrapped once
    frames = [
        fc.encode(
            dialect.MAVLink_raw_imu_message(int(t_imu * 1e6), 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0)
        )
    ]
    wrapped = int((t_imu + 0.005) * 1e6) & 0xFFFFFFFF
    frames.append(
        fc.encode(
            dialect.MAVLink_servo_output_raw_message(
                wrapped, 0, 1500, 1500, 1500, 1500, *([0] * 12)
            )
        )
    )
    parser = FrameParser()
    samples = [session.ingest.decode(m) for f in frames for m in parser.feed(f)]
    assert samples[1].time_s == pytest.approx(t_imu + 0.005, abs=1e-6)


def test_rangefinder_outside_its_range_and_sideways_sensors(config) -> None:
    session = _session(config)
    fc = FrameEncoder(1, 1)
    ok = dialect.MAVLink_distance_sensor_message(1000, 20, 4000, 300, 0, 0, 25, 255)
    too_far = dialect.MAVLink_distance_sensor_message(1001, 20, 4000, 4500, 0, 0, 25, 255)
    forward = dialect.MAVLink_distance_sensor_message(1002, 20, 4000, 300, 0, 0, 0, 255)
    parser = FrameParser()
    decoded = [
        session.ingest.decode(m)
        for m in parser.feed(b"".join(fc.encode(x) for x in (ok, too_far, forward)))
    ]
    assert decoded[0].distance_m == pytest.approx(3.0) and decoded[1] is None and decoded[2] is None
    counters = session.ingest.counters
    assert counters.out_of_range == 1 and counters.not_input == 1 and counters.accepted[RANGE] == 1


def test_px4_flavour_reads_highres_imu(config) -> None:
    px4 = load_service_config(
        None,
        {
            "recording": {"enabled": False},
            "link": {"autopilot": "px4"},
            "inputs": {"reorder_window_s": 0.0},
        },
    )
    session = _session(px4)
    fc = FrameEncoder(1, 1)
    parser = FrameParser()
    msgs = parser.feed(
        fc.encode(
            dialect.MAVLink_highres_imu_message(
                2_000_000, 0.1, 0.2, -9.8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0b111111
            )
        )
        + fc.encode(dialect.MAVLink_raw_imu_message(2_000_000, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0))
    )
    imu = session.ingest.decode(msgs[0])
    assert imu.specific_force_body_mps2 == pytest.approx([0.1, 0.2, -9.8])
    assert session.ingest.decode(msgs[1]) is None  # RAW_IMU is not PX4's input
    assert session.ingest.counters.accepted[IMU] == 1
    assert session.ingest.counters.accepted[ATTITUDE] == session.ingest.counters.accepted[PWM] == 0


def test_clock_offset_from_least_delayed_stamp_and_timesync() -> None:
    clock = FcClock(drift_allowance=0.0)
    assert clock.fc_now_s(0.0) is None and math.isinf(clock.age_s(1.0, 0.0))
    # FC time = local + 100 s; transport delays 3, 1, 7 ms: the 1 ms one wins
    for local, delay in ((1.0, 0.003), (2.0, 0.001), (3.0, 0.007)):
        clock.observe(local + 100.0 - delay, local)
    assert clock.offset_s(3.0) == pytest.approx(100.0 - 0.001)
    assert clock.age_s(103.5, 4.0) == pytest.approx(0.499)
    # a TIMESYNC round trip (symmetric 2 ms each way) pins it to the true offset
    clock.observe_timesync(fc_time_s=10.002 + 100.0, sent_local_s=10.0, received_local_s=10.004)
    assert clock.offset_s(10.004) == pytest.approx(100.0)
    clock.reset()
    assert not clock.synchronised


def test_clock_decays_to_follow_a_slower_fc_crystal() -> None:
    clock = FcClock(drift_allowance=1e-4)
    clock.observe(100.0, 0.0)
    # the FC clock runs 50 ppm slow: stamps fall behind the first offset; the estimate follows
    for local in np.arange(1.0, 1000.0, 1.0):
        clock.observe(100.0 + local * (1 - 50e-6), local)
    assert clock.offset_s(999.0) == pytest.approx(100.0 - 999.0 * 50e-6, abs=1e-3)


def test_three_state_with_tension_from_a_load_cell_message() -> None:
    """3-state EKF fed the tension by NAMED_VALUE_FLOAT "TENSION" (e.g. a load cell on the
    flight controller); without those messages the estimate is stale and nothing is sent."""
    overrides = {
        "recording": {"enabled": False},
        "estimator": {"kind": "three_state"},
        "tension": {"source": "message", "message_name": "TENSION", "sensor_component_id": 1},
    }
    config = load_service_config(None, overrides)
    frames = _hover_frames(config, 10.0)
    fc = FrameEncoder(1, 1)
    with_tension: list[bytes] = []
    for i, frame in enumerate(frames):
        with_tension.append(frame)
        if i % 40 == 0:  # ~10 Hz, stamped with the flight-controller time of its neighbours
            stamp_ms = 10_000 + i * 10_000 // len(frames)
            with_tension.append(
                fc.encode(dialect.MAVLink_named_value_float_message(stamp_ms, b"TENSION", 4.0))
            )
    session = _session(config)
    publications = _run(session, with_tension)
    assert session.ingest.counters.accepted["tension"] > 90
    assert np.linalg.norm(np.array(publications[-1].position_ned_m) - POSITION) < 0.3
    assert publications[-1].tension_n == 4.0
    silent = _session(config)
    assert _run(silent, frames) == [] and silent.estimator.health.stale_tension > 0


def test_a_load_cell_message_just_below_zero_reaches_the_estimator() -> None:
    """A load cell near zero reads below zero about half the time: ingest passes a small
    negative NAMED_VALUE_FLOAT tension to the estimator, which judges it by its noise (the
    dynamic filter takes it as a measurement: not counted as rejected); a tension far beyond
    any tether's either way is ``absurd``."""
    overrides = {
        "recording": {"enabled": False},
        "tension": {"source": "message", "message_name": "TENSION", "sensor_component_id": 1},
    }
    config = load_service_config(None, overrides)
    assert config.estimator.kind == "dynamic"
    fc = FrameEncoder(1, 1)
    frames: list[bytes] = []
    values = [-0.05, -0.2, -5000.0, 5000.0]
    hover = _hover_frames(config, 2.0)
    every = len(hover) // (len(values) + 1)
    for i, frame in enumerate(hover):
        frames.append(frame)
        if i % every == every // 2 and values:
            stamp_ms = 10_000 + i * 2_000 // len(hover)
            frames.append(
                fc.encode(
                    dialect.MAVLink_named_value_float_message(stamp_ms, b"TENSION", values.pop(0))
                )
            )
    assert not values
    session = _session(config)
    _run(session, frames)
    counters = session.ingest.counters
    assert counters.accepted["tension"] == 2 and counters.absurd == 2
    assert session.estimator.health.nonfinite_rejected == 0


def test_ground_station_command_controls_the_tension_modes(config) -> None:
    session = _session(config)
    gcs = FrameEncoder(255, 190)
    parser = FrameParser()

    def command(cmd: int, *params: float, target: tuple[int, int] = (1, 191)):
        values = [*params, *([0.0] * (7 - len(params)))]
        frame = gcs.encode(dialect.MAVLink_command_long_message(*target, cmd, 0, *values))
        (msg,) = parser.feed(frame)
        return session.on_message(msg).messages

    assert not session.modes.modes.enabled  # tension_mode.enabled is false by default
    (ack,) = command(dialect.MAV_CMD_USER_2, 1.0, 0.0)
    assert ack.result == dialect.MAV_RESULT_ACCEPTED and session.modes.modes.enabled
    (ack,) = command(dialect.MAV_CMD_USER_2, -1.0, 1.0)  # request a landing, keep enabled
    assert ack.result == dialect.MAV_RESULT_ACCEPTED and session.modes.modes.enabled
    (ack,) = command(dialect.MAV_CMD_USER_2, 7.0, 0.0)
    assert ack.result == dialect.MAV_RESULT_DENIED
    (ack,) = command(dialect.MAV_CMD_USER_2, float("nan"), 0.0)
    assert ack.result == dialect.MAV_RESULT_DENIED
    (ack,) = command(dialect.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    assert ack.result == dialect.MAV_RESULT_UNSUPPORTED
    assert command(dialect.MAV_CMD_USER_2, 0.0, 0.0, target=(1, 1)) == []  # for the autopilot
    (ack,) = command(dialect.MAV_CMD_USER_2, 0.0, 0.0)
    assert ack.result == dialect.MAV_RESULT_ACCEPTED and not session.modes.modes.enabled
