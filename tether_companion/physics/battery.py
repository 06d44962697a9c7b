"""Battery voltage and rotor thrust: the voltage ratio ArduPilot's compensation assumes.

A motor's speed follows the voltage its ESC applies, duty cycle times battery voltage, so a
sagging battery gives less thrust for the same command. ArduPilot models this by feeding
``a * v`` (output position times the voltage ratio ``v = V / MOT_BAT_VOLT_MAX``) through its
thrust curve (``AP_Motors_Thrust_Linearization.cpp``; see
:mod:`tether_companion.vehicle_params.ardupilot`); :meth:`ThrustCurve.thrust_n` takes the same
``voltage_ratio``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.config import ConfigError, spec


@dataclass(frozen=True)
class BatteryCompensation:
    """Voltage range of the thrust-vs-voltage model (``voltage_max_v = 0``: no model)."""

    voltage_max_v: float = spec(
        0.0,
        minimum=0.0,
        maximum=100.0,
        doc="voltage at which the thrust curve holds (ArduPilot MOT_BAT_VOLT_MAX) [V]; 0 = off",
    )
    voltage_min_v: float = spec(
        0.0,
        minimum=0.0,
        maximum=100.0,
        doc="lower voltages count as this one (MOT_BAT_VOLT_MIN, at least 0.6 x max) [V]",
    )

    def validate(self) -> None:
        """A model that is on needs min < max."""
        if self.enabled and self.voltage_min_v >= self.voltage_max_v:
            raise ConfigError(
                "",
                "voltage_min_v",
                self.voltage_min_v,
                f"must be < voltage_max_v ({self.voltage_max_v})",
            )

    @property
    def enabled(self) -> bool:
        """Whether thrust depends on the measured voltage."""
        return self.voltage_max_v > 0.0

    def ratio(self, voltage_v: float) -> float:
        """``v = clip(V, max(min, 0.6 max), max) / max``; 1 when off or ``V`` is not finite."""
        if not self.enabled or not math.isfinite(voltage_v):
            return 1.0
        low = max(self.voltage_min_v, 0.6 * self.voltage_max_v)
        return min(max(voltage_v, low), self.voltage_max_v) / self.voltage_max_v
