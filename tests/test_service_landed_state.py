"""The flight controller's landed state (EXTENDED_SYS_STATE.landed_state) as the dynamic
filter's independent on-ground sign: decoded from real MAVLink frames, only from the
(authenticated) flight controller, an unknown MAV_LANDED_STATE counted and dropped; ON_GROUND
withholds the position with its reason, TAKEOFF / LANDING / IN_AIR do not (both autopilots send
those in the air); without the stream the filter's own signs alone, as before."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from level_ticks import level_ticks
from lockstep_service import LockstepService

from tether_companion.emulator.lockstep import build_controller
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic.config import DynamicFilterConfig
from tether_companion.estimation.dynamic.offline import run_dynamic
from tether_companion.estimation.dynamic.on_ground import (
    AUTOPILOT_LANDED,
    AUTOPILOT_LANDED_TIMEOUT_S,
)
from tether_companion.estimation.dynamic.output import ON_GROUND
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.mavlink.signing import SignatureVerifier, Signer
from tether_companion.mavlink.trust import REQUIRED, LinkTrust
from tether_companion.service.config import load_service_config
from tether_companion.service.ingest import LANDED, Ingest, LandedState
from tether_companion.service.streams import StreamRequests
from tether_companion.sim.scenario import load_scenario

FC_IDS = (1, 1)
KEY = bytes(range(3, 35))


def _state(landed_state: int) -> dialect.MAVLink_extended_sys_state_message:
    return dialect.MAVLink_extended_sys_state_message(
        dialect.MAV_VTOL_STATE_UNDEFINED, landed_state
    )


def _attitude(time_s: float) -> dialect.MAVLink_attitude_message:
    return dialect.MAVLink_attitude_message(int(round(time_s * 1e3)), 0.0, 0.0, 0.0, 0, 0, 0)


class _Wire:
    """Frames through one parser (fast or pymavlink's decoder, optionally behind the link's
    signing gate) into an :class:`Ingest` of the shipped configuration."""

    def __init__(self, fast: bool, gate: LinkTrust | None = None) -> None:
        config = load_service_config(None, {"recording": {"enabled": False}})
        self.ingest = Ingest(config.link, config.inputs, config.tension, 4)
        self.parser = FrameParser(gate=gate, fast=fast)
        self.fc = FrameEncoder(*FC_IDS)

    def send(self, encoder: FrameEncoder, msg) -> list[LandedState]:
        out = []
        for decoded in self.parser.feed(encoder.encode(msg)):
            out += self.ingest.receive(decoded)
        return [s for s in out if isinstance(s, LandedState)]


@pytest.mark.parametrize("fast", [True, False], ids=["fast", "pymavlink"])
def test_landed_state_from_the_flight_controller_is_stamped_with_its_newest_time(fast) -> None:
    wire = _Wire(fast)
    counters = wire.ingest.counters
    assert wire.send(wire.fc, _state(dialect.MAV_LANDED_STATE_ON_GROUND)) == []
    assert counters.no_fc_time == 1 and counters.dropped == 1  # no clock yet
    wire.send(wire.fc, _attitude(12.5))
    (state,) = wire.send(wire.fc, _state(dialect.MAV_LANDED_STATE_ON_GROUND))
    assert state == LandedState(12.5, dialect.MAV_LANDED_STATE_ON_GROUND) and state.on_ground
    for landed_state in (
        dialect.MAV_LANDED_STATE_IN_AIR,
        dialect.MAV_LANDED_STATE_TAKEOFF,
        dialect.MAV_LANDED_STATE_LANDING,
        dialect.MAV_LANDED_STATE_UNDEFINED,
    ):
        (state,) = wire.send(wire.fc, _state(landed_state))
        assert not state.on_ground
    assert counters.accepted[LANDED] == 5


@pytest.mark.parametrize("value", [5, 17, 255])
def test_an_unknown_landed_state_is_counted_and_dropped(value) -> None:
    wire = _Wire(fast=True)
    wire.send(wire.fc, _attitude(1.0))
    assert wire.send(wire.fc, _state(value)) == []
    assert wire.ingest.counters.absurd == 1 and wire.ingest.counters.accepted[LANDED] == 0


def test_only_the_flight_controller_and_only_signed_when_signing_is_required() -> None:
    wire = _Wire(fast=True)
    wire.send(wire.fc, _attitude(1.0))
    for ids in ((255, 190), (1, 191), (2, 1)):  # a ground station, a companion, another FC
        assert wire.send(FrameEncoder(*ids), _state(dialect.MAV_LANDED_STATE_ON_GROUND)) == []
    assert wire.ingest.counters.wrong_system == 3
    trust = LinkTrust(REQUIRED, verifier=SignatureVerifier(KEY))
    signed = _Wire(fast=True, gate=trust)
    signed.fc = FrameEncoder(*FC_IDS, Signer(KEY, link_id=1))
    signed.send(signed.fc, _attitude(1.0))
    unsigned = FrameEncoder(*FC_IDS)  # the flight controller's ids, without the key
    assert signed.send(unsigned, _state(dialect.MAV_LANDED_STATE_ON_GROUND)) == []
    assert trust.counters.as_dict()["unsigned"] == 1
    assert len(signed.send(signed.fc, _state(dialect.MAV_LANDED_STATE_ON_GROUND))) == 1


def test_the_service_asks_for_the_landed_state() -> None:
    config = load_service_config(None, {"recording": {"enabled": False}})
    table = StreamRequests(config.link, config.streams).table
    assert table[LANDED].message_id == dialect.MAVLINK_MSG_ID_EXTENDED_SYS_STATE
    assert table[LANDED].rate_hz >= 2.0


def _airborne_estimator():
    """The dynamic filter after 3 s of the paper circle (1.5-2.5 m up: its own height says
    airborne) and the time."""
    scenario = dataclasses.replace(load_scenario("paper-circle"), duration_s=3.0, seed=1)
    run = run_dynamic(scenario, EstimatorConfig(), DynamicFilterConfig())
    assert run.estimator.initialised
    return run.estimator, float(run.time_s[-1])


def test_on_ground_from_the_autopilot_withholds_and_says_why() -> None:
    est, t = _airborne_estimator()
    assert level_ticks(est, t).status != ON_GROUND  # its own signs: airborne
    fused = est.health.accel_fused
    est.set_autopilot_landed(True, t)
    estimate = level_ticks(est, t + 0.05)
    assert estimate.status == ON_GROUND and estimate.reason == AUTOPILOT_LANDED
    assert not estimate.observable and np.all(np.isfinite(estimate.position_ned_m))
    assert est.health.accel_fused == fused  # the force balance is not fused on the ground
    assert est.health.on_ground > 0


def test_in_the_air_taking_off_landing_or_a_stale_report_is_no_sign() -> None:
    est, t = _airborne_estimator()
    est.set_autopilot_landed(False, t)  # IN_AIR, TAKEOFF, LANDING, UNDEFINED
    assert level_ticks(est, t).status != ON_GROUND
    est.set_autopilot_landed(True, t - AUTOPILOT_LANDED_TIMEOUT_S - 0.1)  # too old
    assert level_ticks(est, t + 0.05).status != ON_GROUND


def test_the_emulator_sends_it_and_the_session_hands_it_to_the_filter() -> None:
    """A landed, disarmed start on the emulator: EXTENDED_SYS_STATE ON_GROUND reaches the
    dynamic filter over real frames in lock-step."""
    controller = build_controller("hover", landed=True)
    lockstep = LockstepService(controller, {})
    while controller.time_s < 3.0:
        lockstep.advance()
        lockstep.serve()
    session = lockstep.service.session
    assert session.ingest.counters.accepted[LANDED] >= 5  # asked for at 5 Hz
    landed = session.estimator.autopilot_landed
    assert landed.landed and landed.on_ground(controller.boot_time_s)
