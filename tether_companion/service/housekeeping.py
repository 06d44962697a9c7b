"""The live service's periodic duties: HEARTBEAT, TIMESYNC, input rates, stream requests, the
EKF origin, link-loss and silent-input detection (:class:`Housekeeping`, a part of
:class:`~tether_companion.service.app.CompanionService`, which runs it every
``HOUSEKEEPING_PERIOD_S`` from its read callback or a timer)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.mavlink.link import Link
from tether_companion.service.health import NO_IMU, STALE
from tether_companion.service.ingest import IMU
from tether_companion.service.link_supervisor import log
from tether_companion.service.streams import INPUT_SILENT_S

if TYPE_CHECKING:
    from tether_companion.service.clock import FcClock
    from tether_companion.service.config import ServiceConfig
    from tether_companion.service.origin import OriginRequests
    from tether_companion.service.security import LinkSecurity
    from tether_companion.service.session import EstimationSession
    from tether_companion.service.state import ServiceState
    from tether_companion.service.streams import StreamRequests
    from tether_companion.service.vehicle_fetch import VehicleFetch


class Housekeeping:
    """The periodic duties of :class:`~tether_companion.service.app.CompanionService` (a part
    of it: it reads and sets the service's state below and sends with its ``_send``)."""

    config: ServiceConfig
    session: EstimationSession
    security: LinkSecurity
    vehicle_fetch: VehicleFetch | None
    clock: FcClock
    state: ServiceState
    streams: StreamRequests
    origin: OriginRequests
    _vehicle_ready: bool
    _fc_heard_s: float
    _next_heartbeat_s: float
    _next_timesync_s: float
    _timesync_pending: dict[int, float]
    _key_installed: bool
    _send: Callable[[Link, MAVLinkMessage], None]
    """Frames, sends and records one message (the service's)."""

    def housekeep(self, link: Link, now_s: float) -> None:
        """Periodic duties at local time ``now_s`` [s]: heartbeat, TIMESYNC, rates, stream
        requests, origin, link-loss and silent-input detection (public for lock-step use).
        """
        cfg = self.config.link
        fetch = self.vehicle_fetch
        if fetch is not None and not self._vehicle_ready and self.state.link_up:
            for request in fetch.requests(now_s):
                self._send(link, request)
        if now_s >= self._next_heartbeat_s:
            self._next_heartbeat_s = now_s + 1.0 / cfg.heartbeat_hz
            status = (
                dialect.MAV_STATE_ACTIVE
                if self.session.publisher.health == "ok"
                else dialect.MAV_STATE_STANDBY
            )
            self._send(
                link,
                dialect.MAVLink_heartbeat_message(
                    dialect.MAV_TYPE_ONBOARD_CONTROLLER,
                    dialect.MAV_AUTOPILOT_INVALID,
                    0,
                    0,
                    status,
                    3,
                ),
            )
        if cfg.timesync_hz > 0 and now_s >= self._next_timesync_s:
            self._next_timesync_s = now_s + 1.0 / cfg.timesync_hz
            stamp_ns = int(now_s * 1e9)
            self._timesync_pending = {
                k: v for k, v in self._timesync_pending.items() if now_s - v < 5.0
            }
            self._timesync_pending[stamp_ns] = now_s
            self._send(link, dialect.MAVLink_timesync_message(0, stamp_ns))
        self._update_rates(now_s)
        self._report_trust_events(link)
        fc_present = now_s - self._fc_heard_s < cfg.link_timeout_s
        if not fc_present:
            if self.state.link_up:
                self.state.link_up = False
                self.state.link_losses += 1
                self.state.link_text = (
                    f"link lost: nothing from the flight controller for {cfg.link_timeout_s:g} s"
                )
                for msg in self.session.publisher.set_health(STALE):
                    self._send(link, msg)
            return
        if self.config.security.install_key and not self._key_installed:
            self._key_installed = True
            self._send(link, self.security.setup_signing_message())
        self._send_origin(link, now_s)
        if fetch is not None and not self._vehicle_ready:
            return  # inputs are held, not silent: no re-requests, no no_imu until the profile
        for request in self.streams.due(now_s, self.session.ingest.counters.accepted):
            self._send(link, request)
        if self.streams.silent_s(IMU, now_s) > INPUT_SILENT_S:
            for msg in self.session.publisher.set_health(NO_IMU):
                self._send(link, msg)

    def _report_trust_events(self, link: Link) -> None:
        """Log the trust gate's address changes once each (stderr: the journal)."""
        trust = getattr(link, "trust", None)  # lock-step harnesses bring their own link
        if trust is None or not trust.events:
            return
        for event in trust.events:
            log(f"{link.endpoint}: {event}")
        self.state.last_error = trust.events[-1]
        trust.events.clear()

    def _send_origin(self, link: Link, now_s: float) -> None:
        """SET_GPS_GLOBAL_ORIGIN after each FC boot until GPS_GLOBAL_ORIGIN answers (bounded)."""
        msg = self.origin.due(now_s, self.state.origin_confirmed, self.clock.fc_now_s(now_s))
        if msg is not None:
            self.state.origin_sent += 1
            self._send(link, msg)

    def _update_rates(self, now_s: float) -> None:
        counts = {
            **self.session.ingest.counters.accepted,
            "published": self.session.publisher.counters.published,
        }
        if self.state.update_rates(now_s, counts):
            for kind in self.streams.table:
                self.state.ages_s[kind] = self.streams.silent_s(kind, now_s)
