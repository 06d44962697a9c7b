"""The ingest's time line in C (``service/ingest_core.c``'s ``IngestCore``: the clock gate, the
reorder buffer and the order check as one object) against its Python reference
(``fc_time.FcTimeGate``, ``reorder.ReorderBuffer``, ``Ingest.receive_input`` / ``_believed`` /
``_ordered`` / ``_in_order``): the same verdicts, releases, samples, every counter, the reboot
flag and the buffer's state after every input, on random streams whose stamps jitter, reorder,
repeat, jump ahead (alone and in agreeing runs), step back, and reboot (with and without
SYSTEM_TIME's claim), with and without local times, through the frame path, the input path
and the message path (SYSTEM_TIME, a load cell's NAMED_VALUE_FLOAT, EXTENDED_SYS_STATE)
sharing one state.

The extension is optional (no compiler: the Python reference runs); its absence fails this
file where it could have been built, as the other extensions' files do.
"""

from __future__ import annotations

import math
import struct
import types

import numpy as np
import pytest
from optional_extension import import_extension
from test_frame_core import _fix_checksum, _same_samples, _sample_bits
from test_service_ingest_frames import _hover_frames

from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.samples import AttitudeSample, RangeSample
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.fc_time import FcTimeGate
from tether_companion.service.ingest import ATTITUDE, IMU, PWM, RANGE, IngestCounters
from tether_companion.service.reorder import ReorderBuffer
from tether_companion.service.session import EstimationSession

core, pytestmark = import_extension("tether_companion.service._frame_core")

KINDS = (IMU, ATTITUDE, PWM, RANGE)


def _float(value: float) -> bytes:
    return struct.pack("<d", value)


def _gate_params(gate: FcTimeGate) -> tuple:
    return (
        gate.backstep_s,
        gate.future_tolerance_s,
        gate.max_rate,
        gate.confirm_span_s,
        gate.fallback_s,
        gate.confirmations,
        gate.fallback_samples,
    )


def _bare_core(window_s: float):
    owner = types.SimpleNamespace(_local_s=None, rebooted=False)
    return core.IngestCore(owner, IngestCounters(), {}, window_s, _gate_params(FcTimeGate()))


def _stamps(
    rng: np.random.Generator, n: int, local_jitter_s: float = 0.0
) -> list[tuple[float, float | None]]:
    """(stamp, local time) pairs [s]: a 200 Hz clock with jitter, reordering, repeats, lone and
    agreeing jumps ahead, backsteps, reboots and stalls; local times None (replay) half of the
    streams, else each off by up to ``local_jitter_s`` (not in order)."""
    timed = rng.random() < 0.5
    fc, local, out = 100.0, 50.0, []
    while len(out) < n:
        choice = rng.random()
        if choice < 0.02:  # a reboot: the clock starts again near zero
            fc = float(rng.uniform(0.0, 5.0))
        elif choice < 0.04:  # a genuine jump (a stalled link): a run of agreeing stamps
            fc += float(rng.uniform(1.0, 30.0))
            local += float(rng.uniform(0.0, 0.05))
        elif choice < 0.06:  # a stall of the loop (local time jumps, the clock with it)
            stall = float(rng.uniform(0.5, 4.0))
            local += stall
            fc += stall
        fc += 0.005
        local += 0.0025
        stamp = fc
        odd = rng.random()
        if odd < 0.05:
            stamp = fc - float(rng.uniform(0.0, 0.06))  # late (reordered)
        elif odd < 0.07:
            stamp = fc - float(rng.uniform(1.0, 5.0))  # a backstep
        elif odd < 0.08:
            stamp = fc + float(rng.uniform(1.0, 1e6))  # a lone implausible stamp
        elif odd < 0.09 and out:
            stamp = out[-1][0]  # a repeat
        jitter = float(rng.uniform(-local_jitter_s, local_jitter_s))
        out.append((stamp, local + jitter if timed else None))
    return out


def test_the_gate_agrees_on_random_stamps() -> None:
    """check / on_system_time / reset against FcTimeGate, verdict and newest stamp each call."""
    rng = np.random.default_rng(5)
    verdicts = set()
    for _ in range(60):
        gate, twin = FcTimeGate(), _bare_core(0.0)
        for fc_s, local_s in _stamps(rng, 400, local_jitter_s=0.01 * (rng.random() < 0.5)):
            which = rng.random()
            if which < 0.04:
                claim = fc_s - float(rng.uniform(0.0, 3.0)) if rng.random() < 0.7 else fc_s
                result = (gate.on_system_time(claim, local_s), twin.on_system_time(claim, local_s))
            elif which < 0.045:
                gate.reset()
                twin.reset()
                result = ("reset", "reset")
            else:
                result = (gate.check(fc_s, local_s), twin.check(fc_s, local_s))
            assert result[0] == result[1]
            assert _float(gate.latest_fc_s) == _float(twin.latest_fc_s)
            verdicts.add(result[0])
    assert verdicts == {"accept", "implausible", "backstep", "reboot", "reset"}


@pytest.mark.parametrize("timed", [False, True])
def test_the_gate_falls_back_at_the_same_stamp(timed: bool) -> None:
    """A silent old clock (no SYSTEM_TIME): the reboot believed at the same backstep, the
    ``fallback_samples``-th without local times, after ``fallback_s`` with them."""
    gate, twin = FcTimeGate(), _bare_core(0.0)
    verdicts = []
    for k in range(1000):
        fc_s = 100.0 + 0.005 * k if k < 10 else 1.0 + 0.005 * k
        local_s = 0.0025 * k if timed else None
        verdict = gate.check(fc_s, local_s)
        assert twin.check(fc_s, local_s) == verdict
        verdicts.append(verdict)
    reboot = verdicts.index("reboot")
    assert reboot == (10 + 800 if timed else 10 + gate.fallback_samples - 1)
    assert verdicts[10:reboot] == ["backstep"] * (reboot - 10)


def test_the_buffer_agrees_on_random_streams() -> None:
    """push / clear against ReorderBuffer: the releases and the window's state each call."""
    rng = np.random.default_rng(6)
    for window in (0.0, 0.01, 0.03, 0.2):
        buffer, twin = ReorderBuffer(window), _bare_core(window)
        for i, (stamp, _) in enumerate(_stamps(rng, 6000)):
            kind = KINDS[int(rng.integers(4))]
            if rng.random() < 0.002:
                buffer.clear()
                twin.clear()
            assert buffer.push(kind, stamp, i) == twin.push(kind, stamp, i)
            state = (buffer.reordered, buffer.widened, buffer.narrowed, len(buffer))
            assert state == (twin.reordered, twin.widened, twin.narrowed, len(twin))
            assert _float(buffer.window_s) == _float(twin.window_s)
            assert _float(buffer.largest_lateness_s) == _float(twin.largest_lateness_s)
        if window:
            assert buffer.reordered and buffer.widened and buffer.narrowed
    with pytest.raises(ValueError, match="reorder window"):
        _bare_core(math.inf)


def _session_ingest(autopilot: str, window_s: float, monkeypatch, pure: bool):
    import tether_companion.service.ingest as ingest_module
    import tether_companion.service.ingest_frames as frames_module

    overrides = {
        "recording": {"enabled": False},
        "link": {"autopilot": autopilot},
        "inputs": {"reorder_window_s": window_s},
        "tension": {"source": "message"},
    }
    config = load_service_config(None, overrides)
    with monkeypatch.context() as patch:
        if pure:
            patch.setattr(ingest_module, "_CORE", None)
            patch.setattr(frames_module, "_CORE", None)
        session = EstimationSession(config, load_vehicle_for(config), messages=False)
    assert (session.ingest.core is None) is pure
    return session


def _state(ingest) -> tuple:
    counters = ingest.counters
    reorder = ingest.reorder
    return (
        counters,
        _float(counters.reorder_window_s),
        ingest.rebooted,
        _float(ingest.clock.latest_fc_s),
        dict(ingest._latest_by_kind),  # noqa: SLF001
        ingest._local_s,  # noqa: SLF001
        _float(reorder.window_s),
        _float(reorder.largest_lateness_s),
        reorder.narrowed,
        len(reorder),
    )


def _message(msg):
    return FrameParser().feed(FrameEncoder(1, 1).encode(msg))[0]


@pytest.mark.parametrize("window_s", [0.0, 0.03, 0.2])
def test_the_ingest_agrees_on_random_inputs_and_messages(window_s: float, monkeypatch) -> None:
    """Ingest with the core and the pure Python one fed the same inputs (receive_input), the
    same SYSTEM_TIMEs, load-cell readings and landed states (receive): the same samples and
    the whole state after every one."""
    with_c = _session_ingest("ardupilot", window_s, monkeypatch, pure=False).ingest
    pure = _session_ingest("ardupilot", window_s, monkeypatch, pure=True).ingest
    assert with_c.clock is with_c.reorder is with_c.core
    rng = np.random.default_rng(7 + int(window_s * 100))
    seen = set()
    for _ in range(12):
        for stamp, local_s in _stamps(rng, 1500):
            which = rng.random()
            ms = max(0, int(round(stamp * 1000)))
            if which < 0.02:
                back = ms - int(rng.uniform(0, 4000)) if rng.random() < 0.8 else ms
                msg = _message(dialect.MAVLink_system_time_message(0, max(0, back)))
            elif which < 0.06:
                msg = _message(dialect.MAVLink_named_value_float_message(ms, b"TENSION", 3.0))
            elif which < 0.07:
                msg = _message(dialect.MAVLink_extended_sys_state_message(0, 2))
            else:
                kind = KINDS[int(rng.integers(4))]
                sample = None if rng.random() < 0.01 else RangeSample(stamp, float(ms))
                if kind == ATTITUDE and sample is not None:
                    sample = AttitudeSample(stamp, 0.1, 0.2, float(ms))
                fast = with_c.receive_input(kind, sample, local_s)
                slow = pure.receive_input(kind, sample, local_s)
                assert fast == slow
                assert _state(with_c) == _state(pure)
                continue
            fast, slow = with_c.receive(msg, local_s), pure.receive(msg, local_s)
            assert [_sample_bits(s) if hasattr(s, "__slots__") else s for s in fast] == [
                _sample_bits(s) if hasattr(s, "__slots__") else s for s in slow
            ]
            assert _state(with_c) == _state(pure)
        counters = pure.counters
        seen.update(name for name, value in vars(counters).items() if value)
    assert {"implausible", "out_of_order", "duplicate", "reboots", "reordered"} <= seen or (
        window_s == 0.0 and {"implausible", "out_of_order", "duplicate", "reboots"} <= seen
    )
    assert pure.counters.accepted["tension"] and pure.counters.accepted["landed_state"]


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_frames_agree_through_one_call(autopilot: str, monkeypatch) -> None:
    """The frame path with the core (Reader.read, the drop's count and receive_input in one C
    call, ``IngestCore.samples``) against the all-Python one, on recorded frames whose stamps
    are mutated (jumps, backs, wraps) and sent out of order, with a reorder window."""
    session = _session_ingest(autopilot, 0.03, monkeypatch, pure=False)
    with_c = session.frames
    assert with_c.samples == session.ingest.core.samples
    pure = _session_ingest(autopilot, 0.03, monkeypatch, pure=True).frames
    rng = np.random.default_rng(31 if autopilot == "px4" else 32)
    recorded = _hover_frames(autopilot, 2.0, seed=3)
    local = 10.0
    i = 0
    for _ in range(12_000):
        i = min(len(recorded) - 1, max(0, i + int(rng.integers(-6, 8))))  # out of order
        data = bytearray(recorded[i])
        odd = rng.random()
        if odd < 0.05:  # a stamp's bytes (time_usec / time_boot_ms are first)
            data[10 + int(rng.integers(0, 8))] = int(rng.integers(256))
            data = _fix_checksum(data, rng)
        elif odd < 0.08:  # any payload byte (values the checks drop, by reason)
            data[10 + int(rng.integers(data[1]))] = int(rng.integers(256))
            data = _fix_checksum(data, rng)
        frame = bytes(data)
        _same_samples(with_c, pure, frame, local)
        assert _state(with_c._ingest) == _state(pure._ingest)  # noqa: SLF001
        local += 0.0025 if rng.random() < 0.995 else 3.0
    counters = pure._ingest.counters  # noqa: SLF001
    assert counters.reordered and counters.out_of_order and counters.implausible
    assert counters.reorder_widened and counters.duplicate
    assert counters.absurd and counters.out_of_range


def test_pure_python_runs_the_reference(monkeypatch) -> None:
    monkeypatch.setenv("TETHER_PURE_PYTHON", "1")
    from tether_companion.estimation.optional_core import load

    assert load("tether_companion.service._frame_core") is None
    session = _session_ingest("ardupilot", 0.03, monkeypatch, pure=True)
    assert isinstance(session.ingest.clock, FcTimeGate)
    assert isinstance(session.ingest.reorder, ReorderBuffer)
    assert "samples" not in vars(session.frames)  # the class's Python method runs
