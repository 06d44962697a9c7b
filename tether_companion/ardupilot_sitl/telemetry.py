"""What the SITL ground station keeps of the autopilot's and the companion's messages: the
latest of each and a history of samples (SIM_STATE truth beside EKF3's and our position), all
under one lock (:class:`Telemetry`), filled by :func:`absorb` and :func:`absorb_companion`
from the ground station's reader thread. Positions are NED [m] from the SITL home (the
tether's anchor); times are the autopilot's (``time_boot_ms``) [s]."""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np
from pymavlink import mavutil

from tether_companion.mavlink.geo import Geodetic, geodetic_to_ned
from tether_companion.sim.ground_sensors import GroundSensors

EKF_FLAG_POS_HORIZ_ABS = 16
"""EKF_STATUS_REPORT.flags bit: horizontal absolute position OK (EKF_POS_HORIZ_ABS)."""


@dataclass
class Sample:
    """One SIM_STATE truth sample with what the autopilot believed at the same moment."""

    wall_s: float
    fc_s: float
    truth_ned_m: np.ndarray
    fc_ned_m: np.ndarray
    """The autopilot's own LOCAL_POSITION_NED (EKF3) last received."""
    vision_ned_m: np.ndarray
    """The companion's last VISION_POSITION_ESTIMATE (nan before the first)."""
    vision_age_s: float
    """Autopilot seconds since that estimate arrived (nan before the first): while the service
    withholds, the last one grows stale and is no estimate of now."""
    ekf_pos_ratio: float
    """EKF_STATUS_REPORT.pos_horiz_variance: EKF3's horizontal position innovation test ratio."""
    ekf_flags: int
    mode: int
    armed: bool
    yaw_error_rad: float = math.nan
    """The autopilot's ATTITUDE yaw minus SIM_STATE's yaw, wrapped to [-pi, pi)."""


@dataclass
class Telemetry:
    """Everything the reader thread collected (guarded by ``lock``)."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    fc_s: float = 0.0
    heartbeat: object | None = None
    truth_ned_m: np.ndarray | None = None
    fc_ned_m: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    fc_yaw_rad: float = math.nan
    ekf: object | None = None
    texts: list[tuple[float, str]] = field(default_factory=list)
    acks: list[object] = field(default_factory=list)
    samples: list[Sample] = field(default_factory=list)
    forwarded_vision: int = 0
    """VISION_POSITION_ESTIMATEs from our companion (system 1, component 191) routed to us."""
    vision_ned_m: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    """The companion's last VISION_POSITION_ESTIMATE position (NED from the anchor) [m]."""
    vision_fc_s: float = math.nan
    """The autopilot time when that estimate arrived [s]."""
    companion_texts: list[tuple[float, str]] = field(default_factory=list)
    origin: object | None = None
    """The autopilot's GPS_GLOBAL_ORIGIN, once received."""
    params: dict[str, float] = field(default_factory=dict)
    """PARAM_VALUEs received."""
    ground_sensors: GroundSensors | None = None
    """The ground station's sensors, recording each truth (None: no winch, no angle)."""


def absorb(tel: Telemetry, kind: str, msg, home: Geodetic) -> np.ndarray | None:  # noqa: ANN001
    """Take one message of the autopilot's (system 1, component 1) into ``tel`` (under its
    lock); ``home`` is the anchor that SIM_STATE's truth is made NED from. Returns that truth
    [m] for a SIM_STATE (None otherwise)."""
    boot_ms = getattr(msg, "time_boot_ms", None)
    if boot_ms is not None:
        tel.fc_s = boot_ms * 1e-3
    if kind == "HEARTBEAT":
        tel.heartbeat = msg
    elif kind == "STATUSTEXT":
        tel.texts.append((tel.fc_s, msg.text))
    elif kind == "COMMAND_ACK":
        tel.acks.append(msg)
    elif kind == "PARAM_VALUE":
        tel.params[msg.param_id] = float(msg.param_value)
    elif kind == "GPS_GLOBAL_ORIGIN":
        tel.origin = msg
    elif kind == "EKF_STATUS_REPORT":
        tel.ekf = msg
    elif kind == "ATTITUDE":
        tel.fc_yaw_rad = msg.yaw
    elif kind == "LOCAL_POSITION_NED":
        tel.fc_ned_m = np.array([msg.x, msg.y, msg.z])
    elif kind == "SIM_STATE":
        lat = msg.lat_int * 1e-7 if getattr(msg, "lat_int", 0) else msg.lat
        lon = msg.lon_int * 1e-7 if getattr(msg, "lon_int", 0) else msg.lon
        truth = geodetic_to_ned(home, Geodetic(lat, lon, msg.alt))
        tel.truth_ned_m = truth
        hb = tel.heartbeat
        tel.samples.append(
            Sample(
                wall_s=time.monotonic(),
                fc_s=tel.fc_s,
                truth_ned_m=truth,
                fc_ned_m=tel.fc_ned_m.copy(),
                vision_ned_m=tel.vision_ned_m.copy(),
                vision_age_s=tel.fc_s - tel.vision_fc_s,
                ekf_pos_ratio=float(tel.ekf.pos_horiz_variance) if tel.ekf else math.nan,
                ekf_flags=int(tel.ekf.flags) if tel.ekf else 0,
                mode=int(hb.custom_mode) if hb else -1,
                armed=bool(hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                if hb
                else False,
                yaw_error_rad=(tel.fc_yaw_rad - msg.yaw + math.pi) % (2 * math.pi) - math.pi,
            )
        )
        return truth
    return None


def absorb_companion(tel: Telemetry, kind: str, msg) -> None:  # noqa: ANN001 - pymavlink type
    """Take one message of the companion's (system 1, component 191, routed by the autopilot)
    into ``tel`` (under its lock): its VISION_POSITION_ESTIMATE, STATUSTEXT and COMMAND_ACK."""
    if kind == "VISION_POSITION_ESTIMATE":
        tel.forwarded_vision += 1
        tel.vision_ned_m = np.array([msg.x, msg.y, msg.z])
        tel.vision_fc_s = tel.fc_s
    elif kind == "STATUSTEXT":
        tel.companion_texts.append((tel.fc_s, msg.text))
    elif kind == "COMMAND_ACK":
        tel.acks.append(msg)
