"""The tension modes between MAVLink and the decision logic: pure, synchronous glue.

:class:`TensionModeSession` owns a tension filter
(:class:`~tether_companion.estimation.tension_kf.TensionEstimator`) and the decision logic
(:class:`~tether_companion.modes.tension_following.TensionModes`). The service hands it the
decoded samples it already has, the flight controller's HEARTBEAT, and, at its publication
ticks, the position estimate and height; :meth:`TensionModeSession.tick` returns the MAVLink
messages to send to the flight controller:

* velocity target: ``SET_POSITION_TARGET_LOCAL_NED`` in ``MAV_FRAME_LOCAL_NED`` with only the
  velocity used (at most every ``target_period_s``; a change to a stop is sent at once);
* position target: the same with only the position used (the local frame's origin is the EKF
  origin, which the service sets at the anchor);
* LAND: ``COMMAND_LONG MAV_CMD_DO_SET_MODE`` with the Copter custom mode LAND, repeated every
  ``land_period_s`` until the heartbeat reports LAND.

Call :meth:`TensionModeSession.tick` at a steady rate of flight-controller time (e.g. 50 Hz)
driven by **any** timestamped message (ATTITUDE as well as RAW_IMU) or a timer, not only by
IMU samples: when the IMU stream stops, the tension estimate goes stale and the logic must
still run to stop the drone and hand over to LAND (``tests/test_modes_e2e.py`` (c) shows it).

Flight-mode names follow pymavlink's ArduCopter table (``mavutil.mode_mapping_acm``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from pymavlink import mavutil

from tether_companion.estimation.alignment import InputAligner
from tether_companion.estimation.tension_kf import (
    TensionEstimate,
    TensionEstimator,
    TensionFilterConfig,
)
from tether_companion.estimation.thrust_input import ThrustInput
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.modes.config import TensionModeConfig
from tether_companion.modes.tension_following import (
    LAND,
    NOTHING,
    POSITION_TARGET,
    VELOCITY_TARGET,
    ModeAction,
    ModeInputs,
    TensionModes,
)
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample

COPTER_MODE_NAMES: dict[int, str] = dict(mavutil.mode_mapping_acm)
"""ArduCopter custom_mode number -> name (GUIDED = 4, LAND = 9, ...)."""
COPTER_LAND = next(number for number, name in COPTER_MODE_NAMES.items() if name == "LAND")

_IGNORE_ACCEL_YAW = (
    dialect.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | dialect.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | dialect.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | dialect.POSITION_TARGET_TYPEMASK_YAW_IGNORE
    | dialect.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)
VELOCITY_ONLY_MASK = (
    _IGNORE_ACCEL_YAW
    | dialect.POSITION_TARGET_TYPEMASK_X_IGNORE
    | dialect.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | dialect.POSITION_TARGET_TYPEMASK_Z_IGNORE
)
"""type_mask of a velocity-only target."""
POSITION_ONLY_MASK = (
    _IGNORE_ACCEL_YAW
    | dialect.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | dialect.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | dialect.POSITION_TARGET_TYPEMASK_VZ_IGNORE
)
"""type_mask of a position-only target."""


def copter_mode_name(custom_mode: int) -> str:
    """ArduCopter mode name of a HEARTBEAT ``custom_mode`` (``MODE<n>`` if unknown)."""
    return COPTER_MODE_NAMES.get(int(custom_mode), f"MODE{int(custom_mode)}")


def action_messages(
    action: ModeAction, target_system: int, target_component: int, time_boot_ms: int
) -> list[MAVLinkMessage]:
    """The MAVLink messages that carry ``action`` to the flight controller.

    Raises
    ------
    ValueError
        When a target holds a non-finite number (the logic never produces one; this guards
        the wire: no NaN is ever sent to a flight controller).
    """
    if action.kind == NOTHING:
        return []
    if action.kind == LAND:
        return [
            dialect.MAVLink_command_long_message(
                target_system,
                target_component,
                dialect.MAV_CMD_DO_SET_MODE,
                0,
                dialect.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                COPTER_LAND,
                0,
                0,
                0,
                0,
                0,
            )
        ]
    if action.kind == VELOCITY_TARGET:
        vector, mask = action.velocity_ned_m_s, VELOCITY_ONLY_MASK
    elif action.kind == POSITION_TARGET:
        vector, mask = action.position_ned_m, POSITION_ONLY_MASK
    else:
        raise ValueError(f"unknown mode action {action.kind!r}")
    values = [float(v) for v in vector]  # type: ignore[union-attr]
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"refusing to send a non-finite target {values}")
    position = values if action.kind == POSITION_TARGET else [0.0, 0.0, 0.0]
    velocity = values if action.kind == VELOCITY_TARGET else [0.0, 0.0, 0.0]
    return [
        dialect.MAVLink_set_position_target_local_ned_message(
            int(time_boot_ms) & 0xFFFFFFFF,
            target_system,
            target_component,
            dialect.MAV_FRAME_LOCAL_NED,
            mask,
            *position,
            *velocity,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
        )
    ]


class TensionModeSession:
    """Tension filter + decision logic + MAVLink encoding for the service (pure).

    Parameters
    ----------
    mode_config
        Thresholds and gains of the modes.
    filter_config
        Tension filter settings.
    vehicle
        Vehicle profile.
    target_system, target_component
        The flight controller's MAVLink ids.
    thrust_input
        PWM-to-thrust map (default: the vehicle's static curve).
    aligner
        An input-alignment stage shared with another estimator of the same samples (the
        service's EKF), so attitude and PWM are converted once per sample; it brings its own
        thrust input.
    target_period_s, land_period_s
        Shortest interval between two motion targets / two LAND commands [s].
    """

    def __init__(
        self,
        mode_config: TensionModeConfig,
        filter_config: TensionFilterConfig,
        vehicle: VehicleProfile,
        target_system: int,
        target_component: int,
        *,
        thrust_input: ThrustInput | None = None,
        aligner: InputAligner | None = None,
        target_period_s: float = 0.1,
        land_period_s: float = 1.0,
    ) -> None:
        self.estimator = TensionEstimator(filter_config, vehicle, thrust_input, aligner=aligner)
        self.modes = TensionModes(mode_config)
        self.target_system = target_system
        self.target_component = target_component
        self.target_period_s = target_period_s
        self.land_period_s = land_period_s
        self.armed = False
        self.flight_mode = ""
        self.tension: TensionEstimate | None = None
        self.last_action: ModeAction | None = None
        self._last_sent_s = -math.inf
        self._last_kind = NOTHING
        self.sent = 0
        """Messages returned by :meth:`tick` so far."""
        self.land_commands = 0
        """LAND commands among them."""

    # ------------------------------------------------------------------ inputs
    def on_attitude(self, sample: AttitudeSample) -> None:
        """Feed the tension filter."""
        self.estimator.on_attitude(sample)

    def on_pwm(self, sample: PwmSample) -> None:
        """Feed the tension filter."""
        self.estimator.on_pwm(sample)

    def on_imu(self, sample: ImuSample) -> TensionEstimate | None:
        """Feed the tension filter; returns (and keeps) the new tension estimate."""
        estimate = self.estimator.on_imu(sample)
        if estimate is not None:
            self.tension = estimate
        return estimate

    def on_heartbeat(self, base_mode: int, custom_mode: int) -> None:
        """The flight controller's HEARTBEAT: armed flag and Copter mode."""
        self.armed = bool(base_mode & dialect.MAV_MODE_FLAG_SAFETY_ARMED)
        self.flight_mode = copter_mode_name(custom_mode)

    # ------------------------------------------------------------------ the tick
    def tick(
        self, time_s: float, position_ned_m: ArrayLike, height_m: float
    ) -> list[MAVLinkMessage]:
        """Run the logic at flight-controller time ``time_s`` [s]; messages to send now.

        ``position_ned_m`` is the position estimate relative to the anchor (NED, shape (3,),
        ``nan`` when there is none); ``height_m`` the height above ground (``nan``: unknown).
        """
        # ModeInputs positional (a class called with keywords builds a dict: ~2k instructions)
        action = self.modes.step(
            ModeInputs(
                time_s,  # time_s
                self.tension,  # tension
                self.armed,  # armed
                self.flight_mode,  # flight_mode
                np.asarray(position_ned_m, dtype=float),  # position_ned_m
                float(height_m),  # height_m
            )
        )
        self.last_action = action
        if action.kind == NOTHING:
            self._last_kind = NOTHING
            return []
        period = self.land_period_s if action.kind == LAND else self.target_period_s
        stopping = action.kind == VELOCITY_TARGET and not np.any(action.velocity_ned_m_s)
        urgent = action.kind != self._last_kind or stopping
        if not urgent and time_s - self._last_sent_s < period:
            return []
        self._last_sent_s = time_s
        self._last_kind = action.kind
        messages = action_messages(
            action, self.target_system, self.target_component, int(round(time_s * 1000.0))
        )
        self.sent += len(messages)
        if action.kind == LAND:
            self.land_commands += 1
        return messages
