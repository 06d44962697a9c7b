"""Parameter changes made real in the emulated flight controller's simulation.

:class:`ParameterActions` is one part of the
:class:`~tether_companion.emulator.autopilot.FlightController`:
the parameter store calls :meth:`ParameterActions._apply_param` for every accepted change.
"""

from __future__ import annotations

from dataclasses import replace

from tether_companion.emulator.params import (
    NAV_SOURCE_EXTERNAL,
    NAV_SOURCE_GPS,
)
from tether_companion.mavlink.framing import dialect
from tether_companion.physics.cable import CABLE_MODELS, TENSION_CONTROLLED_MODELS


class ParameterActions:
    """The flight controller's parameter side effects (mixed into ``FlightController``)."""

    def _apply_param(self, name: str, value: float) -> None:
        """Make a parameter change real in the simulation (raises ValueError to refuse)."""
        sim = self.sim
        if name == "EK3_SRC1_POSXY":
            if value not in (NAV_SOURCE_GPS, NAV_SOURCE_EXTERNAL):
                raise ValueError(
                    f"only {NAV_SOURCE_GPS} (GPS) or {NAV_SOURCE_EXTERNAL} (ExternalNav)"
                )
            if self.armed:
                raise ValueError("disarm first")
            self._switch_navigation(value == NAV_SOURCE_EXTERNAL)
        elif name == "VISO_TYPE":
            self.nav.enabled = value == 1
        elif name == "TETH_MODEL":
            self._rebuild_cable(model=CABLE_MODELS[int(value)])
        elif name == "TETH_TENSION":
            if CABLE_MODELS[int(self.params.value("TETH_MODEL"))] not in TENSION_CONTROLLED_MODELS:
                raise ValueError(f"TETH_MODEL is not one of {TENSION_CONTROLLED_MODELS}")
            sim.set_tension_n(value)
        elif name == "TETH_LENGTH":
            sim.set_paid_out_m(value)
        elif name == "TETH_WINCH_RATE":
            sim.set_winch_rate_mps(value)
        elif name in ("TETH_STIFFNESS", "TETH_DAMPING", "TETH_DENSITY"):
            self._rebuild_cable(**{_CABLE_FIELDS[name]: value})
        elif name == "TETH_RELEASE":
            if value == 1:
                sim.release_tether()
            elif sim.cable.released:
                raise ValueError("set TETH_MODEL to re-attach the tether")
        elif name in _SENSOR_FIELDS:
            sim.set_sensor_config(replace(sim.sensor_config, **{_SENSOR_FIELDS[name]: value}))
        elif name in ("SIM_ACC_BIAS_X", "SIM_ACC_BIAS_Y", "SIM_ACC_BIAS_Z"):
            bias = list(sim.sensor_config.accel_bias_mps2)
            bias["XYZ".index(name[-1])] = value
            sim.set_sensor_config(replace(sim.sensor_config, accel_bias_mps2=tuple(bias)))
        elif name == "SIM_THR_SCALE":
            sim.set_propulsion(replace(sim.propulsion, thrust_scale=value))
        elif name == "SIM_BATT_SAG":
            battery = replace(sim.propulsion.battery, sag_v_per_cell_per_min=value)
            sim.set_propulsion(replace(sim.propulsion, battery=battery))
        elif name == "SIM_WIND_TURB":
            sim.set_turbulence_w20_mps(value)
        elif name in ("SIM_WIND_N", "SIM_WIND_E", "SIM_WIND_D"):
            wind = list(sim.wind_ned_m_s)
            wind["NED".index(name[-1])] = value
            sim.set_wind_ned_m_s(wind)
        elif name == "EMU_DROP_PCT":
            self.link_faults.drop_probability = value / 100.0
        elif name == "EMU_DUP_PCT":
            self.link_faults.duplicate_probability = value / 100.0
        elif name == "EMU_CORRUPT_PCT":
            self.link_faults.corrupt_probability = value / 100.0
        elif name == "EMU_DELAY_MS":
            self.link_faults.delay_s = value / 1000.0
        elif name == "EMU_JITTER_MS":
            self.link_faults.delay_jitter_s = value / 1000.0
        elif name == "EMU_RNG_OOR":
            self._rangefinder_param_forced = value == 1

    def _rebuild_cable(self, **changes: object) -> None:
        """Replace the simulator's cable with a fresh one built from the current parameters."""
        values = {
            "model": CABLE_MODELS[int(self.params.value("TETH_MODEL"))],
            "tension_n": self.params.value("TETH_TENSION"),
            "length_m": self.sim.cable.paid_out_m
            if self.sim.cable.paid_out_m > 0
            else self.params.value("TETH_LENGTH"),
            "winch_rate_mps": self.params.value("TETH_WINCH_RATE"),
            "stiffness_n_per_m": self.params.value("TETH_STIFFNESS"),
            "damping_n_s_per_m": self.params.value("TETH_DAMPING"),
            "linear_density_kg_per_m": self.params.value("TETH_DENSITY"),
        }
        values.update(changes)
        cable_config = self.scenario.cable
        values["length_m"] = min(
            max(float(values["length_m"]), cable_config.min_length_m), cable_config.spool_length_m
        )
        self.sim.replace_cable(replace(cable_config, **values))
        self.params.force("TETH_RELEASE", 0.0)

    def _switch_navigation(self, vision: bool) -> None:
        self._text(
            dialect.MAV_SEVERITY_INFO, f"Position source {'ExternalNav' if vision else 'GPS'}"
        )
        if vision:
            self._vision_in_use = False
            self._dead_reckoning = None
        else:
            self.origin = self.origin or self.home
            self.nav.origin_set = True


_CABLE_FIELDS = {
    "TETH_STIFFNESS": "stiffness_n_per_m",
    "TETH_DAMPING": "damping_n_s_per_m",
    "TETH_DENSITY": "linear_density_kg_per_m",
}
_SENSOR_FIELDS = {
    "SIM_ACC_NOISE": "accel_noise_std_mps2",
    "SIM_GYR_NOISE": "gyro_noise_std_rad_s",
    "SIM_ATT_NOISE": "attitude_noise_std_rad",
    "SIM_RNG_NOISE": "range_noise_std_m",
    "SIM_VIB_AMP": "accel_vibration_amplitude_mps2",
    "SIM_ATT_ERR": "attitude_error_std_rad",
}
