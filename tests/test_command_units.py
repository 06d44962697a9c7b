"""Motor outputs beyond PWM microseconds: the profile's thrust_curve.command_unit says what
SERVO_OUTPUT_RAW carries; a Crazyflie-class profile (raw 0-65535) replays a log of raw commands."""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path

import numpy as np
import pytest
from paper_filter import with_paper_filter

from tether_companion.config import ConfigError, from_mapping
from tether_companion.errors import InputError
from tether_companion.mavlink.framing import FrameEncoder
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.service.config import load_service_config
from tether_companion.service.recording import RecordingLimits, TlogWriter
from tether_companion.service.replay import replay_log
from tether_companion.service.synthetic import HoverStreams

LIMITS = RecordingLimits(
    max_file_bytes=50_000_000, max_total_bytes=100_000_000, flush_interval_s=1.0
)


@pytest.mark.parametrize(
    ("unit", "low", "high"),
    [("pwm_us", 1000, 2000), ("raw", 0, 65535), ("normalised", 0.0, 1.0), ("dshot", 48, 2047)],
)
def test_each_unit_accepts_its_own_range(unit: str, low: float, high: float) -> None:
    curve = from_mapping(ThrustCurve, {"command_unit": unit, "pwm_min_us": low, "pwm_max_us": high})
    assert curve.thrust_n(high) == pytest.approx(8.0)
    assert curve.thrust_n(low) == pytest.approx(0.0)


@pytest.mark.parametrize(
    ("mapping", "key", "words"),
    [
        ({"pwm_min_us": 0.0}, "thrust_curve.pwm_min_us", "command_unit 'pwm_us'"),
        ({"command_unit": "raw", "pwm_max_us": 70000}, "thrust_curve.pwm_max_us", "<= 65535"),
        (
            {"command_unit": "normalised", "pwm_min_us": 0, "pwm_max_us": 2000},
            "thrust_curve.pwm_max_us",
            "<= 1.0",
        ),
        ({"command_unit": "volts"}, "thrust_curve.command_unit", "one of 'pwm_us', 'raw'"),
    ],
)
def test_outputs_outside_the_unit_are_refused_naming_key_and_unit(
    mapping: dict, key: str, words: str
) -> None:
    from tether_companion.physics.vehicle import VehicleProfile

    with pytest.raises(ConfigError, match=words) as info:
        from_mapping(VehicleProfile, {"thrust_curve": mapping}, source="v.yaml")
    assert info.value.key == key and "v.yaml" in str(info.value)


def test_crazyflie_profile_replays_a_log_of_raw_commands(tmp_path: Path) -> None:
    vehicle = load_vehicle("crazyflie")
    assert vehicle.thrust_curve.command_unit == "raw"
    position = np.array([1.0, 0.5, -1.5])
    streams = HoverStreams(
        vehicle, position, 0.1, rng=np.random.default_rng(3), accel_noise_mps2=0.05
    )
    raw = streams.state.pwm_us
    assert np.all(raw > 2500.0)  # commands no pulse width could be: the ingest must take them
    fc = FrameEncoder(1, 1)
    writer = TlogWriter(tmp_path, LIMITS)
    for k in range(int(12.0 * 200)):
        for msg in streams.messages(20.0 + k * 0.005, k):
            writer.write(fc.encode(msg))
    writer.close()
    assert writer.current_path is not None
    config = load_service_config(  # a 27 g drone's tether pulls ~0.1 N: slack well below that
        None,
        with_paper_filter(
            {
                "recording": {"enabled": False},
                "vehicle": "crazyflie",
                "publish": {"slack_tension_n": 0.02},
            }
        ),
    )
    out = io.StringIO()
    summary = replay_log(writer.current_path, config, vehicle, out)
    rows = [line.split(",") for line in out.getvalue().strip().splitlines()[1:]]
    assert summary.published == len(rows) > 100
    estimate = np.array([float(x) for x in rows[-1][1:4]])
    assert np.linalg.norm(estimate - position) < 0.3
    # the same log through a profile that reads outputs as microseconds drops every command
    # as absurd, and the replay says the motor outputs are missing
    as_pwm = dataclasses.replace(
        vehicle,
        thrust_curve=dataclasses.replace(
            vehicle.thrust_curve, command_unit="pwm_us", pwm_min_us=1000, pwm_max_us=2000
        ),
    )
    with pytest.raises(InputError, match="lacks SERVO_OUTPUT_RAW"):
        replay_log(writer.current_path, config, as_pwm, io.StringIO())
