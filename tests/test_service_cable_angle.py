"""The ground station's cable-angle sensor as a service input (issue 10): DEBUG_VECT decoded on
both decoder paths, checked and counted by reason, its stamp mapped to the flight controller's
clock, signed when the link requires it, fed to the dynamic filter; the emulator's sensor (the
simulated cable's direction at the anchor) in lock-step and over UDP; the configuration's
bounds."""

from __future__ import annotations

import asyncio
import io
import math

import numpy as np
import pytest
from lockstep_service import LockstepService
from rich.console import Console
from scenario_files import gusty_hover_takeoff_scenario
from test_service_emulator import _fly

from tether_companion.config import ConfigError
from tether_companion.emulator.lockstep import build_controller
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.mavlink.signing import SignatureVerifier, Signer
from tether_companion.mavlink.trust import REQUIRED, LinkTrust
from tether_companion.physics.cable_anchor import anchor_direction_ned
from tether_companion.service.cable_angle import CableAngleConfig, CableAngleFeed, CableAngleReading
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.emulator_process import EmulatorProcess
from tether_companion.service.ingest import CABLE_ANGLE, Ingest
from tether_companion.service.session import EstimationSession
from tether_companion.service.status import render

SENSOR_IDS = (255, 158)
FC_IDS = (1, 1)
KEY = bytes(range(7, 39))


def _angle(
    time_s: float, azimuth: float, elevation: float, name: bytes = b"CABLE_ANG"
) -> dialect.MAVLink_debug_vect_message:
    return dialect.MAVLink_debug_vect_message(
        name, int(round(time_s * 1e6)), azimuth, elevation, 0.0
    )


def _attitude(time_s: float) -> dialect.MAVLink_attitude_message:
    return dialect.MAVLink_attitude_message(int(round(time_s * 1e3)), 0.0, 0.0, 0.0, 0, 0, 0)


class _Wire:
    """Frames from the flight controller and the sensor through one parser (fast or pymavlink's
    decoder, optionally behind a link's signing gate) into an :class:`Ingest`."""

    def __init__(self, fast: bool, gate: LinkTrust | None = None, **angle: object) -> None:
        config = load_service_config(
            None, {"recording": {"enabled": False}, "cable_angle": {"enabled": True, **angle}}
        )
        self.ingest = Ingest(
            config.link, config.inputs, config.tension, 4, cable_angle=config.cable_angle
        )
        self.parser = FrameParser(gate=gate, fast=fast)
        self.fc = FrameEncoder(*FC_IDS)
        self.sensor = FrameEncoder(*SENSOR_IDS)

    def fc_at(self, time_s: float) -> None:
        """The flight controller's clock reaches ``time_s`` (an ATTITUDE)."""
        self.send(self.fc, _attitude(time_s))

    def send(self, encoder: FrameEncoder, msg) -> list[CableAngleReading]:
        out = []
        for decoded in self.parser.feed(encoder.encode(msg)):
            out += self.ingest.receive(decoded)
        return [s for s in out if isinstance(s, CableAngleReading)]

    @property
    def counters(self) -> dict[str, int]:
        assert self.ingest.cable_angle is not None
        return self.ingest.cable_angle.counters.as_dict()


@pytest.mark.parametrize("fast", [True, False], ids=["fastdecode", "pymavlink"])
def test_readings_in_radians_calibrated_and_stamped_in_flight_controller_time(fast: bool) -> None:
    wire = _Wire(fast, azimuth_offset_rad=0.1, elevation_offset_rad=-0.02)
    readings = []
    for k in range(20):  # 10 Hz; the sensor's clock is UNIX time, the FC's since its boot
        t_fc = 30.0 + 0.1 * k
        wire.fc_at(t_fc + (0.02 if k % 3 else 0.005))  # deliveries 5-20 ms after the reading
        readings += wire.send(wire.sensor, _angle(1.7e9 + 0.1 * k, 3.1 + 0.001 * k, 0.5))
    assert len(readings) == 20 and wire.ingest.counters.accepted[CABLE_ANGLE] == 20
    first, last = readings[0], readings[-1]
    assert first.elevation_rad == pytest.approx(0.48, abs=1e-6)  # float32 on the wire
    # 3.1 + 0.1 rad is past pi: wrapped to [-pi, pi)
    assert first.azimuth_rad == pytest.approx(3.2 - 2 * math.pi, abs=1e-6)
    assert last.azimuth_rad == pytest.approx(3.219 - 2 * math.pi, abs=1e-6)
    # the fastest delivery seen (5 ms) sets the offset: stamps within 15 ms of the truth
    stamps = np.array([r.time_s for r in readings])
    truth = 30.0 + 0.1 * np.arange(20)
    assert np.all(np.abs(stamps - truth) <= 0.0201) and np.abs(stamps[3:] - truth[3:]).max() < 0.006
    assert sum(wire.counters.values()) == 20  # all accepted, nothing else counted


def test_both_decoder_paths_give_the_same_readings() -> None:
    results = []
    for fast in (True, False):
        wire = _Wire(fast)
        out = []
        for k in range(10):
            wire.fc_at(5.0 + 0.1 * k)
            out += wire.send(wire.sensor, _angle(100.0 + 0.1 * k, -1.0 + 0.05 * k, 0.3 + 0.01 * k))
        results.append(out)
    assert results[0] == results[1] and len(results[0]) == 10


def test_bad_readings_are_dropped_and_counted_by_reason() -> None:
    wire = _Wire(fast=True, elevation_offset_rad=0.1)
    assert wire.send(wire.sensor, _angle(0.0, 0.0, 0.5)) == []  # before any FC stamp
    wire.fc_at(10.0)
    assert len(wire.send(wire.sensor, _angle(1.0, 0.0, 0.5))) == 1
    nan, inf = math.nan, math.inf
    cases = [
        ("wrong_sender", FrameEncoder(255, 1), _angle(1.1, 0.0, 0.5)),
        ("wrong_sender", FrameEncoder(*FC_IDS), _angle(1.1, 0.0, 0.5)),
        ("wrong_name", wire.sensor, _angle(1.1, 0.0, 0.5, name=b"OTHER")),
        ("nonfinite", wire.sensor, _angle(1.1, nan, 0.5)),
        ("nonfinite", wire.sensor, _angle(1.1, 0.0, inf)),
        ("out_of_range", wire.sensor, _angle(1.1, 0.0, 1.6)),
        ("out_of_range", wire.sensor, _angle(1.1, 0.0, 1.5)),  # 1.6 after the offset
        ("out_of_range", wire.sensor, _angle(1.1, 6.3, 0.5)),  # beyond 2 pi
        ("duplicate", wire.sensor, _angle(1.0, 0.0, 0.5)),
        ("out_of_order", wire.sensor, _angle(0.9, 0.0, 0.5)),
    ]
    for reason, encoder, msg in cases:
        before = wire.counters[reason]
        assert wire.send(encoder, msg) == [], reason
        assert wire.counters[reason] == before + 1, reason
    assert wire.counters["no_fc_time"] == 1
    # another component's differently named debug vector is other traffic, not the sensor's
    assert wire.send(FrameEncoder(255, 1), _angle(1.1, 0.0, 0.5, name=b"OTHER")) == []
    assert wire.ingest.counters.wrong_system == 4  # every DEBUG_VECT the gate did not take
    assert wire.counters["wrong_sender"] == 2
    # a reading delivered 0.5 s later than the fastest seen: late
    wire.fc_at(10.6)
    assert wire.send(wire.sensor, _angle(1.1, 0.0, 0.5)) == []
    assert wire.counters["late"] == 1
    assert len(wire.send(wire.sensor, _angle(1.6, 0.0, 0.5))) == 1
    assert wire.ingest.cable_angle.counters.dropped == 10
    assert wire.ingest.counters.accepted[CABLE_ANGLE] == 2


def test_with_signing_required_only_signed_readings_pass() -> None:
    """The link's signing policy applies to the sensor's frames as to every frame."""
    trust = LinkTrust(REQUIRED, verifier=SignatureVerifier(KEY))
    wire = _Wire(fast=True, gate=trust)
    wire.fc = FrameEncoder(*FC_IDS, Signer(KEY, link_id=1))
    wire.fc_at(10.0)
    assert wire.send(wire.sensor, _angle(1.0, 0.0, 0.5)) == []  # unsigned: refused
    assert trust.counters.as_dict()["unsigned"] == 1
    signed = FrameEncoder(*SENSOR_IDS, Signer(KEY, link_id=2))
    assert len(wire.send(signed, _angle(1.1, 0.0, 0.5))) == 1
    forged = FrameEncoder(*SENSOR_IDS, Signer(bytes(32), link_id=2))
    assert wire.send(forged, _angle(1.2, 0.0, 0.5)) == []
    assert wire.counters["accepted"] == 1


def test_after_a_silence_the_clock_starts_afresh() -> None:
    """A sensor silent for ``timeout_s`` is a new start: a new clock offset is believed."""
    wire = _Wire(fast=True, timeout_s=1.0)
    wire.fc_at(10.0)
    assert len(wire.send(wire.sensor, _angle(1.0, 0.0, 0.5))) == 1
    wire.fc_at(12.5)
    (reading,) = wire.send(wire.sensor, _angle(50.0, 0.0, 0.5))  # the sensor's clock jumped
    assert reading.time_s == pytest.approx(12.5)


class _Estimator:
    """Records what the feed hands to a dynamic filter at filter time ``time_s``."""

    def __init__(self) -> None:
        self.time_s = 20.0
        self.angles: list[tuple[object, ...]] = []

    def on_cable_angle(self, *args: object) -> None:
        self.angles.append(args)


def test_feed_hands_the_angle_and_its_noise_to_the_filter_unless_stale_or_vertical() -> None:
    config = CableAngleConfig(
        enabled=True,
        noise_std_rad=0.03,
        azimuth_calibration_std_rad=0.02,
        elevation_calibration_std_rad=0.005,
        timeout_s=1.0,
        max_age_s=0.2,
    )
    feed = CableAngleFeed(config, uses_angle=True)
    estimator = _Estimator()
    assert feed.note == "" and feed.last is None
    feed.on_reading(CableAngleReading(20.05, 0.5, 1.0), estimator)
    assert estimator.angles == [(0.5, 1.0, 20.05, 0.03, (0.005, 0.02))]
    feed.on_reading(CableAngleReading(19.7, 0.5, 1.0), estimator)  # 0.3 s behind the filter
    assert feed.stale_readings == 1 and len(estimator.angles) == 1
    feed.on_reading(CableAngleReading(20.1, 1.45, 1.0), estimator)  # steeper than 1.4 rad
    assert feed.near_vertical == 1 and len(estimator.angles) == 1
    assert feed.timeouts == 0
    estimator.time_s = 25.0
    feed.on_reading(CableAngleReading(25.0, 0.5, 1.0), estimator)  # after 4.9 s of silence
    assert feed.timeouts == 1 and len(estimator.angles) == 2


def test_the_paper_filters_say_once_that_they_do_not_use_the_angle() -> None:
    config = load_service_config(
        None,
        {
            "estimator": {"kind": "four_state"},
            "cable_angle": {"enabled": True},
            "recording": {"enabled": False},
        },
    )
    session = EstimationSession(config, load_vehicle_for(config))
    assert "cable-angle input" in session.cable_angle.note
    session.on_sample(CableAngleReading(3.0, 0.5, 1.0))  # read and counted, not used
    assert session.cable_angle.last is not None
    assert load_service_config(None).cable_angle.enabled is False
    assert CableAngleFeed(CableAngleConfig(enabled=True), uses_angle=True).note == ""


@pytest.mark.parametrize(
    ("overrides", "key"),
    [
        ({"cable_angle": {"enabled": True, "noise_std_rad": 0}}, "cable_angle.noise_std_rad"),
        ({"cable_angle": {"enabled": True, "noise_std_rad": 1.0}}, "cable_angle.noise_std_rad"),
        ({"cable_angle": {"enabled": True, "component_id": 300}}, "cable_angle.component_id"),
        ({"cable_angle": {"message_name": "ELEVEN_CHAR"}}, "cable_angle.message_name"),
        ({"cable_angle": {"message_name": ""}}, "cable_angle.message_name"),
        ({"cable_angle": {"azimuth_offset_rad": 4.0}}, "cable_angle.azimuth_offset_rad"),
        ({"cable_angle": {"max_elevation_rad": 2.0}}, "cable_angle.max_elevation_rad"),
        ({"cable_angle": {"max_age_s": 0.6}}, "cable_angle.max_age_s"),  # > staleness 0.5 s
        ({"cable_angle": {"timeout_s": 0}}, "cable_angle.timeout_s"),
        ({"cable_angle": {"enabled": "yes"}}, "cable_angle.enabled"),
        ({"cable_angle": {"azimuth": 1.0}}, "cable_angle.azimuth"),  # unknown key
    ],
)
def test_bad_cable_angle_settings_are_refused_naming_the_key(overrides: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        load_service_config(None, overrides)


def test_emulated_sensor_feeds_the_dynamic_filter_in_lockstep_and_leaves_the_flight_alone(
    tmp_path,
) -> None:
    """The emulator's ground station sends the simulated cable's direction at the anchor
    (10 Hz, from 255/158); the service (cable_angle enabled) fuses it. The simulated flight is
    the same bit for bit with and without the sensor (its noise has its own generator)."""
    path = gusty_hover_takeoff_scenario(tmp_path, 12.0, seed=3)
    controller = build_controller(str(path), emulator={"cable_angle": {"enabled": True}})
    lockstep = LockstepService(controller, {"cable_angle": {"enabled": True}})
    plain = build_controller(str(path))
    errors = []
    while controller.time_s < 12.0:
        lockstep.advance()
        lockstep.serve()
        plain.advance_to(controller.time_s)
        reading = lockstep.service.session.cable_angle.last
        if reading is not None and reading.time_s > 3.0:  # airborne and taut
            p = controller.sim.position_ned_m
            errors.append(
                (
                    reading.elevation_rad - math.atan2(-p[2], math.hypot(p[0], p[1])),
                    math.remainder(reading.azimuth_rad - math.atan2(p[1], p[0]), 2 * math.pi),
                )
            )
    np.testing.assert_array_equal(controller.sim.position_ned_m, plain.sim.position_ned_m)
    session = lockstep.service.session
    frames = [m for m in lockstep.peer.received if m.get_type() == "DEBUG_VECT"]
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in frames} == {SENSOR_IDS}
    assert 115 <= len(frames) <= 122  # 10 Hz
    assert session.ingest.counters.accepted[CABLE_ANGLE] == len(frames)
    assert session.ingest.cable_angle is not None
    assert session.ingest.cable_angle.counters.dropped == 0
    assert session.estimator.health.cable_angle_fused > 50
    # a straight (constant-tension) cable: the angle is the line's, within 0.01 rad of noise
    # (the reading is up to one 10 Hz period old: the drone moves little in a hover)
    errors = np.array(errors)
    assert np.abs(errors).mean(axis=0).max() < 0.02 and np.abs(errors).max() < 0.06
    view = io.StringIO()
    Console(file=view, width=200).print(render(lockstep.service))
    assert "cable angle at anchor" in view.getvalue()


def test_the_emulated_angle_is_the_catenarys_tangent_at_the_anchor() -> None:
    """On a heavy cable the sensor reports the catenary's direction at the anchor (below the
    straight line to the drone), flat where the cable rests on the ground."""
    from tether_companion.physics.cable import CableConfig, make_cable

    cable = make_cable(CableConfig(model="catenary", length_m=7.0, linear_density_kg_per_m=0.1))
    free = (5.0, 1.0, -4.0)  # chord 6.5 m: the 7 m cable sags, clear of the ground
    cable.force_components(*free, 0.0, 0.0, 0.0)
    north, east, down = anchor_direction_ned(cable, free)
    elevation = math.atan2(-down, math.hypot(north, east))
    chord_elevation = math.atan2(4.0, math.hypot(5.0, 1.0))
    assert elevation < chord_elevation - 0.1
    assert math.atan2(east, north) == pytest.approx(math.atan2(1.0, 5.0))
    grounded = (6.5, 0.0, -1.0)  # most of the cable on the ground
    cable.force_components(*grounded, 0.0, 0.0, 0.0)
    assert anchor_direction_ned(cable, grounded) == pytest.approx((1.0, 0.0, 0.0))


@pytest.mark.integration
def test_cable_angle_over_udp_from_the_emulator_process(tmp_path) -> None:
    """`tether-companion emulate --cable-angle` in its own process, the service (default
    dynamic filter, cable angle enabled) on a UDP socket to it: the sensor's frames arrive,
    pass the checks and are fused."""
    emulator = EmulatorProcess(
        "paper-circle",
        duration_s=8.0,
        score_path=tmp_path / "score.json",
        speed=2.0,
        extra_args=("--cable-angle",),
    )
    service = asyncio.run(_fly(emulator, {"cable_angle": {"enabled": True}}))
    session = service.session
    gate = session.ingest.cable_angle
    assert gate is not None
    accepted = session.ingest.counters.accepted[CABLE_ANGLE]
    assert accepted >= 50, gate.counters  # 10 Hz for 8 s, minus the link's start
    assert gate.counters.dropped <= 2, gate.counters  # a late first frame or two at most
    assert session.estimator.health.cable_angle_fused >= 30
    last = session.cable_angle.last
    assert last is not None and 0.1 < last.elevation_rad < 1.2


@pytest.mark.parametrize(
    ("position", "length_m", "density_kg_per_m"),
    [
        ((5.0, 1.0, -4.0), 7.0, 0.1),  # heavy, free, leaves the anchor below the chord
        ((5.5, -1.0, -3.0), 6.4, 0.0167),  # light, nearly taut
        ((-4.0, 3.0, -3.0), 7.0, 0.1),  # the lowest point between the ends: leaves downward
        ((6.5, 0.0, -1.0), 7.0, 0.1),  # resting on the ground: flat
    ],
)
def test_the_filters_model_is_the_simulated_cables_direction_at_the_anchor(
    position: tuple[float, float, float], length_m: float, density_kg_per_m: float
) -> None:
    """The dynamic filter's cable-angle model (aid/cable_angle.py: the catenary's tangent at
    the anchor through the state's ends and tension) against the simulator's cable
    (physics/cable.py, solved by physics/catenary.py), at the true chord tension."""
    from tether_companion.estimation.dynamic import models
    from tether_companion.physics.cable import CableConfig, make_cable

    cable = make_cable(
        CableConfig(model="catenary", length_m=length_m, linear_density_kg_per_m=density_kg_per_m)
    )
    force = np.array(cable.force_components(*position, 0.0, 0.0, 0.0))
    p = np.array(position)
    chord_tension = math.hypot(force[0], force[1]) * np.linalg.norm(p) / math.hypot(p[0], p[1])
    x = [*p, 0.0, 0.0, 0.0, chord_tension, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    c = [1.5, 0.0, density_kg_per_m * 9.80665]
    (elevation, azimuth), _ = models.CATENARY.cable_angle(x, [], c)
    north, east, down = anchor_direction_ned(cable, position)
    assert elevation == pytest.approx(math.atan2(-down, math.hypot(north, east)), abs=1e-6)
    assert azimuth == pytest.approx(math.atan2(east, north), abs=1e-9)
