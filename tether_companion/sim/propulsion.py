"""What the motors really give for a PWM: the profile's curve times a scale error and the
battery's sag (the truth side; the estimator only sees the profile's curve and the voltage).

A brushless motor's speed at a given duty cycle is proportional to the battery voltage, so a
command ``u`` at voltage ``V`` gives the thrust the profile's curve gives for ``u V / V_ref``,
with ``V_ref`` the voltage the curve was measured at (``ThrustCurve.thrust_n(pwm,
voltage_ratio)``, the assumption of ArduPilot's thrust linearisation, whose
``MOT_BAT_VOLT_MAX/MIN`` compensation undoes it); the true thrust is that times
``thrust_scale``. Our simulated flight controller, like an uncompensated one, leaves the sag
to its integrators. The voltage falls linearly with time at ``sag_v_per_cell_per_min`` (a
LiPo in a steady hover: about 0.05-0.15 V per cell per minute over the flat part of its
discharge curve) and never below ``empty_cell_voltage_v``.
"""

from __future__ import annotations

from dataclasses import dataclass

from tether_companion.config import ConfigError, spec


@dataclass(frozen=True)
class BatteryConfig:
    """The ``propulsion.battery`` section: a LiPo pack's voltage over the flight."""

    cells: int = spec(4, minimum=1, maximum=14, doc="cells in series")
    full_cell_voltage_v: float = spec(
        4.2, minimum=3.0, maximum=4.4, doc="cell voltage at the start [V]"
    )
    reference_cell_voltage_v: float = spec(
        4.2,
        minimum=3.0,
        maximum=4.4,
        doc="cell voltage the vehicle profile's thrust curve holds at [V]",
    )
    empty_cell_voltage_v: float = spec(
        3.3, minimum=2.5, maximum=4.0, doc="cell voltage the pack sags no lower than [V]"
    )
    sag_v_per_cell_per_min: float = spec(
        0.0, minimum=0.0, maximum=1.0, doc="voltage drop per cell per minute of flight [V/min]"
    )

    def validate(self) -> None:
        """The pack cannot start below empty."""
        if self.full_cell_voltage_v <= self.empty_cell_voltage_v:
            raise ConfigError(
                "",
                "full_cell_voltage_v",
                self.full_cell_voltage_v,
                f"must be > empty_cell_voltage_v ({self.empty_cell_voltage_v})",
            )

    def voltage_v(self, time_s: float) -> float:
        """Pack voltage [V] at ``time_s`` seconds into the flight."""
        cell = self.full_cell_voltage_v - self.sag_v_per_cell_per_min * time_s / 60.0
        return self.cells * max(cell, self.empty_cell_voltage_v)


@dataclass(frozen=True)
class PropulsionConfig:
    """The ``propulsion`` section: how the real thrust differs from the profile's curve."""

    thrust_scale: float = spec(
        1.0,
        minimum=0.5,
        maximum=1.5,
        doc="true thrust / the profile curve's thrust at the reference voltage (prop wear, "
        "air density, a curve fitted elsewhere: +-10 % is common)",
    )
    battery: BatteryConfig = spec(default_factory=BatteryConfig, doc="battery pack")

    def voltage_ratio(self, time_s: float) -> float:
        """Battery voltage over the voltage the profile's curve holds at, at ``time_s`` [-]."""
        b = self.battery
        return b.voltage_v(time_s) / (b.cells * b.reference_cell_voltage_v)

    @property
    def exact(self) -> bool:
        """True when the real thrust is the profile's curve at every moment."""
        b = self.battery
        return (
            self.thrust_scale == 1.0
            and b.sag_v_per_cell_per_min == 0.0
            and b.full_cell_voltage_v == b.reference_cell_voltage_v
        )
