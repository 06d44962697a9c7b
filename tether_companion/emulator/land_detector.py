"""ArduCopter's land detector as the emulated flight controller reports it (EXTENDED_SYS_STATE
``MAV_LANDED_STATE_ON_GROUND``).

ArduCopter (``land_detector.cpp``) sets its ``land_complete`` flag while disarmed, clears it as
soon as the vehicle leaves the ground, and sets it again only after ``LAND_DETECTOR_TRIGGER_SEC``
(1 s) of the landing conditions holding (motors at their lower limit, the airframe not
accelerating). The emulator's simulator knows the ground contact exactly; the detector adds
ArduCopter's second of confirmation, so a service that trusts the landed state sees the real
autopilot's delay after a touchdown, not the simulator's instant. Pure.
"""

from __future__ import annotations

LAND_DETECTOR_TRIGGER_S = 1.0
"""Seconds of ground contact with the motors armed before the landing is complete [s]."""


class LandDetector:
    """``complete``: the vehicle is known to be on the ground (disarmed, or armed and in
    contact for :data:`LAND_DETECTOR_TRIGGER_S`). Starts complete (a vehicle boots on the
    ground)."""

    def __init__(self, trigger_s: float = LAND_DETECTOR_TRIGGER_S) -> None:
        self.trigger_s = float(trigger_s)
        self.complete = True
        self._contact_since_s: float | None = None

    def update(self, time_s: float, armed: bool, in_contact: bool) -> None:
        """One tick at ``time_s`` [s]: ``armed`` the motors, ``in_contact`` the simulator's
        ground contact."""
        if not armed:
            self.complete = True
            self._contact_since_s = None
            return
        if not in_contact:
            self.complete = False
            self._contact_since_s = None
            return
        if self.complete:
            return
        if self._contact_since_s is None:
            self._contact_since_s = time_s
        if time_s - self._contact_since_s >= self.trigger_s:
            self.complete = True
