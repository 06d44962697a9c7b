"""The link sections of the companion's configuration: where the flight controller is and who
it is (``link``), the input streams asked of it (``streams``), the EKF origin sent to it
(``origin``) and who is believed on the link (``security``). Validated like every section
(:mod:`tether_companion.service.config`)."""

from __future__ import annotations

from dataclasses import dataclass

from tether_companion.config import ConfigError, spec
from tether_companion.mavlink.endpoints import parse_endpoint
from tether_companion.mavlink.trust import SIGNING_MODES

MAV_COMP_ID_ONBOARD_COMPUTER = 191


@dataclass(frozen=True)
class LinkConfig:
    """The MAVLink link to the flight controller and who is who on it."""

    connect: str = spec(
        "serial:/dev/ttyAMA0:921600",
        doc="flight-controller endpoint: serial:/dev/X:BAUD, udp:HOST:PORT, tcp:HOST:PORT, "
        "udpin:, tcpin:",
    )
    autopilot: str = spec(
        "ardupilot",
        choices=("ardupilot", "px4"),
        doc="flavour: which IMU message and units to decode",
    )
    fc_system_id: int = spec(1, minimum=1, maximum=255, doc="flight controller's MAVLink system id")
    fc_component_id: int = spec(1, minimum=1, maximum=255, doc="flight controller's component id")
    system_id: int = spec(
        1, minimum=1, maximum=255, doc="our system id (the vehicle's, as for any onboard component)"
    )
    component_id: int = spec(
        MAV_COMP_ID_ONBOARD_COMPUTER,
        minimum=1,
        maximum=255,
        doc="our component id (191 = MAV_COMP_ID_ONBOARD_COMPUTER)",
    )
    heartbeat_hz: float = spec(1.0, minimum=0.2, maximum=10.0, doc="our HEARTBEAT rate [Hz]")
    timesync_hz: float = spec(
        1.0, minimum=0.0, maximum=10.0, doc="TIMESYNC request rate [Hz] (0 = off)"
    )
    link_timeout_s: float = spec(
        2.0,
        exclusive_minimum=0.0,
        maximum=60.0,
        doc="no message from the flight controller for this long = link lost [s]",
    )
    retry_initial_s: float = spec(
        0.5, exclusive_minimum=0.0, doc="first back-off after a failed open [s]"
    )
    retry_max_s: float = spec(
        10.0, exclusive_minimum=0.0, doc="longest back-off between open attempts [s]"
    )
    stream_request_interval_s: float = spec(
        1.0,
        exclusive_minimum=0.0,
        doc="re-send stream requests this often while an input is missing [s]",
    )

    def validate(self) -> None:
        """The endpoint parses; back-off bounds in order."""
        parse_endpoint(self.connect, "connect", key="connect")
        if self.retry_max_s < self.retry_initial_s:
            raise ConfigError(
                "",
                "retry_max_s",
                self.retry_max_s,
                f"must be >= retry_initial_s ({self.retry_initial_s})",
            )


@dataclass(frozen=True)
class StreamsConfig:
    """Rates at which the flight controller is asked to send the inputs [Hz]."""

    imu_hz: float = spec(
        200.0, minimum=10.0, maximum=1000.0, doc="RAW_IMU (ArduPilot) / HIGHRES_IMU (PX4) [Hz]"
    )
    attitude_hz: float = spec(200.0, minimum=5.0, maximum=1000.0, doc="ATTITUDE [Hz]")
    servo_hz: float = spec(200.0, minimum=5.0, maximum=1000.0, doc="SERVO_OUTPUT_RAW [Hz]")
    rangefinder_hz: float = spec(
        20.0, minimum=0.0, maximum=200.0, doc="DISTANCE_SENSOR [Hz] (0 = not requested)"
    )


@dataclass(frozen=True)
class OriginConfig:
    """Where the ground station (tether anchor) is: sent as the EKF origin after every FC boot."""

    latitude_deg: float = spec(
        0.0, minimum=-90.0, maximum=90.0, doc="anchor latitude [deg] (WGS84)"
    )
    longitude_deg: float = spec(
        0.0, minimum=-180.0, maximum=180.0, doc="anchor longitude [deg] (WGS84)"
    )
    altitude_m: float = spec(0.0, minimum=-500.0, maximum=9000.0, doc="anchor altitude AMSL [m]")
    send: bool = spec(True, doc="send SET_GPS_GLOBAL_ORIGIN after each flight-controller boot")


@dataclass(frozen=True)
class SecurityConfig:
    """Who the service believes on the link (``docs/security.md``)."""

    signing: str = spec(
        "off",
        choices=SIGNING_MODES,
        doc="MAVLink 2 signing: required (drop every frame not correctly signed), preferred "
        "(check signed frames, accept unsigned), off; we sign what we send unless off",
    )
    key_file: str = spec(
        "",
        doc="the 32-byte signing key: 32 raw bytes or 64 hex digits, readable by the service "
        "user only (chmod 600); needed unless signing is off",
    )
    link_id: int = spec(
        0, minimum=0, maximum=255, doc="this link's id in the signature of what we send"
    )
    command_sources: tuple[int, ...] = spec(
        (255,),
        minimum=1,
        maximum=255,
        doc="system ids of the ground stations whose tension-mode and landing commands are "
        "accepted (others get COMMAND_ACK DENIED)",
    )
    install_key: bool = spec(
        False,
        doc="send the key to the flight controller with SETUP_SIGNING after each of its boots "
        "(serial links only: the key would cross the network in clear otherwise)",
    )

    def validate(self) -> None:
        """A key is needed to sign; installing it needs signing on."""
        if self.signing != "off" and not self.key_file:
            raise ConfigError(
                "", "key_file", self.key_file, f"a key file is needed with signing {self.signing}"
            )
        if self.install_key and self.signing == "off":
            raise ConfigError("", "install_key", True, "needs signing preferred or required")
