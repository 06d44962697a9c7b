"""The service's input sections: ``inputs`` (plausibility bounds of the flight controller's
samples) and ``tension`` (where the cable tension comes from for the 3-state estimator).

Frozen dataclasses validated by :mod:`tether_companion.config` as parts of
:class:`~tether_companion.service.config.ServiceConfig`.
"""

from __future__ import annotations

from dataclasses import dataclass

from tether_companion.config import ConfigError, spec


@dataclass(frozen=True)
class InputLimitsConfig:
    """Plausibility bounds: samples outside them are dropped and counted as absurd."""

    max_specific_force_mps2: float = spec(
        16.0 * 9.80665,
        exclusive_minimum=0.0,
        doc="largest accelerometer magnitude accepted [m/s^2] (16 g)",
    )
    max_angular_rate_rad_s: float = spec(
        35.0, exclusive_minimum=0.0, doc="largest gyro rate accepted [rad/s] (2000 deg/s)"
    )
    pwm_min_us: float = spec(800.0, minimum=0.0, doc="smallest motor pulse width accepted [us]")
    pwm_max_us: float = spec(2200.0, minimum=0.0, doc="largest motor pulse width accepted [us]")
    range_min_m: float = spec(
        0.05, minimum=0.0, doc="rangefinder readings below this are dropped [m]"
    )
    range_max_m: float = spec(
        40.0, exclusive_minimum=0.0, doc="rangefinder readings above this are dropped [m]"
    )
    reorder_window_s: float = spec(
        0.03,
        minimum=0.0,
        maximum=0.2,
        doc="largest reorder window: 0 until the link reorders, then 1.25x the lateness seen "
        "(adds as much latency), back to 0 after 5-10 s without; 0 = drop every late sample [s]",
    )

    def validate(self) -> None:
        """Bounds in order."""
        if self.pwm_max_us <= self.pwm_min_us:
            raise ConfigError(
                "", "pwm_max_us", self.pwm_max_us, f"must be > pwm_min_us ({self.pwm_min_us})"
            )
        if self.range_max_m <= self.range_min_m:
            raise ConfigError(
                "", "range_max_m", self.range_max_m, f"must be > range_min_m ({self.range_min_m})"
            )


@dataclass(frozen=True)
class TensionConfig:
    """Where the cable tension comes from when the 3-state estimator is chosen."""

    source: str = spec(
        "estimate",
        choices=("estimate", "config", "message", "winch"),
        doc="estimate (4-state EKF), config (known_tension_n), "
        "message (NAMED_VALUE_FLOAT from a load cell), winch (WINCH_STATUS tension, carried "
        "from the winch to the drone by the cable's weight; needs winch.enabled)",
    )
    known_tension_n: float = spec(
        4.0, exclusive_minimum=0.0, maximum=500.0, doc="tension when source = config [N]"
    )
    message_name: str = spec(
        "TENSION", doc="NAMED_VALUE_FLOAT name carrying the measured tension [N]"
    )
    sensor_system_id: int = spec(1, minimum=1, maximum=255, doc="system id of the tension sensor")
    sensor_component_id: int = spec(
        1, minimum=0, maximum=255, doc="component id of the tension sensor"
    )

    def validate(self) -> None:
        """NAMED_VALUE_FLOAT names are at most 10 characters."""
        if not 1 <= len(self.message_name) <= 10:
            raise ConfigError(
                "",
                "message_name",
                self.message_name,
                "must be 1 to 10 characters (NAMED_VALUE_FLOAT name)",
            )
