"""When to send the EKF origin (SET_GPS_GLOBAL_ORIGIN), and the message.

Pure bookkeeping (no I/O), like :mod:`tether_companion.service.streams`: after each
flight-controller boot (or new link) the origin is sent, then again every ``ORIGIN_RETRY_S``
of local time until GPS_GLOBAL_ORIGIN confirms it, at most ``ORIGIN_ATTEMPTS`` times per boot.
"""

from __future__ import annotations

import math

from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.mavlink.units import seconds_to_usec
from tether_companion.service.link_config import OriginConfig

ORIGIN_RETRY_S = 1.0
"""Local time between unconfirmed sends [s]."""
ORIGIN_ATTEMPTS = 5
"""Sends per flight-controller boot before giving up (the autopilot may not answer)."""


class OriginRequests:
    """The origin sends due at a local time.

    Parameters
    ----------
    origin
        The anchor's position and whether to send it at all.
    target_system
        The flight controller's system id.
    """

    def __init__(self, origin: OriginConfig, target_system: int) -> None:
        self._origin = origin
        self._target_system = target_system
        self.attempts = 0
        """Sends since the last :meth:`reset`."""
        self._last_s = -math.inf

    def reset(self) -> None:
        """A new boot or link: the origin is sent again."""
        self.attempts = 0
        self._last_s = -math.inf

    def due(self, now_s: float, confirmed: bool, fc_now_s: float | None) -> MAVLinkMessage | None:
        """SET_GPS_GLOBAL_ORIGIN if one is due at local time ``now_s`` [s], stamped with the
        flight controller's time ``fc_now_s`` [s] (0 while unknown); None otherwise."""
        origin = self._origin
        if not origin.send or confirmed or self.attempts >= ORIGIN_ATTEMPTS:
            return None
        if now_s - self._last_s < ORIGIN_RETRY_S:
            return None
        self.attempts += 1
        self._last_s = now_s
        return dialect.MAVLink_set_gps_global_origin_message(
            self._target_system,
            round(origin.latitude_deg * 1e7),
            round(origin.longitude_deg * 1e7),
            round(origin.altitude_m * 1e3),
            seconds_to_usec(fc_now_s) if fc_now_s is not None else 0,
        )
