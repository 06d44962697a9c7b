"""Honest observability when a sensor goes away (issue 13): the covariance grows as the
information does, the health names the missing input, and no estimate reaches the flight
controller with its error beyond 3 sigma of its own covariance. Driven against the emulator's
faults in lock-step (real MAVLink frames both ways, no wall clock)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from lockstep_service import LockstepService, published_errors
from paper_filter import PAPER_FILTER

from tether_companion.emulator.autopilot import FlightController
from tether_companion.emulator.config import FaultConfig, Outage, Window, load_emulator_scenario
from tether_companion.estimation.observability import ObservabilityConfig, RangeWatch
from tether_companion.service.health import NO_RANGE

pytestmark = pytest.mark.integration


def _fly(duration_s: float, faults: FaultConfig, seed: int | None = None) -> LockstepService:
    """The shipped service configuration with the paper's 4-state EKF (whose covariance growth
    these tests check: ``estimation/observability.py``) on the paper's circle (4 N) with
    ``faults``."""
    scenario, emulator_config = load_emulator_scenario("paper-circle")
    scenario = dataclasses.replace(scenario, duration_s=duration_s)
    if seed is not None:
        scenario = dataclasses.replace(scenario, seed=seed)
    controller = FlightController(scenario, dataclasses.replace(emulator_config, faults=faults))
    lockstep = LockstepService(controller, {"estimator": PAPER_FILTER}, record=True)
    while controller.time_s < duration_s:
        lockstep.advance()
        lockstep.serve()
    return lockstep


def test_range_watch_decouples_and_grows_the_variance_along_the_cable() -> None:
    watch = RangeWatch(ObservabilityConfig(range_lost_after_s=0.3, unobserved_speed_mps=2.0))
    rng = np.random.default_rng(3)
    a = rng.normal(size=(4, 4))
    covariance = a @ a.T + 0.1 * np.eye(4)
    position = np.array([3.0, -1.0, -2.0])
    u = position / np.linalg.norm(position)
    watch.on_fused(0.0)
    before = covariance.copy()
    assert not watch.grow(covariance, position, 0.3, 0.005)  # not lost yet: untouched
    np.testing.assert_array_equal(covariance, before)
    along = u @ before[:3, :3] @ u
    assert watch.grow(covariance, position, 0.5, 0.1)
    e = np.append(u, 0.0)
    # no correlation left between the position along the cable and anything else
    np.testing.assert_allclose(covariance @ e, (e @ covariance @ e) * e, atol=1e-12)
    # its variance grew by v^2 (t^2 - (t - dt)^2)
    np.testing.assert_allclose(e @ covariance @ e, along + 4.0 * (0.5**2 - 0.4**2), rtol=1e-12)
    # the part across the cable is unchanged
    across = np.eye(4) - np.outer(e, e)
    np.testing.assert_allclose(across @ covariance @ across, across @ before @ across, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(covariance) > 0.0)
    watch.on_fused(0.6)
    assert not watch.lost(0.7)


def test_rangefinder_out_of_range_is_withheld_with_the_reason_not_published_wrong() -> None:
    """5 s of rangefinder out of range on the circle: before this change the estimate drifted
    3.9 m along the cable while the published variances stayed <= 0.16 m^2. Now what is sent
    stays within 3 sigma, the position is withheld once its variance passes the bound with
    ``no_range`` health and a STATUSTEXT naming the rangefinder, and it comes back after."""
    lockstep = _fly(24.0, FaultConfig(rangefinder_out_of_range=(Window(12.0, 5.0),)))
    errors = published_errors(lockstep)
    assert errors["z"].max() <= 3.0, errors["z"].max(axis=0)
    t = errors["time_s"]
    assert np.any(t > 18.0)  # published again after the height came back
    assert not np.any((t > 13.0) & (t < 17.0))  # withheld while the height was missing
    publisher = lockstep.service.session.publisher
    assert publisher.counters.by_health[NO_RANGE] > 0
    texts = [m.text for m in lockstep.link.sent if m.get_type() == "STATUSTEXT"]
    assert any("rangefinder" in text for text in texts), texts


def test_imu_and_attitude_outages_publish_nothing_beyond_three_sigma_and_name_the_input() -> None:
    """A 0.4 s IMU outage and a 0.4 s attitude outage on the circle: the IMU gap grows every
    position variance by (speed * gap)^2, the attitude outage withholds the position with
    ``stale_attitude`` health; nothing sent from the start of each outage to 1 s after it is
    beyond 3 sigma.

    (Further from the outages the paper's random-walk filter is itself at the edge: 2.95 sigma
    on the clean circle at 8.5 s, and 3.2 sigma 1.2 s after the IMU outage; that is the
    filter's consistency, issue 10's estimator, not the outage's covariance.)"""
    faults = FaultConfig(outages=(Outage("RAW_IMU", 6.0, 0.4), Outage("ATTITUDE", 9.0, 0.4)))
    lockstep = _fly(10.5, faults)
    errors = published_errors(lockstep)
    t = errors["time_s"]
    near = ((t >= 6.0) & (t <= 7.4)) | ((t >= 9.0) & (t <= 10.4))
    assert near.sum() > 25, near.sum()
    assert errors["z"][near].max() <= 3.0, errors["z"][near].max(axis=0)
    assert not np.any((t > 9.05) & (t < 9.4))  # withheld without attitude
    by_health = lockstep.service.session.publisher.counters.by_health
    assert by_health["stale_attitude"] > 0
    texts = [m.text for m in lockstep.link.sent if m.get_type() == "STATUSTEXT"]
    assert any("attitude stale" in text for text in texts), texts
