"""Flights of ArduCopter SITL with ``tether-companion run`` in the loop, scored against
SITL's truth (SIM_STATE).

``gps_to_external_nav``: take off on GPS, fly out until SITL's tether is taut, switch EKF3 to
source set 2 (external navigation = our VISION_POSITION_ESTIMATE) and hold in GUIDED, fly a
slow circle around the anchor, land. ``gps_less``: no GPS at all (GPS1_TYPE 0, source set 1 =
external navigation): arm, take off, hold and land on our estimate alone.

Every phase records the truth against its target (what the drone did), EKF3's own position
against the truth (what the autopilot believed), our VISION_POSITION_ESTIMATE against the
truth (what we told it) and EKF3's horizontal position innovation test ratio
(EKF_STATUS_REPORT.pos_horiz_variance); failsafes are what the autopilot says (STATUSTEXT) and
any mode change nobody commanded. The scoring itself is :mod:`.scoring`.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tether_companion.ardupilot_sitl.companion import CompanionProcess, companion_config
from tether_companion.ardupilot_sitl.ground_station import COPTER_MODES, FlightError, GroundStation
from tether_companion.ardupilot_sitl.process import SitlOptions, SitlProcess
from tether_companion.ardupilot_sitl.scoring import (
    FlightResult,
    score_phase,
    settle_time,
    trace_of,
)
from tether_companion.ardupilot_sitl.telemetry import EKF_FLAG_POS_HORIZ_ABS, Sample
from tether_companion.mavlink.geo import Geodetic
from tether_companion.sim.ground_sensors import GroundSensorConfig

GPS_LESS_PARAMS = {
    "GPS1_TYPE": 0,
    "EK3_SRC1_POSXY": 6,
    "EK3_SRC1_VELXY": 0,
    "EK3_SRC1_POSZ": 1,
    "EK3_SRC1_VELZ": 0,
    "EK3_SRC1_YAW": 1,
    "WPNAV_SPEED": 50,
    "COMPASS_AUTODEC": 0,
    "COMPASS_DEC": 0.22336,
}
"""Source set 1 = external navigation and no GPS (the note in extnav.parm), and GUIDED's
position moves at 0.5 m/s (WPNAV_SPEED [cm/s]; default 10 m/s): our estimate lags about 1 s
in motion, and flying out at the default speed on it the loop oscillated until the line went
slack (two runs of three, docs/ardupilot.md). The magnetic declination is set by hand
(COMPASS_DEC [rad], 12.80 deg: what ArduPilot's own tables give at SITL's home, read back from
a GPS run): without a GPS fix ArduPilot never looks it up, EKF3's heading is then off by the
declination, and our position, which takes its heading from the autopilot's attitude, turns
about the anchor by as much (measured: 13-17 deg, 2.5 m at 7 m)."""
FAILSAFE_WORDS = re.compile(r"failsafe|variance|stopped aiding|lost|emergency|crash", re.I)
"""STATUSTEXT words that mean the autopilot gave up on something (checked case-insensitively)."""


@dataclass
class FlightOptions:
    """What to fly."""

    speedup: float = 1.0
    """SIM_SPEEDUP during the flight (the pre-flight wait runs at ``boot_speedup``)."""
    boot_speedup: float = 4.0
    hold_s: float = 60.0
    """Autopilot seconds held at the target after the source switch."""
    target_ned_m: tuple[float, float, float] = (6.0, 0.0, -4.0)
    """Hold point from the anchor: 7.2 m away; SITL's 6 m line (tether.parm, 8 N/m) stretched
    1.2 m: ~12 N of tension, so a 0.5 m error towards the anchor does not slacken it."""
    circle_speed_mps: float = 1.0
    circle_laps: float = 1.0
    land: bool = True
    land_source_set: int = 1
    """EKF3 source set while landing: 1 (GPS: SITL's tether is a fixed 6 m line, slack below
    6 m from the anchor, where the pull no longer tells the position) or 2 (ours)."""
    gps_less_fly_out: bool = False
    """GPS-less flight: after the hold above the anchor, fly out to ``target_ned_m`` on our
    estimate alone and hold there (not reliable yet: docs/ardupilot.md)."""
    land_by_tether: bool = False
    """GPS-less flight: land by reeling SITL's tether in (SIM_TETH_LINELEN shortened at
    ``reel_in_mps``) with the service's tension-following mode switched on from the ground
    station after the hold (MAV_CMD_USER_2), instead of LAND."""
    reel_in_mps: float = 0.3
    winch: bool = False
    """The ground station is also the tether's winch: WINCH_STATUS
    (:meth:`GroundStation.start_ground_sensors`) and the companion reads it
    (``winch.enabled``)."""
    cable_angle: bool = False
    """The ground station has a cable-angle sensor at the anchor: DEBUG_VECT
    (:meth:`GroundStation.start_ground_sensors`) and the companion reads it
    (``cable_angle.enabled``)."""
    ground_station: GroundSensorConfig = field(default_factory=GroundSensorConfig)
    """The winch's and the angle sensor's rates and errors (a scenario's ``ground_station``
    section; the default: off, 10 Hz, the exact length, 0.01 rad of white angle noise)."""
    ground_station_seed: int = 1
    """Seeds the sensors' calibration draws and noise."""
    companion_overrides: dict = field(default_factory=dict)
    workdir: Path | None = None
    """Kept after the flight when given (SITL's logs, the companion's config, log and .tlog)."""


def _fixed(point: np.ndarray) -> Callable[[float, np.ndarray], np.ndarray]:
    return lambda _t, _truth: point


class _Flight:
    """Shared steps; ``log`` gets one line per step."""

    def __init__(self, gcs: GroundStation, options: FlightOptions, log: Callable[[str], None]):
        self.gcs = gcs
        self.options = options
        self.log = log
        self.commanded_modes: list[int] = []

    def mode(self, name: str) -> None:
        self.commanded_modes.append(COPTER_MODES[name])
        self.gcs.set_mode(name)

    def wait(self, seconds: float) -> None:
        self.gcs.wait_fc_time(seconds, self.options.speedup)

    def wait_truth(self, what: str, predicate: Callable[[np.ndarray], bool], fc_s: float) -> None:
        self.gcs.wait_for(
            what,
            lambda s: s["truth_ned_m"] is not None and predicate(s["truth_ned_m"]),
            timeout_s=10.0 + 3.0 * fc_s / self.options.speedup,
        )

    def fc_now(self) -> float:
        return self.gcs.snapshot()["fc_s"]

    def fly_to(self, target: np.ndarray, within_m: float = 0.5, fc_s: float = 30.0) -> None:
        self.gcs.go_to(tuple(target))
        self.wait_truth(
            f"reach {np.round(target, 2).tolist()}",
            lambda p: float(np.linalg.norm(p - target)) < within_m,
            fc_s,
        )

    def hold(self, name: str, point: np.ndarray, seconds: float, result: FlightResult) -> None:
        """Hold at ``point`` (already commanded): 10 s to settle, then ``seconds`` scored."""
        self.wait(10.0)
        start = self.fc_now()
        self.wait(seconds)
        samples = self.gcs.samples_between(start, self.fc_now())
        result.phases.append(score_phase(name, samples, _fixed(point)))

    def circle(self, centre: np.ndarray, radius_m: float, height_d_m: float) -> tuple[float, float]:
        """One or more laps at circle_speed_mps by GUIDED targets at 10 Hz autopilot time;
        returns (start, end) autopilot time."""
        opts = self.options
        omega = opts.circle_speed_mps / radius_m
        duration = opts.circle_laps * 2.0 * math.pi / omega
        start = self.fc_now()
        while (now := self.fc_now()) < start + duration:
            angle = omega * (now - start)
            point = (
                centre[0] + radius_m * math.cos(angle),
                centre[1] + radius_m * math.sin(angle),
                height_d_m,
            )
            self.gcs.go_to(point)
            time.sleep(0.1 / opts.speedup)
        return start, self.fc_now()

    def unexpected_modes(self, samples: list[Sample]) -> list[str]:
        allowed = set(self.commanded_modes)
        names = {v: k for k, v in COPTER_MODES.items()}
        seen = sorted({s.mode for s in samples if s.armed and s.mode not in allowed})
        return [f"mode {names.get(m, m)} entered without a command" for m in seen]


BOOT_FC_S = 40.0
"""Autopilot seconds to let pass before arming (its INS consistency checks take ~30 s)."""


def gps_to_external_nav(options: FlightOptions, log: Callable[[str], None] = print) -> FlightResult:
    """Take off on GPS, fly out until the tether is taut, switch to external navigation, hold,
    circle, land (see the module docstring)."""

    def ready(snap: dict, gcs: GroundStation) -> bool:
        gps = any("using GPS" in t for t in gcs.texts_since())
        return bool(snap["ekf_flags"] & EKF_FLAG_POS_HORIZ_ABS) and gps

    return _run("gps-to-external-nav", {}, ready, _fly_gps_to_external_nav, options, log)


def gps_less(options: FlightOptions, log: Callable[[str], None] = print) -> FlightResult:
    """No GPS at all: arm, take off above the anchor until the line is taut, fly out to the
    target, hold, circle and land on our estimate alone."""

    def ready(snap: dict, gcs: GroundStation) -> bool:
        return any("initial yaw alignment complete" in t for t in gcs.texts_since())

    name = "gps-less-tether-landing" if options.land_by_tether else "gps-less"
    return _run(name, GPS_LESS_PARAMS, ready, _fly_gps_less, options, log)


def _run(
    name: str,
    params: dict[str, float],
    ready: Callable[[dict, GroundStation], bool],
    fly: Callable[[_Flight, FlightResult], None],
    options: FlightOptions,
    log: Callable[[str], None],
) -> FlightResult:
    """SITL with ``params``, a ground station, boot at ``boot_speedup`` until ``ready``, then
    the companion and ``fly`` at ``speedup``; everything stopped on the way out."""
    result = FlightResult(name)
    sitl_opts = SitlOptions(
        speedup=options.boot_speedup, extra_params=params, keep_dir=options.workdir is not None
    )
    with SitlProcess(sitl_opts) as sitl:
        workdir = options.workdir or sitl.workdir
        assert workdir is not None
        workdir.mkdir(parents=True, exist_ok=True)
        home = Geodetic(*sitl_opts.home[:3])
        with GroundStation(sitl.ports["serial0"], home) as gcs:
            flight = _Flight(gcs, options, log)
            gcs.request_streams()
            gcs.wait_for(
                "autopilot ready",
                lambda s: s["fc_s"] >= BOOT_FC_S and ready(s, gcs),
                timeout_s=10.0 + 3.0 * BOOT_FC_S / options.boot_speedup + 60.0,
            )
            gcs.set_param("SIM_SPEEDUP", options.speedup)
            overrides = {"publish": {"on_unhealthy": "inflate"}, **options.companion_overrides}
            if options.winch or options.cable_angle:
                gcs.start_ground_sensors(
                    options.ground_station,
                    options.ground_station_seed,
                    winch_line_length_m=TETHER_LINE_LENGTH_M if options.winch else None,
                    cable_angle=options.cable_angle,
                )
            if options.winch:
                overrides["winch"] = {"enabled": True}
            if options.cable_angle:
                overrides["cable_angle"] = {"enabled": True}
            config = companion_config(workdir, sitl_opts.home, overrides)
            companion = CompanionProcess(config, sitl.ports["serial1"], workdir / "companion.log")
            with companion:
                try:
                    fly(flight, result)
                    result.completed = True
                except FlightError as exc:
                    result.stopped_at = str(exc)
                    log(f"stopped: {exc}")
                result.companion_exit = companion.stop()
            result.autopilot_texts = gcs.texts_since()
            result.companion_texts = gcs.companion_texts()
            with gcs.telemetry.lock:
                all_samples = list(gcs.telemetry.samples)
            result.trace = trace_of(all_samples)
            result.failsafes = [t for t in result.autopilot_texts if FAILSAFE_WORDS.search(t)]
            result.failsafes += flight.unexpected_modes(all_samples)
    return result


def _fly_gps_to_external_nav(flight: _Flight, result: FlightResult) -> None:
    gcs, opts, log = flight.gcs, flight.options, flight.log
    target = np.array(opts.target_ned_m, dtype=float)
    flight.mode("GUIDED")
    gcs.arm(timeout_s=90.0)
    log("armed on GPS")
    gcs.takeoff(-target[2])
    flight.wait_truth("take-off", lambda p: p[2] < target[2] + 0.5, fc_s=30.0)
    log("airborne")
    flight.fly_to(target, fc_s=40.0)
    flight.wait(10.0)  # the tension estimate and the EKF settle on the taut line
    start = flight.fc_now()
    flight.wait(10.0)
    result.phases.append(
        score_phase("gps-hold", gcs.samples_between(start, flight.fc_now()), _fixed(target))
    )
    log("taut hover on GPS; switching EKF3 to source set 2 (external navigation)")
    ack = gcs.set_ekf_source_set(2)
    if ack != 0:
        raise FlightError(f"MAV_CMD_SET_EKF_SOURCE_SET 2 refused (MAV_RESULT {ack})")
    switch = flight.fc_now()
    flight.wait(opts.hold_s)
    hold = gcs.samples_between(switch, flight.fc_now())
    result.phases.append(score_phase("extnav-hold", hold, _fixed(target)))
    result.settle_s = settle_time(hold, target, switch)
    log(f"held {opts.hold_s:g} s on external navigation")
    radius = float(np.hypot(target[0], target[1]))
    if opts.circle_laps > 0:
        # the circle about the anchor starts where the hold is (angle 0 = north of it)
        start, end = flight.circle(np.zeros(2), radius, target[2])

        def on_circle(_t: float, truth: np.ndarray) -> np.ndarray:
            """The circle's point on the drone's bearing from the anchor: the path error."""
            bearing = math.atan2(truth[1], truth[0])
            return np.array([radius * math.cos(bearing), radius * math.sin(bearing), target[2]])

        result.phases.append(
            score_phase("extnav-circle", gcs.samples_between(start, end), on_circle)
        )
        log("circle flown on external navigation")
        flight.fly_to(target, fc_s=30.0)
    if opts.land:
        if opts.land_source_set != 2:
            gcs.set_ekf_source_set(opts.land_source_set)
            flight.wait(5.0)
        start = flight.fc_now()
        flight.mode("LAND")
        gcs.wait_for("landed and disarmed", lambda s: not s["armed"], 10.0 + 90.0 / opts.speedup)
        landed = gcs.samples_between(start, flight.fc_now())
        name = "extnav-land" if opts.land_source_set == 2 else "gps-land"
        result.phases.append(
            score_phase(name, landed, _fixed(np.array([target[0], target[1], 0.0])))
        )
        log("landed")


def _fly_gps_less(flight: _Flight, result: FlightResult) -> None:
    """Take off above the anchor until the line is taut, hold there (and, with
    ``gps_less_fly_out``, fly out to the target and hold there), then land by LAND or by the
    tether."""
    gcs, opts, log = flight.gcs, flight.options, flight.log
    target = np.array(opts.target_ned_m, dtype=float)
    radius = float(np.linalg.norm(target))
    above = np.array([0.0, 0.0, -radius])
    flight.mode("GUIDED")
    gcs.arm(timeout_s=90.0)
    log("armed without GPS")
    gcs.takeoff(radius)
    flight.wait_truth("take-off above the anchor", lambda p: p[2] < above[2] + 0.5, fc_s=40.0)
    log("taut above the anchor")
    flight.hold("hold-above", above, opts.hold_s, result)
    log(f"held {opts.hold_s:g} s above the anchor")
    hold_point = above
    if opts.gps_less_fly_out:
        # out to the target along the sphere of the taut line (never closer than its length)
        for fraction in (0.25, 0.5, 0.75, 1.0):
            elevation = math.pi / 2 + fraction * (math.asin(-target[2] / radius) - math.pi / 2)
            point = radius * np.array([math.cos(elevation), 0.0, -math.sin(elevation)])
            flight.fly_to(point, within_m=0.7, fc_s=30.0)
        flight.hold("hold-out", target, opts.hold_s, result)
        log(f"held {opts.hold_s:g} s at the target")
        hold_point = target
    if opts.land_by_tether:
        _reel_in(flight, result)
    elif opts.land:
        start = flight.fc_now()
        flight.mode("LAND")
        gcs.wait_for("landed and disarmed", lambda s: not s["armed"], 10.0 + 90.0 / opts.speedup)
        result.phases.append(
            score_phase(
                "land",
                gcs.samples_between(start, flight.fc_now()),
                _fixed(np.array([hold_point[0], hold_point[1], 0.0])),
            )
        )
        log("landed")


MAV_CMD_USER_2 = 31011
"""The service's tension-mode command (docs/landing.md): param1 1 enable, param2 1 land."""
TETHER_LINE_LENGTH_M = 6.0
"""SIM_TETH_LINELEN in the shipped tether.parm [m]."""
REEL_END_M = -2.0
"""Where the reel-in stops [m]. SITL's line is a spring from the anchor: at rest length 0 it
still holds ~9 N at 1.1 m of stretch, and the tension mode, which follows only a pull beyond
the one it has learned, then holds the drone there (measured: 1.58 m up). A negative rest
length keeps the pull growing as a winch still reeling in would."""
REEL_STEP_S = 0.25
"""Autopilot seconds between two SIM_TETH_LINELEN steps while reeling in."""


def _reel_in(flight: _Flight, result: FlightResult) -> None:
    """Shorten SITL's line like a winch (SIM_TETH_LINELEN) until the drone disarms; the
    service's tension-following mode should feel the pull, follow it down and hand over to
    LAND near the ground."""
    gcs, opts, log = flight.gcs, flight.options, flight.log
    flight.commanded_modes.append(COPTER_MODES["LAND"])  # the service's hand-over, not a failsafe
    start = flight.fc_now()
    length = TETHER_LINE_LENGTH_M
    deadline_fc = start + 120.0
    # enabled now, not at start: armed in GUIDED on the ground the service has no position
    # (motors idle), and the mode's "estimate lost -> LAND" rule would land it at once
    result_code = gcs.command_companion(MAV_CMD_USER_2, 1.0, 0.0, wait_s=5.0)
    if result_code != 0:
        raise FlightError(
            f"the service refused to enable the tension mode (MAV_RESULT {result_code})"
        )
    log(f"tension mode on; reeling the tether in at {opts.reel_in_mps:g} m/s")
    while gcs.snapshot()["armed"]:
        if flight.fc_now() > deadline_fc:
            raise FlightError("tether landing: still armed 120 s after the reel-in began")
        length = max(REEL_END_M, length - opts.reel_in_mps * REEL_STEP_S)
        gcs.set_param("SIM_TETH_LINELEN", length)
        gcs.line_length_m = length  # the winch reels with it
        flight.wait(REEL_STEP_S)
    result.phases.append(
        score_phase(
            "tether-landing",
            gcs.samples_between(start, flight.fc_now()),
            _fixed(np.array([0.0, 0.0, 0.0])),
        )
    )
    log(f"landed by the tether; line length {length:.2f} m at touchdown")
