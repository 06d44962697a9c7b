"""The one sample feeder (estimation/feed.py) the offline runs, benchmarks and tests share."""

from __future__ import annotations

import dataclasses

from tether_companion.estimation.feed import (
    ATTITUDE,
    IMU,
    PWM,
    RANGE,
    hand_over,
    imu_ticks,
    schedule,
    simulated,
)
from tether_companion.sim.scenario import load_scenario


class _Recorder:
    def __init__(self, name: str, log: list) -> None:
        self.name, self.log = name, log

    def on_attitude(self, sample: object) -> None:
        self.log.append((self.name, "attitude", sample))

    def on_pwm(self, sample: object) -> None:
        self.log.append((self.name, "pwm", sample))

    def on_range(self, sample: object) -> None:
        self.log.append((self.name, "range", sample))

    def on_imu(self, sample: object) -> None:  # never called by the feeder
        raise AssertionError("the caller ticks")


class _Sim:
    """Reads are labelled with the time the simulator had flown to."""

    physics_dt_s = 0.5

    def __init__(self) -> None:
        self.time_s = 0.0
        self.advanced: list[float] = []

    def advance_to(self, time_s: float) -> None:
        self.advanced.append(time_s)
        self.time_s = time_s

    def read_attitude(self) -> tuple:
        return ("att", self.time_s)

    def read_pwm(self) -> tuple:
        return ("pwm", self.time_s)

    def read_rangefinder(self) -> tuple | None:
        return None if self.time_s == 1.0 else ("rng", self.time_s)

    def read_imu(self) -> tuple:
        return ("imu", self.time_s)


def test_hand_over_gives_inputs_to_every_estimator_in_order_and_leaves_imu() -> None:
    log: list = []
    estimators = (_Recorder("a", log), _Recorder("b", log))
    assert hand_over(ATTITUDE, 1, estimators)
    assert hand_over(PWM, 2, estimators)
    assert hand_over(RANGE, 3, estimators)
    assert not hand_over(IMU, 4, estimators)
    assert log == [
        ("a", "attitude", 1),
        ("b", "attitude", 1),
        ("a", "pwm", 2),
        ("b", "pwm", 2),
        ("a", "range", 3),
        ("b", "range", 3),
    ]


def test_simulated_reads_each_sample_at_its_instant_lazily_and_drops_empty_ranges() -> None:
    sim = _Sim()
    due = [(1, ATTITUDE), (1, IMU), (2, RANGE), (2, IMU), (3, PWM), (3, RANGE)]
    samples = simulated(sim, due)
    assert sim.advanced == []  # nothing read before asked for
    first = next(samples)
    assert first == (ATTITUDE, ("att", 0.5)) and sim.advanced == [0.5]
    rest = list(samples)
    assert rest == [
        (IMU, ("imu", 0.5)),
        (IMU, ("imu", 1.0)),  # the range at 1.0 s read nothing: left out
        (PWM, ("pwm", 1.5)),
        (RANGE, ("rng", 1.5)),
    ]
    with_truth = list(simulated(_Sim(), [(2, IMU)], lambda s: (s.read_imu(), s.time_s * 10)))
    assert with_truth == [(IMU, (("imu", 1.0), 10.0))]


def test_imu_ticks_hands_inputs_over_before_yielding_each_tick() -> None:
    log: list = []
    est = _Recorder("a", log)
    samples = [(ATTITUDE, "q"), (PWM, "u"), (IMU, "i1"), (RANGE, "r"), (IMU, "i2")]
    seen = []
    for imu in imu_ticks(samples, est):
        seen.append((imu, len(log)))
    assert seen == [("i1", 2), ("i2", 3)]


def test_schedule_orders_inputs_before_the_imu_due_at_the_same_step() -> None:
    scenario = dataclasses.replace(load_scenario("realistic-circle"), duration_s=1.0)
    due = schedule(scenario)
    assert due == sorted(due)
    steps = round(scenario.duration_s * scenario.physics_rate_hz)
    assert all(0 < step <= steps for step, _ in due)
    counts = {kind: sum(1 for _, k in due if k == kind) for kind in (ATTITUDE, PWM, IMU, RANGE)}
    sensors = scenario.sensors
    assert counts[IMU] == int(sensors.imu_rate_hz)
    assert counts[ATTITUDE] == int(sensors.attitude_rate_hz)
    assert counts[RANGE] == int(sensors.range_rate_hz)
