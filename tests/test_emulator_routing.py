"""The emulated flight controller routes MAVLink between its links as ArduPilot does
(tether_companion/emulator/routing.py): a ground station's command to the companion reaches
it through the autopilot, bytes unchanged; nothing goes back on the link it came in on."""

from __future__ import annotations

import numpy as np

from tether_companion.emulator.lockstep import LockstepPeer, build_controller
from tether_companion.emulator.routing import MavlinkRoutes, Routing
from tether_companion.mavlink import estimates
from tether_companion.mavlink.framing import FrameEncoder, dialect

COMPANION = (1, 191)
GCS = (255, 190)


def _heartbeat() -> dialect.MAVLink_heartbeat_message:
    return dialect.MAVLink_heartbeat_message(
        dialect.MAV_TYPE_ONBOARD_CONTROLLER, dialect.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3
    )


def _mode_command(target: tuple[int, int]) -> dialect.MAVLink_command_long_message:
    return dialect.MAVLink_command_long_message(
        *target, dialect.MAV_CMD_USER_2, 0, 1, 0, 0, 0, 0, 0, 0
    )


def test_routes_follow_ardupilot_rules() -> None:
    routes = MavlinkRoutes(1, 1)
    assert routes.route(*COMPANION, 0) == Routing((), True)  # nobody known: ours, kept
    routes.learn(*COMPANION, 1)
    routes.learn(*GCS, 0)
    routes.learn(77, 9, 2)
    routes.learn(1, 1, 3)  # our own ids echoed back: not a route
    assert routes.route(1, 1, 0) == Routing((), True)  # for us alone
    assert routes.route(*COMPANION, 0) == Routing((1,), False)  # to the companion's link
    assert routes.route(*COMPANION, 1) == Routing((), True)  # never back where it came from
    assert routes.route(77, 5, 0) == Routing((2,), False)  # another system: any component
    assert routes.route(1, 0, 0) == Routing((1,), True)  # our system's components, and us
    assert routes.route(0, 0, 1) == Routing((0, 2), True)  # broadcast: every other route
    assert routes.route(99, 1, 0) == Routing((), False)  # an unknown system: dropped
    routes.forget_link(1)
    assert routes.route(*COMPANION, 0) == Routing((), True)


def test_a_ground_station_command_reaches_the_companion_through_the_autopilot() -> None:
    fc = build_controller("hover")
    companion = LockstepPeer(fc, *COMPANION)
    gcs = LockstepPeer(fc, *GCS)
    companion.send(_heartbeat())
    gcs.send(_heartbeat())
    assert fc.counters.routed == 1  # the ground station's heartbeat, to the companion
    companion.received.clear()
    gcs.received.clear()

    frame = FrameEncoder(*GCS).encode(_mode_command(COMPANION))
    gcs.send_bytes(frame)
    (relayed,) = [m for m in companion.received if m.get_type() == "COMMAND_LONG"]
    assert bytes(relayed.get_msgbuf()) == frame  # unchanged
    assert (relayed.get_srcSystem(), relayed.get_srcComponent()) == GCS
    assert not [m for m in gcs.received if m.get_type() == "COMMAND_LONG"]  # not echoed
    assert not [m for m in gcs.received if m.get_type() == "COMMAND_ACK"]  # not the FC's
    assert fc.counters.routed == 2 and fc.counters.other_target == 0

    # the companion's answer goes back to the ground station's link only
    ack = dialect.MAVLink_command_ack_message(
        dialect.MAV_CMD_USER_2, dialect.MAV_RESULT_ACCEPTED, 0, 0, *GCS
    )
    companion.send(ack)
    assert [m.result for m in gcs.received if m.get_type() == "COMMAND_ACK"] == [
        dialect.MAV_RESULT_ACCEPTED
    ]

    # the companion's broadcast estimate: used by the autopilot and seen by the ground station
    estimate = estimates.PoseEstimate(fc.boot_time_s, np.zeros(3), (0.0, 0.0, 0.0), np.eye(6), 0)
    received_before = fc.scorer.report().received.get("VISION_POSITION_ESTIMATE", 0)
    companion.send(estimates.vision_position_estimate_message(estimate))
    assert fc.scorer.report().received.get("VISION_POSITION_ESTIMATE", 0) == received_before + 1
    assert [m for m in gcs.received if m.get_type() == "VISION_POSITION_ESTIMATE"]


def test_with_one_link_nothing_is_routed() -> None:
    """The companion alone on the flight controller (the usual test set-up): a command for
    another component of the autopilot's system is the autopilot's to ignore, as before."""
    fc = build_controller("hover")
    companion = LockstepPeer(fc, *COMPANION)
    companion.send(_heartbeat())
    companion.send(_mode_command((1, 154)))
    assert fc.counters.routed == 0 and fc.counters.other_target == 1
