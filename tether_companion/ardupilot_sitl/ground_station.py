"""A ground station for ArduCopter SITL (pymavlink, an independent MAVLink implementation):
commands (mode, arm, takeoff, position targets, EKF source set) and what the autopilot tells
(SIM_STATE truth, EKF_STATUS_REPORT, LOCAL_POSITION_NED, STATUSTEXT, failsafes).

A reader thread keeps the latest of each and a history; every wait is bounded in wall time.
Positions are NED [m] from the SITL home, which is the tether's anchor.

With :meth:`GroundStation.start_ground_sensors` it is also the tether's ground station:
the winch (WINCH_STATUS at ``winch_rate_hz`` from (255, 169)) and the cable-angle sensor at the
anchor (DEBUG_VECT ``CABLE_ANG`` at ``angle_rate_hz`` from (255, 158): the service's convention,
:mod:`tether_companion.service.cable_angle`, ``x`` azimuth from true north toward east, ``y``
elevation up [rad], ``time_usec`` the sensor's UNIX time), which the autopilot routes to the
companion, sent in wall time. What they report is the offline simulator's sensors'
(:class:`tether_companion.sim.ground_sensors.GroundSensors`, configured by a
:class:`~tether_companion.sim.ground_sensors.GroundSensorConfig`, seeded): off, the exact length
and the direction with white noise; on, also the encoder's per-flight scale and offset, the
latencies, the steps and the angle's per-flight biases. The sensors record SITL's SIM_STATE
truth as it arrives (25 Hz) in the autopilot's time, so a latency is resolved to the 0.04 s
of that stream. SITL's tether (SIM_Tether.cpp) is a straight spring of rest length
SIM_TETH_LINELEN (8 N/m in tether.parm, stretching 1.5-2.7 m at 12-22 N), not a stiff tether on
a drum: the winch reported here is that of a stiff tether of the same geometry, whose paid-out
line is the cable's length ``max(LINELEN, |p|)`` (the anchor-to-drone distance while taut); its
tension is reported unknown (NaN). The direction at the anchor is the straight line to the
drone.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

import numpy as np
from pymavlink import mavutil

from tether_companion.ardupilot_sitl.telemetry import (
    Sample,
    Telemetry,
    absorb,
    absorb_companion,
)
from tether_companion.mavlink.geo import Geodetic
from tether_companion.sim.ground_sensors import GroundSensorConfig, GroundSensors

FC_SYSTEM, FC_COMPONENT = 1, 1
COMPANION_COMPONENT = 191
"""The service's component id (link.component_id in configs/companion.yaml)."""
GCS_SYSTEM = 255
WINCH_COMPONENT = 169
"""MAV_COMP_ID_WINCH: the ground station's winch sends as (GCS_SYSTEM, WINCH_COMPONENT)."""
ANGLE_COMPONENT = 158
"""MAV_COMP_ID_PERIPHERAL: the cable-angle sensor sends as (GCS_SYSTEM, ANGLE_COMPONENT)."""
ANGLE_NAME = b"CABLE_ANG"
MAV_CMD_SET_EKF_SOURCE_SET = 42007
COPTER_MODES = {"STABILIZE": 0, "ALT_HOLD": 2, "AUTO": 3, "GUIDED": 4, "LOITER": 5, "RTL": 6,
                "CIRCLE": 7, "LAND": 9}  # fmt: skip
MESSAGE_RATES_HZ = {
    "SIM_STATE": 25.0,
    "EKF_STATUS_REPORT": 10.0,
    "LOCAL_POSITION_NED": 25.0,
    "GLOBAL_POSITION_INT": 5.0,
    "SYS_STATUS": 2.0,
    "ATTITUDE": 25.0,
}
"""What the ground station asks for on its own link (SET_MESSAGE_INTERVAL)."""


class FlightError(RuntimeError):
    """A flight step did not happen within its bound (the text says which and why)."""


class GroundStation:
    """The test's ground station on SITL's SERIAL0 (use as a context manager)."""

    def __init__(self, port: int, home: Geodetic, *, connect_timeout_s: float = 20.0) -> None:
        self.home = home
        self.telemetry = Telemetry()
        self._stop = threading.Event()
        self.master = _connect(port, connect_timeout_s)
        self._thread = threading.Thread(target=self._read_loop, name="sitl-gcs", daemon=True)
        self._thread.start()
        self.line_length_m = math.nan
        """The tether's rest length (SIM_TETH_LINELEN) the winch knows [m]; nan: no winch."""
        self.winch_sent = 0
        self.angle_sent = 0
        self._senders: list[threading.Thread] = []
        """The ground station's sensors' threads (winch, cable angle)."""
        self._write_lock = threading.Lock()
        self._locked = False

    def __enter__(self) -> GroundStation:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the reader (and the winch) and close the socket."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        for sender in self._senders:
            sender.join(timeout=5.0)
        self.master.close()

    # ------------------------------------------------------------------ the ground station
    def start_ground_sensors(
        self,
        config: GroundSensorConfig,
        seed: int,
        *,
        winch_line_length_m: float | None = None,
        cable_angle: bool = False,
    ) -> GroundSensors:
        """From now on, send WINCH_STATUS (with ``winch_line_length_m``: the tether's rest
        length SIM_TETH_LINELEN [m]; update :attr:`line_length_m` as it is reeled) and the
        cable's direction at the anchor (``cable_angle``) at ``config``'s rates (wall time),
        with ``config``'s errors drawn from ``seed`` (module docstring). Returns the sensors
        (their calibration for the flight's record)."""
        sensors = GroundSensors(config, "constant_tension", seed)
        tel = self.telemetry
        with tel.lock:
            tel.ground_sensors = sensors
            if tel.truth_ned_m is not None:
                self._record_truth(tel, tel.truth_ned_m)
        if winch_line_length_m is not None:
            self.line_length_m = winch_line_length_m
            self._start_sender("sitl-winch", config.winch_rate_hz, self._winch_frame)
        if cable_angle:
            self._start_sender("sitl-cable-angle", config.angle_rate_hz, self._angle_frame)
        return sensors

    def _record_truth(self, tel: Telemetry, truth_ned_m: np.ndarray) -> None:
        """Give the ground station's sensors SITL's truth at the autopilot's time (under
        ``tel.lock``): the stiff tether's paid-out length ``max(LINELEN, |p|)``."""
        sensors = tel.ground_sensors
        if sensors is None:
            return
        position = (float(truth_ned_m[0]), float(truth_ned_m[1]), float(truth_ned_m[2]))
        length = max(self.line_length_m, math.dist(position, (0.0, 0.0, 0.0)))
        if not math.isfinite(length):  # the winch not started: the angle needs no length
            length = 0.0
        sensors.record(tel.fc_s, length, position, 0.0)

    def _winch_frame(self, packer: mavutil.mavlink.MAVLink, sensors: GroundSensors) -> bytes:
        length = sensors.winch_length_m(self.telemetry.fc_s)
        self.winch_sent += 1
        return mavutil.mavlink.MAVLink_winch_status_message(
            int(time.time() * 1e6), max(0.0, length), math.nan, math.nan, math.nan, math.nan,
            32767, mavutil.mavlink.MAV_WINCH_STATUS_HEALTHY,
        ).pack(packer)  # fmt: skip

    def _angle_frame(self, packer: mavutil.mavlink.MAVLink, sensors: GroundSensors) -> bytes | None:
        angle = sensors.cable_angle_rad(self.telemetry.fc_s, _straight_line_direction)
        if angle is None:
            return None
        self.angle_sent += 1
        return mavutil.mavlink.MAVLink_debug_vect_message(
            ANGLE_NAME, int(time.time() * 1e6), angle[0], angle[1], 0.0
        ).pack(packer)

    def _start_sender(
        self,
        name: str,
        rate_hz: float,
        frame: Callable[[mavutil.mavlink.MAVLink, GroundSensors], bytes | None],
    ) -> None:
        """A thread writing ``frame(packer, sensors)`` (under the telemetry lock) at
        ``rate_hz`` (wall time) once a truth has arrived (None: nothing to send this time)."""
        component = WINCH_COMPONENT if name == "sitl-winch" else ANGLE_COMPONENT
        packer = mavutil.mavlink.MAVLink(None, srcSystem=GCS_SYSTEM, srcComponent=component)
        write = self.master.write
        if not self._locked:  # commands (this thread) and the sensors' frames share the socket
            self._locked = True

            def locked_write(data: bytes) -> None:
                with self._write_lock:
                    write(data)

            self.master.write = locked_write  # pymavlink's senders call master.write
        send = self.master.write
        tel = self.telemetry

        def send_loop() -> None:
            while not self._stop.wait(1.0 / rate_hz):
                with tel.lock:
                    sensors = tel.ground_sensors
                    if tel.truth_ned_m is None or sensors is None:
                        continue
                    data = frame(packer, sensors)
                if data is not None:
                    send(data)

        sender = threading.Thread(target=send_loop, name=name, daemon=True)
        self._senders.append(sender)
        sender.start()

    # ------------------------------------------------------------------ reading
    def _read_loop(self) -> None:
        tel = self.telemetry
        while not self._stop.is_set():
            try:
                msg = self.master.recv_match(blocking=True, timeout=0.2)
            except (OSError, ValueError):
                return
            if msg is None:
                continue
            kind = msg.get_type()
            src = (msg.get_srcSystem(), msg.get_srcComponent())
            if src == (FC_SYSTEM, COMPANION_COMPONENT):
                with tel.lock:
                    absorb_companion(tel, kind, msg)
                continue
            if src != (FC_SYSTEM, FC_COMPONENT):
                continue  # SITL's tether simulator (system 2) and anyone else
            with tel.lock:
                truth = absorb(tel, kind, msg, self.home)
                if truth is not None:
                    self._record_truth(tel, truth)

    def snapshot(self) -> dict:
        """The latest values (copies)."""
        tel = self.telemetry
        with tel.lock:
            hb = tel.heartbeat
            return {
                "fc_s": tel.fc_s,
                "truth_ned_m": None if tel.truth_ned_m is None else tel.truth_ned_m.copy(),
                "fc_ned_m": tel.fc_ned_m.copy(),
                "mode": int(hb.custom_mode) if hb else -1,
                "armed": bool(hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                if hb
                else False,
                "ekf_flags": int(tel.ekf.flags) if tel.ekf else 0,
                "n_samples": len(tel.samples),
                "vision_ned_m": tel.vision_ned_m.copy(),
                "forwarded_vision": tel.forwarded_vision,
                "origin": tel.origin,
            }

    def texts_since(self, index: int = 0) -> list[str]:
        """STATUSTEXTs received from position ``index`` on."""
        with self.telemetry.lock:
            return [text for _, text in self.telemetry.texts[index:]]

    def companion_texts(self) -> list[str]:
        """STATUSTEXTs the companion sent (routed to us by the autopilot)."""
        with self.telemetry.lock:
            return [text for _, text in self.telemetry.companion_texts]

    def samples_between(self, fc_start_s: float, fc_end_s: float) -> list[Sample]:
        """Truth samples with flight-controller time in [start, end]."""
        with self.telemetry.lock:
            return [s for s in self.telemetry.samples if fc_start_s <= s.fc_s <= fc_end_s]

    # ------------------------------------------------------------------ waiting
    def wait_for(
        self, what: str, predicate: Callable[[dict], bool], timeout_s: float, poll_s: float = 0.05
    ) -> dict:
        """Poll the snapshot until ``predicate`` holds; FlightError naming ``what`` after
        ``timeout_s`` wall seconds (with the last STATUSTEXTs)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            snap = self.snapshot()
            if predicate(snap):
                return snap
            time.sleep(poll_s)
        raise FlightError(
            f"{what}: not within {timeout_s:g} s (last autopilot messages: "
            f"{' | '.join(self.texts_since()[-5:]) or 'none'})"
        )

    def wait_fc_time(self, fc_seconds: float, speedup: float) -> dict:
        """Let ``fc_seconds`` of flight-controller time pass (bounded in wall time)."""
        start = self.snapshot()["fc_s"]
        return self.wait_for(
            f"{fc_seconds:g} s of autopilot time",
            lambda s: s["fc_s"] >= start + fc_seconds,
            timeout_s=10.0 + 3.0 * fc_seconds / speedup,
        )

    # ------------------------------------------------------------------ commanding
    def request_streams(self, rates_hz: dict[str, float] | None = None) -> None:
        """SET_MESSAGE_INTERVAL for each message on this link."""
        for name, rate in (rates_hz or MESSAGE_RATES_HZ).items():
            msg_id = getattr(mavutil.mavlink, f"MAVLINK_MSG_ID_{name}")
            self.command(mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / rate)

    def command(
        self,
        command: int,
        *params: float,
        wait_s: float | None = None,
        component: int = FC_COMPONENT,
    ) -> int | None:
        """COMMAND_LONG to the autopilot (or another ``component`` of the vehicle, routed by
        it); with ``wait_s`` wait for the COMMAND_ACK result."""
        p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
        with self.telemetry.lock:
            n_acks = len(self.telemetry.acks)
        self.master.mav.command_long_send(FC_SYSTEM, component, command, 0, *p)
        if wait_s is None:
            return None
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            with self.telemetry.lock:
                for ack in self.telemetry.acks[n_acks:]:
                    if ack.command == command:
                        return int(ack.result)
            time.sleep(0.02)
        raise FlightError(f"command {command}: no COMMAND_ACK within {wait_s:g} s")

    def command_companion(self, command: int, *params: float, wait_s: float) -> int | None:
        """COMMAND_LONG to the companion (component 191), routed by the autopilot."""
        return self.command(command, *params, wait_s=wait_s, component=COMPANION_COMPONENT)

    def set_mode(self, name: str, timeout_s: float = 10.0) -> None:
        """Switch flight mode and wait until the HEARTBEAT shows it."""
        number = COPTER_MODES[name]
        self.command(
            mavutil.mavlink.MAV_CMD_DO_SET_MODE,
            mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            number,
        )
        self.wait_for(f"mode {name}", lambda s: s["mode"] == number, timeout_s)

    def arm(self, timeout_s: float) -> None:
        """Arm (retried every 2 s while the pre-arm checks refuse, bounded)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.command(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
            try:
                self.wait_for("armed", lambda s: s["armed"], 2.0)
                return
            except FlightError:
                continue
        raise FlightError(
            f"arming refused for {timeout_s:g} s: {' | '.join(self.texts_since()[-5:])}"
        )

    def takeoff(self, height_m: float) -> None:
        """MAV_CMD_NAV_TAKEOFF in GUIDED."""
        self.command(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, height_m)

    def go_to(self, ned_m: tuple[float, float, float], yaw_rad: float = 0.0) -> None:
        """GUIDED position target, LOCAL_NED [m] from the EKF origin."""
        type_mask = 0b0000_1001_1111_1000  # position and yaw only
        self.master.mav.set_position_target_local_ned_send(
            0, FC_SYSTEM, FC_COMPONENT, mavutil.mavlink.MAV_FRAME_LOCAL_NED, type_mask,
            *ned_m, 0, 0, 0, 0, 0, 0, yaw_rad, 0,
        )  # fmt: skip

    def request_message(self, message_id: int) -> None:
        """MAV_CMD_REQUEST_MESSAGE (answered on this link)."""
        self.command(mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE, float(message_id))

    def set_ekf_source_set(self, source_set: int) -> int | None:
        """MAV_CMD_SET_EKF_SOURCE_SET (1 = GPS, 2 = external navigation in our parameters)."""
        return self.command(MAV_CMD_SET_EKF_SOURCE_SET, float(source_set), wait_s=5.0)

    def get_param(self, name: str, timeout_s: float = 5.0) -> float:
        """PARAM_REQUEST_READ and wait (bounded) for the answer."""
        with self.telemetry.lock:
            self.telemetry.params.pop(name, None)
        self.master.mav.param_request_read_send(FC_SYSTEM, FC_COMPONENT, name.encode(), -1)
        snap = self.wait_for(
            f"parameter {name}", lambda _s: name in self.telemetry.params, timeout_s
        )
        del snap
        with self.telemetry.lock:
            return self.telemetry.params[name]

    def set_param(self, name: str, value: float) -> None:
        """PARAM_SET (not waited for)."""
        self.master.mav.param_set_send(
            FC_SYSTEM, FC_COMPONENT, name.encode(), value, mavutil.mavlink.MAV_PARAM_TYPE_REAL32
        )


def _straight_line_direction(
    position_ned_m: tuple[float, float, float],
) -> tuple[float, float, float] | None:
    """SITL's tether at the anchor: the unit vector toward the drone (None at the anchor)."""
    distance = math.dist(position_ned_m, (0.0, 0.0, 0.0))
    if distance <= 0.0:
        return None
    return tuple(v / distance for v in position_ned_m)  # type: ignore[return-value]


def _connect(port: int, timeout_s: float):  # noqa: ANN202 - pymavlink connection type
    """Open tcp:127.0.0.1:port and wait for the autopilot's HEARTBEAT (bounded)."""
    deadline = time.monotonic() + timeout_s
    last_error: Exception | None = None
    while time.monotonic() < deadline:
        try:
            master = mavutil.mavlink_connection(
                f"tcp:127.0.0.1:{port}", source_system=GCS_SYSTEM, autoreconnect=False,
                retries=0,
            )  # fmt: skip
            break
        except OSError as exc:
            last_error = exc
            time.sleep(0.2)
    else:
        raise FlightError(f"cannot connect to SITL on tcp {port}: {last_error}")
    while time.monotonic() < deadline:
        msg = master.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        if (
            msg is not None
            and msg.get_srcSystem() == FC_SYSTEM
            and msg.get_srcComponent() == FC_COMPONENT
        ):
            return master
    master.close()
    raise FlightError(f"no HEARTBEAT from the autopilot on tcp {port} within {timeout_s:g} s")
