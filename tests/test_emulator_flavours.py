"""The emulator's autopilot flavours and parameter overrides, lock-step: the PX4 flavour answers
the vehicle as PX4 parameters with integers bytewise (as PX4 sends them), says PX4 in its
HEARTBEAT and streams HIGHRES_IMU; ``emulator.parameters`` / ``--param`` make it answer a
misconfigured parameter set."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from tether_companion.config import ConfigError
from tether_companion.emulator.lockstep import LockstepPeer, build_controller
from tether_companion.mavlink.framing import dialect
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.vehicle_params import px4
from tether_companion.vehicle_params.emulated import px4_parameters
from tether_companion.vehicle_params.profile import profile_from_parameters
from tether_companion.vehicle_params.sources import param_value

MASS_KG = 1.5  # the hover scenario's default-quad


def _read(gcs: LockstepPeer, name: str):
    gcs.received.clear()
    gcs.send(dialect.MAVLink_param_request_read_message(1, 1, name.encode(), -1))
    return gcs.last("PARAM_VALUE")


def _px4_names(count: int) -> list[str]:
    names = ["CA_AIRFRAME", "CA_ROTOR_COUNT", "THR_MDL_FAC", "MPC_THR_HOVER"]
    for i in range(count):
        names += [f"CA_ROTOR{i}_PX", f"CA_ROTOR{i}_PY", f"CA_ROTOR{i}_KM"]
        names += [f"PWM_MAIN_MIN{i + 1}", f"PWM_MAIN_MAX{i + 1}", f"PWM_MAIN_FUNC{i + 1}"]
    return names


def test_px4_flavour_answers_the_vehicle_bytewise_and_it_builds_the_profile() -> None:
    fc = build_controller("hover", emulator={"autopilot": "px4"})
    gcs = LockstepPeer(fc)
    gcs.advance(0.5)
    heartbeat = gcs.last("HEARTBEAT")
    assert heartbeat.autopilot == dialect.MAV_AUTOPILOT_PX4
    count_msg = _read(gcs, "CA_ROTOR_COUNT")
    assert count_msg.param_type == dialect.MAV_PARAM_TYPE_INT32
    assert count_msg.param_value < 1e-40  # 4's bytes as a float: a denormal, not 4.0
    assert struct.unpack("<i", struct.pack("<f", count_msg.param_value))[0] == 4
    params = {}
    for name in _px4_names(4):
        msg = _read(gcs, name)
        assert msg is not None, name
        params[name] = param_value(msg.param_value, msg.param_type, bytewise=True)
    assert _read(gcs, "MOT_THST_HOVER") is None  # ArduPilot's names are not PX4's
    vehicle = load_vehicle("default-quad")
    assert params == pytest.approx(px4_parameters(vehicle), rel=1e-6)  # float32 on the wire
    profile = profile_from_parameters(params, MASS_KG)
    pwm = np.linspace(1000.0, 2000.0, 21)
    assert profile.thrust_curve.thrust_n(pwm) == pytest.approx(
        vehicle.thrust_curve.thrust_n(pwm), rel=1e-5, abs=1e-6
    )
    assert [m.spin for m in profile.motors] == [m.spin for m in vehicle.motors]
    angles = [m.angle_deg for m in profile.motors]
    assert angles == pytest.approx([m.angle_deg for m in vehicle.motors], abs=1e-4)
    assert px4.rotor_count(params) == 4


def test_px4_flavour_streams_highres_imu_and_reads_param_set_bytewise() -> None:
    fc = build_controller("hover", emulator={"autopilot": "px4"})
    gcs = LockstepPeer(fc)
    gcs.advance(0.2)
    kinds = {m.get_type() for m in gcs.received}
    assert "HIGHRES_IMU" in kinds and "RAW_IMU" not in kinds
    wire = struct.unpack("<f", struct.pack("<i", 80))[0]
    gcs.received.clear()
    gcs.send(
        dialect.MAVLink_param_set_message(1, 1, b"LAND_SPEED", wire, dialect.MAV_PARAM_TYPE_INT32)
    )
    assert fc.params.value("LAND_SPEED") == 80.0  # read as 80, not as the denormal


def test_parameter_override_answers_a_bad_value_but_leaves_the_vehicle() -> None:
    fc = build_controller("hover", emulator={"parameters": {"MOT_SPIN_MIN": 0.5, "LAND_SPEED": 80}})
    gcs = LockstepPeer(fc)
    assert _read(gcs, "MOT_SPIN_MIN").param_value == 0.5
    assert fc.params.value("LAND_SPEED") == 80.0
    assert fc.sim.vehicle.thrust_curve == load_vehicle("default-quad").thrust_curve


@pytest.mark.parametrize(
    ("override", "words"),
    [
        ({"NO_SUCH_PARAM": 1.0}, "unknown parameter"),
        ({"LAND_SPEED": 5000.0}, "outside"),
    ],
)
def test_bad_overrides_are_config_errors(override: dict, words: str) -> None:
    name = next(iter(override))
    with pytest.raises(ConfigError, match=f"emulator.parameters.{name}.*{words}"):
        build_controller("hover", emulator={"parameters": override})


def test_px4_integer_override_must_be_whole() -> None:
    with pytest.raises(ConfigError, match="CA_ROTOR_COUNT.*whole number"):
        build_controller(
            "hover", emulator={"autopilot": "px4", "parameters": {"CA_ROTOR_COUNT": 4.5}}
        )
