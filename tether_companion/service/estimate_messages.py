"""The MAVLink messages of a published estimate: :class:`EstimateMessages`.

Pure: the :class:`~tether_companion.service.publish.Publisher` decides what to send and when;
this builds the messages. Choices, with the reasons:

* ``usec`` is the flight-controller time of the IMU sample the estimate was computed at (time
  since FC boot): ArduPilot maps it onto its own clock with its jitter correction and PX4 with
  the TIMESYNC offset (which our TIMESYNC answers make ~0), and both then fuse the measurement
  at the right point of their delayed-state horizon.
* Roll, pitch and yaw are the flight controller's own ATTITUDE (ArduPilot refuses to arm when
  they differ from its estimate by more than 10 degrees); we estimate no attitude.
* Covariance: the MAVLink spec has only one "unknown" marker, NaN in entry 0, which voids the
  whole matrix; with ``covariance: ekf`` we fill the position block from the EKF (m^2) and put a
  large finite variance (``attitude_variance_rad2``) on the attitude diagonal, meaning "this
  attitude is yours, do not trust it as a measurement". Entries must be finite: ArduPilot
  computes ``angErr = cbrt(c15^2 + c18^2 + c20^2)`` and would get NaN from NaN entries. ArduPilot
  reads ``posErr = cbrt(c0^2 + c6^2 + c11^2)`` and clamps it to [VISO_POS_M_NSE, 100] m; PX4
  (EKF2_EV_NOISE_MD = 0) uses each variance, floored at EKF2_EVP_NOISE^2. An inflated
  publication carries ``inflated_variance_m2`` on the position diagonal.
* An estimate with a velocity (the dynamic filter) also fills ODOMETRY's velocity and its
  covariance, and VISION_SPEED_ESTIMATE when ``speed_estimate`` is on; never a non-finite one.
* For the ground station, NAMED_VALUE_FLOAT: the published estimate's tension
  (``tension_name`` [N]); the tension filter's force of the cable on the drone (``TETH_TN``,
  ``TETH_TE``, ``TETH_TD``, NED [N]) and its magnitude (``TETH_TMAG`` [N]), and the catenary
  position when it runs (``TETH_CN``, ``TETH_CE``, ``TETH_CD`` [m]). One scalar per name, so
  any plotter can pick one (pymavlink's ``NAMED_VALUE_FLOAT.value{NAMED_VALUE_FLOAT.name==
  "TETH_TN"}`` in MAVProxy's ``graph``). Never a non-finite value.
* A health change is announced as STATUSTEXT ``TETHER: <text>`` (at most 50 characters).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.catenary_position import CatenaryPosition
from tether_companion.estimation.tension_kf import TensionEstimate
from tether_companion.mavlink.estimates import (
    PoseEstimate,
    VelocityEstimate,
    odometry_message,
    vision_speed_estimate_message,
)
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.mavlink.units import (
    MAV_FRAME_LOCAL_FRD,
    MAV_FRAME_LOCAL_NED,
    POSE_DIM,
    covariance_to_urt,
    seconds_to_boot_ms,
    seconds_to_usec,
)
from tether_companion.samples import AttitudeSample
from tether_companion.service.health import OK, PositionEstimate, health_text
from tether_companion.service.publish_config import PublishConfig

FloatArray = NDArray[np.float64]

STATUSTEXT_PREFIX = "TETHER: "
"""What every health STATUSTEXT starts with."""
TENSION_VECTOR_NAMES = (b"TETH_TN", b"TETH_TE", b"TETH_TD")
"""NAMED_VALUE_FLOAT names of the filtered force of the cable on the drone, NED [N]."""
TENSION_MAGNITUDE_NAME = b"TETH_TMAG"
"""NAMED_VALUE_FLOAT name of the filtered tension magnitude [N]."""
CATENARY_POSITION_NAMES = (b"TETH_CN", b"TETH_CE", b"TETH_CD")
"""NAMED_VALUE_FLOAT names of the catenary estimator's position, NED from the anchor [m]."""

_ODOMETRY_FRAMES = {"local_ned": MAV_FRAME_LOCAL_NED, "local_frd": MAV_FRAME_LOCAL_FRD}


def velocity_of(
    estimate: PositionEstimate, time_s: float, reset_counter: int
) -> VelocityEstimate | None:
    """The estimate's velocity to send, or None when it has none (the paper's random-walk
    filters) or when it or its covariance is not finite (never NaN to a flight controller).

    An estimator with a velocity state exposes ``velocity_ned_mps`` (shape (3,), NED [m/s])
    and ``velocity_covariance_m2ps2`` (shape (3, 3) [m^2/s^2]).
    """
    velocity = getattr(estimate, "velocity_ned_mps", None)
    covariance = getattr(estimate, "velocity_covariance_m2ps2", None)
    if velocity is None or covariance is None:
        return None
    velocity = np.asarray(velocity, dtype=float)
    covariance = np.asarray(covariance, dtype=float)
    if not (np.all(np.isfinite(velocity)) and np.all(np.isfinite(covariance))):
        return None
    return VelocityEstimate(time_s, velocity, 0.5 * (covariance + covariance.T), reset_counter)


class EstimateMessages:
    """Builds the messages of the ``publish`` section's choices.

    Parameters
    ----------
    config
        The ``publish`` section.
    """

    def __init__(self, config: PublishConfig) -> None:
        self.config = config

    def position(
        self,
        estimate: PositionEstimate,
        position: tuple[float, float, float],
        attitude: AttitudeSample,
        inflated: bool,
        reset_counter: int,
    ) -> list[MAVLinkMessage]:
        """VISION_POSITION_ESTIMATE (and ODOMETRY, VISION_SPEED_ESTIMATE when configured) for
        ``position`` (NED [m], floats) at the estimate's time; ``inflated``: the position is
        the last healthy one, sent with ``inflated_variance_m2`` and no velocity.

        VISION_POSITION_ESTIMATE is built from Python floats (:meth:`_pose_urt`): it is what
        the flight controller waits for, so no numpy on its way out."""
        t = estimate.time_s
        euler = (attitude.roll_rad, attitude.pitch_rad, attitude.yaw_rad)
        out = [
            dialect.MAVLink_vision_position_estimate_message(
                seconds_to_usec(t),
                *position,
                *(float(a) for a in euler),
                self._pose_urt(estimate, inflated),
                reset_counter & 0xFF,
            )
        ]
        config = self.config
        if not (config.odometry or config.speed_estimate):
            return out
        velocity = None if inflated else velocity_of(estimate, t, reset_counter)
        if config.odometry:
            pose = PoseEstimate(
                time_s=t,
                position_ned_m=np.array(position),
                euler_rad=euler,
                covariance=self._pose_covariance(estimate, inflated=inflated),
                reset_counter=reset_counter,
            )
            frame = _ODOMETRY_FRAMES[config.odometry_frame]
            out.append(odometry_message(pose, velocity, frame_id=frame))
        if config.speed_estimate and velocity is not None:
            out.append(vision_speed_estimate_message(velocity))
        return out

    def tension(self, time_s: float, tension_n: float) -> MAVLinkMessage:
        """NAMED_VALUE_FLOAT ``tension_name`` of the published estimate's tension [N] at FC
        time ``time_s`` [s]."""
        name = self.config.tension_name.encode("ascii")
        return dialect.MAVLink_named_value_float_message(
            seconds_to_boot_ms(time_s), name, float(tension_n)
        )

    @staticmethod
    def filtered(
        time_s: float, tension: TensionEstimate | None, catenary: CatenaryPosition | None
    ) -> list[MAVLinkMessage]:
        """NAMED_VALUE_FLOATs at FC time ``time_s`` [s] of the tension filter's force on the
        drone (NED [N]) and its magnitude [N] when ``tension`` is given, and of the catenary
        position (NED [m]) when ``catenary`` is given; non-finite values left out."""
        values: list[tuple[bytes, float]] = []
        if tension is not None:
            force = tension.tension_ned_n
            values += zip(TENSION_VECTOR_NAMES, (float(v) for v in force), strict=True)
            values.append((TENSION_MAGNITUDE_NAME, tension.magnitude_n))
        if catenary is not None:
            position = catenary.position_ned_m
            values += zip(CATENARY_POSITION_NAMES, (float(v) for v in position), strict=True)
        stamp_ms = seconds_to_boot_ms(time_s)
        return [
            dialect.MAVLink_named_value_float_message(stamp_ms, name, value)
            for name, value in values
            if math.isfinite(value)
        ]

    @staticmethod
    def statustext(health: str) -> MAVLinkMessage:
        """The STATUSTEXT announcing ``health`` (info when ``ok``, else warning)."""
        severity = dialect.MAV_SEVERITY_INFO if health == OK else dialect.MAV_SEVERITY_WARNING
        text = (STATUSTEXT_PREFIX + health_text(health))[:50].encode("ascii")
        return dialect.MAVLink_statustext_message(severity, text, 0, 0)

    def _pose_urt(self, estimate: PositionEstimate, inflated: bool) -> list[float]:
        """:meth:`_pose_covariance` as MAVLink's 21-entry upper right triangle, in Python
        floats (the same values as ``covariance_to_urt(self._pose_covariance(...))``).

        Raises
        ------
        ValueError
            When an entry is not finite (as ``covariance_to_urt``).
        """
        config = self.config
        if config.covariance == "unknown":
            return covariance_to_urt(None)
        if inflated:
            nn = ee = dd = config.inflated_variance_m2
            ne = nd = ed = 0.0
        else:
            (a, b, c), (d, e, f), (g, h, i) = estimate.position_covariance_m2.tolist()
            nn, ne, nd = 0.5 * (a + a), 0.5 * (b + d), 0.5 * (c + g)
            ee, ed, dd = 0.5 * (e + e), 0.5 * (f + h), 0.5 * (i + i)
        att = config.attitude_variance_rad2
        if not all(map(math.isfinite, (nn, ne, nd, ee, ed, dd, att))):
            raise ValueError("pose covariance holds non-finite values")
        return [
            nn, ne, nd, 0.0, 0.0, 0.0,
            ee, ed, 0.0, 0.0, 0.0,
            dd, 0.0, 0.0, 0.0,
            att, 0.0, 0.0,
            att, 0.0,
            att,
        ]  # fmt: skip

    def _pose_covariance(self, estimate: PositionEstimate, *, inflated: bool) -> FloatArray | None:
        """The 6x6 pose covariance (position [m^2], attitude [rad^2]); None when the config
        says the covariance is unknown."""
        if self.config.covariance == "unknown":
            return None
        pose = np.zeros((POSE_DIM, POSE_DIM))
        if inflated:
            pose[:3, :3] = np.eye(3) * self.config.inflated_variance_m2
        else:
            block = estimate.position_covariance_m2
            pose[:3, :3] = 0.5 * (block + block.T)
        pose[3:, 3:] = np.eye(3) * self.config.attitude_variance_rad2
        return pose
