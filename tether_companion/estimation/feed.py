"""The simulator's sensor samples in time order, and handing them to estimators: the one feeder
the offline runs (:mod:`~tether_companion.estimation.runner`,
:mod:`~tether_companion.estimation.dynamic.offline`), the benchmarks and the tests share.

A sample is ``(kind, sample)`` with ``kind`` one of :data:`ATTITUDE`, :data:`PWM`, :data:`IMU`,
:data:`RANGE`. Attitude, motor-output and rangefinder samples are inputs every estimator takes
as they come (``on_attitude``, ``on_pwm``, ``on_range``); an IMU sample is a tick, which each
caller runs itself (``on_imu``, with what it records around it).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the simulator is imported only by whoever makes one
    from tether_companion.sim.scenario import Scenario
    from tether_companion.sim.simulator import Simulator

ATTITUDE, PWM, IMU, RANGE = 0, 1, 2, 3
"""Sample kinds, in the order samples due at the same instant are handed over (IMU after its
inputs)."""


def schedule(scenario: Scenario) -> list[tuple[int, int]]:
    """(physics step, kind) of every sample due in the run, in time order."""
    physics_hz = scenario.physics_rate_hz
    sensors = scenario.sensors
    steps_total = int(round(scenario.duration_s * physics_hz))
    events: list[tuple[int, int]] = []
    for kind, rate_hz in (
        (ATTITUDE, sensors.attitude_rate_hz),
        (PWM, sensors.pwm_rate_hz),
        (IMU, sensors.imu_rate_hz),
        (RANGE, sensors.range_rate_hz),
    ):
        count = int(scenario.duration_s * rate_hz + 1e-9)
        events += [(int(round(k * physics_hz / rate_hz)), kind) for k in range(1, count + 1)]
    due = [e for e in events if e[0] <= steps_total]
    due.sort()
    return due


def imu_count(due: Iterable[tuple[int, int]]) -> int:
    """How many IMU ticks the samples ``due`` (:func:`schedule`) hold."""
    return sum(1 for _, kind in due if kind == IMU)


def simulated(
    sim: Simulator,
    due: Iterable[tuple[int, int]],
    imu: Callable[[Simulator], Any] | None = None,
) -> Iterator[tuple[int, Any]]:
    """The samples ``due`` (:func:`schedule`) read from ``sim`` as it flies to each one, as
    ``(kind, sample)``; a rangefinder reading outside its span (``None``) is left out. An IMU
    sample is ``sim.read_imu()``, or ``imu(sim)`` when given (to take the truth with it). Lazy:
    when a sample is yielded the simulator is at its instant."""
    dt_s = sim.physics_dt_s
    for step, kind in due:
        sim.advance_to(step * dt_s)
        if kind == ATTITUDE:
            yield kind, sim.read_attitude()
        elif kind == PWM:
            yield kind, sim.read_pwm()
        elif kind == RANGE:
            reading = sim.read_rangefinder()
            if reading is not None:
                yield kind, reading
        else:
            yield kind, (sim.read_imu() if imu is None else imu(sim))


def hand_over(kind: int, sample: Any, estimators: Sequence[Any]) -> bool:
    """Give an attitude, PWM or range ``sample`` to every estimator, in order; ``False`` (and
    nothing handed over) for an IMU sample, which the caller ticks."""
    if kind == ATTITUDE:
        for estimator in estimators:
            estimator.on_attitude(sample)
    elif kind == PWM:
        for estimator in estimators:
            estimator.on_pwm(sample)
    elif kind == RANGE:
        for estimator in estimators:
            estimator.on_range(sample)
    else:
        return False
    return True


def imu_ticks(samples: Iterable[tuple[int, Any]], *estimators: Any) -> Iterator[Any]:
    """Hand every input sample of ``samples`` to the ``estimators`` (:func:`hand_over`) and
    yield each IMU sample, in order, for the caller to tick them with."""
    for kind, sample in samples:
        if not hand_over(kind, sample, estimators):
            yield sample
