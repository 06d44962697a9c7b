"""MAVLink 2 signing: our implementation against pymavlink's, both directions, with the
spec's timestamp rules (per-stream replay, one-minute window for a new stream, link id)."""

from __future__ import annotations

import os

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from tether_companion.config import ConfigError
from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.mavlink.signing import (
    BAD_SIGNATURE,
    EPOCH_2015_UNIX_S,
    NEW_STREAM_WINDOW,
    REPLAY,
    STALE_STREAM,
    UNSIGNED,
    SignatureVerifier,
    Signer,
    is_signed,
    load_key,
    sign_frame,
    timestamp_from_unix_s,
)
from tether_companion.service.config import load_service_config
from tether_companion.service.security import LinkSecurity

KEY = bytes(range(100, 132))
NOW_UNIX_S = 1.75e9


def _pymavlink(key: bytes | None, *, system_id: int = 1, link_id: int = 0, timestamp: int = 0):
    m = mav.MAVLink(None, srcSystem=system_id, srcComponent=1)
    if key is not None:
        m.signing.secret_key = key
        m.signing.sign_outgoing = True
        m.signing.link_id = link_id
        m.signing.timestamp = timestamp
    return m


def _imu(t_us: int) -> mav.MAVLink_message:
    return mav.MAVLink_raw_imu_message(t_us, 1, 2, -1000, 4, 5, 6, 0, 0, 0, 0, 0)


def test_timestamp_units_are_10_us_since_2015() -> None:
    assert timestamp_from_unix_s(EPOCH_2015_UNIX_S) == 0
    assert timestamp_from_unix_s(EPOCH_2015_UNIX_S + 1.0) == 100_000
    assert timestamp_from_unix_s(0.0) == 0  # a clock before 2015 does not go negative


def test_pymavlink_signed_frames_verify_here_with_link_id_and_48_bit_timestamp() -> None:
    ts = timestamp_from_unix_s(NOW_UNIX_S)
    sender = _pymavlink(KEY, link_id=7, timestamp=ts)
    verifier = SignatureVerifier(KEY, clock_s=lambda: NOW_UNIX_S)
    frames = [bytes(_imu(i).pack(sender)) for i in range(5)]
    for frame in frames:
        assert verifier.check(frame) is None
    assert verifier.stream_timestamp(1, 1, 7) == ts + 4  # pymavlink adds 1 per frame
    assert verifier.check(frames[2]) == REPLAY
    # link id is part of the stream: the same system on link 8 is a new stream
    other = _pymavlink(KEY, link_id=8, timestamp=ts - 10)
    assert verifier.check(bytes(_imu(9).pack(other))) is None
    # our parser decodes a signed frame (and its fields) once the signature is checked
    (msg,) = FrameParser().feed(frames[0])
    assert msg.get_type() == "RAW_IMU" and msg.time_usec == 0


def test_frames_signed_here_are_accepted_by_pymavlink_and_replays_refused() -> None:
    signer = Signer(KEY, link_id=3, clock_s=lambda: NOW_UNIX_S)
    encoder = FrameEncoder(1, 191)
    signed = [signer.sign(encoder.encode(_imu(i))) for i in range(3)]
    receiver = _pymavlink(KEY, system_id=255)
    receiver.signing.timestamp = timestamp_from_unix_s(NOW_UNIX_S)
    for i, frame in enumerate(signed):
        msgs = receiver.parse_buffer(frame)
        assert msgs is not None and len(msgs) == 1
        assert msgs[0].get_signed() and msgs[0].get_link_id() == 3
        assert msgs[0].time_usec == i
    assert receiver.signing.goodsig_count == 3 and receiver.signing.badsig_count == 0
    with pytest.raises(mav.MAVError, match="Invalid signature"):
        receiver.parse_buffer(signed[1])  # replayed: pymavlink refuses it too
    assert receiver.signing.badsig_count == 1
    # the timestamp increases by at least one per frame even with a frozen clock
    assert signer.timestamp == timestamp_from_unix_s(NOW_UNIX_S) + 2


def test_wrong_key_and_altered_bytes_are_bad_signatures() -> None:
    verifier = SignatureVerifier(KEY, clock_s=lambda: NOW_UNIX_S)
    ts = timestamp_from_unix_s(NOW_UNIX_S)
    forged = bytes(_imu(1).pack(_pymavlink(bytes(32), timestamp=ts)))
    assert verifier.check(forged) == BAD_SIGNATURE
    genuine = bytearray(_imu(2).pack(_pymavlink(KEY, timestamp=ts)))
    for index in (6, 12, len(genuine) - 8):  # component id, payload, timestamp
        altered = bytearray(genuine)
        altered[index] ^= 0x01
        assert verifier.check(bytes(altered)) == BAD_SIGNATURE
    assert verifier.check(bytes(genuine)) is None
    unsigned = bytes(_imu(3).pack(_pymavlink(None)))
    assert verifier.check(unsigned) == UNSIGNED
    assert verifier.counters.bad_signature == 4 and verifier.counters.unsigned == 1


def test_a_new_stream_more_than_a_minute_behind_is_refused() -> None:
    verifier = SignatureVerifier(KEY, clock_s=lambda: NOW_UNIX_S)
    now = timestamp_from_unix_s(NOW_UNIX_S)
    old = bytes(_imu(1).pack(_pymavlink(KEY, timestamp=now - NEW_STREAM_WINDOW - 100)))
    recent = bytes(
        _imu(1).pack(_pymavlink(KEY, system_id=2, timestamp=now - NEW_STREAM_WINDOW + 100))
    )
    assert verifier.check(old) == STALE_STREAM
    assert verifier.check(recent) is None


def test_without_a_clock_the_time_is_learned_from_accepted_frames() -> None:
    verifier = SignatureVerifier(KEY, clock_s=lambda: 0.0)  # no RTC: starts at 2015
    ts = timestamp_from_unix_s(NOW_UNIX_S)
    assert verifier.check(bytes(_imu(1).pack(_pymavlink(KEY, timestamp=ts)))) is None
    assert verifier.timestamp == ts
    late = bytes(_imu(1).pack(_pymavlink(KEY, system_id=9, timestamp=ts - 2 * NEW_STREAM_WINDOW)))
    assert verifier.check(late) == STALE_STREAM
    signer = Signer(KEY, link_id=0, clock_s=lambda: 0.0)
    signer.observe(verifier.timestamp)
    assert signer.next_timestamp() == ts + 1


def test_sign_frame_refuses_what_it_cannot_sign() -> None:
    frame = FrameEncoder(1, 1).encode(dialect.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3))
    with pytest.raises(ValueError):
        sign_frame(frame, KEY[:31], 0, 0)
    with pytest.raises(ValueError):
        sign_frame(frame[:-1], KEY, 0, 0)
    signed = sign_frame(frame, KEY, 0, 5)
    with pytest.raises(ValueError):
        sign_frame(signed, KEY, 0, 6)


def _key_file(tmp_path, content: bytes, mode: int):
    path = tmp_path / "key"
    path.write_bytes(content)
    os.chmod(path, mode)
    return path


def test_key_file_raw_or_hex_readable_by_the_owner_only(tmp_path) -> None:
    assert load_key(_key_file(tmp_path, KEY, 0o600)) == KEY
    assert load_key(_key_file(tmp_path, KEY.hex().encode() + b"\n", 0o400)) == KEY
    for mode in (0o640, 0o604, 0o660):
        with pytest.raises(ConfigError, match="chmod 600"):
            load_key(_key_file(tmp_path, KEY, mode))
    with pytest.raises(ConfigError, match="32 raw bytes or 64 hex"):
        load_key(_key_file(tmp_path, b"short", 0o600))
    with pytest.raises(ConfigError, match="cannot read"):
        load_key(tmp_path / "missing")
    with pytest.raises(ConfigError, match="regular file"):
        load_key(tmp_path)


def test_setup_signing_installs_our_key_and_64_bit_timestamp_in_a_pymavlink_autopilot(
    tmp_path,
) -> None:
    """The service's SETUP_SIGNING (``security.install_key``), signed as the link signs, read by
    a pymavlink flight controller that has no key yet: the uint64 initial_timestamp arrives
    whole (10 us units since 2015, above 2^32), the autopilot takes the key and that timestamp
    as ArduPilot does, and from then on each side accepts the other's signed frames."""
    key_path = _key_file(tmp_path, KEY, 0o600)
    config = load_service_config(
        None,
        {
            "link": {"connect": "serial:/dev/ttyAMA0:921600"},
            "security": {"signing": "required", "key_file": str(key_path), "link_id": 4},
        },
    )
    security = LinkSecurity(config.security, config.link, unix_s=lambda: NOW_UNIX_S)
    ours = FrameEncoder(config.link.system_id, config.link.component_id, security.signer)
    setup_frame = ours.encode(security.setup_signing_message())

    assert is_signed(setup_frame)
    autopilot = _pymavlink(None)  # no key yet: a signed frame is read without checking
    (setup,) = autopilot.parse_buffer(setup_frame)
    assert setup.get_type() == "SETUP_SIGNING"
    assert setup.initial_timestamp == timestamp_from_unix_s(NOW_UNIX_S) > 2**32
    assert (setup.target_system, setup.target_component) == (1, 1)
    autopilot.signing.secret_key = bytes(setup.secret_key)
    autopilot.signing.timestamp = max(autopilot.signing.timestamp, setup.initial_timestamp)
    autopilot.signing.sign_outgoing = True
    autopilot.signing.link_id = 0  # ArduPilot signs with its channel number

    # the autopilot's signed stream verifies here ...
    verifier = security.verifier
    assert verifier is not None
    for i in range(3):
        assert verifier.check(bytes(_imu(i).pack(autopilot))) is None
    assert verifier.stream_timestamp(1, 1, 0) == setup.initial_timestamp + 2  # +1 a frame
    # ... and ours there (link id 4), a replay refused by both
    frames = [ours.encode(_imu(10 + i)) for i in range(2)]
    for frame in frames:
        (msg,) = autopilot.parse_buffer(frame)
        assert msg.get_signed() and msg.get_link_id() == 4
    assert autopilot.signing.badsig_count == 0 and autopilot.signing.goodsig_count == 2
    with pytest.raises(mav.MAVError, match="Invalid signature"):
        autopilot.parse_buffer(frames[0])
    assert verifier.check(bytes(_imu(0).pack(autopilot))) is None  # a new frame: newer stamp
    replayed = bytes(_imu(1).pack(autopilot))
    assert verifier.check(replayed) is None and verifier.check(replayed) == REPLAY
