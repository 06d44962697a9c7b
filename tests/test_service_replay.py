"""Replay: .tlog and ArduPilot dataflash .bin through the service pipeline; clear errors for
missing, truncated and incomplete logs (exit code 2 from the command line)."""

from __future__ import annotations

import io
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from paper_filter import with_paper_filter

from tether_companion.cli import main
from tether_companion.errors import InputError
from tether_companion.mavlink.framing import FrameEncoder, FrameParser
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.recording import RecordingLimits, TlogWriter, read_tlog
from tether_companion.service.replay import ReplaySummary, replay_log
from tether_companion.service.synthetic import HoverStreams, hover_state

POSITION = np.array([2.0, 1.0, -3.0])
LIMITS = RecordingLimits(
    max_file_bytes=50_000_000, max_total_bytes=100_000_000, flush_interval_s=1.0
)


@pytest.fixture(scope="module")
def config():
    return load_service_config(None, with_paper_filter({"recording": {"enabled": False}}))


def _write_tlog(directory: Path, config, seconds: float, skip: tuple[str, ...] = ()) -> Path:
    vehicle = load_vehicle_for(config)
    streams = HoverStreams(vehicle, POSITION, 4.0, rng=np.random.default_rng(11))
    fc = FrameEncoder(1, 1)
    writer = TlogWriter(directory, LIMITS)
    for k in range(int(seconds * 200)):
        for msg in streams.messages(20.0 + k * 0.005, k):
            if msg.get_type() not in skip:
                writer.write(fc.encode(msg))
    writer.close()
    assert writer.current_path is not None
    return writer.current_path


def _rows(text: str) -> list[list[str]]:
    return [line.split(",") for line in text.strip().splitlines()[1:]]


def test_tlog_replay_converges_and_is_deterministic(tmp_path: Path, config) -> None:
    path = _write_tlog(tmp_path, config, 15.0)
    first, second = io.StringIO(), io.StringIO()
    summary = replay_log(path, config, load_vehicle_for(config), first)
    replay_log(path, config, load_vehicle_for(config), second)
    assert first.getvalue() == second.getvalue()
    rows = _rows(first.getvalue())
    # 30 Hz over 15 s, less the settling time before the first position (publish.settle_s)
    assert summary.published == len(rows) and 400 <= len(rows) <= 451
    north, east, down, tension = (float(x) for x in rows[-1][1:5])
    assert np.linalg.norm(np.array([north, east, down]) - POSITION) < 0.3
    assert abs(tension - 4.0) < 0.5
    assert all(math.isfinite(float(x)) for row in rows for x in row[:9])


def test_cli_replay_writes_csv(tmp_path: Path, config, capsys) -> None:
    path = _write_tlog(tmp_path, config, 3.0)
    out = tmp_path / "estimates.csv"
    assert main(["replay", str(path), "--out", str(out)]) == 0
    header = out.read_text().splitlines()[0]
    assert header.startswith("time_usec,north_m,east_m,down_m,tension_n,var_north_m2")
    assert "replay:" in capsys.readouterr().err


def test_missing_truncated_and_lacking_logs(tmp_path: Path, config, capsys) -> None:
    vehicle = load_vehicle_for(config)
    with pytest.raises(InputError, match="no such log file"):
        replay_log(tmp_path / "missing.tlog", config, vehicle, io.StringIO())
    assert main(["replay", str(tmp_path / "missing.tlog"), "--out", str(tmp_path / "x.csv")]) == 2
    assert "no such log file" in capsys.readouterr().err

    good = _write_tlog(tmp_path / "a", config, 2.0)
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(good.read_bytes()[:-7])
    with pytest.raises(InputError, match="truncated"):
        replay_log(cut, config, vehicle, io.StringIO())
    assert replay_log(cut, config, vehicle, io.StringIO(), allow_truncated=True).published > 0

    no_attitude = _write_tlog(tmp_path / "b", config, 2.0, skip=("ATTITUDE",))
    # 400 IMU samples, all processed (the log is in order: the reorder buffer holds nothing)
    with pytest.raises(
        InputError, match=r"lacks ATTITUDE messages from system 1 component 1.*RAW_IMU x400"
    ):
        replay_log(no_attitude, config, vehicle, io.StringIO())

    other_id = load_service_config(
        None, {"recording": {"enabled": False}, "link": {"fc_system_id": 7}}
    )
    with pytest.raises(
        InputError, match="lacks RAW_IMU, ATTITUDE, SERVO_OUTPUT_RAW messages from system 7"
    ):
        replay_log(good, other_id, vehicle, io.StringIO())

    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(InputError, match="unknown log kind"):
        replay_log(text, config, vehicle, io.StringIO())


# --- ArduPilot dataflash ------------------------------------------------------------------------

_FMT = struct.Struct("<BBB4s16s64s")  # header (3) is written separately


def _dataflash_fmt(msg_type: int, name: str, fmt: str, columns: str) -> bytes:
    length = 3 + struct.calcsize("<" + fmt.replace("n", "4s"))
    body = struct.pack(
        "<BB4s16s64s", msg_type, length, name.encode(), fmt.encode(), columns.encode()
    )
    return bytes((0xA3, 0x95, 0x80)) + body


def _dataflash_msg(msg_type: int, fmt: str, *values) -> bytes:
    return bytes((0xA3, 0x95, msg_type)) + struct.pack("<" + fmt, *values)


def _write_bin(path: Path, config, seconds: float, with_rcou: bool = True) -> Path:
    vehicle = load_vehicle_for(config)
    state = hover_state(vehicle, POSITION, 4.0)
    rng = np.random.default_rng(5)
    parts = [
        _dataflash_fmt(200, "IMU", "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
        _dataflash_fmt(201, "ATT", "Qfff", "TimeUS,Roll,Pitch,Yaw"),
        _dataflash_fmt(202, "RCOU", "QHHHH", "TimeUS,C1,C2,C3,C4"),
        _dataflash_fmt(203, "RFND", "QBfB", "TimeUS,Instance,Dist,Orient"),
    ]
    tilt = math.cos(state.roll_rad) * math.cos(state.pitch_rad)
    for k in range(int(seconds * 200)):
        t_us = 30_000_000 + k * 5000
        parts.append(
            _dataflash_msg(
                201,
                "Qfff",
                t_us,
                math.degrees(state.roll_rad),
                math.degrees(state.pitch_rad),
                359.0,
            )
        )
        if with_rcou:
            parts.append(_dataflash_msg(202, "QHHHH", t_us, *(int(round(p)) for p in state.pwm_us)))
        if k % 10 == 0:
            parts.append(_dataflash_msg(203, "QBfB", t_us, 0, float(-POSITION[2] / tilt), 25))
        accel = state.specific_force_body_mps2 + rng.normal(0.0, 0.1, 3)
        parts.append(_dataflash_msg(200, "QBffffff", t_us, 0, 0.0, 0.0, 0.0, *accel))
        parts.append(
            _dataflash_msg(200, "QBffffff", t_us, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        )  # IMU 2: ignored
    path.write_bytes(b"".join(parts))
    return path


def test_dataflash_bin_replays_through_the_same_pipeline(tmp_path: Path, config) -> None:
    path = _write_bin(tmp_path / "flight.bin", config, 15.0)
    out = io.StringIO()
    summary = replay_log(path, config, load_vehicle_for(config), out)
    assert summary.inputs == {"imu": 3000, "attitude": 3000, "pwm": 3000}
    north, east, down, tension = (float(x) for x in _rows(out.getvalue())[-1][1:5])
    assert np.linalg.norm(np.array([north, east, down]) - POSITION) < 0.3
    assert abs(tension - 4.0) < 0.5


def test_dataflash_errors(tmp_path: Path, config) -> None:
    vehicle = load_vehicle_for(config)
    no_rcou = _write_bin(tmp_path / "no_rcou.bin", config, 1.0, with_rcou=False)
    with pytest.raises(InputError, match=r"lacks RCOU messages \(found: IMU x200, ATT x200\)"):
        replay_log(no_rcou, config, vehicle, io.StringIO())
    good = _write_bin(tmp_path / "good.bin", config, 1.0)
    cut = tmp_path / "cut.bin"
    cut.write_bytes(good.read_bytes()[:-5])
    with pytest.raises(InputError, match="truncated"):
        replay_log(cut, config, vehicle, io.StringIO())
    junk = tmp_path / "junk.bin"
    junk.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match="not an ArduPilot dataflash log"):
        replay_log(junk, config, vehicle, io.StringIO())


def test_replay_says_why_nothing_was_published(tmp_path: Path, config, capsys) -> None:
    """A hover log without DISTANCE_SENSOR: the height along the cable is never measured, the
    covariance there grows until the position cannot be published, and the summary says so
    instead of a bare "0 estimates"."""
    path = _write_tlog(tmp_path, config, 4.0, skip=("DISTANCE_SENSOR",))
    summary = replay_log(path, config, load_vehicle_for(config), io.StringIO())
    # 800 IMU ticks, all processed (in order: the reorder buffer holds nothing)
    assert summary.estimates == 800 and summary.not_ok.get("no_range", 0) > 0
    out = tmp_path / "estimates.csv"
    paper = tmp_path / "paper.yaml"
    paper.write_text("estimator: {kind: four_state}\n", encoding="utf-8")
    assert main(["replay", str(path), "--out", str(out), "--config", str(paper)]) == 0
    err = capsys.readouterr().err
    assert "no_range" in err and "no rangefinder height" in err, err


def test_summary_without_any_imu_tick_says_so() -> None:
    summary = ReplaySummary("x.tlog", {"imu": 0, "attitude": 10}, 0, 0.0, 3)
    assert "no IMU sample reached the estimator" in summary.reasons_text()
    assert ReplaySummary("x.tlog", {"imu": 5}, 5, 1.0, 0, 5, {}).reasons_text() == ""


@pytest.mark.parametrize(
    "overrides",
    [
        {"estimator": {"kind": "four_state"}},
        {
            "estimator": {"kind": "four_state"},
            "publish": {"on_unhealthy": "inflate", "odometry": True},
            "tension_mode": {},
        },
        {"estimator": {"kind": "three_state"}, "tension": {"source": "config"}},
        {
            "position": {"source": "catenary"},
            "catenary": {
                "case": "known_length",
                "weight_per_length_n_per_m": 0.05,
                "default_length_m": 4.0,
            },
        },
    ],
    ids=["four-state", "inflate-odometry", "three-state", "catenary"],
)
def test_a_session_without_messages_publishes_the_same(tmp_path: Path, overrides) -> None:
    """Replay's session builds no messages (nobody reads them) and skips the tension modes;
    its publication records, counters and reset counter equal the live session's, message for
    message, on a flight with a 1 s attitude outage (unhealthy, then a resumed publication)."""
    from tether_companion.service.session import EstimationSession

    config = load_service_config(None, {"recording": {"enabled": False}, **overrides})
    vehicle = load_vehicle_for(config)
    streams = HoverStreams(vehicle, POSITION, 4.0, rng=np.random.default_rng(12))
    fc = FrameEncoder(1, 1)
    writer = TlogWriter(tmp_path, LIMITS)
    for k in range(8 * 200):
        for msg in streams.messages(20.0 + k * 0.005, k):
            if not (4.0 <= k * 0.005 < 5.0 and msg.get_type() == "ATTITUDE"):
                writer.write(fc.encode(msg))
    writer.close()
    assert writer.current_path is not None
    live = EstimationSession(config, vehicle)
    quiet = EstimationSession(config, vehicle, messages=False)
    sent = 0
    parser = FrameParser()
    received = (
        (msg, stamp_us * 1e-6)
        for stamp_us, frame in read_tlog(writer.current_path)
        for msg in parser.feed(frame)
    )
    for msg, received_s in received:
        a, b = live.on_message(msg, received_s), quiet.on_message(msg, received_s)
        assert a.publication == b.publication
        assert b.messages == []
        sent += len(a.messages)
    assert sent > 0 and live.publisher.counters.published > 100
    assert live.publisher.counters == quiet.publisher.counters
    assert live.publisher.reset_counter == quiet.publisher.reset_counter
    counters = live.publisher.counters
    assert counters.resets + counters.inflated > 0  # the outage: a pause and reset, or inflated
