"""FrameIngest (frame bytes straight to checked samples) against the generic path (issue 12).

Property: for every frame, FrameIngest (falling back to the parser for what it leaves) and
the parser with pymavlink's decoder followed by ``Ingest.receive`` give the same samples, bit
for bit, and the same counts (framing and ingest, every reason) and reboot flag, frame by
frame: on a recorded hover (ArduPilot's RAW_IMU and PX4's HIGHRES_IMU), on messages that each
check drops (other IMU, NaN, absurd values, port 1, an upward rangefinder, out of range, stamps
going back, duplicates, other senders, MAVLink 1, signed, truncated payloads), and on randomly
mutated frames.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.ingest import Ingest
from tether_companion.service.ingest_frames import FrameIngest
from tether_companion.service.session import EstimationSession
from tether_companion.service.synthetic import HoverStreams

FLAVOURS = ("ardupilot", "px4")


def _ingest(autopilot: str) -> tuple[Ingest, int]:
    overrides = {"recording": {"enabled": False}, "link": {"autopilot": autopilot}}
    config = load_service_config(None, overrides)
    vehicle = load_vehicle_for(config)
    return EstimationSession(config, vehicle, messages=False).ingest, vehicle.n_motors


def _bits(value) -> object:
    """``value`` with floats as their IEEE bytes and arrays as dtype, shape and bytes."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, value.tobytes())
    return value


def _sample(sample) -> tuple:
    names = type(sample).__slots__
    return type(sample).__name__, tuple(_bits(getattr(sample, name)) for name in names)


class _Both:
    """FrameIngest with its fallback, and the generic path, fed the same frames."""

    def __init__(self, autopilot: str) -> None:
        self.fast_ingest, self.n_motors = _ingest(autopilot)
        self.slow_ingest, _ = _ingest(autopilot)
        self.fast_parser, self.slow_parser = FrameParser(), FrameParser(fast=False)
        self.frames = FrameIngest(self.fast_ingest, self.fast_parser)
        self.taken = 0

    def feed(self, frame: bytes, local_s: float | None) -> None:
        fast = self.frames.receive(frame, local_s)
        if fast is None:
            fast = [
                s
                for msg in self.fast_parser.feed(frame)
                for s in self.fast_ingest.receive(msg, local_s)
            ]
            self.fast_parser.end_datagram()
        else:
            self.taken += 1
        slow = [
            s
            for msg in self.slow_parser.feed(frame)
            for s in self.slow_ingest.receive(msg, local_s)
        ]
        self.slow_parser.end_datagram()
        assert [_sample(s) for s in fast] == [_sample(s) for s in slow]
        assert self.fast_ingest.counters == self.slow_ingest.counters
        assert self.fast_parser.counters == self.slow_parser.counters
        assert self.fast_ingest.rebooted == self.slow_ingest.rebooted


def _hover_frames(autopilot: str, seconds: float, seed: int) -> list[bytes]:
    config = load_service_config(None, {"link": {"autopilot": autopilot}})
    vehicle = load_vehicle_for(config)
    rng = np.random.default_rng(seed)
    streams = HoverStreams(vehicle, np.array([2.0, 1.0, -3.0]), 4.0, rng=rng)
    encoder = FrameEncoder(1, 1)
    frames = []
    for k in range(int(seconds * 200)):
        for msg in streams.messages(20.0 + k * 0.005, k):
            if autopilot == "px4" and msg.get_type() == "RAW_IMU":
                g = 9.80665e-3
                msg = dialect.MAVLink_highres_imu_message(
                    msg.time_usec,
                    msg.xacc * g,
                    msg.yacc * g,
                    msg.zacc * g,
                    msg.xgyro * 1e-3,
                    msg.ygyro * 1e-3,
                    msg.zgyro * 1e-3,
                    0.0,
                    0.0,
                    0.0,
                    1013.0,
                    0.0,
                    0.0,
                    20.0,
                    0x3F,
                    0,
                )
            frames.append(encoder.encode(msg))
    return frames


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_a_recorded_hover_gives_the_same_samples_and_counts(autopilot: str) -> None:
    both = _Both(autopilot)
    frames = _hover_frames(autopilot, 3.0, seed=4)
    for k, frame in enumerate(frames):
        both.feed(frame, 100.0 + 0.00125 * k)
    assert both.taken == len(frames)  # every frame was an input stream's, taken straight
    assert sum(both.fast_ingest.counters.accepted.values()) == len(frames)


def _odd_messages(n_motors: int) -> list:
    """Messages each of which some check of the input streams drops (or, last, accepts)."""
    nan = math.nan
    servo = [1500] * 16
    out = [
        dialect.MAVLink_raw_imu_message(21_000_000, 0, 0, -1000, 1, 2, 3, 0, 0, 0, 1, 20),  # IMU 1
        dialect.MAVLink_raw_imu_message(21_005_000, 30000, 0, -1000, 1, 2, 3, 0, 0, 0, 0, 20),
        dialect.MAVLink_raw_imu_message(21_010_000, 0, 0, -1000, 30000, 2, 3, 0, 0, 0, 0, 20),
        dialect.MAVLink_highres_imu_message(21_010_000, *([0.0] * 12), 20.0, 0, 0),  # other IMU
        dialect.MAVLink_attitude_message(21_000, nan, 0.1, 0.2, 0.0, 0.0, 0.0),
        dialect.MAVLink_attitude_message(21_001, 0.1, 2.0, 0.2, 0.0, 0.0, 0.0),
        dialect.MAVLink_attitude_message(21_002, 0.1, 0.1, math.inf, 0.0, 0.0, 0.0),
        dialect.MAVLink_attitude_message(21_003, -0.1, 0.05, -3.0, 0.0, 0.0, 0.0),
        dialect.MAVLink_servo_output_raw_message(21_000_000, 1, *servo),  # port 1
        dialect.MAVLink_servo_output_raw_message(21_000_500, 0, 5000, *servo[1:]),  # absurd
        dialect.MAVLink_servo_output_raw_message(21_001_000, 0, *servo),
        dialect.MAVLink_servo_output_raw_message(21_001_000, 0, *servo),  # duplicate
        dialect.MAVLink_servo_output_raw_message(19_000_000, 0, *servo),  # back 2 s
        dialect.MAVLink_distance_sensor_message(21_000, 10, 2000, 300, 0, 0, 24, 0),  # up
        dialect.MAVLink_distance_sensor_message(21_001, 10, 2000, 5, 0, 0, 25, 0),  # too close
        dialect.MAVLink_distance_sensor_message(21_002, 10, 2000, 300, 0, 0, 25, 0),
        dialect.MAVLink_distance_sensor_message(21_002, 10, 2000, 300, 0, 0, 25, 0),  # duplicate
        dialect.MAVLink_raw_imu_message(21_020_000, 0, 0, -1000, 1, 2, 3, 0, 0, 0, 0, 20),
        dialect.MAVLink_raw_imu_message(99_000_000, 0, 0, -1000, 1, 2, 3, 0, 0, 0, 0, 20),  # jump
        dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3),
        dialect.MAVLink_system_time_message(0, 1_000),  # its clock went back
        dialect.MAVLink_raw_imu_message(1_100_000, 0, 0, -1000, 1, 2, 3, 0, 0, 0, 0, 20),
    ]
    assert n_motors <= 8
    return out


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_every_drop_is_counted_under_the_same_reason(autopilot: str) -> None:
    both = _Both(autopilot)
    fc, other = FrameEncoder(1, 1), FrameEncoder(2, 1)
    local = 500.0
    for frame in _hover_frames(autopilot, 0.2, seed=1):
        both.feed(frame, local)
        local += 0.001
    for repeat in range(3):  # the reboot's confirmations need a few
        for msg in _odd_messages(both.n_motors):
            for encoder in (fc, other):
                frame = encoder.encode(msg)
                both.feed(frame, local)
                local += 0.01 if repeat < 2 else 1.0
    v1 = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    msg = dialect.MAVLink_attitude_message(30_000, 0.1, 0.1, 0.1, 0.0, 0.0, 0.0)
    both.feed(bytes(msg.pack(v1, force_mavlink1=True)), local)
    counters = both.fast_ingest.counters
    assert counters.not_input and counters.nonfinite and counters.absurd and counters.duplicate
    assert counters.out_of_range and counters.out_of_order and counters.wrong_system


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_mutated_frames_get_the_same_verdicts(autopilot: str) -> None:
    """Random bit flips, byte changes and cuts (header, payload, checksum) of recorded frames,
    interleaved with intact ones."""
    rng = np.random.default_rng(31)
    both = _Both(autopilot)
    frames = _hover_frames(autopilot, 2.0, seed=2)
    local = 50.0
    for frame in frames:
        data = bytearray(frame)
        choice = rng.integers(6)
        if choice == 1:
            data[rng.integers(len(data))] ^= 1 << int(rng.integers(8))
        elif choice == 2:
            data[rng.integers(len(data))] = int(rng.integers(256))
        elif choice == 3:
            data = data[: int(rng.integers(1, len(data)))]
        elif choice == 4:  # a truncated payload (trailing zeros cut) with its checksum fixed up
            data = _retruncated(data, int(rng.integers(1, 4)))
        elif choice == 5:
            data += bytes(rng.integers(0, 256, int(rng.integers(1, 4)), dtype=np.uint8))
        both.feed(bytes(data), local)
        local += 0.00125
    assert both.taken > len(frames) // 3


def _retruncated(frame: bytearray, cut: int) -> bytearray:
    """``frame`` (MAVLink 2) with ``cut`` fewer payload bytes and a valid checksum for them (the
    cut bytes are treated as the zeros a sender may truncate, so the values may change)."""
    from tether_companion.mavlink.framing import _checksum

    length = frame[1]
    cut = min(cut, length - 1)
    payload = frame[10 : 10 + length - cut]
    header = bytearray(frame[:10])
    header[1] = len(payload)
    msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
    extra = bytes((dialect.mavlink_map[msg_id].crc_extra,))
    crc = _checksum(bytes(header[1:]) + payload, extra)
    return header + payload + struct.pack("<H", crc)


def test_a_gated_parser_is_refused() -> None:
    ingest, _ = _ingest("ardupilot")

    class Gate:
        def admit(self, frame, source) -> bool:
            return True

    with pytest.raises(ValueError, match="gated"):
        FrameIngest(ingest, FrameParser(gate=Gate()))
