"""Settings of the tension-driven modes (tension-following and landing by the tether).

Validated at start: a threshold out of range or inconsistent with another is a
:class:`~tether_companion.config.ConfigError` naming the key, never a surprise in flight.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tether_companion.config import ConfigError, load_yaml, spec

VELOCITY = "velocity"
POSITION = "position"


@dataclass(frozen=True)
class TensionModeConfig:
    """Tension-following and landing by the tether (Martins 2019 section 5.1)."""

    enabled: bool = spec(False, doc="run the mode (also settable from the CLI and at run time)")
    land_on_first_tug: bool = spec(
        True, doc="the first detected pull sets the landing flag (else follow only)"
    )
    command: str = spec(
        VELOCITY,
        choices=(VELOCITY, POSITION),
        doc="GUIDED targets sent: velocity, or position (current position + lead along the pull)",
    )
    guided_modes: tuple[str, ...] = spec(
        ("GUIDED",), doc="flight-mode names in which the mode may act (ArduPilot GUIDED)"
    )
    horizontal_threshold_n: float = spec(
        1.0,
        exclusive_minimum=0.0,
        maximum=50.0,
        doc="horizontal pull beyond the cable's own that starts following [N]",
    )
    horizontal_release_n: float = spec(
        0.5,
        minimum=0.0,
        maximum=50.0,
        doc="following stops (and the drone holds) when the extra pull drops below this [N]",
    )
    vertical_threshold_n: float = spec(
        1.0,
        exclusive_minimum=0.0,
        maximum=50.0,
        doc="downward pull beyond the cable's own that counts as a tug / reel-in [N]",
    )
    vertical_release_n: float = spec(
        0.3,
        minimum=0.0,
        maximum=50.0,
        doc="landing: downward extra pull below this does not make the drone descend [N]",
    )
    debounce_s: float = spec(
        0.2, minimum=0.0, maximum=5.0, doc="a pull must last this long to count [s]"
    )
    baseline_time_constant_s: float = spec(
        3.0,
        minimum=0.1,
        maximum=120.0,
        doc="time constant of the learnt pull of the cable itself, while idle [s]",
    )
    follow_gain_mps_per_n: float = spec(
        0.4, exclusive_minimum=0.0, maximum=5.0, doc="target speed per newton of extra pull [m/s/N]"
    )
    max_horizontal_speed_mps: float = spec(
        1.0, exclusive_minimum=0.0, maximum=5.0, doc="largest horizontal target speed [m/s]"
    )
    max_descent_speed_mps: float = spec(
        0.7, exclusive_minimum=0.0, maximum=3.0, doc="largest descent target speed [m/s]"
    )
    position_lead_m: float = spec(
        0.5,
        exclusive_minimum=0.0,
        maximum=5.0,
        doc="position command: target this far ahead of the drone along the pull [m]",
    )
    land_height_m: float = spec(
        0.5,
        minimum=0.1,
        maximum=10.0,
        doc="landing: below this height the autopilot's LAND is commanded [m]",
    )
    min_anchor_distance_m: float = spec(
        0.3,
        exclusive_minimum=0.0,
        doc="closer (horizontally) to the anchor the cable's own horizontal pull is taken as 0 [m]",
    )
    max_tension_age_s: float = spec(
        0.3, exclusive_minimum=0.0, maximum=5.0, doc="older tension estimates count as lost [s]"
    )
    max_tension_n: float = spec(
        60.0, exclusive_minimum=0.0, doc="larger tension estimates are absurd and count as lost [N]"
    )
    lost_timeout_s: float = spec(
        0.5,
        minimum=0.0,
        maximum=10.0,
        doc="inputs lost this long while active make the autopilot LAND [s]",
    )

    def validate(self) -> None:
        """Release thresholds below start thresholds; at least one guided mode."""
        if self.horizontal_release_n >= self.horizontal_threshold_n:
            raise ConfigError(
                "",
                "horizontal_release_n",
                self.horizontal_release_n,
                f"must be < horizontal_threshold_n ({self.horizontal_threshold_n})",
            )
        if self.vertical_release_n >= self.vertical_threshold_n:
            raise ConfigError(
                "",
                "vertical_release_n",
                self.vertical_release_n,
                f"must be < vertical_threshold_n ({self.vertical_threshold_n})",
            )
        if not self.guided_modes or not all(name.strip() for name in self.guided_modes):
            raise ConfigError(
                "", "guided_modes", self.guided_modes, "must list at least one mode name"
            )
        if self.max_tension_n <= self.horizontal_threshold_n:
            raise ConfigError(
                "",
                "max_tension_n",
                self.max_tension_n,
                f"must exceed horizontal_threshold_n ({self.horizontal_threshold_n})",
            )


def load_tension_mode_config(path: str | Path) -> TensionModeConfig:
    """Load a :class:`TensionModeConfig` from YAML (ConfigError names file, key and value)."""
    return load_yaml(TensionModeConfig, path)
