"""The emulator's landed state follows ArduCopter's land detector: on the ground while
disarmed, off it at lift-off, on it again only after 1 s of contact (not at the simulator's
instant of touchdown)."""

from __future__ import annotations

from tether_companion.emulator.land_detector import LAND_DETECTOR_TRIGGER_S, LandDetector
from tether_companion.emulator.lockstep import LockstepPeer, build_controller
from tether_companion.emulator.modes import CopterMode
from tether_companion.mavlink.framing import dialect

ON_GROUND = dialect.MAV_LANDED_STATE_ON_GROUND


def test_the_detector_confirms_a_touchdown_after_its_trigger_time() -> None:
    detector = LandDetector()
    assert detector.complete  # boots on the ground
    detector.update(0.0, armed=True, in_contact=True)
    assert detector.complete  # armed on the ground: still landed until it leaves
    detector.update(0.1, armed=True, in_contact=False)
    assert not detector.complete
    detector.update(5.0, armed=True, in_contact=True)
    detector.update(5.0 + 0.9 * LAND_DETECTOR_TRIGGER_S, armed=True, in_contact=True)
    assert not detector.complete
    detector.update(5.0 + 0.95 * LAND_DETECTOR_TRIGGER_S, armed=True, in_contact=False)
    detector.update(6.0, armed=True, in_contact=True)  # a bounce restarts the count
    detector.update(6.0 + 0.99 * LAND_DETECTOR_TRIGGER_S, armed=True, in_contact=True)
    assert not detector.complete
    detector.update(6.0 + LAND_DETECTOR_TRIGGER_S, armed=True, in_contact=True)
    assert detector.complete
    detector.update(7.5, armed=True, in_contact=False)
    detector.update(7.6, armed=False, in_contact=False)  # disarmed: landed, as ArduCopter says
    assert detector.complete


def test_the_emulator_reports_on_ground_a_second_after_touchdown() -> None:
    fc = build_controller("hover", landed=True)
    gcs = LockstepPeer(fc)
    assert gcs.command(dialect.MAV_CMD_DO_SET_MODE, 1, int(CopterMode.GUIDED)) == 0
    assert gcs.command(dialect.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
    assert gcs.command(dialect.MAV_CMD_SET_MESSAGE_INTERVAL, 245, 2e4) == 0  # 50 Hz
    assert gcs.command(dialect.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 3.0) == 0
    gcs.advance(8.0)
    assert not fc.sim.landed
    assert gcs.command(dialect.MAV_CMD_NAV_LAND) == 0
    touchdown_s = None
    states: list[tuple[float, int]] = []
    for _ in range(1500):  # 15 s in 10 ms steps
        for m in gcs.advance(0.01):
            if m.get_type() == "EXTENDED_SYS_STATE":
                states.append((fc.sim.time_s, m.landed_state))
        if touchdown_s is None and fc.sim.landed:
            touchdown_s = fc.sim.time_s
    assert touchdown_s is not None
    first_on_ground = min(t for t, s in states if s == ON_GROUND and t > touchdown_s - 1.0)
    assert LAND_DETECTOR_TRIGGER_S - 0.05 <= first_on_ground - touchdown_s <= 1.2
    in_contact_before = [s for t, s in states if touchdown_s <= t < first_on_ground]
    assert in_contact_before and ON_GROUND not in in_contact_before
