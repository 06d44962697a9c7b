"""The service's ``publish`` section: what is sent to the flight controller and when.

A frozen dataclass validated by :mod:`tether_companion.config` as part of
:class:`~tether_companion.service.config.ServiceConfig`; read by
:class:`~tether_companion.service.publish.Publisher` and
:func:`~tether_companion.service.health.assess_health`.
"""

from __future__ import annotations

from dataclasses import dataclass

from tether_companion.config import ConfigError, spec


@dataclass(frozen=True)
class PublishConfig:
    """What is sent to the flight controller and when."""

    rate_hz: float = spec(
        30.0,
        minimum=1.0,
        maximum=200.0,
        doc="VISION_POSITION_ESTIMATE rate [Hz] (flight-controller time)",
    )
    covariance: str = spec(
        "ekf",
        choices=("ekf", "unknown"),
        doc="ekf: position variances from the EKF; "
        "unknown: covariance[0] = NaN (ArduPilot then uses VISO_POS_M_NSE)",
    )
    attitude_variance_rad2: float = spec(
        1.0,
        exclusive_minimum=0.0,
        maximum=10.0,
        doc="roll/pitch/yaw variance sent [rad^2] (large: the attitude is the FC's own)",
    )
    odometry: bool = spec(
        False,
        doc="also send ODOMETRY (pose, and the velocity in the body frame with its covariance "
        "when the estimator has one; velocity marked unknown otherwise)",
    )
    odometry_frame: str = spec(
        "local_ned",
        choices=("local_ned", "local_frd"),
        doc="ODOMETRY frame_id: local_ned for PX4; local_frd for ArduPilot, which ignores "
        "ODOMETRY in any other frame",
    )
    speed_estimate: bool = spec(
        False,
        doc="also send VISION_SPEED_ESTIMATE (NED velocity and covariance; ArduPilot fuses it "
        "with EK3_SRC1_VELXY 6) when the estimator has a velocity",
    )
    tension_rate_hz: float = spec(
        10.0, minimum=0.0, maximum=50.0, doc="NAMED_VALUE_FLOAT tension rate [Hz] (0 = off)"
    )
    tension_name: str = spec(
        "TETH_TENS", doc="NAMED_VALUE_FLOAT name of the tension of the published estimate"
    )
    filtered_rate_hz: float = spec(
        10.0,
        minimum=0.0,
        maximum=50.0,
        doc="NAMED_VALUE_FLOAT rate of the tension filter's force on the drone TETH_TN, "
        "TETH_TE, TETH_TD (NED) and magnitude TETH_TMAG [N], and of the catenary position "
        "TETH_CN, TETH_CE, TETH_CD [m] when it runs [Hz] (0 = off)",
    )
    filtered_max_age_s: float = spec(
        0.3,
        exclusive_minimum=0.0,
        maximum=5.0,
        doc="a filtered tension not updated for this long is not published [s]",
    )
    statustext: bool = spec(True, doc="send STATUSTEXT when the health changes")
    on_unhealthy: str = spec(
        "stop",
        choices=("stop", "inflate"),
        doc="when not healthy (stale, diverged, slack, weak pull, short cable): stop sending, "
        "or send the last healthy position with inflated_variance_m2",
    )
    inflated_variance_m2: float = spec(
        100.0, exclusive_minimum=0.0, maximum=1e4, doc="position variance sent when unhealthy [m^2]"
    )
    max_position_variance_m2: float = spec(
        0.5,
        exclusive_minimum=0.0,
        doc="an estimate whose largest position variance reaches this is not healthy [m^2]",
    )
    settle_s: float = spec(
        1.0,
        minimum=0.0,
        maximum=60.0,
        doc="an estimator run must stay healthy this long before its first position is sent [s]",
    )
    idle_thrust_fraction: float = spec(
        0.25,
        minimum=0.0,
        maximum=1.0,
        doc="total motor thrust below this fraction of the weight = on the ground, not sent",
    )
    slack_tension_n: float = spec(
        0.3,
        minimum=0.0,
        doc="estimated tension below this = slack tether, position unobservable [N]",
    )
    jump_m: float = spec(
        1.0,
        exclusive_minimum=0.0,
        doc="a move this large between two publications raises reset_counter [m]",
    )
    short_cable_m: float = spec(
        1.0,
        minimum=0.0,
        doc="dynamic filter: a position withheld for a weak pull or a slack cable closer than "
        "this to the anchor is reported as short_cable [m]",
    )

    def validate(self) -> None:
        """NAMED_VALUE_FLOAT names are at most 10 characters."""
        if not 1 <= len(self.tension_name) <= 10:
            raise ConfigError(
                "",
                "tension_name",
                self.tension_name,
                "must be 1 to 10 characters (NAMED_VALUE_FLOAT name)",
            )
