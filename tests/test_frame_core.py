"""The input frames' test and field read in C (``service/frame_core.c``) against its Python
reference (``FrameIngest.take`` / ``FrameIngest.fields`` of the class, ``_entry`` and the
message's ``struct``): the same verdict and the same values (types and float bits) on recorded
frames of both flavours, on frames each check refuses, and on 100,000 random and mutated
frames, half of them with their checksum made good again so that the checks after it run.

The extension is optional (no compiler: the Python reference runs). Its absence fails this
file where it could have been built (a C compiler and the Python headers here) or with
``TETHER_REQUIRE_CORE=1``, as the other extensions' files do.
"""

from __future__ import annotations

import functools
import struct

import numpy as np
import pytest
from optional_extension import import_extension
from test_service_ingest_frames import _hover_frames, _ingest, _odd_messages

from tether_companion.mavlink.framing import FrameEncoder, _checksum, dialect
from tether_companion.service.ingest_frames import FrameIngest

core, pytestmark = import_extension("tether_companion.service._frame_core")

FLAVOURS = ("ardupilot", "px4")


def _bits(values: tuple | None) -> object:
    """Values by type and, for floats, bit pattern (-0.0 != 0.0, NaNs compare)."""
    if values is None:
        return None
    return [(type(v), struct.pack("<d", v) if type(v) is float else v) for v in values]


def _frames(autopilot: str) -> FrameIngest:
    frames = FrameIngest(_ingest(autopilot)[0])
    assert isinstance(frames.take, functools.partial)  # C runs
    assert isinstance(frames.fields, functools.partial)
    return frames


def _same(frames: FrameIngest, frame: bytes | bytearray) -> bool:
    """Asserts C and Python agree on ``frame``; whether it was taken."""
    reference = FrameIngest.fields(frames, frame)
    assert _bits(frames.fields(frame)) == _bits(reference), bytes(frame).hex()
    assert frames.take(frame) is FrameIngest.take(frames, frame) is (reference is not None)
    return reference is not None


def _fix_checksum(data: bytearray, rng: np.random.Generator) -> bytearray:
    """``data`` with its last two bytes the checksum over what it holds as a MAVLink 2 frame
    (the crc_extra of its message id when the dialect knows it, else a random one)."""
    if len(data) < 3:
        return data
    msg_id = data[7] | (data[8] << 8) | (data[9] << 16) if len(data) >= 10 else -1
    known = dialect.mavlink_map.get(msg_id)
    extra = known.crc_extra if known is not None else int(rng.integers(256))
    data[-2:] = struct.pack("<H", _checksum(bytes(data[1:-2]), bytes((extra,))))
    return data


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_recorded_and_refused_frames_agree(autopilot: str) -> None:
    frames = _frames(autopilot)
    recorded = _hover_frames(autopilot, 1.0, seed=3)
    assert all(_same(frames, frame) for frame in recorded)
    for frame in recorded[:8]:  # as bytearray and memoryview too (tlog records, buffers)
        assert _same(frames, bytearray(frame))
        assert frames.fields(memoryview(frame)) == frames.fields(frame)
    taken = 0
    for encoder in (FrameEncoder(1, 1), FrameEncoder(2, 1), FrameEncoder(1, 2)):
        for msg in _odd_messages(8):
            taken += _same(frames, encoder.encode(msg))
    assert 0 < taken < 3 * len(_odd_messages(8))
    v1 = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    msg = dialect.MAVLink_attitude_message(30_000, 0.1, 0.1, 0.1, 0.0, 0.0, 0.0)
    assert not _same(frames, bytes(msg.pack(v1, force_mavlink1=True)))


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_random_and_mutated_frames_agree(autopilot: str) -> None:
    rng = np.random.default_rng(12 if autopilot == "px4" else 11)
    frames = _frames(autopilot)
    recorded = _hover_frames(autopilot, 1.0, seed=5)
    taken = fixed_taken = 0
    for k in range(50_000):
        data = bytearray(recorded[int(rng.integers(len(recorded)))])
        choice = int(rng.integers(9))
        if choice == 1:
            data[rng.integers(len(data))] ^= 1 << int(rng.integers(8))
        elif choice == 2:
            data[rng.integers(len(data))] = int(rng.integers(256))
        elif choice == 3:
            data = data[: int(rng.integers(len(data) + 1))]
        elif choice == 4:  # the payload cut (the sender's trailing zeros) or grown
            cut = int(rng.integers(-3, data[1] + 1))
            data[1] = (data[1] - cut) % 256
            data = data[: 10 + data[1]] + bytes(max(0, 10 + data[1] - len(data))) + b"\0\0"
        elif choice == 5:
            data += bytes(rng.integers(0, 256, int(rng.integers(1, 4)), dtype=np.uint8))
        elif choice == 6:  # a header byte: STX, length, flags, ids, message id
            data[rng.integers(10)] = int(rng.integers(256))
        elif choice == 7:
            data = bytearray(rng.integers(0, 256, int(rng.integers(0, 80)), dtype=np.uint8))
        elif choice == 8:  # random payload bytes (NaN and inf floats, extreme integers)
            for i in range(10, len(data) - 2):
                data[i] = int(rng.integers(256))
        if k % 2:
            data = _fix_checksum(data, rng)
            fixed_taken += _same(frames, bytes(data))
        else:
            taken += _same(frames, bytes(data))
    assert fixed_taken > 5_000 and taken > 2_000  # both verdicts, and the later checks, ran


def test_a_malformed_spec_is_refused() -> None:
    frame = _hover_frames("ardupilot", 0.01, seed=1)[0]
    with pytest.raises(ValueError, match="malformed"):
        core.take(b"\x01\x01", frame)
    with pytest.raises(ValueError, match="malformed"):
        core.fields(b"\x01\x01\x02" + bytes(9), frame)
    with pytest.raises(TypeError):
        core.take(b"\x01\x01\x00")
    assert core.fields(b"\x01\x01\x00", frame) is None  # an empty table takes nothing


def test_pure_python_runs_the_reference(monkeypatch: pytest.MonkeyPatch) -> None:
    import tether_companion.service.ingest_frames as module

    with_c = _frames("ardupilot")
    monkeypatch.setattr(module, "_CORE", None)
    frames = FrameIngest(_ingest("ardupilot")[0])
    assert not isinstance(frames.take, functools.partial)
    frame = _hover_frames("ardupilot", 0.01, seed=1)[0]
    assert frames.fields(frame) == with_c.fields(frame)


def _sample_bits(sample) -> object:
    if sample is None:
        return None
    values = []
    for name in type(sample).__slots__:
        value = getattr(sample, name)
        if isinstance(value, np.ndarray):
            flags = value.flags
            values.append(
                (value.dtype.str, value.shape, value.tobytes(), flags.writeable, flags.owndata)
                + (flags.c_contiguous, flags.aligned, value.base is None)
            )
        else:
            values.append((type(value), struct.pack("<d", value)))
    return type(sample), values


def _same_samples(with_c: FrameIngest, pure: FrameIngest, frame: bytes, local: float) -> object:
    """Both ingests' samples of ``frame`` at local time ``local`` [s] (None where not taken),
    asserted the same, bit for bit; returns the C ingest's."""
    fast = with_c.samples(frame, local) if with_c.take(frame) else None
    slow = pure.samples(frame, local) if pure.take(frame) else None
    assert (fast is None) == (slow is None)
    if fast is not None:
        assert [_sample_bits(s) for s in fast] == [_sample_bits(s) for s in slow]
    return fast


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_samples_and_counts_agree_on_random_and_mutated_frames(
    autopilot: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """C's Reader (units, checks, sample objects, SERVO_OUTPUT_RAW's time unwrapped at the
    clock's newest stamp) against the Python converts and Ingest's checks, each with its own
    ingest, through the clock, reorder and order steps: the same samples (float bits, arrays'
    dtype, shape and bytes) and counts after every frame, on random payloads (NaN, inf,
    extreme integers) with good checksums and stamps that jump, go back and wrap."""
    import tether_companion.service.ingest_frames as module

    with_c = _frames(autopilot)
    assert type(with_c._read).__name__ == "builtin_function_or_method"  # noqa: SLF001
    monkeypatch.setattr(module, "_CORE", None)
    pure = FrameIngest(_ingest(autopilot)[0])
    rng = np.random.default_rng(21 if autopilot == "px4" else 22)
    recorded = _hover_frames(autopilot, 1.0, seed=6)
    local = 10.0
    kinds = set()
    for _ in range(20_000):
        data = bytearray(recorded[int(rng.integers(len(recorded)))])
        choice = int(rng.integers(6))
        if choice == 1:  # random payload bytes
            for i in range(10, len(data) - 2):
                data[i] = int(rng.integers(256))
        elif choice == 2:  # a random byte of the payload
            data[10 + int(rng.integers(data[1]))] = int(rng.integers(256))
        elif choice == 3:  # a stamp's high bytes (time_usec / time_boot_ms are first)
            data[10 + int(rng.integers(2, 8))] = int(rng.integers(256))
        elif choice == 4:  # the payload truncated
            cut = int(rng.integers(1, data[1]))
            data[1] -= cut
            data = data[: 10 + data[1]] + b"\0\0"
        if choice:
            data = _fix_checksum(data, rng)
        frame = bytes(data)
        fast = _same_samples(with_c, pure, frame, local)
        if fast is not None:
            kinds.update(type(s).__name__ for s in fast)
        assert with_c._ingest.counters == pure._ingest.counters  # noqa: SLF001
        local += 0.0025 if rng.random() < 0.99 else 3.0
    counters = pure._ingest.counters  # noqa: SLF001
    assert kinds == {"ImuSample", "AttitudeSample", "PwmSample", "RangeSample"}
    assert counters.nonfinite and counters.absurd and counters.not_input
    assert counters.out_of_range and counters.out_of_order and counters.implausible


def test_the_samples_have_the_fields_reader_sets() -> None:
    """Reader fills the sample classes as their dataclass __init__ does: these fields, in this
    order, and nothing after (no __post_init__)."""
    import dataclasses

    from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample

    expected = {
        ImuSample: ("time_s", "specific_force_body_mps2", "angular_rate_body_rad_s"),
        AttitudeSample: ("time_s", "roll_rad", "pitch_rad", "yaw_rad"),
        PwmSample: ("time_s", "pwm_us"),
        RangeSample: ("time_s", "distance_m"),
    }
    for cls, names in expected.items():
        assert tuple(f.name for f in dataclasses.fields(cls)) == names
        assert cls.__slots__ == names
        assert not hasattr(cls, "__post_init__")


def _pair(autopilot: str, monkeypatch: pytest.MonkeyPatch, inputs: dict) -> tuple:
    """FrameIngest with C's Reader and the Python one, each with its own ingest configured with
    the ``inputs`` limits."""
    import tether_companion.service.ingest_frames as module
    from tether_companion.service.config import load_service_config, load_vehicle_for
    from tether_companion.service.session import EstimationSession

    def ingest():
        overrides = {"recording": {"enabled": False}, "link": {"autopilot": autopilot}}
        config = load_service_config(None, {**overrides, "inputs": inputs})
        return EstimationSession(config, load_vehicle_for(config), messages=False).ingest

    with_c = FrameIngest(ingest())
    assert type(with_c._read).__name__ == "builtin_function_or_method"  # noqa: SLF001
    with monkeypatch.context() as patch:
        patch.setattr(module, "_CORE", None)
        pure = FrameIngest(ingest())
    return with_c, pure


def _agree(pair: tuple, msg, local_s: float | None) -> list:
    with_c, pure = pair
    frame = FrameEncoder(1, 1).encode(msg)
    fast, slow = with_c.samples(frame, local_s), pure.samples(frame, local_s)
    assert [_sample_bits(s) for s in fast] == [_sample_bits(s) for s in slow]
    assert with_c._ingest.counters == pure._ingest.counters  # noqa: SLF001
    return slow


def _around(value: float) -> list[float]:
    """The float32 values nearest ``value``, both signs."""
    f = np.float32(value)
    near = [np.nextafter(f, np.float32(-np.inf)), f, np.nextafter(f, np.float32(np.inf))]
    return [float(s * v) for v in near for s in (1, -1)]


def _force_sum_differs(autopilot: str) -> tuple[tuple, float]:
    """An accelerometer triple whose squared norm summed x, y, z differs from z, y, x, and a
    bound on the specific force that only the first order exceeds (x, y, z in the message's
    units)."""
    import math

    from tether_companion.mavlink.units import MILLI_G_TO_MPS2

    rng = np.random.default_rng(3)
    while True:
        raw = rng.integers(-9000, 9000, 3)
        if autopilot == "ardupilot":
            xyz = tuple(int(v) for v in raw)
            f = [v * MILLI_G_TO_MPS2 for v in xyz]
        else:
            xyz = tuple(float(np.float32(v * 0.0123)) for v in raw)
            f = list(xyz)
        ours = f[0] * f[0] + f[1] * f[1] + f[2] * f[2]
        other = f[2] * f[2] + f[1] * f[1] + f[0] * f[0]
        if ours <= other:
            continue
        bound = math.sqrt(other)
        for _ in range(8):
            if bound * bound >= ours:
                bound = math.nextafter(bound, 0.0)
            elif bound * bound < other:
                bound = math.nextafter(bound, math.inf)
        if other <= bound * bound < ours:
            return xyz, bound


@pytest.mark.parametrize("autopilot", FLAVOURS)
def test_samples_agree_at_every_bound(autopilot: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Values at and next to each check's bound, the squared force's summation order, and
    SERVO_OUTPUT_RAW's time half way between two wraps (Python's round: to even)."""
    import math

    xyz, bound = _force_sum_differs(autopilot)
    limits = {"max_specific_force_mps2": bound, "max_angular_rate_rad_s": 30.0}
    pair = _pair(autopilot, monkeypatch, limits)
    t_us = 1_000_000
    imu = dialect.MAVLink_raw_imu_message if autopilot == "ardupilot" else None

    def imu_msg(acc: tuple, rate: tuple):
        nonlocal t_us
        t_us += 1000
        if imu is not None:
            return imu(t_us, *acc, *rate, 0, 0, 0, 0, 20)
        return dialect.MAVLink_highres_imu_message(t_us, *acc, *rate, *([0.0] * 7), 0, 0)

    assert not _agree(pair, imu_msg(xyz, (0, 0, 0)), None)  # absurd in our order only
    rates = [30000, 30001, -30001] if autopilot == "ardupilot" else _around(30.0)
    for r in rates:
        for axis in range(3):
            _agree(
                pair,
                imu_msg(
                    (0, 0, -1000 if imu else -9.8), tuple(r if i == axis else 0 for i in range(3))
                ),
                None,
            )
    t_ms = 2000
    for bound_rad in (math.pi + 1e-3, 0.5 * math.pi + 1e-3, 2.0 * math.pi):
        for v in _around(bound_rad):
            for axis in range(3):
                t_ms += 1
                angles = [v if i == axis else 0.0 for i in range(3)]
                _agree(pair, dialect.MAVLink_attitude_message(t_ms, *angles, 0, 0, 0), None)
    for cm, low, high in (
        (5, 5, 4000),
        (4, 4, 4000),
        (4000, 5, 4000),
        (4001, 5, 4001),
        (300, 300, 300),
        (300, 301, 400),
        (300, 200, 299),
    ):
        t_ms += 1
        _agree(
            pair, dialect.MAVLink_distance_sensor_message(t_ms, low, high, cm, 0, 0, 25, 0), None
        )
    servo = [1500] * 16
    for out in (800, 799, 2200, 2201):
        t_ms += 1
        _agree(
            pair, dialect.MAVLink_servo_output_raw_message(t_ms * 1000, 0, out, *servo[1:]), None
        )
    # newest stamp 2^31 + 1000 us, exact in float: a SERVO_OUTPUT_RAW stamped 1000 us is half
    # a wrap behind, round(0.5) = 0 wraps: dropped as a backstep (with 1 wrap: accepted)
    _agree(pair, imu_msg((0, 0, -1000 if imu else -9.8), (0, 0, 0)), None)
    t_us = 2**31 + 1000 - 1000
    _agree(pair, imu_msg((0, 0, -1000 if imu else -9.8), (0, 0, 0)), None)
    before = pair[1]._ingest.counters.out_of_order  # noqa: SLF001
    assert not _agree(pair, dialect.MAVLink_servo_output_raw_message(1000, 0, *servo), None)
    assert pair[1]._ingest.counters.out_of_order == before + 1  # noqa: SLF001


def test_a_build_whose_reader_does_not_fill_arrays_keeps_the_python_read(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The Reader is handed numpy.empty to fill (READER_FILLS); an extension built before
    that (it would call empty with the values) is not used for the read."""
    import tether_companion.service.ingest_frames as module

    assert type(_frames("ardupilot")._read).__name__ == "builtin_function_or_method"  # noqa: SLF001
    monkeypatch.delattr(module._CORE, "READER_FILLS")  # noqa: SLF001
    frames = _frames("ardupilot")
    assert frames._read == frames._read_fields  # noqa: SLF001 - the Python reference
