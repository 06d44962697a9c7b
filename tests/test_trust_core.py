"""trust_core.c's ``admit`` against its reference, :meth:`LinkTrust.admit_reference`: the same
decisions, counters, pinned address, candidate, protected peers, events and exceptions over
random frame streams; its usual frame taken without the reference, every other frame by it.

Absent where the extension could not be built (``optional_extension.import_extension``)."""

from __future__ import annotations

import random
from collections.abc import Callable

import pytest
from optional_extension import import_extension
from pymavlink.dialects.v20 import ardupilotmega as mav

from tether_companion.mavlink.framing import FrameEncoder
from tether_companion.mavlink.signing import SignatureVerifier, Signer
from tether_companion.mavlink.trust import OFF, PREFERRED, REQUIRED, LinkTrust

core, pytestmark = import_extension("tether_companion.mavlink._trust_core")

KEY = bytes(range(1, 33))
NOW_UNIX_S = 1.75e9
FC = ("127.0.0.1", 5760)
SOURCES = [FC, ("127.0.0.1", 6000), ("10.0.0.2", 14550), None, "/dev/ttyUSB0"]
SENDERS = [(1, 1), (1, 1), (1, 1), (1, 2), (255, 190), (7, 1), (2, 1)]


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _trust(signing: str, clock: Clock) -> LinkTrust:
    verifier = SignatureVerifier(KEY, clock_s=lambda: NOW_UNIX_S) if signing != OFF else None
    return LinkTrust(
        signing,
        verifier=verifier,
        fc_ids=(1, 1),
        command_sources=(255,),
        repin_silence_s=2.0,
        monotonic_s=clock,
    )


def _frames(rng: random.Random, count: int) -> list[bytes]:
    """MAVLink 2 frames (signed and not) of HEARTBEAT, RAW_IMU and COMMAND_LONG from several
    senders, MAVLink 1-shaped frames, and frames too short to hold their ids."""
    encoders = {
        (ids, signed): FrameEncoder(
            *ids, Signer(KEY, 0, clock_s=lambda: NOW_UNIX_S) if signed else None
        )
        for ids in set(SENDERS)
        for signed in (False, True)
    }
    frames = []
    for i in range(count):
        kind = rng.random()
        if kind < 0.05:
            marker = [0xFE] if rng.random() < 0.5 else []  # half of them MAVLink 1-shaped
            frames.append(bytes(marker + [rng.randrange(256) for _ in range(rng.randrange(11))]))
            continue
        ids = rng.choice(SENDERS)
        if kind < 0.15:  # the trust reads a MAVLink 1 frame's ids only (bytes 3-5)
            body = [0xFE, 9, i % 256, ids[0], ids[1], rng.choice([0, 27, 76])]
            frames.append(bytes(body + [rng.randrange(256) for _ in range(rng.randrange(12))]))
            continue
        encoder = encoders[(ids, rng.random() < 0.2)]
        message = rng.choice(
            [
                mav.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3),
                mav.MAVLink_raw_imu_message(i, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0),
                mav.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),
            ]
        )
        frames.append(encoder.encode(message))
    return frames


def _state(trust: LinkTrust) -> tuple:
    return (
        trust.counters.as_dict(),
        trust.fc_source,
        trust._fc_heard_s,
        trust._candidate,
        trust._candidate_heartbeats,
        list(trust._ground_stations),
        list(trust.events),
    )


def _outcome(admit: Callable[[bytes, object], bool], frame: bytes, source: object) -> object:
    try:
        return admit(frame, source)
    except Exception as error:  # the reference's IndexError / struct.error on a short frame
        return type(error)


@pytest.mark.parametrize("signing", [OFF, OFF, PREFERRED, REQUIRED])
@pytest.mark.parametrize("seed", range(6))
def test_admit_decides_and_counts_as_the_reference(signing: str, seed: int) -> None:
    rng = random.Random(seed)
    clock = Clock()
    in_c, in_python = _trust(signing, clock), _trust(signing, clock)
    for frame in _frames(rng, 600):
        clock.t += rng.choice([0.001, 0.005, 0.4, 2.5])
        source = rng.choice(SOURCES) if rng.random() < 0.3 else FC
        taken = _outcome(lambda f, s: core.admit(in_c, f, s), frame, source)
        assert taken == _outcome(in_python.admit_reference, frame, source), frame.hex()
        assert _state(in_c) == _state(in_python)
    assert in_c.counters.admitted > 100


def test_the_usual_frame_is_taken_without_the_reference_and_the_rest_by_it() -> None:
    clock = Clock()
    trust = _trust(OFF, clock)
    referred: list[bytes] = []
    reference = trust.admit_reference

    def counted(frame: bytes, source: object) -> bool:
        referred.append(frame)
        return reference(frame, source)

    trust.admit_reference = counted  # type: ignore[method-assign]
    fc, other, station = FrameEncoder(1, 1), FrameEncoder(7, 1), FrameEncoder(255, 190)
    imu = mav.MAVLink_raw_imu_message(1, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0)
    first = fc.encode(imu)
    assert core.admit(trust, first, FC) and referred == [first]  # pins the address
    for t in range(1, 50):
        clock.t = t * 0.005
        assert core.admit(trust, fc.encode(imu), FC)
        assert core.admit(trust, other.encode(imu), ("10.0.0.2", 1))
    assert len(referred) == 1 and trust._fc_heard_s == 49 * 0.005
    assert trust.counters.admitted == 99
    foreign = fc.encode(imu)
    assert not core.admit(trust, foreign, ("10.0.0.9", 1)) and referred[-1] is foreign
    from_station = station.encode(imu)
    assert core.admit(trust, from_station, ("10.0.0.3", 2)) and referred[-1] is from_station
    assert trust.protected(("10.0.0.3", 2))


def test_link_trust_admit_is_the_c_where_built() -> None:
    import tether_companion.mavlink.trust as trust_module

    if trust_module.ADMIT_CORE is None:  # TETHER_PURE_PYTHON: the reference is admit
        assert LinkTrust.__dict__["admit"] is LinkTrust.__dict__["admit_reference"]
    else:
        assert LinkTrust.__dict__["admit"] is trust_module.ADMIT_CORE
