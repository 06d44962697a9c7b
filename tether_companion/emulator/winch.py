"""The ground station's winch, emulated: WINCH_STATUS from the simulated cable.

A real ground-station winch reports its line length from a drum encoder, its tension from a
load cell at the winch (in kilogram-force, as common.xml says), at ~10 Hz, from its own
system/component id; the autopilot routes the frames unchanged to the companion.
:class:`EmulatedWinch` does that from the simulator's cable. The length is the drum encoder of
:class:`~tether_companion.sim.ground_sensors.GroundSensors`, the offline simulator's, with the
scenario's ``ground_station`` errors and rate (off: the exact ``paid_out_m`` at
``winch_rate_hz``; on, as the realistic scenarios have it: a per-flight scale error and zero
offset, the latency, the steps, the cable's stretch the encoder does not see). The tension is
the one at the drone less the hanging cable's weight ``w h`` (a heavy cable's tension falls by
that from the drone down to the winch), with the load cell's noise of ``emulator.winch``: near
zero it reads below zero at times, as a load cell does (the service passes such readings and
the dynamic filter takes them down to 5 noise standard deviations below zero; clamped at zero
they averaged above the true tension, docs/estimation-history.md sag15). Every
random draw comes from the sensors' own generators (seeded from the scenario's seed), so
switching the winch on does not change the simulated flight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tether_companion.config import spec
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.mavlink.framing import FrameEncoder, dialect
from tether_companion.physics.cable import cable_weight_n_per_m
from tether_companion.sim.ground_sensors import GroundSensors
from tether_companion.sim.scenario import Scenario
from tether_companion.sim.simulator import Simulator

_KGF_N = GRAVITY_MPS2
"""WINCH_STATUS.tension is in kilogram-force: newtons per kgf."""
_SEED_SALT = 9005
"""Mixed into the scenario's seed for the load cell's noise (WINCH_STATUS's message id)."""


@dataclass(frozen=True)
class EmulatedWinchConfig:
    """The ``emulator.winch`` section: a ground-station winch sending WINCH_STATUS (its length's
    rate and errors: the scenario's ``ground_station`` section)."""

    enabled: bool = spec(False, doc="send WINCH_STATUS from the simulated cable")
    system_id: int = spec(255, minimum=1, maximum=255, doc="the winch's MAVLink system id")
    component_id: int = spec(
        dialect.MAV_COMP_ID_WINCH, minimum=0, maximum=255, doc="its component id (169: winch)"
    )
    tension_noise_std_n: float = spec(0.2, minimum=0.0, doc="load cell noise at the winch [N]")
    tension_resolution_kg: float = spec(
        0.01, minimum=0.0, doc="load cell step, in the message's kilogram-force (0: none) [kg]"
    )


class EmulatedWinch:
    """Builds the winch's WINCH_STATUS frames (see the module docstring).

    Parameters
    ----------
    config
        The ``emulator.winch`` section.
    scenario
        The simulated world (its cable's weight, its seed, its ``ground_station`` rate).
    sensors
        The ground station's sensors of this flight (shared with the cable-angle sensor).
    unix_time_at_start_s
        UNIX time of simulation time 0 [s]: the winch stamps in UNIX time (its own clock).
    """

    def __init__(
        self,
        config: EmulatedWinchConfig,
        scenario: Scenario,
        sensors: GroundSensors,
        unix_time_at_start_s: float,
    ) -> None:
        self.config = config
        self._encoder = FrameEncoder(config.system_id, config.component_id)
        self._rng = np.random.default_rng([scenario.seed, _SEED_SALT])
        cable = scenario.cable
        self._weight_n_per_m = cable_weight_n_per_m(cable)
        self._sensors = sensors
        self._unix0_s = unix_time_at_start_s
        self.period_s = 1.0 / scenario.ground_station.winch_rate_hz
        self.next_s = 0.0
        """Simulation time of the next report [s]."""
        self.sent = 0
        self._last_paid_out_m = math.nan

    def frame(self, sim: Simulator) -> bytes:
        """The next WINCH_STATUS frame, measured now (the sensors have recorded the state
        now); schedules the one after."""
        self.next_s = sim.time_s + self.period_s
        cfg = self.config
        rng = self._rng
        cable = sim.cable
        length = self._sensors.winch_length_m(sim.time_s)
        height = max(0.0, -sim.position_ned_m[2])
        tension_n = cable.tension_n - self._weight_n_per_m * height
        tension_n += cfg.tension_noise_std_n * rng.standard_normal()
        tension_kg = tension_n / _KGF_N  # near zero the noise reads below it, as a load cell's
        status = dialect.MAV_WINCH_STATUS_HEALTHY
        if cable.paid_out_m <= 0.0:
            status |= dialect.MAV_WINCH_STATUS_FULLY_RETRACTED
        # the drum's speed over the last period (nan for the first report)
        speed = (cable.paid_out_m - self._last_paid_out_m) / self.period_s
        self._last_paid_out_m = cable.paid_out_m
        if abs(speed) > 0.01:
            status |= dialect.MAV_WINCH_STATUS_MOVING
        msg = dialect.MAVLink_winch_status_message(
            int((self._unix0_s + sim.time_s) * 1e6),
            max(0.0, length),
            float(speed),
            _quantised(tension_kg, cfg.tension_resolution_kg),
            math.nan,  # voltage, current, temperature: unknown
            math.nan,
            32767,
            status,
        )
        self.sent += 1
        return self._encoder.encode(msg)


def _quantised(value: float, step: float) -> float:
    return round(value / step) * step if step > 0.0 else value
