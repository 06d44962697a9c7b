"""Flight-log loaders on logs written with pymavlink (.tlog), hand-built dataflash records
(.bin) and hand-made CSV, plus every kind of bad log (clear InputError, CLI exit code 2)."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from sysid_synthetic import log_signals

from tether_companion.cli import main
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.errors import InputError
from tether_companion.sysid.logs import load_flight_log
from tether_companion.sysid.logs.dataflash_writer import (
    DataflashWriter,
    declare_identification_messages,
)
from tether_companion.sysid.processing import prepare

RANGE = (1000.0, 2000.0)
MASS_KG = 1.5


def write_tlog(path, signals, skip=(), other_system=True, imu="RAW_IMU"):
    """A .tlog as a ground station records it, packed by pymavlink's MAVLink 2 encoder.

    ArduPilot units: RAW_IMU milli-g, ATTITUDE rad, SERVO_OUTPUT_RAW us, DISTANCE_SENSOR cm.
    A second system (id 2, like SITL's tether simulator) sends a few ATTITUDE messages that
    the loader must ignore.
    """
    fc = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    other = mavlink2.MAVLink(None, srcSystem=2, srcComponent=1)
    with open(path, "wb") as out:

        def put(t, link, msg):
            out.write(struct.pack(">Q", int(1.7e15 + t * 1e6)) + msg.pack(link))

        for k, t in enumerate(signals["time_s"]):
            usec, ms = int(t * 1e6), int(t * 1e3)
            acc = signals["accel_mps2"][k] / GRAVITY_MPS2 * 1000.0
            roll, pitch, yaw = signals["euler_rad"][k]
            pwm = [int(p) for p in signals["pwm_us"][k]] + [0] * 12
            if imu == "HIGHRES_IMU":  # PX4: m/s^2
                imu_msg = mavlink2.MAVLink_highres_imu_message(
                    usec, *signals["accel_mps2"][k], *([0.0] * 10), 0b111, 0
                )
            else:
                imu_msg = mavlink2.MAVLink_raw_imu_message(
                    usec, *(int(round(a)) for a in acc), 0, 0, 0, 0, 0, 0, 0, 0
                )
            messages = {
                imu: imu_msg,
                "ATTITUDE": mavlink2.MAVLink_attitude_message(ms, roll, pitch, yaw, 0.0, 0.0, 0.0),
                "SERVO_OUTPUT_RAW": mavlink2.MAVLink_servo_output_raw_message(usec, 0, *pwm),
                "DISTANCE_SENSOR": mavlink2.MAVLink_distance_sensor_message(
                    ms,
                    5,
                    2000,
                    int(round(signals["height_m"][k] * 100.0)),
                    0,
                    0,
                    mavlink2.MAV_SENSOR_ROTATION_PITCH_270,
                    255,
                ),
            }
            for name, msg in messages.items():
                if name not in skip:
                    put(t, fc, msg)
            if other_system and k % 50 == 0:
                put(t, other, mavlink2.MAVLink_attitude_message(ms, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0))


def write_bin(path, signals, truncate_bytes=0):
    """An ArduPilot dataflash log: FMT records then IMU, ATT (deg), RCOU, RFND records."""
    with open(path, "wb") as out:
        writer = DataflashWriter(out)
        declare_identification_messages(writer)
        for k, t in enumerate(signals["time_s"]):
            us = int(t * 1e6)
            writer.write("IMU", us, 0, 0.0, 0.0, 0.0, *signals["accel_mps2"][k])
            writer.write("ATT", us, *np.degrees(signals["euler_rad"][k]))
            writer.write("RCOU", us, *(int(p) for p in signals["pwm_us"][k]))
            writer.write("RFND", us, 0, float(signals["height_m"][k]))
    if truncate_bytes:
        data = path.read_bytes()
        path.write_bytes(data[: len(data) - truncate_bytes])


def write_csv(path, signals, drop_column=None, height=True):
    """A hand-made CSV with the documented columns."""
    columns = [
        "time_s",
        "pwm1_us",
        "pwm2_us",
        "pwm3_us",
        "pwm4_us",
        "acc_x_mps2",
        "acc_y_mps2",
        "acc_z_mps2",
        "roll_rad",
        "pitch_rad",
        "yaw_rad",
    ] + (["height_m"] if height else [])
    rows = [",".join(c for c in columns if c != drop_column)]
    for k, t in enumerate(signals["time_s"]):
        values = [t, *signals["pwm_us"][k], *signals["accel_mps2"][k], *signals["euler_rad"][k]]
        if height:
            values.append(signals["height_m"][k])
        rows.append(
            ",".join(f"{v:.6f}" for c, v in zip(columns, values, strict=True) if c != drop_column)
        )
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def write_ulog(path, signals, battery=None):
    """A PX4 ULog built by hand: header, FMT ('F'), add-logged ('A') and data ('D') messages
    for sensor_combined, vehicle_attitude (quaternion w-x-y-z), actuator_outputs and
    distance_sensor, as pyulog reads them; ``battery``: (time_s, voltage_v, connected) rows
    of a battery_status topic."""
    topics = [
        ("sensor_combined", "uint64_t timestamp;float[3] accelerometer_m_s2;", "<Q3f"),
        ("vehicle_attitude", "uint64_t timestamp;float[4] q;", "<Q4f"),
        ("actuator_outputs", "uint64_t timestamp;float[16] output;", "<Q16f"),
        ("distance_sensor", "uint64_t timestamp;float current_distance;", "<Qf"),
        ("battery_status", "uint64_t timestamp;float voltage_v;bool connected;", "<Qf?"),
    ]

    def message(kind, payload):
        return struct.pack("<HB", len(payload), ord(kind)) + payload

    out = bytearray(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0))
    out += message("B", bytes(40))
    for name, fields, _ in topics:
        out += message("F", f"{name}:{fields}".encode())
    for i, (name, _, _) in enumerate(topics):
        out += message("A", struct.pack("<BH", 0, i) + name.encode())
    pending = sorted(battery or [])
    for k, t in enumerate(signals["time_s"]):
        us = int(t * 1e6)
        r, p, y = signals["euler_rad"][k] / 2.0
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        q = (
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        )
        rows = [
            (us, *signals["accel_mps2"][k]),
            (us, *q),
            (us, *signals["pwm_us"][k], *([0.0] * 12)),
            (us, signals["height_m"][k]),
        ]
        for i, ((_, _, fmt), row) in enumerate(zip(topics, rows, strict=False)):
            out += message("D", struct.pack("<H", i) + struct.pack(fmt, *row))
        while pending and pending[0][0] <= t:
            bt, volts, connected = pending.pop(0)
            row = struct.pack(topics[4][2], int(bt * 1e6), volts, connected)
            out += message("D", struct.pack("<H", 4) + row)
    path.write_bytes(bytes(out))


@pytest.fixture(scope="module")
def signals():
    return log_signals()


def _check_log(log, signals, accel_tol):
    s = signals
    np.testing.assert_allclose(log.pwm_us.time_s, s["time_s"], atol=1e-6)
    np.testing.assert_allclose(log.pwm_us.values, s["pwm_us"])
    np.testing.assert_allclose(log.specific_force_body_mps2.values, s["accel_mps2"], atol=accel_tol)
    np.testing.assert_allclose(log.euler_rad.values, s["euler_rad"], atol=1e-5)
    assert log.height_m is not None


def test_px4_highres_imu_tlog(tmp_path, signals):
    path = tmp_path / "px4.tlog"
    write_tlog(path, signals, imu="HIGHRES_IMU")
    _check_log(load_flight_log(path), signals, accel_tol=1e-5)


def test_tlog_written_with_pymavlink(tmp_path, signals):
    path = tmp_path / "flight.tlog"
    write_tlog(path, signals)
    log = load_flight_log(path)
    # RAW_IMU carries whole milli-g: half a milli-g of rounding
    _check_log(log, signals, accel_tol=0.5e-3 * GRAVITY_MPS2 + 1e-9)
    # DISTANCE_SENSOR readings below min_distance (5 cm, on the ground) are dropped
    assert np.all(log.height_m.values == 1.5)
    assert log.notes == ()
    data = prepare(log, MASS_KG, RANGE)
    assert data.airborne_s[0] > signals["time_s"][0] + 3.0
    expected = np.sum(0.5 * 0.668 + 7.5 * 0.668**2) * 4
    assert np.mean(data.estimation.thrust_n) == pytest.approx(expected, rel=0.02)


def test_dataflash_written_by_hand(tmp_path, signals):
    path = tmp_path / "flight.bin"
    write_bin(path, signals)
    log = load_flight_log(path)
    _check_log(log, signals, accel_tol=1e-5)
    np.testing.assert_allclose(log.height_m.values[:, 0], signals["height_m"], atol=1e-6)
    data = prepare(log, MASS_KG, RANGE)
    assert len(data.estimation) > len(data.validation) > 0


def test_hand_made_csv(tmp_path, signals):
    path = tmp_path / "flight.csv"
    write_csv(path, signals)
    log = load_flight_log(path)
    _check_log(log, signals, accel_tol=1e-6)
    np.testing.assert_allclose(log.height_m.values[:, 0], signals["height_m"], atol=1e-6)
    without_height = tmp_path / "noheight.csv"
    write_csv(without_height, signals, height=False)
    log = load_flight_log(without_height)
    assert log.height_m is None
    # airborne from mean PWM above 1150 us instead of height
    assert prepare(log, MASS_KG, RANGE).airborne_s[0] > signals["time_s"][0] + 3.0


def test_ulog_written_by_hand(tmp_path, signals):
    path = tmp_path / "flight.ulg"
    write_ulog(path, signals)
    log = load_flight_log(path)
    _check_log(log, signals, accel_tol=1e-5)
    assert len(prepare(log, MASS_KG, RANGE).validation) > 0


@pytest.mark.parametrize("suffix", [".tlog", ".bin", ".csv", ".ulg"])
def test_missing_file(tmp_path, suffix):
    with pytest.raises(InputError, match="no such file"):
        load_flight_log(tmp_path / f"absent{suffix}")


def test_unknown_extension(tmp_path):
    path = tmp_path / "flight.txt"
    path.write_text("x")
    with pytest.raises(InputError, match="unknown log type"):
        load_flight_log(path)


@pytest.mark.parametrize("suffix", [".tlog", ".bin", ".ulg", ".csv"])
def test_garbage_file(tmp_path, suffix):
    path = tmp_path / f"garbage{suffix}"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    with pytest.raises(InputError):
        load_flight_log(path)


@pytest.mark.parametrize("suffix", [".tlog", ".bin", ".ulg", ".csv"])
def test_empty_file(tmp_path, suffix):
    path = tmp_path / f"empty{suffix}"
    path.write_bytes(b"")
    with pytest.raises(InputError):
        load_flight_log(path)


def test_tlog_lacking_servo_output(tmp_path, signals):
    path = tmp_path / "noservo.tlog"
    write_tlog(path, signals, skip=("SERVO_OUTPUT_RAW",))
    with pytest.raises(InputError, match="no SERVO_OUTPUT_RAW message"):
        load_flight_log(path)


def test_tlog_truncated_mid_record(tmp_path, signals):
    path = tmp_path / "cut.tlog"
    write_tlog(path, signals)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2 + 7])
    log = load_flight_log(path)
    assert any("truncated" in note for note in log.notes)
    # cut before the first SERVO_OUTPUT_RAW: the error names the missing message and the cut
    path.write_bytes(data[:60])
    with pytest.raises(InputError, match="truncated"):
        load_flight_log(path)


def test_dataflash_truncated(tmp_path, signals):
    path = tmp_path / "cut.bin"
    write_bin(path, signals)
    data = path.read_bytes()
    path.write_bytes(data[:300])
    with pytest.raises(InputError, match="no (IMU|ATT|RCOU) message"):
        load_flight_log(path)


def test_csv_errors(tmp_path, signals):
    path = tmp_path / "bad.csv"
    write_csv(path, signals, drop_column="acc_z_mps2")
    with pytest.raises(InputError, match="missing column.*acc_z_mps2"):
        load_flight_log(path)
    write_csv(path, signals)
    lines = path.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[2], "fast", 1)
    path.write_text("\n".join(lines))
    with pytest.raises(InputError, match="line 6.*not a number"):
        load_flight_log(path)
    lines = path.read_text().splitlines()[:5] + ["1.0,1500"]
    path.write_text("\n".join(lines))
    with pytest.raises(InputError, match="truncated"):
        load_flight_log(path)


def test_too_short(tmp_path):
    path = tmp_path / "short.csv"
    write_csv(path, log_signals(duration_s=8.0, ground_s=1.0))
    with pytest.raises(InputError, match="too short"):
        prepare(load_flight_log(path), MASS_KG, RANGE)


def test_never_airborne(tmp_path):
    s = log_signals()
    s["height_m"][:] = 0.0
    path = tmp_path / "ground.csv"
    write_csv(path, s)
    with pytest.raises(InputError, match="never airborne"):
        prepare(load_flight_log(path), MASS_KG, RANGE)


def test_constant_inputs_excite_nothing(tmp_path):
    path = tmp_path / "constant.csv"
    write_csv(path, log_signals(constant=True))
    with pytest.raises(InputError, match="constant.*nothing is excited"):
        prepare(load_flight_log(path), MASS_KG, RANGE)


def test_ulog_without_pyulog_says_how_to_install(tmp_path, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_pyulog(name, *args, **kwargs):
        if name.startswith("pyulog"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pyulog)
    path = tmp_path / "flight.ulg"
    path.write_bytes(b"ULog")
    with pytest.raises(InputError, match=r"pip install 'tether-companion\[ulog\]'"):
        load_flight_log(path)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: None, "no such file"),
        (lambda p: p.write_bytes(b"\x00" * 100), "no IMU"),
        (
            lambda p: write_csv(p.with_suffix(".csv"), log_signals(constant=True)),
            "nothing is excited",
        ),
    ],
)
def test_cli_bad_log_exits_2(tmp_path, capsys, make, message):
    path = tmp_path / "bad.tlog"
    make(path)
    target = path.with_suffix(".csv") if "excited" in message else path
    assert main(["sysid", str(target)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_cli_without_logs_exits_2(capsys):
    assert main(["sysid"]) == 2
    assert "at least one LOG" in capsys.readouterr().err


def test_euler_from_quaternion_matches_frames():
    from tether_companion.frames import euler_from_rotation_body_to_ned, rotation_body_to_ned
    from tether_companion.sysid.logs.ulog import euler_from_quaternion_rad

    roll, pitch, yaw = 0.3, -0.2, 2.5
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    q = np.array(
        [
            [
                cr * cp * cy + sr * sp * sy,
                sr * cp * cy - cr * sp * sy,
                cr * sp * cy + sr * cp * sy,
                cr * cp * sy - sr * sp * cy,
            ]
        ]
    )
    np.testing.assert_allclose(euler_from_quaternion_rad(q)[0], [roll, pitch, yaw], atol=1e-12)
    np.testing.assert_allclose(
        euler_from_rotation_body_to_ned(rotation_body_to_ned(roll, pitch, yaw)), [roll, pitch, yaw]
    )


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--cutoff-hz", "60"], "cutoff_hz"),
        (["--estimation-fraction", "1.5"], "estimation_fraction"),
        (["--vehicle", "no-such-quad"], "no-such-quad"),
        (["--k-steps", "0"], "--k-steps"),
        (["--structure", "arx", "--write", "oe"], "--write oe"),
        (["--structure", "static", "--out", "/nonexistent-dir/x.yaml"], "cannot write"),
    ],
)
def test_cli_bad_options_exit_2(tmp_path, signals, capsys, extra, message):
    path = tmp_path / "flight.csv"
    write_csv(path, signals)
    assert main(["sysid", str(path), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
