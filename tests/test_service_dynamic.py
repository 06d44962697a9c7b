"""The dynamic filter (``estimator.kind: dynamic``) in the service: its status mapped onto the
published health, the inflate policy holding the last healthy position, and end to end over
UDP on 127.0.0.1 against the built-in emulator (velocity and covariance scored there)."""

from __future__ import annotations

import asyncio
import io

import numpy as np
import pytest
from lockstep_service import LockstepService
from rich.console import Console
from scenario_files import gusty_hover_takeoff_scenario
from test_service_emulator import _fly

from tether_companion.emulator.lockstep import build_controller
from tether_companion.estimation.dynamic import output
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.output import NavigationEstimate
from tether_companion.samples import AttitudeSample
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.emulator_process import EmulatorProcess
from tether_companion.service.health import (
    CONVERGING,
    DIVERGED,
    LEARNING,
    MOTORS_IDLE,
    OK,
    SHORT_CABLE,
    SLACK,
    WEAK_PULL,
    dynamic_health,
)
from tether_companion.service.publish import Publisher
from tether_companion.service.publish_config import PublishConfig
from tether_companion.service.session import EstimationSession
from tether_companion.service.status import render

FAR = np.array([3.0, 1.0, -2.0])
NEAR = np.array([0.3, 0.1, -0.4])


def _estimate(
    status: str = output.OK,
    position: np.ndarray = FAR,
    time_s: float = 1.0,
    reset_counter: int = 0,
    position_variance_m2: float = 0.01,
) -> NavigationEstimate:
    covariance = np.diag([position_variance_m2] * 3 + [0.01] * 3)
    return NavigationEstimate(
        time_s=time_s,
        position_ned_m=np.array(position, dtype=float),
        velocity_ned_mps=np.array([0.5, -0.2, 0.0]),
        position_velocity_covariance=covariance,
        tension_n=4.0,
        tension_variance_n2=0.04,
        reset_counter=reset_counter,
        status=status,
        reason="" if status == output.OK else "why",
        accel_fused=True,
        thrust_scale=1.0,
        accel_bias_body_mps2=np.zeros(3),
        wind_ne_mps=np.zeros(2),
        health_values=(),
    )


STATUS_CASES = [
    (output.OK, FAR, False, None),
    (output.OK, FAR, True, SHORT_CABLE),
    (output.STALE_INPUTS, FAR, False, None),
    (output.INITIALISING, FAR, False, CONVERGING),
    (output.LEARNING, FAR, False, LEARNING),
    (output.LEARNING, NEAR, False, SHORT_CABLE),
    (output.WEAK_PULL, FAR, False, WEAK_PULL),
    (output.WEAK_PULL, NEAR, False, SHORT_CABLE),
    (output.SLACK, FAR, False, SLACK),
    (output.SLACK, NEAR, False, SHORT_CABLE),
    (output.ON_GROUND, FAR, False, MOTORS_IDLE),
    (output.RESET, FAR, False, DIVERGED),
]


@pytest.mark.parametrize(("status", "position", "near_anchor", "health"), STATUS_CASES)
def test_a_filter_status_maps_onto_a_published_health(status, position, near_anchor, health):
    assert dynamic_health(_estimate(status, position), 1.0, near_anchor) == health


def test_every_filter_status_has_a_case() -> None:
    assert set(output.STATUSES) == {case[0] for case in STATUS_CASES}


def _attitude(t: float) -> AttitudeSample:
    return AttitudeSample(t, 0.0, 0.0, 0.0)


def test_inflate_holds_the_last_healthy_position_and_a_reset_raises_reset_counter() -> None:
    """``on_unhealthy: inflate`` sends the last position published healthy (not the drifting
    unobservable one) with the inflated variance and no velocity; the filter's restart
    (its reset_counter) raises the published reset_counter; nothing non-finite is sent. The
    health comes from the filter's status as the session maps it."""
    config = PublishConfig(
        on_unhealthy="inflate", settle_s=0.0, odometry=True, speed_estimate=True, rate_hz=10.0
    )
    publisher = Publisher(config, has_tension_state=True)
    sent = []
    t = 0.0
    for k in range(5):  # healthy at 10 Hz
        t = 0.1 * k
        messages, pub = publisher.on_estimate(_estimate(time_s=t), _attitude(t))
        sent += messages
        assert pub is not None and pub.health == OK
    speeds = [m for m in sent if m.get_type() == "VISION_SPEED_ESTIMATE"]
    assert len(speeds) == 5 and speeds[-1].x == pytest.approx(0.5)
    odometry = [m for m in sent if m.get_type() == "ODOMETRY"]
    assert np.isfinite(odometry[-1].vx) and np.isfinite(odometry[-1].velocity_covariance[0])
    drifted = FAR + np.array([5.0, -4.0, 0.0])
    t += 0.1
    weak = _estimate(output.WEAK_PULL, drifted, t, position_variance_m2=30.0)
    messages, pub = publisher.on_estimate(
        weak, _attitude(t), unavailable=dynamic_health(weak, 1.0, False)
    )
    vision = next(m for m in messages if m.get_type() == "VISION_POSITION_ESTIMATE")
    np.testing.assert_allclose([vision.x, vision.y, vision.z], FAR, atol=1e-6)
    assert vision.covariance[0] == pytest.approx(config.inflated_variance_m2)
    assert not any(m.get_type() == "VISION_SPEED_ESTIMATE" for m in messages)
    assert pub is not None and pub.health == WEAK_PULL
    assert publisher.counters.inflated == 1
    before = publisher.reset_counter
    t += 0.1
    reset = _estimate(output.RESET, np.zeros(3), t, reset_counter=1, position_variance_m2=1e6)
    messages, pub = publisher.on_estimate(
        reset, _attitude(t), unavailable=dynamic_health(reset, 1.0, False)
    )
    assert publisher.reset_counter == (before + 1) & 0xFF
    assert publisher.health == DIVERGED
    for message in messages:
        if message.get_type() == "VISION_POSITION_ESTIMATE":
            assert np.all(np.isfinite([message.x, message.y, message.z]))
            assert np.all(np.isfinite(message.covariance))


def test_the_session_runs_the_dynamic_filter_with_the_configured_section() -> None:
    config = load_service_config(
        None,
        {
            "estimator": {"kind": "dynamic", "ground_station": {"anchor_height_m": 1.0}},
            "dynamic_filter": {"accel_noise_std_mps2": 0.2},
        },
    )
    session = EstimationSession(config, load_vehicle_for(config))
    estimator = session.estimator
    assert isinstance(estimator, DynamicTetherEstimator)
    assert estimator.dynamic.accel_noise_std_mps2 == 0.2
    assert estimator.config.ground_station.anchor_height_m == 1.0  # the one anchor-height key
    assert estimator.aligner is session.aligner  # one alignment with the tension filter
    session.restart()
    assert isinstance(session.estimator, DynamicTetherEstimator)


def _score_line(score: dict) -> str:
    """The emulator's score in one line: position and velocity accuracy and consistency."""
    nan = float("nan")
    r = {k: nan if v is None else v for k, v in score["rmse_m"].items()}
    v = score["velocity_rmse_m_s"] or {"3d": nan}
    score = {k: nan if value is None else value for k, value in score.items()}
    return (
        f"received {score['received']}; RMSE N/E/D {r['north']:.3f}/{r['east']:.3f}/"
        f"{r['down']:.3f} m, horizontal {r['horizontal']:.3f} m; beyond 3 sigma "
        f"{score['beyond_3_sigma']} of {score['with_covariance']}, NEES {score['nees_mean']:.2f};"
        f" velocity RMSE 3-D {v['3d']:.3f} m/s, beyond 3 sigma "
        f"{score['velocity_beyond_3_sigma']} of {score['velocity_with_covariance']}, NEES "
        f"{score['velocity_nees_mean']:.2f}"
    )


DYNAMIC_OVERRIDES = {
    "estimator": {"kind": "dynamic"},
    "publish": {"odometry": True, "speed_estimate": True},
    "recording": {"enabled": False},
    "streams": {"rangefinder_hz": 200.0},  # the paper circle's ultrasound rate
}


@pytest.mark.integration
def test_dynamic_filter_over_udp_on_the_paper_circle(tmp_path) -> None:
    """The emulator (its own process, real time) flies the paper's circle (4 N) for 30 s;
    the service runs the dynamic filter. It withholds while the thrust scale is not yet
    learned (``learning``, named in STATUSTEXT), then publishes VISION_POSITION_ESTIMATE,
    ODOMETRY with velocity and VISION_SPEED_ESTIMATE, each with its covariance, all scored by
    the emulator against its truth. Measured (seed 1, filter of adc8176): horizontal RMSE
    0.100 m, velocity 0.033 m/s 3-D, position NEES mean 0.79, none beyond 3 sigma.

    Real time, not faster: on this 2-core machine under load, at 2x the starved service lost
    1.6-2.7 s of IMU at a time from its socket, and each gap restarts the filter."""
    emulator = EmulatorProcess(
        "paper-circle", duration_s=30.0, score_path=tmp_path / "score.json", speed=1.0
    )
    service = asyncio.run(_fly(emulator, DYNAMIC_OVERRIDES))
    score = emulator.score()
    print(_score_line(score))  # the numbers the docs quote (pytest -s)
    publisher = service.session.publisher
    assert isinstance(service.session.estimator, DynamicTetherEstimator)
    assert publisher.counters.by_health[LEARNING] > 0  # withheld before it could know
    assert service.state.sent_by_type.get("STATUSTEXT", 0) >= 2  # the health changes said
    status = io.StringIO()
    Console(file=status, width=140).print(render(service))
    assert "velocity [m/s]" in status.getvalue()  # --status shows the filter's velocity
    assert score["invalid"] == 0 and score["unmatched"] == 0
    received = score["received"]
    # >= 1 s of 30 Hz after converging (~16 s in lock-step; on this loaded machine an IMU gap
    # can restart the filter and cost ~15 s more)
    assert received["VISION_POSITION_ESTIMATE"] >= 30
    # one of each per publication; the flight's end may fall between the two of the last one
    # (measured once under load: ODOMETRY 595, VISION_POSITION_ESTIMATE 596)
    assert abs(received["ODOMETRY"] - received["VISION_POSITION_ESTIMATE"]) <= 1
    # Horizontal RMSE over 4 alternated runs at load 8 (23:20 UTC, 2026-11-25), main b3d5450
    # and dc72492 alike: 0.054-0.208 m, NEES 0.11-0.33. Under load the socket's jitter moves
    # the first publication earlier or later, and the first seconds after learning carry the
    # larger errors (honestly: none beyond 3 sigma), so the bound leaves room for them.
    assert score["rmse_m"]["horizontal"] < 0.3 and score["rmse_m"]["down"] < 0.1
    assert score["velocity_scored"] >= 2 * received["ODOMETRY"] - 2  # ODOMETRY + SPEED
    assert score["velocity_rmse_m_s"]["3d"] < 0.1
    assert score["with_covariance"] == score["scored"]
    assert score["beyond_3_sigma"] == 0 and score["nees_mean"] < 3.0
    assert score["velocity_with_covariance"] == score["velocity_scored"]
    assert score["velocity_beyond_3_sigma"] == 0


EIGHT_FAULTS = (
    *("--drop", "0.01", "--duplicate", "0.01", "--corrupt", "0.01"),
    *("--delay-ms", "20", "--jitter-ms", "3"),
    *("--outage", "RAW_IMU:24:0.4", "--outage", "ATTITUDE:27:0.4"),
    *("--range-out", "29:2", "--reboot-at", "34"),
)
"""The emulator's eight faults: frames dropped, duplicated, corrupted, delayed, jittered; an
IMU and an attitude outage; the rangefinder out of range; a flight-controller reboot (the
drone falls and lies on the ground)."""


@pytest.mark.slow
@pytest.mark.integration
def test_eight_faults_publish_within_three_sigma_as_often_as_an_honest_filter(tmp_path):
    """The dynamic filter on the paper circle over UDP (real time, 40 s) with every fault the
    emulator has: what the flight controller receives is never non-finite, and is beyond 3
    standard deviations of its own covariance on some axis no more often than an honest
    Gaussian estimate is (scored by the emulator against its truth); the faults are seen.

    Why not "never beyond 3 sigma": for an honest 3-D Gaussian error, 0.8 % of estimates have
    some axis beyond 3 sigma (1 - 0.9973^3), so none among ~1000 only a covariance inflated
    well beyond the error can promise. Measured: 14 of 962 (1.5 %) over UDP; 4 of 513 (0.8 %,
    max 3.15 sigma) in lock-step with the flight controller's faults only, all four on the
    down axis 1.0-1.3 s after the 0.4 s IMU outage (the filter's down variance recovers faster
    than its error after an IMU gap). A second UDP run: 0 of 656, NEES 1.65 (filter of f14b592,
    faults 6 s earlier). With adc8176's filter (converging later, so the faults moved later):
    0 of 94, NEES 2.39.

    Estimates stamped in the old boot's time base that arrive after the reboot cannot be
    matched to the truth by the emulator (``unmatched``: 300 in that run) and are not
    scored."""
    emulator = EmulatorProcess(
        "paper-circle",
        duration_s=40.0,
        score_path=tmp_path / "score.json",
        speed=1.0,
        extra_args=EIGHT_FAULTS,
    )
    service = asyncio.run(_fly(emulator, DYNAMIC_OVERRIDES))
    score = emulator.score()
    print(_score_line(score))
    counters = service.session.ingest.counters
    publisher = service.session.publisher
    assert counters.reboots == 1 and counters.duplicate > 0
    assert publisher.counters.by_health[MOTORS_IDLE] > 0  # on the ground after the reboot
    # (estimates stamped in the old boot's time base that arrive after the reboot are
    # unmatched: the emulator cannot score them)
    assert score["invalid"] == 0, score
    assert score["scored"] >= 30 and score["with_covariance"] == score["scored"], score
    assert score["beyond_3_sigma"] <= 0.02 * score["scored"], score
    assert score["nees_mean"] <= 3.0, score
    # velocity: looser, as measured (two runs: 0 and 18 of 656 beyond 3 sigma, NEES mean
    # 3.08 in the second); its tails after the faults are heavier than the position's
    assert score["velocity_beyond_3_sigma"] <= 0.05 * score["velocity_scored"], score
    assert score["velocity_nees_mean"] <= 6.0, score


HOLD_S = 60.0
SETTLE_S = 5.0
LATEST_START_S = 40.0


def _closed_loop_hover(
    tmp_path,
    seed: int,
    winch: bool = False,
    cable_angle: bool = False,
    ground_station: bool = False,
    vehicle: str = "default-quad",
) -> dict:
    """Take off into the gusty hover (the emulator's navigation on its truth until our first
    estimate, as a pilot would climb in ALT_HOLD), then fly on nothing but the published
    estimate: the deviation from the hover point over ``HOLD_S`` after ``SETTLE_S``. With
    ``winch`` the emulator's ground station sends WINCH_STATUS (10 Hz), with ``cable_angle``
    the cable's direction at the anchor (DEBUG_VECT, 10 Hz, 0.01 rad per axis), and the
    service reads them; with ``ground_station`` they have the realistic scenarios' errors
    (the encoder's scale, offset, latency and steps, the angle's biases, latency and steps:
    sim/ground_sensors.py), else the exact length and the angle's white noise only;
    ``vehicle`` the profile flown (and given to the service)."""
    path = gusty_hover_takeoff_scenario(
        tmp_path, LATEST_START_S + SETTLE_S + HOLD_S, seed, ground_station, vehicle
    )
    emulator: dict = {"navigation": "vision"}
    overrides: dict = {"estimator": {"kind": "dynamic"}}
    if winch:
        emulator["winch"] = overrides["winch"] = {"enabled": True}
    if cable_angle:
        emulator["cable_angle"] = overrides["cable_angle"] = {"enabled": True}
    controller = build_controller(str(path), emulator=emulator)
    lockstep = LockstepService(controller, overrides)
    target = np.array(controller.scenario.trajectory.position_ned_m)
    start_s = None
    deviations = []
    while controller.time_s < controller.scenario.duration_s:
        lockstep.advance()
        lockstep.serve()
        if start_s is None and controller.nav.counters.used > 0:
            start_s = controller.time_s
        if start_s is None and controller.time_s > LATEST_START_S:
            break
        if start_s is not None:
            since = controller.time_s - start_s
            if since >= SETTLE_S + HOLD_S:
                break
            if since >= SETTLE_S:
                deviations.append(float(np.linalg.norm(controller.sim.body.x[:3] - target)))
    return {
        "start_s": start_s,
        "max_m": max(deviations, default=float("inf")),
        "mode": controller.mode.name,
        "armed": controller.armed,
        "used": controller.nav.counters.used,
    }


IMU_ONLY_XFAIL = pytest.mark.xfail(
    strict=True,
    reason="issue 10 target not met IMU-only (docs/estimation.md, 'In the service'): a steady "
    "hover does not observe the range (thrust scale and wind); default dynamic_filter on "
    "main e4eaf76, seeds 1-5: 1, 3, 4 never publish in 40 s, 2 and 5 publish from 3.0 and "
    "8.5 s, withhold, and the autopilot lands in its failsafe 2.88 and 2.83 m off",
)


REALISTIC_WINCH_XFAIL = pytest.mark.xfail(
    strict=True,
    reason="the winch alone with the realistic encoder (1 % scale, 0.1 m offset per flight, "
    "0.1 s late, 1 cm steps): seed 1 holds within 0.33 m "
    "(docs/estimation-history.md, 'groundsim10')",
)
REALISTIC_ANGLE_XFAIL = pytest.mark.xfail(
    strict=True,
    reason="the angle alone with the realistic sensor (1.5 deg azimuth and 0.4 deg elevation "
    "biases per flight, 0.05 s late, 12-bit): seeds 3 and 5 hold within 0.35 and 0.32 m "
    "(docs/estimation-history.md, 'groundsim10')",
)
DRAG_WINCH_XFAIL = pytest.mark.xfail(
    strict=True,
    reason="the winch alone on a quad with drag never publishes in the gusty hover (seeds 1-5, "
    "lead 2026-11-28): the length fixes the range, and the bearing comes from the horizontal "
    "force, which the gusts' drag on an unknown wind shares with the cable's pull; the "
    "filter withholds (the scorecard's realistic-gusty-hover winch alone: 0 % published)",
)
DRAG = "realistic-quad"
"""A quad with drag (rotor drag 0.2 1/s, body drag 17 kg/m^2, as ArduPilot's SITL quad)."""


@pytest.mark.slow
@pytest.mark.integration
@pytest.mark.parametrize(
    ("winch", "cable_angle", "ground_station", "vehicle"),
    [
        pytest.param(False, False, False, "default-quad", marks=IMU_ONLY_XFAIL, id="imu-only"),
        pytest.param(True, False, False, "default-quad", id="winch"),
        pytest.param(False, True, False, "default-quad", id="cable-angle"),
        pytest.param(True, True, False, "default-quad", id="winch-cable-angle"),
        pytest.param(
            True, False, True, "default-quad", marks=REALISTIC_WINCH_XFAIL, id="winch-realistic"
        ),
        pytest.param(
            False, True, True, "default-quad", marks=REALISTIC_ANGLE_XFAIL,
            id="cable-angle-realistic",
        ),  # fmt: skip
        pytest.param(True, True, True, "default-quad", id="winch-cable-angle-realistic"),
        pytest.param(True, False, False, DRAG, marks=DRAG_WINCH_XFAIL, id="winch-drag"),
        pytest.param(False, True, False, DRAG, id="cable-angle-drag"),
        pytest.param(True, True, False, DRAG, id="winch-cable-angle-drag"),
        pytest.param(True, True, True, DRAG, id="winch-cable-angle-realistic-drag"),
    ],
)
def test_closed_loop_gusty_hover_on_the_dynamic_filter_holds_within_0_3_m(
    tmp_path, winch: bool, cable_angle: bool, ground_station: bool, vehicle: str
) -> None:
    """Issue 10: the emulator's navigation flying on the published estimate holds a 60 s
    gusty hover within 0.3 m, 5 seeds, in lock-step (deterministic; real MAVLink frames):
    with the ground station's winch length, its cable angle, or both (met), IMU-only (not
    met: strict xfail). The angle alone is close to the bound: 0.22-0.27 m here, and on the
    held-out seeds 6-10 0.24-0.38 m (7, 8 and 10 beyond 0.3 m; docs/estimation.md). With
    the ground station's realistic errors (``ground_station``: the offline simulator's
    calibration, latency and steps) the winch and the angle together still hold it (0.11-0.27
    m); either alone does not on every seed (strict xfails). default-quad has no drag, so
    its gusts move only the cable; ``-drag`` flies realistic-quad (:data:`DRAG`), whose gusts
    push the drone: the angle, alone or with the winch, holds it; the winch alone withholds."""
    results = {
        seed: _closed_loop_hover(tmp_path, seed, winch, cable_angle, ground_station, vehicle)
        for seed in range(1, 6)
    }
    for seed, result in results.items():
        print(f"seed {seed}: {result}")  # the numbers the docs quote (pytest -s)
    for seed, result in results.items():
        assert result["start_s"] is not None, (seed, result)
        assert result["mode"] == "AUTO" and result["armed"], (seed, result)
        assert result["max_m"] <= 0.3, (seed, result)

