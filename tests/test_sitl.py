"""ArduCopter SITL (the real flight code) against ``tether-companion run`` over TCP.

SITL is a fixture beside the project (``../shared/ardupilot-sitl`` or ``TETHER_SITL_DIR``);
without it these tests skip and say why. The long flights are ``slow`` (docs/ardupilot.md).
"""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import Callable

import numpy as np
import pytest

from tether_companion.ardupilot_sitl.companion import (
    SITL_VEHICLE,
    CompanionProcess,
    companion_config,
)
from tether_companion.ardupilot_sitl.flights import GPS_LESS_PARAMS
from tether_companion.ardupilot_sitl.ground_station import GroundStation
from tether_companion.ardupilot_sitl.process import (
    SitlFailed,
    SitlOptions,
    SitlProcess,
    SitlUnavailable,
    find_sitl,
    ports_of,
)
from tether_companion.ardupilot_sitl.telemetry import EKF_FLAG_POS_HORIZ_ABS
from tether_companion.mavlink.geo import Geodetic
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.systemd import SystemdNotifier

pytestmark = [pytest.mark.integration, pytest.mark.sitl]

HOLD_WITHHELD = (
    "the default dynamic filter withholds SITL's steady hovers (measured by replaying the "
    "flight's .tlog, docs/ardupilot.md): at the taut hold (7.2 m out, 12-22 N) the thrust scale "
    "and the wind trade against the cable's pull and the horizontal std grows 0.6 -> 1.3 m "
    "(0.22-0.28 m were they known); above the anchor there is no horizontal pull. With "
    "on_unhealthy inflate EKF3 gets our position at 100 m^2 and drifts 0.9-1.5 m from the hold "
    "(the tether landing touched down 1.38 m from the anchor, bound 0.5 m)"
)
"""Why the flights' 0.3 m hold fails with the default filter (strict: passes once fixed)."""
KINDS = [
    pytest.param("four_state", id="four_state"),
    pytest.param(
        "dynamic", id="dynamic", marks=pytest.mark.xfail(strict=True, reason=HOLD_WITHHELD)
    ),
]
"""The paper's filter, which holds these flights, and the service's default."""
WINCH_TANGENTIAL = (
    "with the ground station's winch (WINCH_STATUS, the stiff tether's length) the range is "
    "known (sd 0.08 m) but not the bearing: at the taut hold the tangential sd is 0.4-0.5 m "
    "(the wind's drag on SITL's '+' quad, 0.63 N per m/s, trades against the cable's "
    "sideways pull; the filter invented ~1 m/s of wind in SITL's calm air), so the position "
    "is withheld (learning) 10-90 % of each 10 s and sent inflated; measured twice (winch10, "
    "5aa6af7 and 2a936c9): hold truth-to-target max 1.13 / 1.13 m, RMS 0.36 / 0.57 m (bound "
    "0.3 m), ours 0.33 / 0.57 m RMS off; in the second run the filter published 1.5 m off "
    "across the cable at a claimed 0.37 m at the switch (2.7 m/s of invented wind); the "
    "circle and the landing completed without failsafe"
)
"""Why the taut hold fails with the default filter and the winch (strict: passes once fixed)."""
ANGLE_RANGE = (
    "with the ground station's cable angle alone (DEBUG_VECT, 0.01 rad of noise per axis) the "
    "bearing is measured but the range only through the elevation and the rangefinder's "
    "height (at 34 degrees of elevation and 4 m of height 0.01 rad of elevation is 0.13 m of "
    "range): measured twice (angle10): hold truth-to-target max 0.373 / 0.572 m, RMS 0.174 / "
    "0.229 m (bound 0.3 m), ours 0.157 / 0.194 m RMS off, EKF3's test ratio at most 0.09 / "
    "0.17; the circle and the landing completed without failsafe. With the winch as well it "
    "holds (dynamic-winch-angle)"
)
"""Why the taut hold fails with the cable angle alone (strict: passes once fixed)."""
TAUT_KINDS = [
    *KINDS,
    pytest.param(
        "dynamic-winch",
        id="dynamic-winch",
        marks=pytest.mark.xfail(strict=True, reason=WINCH_TANGENTIAL),
    ),
    pytest.param(
        "dynamic-angle",
        id="dynamic-angle",
        marks=pytest.mark.xfail(strict=True, reason=ANGLE_RANGE),
    ),
    pytest.param("dynamic-winch-angle", id="dynamic-winch-angle"),  # 2 of 3 runs passed
    pytest.param("dynamic-winch-angle-errors", id="dynamic-winch-angle-errors"),
]
"""The taut hold also with the winch (the ground station sends WINCH_STATUS) and with its
cable-angle sensor (DEBUG_VECT, the direction from the anchor to SITL's truth); ``-errors``:
the two with the offline simulator's realistic errors (``GroundSensorConfig(enabled=True)``,
seed 1: the winch reads 0.148 m short and 1.7 % small, the elevation 0.0075 rad low), which the
filter's calibration states learn."""
ERRORS_HOLD_RMS_M = 0.1
"""Our estimate's RMS error in the external-navigation hold with the ground station's errors
[m]: measured 0.058 m learning the calibration, 0.158 m holding it (the same flight's .tlog
replayed with ``learn_calibration: false``; docs/estimation.md, sitlcal13)."""


@pytest.fixture
def sitl_available() -> None:
    try:
        find_sitl()
    except SitlUnavailable as exc:
        pytest.skip(str(exc))


def test_companion_gives_a_gps_less_ekf3_its_origin_and_position(sitl_available, tmp_path) -> None:
    """Start SITL without GPS, run the service as a user would: EKF3 takes our origin and
    fuses our VISION_POSITION_ESTIMATE (its own words), and the service stops cleanly."""
    options = SitlOptions(speedup=1.0, extra_params=GPS_LESS_PARAMS)
    with SitlProcess(options) as sitl:
        home = Geodetic(*options.home[:3])
        with GroundStation(sitl.ports["serial0"], home) as gcs:
            config = companion_config(
                tmp_path, options.home, {"publish": {"on_unhealthy": "inflate"}}
            )
            companion = CompanionProcess(config, sitl.ports["serial1"], tmp_path / "run.log")
            with companion:
                gcs.request_streams()
                texts = gcs.wait_for(
                    "EKF3 using external navigation",
                    lambda s: s["ekf_flags"] & EKF_FLAG_POS_HORIZ_ABS and s["forwarded_vision"] > 0,
                    timeout_s=60.0,
                )
                gcs.request_message(49)  # GPS_GLOBAL_ORIGIN
                snap = gcs.wait_for("GPS_GLOBAL_ORIGIN", lambda s: s["origin"] is not None, 10)
                assert companion.alive(), companion.output()
                exit_code = companion.stop()
            log = companion.output()
            autopilot_says = gcs.texts_since()
    assert texts["ekf_flags"] & EKF_FLAG_POS_HORIZ_ABS
    assert any("origin set" in t for t in autopilot_says), autopilot_says
    assert any("is using external nav data" in t for t in autopilot_says), autopilot_says
    origin = snap["origin"]
    assert origin.latitude == round(options.home[0] * 1e7)
    assert origin.longitude == round(options.home[1] * 1e7)
    assert abs(origin.altitude - options.home[2] * 1e3) <= 1
    assert exit_code == 0, log
    assert "Traceback" not in log, log
    assert list((tmp_path / "rec").glob("*.tlog")), "the service recorded nothing"


SITL_MASS_KG = 3.0
"""SIM_Frame's default model mass: the one value no ArduPilot parameter holds."""


async def _read_vehicle(
    service: CompanionService, timeout_s: float, heard: Callable[[], bool], heard_s: float
) -> float:
    """Run ``service`` until it has built its profile from the flight controller (or
    ``timeout_s`` [s] pass), then on until ``heard()`` (the ground station saw what it said)
    or ``heard_s`` [s] more pass: stopped at once, the service closed its TCP link within
    50 ms of the text and SITL forwarded the text in only 4 of 8 runs (bytes it had received
    but not parsed are evidently lost with the connection). Returns the wall time the profile
    took [s]."""
    stop = asyncio.Event()
    start = time.monotonic()
    task = asyncio.create_task(service.run(stop), name="service")
    try:
        while not service.vehicle.name.startswith("from-") and not task.done():
            if time.monotonic() - start > timeout_s:
                break
            await asyncio.sleep(0.05)
        took_s = time.monotonic() - start
        while not heard() and not task.done() and time.monotonic() - start < took_s + heard_s:
            await asyncio.sleep(0.05)
        return took_s
    finally:
        stop.set()
        await asyncio.wait_for(task, timeout=10.0)


def test_service_builds_the_vehicle_from_sitls_parameters(sitl_available) -> None:
    """``vehicle: from_autopilot`` against the real ArduCopter: the service reads SITL's
    parameters over TCP (PARAM_REQUEST_READ by name on SERIAL1) and builds the '+' quad that
    SITL's frame model flies, as configs/vehicles/ardupilot-sitl-plus.yaml writes it from
    SIM_Frame (mass 3 kg, hoverThrOut 0.39, expo 0.65, PWM 1000-2000, spin 0.15-0.95, motors 1
    right, 2 left, 3 front, 4 back), with ArduPilot's battery compensation of copter.parm."""
    options = SitlOptions(speedup=1.0)
    with SitlProcess(options) as sitl:
        with GroundStation(sitl.ports["serial0"], Geodetic(*options.home[:3])) as gcs:
            gcs.request_streams()  # ArduPilot routes a broadcast only to links it heard from
            overrides = {
                "vehicle": "from_autopilot",
                "autopilot_vehicle": {"mass_kg": SITL_MASS_KG},
                "link": {"connect": f"tcp:127.0.0.1:{sitl.ports['serial1']}"},
                "recording": {"enabled": False},
            }
            config = load_service_config(None, overrides)
            service = CompanionService(
                config, load_vehicle_for(config), notifier=SystemdNotifier({})
            )

            def said() -> bool:
                return any("from FC params" in t for t in gcs.companion_texts())

            took_s = asyncio.run(_read_vehicle(service, 30.0, said, heard_s=5.0))
            assert said(), (
                f"the companion's STATUSTEXT never reached the GCS: {gcs.companion_texts()}"
            )
    print(f"profile from SITL's parameters in {took_s:.2f} s")
    built, frame = service.vehicle, load_vehicle(SITL_VEHICLE)
    assert built.name == "from-ardupilot-quad-plus", (built.name, service.state.last_error)
    assert built.motors == frame.motors  # FRAME_CLASS 1, FRAME_TYPE 0: SIM_Frame's '+' order
    assert service.session.vehicle.n_motors == 4
    curve, truth = built.thrust_curve, frame.thrust_curve
    assert (curve.pwm_min_us, curve.pwm_max_us) == pytest.approx((1150.0, 1950.0), abs=1e-3)
    # the profile's coefficients are rounded to 1 mN; ArduPilot's floats to float32
    assert curve.coefficients_n == pytest.approx(truth.coefficients_n, abs=1e-3)
    pwm = np.linspace(1000.0, 2000.0, 41)
    assert curve.thrust_n(pwm) == pytest.approx(truth.thrust_n(pwm), abs=2e-3)
    hover_pwm = 1150.0 + 800.0 * 0.551  # the profile's hover point (its comment)
    assert float(curve.thrust_n(hover_pwm)) == pytest.approx(SITL_MASS_KG * 9.80665 / 4, rel=2e-3)
    battery = built.battery  # copter.parm: MOT_BAT_VOLT_MAX 12.8, MOT_BAT_VOLT_MIN 9.6
    assert (battery.voltage_max_v, battery.voltage_min_v) == pytest.approx((12.8, 9.6), rel=1e-6)
    assert took_s < 10.0


def test_a_port_in_use_fails_with_the_reason(sitl_available) -> None:
    """Asking for an instance whose SERIAL0 port is taken: SitlFailed naming the ports."""
    with socket.socket() as blocker:
        instance = 37
        blocker.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        blocker.bind(("0.0.0.0", ports_of(instance)["serial0"]))
        blocker.listen(1)
        start = time.monotonic()
        with pytest.raises(SitlFailed, match="in use"):
            SitlProcess(SitlOptions(instance=instance)).start()
        assert time.monotonic() - start < 5.0


def test_missing_binary_is_unavailable_with_the_path(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("TETHER_SITL_DIR", str(tmp_path))
    with pytest.raises(SitlUnavailable, match=str(tmp_path / "arducopter")):
        find_sitl()


def test_a_binary_that_dies_at_start_fails_with_its_output(tmp_path, monkeypatch) -> None:
    """A 'SITL' that exits at once: SitlFailed with its exit code and last words, no hang."""
    fake = tmp_path / "arducopter"
    fake.write_text("#!/bin/sh\necho 'PANIC: no frame model'\nexit 3\n")
    fake.chmod(0o755)
    for name in ("copter.parm", "tether.parm", "extnav.parm"):
        (tmp_path / name).write_text("")
    monkeypatch.setenv("TETHER_SITL_DIR", str(tmp_path))
    with pytest.raises(SitlFailed, match="exited with code 3.*PANIC: no frame model"):
        with SitlProcess(SitlOptions(start_timeout_s=10.0)):
            pass


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("kind", TAUT_KINDS)
def test_gps_to_external_navigation_switch_at_a_taut_hover(sitl_available, tmp_path, kind) -> None:
    """Issue 14's flight: take off on GPS, fly out until SITL's tether is taut, switch EKF3 to
    our position (source set 2), hold 60 s, fly a 1 m/s circle about the anchor, land. With the
    ground station's errors our estimate is also within ERRORS_HOLD_RMS_M in the hold.

    Bounds: no failsafe and EKF3 never without a horizontal position; during the hold the truth
    stays within 0.3 m of the target (the issue's bound) and EKF3 accepts our position (test
    ratio < 1). The circle's errors are printed (measured, not bounded: docs/ardupilot.md).
    About 4 minutes at speedup 1.
    """
    from tether_companion.ardupilot_sitl.flights import FlightOptions, gps_to_external_nav
    from tether_companion.sim.ground_sensors import GroundSensorConfig

    errors = kind.endswith("-errors")
    sensors = kind.removesuffix("-errors")
    winch = sensors.startswith("dynamic-winch")
    angle = sensors.endswith("-angle")
    overrides = {"estimator": {"kind": "dynamic" if kind.startswith("dynamic") else kind}}
    options = FlightOptions(
        workdir=tmp_path,
        companion_overrides=overrides,
        winch=winch,
        cable_angle=angle,
        ground_station=GroundSensorConfig(enabled=errors),
    )
    result = gps_to_external_nav(options, log=print)
    for phase in result.phases:
        print(phase)
    assert result.completed, result.stopped_at
    assert result.failsafes == [], result.failsafes
    hold = result.phase("extnav-hold")
    assert hold.duration_s >= 59.0
    assert hold.truth_to_target_max_m < 0.3
    assert hold.test_ratio_max < 1.0
    for phase in result.phases:
        assert phase.position_lost_samples == 0, phase
    circle = result.phase("extnav-circle")
    assert circle.test_ratio_max < 1.0
    if errors:
        assert hold.ours_error_rms_m < ERRORS_HOLD_RMS_M
    assert result.companion_exit == 0


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("kind", KINDS)
def test_gps_less_flight_from_the_ground_up(sitl_available, tmp_path, kind) -> None:
    """GPS1_TYPE 0: arm, take off above the anchor until SITL's line is taut, hold 60 s there
    and land, EKF3 on our position alone. Bounds: no failsafe, EKF3 never without a horizontal
    position, the hold within 0.3 m of the point above the anchor with test ratio < 1, and it
    lands and disarms (drifting: the line is slack below 6 m; the drift is printed). Flying out
    from there on our estimate alone is not reliable yet (docs/ardupilot.md) and not flown here.
    About 3 minutes at speedup 1."""
    from tether_companion.ardupilot_sitl.flights import FlightOptions, gps_less

    overrides = {"estimator": {"kind": kind}}
    result = gps_less(FlightOptions(workdir=tmp_path, companion_overrides=overrides), log=print)
    for phase in result.phases:
        print(phase)
    assert result.completed, result.stopped_at
    assert result.failsafes == [], result.failsafes
    hold = result.phase("hold-above")
    assert hold.duration_s >= 59.0
    assert hold.truth_to_target_max_m < 0.3
    assert hold.test_ratio_max < 1.0
    for phase in result.phases:
        assert phase.position_lost_samples == 0, phase
    assert result.companion_exit == 0


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize("kind", KINDS)
def test_gps_less_landing_by_reeling_the_tether_in(sitl_available, tmp_path, kind) -> None:
    """GPS1_TYPE 0, taut above the anchor, then the ground station switches the service's
    tension mode on (MAV_CMD_USER_2) and SITL's line is reeled in at 0.3 m/s: the mode feels
    the pull, follows it down and hands over to LAND near the ground; the drone disarms
    within 0.5 m of the anchor, with no failsafe and EKF3 never without a position."""
    from tether_companion.ardupilot_sitl.flights import FlightOptions, gps_less
    from tether_companion.ardupilot_sitl.ground_station import COPTER_MODES
    from tether_companion.ardupilot_sitl.scoring import TRACE_COLUMNS

    options = FlightOptions(
        workdir=tmp_path,
        hold_s=20.0,
        land_by_tether=True,
        companion_overrides={"estimator": {"kind": kind}},
    )
    result = gps_less(options, log=print)
    for phase in result.phases:
        print(phase)
    assert result.completed, result.stopped_at
    assert result.failsafes == [], result.failsafes
    landing = result.phase("tether-landing")
    assert landing.truth_to_target_max_m < 0.5  # horizontal distance from the anchor
    assert landing.position_lost_samples == 0
    modes = result.trace[:, TRACE_COLUMNS.index("mode")]
    assert COPTER_MODES["LAND"] in modes  # the service's hand-over: nobody else sent LAND
