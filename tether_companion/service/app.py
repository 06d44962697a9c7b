"""The companion service: an asyncio process around one :class:`EstimationSession`.

Tasks (all named, all owned by :meth:`CompanionService.run`, all cancelled and awaited on the
way out):

* ``link``: :class:`~tether_companion.service.link_supervisor.LinkSupervisor` opens the
  flight-controller link with exponential back-off (missing serial port, refused TCP socket),
  then this class serves it until it closes: the receive loop records every frame,
  hands every message to the session and sends what the session returns; the housekeeping
  (every :data:`HOUSEKEEPING_PERIOD_S`) sends our HEARTBEAT, TIMESYNC requests, stream requests
  (MAV_CMD_SET_MESSAGE_INTERVAL, then REQUEST_DATA_STREAM when that does not work), the EKF
  origin after every flight-controller boot, and notices link loss and silent inputs; it runs
  in the read callback after the batch that finds it due (the flight controller's datagrams
  wake the process 200 times a second: no wake-up of its own, which costs more than the duties
  after a sleep), or from a timer when no datagram came for a period and a grace;
* ``watchdog``: ``WATCHDOG=1`` and ``STATUS=`` to systemd (only if systemd asked).

The recording is written by its own thread (:class:`RecorderThread`: write, rotate, fsync),
so the receive path only queues each frame.

Nothing in the receive path blocks: decoding, the EKF update and the reply happen inline
within the socket's read callback (no queue, no task switch), which is what keeps the
IMU-to-estimate latency and the CPU per datagram low.
"""

from __future__ import annotations

import asyncio
import gc
import math
import time
import traceback
from collections.abc import Awaitable, Callable

from tether_companion.config import ConfigError
from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.mavlink.link import Delivered, Link
from tether_companion.physics.vehicle import VehicleProfile, load_vehicle
from tether_companion.service.clock import FcClock
from tether_companion.service.config import ServiceConfig
from tether_companion.service.housekeeping import Housekeeping
from tether_companion.service.ingest import IMU
from tether_companion.service.link_supervisor import LinkSupervisor, log, wait_or_stop
from tether_companion.service.origin import OriginRequests
from tether_companion.service.publish import Publication
from tether_companion.service.recording_thread import RecorderThread, open_recorder
from tether_companion.service.security import LinkSecurity
from tether_companion.service.session import EstimationSession, Step
from tether_companion.service.state import ServiceState
from tether_companion.service.streams import StreamRequests
from tether_companion.service.systemd import SystemdNotifier
from tether_companion.service.vehicle_fetch import FROM_AUTOPILOT, VehicleFetch
from tether_companion.vehicle_params.profile import profile_from_parameters

HOUSEKEEPING_PERIOD_S = 0.05
HOUSEKEEPING_GRACE_S = 0.01
"""The timer does the housekeeping when no datagram came this long [s] after it was due."""


class CompanionService(Housekeeping):
    """The live service: link management around an :class:`EstimationSession`.

    Parameters
    ----------
    config
        Validated configuration.
    vehicle
        Vehicle profile.
    notifier
        systemd notifier (default: from the environment).
    open_link_fn
        Opens the link (injected in tests); default opens ``config.link.connect``.
    monotonic_s
        Local clock [s].
    on_publication
        Called with every published estimate (e.g. a CSV writer).
    """

    def __init__(
        self,
        config: ServiceConfig,
        vehicle: VehicleProfile,
        *,
        notifier: SystemdNotifier | None = None,
        open_link_fn: Callable[[], Awaitable[Link]] | None = None,
        monotonic_s: Callable[[], float] = time.monotonic,
        on_publication: Callable[[Publication], None] | None = None,
    ) -> None:
        self.config = config
        self.vehicle = vehicle
        self.session = EstimationSession(config, vehicle)
        self.security = LinkSecurity(config.security, config.link, monotonic_s=monotonic_s)
        """Signing key, signer and verifier; a trust gate per opened link (docs/security.md)."""
        self.vehicle_fetch = (
            VehicleFetch(
                config.link.autopilot,
                config.link.fc_system_id,
                config.link.fc_component_id,
                config.autopilot_vehicle,
            )
            if config.vehicle == FROM_AUTOPILOT
            else None
        )
        """Reads the profile from the flight controller (vehicle: from_autopilot); while it is
        not done the inputs are held (no estimate from a profile the vehicle may not have)."""
        self._vehicle_ready = False
        self._fatal: ConfigError | None = None
        self.notifier = notifier if notifier is not None else SystemdNotifier()
        self.clock = FcClock()
        self.state = ServiceState()
        self.recorder: RecorderThread | None = None
        self.link: Link | None = None
        self._monotonic_s = monotonic_s
        self._on_publication = on_publication
        self._endpoint = parse_endpoint(config.link.connect, "connect", key="link.connect")
        self.supervisor = LinkSupervisor(
            self._endpoint, open_link_fn or self._open_default_link, config.link, self.state
        )
        """Opens the link, hands it to :meth:`_serve_opened`, re-opens it."""
        self.streams = StreamRequests(config.link, config.streams)
        """The inputs asked for and when to ask again."""
        self._timesync_pending: dict[int, float] = {}
        self._fc_heard_s = -math.inf
        self._next_heartbeat_s = -math.inf
        self._next_timesync_s = -math.inf
        self.origin = OriginRequests(config.origin, config.link.fc_system_id)
        """When to send the EKF origin again."""
        self._last_latest_fc_s = -math.inf
        self._key_installed = False

    def monotonic_s(self) -> float:
        """The service's local clock [s] (injected for lock-step use)."""
        return self._monotonic_s()

    # ------------------------------------------------------------------ lifecycle
    async def run(self, stop: asyncio.Event) -> None:
        """Run until ``stop`` is set (SIGTERM/SIGINT), then shut down cleanly.

        Raises
        ------
        ConfigError
            When the recording directory cannot be created or written.
        """
        self.recorder = open_recorder(self.config.recording)
        for note in (self.session.winch.note, self.session.cable_angle.note):
            if note:
                log(note)
        gc.collect()
        gc.freeze()  # start-up objects leave the collector's view: shorter pauses on the hot path
        self.notifier.ready(status="started, connecting to the flight controller")
        tasks = [
            asyncio.create_task(self.supervisor.run(stop, self._serve_opened), name="link"),
            asyncio.create_task(self._watchdog(stop), name="watchdog"),
        ]
        stopper = asyncio.create_task(stop.wait(), name="stop")
        try:
            done, _ = await asyncio.wait([*tasks, stopper], return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                if task is not stopper and not task.cancelled() and task.exception() is not None:
                    raise task.exception()  # type: ignore[misc]
        finally:
            self.notifier.stopping()
            for task in (*tasks, stopper):
                task.cancel()
            await asyncio.gather(*tasks, stopper, return_exceptions=True)
            if self.recorder is not None:
                await asyncio.to_thread(self.recorder.close)
            self.notifier.close()

    async def _open_default_link(self) -> Link:
        link_cfg = self.config.link
        return await open_link(
            self._endpoint,
            system_id=link_cfg.system_id,
            component_id=link_cfg.component_id,
            trust=self.security.new_trust(),
            signer=self.security.signer,
        )

    # ------------------------------------------------------------------ link supervision
    async def _serve_opened(self, link: Link) -> None:
        """Serve one link the supervisor opened, until it closes."""
        self.link = link
        try:
            await self._serve(link)
        finally:
            self.link = None

    async def _serve(self, link: Link) -> None:
        """Receive and housekeep on one open link until it closes (LinkClosed).

        Messages are handled inside the transport's read callback (:meth:`Link.set_receiver`):
        no queue and no task switch between a datagram and its estimate.
        """
        self._reset_link_state()
        self._send_now_to(link)
        loop = asyncio.get_running_loop()
        fatal = loop.create_future()
        timer: asyncio.TimerHandle | None = None
        next_due_s = -math.inf

        def housekeeping(fallback_s: float) -> None:
            """Housekeeping if due; the timer re-armed ``fallback_s`` [s] ahead."""
            nonlocal timer, next_due_s
            now = self._monotonic_s()
            if now < next_due_s:
                return
            next_due_s = now + HOUSEKEEPING_PERIOD_S
            if timer is not None:
                timer.cancel()
            timer = loop.call_later(fallback_s, housekeeping, HOUSEKEEPING_PERIOD_S)
            self.housekeep(link, now)

        def receive(items: list[Delivered]) -> None:
            for item in items:
                self._handle_guarded(link, item)
            housekeeping(HOUSEKEEPING_PERIOD_S + HOUSEKEEPING_GRACE_S)
            if self._fatal is not None and not fatal.done():  # vehicle: from_autopilot
                fatal.set_result(None)

        getter: asyncio.Future[MAVLinkMessage] | None = None
        try:
            housekeeping(HOUSEKEEPING_PERIOD_S)
            # the input frames' test reads the configuration only: a session made later (the
            # vehicle read from the flight controller) takes the same frames
            link.set_receiver(receive, self.session.frames.take)
            while True:  # what was queued before the receiver was set, then the closing
                getter = asyncio.ensure_future(link.recv())
                await asyncio.wait([getter, fatal], return_when=asyncio.FIRST_COMPLETED)
                if fatal.done():
                    raise self._fatal  # type: ignore[misc]
                receive([getter.result()])  # raises LinkClosed once closed
        finally:
            link.set_receiver(None)
            self.session.send_now = None
            if getter is not None:
                getter.cancel()
            if timer is not None:
                timer.cancel()

    def _send_now_to(self, link: Link) -> None:
        """The session hands its messages to ``link`` the moment they exist: an estimate goes
        out before the book-keeping of its tick (:attr:`EstimationSession.send_now`)."""
        send = self._send

        def send_now(messages: list[MAVLinkMessage]) -> None:
            for out in messages:
                send(link, out)

        self.session.send_now = send_now

    def _handle_guarded(self, link: Link, item: Delivered) -> None:
        """One message, or one input frame the link delivered as bytes (:meth:`handle_frame`);
        an unexpected error is counted and reported, never fatal in flight."""
        try:
            if type(item) is bytes:
                self.handle_frame(link, item, self._monotonic_s())
            else:
                self.handle_message(link, item, self._monotonic_s())  # type: ignore[arg-type]
        except Exception as exc:  # noqa: BLE001 - a bug must not take the position away
            self.state.handler_errors += 1
            self.state.last_error = f"error handling {_kind_of(item)}: {exc!r}"
            if self.state.handler_errors == 1:
                traceback.print_exc()

    def _reset_link_state(self) -> None:
        self._fc_heard_s = -math.inf
        self._next_heartbeat_s = -math.inf
        self.streams.reset()
        self.origin.reset()
        self.state.origin_confirmed = False
        self._key_installed = False

    # ------------------------------------------------------------------ receive path
    def handle_message(self, link: Link, msg: MAVLinkMessage, now_s: float) -> None:
        """Record, process and answer one received message (``now_s``: local time [s]).

        Public so that a lock-step harness can drive the service without sockets.
        """
        if self.recorder is not None:
            self.recorder.write(bytes(msg.get_msgbuf()))
        self.state.received += 1
        session = self.session
        kind = None
        if session.ingest.from_flight_controller(msg):
            self._fc_heard(now_s)
            kind = msg.get_type()
            if kind in ("HEARTBEAT", "TIMESYNC", "COMMAND_ACK", "GPS_GLOBAL_ORIGIN"):
                self._handle_control(link, msg, kind, now_s)
                return
            fetch = self.vehicle_fetch
            if fetch is not None and kind == "PARAM_VALUE":
                fetch.on_param_value(msg)
                return
        if self.vehicle_fetch is not None and not self._vehicle_read(link, now_s):
            return
        self._after_step(link, session, session.on_message(msg, now_s, kind), now_s)

    def handle_frame(self, link: Link, frame: bytes, now_s: float) -> None:
        """:meth:`handle_message` for one intact, admitted frame of the flight controller's
        input streams that the session's
        :meth:`FrameIngest.take <tether_companion.service.ingest_frames.FrameIngest.take>`
        accepted (the link delivers such a datagram as its bytes): the same recording, counts,
        samples and replies as for the message decoded from it, without the message."""
        if self.recorder is not None:
            self.recorder.write(frame)
        state = self.state
        state.received += 1
        # take() checked the sender ids, the gate the address: the flight controller heard
        self._fc_heard_s = now_s
        if not state.link_up:  # the rest of _fc_heard, once per link
            self._fc_heard(now_s)
        if self.vehicle_fetch is not None and not self._vehicle_read(link, now_s):
            return
        session = self.session
        self._after_step(link, session, session.on_frame(frame, now_s), now_s)

    def _fc_heard(self, now_s: float) -> None:
        """A message from the flight controller at local time ``now_s`` [s]."""
        self._fc_heard_s = now_s
        if not self.state.link_up:
            self.state.link_up = True
            ids = f"{self.config.link.fc_system_id}/{self.config.link.fc_component_id}"
            self.state.link_text = f"flight controller {ids} on {self._endpoint}"

    def _after_step(
        self, link: Link, session: EstimationSession, step: Step | None, now_s: float
    ) -> None:
        """What follows one message's step: a reboot it confirmed, the clock model, the
        messages to send, the publication record (None: an empty step)."""
        ingest = session.ingest
        if ingest.rebooted:
            self._on_fc_reboot()
        latest = ingest.clock.latest_fc_s
        if latest > self._last_latest_fc_s:
            self._last_latest_fc_s = latest
            self.clock.observe(latest, now_s)
        if step is None:
            return
        messages = step.messages
        if messages:  # none with send_now wired (the live service): they went out already
            for out in messages:
                self._send(link, out)
        if step.publication is not None and self._on_publication is not None:
            self._on_publication(step.publication)

    def _handle_control(self, link: Link, msg: MAVLinkMessage, kind: str, now_s: float) -> None:
        if kind == "HEARTBEAT":
            self.session.on_fc_heartbeat(msg.base_mode, msg.custom_mode)
            self.state.fc_autopilot = msg.autopilot
            self.state.fc_armed = bool(msg.base_mode & dialect.MAV_MODE_FLAG_SAFETY_ARMED)
        elif kind == "TIMESYNC":
            if msg.tc1 == 0:
                fc_now = self.clock.fc_now_s(now_s)
                if fc_now is not None:  # answer in the FC's own time base: its offset stays ~0
                    self._send(link, dialect.MAVLink_timesync_message(int(fc_now * 1e9), msg.ts1))
            else:
                sent = self._timesync_pending.pop(msg.ts1, None)
                if sent is not None:
                    self.clock.observe_timesync(msg.tc1 * 1e-9, sent, now_s)
        elif kind == "COMMAND_ACK":
            if msg.command == dialect.MAV_CMD_SET_MESSAGE_INTERVAL:
                self.streams.on_interval_ack(msg.result)
        elif kind == "GPS_GLOBAL_ORIGIN":
            self.state.origin_confirmed = True

    def _vehicle_read(self, link: Link, now_s: float) -> bool:
        """Whether the profile from the flight controller is in use (built on the first call
        after the fetch completes; a bad parameter set falls back or stops the service)."""
        fetch = self.vehicle_fetch
        if fetch is None or self._vehicle_ready:
            return True
        if not fetch.done(now_s):
            return False
        settings = self.config.autopilot_vehicle
        ids = f"{self.config.link.fc_system_id}/{self.config.link.fc_component_id}"
        try:
            profile = profile_from_parameters(
                fetch.params,
                float(settings.mass_kg or 0.0),
                load_vehicle(settings.base),
                source=f"flight controller {ids} parameters",
            )
        except ConfigError as exc:
            if settings.fallback is None:
                self._fatal = exc
                return False
            self._vehicle_ready = True  # keep the fallback profile the session was built with
            self._send_text(
                link,
                dialect.MAV_SEVERITY_WARNING,
                f"{exc.key}={exc.value} bad: vehicle {settings.fallback}",
            )
            self.state.last_error = f"vehicle from autopilot: {exc}; using {settings.fallback}"
            return True
        self._vehicle_ready = True
        self.vehicle = profile
        self.session = EstimationSession(self.config, profile)
        self._send_now_to(link)
        self._send_text(link, dialect.MAV_SEVERITY_INFO, f"vehicle {profile.frame} from FC params")
        return True

    def _send_text(self, link: Link, severity: int, text: str) -> None:
        self._send(link, dialect.MAVLink_statustext_message(severity, text[:50].encode(), 0, 0))

    def _on_fc_reboot(self) -> None:
        """The flight controller restarted: new clock, new origin, streams asked for again."""
        if self.vehicle_fetch is not None:  # its parameters may have changed: read them again
            self.vehicle_fetch.restart()
            self._vehicle_ready = False
        self.clock.reset()
        self._last_latest_fc_s = -math.inf
        self.streams.reset()
        self.origin.reset()
        self.state.origin_confirmed = False
        self._timesync_pending.clear()
        self._key_installed = False

    def _send(self, link: Link, msg: MAVLinkMessage) -> None:
        frame = link.encoder.encode(msg)
        link.send_bytes(frame)
        if self.recorder is not None:
            self.recorder.write(frame)
        kind = msg.get_type()
        self.state.sent_by_type[kind] = self.state.sent_by_type.get(kind, 0) + 1

    # ------------------------------------------------------------------ systemd, recording
    async def _watchdog(self, stop: asyncio.Event) -> None:
        interval = self.notifier.watchdog_interval_s or self.config.watchdog_interval_s or None
        status_every_s = 5.0
        next_status = 0.0
        while not stop.is_set():
            now = self._monotonic_s()
            if interval:
                self.notifier.watchdog()
            if now >= next_status:
                next_status = now + status_every_s
                self.notifier.status(self.status_line())
            await wait_or_stop(stop, min(interval or status_every_s, status_every_s))

    def status_line(self) -> str:
        """One line for ``systemctl status`` and logs."""
        pub = self.session.publisher
        return (
            f"{self.state.link_text}; IMU {self.state.rates_hz[IMU]:.0f} Hz; "
            f"published {self.state.rates_hz['published']:.1f} Hz; health {pub.health}"
        )


def _kind_of(item: Delivered) -> str:
    """The message name of a delivered message or input frame (MAVLink 2)."""
    if type(item) is bytes:
        msg_id = item[7] | (item[8] << 8) | (item[9] << 16)
        return dialect.mavlink_map[msg_id].msgname
    return item.get_type()  # type: ignore[union-attr]
