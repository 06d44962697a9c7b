"""Thrust scaled by the measured battery voltage as ArduPilot's compensation assumes: its
forward chain with a sagging battery (throttle / lift_max, curve solved with lift_max, divided
by the voltage ratio) must give the same thrust through our curve at that voltage."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_vehicle_params import ARDUPILOT_PLUS

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.thrust_input import MotorLagThrustInput, StaticThrustInput
from tether_companion.mavlink.battery import battery_voltage_v
from tether_companion.mavlink.framing import dialect
from tether_companion.service.config import load_service_config
from tether_companion.service.session import EstimationSession
from tether_companion.vehicle_params.profile import profile_from_parameters

MASS_KG = 3.0


def ardupilot_pulse_us(throttle: float, voltage_v: float, p: dict) -> float:
    """ArduPilot with battery compensation, from AP_Motors_Thrust_Linearization.cpp:
    v = clip(V, max(VMIN, 0.6 VMAX), VMAX) / VMAX, lift_max = v (1 - e) + e v^2,
    thrust = throttle * get_compensation_gain() = throttle / lift_max,
    a = solution of e a^2 + (1 - e) a = lift_max * thrust, divided by v."""
    e, vmax = p["MOT_THST_EXPO"], p["MOT_BAT_VOLT_MAX"]
    v = min(max(voltage_v, max(p["MOT_BAT_VOLT_MIN"], 0.6 * vmax)), vmax) / vmax
    lift_max = v * (1 - e) + e * v * v
    thrust = throttle / lift_max
    ratio = ((e - 1) + math.sqrt((1 - e) ** 2 + 4 * e * lift_max * thrust)) / (2 * e)
    actuator_ratio = min(max(ratio / v, 0.0), 1.0)
    actuator = p["MOT_SPIN_MIN"] + (p["MOT_SPIN_MAX"] - p["MOT_SPIN_MIN"]) * actuator_ratio
    return p["MOT_PWM_MIN"] + (p["MOT_PWM_MAX"] - p["MOT_PWM_MIN"]) * actuator


@pytest.mark.parametrize("voltage_v", [12.8, 12.0, 11.1, 10.0, 9.0])
def test_compensated_outputs_give_the_same_thrust_at_any_voltage(voltage_v: float) -> None:
    profile = profile_from_parameters(ARDUPILOT_PLUS, MASS_KG)
    thrust = StaticThrustInput(profile)
    thrust.set_battery_voltage_v(voltage_v)
    full = MASS_KG * GRAVITY_MPS2 / (4 * ARDUPILOT_PLUS["MOT_THST_HOVER"])
    for throttle in (0.2, 0.39, 0.6):
        pulse = ardupilot_pulse_us(throttle, voltage_v, ARDUPILOT_PLUS)
        got = thrust.total_thrust_n(np.full(4, pulse), 0.0)
        assert got == pytest.approx(4 * full * throttle, rel=1e-9)
    # without the voltage the sagged battery's larger pulses read as more thrust
    if voltage_v < 12.8:
        blind = StaticThrustInput(profile).total_thrust_n(np.full(4, pulse), 0.0)
        assert blind > 1.02 * 4 * full * 0.6


def test_no_battery_model_ignores_the_voltage() -> None:
    profile = profile_from_parameters({**ARDUPILOT_PLUS, "MOT_BAT_VOLT_MAX": 0}, MASS_KG)
    thrust = MotorLagThrustInput(profile)
    before = thrust.total_thrust_n(np.full(4, 1500.0), 0.0)
    thrust.set_battery_voltage_v(9.0)
    assert thrust.total_thrust_n(np.full(4, 1500.0), 0.001) == pytest.approx(before, rel=1e-6)


def test_voltage_from_sys_status_and_battery_status() -> None:
    sys_status = dialect.MAVLink_sys_status_message(0, 0, 0, 500, 11100, -1, -1, 0, 0, 0, 0, 0, 0)
    assert battery_voltage_v(sys_status) == pytest.approx(11.1)
    unknown = dialect.MAVLink_sys_status_message(0, 0, 0, 500, 65535, -1, -1, 0, 0, 0, 0, 0, 0)
    assert math.isnan(battery_voltage_v(unknown))
    cells = [3700, 3710, 3690] + [65535] * 7
    status = dialect.MAVLink_battery_status_message(0, 0, 0, 2500, cells, -1, -1, -1, 80)
    assert battery_voltage_v(status) == pytest.approx(11.1)


def test_session_applies_the_flight_controllers_voltage(tmp_path) -> None:
    profile = profile_from_parameters(ARDUPILOT_PLUS, MASS_KG)
    config = load_service_config(None, {"recording": {"enabled": False}})
    session = EstimationSession(config, profile)
    msg = dialect.MAVLink_sys_status_message(0, 0, 0, 500, 11520, -1, -1, 0, 0, 0, 0, 0, 0)
    msg.pack(dialect.MAVLink(None, srcSystem=1, srcComponent=1))
    session.on_message(msg)
    assert session.aligner.thrust_input._static.voltage_ratio == pytest.approx(0.9)
    other = dialect.MAVLink_sys_status_message(0, 0, 0, 500, 9000, -1, -1, 0, 0, 0, 0, 0, 0)
    other.pack(dialect.MAVLink(None, srcSystem=7, srcComponent=1))  # not the FC: ignored
    session.on_message(other)
    assert session.aligner.thrust_input._static.voltage_ratio == pytest.approx(0.9)
