"""A tethered drone holding still, as the MAVLink streams an ArduPilot flight controller sends.

Used by the latency benchmark and by tests that need exact, deterministic input without the
full emulator. The drone hovers at ``position_ned_m`` relative to the anchor with the cable
pulling it toward the anchor at ``tension_n``; attitude and thrust are those of force balance:

    T_vec + F_cable + m g e_d = 0,   F_cable = -f u,   u = p / |p|

so the thrust vector is ``T_vec = f u - m g e_d``, the body z axis points along ``-T_vec``, and
the accelerometer reads the specific force ``R (T_vec + F_cable) / m = R (0, 0, -g)``.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.frames import rotation_ned_to_body
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.mavlink.link import Link, LinkClosed
from tether_companion.mavlink.units import (
    attitude_message,
    distance_sensor_message,
    raw_imu_message,
    servo_output_raw_message,
)
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class HoverState:
    """Attitude [rad], per-motor PWM [us] and specific force (FRD) [m/s^2] of the hover."""

    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    pwm_us: FloatArray
    specific_force_body_mps2: FloatArray
    thrust_n: float


def hover_state(
    vehicle: VehicleProfile, position_ned_m: FloatArray, tension_n: float, yaw_rad: float = 0.0
) -> HoverState:
    """Force-balanced hover of ``vehicle`` at ``position_ned_m`` with the cable at ``tension_n``."""
    p = np.asarray(position_ned_m, dtype=float)
    u = p / np.linalg.norm(p)
    thrust_vec = tension_n * u - vehicle.mass_kg * GRAVITY_MPS2 * np.array([0.0, 0.0, 1.0])
    thrust_n = float(np.linalg.norm(thrust_vec))
    z_body = -thrust_vec / thrust_n
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    zx = cy * z_body[0] + sy * z_body[1]
    zy = -sy * z_body[0] + cy * z_body[1]
    roll = -math.asin(max(-1.0, min(1.0, zy)))
    pitch = math.atan2(zx, z_body[2])
    rotation = rotation_ned_to_body(roll, pitch, yaw_rad)
    force = rotation @ np.array([0.0, 0.0, -GRAVITY_MPS2])
    pwm = _pwm_for_thrust(vehicle, thrust_n / vehicle.n_motors)
    return HoverState(roll, pitch, yaw_rad, np.full(vehicle.n_motors, pwm), force, thrust_n)


def _pwm_for_thrust(vehicle: VehicleProfile, motor_thrust_n: float) -> float:
    """Invert the static thrust curve of one motor [N] -> [us]."""
    curve = vehicle.thrust_curve
    c0, c1, c2 = curve.coefficients_n
    if c2 > 0:
        cmd = (-c1 + math.sqrt(c1 * c1 + 4.0 * c2 * (motor_thrust_n - c0))) / (2.0 * c2)
    else:
        cmd = (motor_thrust_n - c0) / c1
    fraction = min(1.0, max(0.0, cmd / curve.command_full_scale))
    return curve.pwm_min_us + fraction * (curve.pwm_max_us - curve.pwm_min_us)


class HoverStreams:
    """The MAVLink messages of a hovering drone, stamped at a given flight-controller time.

    Parameters
    ----------
    vehicle
        Vehicle profile.
    position_ned_m, tension_n
        Where it hovers and how hard the cable pulls.
    rng
        Noise source; None gives noise-free readings.
    accel_noise_mps2
        Accelerometer white-noise standard deviation [m/s^2].
    imu_hz, attitude_hz, servo_hz, range_hz
        Stream rates [Hz]; each of the others must divide ``imu_hz`` (one IMU sample a tick).
    """

    def __init__(
        self,
        vehicle: VehicleProfile,
        position_ned_m: FloatArray,
        tension_n: float,
        rng: np.random.Generator | None = None,
        accel_noise_mps2: float = 0.1,
        *,
        imu_hz: float = 200.0,
        attitude_hz: float = 100.0,
        servo_hz: float = 100.0,
        range_hz: float = 20.0,
    ) -> None:
        self.state = hover_state(vehicle, position_ned_m, tension_n)
        self.position_ned_m = np.asarray(position_ned_m, dtype=float)
        self._rng = rng
        self._accel_noise = accel_noise_mps2
        self.tick_s = 1.0 / imu_hz
        """IMU period [s]: one tick of :meth:`messages`."""
        self._every = tuple(_ticks_per(imu_hz, hz) for hz in (attitude_hz, servo_hz, range_hz))

    def imu(self, time_s: float) -> MAVLinkMessage:
        """RAW_IMU (milli-g) at ``time_s``."""
        force = self.state.specific_force_body_mps2
        if self._rng is not None:
            force = force + self._rng.normal(0.0, self._accel_noise, 3)
        return raw_imu_message(ImuSample(time_s, force, np.zeros(3)))

    def attitude(self, time_s: float) -> MAVLinkMessage:
        """ATTITUDE at ``time_s``."""
        s = self.state
        return attitude_message(
            AttitudeSample(time_s, s.roll_rad, s.pitch_rad, s.yaw_rad), np.zeros(3)
        )

    def servo(self, time_s: float) -> MAVLinkMessage:
        """SERVO_OUTPUT_RAW at ``time_s``."""
        return servo_output_raw_message(PwmSample(time_s, self.state.pwm_us))

    def rangefinder(self, time_s: float) -> MAVLinkMessage:
        """Downward DISTANCE_SENSOR at ``time_s`` (along the tilted body z axis)."""
        s = self.state
        distance = -self.position_ned_m[2] / (math.cos(s.roll_rad) * math.cos(s.pitch_rad))
        return distance_sensor_message(time_s, distance, min_distance_m=0.2, max_distance_m=40.0)

    def messages(self, time_s: float, tick: int) -> list[MAVLinkMessage]:
        """Everything due at IMU tick ``tick`` (by default a 200 Hz IMU, attitude and servo at
        100 Hz, rangefinder at 20 Hz), attitude and servo first so the IMU tick uses them."""
        attitude_every, servo_every, range_every = self._every
        out: list[MAVLinkMessage] = []
        if tick % attitude_every == 0:
            out.append(self.attitude(time_s))
        if tick % servo_every == 0:
            out.append(self.servo(time_s))
        if tick % range_every == 0:
            out.append(self.rangefinder(time_s))
        out.append(self.imu(time_s))
        return out


def _ticks_per(imu_hz: float, hz: float) -> int:
    """IMU ticks per sample of a stream at ``hz`` (ValueError unless it divides ``imu_hz``)."""
    every = round(imu_hz / hz) if hz > 0 else 0
    if every < 1 or abs(imu_hz / every - hz) > 1e-9 * imu_hz:
        raise ValueError(f"a {hz:g} Hz stream does not divide the {imu_hz:g} Hz IMU stream")
    return every


@dataclass
class FakeFcLog:
    """What a :class:`FakeFlightController` received from the companion."""

    vision: list[MAVLinkMessage]
    commands: list[MAVLinkMessage]
    origins: list[MAVLinkMessage]
    heartbeats: list[MAVLinkMessage]
    statustexts: list[MAVLinkMessage]
    named_values: list[MAVLinkMessage]
    timesync_replies: list[MAVLinkMessage]
    stream_requests: list[MAVLinkMessage]
    vision_arrival_s: dict[int, float]
    """Local monotonic arrival time of each VISION_POSITION_ESTIMATE, by its ``usec``."""


class FakeFlightController:
    """A minimal ArduPilot-like flight controller streaming a hover over a real link.

    It streams only after the companion asked (SET_MESSAGE_INTERVAL or REQUEST_DATA_STREAM
    for RAW_IMU), with SYSTEM_TIME at 5 Hz beside the hover, answers COMMAND_LONG with
    COMMAND_ACK, SET_GPS_GLOBAL_ORIGIN with GPS_GLOBAL_ORIGIN and TIMESYNC requests in its own
    time base, and records everything the companion sends. ``speed`` > 1 runs its clock
    faster than real time (bursts of ticks).

    Parameters
    ----------
    link
        An open listening link (the companion connects to it).
    streams
        The hover's messages.
    speed
        Flight-controller seconds per real second.
    boot_time_s
        Flight-controller time at start (time since its boot) [s].
    message_interval_supported
        False: refuse MAV_CMD_SET_MESSAGE_INTERVAL (old firmware); stream on
        REQUEST_DATA_STREAM only.
    """

    SYSTEM_TIME_S = 0.2
    """SYSTEM_TIME period [s] (5 Hz): what tells the companion of a reboot."""

    def __init__(
        self,
        link: Link,
        streams: HoverStreams,
        *,
        speed: float = 1.0,
        boot_time_s: float = 5.0,
        message_interval_supported: bool = True,
    ) -> None:
        self.link = link
        self.message_interval_supported = message_interval_supported
        self.streams = streams
        self.tick_s = streams.tick_s
        self._system_time_ticks = max(1, round(self.SYSTEM_TIME_S / streams.tick_s))
        self.speed = speed
        self.time_s = boot_time_s
        self.tick = 0
        self.streaming = False
        self.log = FakeFcLog([], [], [], [], [], [], [], [], {})
        self.imu_sent_s: dict[int, float] = {}
        """Local monotonic send time of each RAW_IMU, by its ``time_usec``."""
        self.inject: list[bytes] = []
        """Raw bytes to send before the next tick (garbage, foreign frames)."""

    def reboot(self) -> None:
        """Start the clock again from a fresh boot; streams stop until requested again."""
        self.time_s = 0.5
        self.streaming = False

    async def run(self, duration_fc_s: float) -> None:
        """Serve for ``duration_fc_s`` of flight-controller time once streaming started.

        A receive task answers and time-stamps what the companion sends the moment it arrives.
        """
        receiver = asyncio.create_task(self._receive(), name="fake-fc-rx")
        try:
            await self._stream(duration_fc_s)
        finally:
            receiver.cancel()
            with contextlib.suppress(asyncio.CancelledError, LinkClosed):
                await receiver

    async def _stream(self, duration_fc_s: float) -> None:
        d = dialect
        next_heartbeat = 0.0
        streamed = 0.0
        ticks_per_wakeup = max(1, round(self.speed))
        start = time.monotonic()
        wakeups = 0
        while streamed < duration_fc_s:
            now = time.monotonic()
            if now >= next_heartbeat:
                next_heartbeat = now + 1.0
                self.link.send(
                    d.MAVLink_heartbeat_message(
                        d.MAV_TYPE_QUADROTOR,
                        d.MAV_AUTOPILOT_ARDUPILOTMEGA,
                        0,
                        0,
                        d.MAV_STATE_STANDBY,
                        3,
                    )
                )
            for frame in self.inject:
                self.link.send_bytes(frame)
            self.inject.clear()
            for _ in range(ticks_per_wakeup):
                self.time_s += self.tick_s
                if self.streaming:
                    if self.tick % self._system_time_ticks == 0:
                        boot_ms = round(self.time_s * 1e3)
                        self.link.send(d.MAVLink_system_time_message(0, boot_ms))
                    for msg in self.streams.messages(self.time_s, self.tick):
                        if msg.get_type() == "RAW_IMU":
                            self.imu_sent_s[msg.time_usec] = time.monotonic()
                        self.link.send(msg)
                    streamed += self.tick_s
                self.tick += 1
            wakeups += 1
            delay = start + wakeups * self.tick_s * ticks_per_wakeup / self.speed - time.monotonic()
            await asyncio.sleep(max(0.0, delay))
        await asyncio.sleep(0.05)  # let the last replies arrive

    async def _receive(self) -> None:
        while True:
            msg = await self.link.recv()
            self._on_message(msg, time.monotonic())

    def _on_message(self, msg: MAVLinkMessage, arrival_s: float) -> None:
        d = dialect
        log = self.log
        kind = msg.get_type()
        if kind == "VISION_POSITION_ESTIMATE":
            log.vision.append(msg)
            log.vision_arrival_s[msg.usec] = arrival_s
        elif kind == "COMMAND_LONG":
            log.commands.append(msg)
            result = d.MAV_RESULT_ACCEPTED
            if msg.command == d.MAV_CMD_SET_MESSAGE_INTERVAL:
                if not self.message_interval_supported:
                    result = d.MAV_RESULT_UNSUPPORTED
                elif int(msg.param1) == d.MAVLINK_MSG_ID_RAW_IMU:
                    self.streaming = True
            self.link.send(d.MAVLink_command_ack_message(msg.command, result))
        elif kind == "REQUEST_DATA_STREAM":
            log.stream_requests.append(msg)
            self.streaming = True
        elif kind == "SET_GPS_GLOBAL_ORIGIN":
            log.origins.append(msg)
            self.link.send(
                d.MAVLink_gps_global_origin_message(msg.latitude, msg.longitude, msg.altitude, 0)
            )
        elif kind == "HEARTBEAT":
            log.heartbeats.append(msg)
        elif kind == "STATUSTEXT":
            log.statustexts.append(msg)
        elif kind == "NAMED_VALUE_FLOAT":
            log.named_values.append(msg)
        elif kind == "TIMESYNC":
            if msg.tc1 == 0:
                self.link.send(d.MAVLink_timesync_message(int(self.time_s * 1e9), msg.ts1))
            else:
                log.timesync_replies.append(msg)
