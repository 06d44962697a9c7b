"""Fuzz: >= 100,000 random and mutated frames into the flight controller's input path.

The frames go through the real parser and message handlers (lock-step, in process, for
speed); the over-the-socket portion is in test_emulator_wire.py. The vehicle flies the paper
circle in AUTO throughout; afterwards it must still be flying the circle, still streaming,
still answering commands, and no handler may have failed.
"""

from __future__ import annotations

import math

import numpy as np

from tether_companion.emulator.lockstep import LockstepPeer, build_controller
from tether_companion.emulator.modes import CopterMode
from tether_companion.mavlink.framing import FrameEncoder, dialect

N_FRAMES = 100_000
ODD_FLOATS = (math.nan, math.inf, -math.inf, 0.0, -0.0, 1e38, -1e38, 1e-45, 21196.0, 1.0, -1.0)
SAFE_COMMANDS = (
    dialect.MAV_CMD_COMPONENT_ARM_DISARM,
    dialect.MAV_CMD_NAV_TAKEOFF,
    dialect.MAV_CMD_SET_MESSAGE_INTERVAL,
    dialect.MAV_CMD_GET_MESSAGE_INTERVAL,
    dialect.MAV_CMD_REQUEST_MESSAGE,
    dialect.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    dialect.MAV_CMD_USER_1,
    dialect.MAV_CMD_USER_3,
    dialect.MAV_CMD_DO_WINCH,
    dialect.MAV_CMD_DO_REPOSITION,
)
"""Implemented commands whose random parameters cannot legitimately end the flight."""
FLIGHT_ENDING = frozenset(
    {
        dialect.MAV_CMD_NAV_LAND,
        dialect.MAV_CMD_NAV_RETURN_TO_LAUNCH,
        dialect.MAV_CMD_DO_SET_MODE,
        dialect.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN,
        dialect.MAV_CMD_USER_2,
    }
)
"""Commands that, when valid, rightly end the flight: never drawn at random."""
DEFANG = {
    dialect.MAV_CMD_USER_1: (0,),  # a valid tug may push the drone anywhere
    dialect.MAV_CMD_USER_3: (0,),  # a valid tension (0 N) changes the flight
    dialect.MAV_CMD_DO_WINCH: (2, 3),
    dialect.MAV_CMD_DO_REPOSITION: (1,),  # the change-mode flag would switch to GUIDED
}
"""Parameters forced to NaN for commands whose valid forms rightly change the flight."""


class FrameFactory:
    """Random messages of the types the emulator handles, with hostile field values."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.encoder = FrameEncoder(255, 190)
        self.param_names = None

    def floats(self, n: int) -> list[float]:
        """``n`` floats: odd values (NaN, inf, huge, tiny, magic), small integers or normals."""
        rng = self.rng
        kind = rng.random(n)
        odd = np.array(ODD_FLOATS)[rng.integers(len(ODD_FLOATS), size=n)]
        small = rng.integers(-3, 300, size=n).astype(float)
        wide = rng.normal(0.0, 1.0, size=n) * 10.0 ** rng.integers(-3, 8, size=n)
        return np.where(kind < 0.3, odd, np.where(kind < 0.6, small, wide)).tolist()

    def command(self) -> int:
        rng = self.rng
        if rng.random() < 0.7:
            return int(SAFE_COMMANDS[rng.integers(len(SAFE_COMMANDS))])
        command = int(rng.integers(0, 65536))
        while command in FLIGHT_ENDING:
            command = int(rng.integers(0, 65536))
        return command

    def command_params(self, command: int, n: int) -> list[float]:
        """Random parameters, made invalid where valid ones would rightly change the flight."""
        p = self.floats(n)
        if command == dialect.MAV_CMD_COMPONENT_ARM_DISARM and p[0] == 0.0 and p[1] == 21196.0:
            p[1] = 0.0  # a forced in-flight disarm is a legitimate order to fall
        for index in DEFANG.get(command, ()):
            p[index] = math.nan
        return p

    def target(self) -> tuple[int, int]:
        r = self.rng.random()
        return (
            (1, 1) if r < 0.8 else (int(self.rng.integers(0, 256)), int(self.rng.integers(0, 256)))
        )

    def message(self, names: list[str]) -> dialect.MAVLink_message:
        rng = self.rng
        kind = int(rng.integers(10))
        ts, tc = self.target()
        if kind == 0:
            command = self.command()
            p = self.command_params(command, 7)
            return dialect.MAVLink_command_long_message(ts, tc, command, int(rng.integers(256)), *p)
        if kind == 1:
            command = self.command()
            p = self.command_params(command, 4)
            xy = [int(v) for v in rng.integers(-(2**31), 2**31, 2)]
            return dialect.MAVLink_command_int_message(
                ts, tc, int(rng.integers(256)), command, 0, 0, *p, *xy, self.floats(1)[0]
            )
        if kind == 2:
            name = (
                names[rng.integers(len(names))]
                if rng.random() < 0.5
                else "".join(chr(int(c)) for c in rng.integers(33, 127, int(rng.integers(0, 17))))
            )
            value = self.floats(1)[0]
            if name in names and math.isfinite(value) and abs(value) < 1e30:
                value = math.nan  # valid changes (e.g. 30 m/s wind) could fairly end the flight
            return dialect.MAVLink_param_set_message(
                ts, tc, name.encode(), value, int(rng.integers(256))
            )
        if kind == 3:
            return dialect.MAVLink_set_position_target_local_ned_message(
                0, ts, tc, int(rng.integers(256)), int(rng.integers(65536)), *self.floats(11)
            )
        if kind == 4:
            return dialect.MAVLink_set_mode_message(
                ts, int(rng.integers(256)), int(rng.integers(20, 2**32))
            )
        if kind == 5:
            est = self.floats(6)
            return dialect.MAVLink_vision_position_estimate_message(
                int(rng.integers(0, 2**63)), *est, self.floats(21), int(rng.integers(256))
            )
        if kind == 6:
            return dialect.MAVLink_request_data_stream_message(
                ts, tc, int(rng.integers(256)), int(rng.integers(65536)), int(rng.integers(256))
            )
        if kind == 7:
            return dialect.MAVLink_param_request_read_message(
                ts,
                tc,
                b"SIM_WIND_N" if rng.random() < 0.5 else b"?",
                int(rng.integers(-32768, 32768)),
            )
        if kind == 8:
            return dialect.MAVLink_odometry_message(
                int(rng.integers(0, 2**63)),
                int(rng.integers(256)),
                int(rng.integers(256)),
                *self.floats(3),
                self.floats(4),
                *self.floats(6),
                self.floats(21),
                self.floats(21),
                int(rng.integers(256)),
                int(rng.integers(256)),
                int(rng.integers(-128, 128)),
            )
        return dialect.MAVLink_set_position_target_global_int_message(
            0,
            ts,
            tc,
            int(rng.integers(256)),
            int(rng.integers(65536)),
            int(rng.integers(-(2**31), 2**31)),
            int(rng.integers(-(2**31), 2**31)),
            *self.floats(9),
        )

    def mutate(self, frame: bytes) -> bytes:
        rng = self.rng
        data = bytearray(frame)
        r = rng.random()
        if r < 0.25:
            for _ in range(int(rng.integers(1, 4))):
                data[int(rng.integers(len(data)))] ^= int(rng.integers(1, 256))
        elif r < 0.4:
            data = data[: int(rng.integers(1, len(data)))]
        elif r < 0.5:
            data = bytearray(
                rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes()
            )
        elif r < 0.55:
            data[1] = int(rng.integers(256))  # wrong payload length
        return bytes(data)


def test_fuzz_100k_frames_keeps_flying_and_streaming() -> None:
    fc = build_controller("paper-circle")
    fuzzer = LockstepPeer(fc)
    companion = LockstepPeer(fc, system_id=1, component_id=197)  # an untouched second link
    fuzzer.collecting = companion.collecting = False  # output checked after the fuzz
    rng = np.random.default_rng(7)
    factory = FrameFactory(rng)
    names = fc.params.names
    sent = 0
    chunk: list[bytes] = []
    while sent < N_FRAMES:
        frame = factory.encoder.encode(factory.message(names))
        chunk.append(factory.mutate(frame) if rng.random() < 0.5 else frame)
        sent += 1
        if len(chunk) == 50:  # a burst of 50 frames, then 20 ms of flight
            fuzzer.send_bytes(b"".join(chunk))
            chunk.clear()
            fuzzer.advance(0.02)
    assert fc.counters.handler_errors == 0
    parser = fuzzer._to_controller.counters
    assert parser.frames_ok > 0.5 * N_FRAMES
    assert parser.bad_crc > 1000 and parser.garbage_bytes > 1000
    assert fc.counters.other_target > 1000 and fc.counters.bad_values > 1000
    # still flying the circle, armed in AUTO, and streaming
    assert fc.armed and fc.mode == CopterMode.AUTO and not fc.sim.landed
    setpoint = fc.sim.trajectory.setpoint_at(fc.time_s).position_ned_m
    assert np.linalg.norm(fc.sim.truth.position_ned_m - np.array(setpoint)) < 0.5
    companion.collecting = True
    companion.advance(1.0)
    assert companion.counts()["RAW_IMU"] in (200, 201) and companion.counts()["HEARTBEAT"] >= 1
    ok = dialect.MAV_RESULT_ACCEPTED
    assert (
        companion.command(dialect.MAV_CMD_REQUEST_MESSAGE, dialect.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        == ok
    )
