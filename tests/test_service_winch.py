"""The ground station's winch as a service input (issue 10): WINCH_STATUS decoded on both
decoder paths, checked and counted by reason, its stamp mapped to the flight controller's
clock, fed to the dynamic filter (length; tension carried to the drone when trusted), timed
out when silent; the emulator's winch; the configuration's bounds."""

from __future__ import annotations

import asyncio
import io
import math
from types import SimpleNamespace

import numpy as np
import pytest
from lockstep_service import LockstepService
from rich.console import Console
from scenario_files import gusty_hover_takeoff_scenario
from test_service_emulator import _fly

from tether_companion.config import ConfigError
from tether_companion.emulator.lockstep import build_controller
from tether_companion.emulator.winch import EmulatedWinch, EmulatedWinchConfig
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.physics.cable import cable_weight_n_per_m
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.emulator_process import EmulatorProcess
from tether_companion.service.ingest import WINCH, Ingest
from tether_companion.service.session import EstimationSession
from tether_companion.service.status import render
from tether_companion.service.winch import (
    HEALTHY,
    STANDARD_GRAVITY_MPS2,
    WinchConfig,
    WinchFeed,
    WinchReading,
)
from tether_companion.sim.scenario import load_scenario

WINCH_IDS = (255, 169)
FC_IDS = (1, 1)


def _winch_status(
    time_s: float,
    length_m: float,
    *,
    speed: float = 0.0,
    tension_kg: float = 0.5,
    status: int = HEALTHY,
) -> dialect.MAVLink_winch_status_message:
    return dialect.MAVLink_winch_status_message(
        int(round(time_s * 1e6)), length_m, speed, tension_kg, math.nan, math.nan, 32767, status
    )


def _attitude(time_s: float) -> dialect.MAVLink_attitude_message:
    return dialect.MAVLink_attitude_message(int(round(time_s * 1e3)), 0.0, 0.0, 0.0, 0, 0, 0)


class _Wire:
    """Frames from the flight controller and the winch through one parser (fast or pymavlink's
    decoder) into an :class:`Ingest` with the winch enabled."""

    def __init__(self, fast: bool, **winch: object) -> None:
        config = load_service_config(
            None, {"recording": {"enabled": False}, "winch": {"enabled": True, **winch}}
        )
        self.ingest = Ingest(config.link, config.inputs, config.tension, 4, winch=config.winch)
        self.parser = FrameParser(fast=fast)
        self.fc = FrameEncoder(*FC_IDS)
        self.winch = FrameEncoder(*WINCH_IDS)

    def fc_at(self, time_s: float) -> None:
        """The flight controller's clock reaches ``time_s`` (an ATTITUDE)."""
        self.send(self.fc, _attitude(time_s))

    def send(self, encoder: FrameEncoder, msg) -> list:
        out = []
        for decoded in self.parser.feed(encoder.encode(msg)):
            out += self.ingest.receive(decoded)
        return [s for s in out if isinstance(s, WinchReading)]

    @property
    def counters(self) -> dict[str, int]:
        assert self.ingest.winch is not None
        return self.ingest.winch.counters.as_dict()


@pytest.mark.parametrize("fast", [True, False], ids=["fastdecode", "pymavlink"])
def test_readings_in_si_units_stamped_in_flight_controller_time(fast: bool) -> None:
    wire = _Wire(fast)
    readings = []
    for k in range(20):  # 10 Hz; the winch's clock is UNIX time, the FC's since its boot
        t_fc = 30.0 + 0.1 * k
        wire.fc_at(t_fc + (0.02 if k % 3 else 0.005))  # deliveries 5-20 ms after the reading
        readings += wire.send(wire.winch, _winch_status(1.7e9 + 0.1 * k, 5.0 + 0.01 * k))
    assert len(readings) == 20 and wire.ingest.counters.accepted[WINCH] == 20
    first = readings[0]
    assert first.length_m == pytest.approx(5.0) and first.speed_mps == 0.0
    assert first.tension_n == pytest.approx(0.5 * STANDARD_GRAVITY_MPS2, rel=1e-6)  # kgf -> N
    assert first.status == HEALTHY
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
            out += wire.send(wire.winch, _winch_status(100.0 + 0.1 * k, 3.0 + 0.05 * k))
        results.append(out)
    assert results[0] == results[1] and len(results[0]) == 10


def test_bad_readings_are_dropped_and_counted_by_reason() -> None:
    wire = _Wire(fast=True, spool_length_m=50.0, max_speed_mps=2.0)
    assert wire.send(wire.winch, _winch_status(0.0, 5.0)) == []  # before any FC stamp
    wire.fc_at(10.0)
    assert len(wire.send(wire.winch, _winch_status(1.0, 5.0))) == 1
    cases = [
        ("wrong_sender", FrameEncoder(255, 1), _winch_status(1.1, 5.0)),
        ("wrong_sender", FrameEncoder(*FC_IDS), _winch_status(1.1, 5.0)),
        ("no_length", wire.winch, _winch_status(1.1, math.nan)),
        ("nonfinite", wire.winch, _winch_status(1.1, math.inf)),
        ("absurd", wire.winch, _winch_status(1.1, -0.5)),
        ("absurd", wire.winch, _winch_status(1.1, 50.5)),  # beyond the spool
        ("absurd", wire.winch, _winch_status(1.1, 5.0, speed=3.0)),
        ("unhealthy", wire.winch, _winch_status(1.1, 5.0, status=0)),
        ("duplicate", wire.winch, _winch_status(1.0, 5.0)),
        ("out_of_order", wire.winch, _winch_status(0.9, 5.0)),
        ("too_fast", wire.winch, _winch_status(1.1, 5.5)),  # 5 m/s over 0.1 s
    ]
    for reason, encoder, msg in cases:
        before = wire.counters[reason]
        assert wire.send(encoder, msg) == [], reason
        assert wire.counters[reason] == before + 1, reason
    assert wire.counters["no_fc_time"] == 1
    assert wire.ingest.counters.wrong_system == 2
    # within the speed limit and its tolerance: accepted
    assert len(wire.send(wire.winch, _winch_status(1.1, 5.25))) == 1
    # a reading delivered 0.5 s later than the fastest seen: late
    wire.fc_at(10.7)
    assert wire.send(wire.winch, _winch_status(1.2, 5.25)) == []
    assert wire.counters["late"] == 1
    # a bad tension keeps the length, without the tension
    (reading,) = wire.send(wire.winch, _winch_status(1.7, 5.3, tension_kg=-2000.0))
    assert math.isnan(reading.tension_n) and wire.counters["bad_tension"] == 1
    # a load cell's reading just below zero is its noise about a slack line: passed on
    (reading,) = wire.send(wire.winch, _winch_status(1.8, 5.3, tension_kg=-0.01))
    assert reading.tension_n == pytest.approx(-0.01 * STANDARD_GRAVITY_MPS2)
    assert wire.counters["bad_tension"] == 1
    assert wire.ingest.counters.accepted[WINCH] == 4


def test_after_a_silence_the_checks_start_afresh() -> None:
    """A winch silent for ``timeout_s`` is a new start: a length far from the last accepted
    one and a new clock offset are believed (the line may have moved meanwhile)."""
    wire = _Wire(fast=True, timeout_s=1.0)
    wire.fc_at(10.0)
    assert len(wire.send(wire.winch, _winch_status(1.0, 5.0))) == 1
    wire.fc_at(10.5)
    assert wire.send(wire.winch, _winch_status(1.5, 9.0)) == []  # 8 m/s: too fast
    wire.fc_at(12.5)
    (reading,) = wire.send(wire.winch, _winch_status(3.5, 9.0))
    assert reading.length_m == 9.0 and reading.time_s == pytest.approx(12.5)


class _Estimator:
    """Records what the feed hands to an estimator (with a dynamic filter's cable constants)."""

    def __init__(self) -> None:
        self.lengths: list[tuple[float, float]] = []
        self.tensions: list[tuple[float, float]] = []

        class _Constants:
            length_m = math.nan

        self.constants = _Constants()

    def set_paid_out_length_m(self, length_m: float, time_s: float) -> None:
        self.lengths.append((length_m, time_s))
        self.constants.length_m = length_m

    def set_known_tension_n(self, tension_n: float, time_s: float) -> None:
        self.tensions.append((tension_n, time_s))


def test_feed_carries_the_tension_to_the_drone_and_forgets_a_silent_winch() -> None:
    config = WinchConfig(enabled=True, timeout_s=1.0)
    estimator = _Estimator()
    feed = WinchFeed(config, use_tension=True, cable_weight_n_per_m=0.2, uses_length=True)
    assert feed.note == "" and feed.deadline_s == math.inf
    feed.on_reading(WinchReading(20.0, 6.0, 3.0, 0.0, HEALTHY), estimator, (5.0, 0.0, -2.5))
    assert estimator.lengths == [(6.0, 20.0)]
    # 3 N at the winch, 2.5 m of climb on a 0.2 N/m cable: 3.5 N at the drone
    assert estimator.tensions == [(pytest.approx(3.5), 20.0)]
    assert feed.deadline_s == 21.0 and not feed.stale
    # no estimate yet: a heavy cable's tension at the drone is unknown, not guessed
    feed.on_reading(WinchReading(20.1, 6.0, 3.0, 0.0, HEALTHY), estimator, None)
    assert len(estimator.tensions) == 1 and len(estimator.lengths) == 2
    # near the vertical (span 1 m of 6.1 m < 0.5): the length is not fused, and counted
    feed.on_reading(WinchReading(20.2, 6.1, 3.0, 0.0, HEALTHY), estimator, (1.0, 0.0, -6.0))
    assert len(estimator.lengths) == 2 and feed.near_vertical == 1
    feed.expire(estimator)
    assert math.isnan(estimator.constants.length_m) and feed.stale and feed.timeouts == 1
    # without tension.source winch the tension is not used
    plain = WinchFeed(config, use_tension=False, cable_weight_n_per_m=0.0, uses_length=True)
    other = _Estimator()
    plain.on_reading(WinchReading(1.0, 4.0, 3.0, 0.0, HEALTHY), other, (3.9, 0.0, -1.0))
    assert other.tensions == [] and other.lengths == [(4.0, 1.0)]


class _DynamicEstimator(_Estimator):
    """Records what the feed hands to the dynamic filter, which models the winch's end."""

    def __init__(self) -> None:
        super().__init__()
        self.winch_tensions: list[tuple[float, float]] = []

    def set_winch_tension_n(self, tension_n: float, time_s: float) -> None:
        self.winch_tensions.append((tension_n, time_s))


def test_feed_gives_the_dynamic_filter_the_tension_at_the_winch() -> None:
    """The dynamic filter gets the winch's own tension (its model has the cable's shape), also
    before its first estimate; nothing carried to the drone."""
    feed = WinchFeed(
        WinchConfig(enabled=True), use_tension=True, cable_weight_n_per_m=0.2, uses_length=True
    )
    estimator = _DynamicEstimator()
    feed.on_reading(WinchReading(20.0, 6.0, 3.0, 0.0, HEALTHY), estimator, (5.0, 0.0, -2.5))
    feed.on_reading(WinchReading(20.1, 6.0, 3.2, 0.0, HEALTHY), estimator, None)
    assert estimator.winch_tensions == [(3.0, 20.0), (3.2, 20.1)]
    assert estimator.tensions == []


def test_the_paper_filters_say_once_that_they_do_not_use_the_length() -> None:
    feed = WinchFeed(
        WinchConfig(enabled=True), use_tension=False, cable_weight_n_per_m=0.0, uses_length=False
    )
    estimator = _Estimator()
    feed.on_reading(WinchReading(1.0, 4.0, 3.0, 0.0, HEALTHY), estimator, (3.9, 0.0, -1.0))
    assert estimator.lengths == [] and "paid-out length" in feed.note


@pytest.mark.parametrize(
    ("overrides", "key"),
    [
        ({"tension": {"source": "winch"}}, "tension.source"),
        ({"winch": {"enabled": True, "max_speed_mps": -1.0}}, "winch.max_speed_mps"),
        ({"winch": {"enabled": True, "component_id": 300}}, "winch.component_id"),
        ({"winch": {"enabled": True, "timeout_s": 0}}, "winch.timeout_s"),
        ({"winch": {"enabled": "yes"}}, "winch.enabled"),
        (
            {
                "estimator": {"kind": "four_state"},
                "winch": {"enabled": True},
                "tension": {"source": "winch"},
            },
            "tension.source",
        ),  # fmt: skip
    ],
)
def test_bad_winch_settings_are_refused_naming_the_key(overrides: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        load_service_config(None, overrides)


def test_winch_is_off_by_default_and_the_dynamic_filter_takes_its_tension() -> None:
    assert not load_service_config(None).winch.enabled
    config = load_service_config(
        None, {"winch": {"enabled": True, "system_id": 1}, "tension": {"source": "winch"}}
    )
    assert config.winch.system_id == 1 and config.winch.component_id == 169


def test_emulated_winch_feeds_the_dynamic_filter_in_lockstep(tmp_path) -> None:
    """The emulator's ground station sends WINCH_STATUS (10 Hz, with the realistic encoder's
    errors: 1 cm steps, the flight's scale and offset; from 255/169); the service (shipped
    configuration, winch enabled) fuses its length: the filter's cable length is the true
    distance within the encoder's calibration error."""
    path = gusty_hover_takeoff_scenario(tmp_path, 14.0, seed=3, ground_station=True)
    controller = build_controller(str(path), emulator={"winch": {"enabled": True}})
    lockstep = LockstepService(controller, {"winch": {"enabled": True}})
    while controller.time_s < 14.0:
        lockstep.advance()
        lockstep.serve()
    session = lockstep.service.session
    winch_msgs = [m for m in lockstep.peer.received if m.get_type() == "WINCH_STATUS"]
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in winch_msgs} == {WINCH_IDS}
    assert 135 <= len(winch_msgs) <= 142  # 10 Hz
    assert all(round(m.line_length * 100) == pytest.approx(m.line_length * 100, abs=1e-3)
               for m in winch_msgs)  # fmt: skip
    assert session.ingest.counters.accepted[WINCH] == len(winch_msgs)
    assert session.ingest.winch is not None and session.ingest.winch.counters.dropped == 0
    assert session.estimator.health.winch_fused > 50
    distance = float(np.linalg.norm(controller.sim.position_ned_m))
    calibration = controller.ground_sensors.calibration  # seed 3: 11 cm long
    encoder = calibration.winch_offset_m + (1.0 + calibration.winch_scale) * distance
    assert abs(encoder - distance) > 0.05
    assert session.estimator.constants.length_m == pytest.approx(encoder, abs=0.03)
    view = io.StringIO()
    Console(file=view, width=200).print(render(lockstep.service))
    assert "winch line [m], tension at winch [N]" in view.getvalue()
    assert "winch" in view.getvalue().split("inputs")[1]  # its rate and count
    # a service without the winch enabled leaves the frames alone (counted as other traffic)
    plain = LockstepService(build_controller(str(path), emulator={"winch": {"enabled": True}}), {})
    for _ in range(400):
        plain.advance()
        plain.serve()
    assert plain.service.session.ingest.winch is None
    assert plain.service.session.ingest.counters.accepted[WINCH] == 0


@pytest.mark.integration
def test_winch_over_udp_from_the_emulator_process(tmp_path) -> None:
    """`tether-companion emulate --winch` in its own process, the service (default dynamic
    filter, winch enabled) on a UDP socket to it: the winch's frames arrive, pass the checks
    and are fused."""
    emulator = EmulatorProcess(
        "paper-circle",
        duration_s=8.0,
        score_path=tmp_path / "score.json",
        speed=2.0,
        extra_args=("--winch",),
    )
    service = asyncio.run(_fly(emulator, {"winch": {"enabled": True}}))
    session = service.session
    gate = session.ingest.winch
    assert gate is not None
    accepted = session.ingest.counters.accepted[WINCH]
    assert accepted >= 50, gate.counters  # 10 Hz for 8 s, minus the link's start
    assert gate.counters.dropped <= 2, gate.counters  # a late first frame or two at most
    assert session.estimator.health.winch_fused >= 30
    assert session.winch.last is not None and 1.0 < session.winch.last.length_m < 20.0


def test_three_state_takes_the_winch_tension_as_its_known_tension() -> None:
    """The paper's 3-state filter with ``tension.source: winch``: the winch's tension (a
    weightless cable: unchanged) is its known tension; the length is not used (said once)."""
    config = load_service_config(
        None,
        {
            "estimator": {"kind": "three_state"},
            "tension": {"source": "winch"},
            "winch": {"enabled": True},
            "recording": {"enabled": False},
        },
    )
    session = EstimationSession(config, load_vehicle_for(config))
    assert "paid-out length" in session.winch.note
    session.on_sample(WinchReading(3.0, 5.0, 4.5, 0.0, HEALTHY))
    assert session.estimator._known_tension_n == 4.5
    assert session.estimator._tension_time_s == 3.0


def test_the_emulated_load_cell_reads_below_zero_about_a_slack_line() -> None:
    """The emulated winch's load cell on a weightless slack line (0 N): its readings scatter
    about zero with the configured 0.2 N of noise, below zero about half the time, and their
    mean is the true zero within its standard error (clamped at zero they average
    0.2 N / sqrt(2 pi) = +0.08 N, the bias the dynamic filter took as pull; sag15)."""
    scenario = load_scenario("paper-circle")
    assert cable_weight_n_per_m(scenario.cable) == 0.0
    sensors = SimpleNamespace(winch_length_m=lambda time_s: 5.0)
    winch = EmulatedWinch(EmulatedWinchConfig(enabled=True), scenario, sensors, 1.7e9)
    sim = SimpleNamespace(
        time_s=0.0,
        cable=SimpleNamespace(tension_n=0.0, paid_out_m=5.0),
        position_ned_m=np.array((3.0, 0.0, 0.0)),
    )
    parser = FrameParser(fast=False)
    tensions = []
    for i in range(400):
        sim.time_s = 0.1 * i
        (msg,) = parser.feed(winch.frame(sim))
        tensions.append(msg.tension * STANDARD_GRAVITY_MPS2)
    below = sum(t < 0.0 for t in tensions) / len(tensions)
    assert 0.4 < below < 0.6
    assert abs(float(np.mean(tensions))) < 3.0 * 0.2 / math.sqrt(len(tensions))
