"""The per-sample input arithmetic in C (``_tension_core``) against the Python references: the
static thrust curve's sum over the motors (``static_thrust``, ``thrust_input.static_thrust_n``),
the attitude's rotation rows (``rotation_rows``, ``frames.rotation_ned_to_body_rows``) and the
tension filter's observation (``observe_tension``,
``tension_kf.observe_tension_ned_values``): the same floats bit for bit, and the Python
function's result or exception wherever C could differ.

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

from tether_companion import frames
from tether_companion.bench.dynamic import record
from tether_companion.estimation import alignment, tension_kf, thrust_input
from tether_companion.estimation.feed import ATTITUDE, IMU, PWM
from tether_companion.estimation.tension_kf import TensionEstimator, TensionFilterConfig
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


# ---------------------------------------------------------------- the attitude's rotation rows

ROWS_PY = frames.rotation_ned_to_body_rows


def _nested_bits(value: object) -> object:
    if isinstance(value, (list, tuple)):
        return [type(value).__name__, [_nested_bits(v) for v in value]]
    return _bits(value)


def test_rotation_rows_equal_the_python_function_bit_for_bit(rng):
    """Angles within a turn, over many turns and tiny (libm's ``sin``/``cos`` as ``math``'s, no
    merged ``sincos``), signed zeros, and NaN (Python's, as a non-finite result): the same
    floats in new lists (a change of one product's order in tension_core.c fails this)."""
    for scale in (0.1, 3.5, 1e3, 1e-9):
        for _ in range(20000):
            roll, pitch, yaw = (float(v) for v in rng.uniform(-scale, scale, 3))
            assert _nested_bits(core.rotation_rows(ROWS_PY, roll, pitch, yaw)) == _nested_bits(
                ROWS_PY(roll, pitch, yaw)
            )
    for angles in [(0.0, -0.0, 0.0), (-0.0, -0.0, -0.0), (math.nan, 0.1, 0.2)]:
        assert _nested_bits(core.rotation_rows(ROWS_PY, *angles)) == _nested_bits(ROWS_PY(*angles))


def test_where_c_could_differ_the_rotation_rows_are_python_s():
    """An infinite angle raises as ``math.cos`` does; ints and numpy floats give the Python
    function's floats; a wrong argument count raises."""
    with pytest.raises(ValueError):
        core.rotation_rows(ROWS_PY, 0.1, math.inf, 0.2)
    for angles in [(0, 1, 2), (np.float64(0.1), 0.2, 0.3)]:
        assert _nested_bits(core.rotation_rows(ROWS_PY, *angles)) == _nested_bits(ROWS_PY(*angles))
    with pytest.raises(TypeError):
        core.rotation_rows(ROWS_PY, 0.1, 0.2)


# ---------------------------------------------------------------- the tension observation

OBSERVE_PY = tension_kf.observe_tension_ned_values


def test_the_observation_equals_the_python_function_bit_for_bit(rng):
    """Random specific forces, rotations (from the rows function), thrusts and masses, now and
    then with signed zeros, NaNs and infinities: the same floats (a regrouped sum in
    tension_core.c fails this)."""
    for special in (False, True):
        for _ in range(20000):
            force = [float(v) for v in rng.normal(0.0, 5.0, 3)]
            rows = ROWS_PY(*(float(v) for v in rng.uniform(-3.5, 3.5, 3)))
            thrust, mass = float(rng.uniform(0.0, 60.0)), float(rng.uniform(0.5, 5.0))
            if special and rng.uniform() < 0.3:
                force[int(rng.integers(0, 3))] = [0.0, -0.0, math.nan, math.inf][rng.integers(0, 4)]
            args = (force, rows, thrust, mass)
            assert _nested_bits(core.observe_tension(OBSERVE_PY, *args)) == _nested_bits(
                OBSERVE_PY(*args)
            )


def test_where_c_could_differ_the_observation_is_python_s():
    """Ints, numpy arrays, tuples of rows and short rows: the Python function's result or its
    exception."""
    rows = ROWS_PY(0.1, 0.2, 0.3)
    force = [0.1, -0.2, -9.6]
    for args in [
        ([0, 0, -10], rows, 20.0, 2.0),
        (np.array(force), rows, 20.0, 2.0),
        (force, tuple(tuple(r) for r in rows), 20.0, 2.0),
        (force, np.array(rows), 20.0, 2.0),
        (force, rows, 20, 2.0),
        (force, rows, 20.0, np.float64(2.0)),
    ]:
        assert _nested_bits(core.observe_tension(OBSERVE_PY, *args)) == _nested_bits(
            OBSERVE_PY(*args)
        )
    with pytest.raises(ValueError):
        core.observe_tension(OBSERVE_PY, force, [rows[0], rows[1][:2], rows[2]], 20.0, 2.0)


def test_a_flight_s_attitudes_and_observations_run_in_c():
    """The tension filter fed a circle's samples: every attitude's rows and every tick's
    observation go through C (no fallback) and give the Python function's floats."""
    vehicle = load_vehicle(load_scenario("realistic-circle").vehicle)
    estimator = TensionEstimator(TensionFilterConfig(), vehicle)
    with (
        recording_c_calls(alignment, "ROTATION_ROWS", core.rotation_rows, ROWS_PY) as (
            rotations,
            rotation_fallbacks,
        ),
        recording_c_calls(tension_kf, "OBSERVE_TENSION", core.observe_tension, OBSERVE_PY) as (
            observations,
            observation_fallbacks,
        ),
    ):
        for kind, sample in record("realistic-circle", 4.0):
            if kind == ATTITUDE:
                estimator.on_attitude(sample)
            elif kind == PWM:
                estimator.on_pwm(sample)
            elif kind == IMU:
                estimator.on_imu(sample)
    assert len(rotations) > 100 and len(observations) > 100
    assert not rotation_fallbacks and not observation_fallbacks
    for args in rotations:
        assert _nested_bits(core.rotation_rows(ROWS_PY, *args)) == _nested_bits(ROWS_PY(*args))
    for args in observations:
        assert _nested_bits(core.observe_tension(OBSERVE_PY, *args)) == _nested_bits(
            OBSERVE_PY(*args)
        )


# ---------------------------------------------------------------- the motor lag's step

LAG_PY = thrust_input.lagged_thrust_n


def _lag_outcome(function: object, args: tuple) -> object:
    try:
        return _nested_bits(function(*args))  # type: ignore[operator]
    except Exception as exc:  # noqa: BLE001 - compared, not handled
        return type(exc)


def _lag_args(rng: np.random.Generator, special: bool) -> tuple:
    """A PWM sample's step: intervals around and at the restart gap (and nan, negative), thrusts
    and time constants over many decades; with ``special`` now and then a signed zero, NaN or
    infinity anywhere."""
    dt = [
        float(rng.uniform(0.0, 0.05)),
        float(rng.uniform(0.0, 2.0)),
        thrust_input.RESTART_GAP_S,
        math.nextafter(thrust_input.RESTART_GAP_S, 2.0),
        0.0,
        -0.0,
        math.nan,
        float(-rng.uniform(0.0, 1.0)),
    ][rng.integers(0, 8)]
    values = [
        float(rng.normal() * 10.0 ** rng.uniform(-3, 3)),  # command
        dt,
        float(rng.normal() * 10.0 ** rng.uniform(-3, 3)),  # thrust
        float(rng.normal() * 10.0 ** rng.uniform(-3, 3)),  # last command
        float(rng.uniform(0.0, 1.0)) if rng.uniform() < 0.9 else 0.0,  # interval
        float(10.0 ** rng.uniform(-310, 3)),  # time constant, down to subnormal
    ]
    if special:
        for i in rng.integers(0, 6, rng.integers(1, 3)):
            values[i] = [0.0, -0.0, math.nan, math.inf, -math.inf][rng.integers(0, 5)]
    return tuple(values)


@pytest.mark.parametrize("special", [False, True])
def test_the_motor_lag_step_equals_the_python_function_bit_for_bit(special, rng):
    """``lagged_thrust`` against ``thrust_input.lagged_thrust_n`` on 40k random steps (the
    restart gap's edges, nan, negative and zero intervals, time constants down to subnormal):
    the same floats, or the Python function's result or exception. A `<` for the gap's `<=`,
    or the decay's product distributed over the difference, fails this."""
    for _ in range(20000):
        args = _lag_args(rng, special)
        assert _lag_outcome(lambda *a: core.lagged_thrust(LAG_PY, *a), args) == _lag_outcome(
            LAG_PY, args
        ), args


def test_where_c_could_differ_the_motor_lag_step_is_python_s():
    """Ints and numpy floats: the Python function's result; a wrong argument count raises."""
    args = (12.0, 0.005, 11.0, 10.0, 0.005, 0.04)
    for position, bad in [(0, 12), (1, np.float64(0.005)), (5, 1)]:
        changed = list(args)
        changed[position] = bad
        assert _lag_outcome(lambda *a: core.lagged_thrust(LAG_PY, *a), tuple(changed)) == (
            _lag_outcome(LAG_PY, tuple(changed))
        )
    with pytest.raises(TypeError):
        core.lagged_thrust(LAG_PY, *args[:5])


def test_a_flight_s_motor_lag_runs_in_c_with_the_python_floats():
    """The motor lag over a flight's PWM samples (with a restart after a gap): every step goes
    through C (no fallback) and gives the Python function's floats."""
    vehicle = load_vehicle(load_scenario("realistic-circle").vehicle)
    rng = np.random.default_rng(6)
    samples = rng.uniform(1100.0, 1900.0, (300, vehicle.n_motors))
    times = 0.005 * np.arange(300) + np.where(np.arange(300) >= 150, 2.0, 0.0)
    with recording_c_calls(thrust_input, "LAGGED_THRUST", core.lagged_thrust, LAG_PY) as (
        calls,
        fallbacks,
    ):
        lag = MotorLagThrustInput(vehicle)
        for pwm, t in zip(samples, times.tolist(), strict=True):
            lag.total_thrust_n(pwm, t)
    assert len(calls) == len(samples)
    assert not fallbacks
    for args in calls:
        assert _lag_outcome(lambda *a: core.lagged_thrust(LAG_PY, *a), args) == _lag_outcome(
            LAG_PY, args
        )
