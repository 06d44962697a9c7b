"""Input trust without signing: stamps far from the flight controller's clock model are
dropped, a reboot needs SYSTEM_TIME evidence, late samples are put back in order by the
reorder buffer (delay 30 ms, jitter 20 ms: < 1 % dropped)."""

from __future__ import annotations

import numpy as np
import pytest
from paper_filter import with_paper_filter

from tether_companion.mavlink.framing import FrameEncoder, FrameParser, dialect
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.fc_time import (
    ACCEPT,
    BACKSTEP,
    IMPLAUSIBLE,
    REBOOT,
    FcTimeGate,
)
from tether_companion.service.ingest import IngestCounters
from tether_companion.service.reorder import ReorderBuffer
from tether_companion.service.session import EstimationSession
from tether_companion.service.synthetic import HoverStreams

POSITION = np.array([2.0, 1.0, -3.0])
OFFSET_S = 9.0
"""Flight-controller time minus local time in these tests [s]."""


def test_a_stamp_far_ahead_is_implausible_and_does_not_move_the_clock() -> None:
    gate = FcTimeGate()
    assert gate.check(10.0, 1.0) == ACCEPT
    assert gate.check(2.0**63 * 1e-6, 1.001) == IMPLAUSIBLE
    assert gate.latest_fc_s == 10.0
    assert gate.check(10.005, 1.005) == ACCEPT
    # after a 5 s gap on the link the clock model expects ~15 s: that is plausible
    assert gate.check(15.1, 6.0) == ACCEPT


def test_a_genuine_jump_after_a_stall_is_believed_once_confirmed_over_time() -> None:
    """The link and our loop stalled together: the stamps after the gap arrive 1 s ahead at
    once. Five of them in one datagram are not enough; the stream going on over 10 ms is."""
    gate = FcTimeGate()
    for k in range(100):
        assert gate.check(10.0 + 0.005 * k, 1.0 + 0.005 * k) == ACCEPT
    assert [gate.check(11.5 + 0.005 * i, 1.5) for i in range(5)] == [IMPLAUSIBLE] * 5
    verdicts = [gate.check(11.525 + 0.006 * i, 1.5 + 0.006 * i) for i in range(4)]
    assert verdicts == [IMPLAUSIBLE, IMPLAUSIBLE, ACCEPT, ACCEPT]
    assert gate.latest_fc_s == pytest.approx(11.543)


def test_one_sample_or_one_datagram_cannot_declare_a_reboot() -> None:
    gate = FcTimeGate()
    for k in range(100):
        assert gate.check(10.0 + 0.005 * k, 1.0 + 0.005 * k) == ACCEPT
    # a spoofed datagram: SYSTEM_TIME of a fresh boot and five samples, all at one local time
    assert gate.on_system_time(0.1, 1.5) == BACKSTEP
    assert [gate.check(0.1 + 0.005 * i, 1.5) for i in range(5)] == [BACKSTEP] * 5
    # the genuine stream goes on and cancels the claim
    assert gate.check(10.5, 1.5) == ACCEPT
    assert [gate.check(0.2 + 0.005 * i, 1.51 + 0.005 * i) for i in range(5)] == [BACKSTEP] * 5
    # backstepped stamps without SYSTEM_TIME: no reboot while the old clock still talks
    for k in range(1000):
        assert gate.check(3.0, 1.52 + 0.001 * k) == BACKSTEP
        assert gate.check(10.51 + 0.001 * k, 1.52 + 0.001 * k) == ACCEPT


def test_a_real_reboot_is_believed_from_system_time_and_agreeing_stamps() -> None:
    gate = FcTimeGate()
    for k in range(100):
        gate.check(100.0 + 0.005 * k, 1.0 + 0.005 * k)
    assert gate.check(0.5, 2.0) == BACKSTEP  # before SYSTEM_TIME: just dropped
    assert gate.on_system_time(0.51, 2.01) == BACKSTEP
    verdicts = [gate.check(0.515 + 0.006 * i, 2.015 + 0.006 * i) for i in range(4)]
    assert verdicts == [BACKSTEP, BACKSTEP, REBOOT, ACCEPT]  # three over >= 10 ms local time
    assert gate.latest_fc_s == pytest.approx(0.533)


def test_without_system_time_a_silent_old_clock_means_a_reboot_after_two_seconds() -> None:
    gate = FcTimeGate()
    for k in range(100):
        gate.check(100.0 + 0.005 * k, 1.0 + 0.005 * k)
    verdicts = [gate.check(0.5 + 0.005 * i, 2.0 + 0.005 * i) for i in range(401)]
    assert verdicts[:400] == [BACKSTEP] * 400 and verdicts[400] == REBOOT


def _stream(seconds: float, start_s: float, seed: int = 5):
    config = load_service_config(None, with_paper_filter({"recording": {"enabled": False}}))
    streams = HoverStreams(load_vehicle_for(config), POSITION, 4.0, rng=np.random.default_rng(seed))
    fc = FrameEncoder(1, 1)
    for k in range(int(seconds * 200)):
        t = start_s + k * 0.005
        yield t, [fc.encode(m) for m in streams.messages(t, k)]


def _publish_gaps(publications: list) -> float:
    stamps = np.array([p.time_usec for p in publications]) * 1e-6
    return float(np.diff(stamps).max())


def test_spoofed_bombs_and_reboots_without_signing_do_not_interrupt_positions() -> None:
    """Once a second a stranger's datagram claims to be the flight controller: a RAW_IMU
    stamped 2^63 us, a SYSTEM_TIME of a fresh boot with samples of that boot, a stream stamped
    a second in the past. No restart, no publication gap over 0.1 s of FC time."""
    config = load_service_config(None, with_paper_filter({"recording": {"enabled": False}}))
    session = EstimationSession(config, load_vehicle_for(config))
    parser = FrameParser()
    spoof = FrameEncoder(1, 1)
    imu = dialect.MAVLink_raw_imu_message
    publications = []
    for t, frames in _stream(20.0, 30.0):
        local = t - OFFSET_S + 0.002
        if abs((t % 1.0) - 0.5) < 1e-6:
            frames = frames + [
                spoof.encode(imu(2**63, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0)),
                spoof.encode(dialect.MAVLink_system_time_message(0, 100))
                + b"".join(
                    spoof.encode(imu(100_000 + 5000 * i, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0))
                    for i in range(5)
                ),
                spoof.encode(imu(int((t - 1.5) * 1e6), 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0, 0)),
            ]
        for frame in frames:
            for msg in parser.feed(frame):
                step = session.on_message(msg, local)
                if step.publication is not None:
                    publications.append(step.publication)
    counters = session.ingest.counters
    assert counters.reboots == 0 and session.boots == 0
    assert counters.implausible == 20 and counters.out_of_order >= 20 * 6
    assert len(publications) > 500 and _publish_gaps(publications[5:]) < 0.1
    last = publications[-1]
    assert np.linalg.norm(np.array(last.position_ned_m) - POSITION) < 0.3


def test_a_real_reboot_restarts_the_estimator_once_system_time_says_so() -> None:
    config = load_service_config(None, with_paper_filter({"recording": {"enabled": False}}))
    session = EstimationSession(config, load_vehicle_for(config))
    parser = FrameParser()
    fc = FrameEncoder(1, 1)
    publications = []
    for start, boot_ms in ((30.0, 30_000), (0.5, 500)):
        frames = [(start, [fc.encode(dialect.MAVLink_system_time_message(0, boot_ms))])]
        for t, batch in [*frames, *_stream(6.0, start)]:
            for frame in batch:
                for msg in parser.feed(frame):
                    step = session.on_message(msg, t - start + 100.0)
                    if step.publication is not None:
                        publications.append(step.publication)
        if start == 30.0:
            assert session.boots == 0
    assert session.ingest.counters.reboots == 1 and session.boots == 1
    # dropped: the confirmations (over >= 10 ms: three IMU ticks' samples) before the restart
    assert session.ingest.counters.out_of_order <= 12
    assert publications[-1].time_usec < 7_000_000
    assert np.linalg.norm(np.array(publications[-1].position_ned_m) - POSITION) < 0.3


def test_reorder_buffer_releases_in_stamp_order_once_reordering_is_seen() -> None:
    buffer: ReorderBuffer[str] = ReorderBuffer(max_window_s=0.02)
    assert buffer.push("imu", 1.000, "a") == [("imu", "a")]  # clean so far: no delay
    assert buffer.push("att", 0.990, "other stream") == [("att", "other stream")]
    assert buffer.window_s == 0.0 and buffer.reordered == 0  # streams out of step: not reordering
    assert buffer.push("imu", 0.992, "late") == []  # imu overtook itself by 8 ms
    assert buffer.reordered == 1 and buffer.widened == 1
    assert buffer.window_s == pytest.approx(1.25 * 0.008)
    assert buffer.push("att", 1.005, "b") == [("imu", "late")]
    assert buffer.push("imu", 1.004, "c") == []
    assert [s for _, s in buffer.push("imu", 1.016, "d")] == ["c", "b"]
    assert len(buffer) == 1  # d waits for newer stamps
    buffer.push("imu", 0.5, "very late")  # bounded: the window never passes the maximum
    assert buffer.window_s == 0.02 and buffer.largest_lateness_s == pytest.approx(0.516)
    assert ReorderBuffer(0.0).push("imu", 1.0, "x") == [("imu", "x")]


def test_reorder_window_stays_zero_on_a_clean_link_and_decays_after_reordering_stops() -> None:
    """In order: every sample out on its own push. A reordering burst widens the window; 5-10 s
    of flight-controller time without reordering bring it back to 0 (and nothing stays held)."""
    buffer: ReorderBuffer[float] = ReorderBuffer(max_window_s=0.03)
    t = 100.0
    for k in range(2000):  # 10 s: imu at 200 Hz, attitude stamped 1 ms ahead of it
        t = 100.0 + 0.005 * k
        assert buffer.push("att", t + 0.001, k) == [("att", k)]
        assert buffer.push("imu", t, k) == [("imu", k)]
    assert buffer.window_s == 0.0 and buffer.reordered == 0 and len(buffer) == 0
    for k in range(2000, 2200):  # 1 s of pairs swapped: every other imu sample 5 ms late
        t = 100.0 + 0.005 * k
        stamp = t + (0.005 if k % 2 == 0 else -0.005)
        buffer.push("imu", stamp, stamp)
    assert buffer.reordered == 100 and buffer.window_s == pytest.approx(1.25 * 0.005)
    released = []
    for k in range(2200, 4400):  # 11 s clean again
        t = 100.0 + 0.005 * k
        released += buffer.push("imu", t, t)
    assert buffer.window_s == 0.0 and buffer.narrowed == 1
    assert buffer.push("imu", t + 0.005, -1.0) == [("imu", -1.0)] and len(buffer) == 0
    stamps = [stamp for _, stamp in released]
    assert stamps == sorted(stamps) and len(stamps) > 2200  # the held ones came out in order


def _jittered_drop_fraction(window_s: float, seed: int) -> tuple[float, IngestCounters]:
    """Share of inputs dropped as late through a link with 30 ms delay and 20 ms uniform
    jitter (the emulator's ``delay_s``/``delay_jitter_s`` model), and the ingest counters."""
    config = load_service_config(
        None, {"recording": {"enabled": False}, "inputs": {"reorder_window_s": window_s}}
    )
    session = EstimationSession(config, load_vehicle_for(config))
    rng = np.random.default_rng(seed)
    arrivals = []
    for t, frames in _stream(10.0, 10.0, seed=seed):
        for frame in frames:
            arrivals.append((t + 0.03 + 0.02 * rng.random(), len(arrivals), frame))
    arrivals.sort()
    parser = FrameParser()
    for arrival, _, frame in arrivals:
        for msg in parser.feed(frame):
            session.on_message(msg, arrival - OFFSET_S)
    counters = session.ingest.counters
    return (counters.out_of_order + counters.duplicate) / len(arrivals), counters


@pytest.mark.parametrize("seed", [11, 12])
def test_delay_30_ms_jitter_20_ms_drops_under_one_percent(seed: int) -> None:
    """The default (adaptive, at most 30 ms) against the issue's link; without a window (0)
    the same link loses a fifth of the inputs. (Fixed windows of 5/10/15 ms were tried on
    seeds 1-3: 6.4 %, 1.5 %, 0.0 % dropped.)"""
    default = load_service_config(None).inputs.reorder_window_s
    dropped, counters = _jittered_drop_fraction(default, seed)
    print(f"dropped {100 * dropped:.3f} %, window {1e3 * counters.reorder_window_s:.1f} ms")
    assert dropped < 0.01
    assert 0.01 < counters.reorder_window_s <= default  # opened to the reordering it saw
    assert _jittered_drop_fraction(0.0, seed)[0] > 0.1
