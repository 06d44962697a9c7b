"""Battery voltage from the flight controller's SYS_STATUS or BATTERY_STATUS [V]."""

from __future__ import annotations

import math

from tether_companion.mavlink.framing import MAVLinkMessage

BATTERY_MESSAGES = frozenset({"SYS_STATUS", "BATTERY_STATUS"})
UNKNOWN_MV = 65535
"""UINT16_MAX: the voltage (or cell) is not known."""


def battery_voltage_v(msg: MAVLinkMessage) -> float:
    """The battery voltage [V] a SYS_STATUS (``voltage_battery`` [mV]) or BATTERY_STATUS
    (sum of the known ``voltages`` [mV]: the cells, or the whole pack in the first) carries;
    NaN when unknown."""
    if msg.get_type() == "SYS_STATUS":
        millivolts = msg.voltage_battery
        return math.nan if millivolts in (UNKNOWN_MV, 0) else millivolts * 1e-3
    cells = [v for v in msg.voltages if v != UNKNOWN_MV]
    return sum(cells) * 1e-3 if cells and sum(cells) > 0 else math.nan
