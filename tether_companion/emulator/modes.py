"""ArduPilot Copter flight modes as the emulator implements them.

Mode numbers are Copter's ``custom_mode`` values (ArduCopter ``mode.h``), so ground stations
show the right names. There is no RC transmitter in the emulator, so the pilot-input modes
(STABILIZE, ALT_HOLD, LOITER, POSHOLD, BRAKE) hold the position where they were entered, as a
pilot with centred sticks would in LOITER.
"""

from __future__ import annotations

import enum


class CopterMode(enum.IntEnum):
    """Copter ``custom_mode`` numbers of the supported modes."""

    STABILIZE = 0
    ALT_HOLD = 2
    AUTO = 3
    GUIDED = 4
    LOITER = 5
    RTL = 6
    LAND = 9
    POSHOLD = 16
    BRAKE = 17


ARMABLE_MODES: frozenset[CopterMode] = frozenset(
    {
        CopterMode.STABILIZE,
        CopterMode.ALT_HOLD,
        CopterMode.GUIDED,
        CopterMode.LOITER,
        CopterMode.POSHOLD,
    }
)
"""Modes Copter lets you arm in (AUTO, RTL, LAND and BRAKE refuse)."""

POSITION_MODES: frozenset[CopterMode] = frozenset(
    {
        CopterMode.AUTO,
        CopterMode.GUIDED,
        CopterMode.LOITER,
        CopterMode.RTL,
        CopterMode.POSHOLD,
        CopterMode.BRAKE,
    }
)
"""Modes that need a position estimate (Copter refuses to enter them without one)."""

GUIDED_FLAG_MODES: frozenset[CopterMode] = frozenset(
    {CopterMode.AUTO, CopterMode.GUIDED, CopterMode.RTL}
)
"""Modes reported with MAV_MODE_FLAG_GUIDED_ENABLED in HEARTBEAT.base_mode."""


def mode_from_number(value: float) -> CopterMode | None:
    """The mode for a ``custom_mode`` value, or None if it is not a supported whole number."""
    if value != value or not float(value).is_integer():  # NaN or fractional
        return None
    try:
        return CopterMode(int(value))
    except ValueError:
        return None
