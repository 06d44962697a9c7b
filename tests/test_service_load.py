"""Estimate age at the flight controller with the machine loaded: the service (its own
process, the shipped configuration) beside CPU hogs, over real UDP on 127.0.0.1.

Scheduling as deployed (``unit_priority.py``): the service in a session, hence a scheduling
group, of its own at the systemd unit's priority (``Nice=-10``, ``CPUWeight=1000``); each hog
and everything else on the machine ordinary (own group, nice 0). The fake flight controller
(this test's process) gets the same priority for the test: a real one is a microcontroller,
not a process on the companion, and its own stalls would count against the service (each
sample leaves the reorder buffer only when a newer one arrives).

On this shared 2-core machine at load 13 (docs/security.md has the runs): a 200 Hz sleeper
at ordinary priority in a group of its own woke up to 87-317 ms late; the service and the
fake flight controller at ordinary priority held estimates over 100 ms (p99.9) in 7 of 15
runs, up to 1.07 s; at the unit's priority, 31-61 ms in 8 runs. Lowering a nice needs
CAP_SYS_NICE (root): without it the test is skipped, saying so.

Slow (30 s of flight, 10 s for the negative control): ``pytest -m slow``.
"""

from __future__ import annotations

import asyncio
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from loaded_flight import fly_hover_beside_hogs
from unit_priority import at_unit_priority, in_own_group_at_unit_priority

from tether_companion.service.synthetic import FakeFlightController

pytestmark = [pytest.mark.slow, pytest.mark.integration]
AGE_P999_BOUND_S = 0.1
"""The issue's bound on the estimate age at the autopilot, p99.9 [s]."""
SERVICE = (sys.executable, "-m", "tether_companion.cli")
BLOCKING_SERVICE = (sys.executable, str(Path(__file__).with_name("blocking_housekeeping.py")))


def _ages(tmp_path, hogs: int, flight_s: float, service_cmd: tuple[str, ...]) -> np.ndarray:
    """Estimate ages [s] at the flight controller: RAW_IMU sent to VISION_POSITION_ESTIMATE
    with that IMU stamp received, after the first second of publication."""

    async def scenario() -> FakeFlightController:
        return await fly_hover_beside_hogs(
            tmp_path, service_cmd, hogs, flight_s, in_own_group_at_unit_priority
        )

    with at_unit_priority():
        fc = asyncio.run(scenario())
    log = fc.log
    ages = [
        log.vision_arrival_s[v.usec] - fc.imu_sent_s[v.usec]
        for v in log.vision
        if v.usec in fc.imu_sent_s
    ]
    assert len(ages) > 0.8 * 30.0 * (flight_s - 2.0)  # published at 30 Hz throughout
    return np.array(ages[30:])


def _p999_s(ages: np.ndarray, label: str) -> float:
    p50, p99, p999 = np.percentile(ages, [50, 99, 99.9])
    print(
        f"estimate age {label}: n {len(ages)} p50 {p50 * 1e3:.1f} ms p99 {p99 * 1e3:.1f} ms "
        f"p99.9 {p999 * 1e3:.1f} ms max {ages.max() * 1e3:.1f} ms"
    )
    return float(p999)


def test_estimate_age_p999_under_100_ms_beside_cpu_hogs(tmp_path) -> None:
    ages = _ages(tmp_path, hogs=os.cpu_count() or 2, flight_s=30.0, service_cmd=SERVICE)
    assert _p999_s(ages, "beside CPU hogs") < AGE_P999_BOUND_S


def test_the_bound_catches_a_hot_path_waiting_behind_housekeeping(tmp_path) -> None:
    """Negative control: the same measurement fails when a housekeeping turn blocks the event
    loop for 120 ms once a second (``blocking_housekeeping.py``), no hogs."""
    ages = _ages(tmp_path, hogs=0, flight_s=10.0, service_cmd=BLOCKING_SERVICE)
    assert _p999_s(ages, "behind blocking housekeeping") > AGE_P999_BOUND_S
