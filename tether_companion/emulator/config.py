"""Emulator settings: identity, navigation source, stream rates, fault injection.

They come from the optional ``emulator:`` section of a scenario file (everything else in the
file is the simulator's :class:`~tether_companion.sim.scenario.Scenario`) and from command-line
flags, which override the file. Example::

    emulator:
      navigation: vision
      stream_rates_hz: {RAW_IMU: 400, SIM_STATE: 0}
      parameters: {MOT_SPIN_MIN: 0.5}
      faults:
        drop_probability: 0.01
        outages: [{stream: ATTITUDE, start_s: 10, duration_s: 0.5}]
        reboots_s: [30]
      winch: {enabled: true, tension_noise_std_n: 0.2}
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tether_companion.config import ConfigError, from_mapping, read_yaml, spec
from tether_companion.emulator.cable_angle import EmulatedCableAngleConfig
from tether_companion.emulator.streams import STREAMS
from tether_companion.emulator.winch import EmulatedWinchConfig
from tether_companion.sim.scenario import Scenario, resolve_scenario_path, scenario_from_mapping

NAVIGATION_SOURCES: tuple[str, ...] = ("truth", "vision")
AUTOPILOTS: tuple[str, ...] = ("ardupilot", "px4")
MAX_STREAM_RATE_HZ = 1000.0


@dataclass(frozen=True)
class Window:
    """A time window in simulation time [s] from the start of the run."""

    start_s: float = spec(minimum=0.0, doc="window start [s]")
    duration_s: float = spec(exclusive_minimum=0.0, doc="window length [s]")

    def contains(self, time_s: float) -> bool:
        """True when ``start_s <= time_s < start_s + duration_s``."""
        return self.start_s <= time_s < self.start_s + self.duration_s


@dataclass(frozen=True)
class Outage:
    """One stream that stops sending for a window (a sensor or link fault)."""

    stream: str = spec(doc="message name, e.g. RAW_IMU")
    start_s: float = spec(minimum=0.0, doc="outage start [s]")
    duration_s: float = spec(exclusive_minimum=0.0, doc="outage length [s]")

    def validate(self) -> None:
        """The stream must be one the emulator sends."""
        if self.stream not in STREAMS:
            raise ConfigError("", "stream", self.stream, f"must be one of {', '.join(STREAMS)}")

    def contains(self, time_s: float) -> bool:
        """True inside the outage."""
        return self.start_s <= time_s < self.start_s + self.duration_s


@dataclass(frozen=True)
class FaultConfig:
    """Faults injected on what the emulator sends (drop, delay, duplication, corruption) and
    in the flight controller itself (stream outages, reboots, rangefinder out of range)."""

    drop_probability: float = spec(0.0, minimum=0.0, maximum=1.0, doc="chance each frame is lost")
    duplicate_probability: float = spec(
        0.0, minimum=0.0, maximum=1.0, doc="chance a frame is sent twice"
    )
    corrupt_probability: float = spec(
        0.0, minimum=0.0, maximum=1.0, doc="chance a frame has one byte flipped (fails its CRC)"
    )
    delay_ms: float = spec(
        0.0, minimum=0.0, maximum=5000.0, doc="extra latency of every frame [ms]"
    )
    delay_jitter_ms: float = spec(
        0.0, minimum=0.0, maximum=5000.0, doc="uniform random extra latency on top [ms] (reorders)"
    )
    outages: tuple[Outage, ...] = spec((), doc="stream outages")
    reboots_s: tuple[float, ...] = spec(
        (), minimum=0.0, doc="flight-controller reboots at these times [s]"
    )
    rangefinder_out_of_range: tuple[Window, ...] = spec(
        (), doc="windows in which the rangefinder reports out of range"
    )


@dataclass(frozen=True)
class EmulatorConfig:
    """The ``emulator`` section of a scenario file."""

    system_id: int = spec(
        1, minimum=1, maximum=255, doc="MAVLink system id of the flight controller"
    )
    component_id: int = spec(1, minimum=1, maximum=255, doc="MAVLink component id (1 = autopilot)")
    navigation: str = spec(
        "truth",
        choices=NAVIGATION_SOURCES,
        doc="truth: fly on true position; vision: on received estimates",
    )
    stream_rates_hz: dict[str, float] = spec(
        default_factory=dict,
        minimum=0.0,
        maximum=MAX_STREAM_RATE_HZ,
        doc="default rate per message name (0 = off); unnamed streams keep their defaults [Hz]",
    )
    autopilot: str = spec(
        "ardupilot",
        choices=AUTOPILOTS,
        doc="flavour: px4 sends HEARTBEAT autopilot PX4, the vehicle as PX4 parameters "
        "(integers bytewise) and HIGHRES_IMU instead of RAW_IMU; modes stay ArduPilot's",
    )
    parameters: dict[str, float] = spec(
        default_factory=dict,
        doc="values answered instead of the defaults, the read-only vehicle parameters "
        "included (a misconfigured autopilot; the simulated vehicle is unchanged)",
    )
    score_start_s: float = spec(
        0.0, minimum=0.0, doc="estimates stamped before this time are not scored (warm-up) [s]"
    )
    faults: FaultConfig = spec(default_factory=FaultConfig, doc="fault injection")
    winch: EmulatedWinchConfig = spec(
        default_factory=EmulatedWinchConfig,
        doc="a ground-station winch whose WINCH_STATUS the autopilot routes to every link",
    )
    cable_angle: EmulatedCableAngleConfig = spec(
        default_factory=EmulatedCableAngleConfig,
        doc="a ground-station cable-angle sensor whose DEBUG_VECT the autopilot routes to "
        "every link",
    )

    def validate(self) -> None:
        """Stream names must be known."""
        for name in self.stream_rates_hz:
            if name not in STREAMS:
                raise ConfigError(
                    "",
                    f"stream_rates_hz.{name}",
                    name,
                    f"unknown stream; one of {', '.join(STREAMS)}",
                )


def load_emulator_scenario(path_or_name: str | Path) -> tuple[Scenario, EmulatorConfig]:
    """Load a scenario file and its optional ``emulator:`` section.

    The section (default settings without one) is validated here, the rest of the file as
    :func:`~tether_companion.sim.scenario.load_scenario` would read it.

    Raises
    ------
    ConfigError
        Naming the file, key, value and what is allowed.
    """
    path = resolve_scenario_path(path_or_name)
    data = read_yaml(path)
    section = data.get("emulator")
    emulator = (
        EmulatorConfig()
        if section is None
        else from_mapping(EmulatorConfig, section, source=str(path), prefix="emulator")
    )
    rest = {k: v for k, v in data.items() if k != "emulator"}
    return scenario_from_mapping(rest, path), emulator
