"""A vehicle profile from an autopilot's parameter set and the take-off mass (pure)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from tether_companion.config import ConfigError
from tether_companion.physics.battery import BatteryCompensation
from tether_companion.physics.frames import FRAMES
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.vehicle_params import ardupilot, px4

MIN_MASS_KG = 0.005
MAX_MASS_KG = 500.0


def profile_from_parameters(
    params: Mapping[str, float],
    mass_kg: float,
    base: VehicleProfile | None = None,
    *,
    source: str = "",
) -> VehicleProfile:
    """The profile the flight controller flies by: frame, PWM range, thrust curve and battery
    compensation from its parameters, the scale from the hover throttle and ``mass_kg``.

    Parameters
    ----------
    params
        Parameter names to values (PARAM_VALUE, dataflash PARM or ULog parameters).
    mass_kg
        Take-off mass [kg], given by the user (no autopilot parameter holds it).
    base
        Where the keys the parameters do not give (inertia, arm length for ArduPilot, motor
        lag, drag) come from; the default profile when None.
    source
        Where the parameters came from, for error messages.

    Raises
    ------
    ConfigError
        Naming the parameter and its value when one is missing, out of its documented range,
        contradicts another (MOT_SPIN_MIN >= MOT_SPIN_MAX) or names an unsupported frame.
    """
    base = base or VehicleProfile()
    if not MIN_MASS_KG <= mass_kg <= MAX_MASS_KG:
        raise ConfigError(
            source, "mass_kg", mass_kg, f"must be in [{MIN_MASS_KG}, {MAX_MASS_KG}] kg"
        )
    if ardupilot.is_ardupilot(params):
        where = source or ardupilot.SOURCE
        frame = ardupilot.frame_name(params, where)
        n_motors = len(FRAMES[frame])
        profile = dataclasses.replace(
            base,
            name=f"from-ardupilot-{frame}",
            mass_kg=mass_kg,
            frame=frame,
            motors=FRAMES[frame],
            thrust_curve=ardupilot.thrust_curve(params, mass_kg, n_motors, where),
            battery=ardupilot.battery_compensation(params, where) or BatteryCompensation(),
        )
    elif px4.is_px4(params):
        where = source or px4.SOURCE
        arm_m, motors = px4.geometry(params, where)
        profile = dataclasses.replace(
            base,
            name=f"from-px4-{len(motors)}-rotors",
            mass_kg=mass_kg,
            arm_length_m=arm_m,
            frame="custom",
            motors=motors,
            thrust_curve=px4.thrust_curve(params, mass_kg, len(motors), where),
            battery=BatteryCompensation(),
        )
    else:
        raise ConfigError(
            source or "autopilot parameters",
            "FRAME_CLASS",
            "<missing>",
            "neither ArduPilot (FRAME_CLASS) nor PX4 (CA_ROTOR_COUNT) parameters found",
        )
    profile.validate()
    return profile
