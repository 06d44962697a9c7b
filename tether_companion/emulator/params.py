"""The emulator's MAVLink parameters: the simulation's tunables, changeable in flight.

Every parameter is a float on the wire (PARAM_VALUE); whole-number ones are sent with
MAV_PARAM_TYPE_INT32 and their value cast to float, as ArduPilot does, or, in the PX4 flavour,
with the int32's bytes in the float field, as PX4 does (and read back so from PARAM_SET). A
PARAM_SET outside a parameter's range, non-finite, or fractional for an integer parameter is
refused: the reply is the unchanged value and a STATUSTEXT says why. docs/emulator.md lists
them all.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from tether_companion.emulator.config import EmulatorConfig
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.physics.cable import CABLE_MODELS
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.sim.scenario import Scenario
from tether_companion.vehicle_params.emulated import ardupilot_parameters, px4_parameters
from tether_companion.vehicle_params.sources import param_value

PARAM_ID_LEN = 16


@dataclass(frozen=True)
class ParamDef:
    """One parameter: name (<= 16 characters), default, range, integer or not, meaning."""

    name: str
    default: float
    minimum: float
    maximum: float
    doc: str
    integer: bool = False

    def check(self, value: float) -> str | None:
        """Why ``value`` is refused, or None when it is acceptable."""
        if not math.isfinite(value):
            return "not a finite number"
        if not self.minimum <= value <= self.maximum:
            return f"outside [{self.minimum:g}, {self.maximum:g}]"
        if self.integer and not float(value).is_integer():
            return "must be a whole number"
        return None


NAV_SOURCE_GPS = 3
"""EK3_SRC1_POSXY value for GPS: the emulator flies on true position."""
NAV_SOURCE_EXTERNAL = 6
"""EK3_SRC1_POSXY value for ExternalNav: the emulator flies on received estimates."""


def parameter_definitions(scenario: Scenario, config: EmulatorConfig) -> list[ParamDef]:
    """The parameter table, with defaults taken from the scenario and emulator settings."""
    cable, sensors, faults = scenario.cable, scenario.sensors, config.faults
    wind = scenario.wind.velocity_ned_m_s
    models = ", ".join(f"{i} {name}" for i, name in enumerate(CABLE_MODELS))
    return [
        ParamDef("SYSID_THISMAV", config.system_id, 1, 255, "MAVLink system id (read only)", True),
        ParamDef(
            "EK3_SRC1_POSXY",
            NAV_SOURCE_EXTERNAL if config.navigation == "vision" else NAV_SOURCE_GPS,
            0,
            6,
            f"position source: {NAV_SOURCE_GPS} GPS (fly on truth), {NAV_SOURCE_EXTERNAL} "
            "ExternalNav (fly on VISION_POSITION_ESTIMATE)",
            True,
        ),
        ParamDef(
            "VISO_TYPE", 1, 0, 1, "visual odometry: 0 none (estimates ignored), 1 MAVLink", True
        ),
        ParamDef("LAND_SPEED", 50, 30, 200, "descent speed in LAND [cm/s]", True),
        ParamDef(
            "DISARM_DELAY", 10, 0, 127, "auto-disarm after this long landed [s] (0 = never)", True
        ),
        ParamDef(
            "TETH_MODEL",
            CABLE_MODELS.index(cable.model),
            0,
            len(CABLE_MODELS) - 1,
            f"cable model: {models} (a change re-attaches the cable)",
            True,
        ),
        ParamDef(
            "TETH_TENSION",
            cable.tension_n,
            0.0,
            100.0,
            "winch tension, constant_tension and winch_catenary (at the anchor) [N]",
        ),
        ParamDef(
            "TETH_LENGTH",
            cable.length_m,
            cable.min_length_m,
            cable.spool_length_m,
            "paid-out length, elastic and catenary [m]",
        ),
        ParamDef(
            "TETH_WINCH_RATE", cable.winch_rate_mps, -10.0, 10.0, "winch rate, + pays out [m/s]"
        ),
        ParamDef("TETH_STIFFNESS", cable.stiffness_n_per_m, 1e-3, 1e6, "axial stiffness [N/m]"),
        ParamDef("TETH_DAMPING", cable.damping_n_s_per_m, 0.0, 1e4, "axial damping [N s/m]"),
        ParamDef(
            "TETH_DENSITY", cable.linear_density_kg_per_m, 0.0, 10.0, "cable mass per length [kg/m]"
        ),
        ParamDef("TETH_RELEASE", 0, 0, 1, "1 lets the tether go (TETH_MODEL re-attaches)", True),
        ParamDef(
            "SIM_ACC_NOISE",
            sensors.accel_noise_std_mps2,
            0.0,
            50.0,
            "accelerometer noise sigma [m/s^2]",
        ),
        ParamDef(
            "SIM_GYR_NOISE", sensors.gyro_noise_std_rad_s, 0.0, 10.0, "gyro noise sigma [rad/s]"
        ),
        ParamDef(
            "SIM_ATT_NOISE", sensors.attitude_noise_std_rad, 0.0, 1.0, "attitude noise sigma [rad]"
        ),
        ParamDef(
            "SIM_RNG_NOISE", sensors.range_noise_std_m, 0.0, 10.0, "rangefinder noise sigma [m]"
        ),
        ParamDef(
            "SIM_VIB_AMP",
            sensors.accel_vibration_amplitude_mps2,
            0.0,
            100.0,
            "accelerometer vibration amplitude [m/s^2]",
        ),
        ParamDef(
            "SIM_ATT_ERR",
            sensors.attitude_error_std_rad,
            0.0,
            0.2,
            "the FC's attitude-estimate error sigma (Gauss-Markov) [rad]",
        ),
        *(
            ParamDef(
                f"SIM_ACC_BIAS_{axis}",
                sensors.accel_bias_mps2[i],
                -5.0,
                5.0,
                f"accelerometer bias, body {axis.lower()} [m/s^2]",
            )
            for i, axis in enumerate("XYZ")
        ),
        ParamDef(
            "SIM_THR_SCALE",
            scenario.propulsion.thrust_scale,
            0.5,
            1.5,
            "true thrust / the profile's curve at the reference voltage",
        ),
        ParamDef(
            "SIM_BATT_SAG",
            scenario.propulsion.battery.sag_v_per_cell_per_min,
            0.0,
            1.0,
            "battery sag per cell [V/min]",
        ),
        ParamDef(
            "SIM_WIND_TURB",
            scenario.wind.turbulence_w20_mps,
            0.0,
            25.0,
            "Dryden turbulence: wind at 6.1 m setting its intensity (0 = none) [m/s]",
        ),
        ParamDef("SIM_WIND_N", wind[0], -30.0, 30.0, "wind velocity north [m/s]"),
        ParamDef("SIM_WIND_E", wind[1], -30.0, 30.0, "wind velocity east [m/s]"),
        ParamDef("SIM_WIND_D", wind[2], -30.0, 30.0, "wind velocity down [m/s]"),
        ParamDef(
            "EMU_DROP_PCT", 100 * faults.drop_probability, 0.0, 100.0, "sent frames dropped [%]"
        ),
        ParamDef(
            "EMU_DUP_PCT",
            100 * faults.duplicate_probability,
            0.0,
            100.0,
            "sent frames duplicated [%]",
        ),
        ParamDef(
            "EMU_CORRUPT_PCT",
            100 * faults.corrupt_probability,
            0.0,
            100.0,
            "sent frames with a flipped byte [%]",
        ),
        ParamDef("EMU_DELAY_MS", faults.delay_ms, 0.0, 5000.0, "extra latency of sent frames [ms]"),
        ParamDef("EMU_JITTER_MS", faults.delay_jitter_ms, 0.0, 5000.0, "random extra latency [ms]"),
        ParamDef("EMU_RNG_OOR", 0, 0, 1, "1 forces the rangefinder out of range", True),
    ]


_VEHICLE_PARAM_DOCS = {
    "FRAME_CLASS": ("frame class (1 quad, 2 hexa, 3 octa, 4 octaquad, 5 Y6)", True),
    "FRAME_TYPE": ("frame type (0 +, 1 X, 2 V, 3 H)", True),
    "MOT_PWM_MIN": ("PWM at zero output [us]", True),
    "MOT_PWM_MAX": ("PWM at full output [us]", True),
    "MOT_SPIN_MIN": ("output where thrust starts (0-1)", False),
    "MOT_SPIN_MAX": ("output where thrust saturates (0-1)", False),
    "MOT_THST_EXPO": ("thrust curve expo", False),
    "MOT_THST_HOVER": ("hover throttle (thrust demand, 0-1)", False),
    "MOT_BAT_VOLT_MAX": ("battery compensation maximum voltage [V] (0 = off)", False),
    "MOT_BAT_VOLT_MIN": ("battery compensation minimum voltage [V]", False),
}


def _px4_doc(name: str) -> tuple[str, bool]:
    """Meaning and integer-ness of a PX4 vehicle parameter (per-rotor names by their suffix)."""
    fixed = {
        "CA_AIRFRAME": ("airframe (0 multirotor)", True),
        "CA_ROTOR_COUNT": ("number of rotors", True),
        "THR_MDL_FAC": ("thrust model factor (0 linear, 1 quadratic)", False),
        "MPC_THR_HOVER": ("hover thrust (collective demand, 0-1)", False),
    }
    if name in fixed:
        return fixed[name]
    for prefix, doc, integer in (
        ("PWM_MAIN_MIN", "PWM at zero output [us]", True),
        ("PWM_MAIN_MAX", "PWM at full output [us]", True),
        ("PWM_MAIN_FUNC", "output function (101 = Motor 1)", True),
    ):
        if name.startswith(prefix):
            return doc, integer
    suffix = {"_PX": "rotor position, body x [m]", "_PY": "rotor position, body y [m]"}
    return suffix.get(name[-3:], "rotor moment ratio (> 0 ccw, < 0 cw)"), False


def vehicle_parameter_definitions(
    vehicle: VehicleProfile, autopilot: str = "ardupilot"
) -> list[ParamDef]:
    """The frame and motor parameters of the simulated vehicle (read only) as ArduPilot or
    PX4 names them, so that a companion can build its profile with ``vehicle:
    from_autopilot``; none when the autopilot's parameters cannot express the profile (a
    raw-command or custom-layout vehicle)."""
    try:
        values = px4_parameters(vehicle) if autopilot == "px4" else ardupilot_parameters(vehicle)
    except ValueError:
        return []
    docs = {
        name: _px4_doc(name) if autopilot == "px4" else _VEHICLE_PARAM_DOCS[name] for name in values
    }
    return [
        ParamDef(name, value, value, value, doc + " (read only: the simulated vehicle's)", integer)
        for name, value in values.items()
        for doc, integer in (docs[name],)
    ]


class ParameterStore:
    """Values of a parameter table, with the PARAM_VALUE encoding.

    Parameters
    ----------
    definitions
        The table (order = index on the wire).
    apply
        Called as ``apply(name, value)`` with the new value already stored; it may raise
        ``ValueError`` to refuse it (the old value is restored and the message reported).
    read_only
        Names that cannot be set.
    bytewise
        Integer parameters travel as their int32's bytes in the float field (PX4), not as a
        float value (ArduPilot).
    """

    def __init__(
        self,
        definitions: Sequence[ParamDef],
        apply: Callable[[str, float], None],
        read_only: frozenset[str] = frozenset({"SYSID_THISMAV"}),
        *,
        bytewise: bool = False,
    ) -> None:
        self.definitions = {d.name: d for d in definitions}
        self._names = [d.name for d in definitions]
        self._index = {name: i for i, name in enumerate(self._names)}
        self._values = {d.name: float(d.default) for d in definitions}
        self._apply = apply
        self._read_only = read_only
        self.bytewise = bytewise
        for name in self._names:
            if len(name) > PARAM_ID_LEN:
                raise ValueError(f"parameter name {name!r} is longer than 16 characters")

    def __len__(self) -> int:
        return len(self._names)

    def __contains__(self, name: object) -> bool:
        return name in self._values

    @property
    def names(self) -> list[str]:
        """Names in wire order."""
        return list(self._names)

    def value(self, name: str) -> float:
        """Current value of ``name``."""
        return self._values[name]

    def name_at(self, index: int) -> str | None:
        """Name at wire index ``index``, or None."""
        return self._names[index] if 0 <= index < len(self._names) else None

    def set(self, name: str, value: float) -> str | None:
        """Set ``name`` to ``value``; returns why it was refused, or None when it was taken."""
        if name in self._read_only:
            return "read only"
        why = self.definitions[name].check(value)
        if why is not None:
            return why
        previous = self._values[name]
        self._values[name] = float(value)  # stored first: apply() may read the new value
        try:
            self._apply(name, float(value))
        except ValueError as exc:
            self._values[name] = previous
            return str(exc)
        return None

    def override(self, name: str, value: float) -> str | None:
        """Answer ``value`` for ``name`` from now on: a read-only parameter takes any value
        (a misconfigured autopilot), another one is set as by PARAM_SET. Returns why it was
        refused (unknown name, a refused value), or None."""
        if name not in self._values:
            return "unknown parameter"
        if self.bytewise and self.definitions[name].integer and not float(value).is_integer():
            return "must be a whole number (an integer parameter)"
        if name in self._read_only:
            self._values[name] = float(value)
            return None
        return self.set(name, value)

    def decode(self, value: float, param_type: int) -> float:
        """A PARAM_SET's value (bytewise integers in the PX4 flavour)."""
        return param_value(value, param_type, self.bytewise)

    def force(self, name: str, value: float) -> None:
        """Record a value changed by the emulator itself (no checks, no apply)."""
        self._values[name] = float(value)

    def message(self, name: str) -> MAVLinkMessage:
        """PARAM_VALUE for ``name``."""
        definition = self.definitions[name]
        param_type = (
            dialect.MAV_PARAM_TYPE_INT32 if definition.integer else dialect.MAV_PARAM_TYPE_REAL32
        )
        value = self._values[name]
        if self.bytewise and definition.integer:
            value = struct.unpack("<f", struct.pack("<i", int(value)))[0]
        return dialect.MAVLink_param_value_message(
            name.encode("ascii"),
            value,
            param_type,
            len(self._names),
            self._index[name],
        )
