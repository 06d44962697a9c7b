"""Vehicle profiles: mass, inertia, motor geometry and thrust curve of a multicopter.

Loaded from YAML files in ``configs/vehicles/``. Motor geometry is a named ``frame``
(:mod:`tether_companion.physics.frames`, the autopilots' numbering: motor ``i`` is
SERVO_OUTPUT_RAW ``servo{i}_raw``) or an explicit ``motors`` list.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tether_companion.config import ConfigError, load_yaml, spec
from tether_companion.physics.battery import BatteryCompensation
from tether_companion.physics.frames import FRAME_NAMES, FRAMES
from tether_companion.physics.motor_layout import Motor
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.resources import VEHICLES_DIR, builtin_path

FloatArray = NDArray[np.float64]


QUAD_X_ARDUPILOT: tuple[Motor, ...] = FRAMES["quad-x"]
"""ArduPilot Copter quad X: motor 1 front-right, 2 back-left, 3 front-left, 4 back-right."""


@dataclass(frozen=True)
class VehicleProfile:
    """Rigid-body and propulsion parameters of a multicopter (SI units)."""

    name: str = spec("default-quad", doc="profile name")
    mass_kg: float = spec(1.5, exclusive_minimum=0.0, doc="take-off mass [kg]")
    inertia_kg_m2: tuple[float, float, float] = spec(
        (0.015, 0.015, 0.025), exclusive_minimum=0.0, doc="principal moments (Jx, Jy, Jz) [kg m^2]"
    )
    arm_length_m: float = spec(0.25, exclusive_minimum=0.0, doc="centre to rotor axis [m]")
    yaw_moment_per_thrust_m: float = spec(
        0.016, minimum=0.0, doc="rotor drag torque per unit thrust [N m / N]"
    )
    drag_coefficient_n_s_per_m: float = spec(
        0.0, minimum=0.0, doc="isotropic linear drag on the airframe, NED [N per m/s] (legacy)"
    )
    rotor_drag_per_s: float = spec(
        0.0,
        minimum=0.0,
        maximum=2.0,
        doc="rotor drag mu: body-horizontal a = -mu v_air [1/s] (ArduPilot EK3_DRAG_MCOEF; "
        "0.1-0.3 on small multirotors)",
    )
    ballistic_coefficient_kg_per_m2: float = spec(
        0.0,
        minimum=0.0,
        doc="quadratic body drag B = m/(Cd A) [kg/m^2] (ArduPilot EK3_DRAG_BCOEF_X/Y); 0 = none",
    )
    motor_time_constant_s: float = spec(
        0.04, exclusive_minimum=0.0, doc="first-order lag of each motor's thrust [s]"
    )
    thrust_curve: ThrustCurve = spec(default_factory=ThrustCurve, doc="static PWM-to-thrust map")
    battery: BatteryCompensation = spec(
        default_factory=BatteryCompensation,
        doc="thrust scaled by the measured battery voltage (as ArduPilot's MOT_BAT_VOLT_*)",
    )
    frame: str = spec(
        "custom",
        choices=("custom", *FRAME_NAMES),
        doc="motor layout by name (sets motors); 'custom' takes the motors list",
    )
    motors: tuple[Motor, ...] = spec(QUAD_X_ARDUPILOT, doc="rotors in output-channel order")

    def __post_init__(self) -> None:
        if self.frame != "custom" and self.motors == QUAD_X_ARDUPILOT:
            object.__setattr__(self, "motors", FRAMES[self.frame])

    def validate(self) -> None:
        """A profile must be able to hover, have at least 4 motors and one motor layout."""
        if self.frame != "custom" and self.motors != FRAMES[self.frame]:
            raise ConfigError(
                "", "motors", len(self.motors), f"give either frame ({self.frame!r}) or motors"
            )
        if len(self.motors) < 4:
            raise ConfigError("", "motors", len(self.motors), "at least 4 motors are needed")
        capacity = self.thrust_curve.max_thrust_n * len(self.motors)
        weight = self.mass_kg * 9.80665
        if capacity <= weight:
            raise ConfigError(
                "",
                "thrust_curve",
                capacity,
                f"total maximum thrust must exceed the weight ({weight:.2f} N)",
            )

    @property
    def n_motors(self) -> int:
        """Number of rotors."""
        return len(self.motors)

    def allocation_matrix(self) -> FloatArray:
        """Map motor thrusts [N] to (total thrust [N], roll, pitch, yaw torque [N m]).

        Shape (4, n_motors). Thrust acts along body -z (up); torques are about the FRD body
        axes: a rotor at body (x, y) gives roll ``-y f`` and pitch ``x f``; a ``ccw`` rotor
        gives yaw ``+k f`` (Martins 2019 eq. 3-5 for a general layout).
        """
        columns = []
        for motor in self.motors:
            angle = math.radians(motor.angle_deg)
            radius = self.arm_length_m * motor.radius_scale
            x = radius * math.cos(angle)
            y = radius * math.sin(angle)
            yaw = self.yaw_moment_per_thrust_m * (1.0 if motor.spin == "ccw" else -1.0)
            columns.append((1.0, -y, x, yaw))
        return np.array(columns, dtype=float).T


def load_vehicle(name_or_path: str | Path) -> VehicleProfile:
    """Load a vehicle profile by built-in name (``configs/vehicles/NAME.yaml``) or file path.

    Raises
    ------
    ConfigError
        When the file is missing or any value is invalid.
    """
    path = Path(name_or_path)
    if not path.suffix:
        try:
            path = builtin_path(VEHICLES_DIR, str(name_or_path))
        except FileNotFoundError as exc:
            raise ConfigError(str(name_or_path), "", str(name_or_path), str(exc)) from None
    return load_yaml(VehicleProfile, path)
