"""The static thrust curve's sum over the motors in C (``_tension_core.static_thrust``) against
its Python reference ``thrust_input.static_thrust_n``: the same floats bit for bit, and the
Python function's result or exception wherever C could differ.

The extension is optional (no compiler: the Python function runs). Its absence fails this file
where it could have been built or with ``TETHER_REQUIRE_CORE=1``, as
``test_tension_core.py`` does.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from optional_extension import import_extension, recording_c_calls

from tether_companion.estimation import thrust_input
from tether_companion.estimation.thrust_input import MotorLagThrustInput, StaticThrustInput
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import load_scenario

core, pytestmark = import_extension("tether_companion.estimation._tension_core")

PY = thrust_input.static_thrust_n


def _c(*args: object) -> object:
    return core.static_thrust(PY, *args)


def _bits(value: object) -> object:
    return struct.pack("<d", value) if isinstance(value, float) else (type(value), value)


def _args(rng: np.random.Generator, special: bool) -> tuple:
    motors = int(rng.integers(0, 17))
    pwm = [float(v) for v in rng.uniform(800.0, 2200.0, motors)]  # below, in and above range
    constants = [
        float(rng.uniform(900.0, 1200.0)),  # pwm_min_us
        float(1.0 / rng.uniform(500.0, 1200.0)),  # per_us
        float(rng.uniform(0.5, 1.5)),  # scale (the voltage ratio's)
        float(rng.normal(0.0, 1.0) * motors),  # total: n c0
        float(rng.normal(0.0, 5.0)),  # c1
        float(rng.normal(0.0, 10.0)),  # c2
    ]
    if special:  # boundary commands, signed zeros, NaNs and infinities now and then
        for i in rng.integers(0, max(motors, 1), rng.integers(0, 3)) if motors else ():
            pwm[i] = [constants[0], constants[0] + 1.0 / constants[1], math.nan, math.inf][
                rng.integers(0, 4)
            ]
        if rng.uniform() < 0.1:
            constants[int(rng.integers(0, 6))] = [0.0, -0.0, math.nan, -math.inf][
                rng.integers(0, 4)
            ]
    container = [list, tuple][rng.integers(0, 2)]
    return (container(pwm), *constants)


@pytest.mark.parametrize("special", [False, True])
def test_c_equals_the_python_function_bit_for_bit(special, rng):
    """Random pulse widths below, inside and above the curve's range for 0-16 motors (and the
    command's bounds exactly, signed zeros, NaNs and infinities): the same float (a change of
    one operation's order in tension_core.c fails this)."""
    for _ in range(20000):
        args = _args(rng, special)
        assert _bits(_c(*args)) == _bits(PY(*args)), args


def test_where_c_could_differ_it_returns_what_python_returns(rng):
    """Ints, numpy floats, more motors than C reads and other containers go to the Python
    function (its result, bit for bit); a wrong argument count raises."""
    args = _args(rng, False)
    pwm = [1500.0, 1400.0, 1600.0, 1550.0]
    for changed in [
        ([1500, 1400, 1600, 1550], *args[1:]),
        (np.array(pwm), *args[1:]),
        ([np.float64(v) for v in pwm], *args[1:]),
        ([1500.0] * 17, *args[1:]),
        (pwm, 1000, *args[2:]),
        (pwm, *args[1:4], 0, *args[5:]),
        (pwm, *args[1:6], np.float64(7.5)),
    ]:
        assert _bits(_c(*changed)) == _bits(PY(*changed))
    with pytest.raises(TypeError):
        core.static_thrust(PY, pwm, *args[1:6])


def test_a_flight_s_thrust_runs_in_c_with_the_python_floats():
    """The static curve and the motor lag over a flight's PWM samples (with a battery ratio
    other than 1): every sum goes through C (no fallback) and gives the Python function's
    float; the totals are the reference's."""
    vehicle = load_vehicle(load_scenario("realistic-circle").vehicle)
    rng = np.random.default_rng(5)
    samples = rng.uniform(1100.0, 1900.0, (300, vehicle.n_motors))
    with recording_c_calls(thrust_input, "STATIC_THRUST", core.static_thrust, PY) as (
        calls,
        fallbacks,
    ):
        static, lag = StaticThrustInput(vehicle), MotorLagThrustInput(vehicle)
        static.voltage_ratio = 0.93
        for k, pwm in enumerate(samples):
            static.total_thrust_n(pwm, 0.005 * k)
            lag.total_thrust_n(pwm, 0.005 * k)
    assert len(calls) == 2 * len(samples)
    assert not fallbacks
    for args in calls:
        assert _bits(_c(*args)) == _bits(PY(*args))
