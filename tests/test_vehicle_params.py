"""The vehicle profile from autopilot parameters: ArduPilot's and PX4's thrust linearisation
re-done forward from their source (demand -> actuator -> pulse) must give back the demanded
thrust through our curve; frames, bad parameter sets, parameter sets in logs."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from tether_companion.cli import main
from tether_companion.config import ConfigError
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.frames import ARDUPILOT_FRAMES, FRAMES
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sysid.logs.dataflash_writer import DataflashWriter
from tether_companion.vehicle_params.profile import profile_from_parameters
from tether_companion.vehicle_params.sources import param_value, read_parameters

ARDUPILOT_PLUS = {
    "FRAME_CLASS": 1,
    "FRAME_TYPE": 0,
    "MOT_PWM_MIN": 1000,
    "MOT_PWM_MAX": 2000,
    "MOT_SPIN_MIN": 0.15,
    "MOT_SPIN_MAX": 0.95,
    "MOT_THST_EXPO": 0.65,
    "MOT_THST_HOVER": 0.39,
    "MOT_BAT_VOLT_MAX": 12.8,
    "MOT_BAT_VOLT_MIN": 9.6,
}

PX4_QUAD_X = {
    "CA_AIRFRAME": 0,
    "CA_ROTOR_COUNT": 4,
    "CA_ROTOR0_PX": 0.15,
    "CA_ROTOR0_PY": 0.25,
    "CA_ROTOR0_KM": 0.05,
    "CA_ROTOR1_PX": -0.15,
    "CA_ROTOR1_PY": -0.25,
    "CA_ROTOR1_KM": 0.05,
    "CA_ROTOR2_PX": 0.15,
    "CA_ROTOR2_PY": -0.25,
    "CA_ROTOR2_KM": -0.05,
    "CA_ROTOR3_PX": -0.15,
    "CA_ROTOR3_PY": 0.25,
    "CA_ROTOR3_KM": -0.05,
    "THR_MDL_FAC": 0.3,
    "MPC_THR_HOVER": 0.42,
    **{f"PWM_MAIN_MIN{i}": 1100 for i in range(1, 5)},
    **{f"PWM_MAIN_MAX{i}": 1900 for i in range(1, 5)},
}


def ardupilot_pulse_us(thrust: float, p: dict) -> float:
    """ArduPilot's forward chain at full voltage, written from the source's description:
    thrust_to_actuator -> apply_thrust_curve_and_volt_scaling -> output_to_pwm."""
    e = p["MOT_THST_EXPO"]
    if e == 0.0:
        ratio = thrust
    else:
        ratio = ((e - 1.0) + math.sqrt((1.0 - e) ** 2 + 4.0 * e * thrust)) / (2.0 * e)
    actuator = p["MOT_SPIN_MIN"] + (p["MOT_SPIN_MAX"] - p["MOT_SPIN_MIN"]) * ratio
    return p["MOT_PWM_MIN"] + (p["MOT_PWM_MAX"] - p["MOT_PWM_MIN"]) * actuator


@pytest.mark.parametrize("expo", [-0.4, 0.0, 0.65, 1.0])
def test_ardupilot_curve_gives_back_the_demanded_thrust(expo: float) -> None:
    params = {**ARDUPILOT_PLUS, "MOT_THST_EXPO": expo}
    mass = 3.0
    profile = profile_from_parameters(params, mass)
    full = mass * GRAVITY_MPS2 / (4 * params["MOT_THST_HOVER"])
    for demand in np.linspace(0.0, 1.0, 11):
        pulse = ardupilot_pulse_us(demand, params)
        assert profile.thrust_curve.thrust_n(pulse) == pytest.approx(full * demand, abs=1e-9)
    # the learned hover throttle holds the weight
    hover = ardupilot_pulse_us(params["MOT_THST_HOVER"], params)
    assert 4 * profile.thrust_curve.thrust_n(hover) == pytest.approx(mass * GRAVITY_MPS2)


def test_px4_curve_gives_back_the_demanded_thrust() -> None:
    mass = 1.2
    profile = profile_from_parameters(PX4_QUAD_X, mass)
    f = PX4_QUAD_X["THR_MDL_FAC"]
    full = mass * GRAVITY_MPS2 / (4 * PX4_QUAD_X["MPC_THR_HOVER"])
    for demand in np.linspace(0.01, 1.0, 9):
        # FunctionMotors::updateValues: x solves f x^2 + (1 - f) x = demand, then [0,1] -> pulse
        x = -(1 - f) / (2 * f) + math.sqrt((1 - f) ** 2 / (4 * f * f) + demand / f)
        pulse = 1100 + 800 * x
        assert profile.thrust_curve.thrust_n(pulse) == pytest.approx(full * demand, abs=1e-9)
    assert [m.spin for m in profile.motors] == [m.spin for m in FRAMES["quad-x"]]
    assert [round(m.angle_deg, 3) for m in profile.motors] == pytest.approx(
        [59.036, -120.964, -59.036, 120.964]
    )
    assert profile.arm_length_m == pytest.approx(math.hypot(0.15, 0.25))


@pytest.mark.parametrize(("ids", "frame"), sorted(ARDUPILOT_FRAMES.items()) + [((5, 0), "y6")])
def test_every_ardupilot_frame_gives_its_layout(ids: tuple[int, int], frame: str) -> None:
    params = {**ARDUPILOT_PLUS, "FRAME_CLASS": ids[0], "FRAME_TYPE": ids[1]}
    profile = profile_from_parameters(params, 2.0)
    assert profile.frame == frame and profile.motors == FRAMES[frame]
    wrench = profile.allocation_matrix() @ np.ones(profile.n_motors)
    assert wrench[0] == profile.n_motors  # equal thrusts: no roll/yaw, pitch only on Y6's arms
    assert abs(wrench[1]) < 1e-9 and abs(wrench[3]) < 1e-9 and abs(wrench[2]) < 1e-3


def test_ardupilot_motor_order_of_quad_plus_and_hexa_x() -> None:
    """AP_MotorsMatrix: '+' motor 1 right, 2 left, 3 front, 4 back; hexa X motor 1 right CW."""
    plus = [(m.angle_deg, m.spin) for m in FRAMES["quad-plus"]]
    assert plus == [(90, "ccw"), (-90, "ccw"), (0, "cw"), (180, "cw")]
    assert (FRAMES["hexa-x"][0].angle_deg, FRAMES["hexa-x"][0].spin) == (90, "cw")


BAD_SETS = [
    (
        {"MOT_SPIN_MIN": 0.25, "MOT_SPIN_MAX": 0.9, "MOT_PWM_MIN": 1500, "MOT_PWM_MAX": 1400},
        "MOT_PWM_MIN",
        "must be < MOT_PWM_MAX",
    ),
    ({"MOT_SPIN_MIN": 0.3, "MOT_SPIN_MAX": 0.9}, None, None),  # valid edge: accepted
    ({"MOT_THST_HOVER": 0.9}, "MOT_THST_HOVER", "outside its documented range"),
    ({"MOT_SPIN_MIN": 0.5}, "MOT_SPIN_MIN", r"outside its documented range \[0, 0.3\]"),
    ({"MOT_THST_EXPO": float("nan")}, "MOT_THST_EXPO", "documented range"),
    ({"FRAME_CLASS": 7}, "FRAME_CLASS", "not a supported multicopter frame"),
    ({"FRAME_TYPE": 10, "FRAME_CLASS": 5}, "FRAME_CLASS", "not a supported"),
    ({"FRAME_CLASS": None}, "FRAME_CLASS", "is required"),
    ({"MOT_THST_HOVER": None}, "MOT_THST_HOVER", "is required"),
    ({"MOT_PWM_MIN": 0, "MOT_PWM_MAX": 0}, None, None),  # RC3_MIN/MAX defaults
]


@pytest.mark.parametrize(("change", "key", "words"), BAD_SETS)
def test_bad_ardupilot_parameters_are_named(change: dict, key: str | None, words: str) -> None:
    params = {k: v for k, v in {**ARDUPILOT_PLUS, **change}.items() if v is not None}
    if key is None:
        profile_from_parameters(params, 1.5)
        return
    with pytest.raises(ConfigError, match=words) as info:
        profile_from_parameters(params, 1.5, source="fc")
    assert info.value.key == key
    assert str(info.value).startswith(f"fc: {key} = ")


def test_spin_min_not_below_spin_max_is_refused() -> None:
    # SPIN_MIN's range ends at 0.3 and SPIN_MAX's starts at 0.9, so the contradiction needs
    # both out of range: the first one out of range is named
    with pytest.raises(ConfigError, match="MOT_SPIN_MIN"):
        profile_from_parameters({**ARDUPILOT_PLUS, "MOT_SPIN_MIN": 0.95}, 1.5)


@pytest.mark.parametrize(
    ("change", "key", "words"),
    [
        ({"CA_AIRFRAME": 2}, "CA_AIRFRAME", "must be 0"),
        ({"CA_ROTOR_COUNT": 3}, "CA_ROTOR_COUNT", "4 to 12"),
        ({"CA_ROTOR2_KM": 0.0}, "CA_ROTOR2_KM", "ccw"),
        ({"PWM_MAIN_MIN3": 1000}, "PWM_MAIN_MIN3", "one range for all motors"),
        ({"MPC_THR_HOVER": 0.95}, "MPC_THR_HOVER", "documented range"),
        ({"PWM_MAIN_FUNC1": 102}, "PWM_MAIN_FUNC1", "Motor 1"),
        ({"CA_ROTOR3_PY": None}, "CA_ROTOR3_PY", "is required"),
    ],
)
def test_bad_px4_parameters_are_named(change: dict, key: str, words: str) -> None:
    params = {k: v for k, v in {**PX4_QUAD_X, **change}.items() if v is not None}
    with pytest.raises(ConfigError, match=words) as info:
        profile_from_parameters(params, 1.5)
    assert info.value.key == key


def test_neither_autopilot_and_bad_mass() -> None:
    with pytest.raises(ConfigError, match="neither ArduPilot"):
        profile_from_parameters({"SYSID_THISMAV": 1}, 1.5)
    with pytest.raises(ConfigError, match="mass_kg"):
        profile_from_parameters(ARDUPILOT_PLUS, 0.0)


def test_px4_bytewise_integer_parameters() -> None:
    as_float = struct.unpack("<f", struct.pack("<i", 4))[0]  # what PX4 puts on the wire
    assert param_value(as_float, 6, bytewise=True) == 4.0
    assert param_value(4.0, 6, bytewise=False) == 4.0
    assert param_value(0.42, 9, bytewise=True) == pytest.approx(0.42)


def test_dataflash_parm_set(tmp_path: Path) -> None:
    path = tmp_path / "flight.bin"
    with path.open("wb") as stream:
        writer = DataflashWriter(stream)
        writer.declare("PARM", "QNff", ("TimeUS", "Name", "Value", "Default"))
        for i, (name, value) in enumerate(ARDUPILOT_PLUS.items()):
            writer.write("PARM", i, name.encode(), float(value), 0.0)
        writer.write("PARM", 99, b"MOT_THST_HOVER", 0.41, 0.35)  # learned later: last one wins
    params = read_parameters(path)
    assert params["FRAME_CLASS"] == 1 and params["MOT_THST_HOVER"] == pytest.approx(0.41)
    profile = profile_from_parameters(params, 3.0)
    assert profile.frame == "quad-plus"


def write_ulog_parameters(path: Path, params: dict[str, float], integers: set[str]) -> None:
    """A ULog holding only its header, flag bits and parameter ('P') messages."""

    def message(kind: str, payload: bytes) -> bytes:
        return struct.pack("<HB", len(payload), ord(kind)) + payload

    out = bytearray(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0))
    out += message("B", bytes(40))
    for name, value in params.items():
        key = f"{'int32_t' if name in integers else 'float'} {name}".encode()
        raw = struct.pack("<i", int(value)) if name in integers else struct.pack("<f", value)
        out += message("P", bytes([len(key)]) + key + raw)
    path.write_bytes(bytes(out))


def test_ulog_parameter_set(tmp_path: Path) -> None:
    path = tmp_path / "flight.ulg"
    integers = {"CA_AIRFRAME", "CA_ROTOR_COUNT", *(k for k in PX4_QUAD_X if k.startswith("PWM"))}
    write_ulog_parameters(path, PX4_QUAD_X, integers)
    params = read_parameters(path)
    assert params["CA_ROTOR_COUNT"] == 4 and params["PWM_MAIN_MAX2"] == 1900
    profile = profile_from_parameters(params, 1.2)
    assert profile.n_motors == 4 and profile.thrust_curve.pwm_min_us == 1100


def test_cli_from_params_writes_a_profile_that_loads(tmp_path: Path) -> None:
    """Two parameter files merged, as ArduPilot SITL's --defaults copter.parm,tether.parm."""
    first, second = tmp_path / "copter.parm", tmp_path / "extra.parm"
    first.write_text("".join(f"{k}\t{v}\n" for k, v in ARDUPILOT_PLUS.items()) + "# end\n")
    second.write_text("MOT_THST_HOVER,0.4\n")
    out = tmp_path / "plus.yaml"
    args = ["sysid", "--from-params", str(first), "--from-params", str(second)]
    assert main([*args, "--mass-kg", "3", "--out", str(out)]) == 0
    profile = load_vehicle(out)
    assert profile.frame == "quad-plus" and profile.battery.voltage_max_v == 12.8
    hover_pwm = profile.thrust_curve.pwm_for_thrust(3.0 * GRAVITY_MPS2 / 4)
    assert 4 * profile.thrust_curve.thrust_n(hover_pwm) == pytest.approx(3.0 * GRAVITY_MPS2)
    full = profile.thrust_curve.max_thrust_n
    assert full == pytest.approx(3.0 * GRAVITY_MPS2 / (4 * 0.4))  # the second file's hover


def test_cli_from_params_errors_exit_2(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.parm"
    bad.write_text("FRAME_CLASS 1\nFRAME_TYPE 0\nMOT_THST_HOVER 0.39\nMOT_SPIN_MAX 1.5\n")
    out = str(tmp_path / "p.yaml")
    assert main(["sysid", "--from-params", str(bad), "--mass-kg", "2", "--out", out]) == 2
    err = capsys.readouterr().err
    assert "MOT_SPIN_MAX = 1.5" in err and err.count("\n") == 1
    assert main(["sysid", "--from-params", str(bad), "--out", out]) == 2
    assert "--mass-kg" in capsys.readouterr().err
    garbage = tmp_path / "g.parm"
    garbage.write_text("FRAME_CLASS one\n")
    assert main(["sysid", "--from-params", str(garbage), "--mass-kg", "2", "--out", out]) == 2
    assert "g.parm:1: FRAME_CLASS" in capsys.readouterr().err


def test_docs_vehicle_reference_is_generated_from_the_code() -> None:
    from tether_companion.physics.vehicle_reference import vehicle_reference

    doc = (Path(__file__).resolve().parents[1] / "docs" / "vehicle-reference.md").read_text()
    missing = [row for row in vehicle_reference().splitlines() if row not in doc]
    assert not missing, "regenerate: python -m tether_companion.physics.vehicle_reference\n" + (
        "\n".join(missing)
    )


def test_relative_vehicle_path_is_taken_from_the_config_folder(tmp_path: Path, monkeypatch) -> None:
    from tether_companion.service.config import load_service_config, load_vehicle_for

    folder = tmp_path / "etc"
    (folder / "vehicles").mkdir(parents=True)
    (folder / "vehicles" / "mine.yaml").write_text("name: mine\nmass_kg: 2.0\nframe: hexa-x\n")
    (folder / "companion.yaml").write_text("vehicle: vehicles/mine.yaml\n")
    monkeypatch.chdir(tmp_path)  # not the config's folder
    config = load_service_config(folder / "companion.yaml")
    vehicle = load_vehicle_for(config)
    assert vehicle.name == "mine" and vehicle.n_motors == 6
    (folder / "companion.yaml").write_text("vehicle: crazyflie\n")  # built-in names unchanged
    assert load_vehicle_for(load_service_config(folder / "companion.yaml")).name == "crazyflie"


def test_sitl_parameters_give_the_curve_read_from_sitls_frame_model() -> None:
    """ArduPilot SITL's '+' model (configs/vehicles/ardupilot-sitl-plus.yaml, written by another
    helper from SITL's SIM_Frame/SIM_Motor source) against the profile built from the
    parameters SITL flies it with (Tools/autotest/default_params/copter.parm values)."""
    sitl = load_vehicle("ardupilot-sitl-plus")
    ours = profile_from_parameters(ARDUPILOT_PLUS, sitl.mass_kg)
    assert ours.frame == sitl.frame == "quad-plus"
    pwm = np.linspace(1100.0, 2000.0, 46)
    assert ours.thrust_curve.thrust_n(pwm) == pytest.approx(
        sitl.thrust_curve.thrust_n(pwm), rel=2e-4, abs=1e-3
    )
