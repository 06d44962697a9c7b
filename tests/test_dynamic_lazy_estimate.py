"""The dynamic filter's estimate computed when read (estimation/dynamic/published.py): every
field read at the tick, read long after, or never read but the status, is the former per-tick
computation's bit for bit; the cheap status and the publisher's cheap checks decide as the
exact values do, and say "unsure" near a threshold instead of guessing."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.bench.dynamic import record
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.bearing_ambiguity import bearing_ambiguity
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.observability import (
    HoverUnknowns,
    assess,
    decide,
    horizontal_pull_n,
    min_horizontal_pull_n,
    unmodelled_position_covariance,
)
from tether_companion.estimation.dynamic.output import (
    LEARNING,
    OK,
    SLACK,
    WEAK_PULL,
    NavigationEstimate,
)
from tether_companion.estimation.dynamic.position_information import (
    height_excess,
    reduce_added_rows,
)
from tether_companion.estimation.dynamic.published import UNKNOWN_VARIANCE
from tether_companion.estimation.feed import hand_over
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.session import EstimationSession
from tether_companion.sim.scenario import load_scenario

FLIGHTS = [("realistic-takeoff-figure8", 9.0), ("realistic-sagging-circle", 5.0)]
"""On the ground, initialising, the bank, learning, weak pull, slack; the straight cable and
the catenary."""
_HOVER = [state.SCALE, state.WIND.start, state.WIND.start + 1]


@pytest.fixture(scope="module", params=FLIGHTS, ids=[name for name, _ in FLIGHTS])
def flight(request):
    name, seconds = request.param
    return name, record(name, seconds)


def _former_estimate(est: DynamicTetherEstimator, source) -> tuple:  # noqa: ANN001
    """The estimate's fields as the filter computed them at every tick before they became
    lazy (its arithmetic, from the filter's state right after the tick; the tick's flags are
    inputs, taken from the tick)."""
    bank, dyn = est.bank, est.dynamic
    if bank is None:
        x = np.zeros(state.N_STATES)
        p = np.eye(state.N_STATES) * UNKNOWN_VARIANCE
        tension, tension_var = 0.0, UNKNOWN_VARIANCE
    else:
        x, p = bank.mixture()
        batch = est._batch
        if batch is not None and batch.ticks:
            x, p = batch.step_state(x, est._walk.matrix), batch.step_covariance(p, est._walk.matrix)
        values = x.tolist()
        tension, tension_var = est.constants.tension_at_drone(values, p)
    published = p[state.POSITION_VELOCITY, state.POSITION_VELOCITY].copy()
    if bank is None:
        published[2, 2] += est.rangefinder.excess.variance
    else:  # each entry: the unmodelled term + the height's excess + the bearing's ambiguity
        added = unmodelled_position_covariance(
            x[state.POSITION],
            tension,
            est.bearing.force_std_n,  # the unmodelled force, widened by the bearing window
            dyn.winch_length_noise_std_m if est.health.winch_fused else 0.0,
        )
        # narrowed by the cable angles fused within the correlation time (none here: None)
        information = est.ground_station.position_information.at(est.time_s)
        unmodelled = reduce_added_rows(added.tolist(), information)
        # without a winch length the height's excess goes along the line from the anchor too
        excess = height_excess(
            values[:3], est.rangefinder.excess.variance, bool(est.health.winch_fused)
        )
        # a tick the pull rule withholds: the bearing's ambiguity
        settings = est.ground_station.status_settings(est.time_s, bank.bearing_confirmed)
        wind_n, wind_e = float(x[state.WIND][0]), float(x[state.WIND][1])
        pull = horizontal_pull_n(values)
        ring = (0.0, 0.0, 0.0)
        if pull < min_horizontal_pull_n(
            settings.pull_per_wind_n_s_per_m, dyn.initial.wind_std_mps, wind_n, wind_e
        ):
            drag = min_horizontal_pull_n(
                settings.drag_per_wind_n_s_per_m, dyn.initial.wind_std_mps, wind_n, wind_e
            )
            ring = bearing_ambiguity(values[0], values[1], pull, drag)
        for k, (i, j) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
            entry = unmodelled[i][j] + excess[k] + 0.0
            entry += {0: ring[0], 1: ring[1], 3: ring[2]}.get(k, 0.0)
            published[i, j] += entry
            if i != j:
                published[j, i] += entry
    status, reason = assess(
        initialised_reason=None if bank is not None else est.initialising_reason,
        reset_reason=source.reset_reason,
        on_ground=source.on_ground,
        inputs_stale=source.inputs_stale,
        tension_n=tension,
        slack_tension_n=dyn.slack_tension_n,
        position_covariance_m2=published[:3, :3],
        max_horizontal_std_m=dyn.max_horizontal_std_m,
        horizontal_pull_n=0.0 if bank is None else horizontal_pull_n(values),
        min_horizontal_pull_n=min_horizontal_pull_n(
            est.ground_station.status_settings(
                est.time_s, bank is not None and bank.bearing_confirmed
            ).pull_per_wind_n_s_per_m,
            dyn.initial.wind_std_mps,
            float(x[state.WIND][0]),
            float(x[state.WIND][1]),
        ),
        hover_unknowns=None
        if bank is None
        else HoverUnknowns(
            float(x[state.SCALE]),
            x[state.WIND].copy(),
            p[_HOVER][:, _HOVER],
            p[:2][:, _HOVER],
            len(bank.filters),
        ),
    )
    return _fields(
        x[state.POSITION],
        x[state.VELOCITY],
        published,
        float(tension),
        tension_var,
        status,
        reason,
        float(x[state.SCALE]),
        x[state.BIAS],
        x[state.WIND],
    )


def _check_approximation(approx, former: tuple) -> None:  # noqa: ANN001
    position, _, covariance, tension = former[:4]
    assert approx.finite
    for a, b in zip(approx.position, position, strict=True):
        assert abs(a - b) <= approx.position_tol
    north, north_east, east = approx.horizontal
    tol = approx.covariance_tol
    assert abs(north - covariance[0][0]) <= tol and abs(east - covariance[1][1]) <= tol
    assert abs(north_east - covariance[0][1]) <= tol
    assert abs(approx.down_variance - covariance[2][2]) <= tol
    assert abs(approx.tension_n - tension) <= 1e-12 * abs(tension)
    assert tol <= 1e-3 * (north + east + approx.down_variance)  # the step's bound is small


def _fields(*values) -> tuple:  # noqa: ANN002
    return tuple(v.tolist() if isinstance(v, np.ndarray) else v for v in values)


def _read(e) -> tuple:  # noqa: ANN001
    return _fields(
        e.position_ned_m,
        e.velocity_ned_mps,
        e.position_velocity_covariance,
        e.tension_n,
        e.tension_variance_n2,
        e.status,
        e.reason,
        e.thrust_scale,
        e.accel_bias_body_mps2,
        e.wind_ne_mps,
    )


def test_every_field_is_the_former_per_tick_value_whenever_it_is_read(flight) -> None:
    name, samples = flight
    vehicle = load_vehicle(load_scenario(name).vehicle)
    est = DynamicTetherEstimator(EstimatorConfig(), vehicle)
    later = DynamicTetherEstimator(EstimatorConfig(), vehicle)  # read after the flight
    expected, kept, statuses = [], [], set()
    undecided = 0  # ticks whose status the approximation left to the exact values
    for kind, sample in samples:
        if hand_over(kind, sample, (est, later)):
            continue
        e = est.on_imu(sample)
        e_later = later.on_imu(sample)
        former = _former_estimate(est, e._source)
        approx = e.approximate()
        status = e.status  # first the cheap status alone, as the service reads it
        assert status == former[5]
        undecided += e._source._quick_status() is None
        assert _read(e) == former
        if approx is not None:  # within the rounding it claims
            _check_approximation(approx, former)
        expected.append(former)
        kept.append(e_later)
        statuses.add(status)
    assert [_read(e) for e in kept] == expected  # bit for bit, read after 1000s of ticks
    assert {LEARNING, WEAK_PULL} & statuses  # the flights reach the numeric tests
    assert undecided <= 0.01 * len(expected)  # the approximation decides nearly every tick


def _session_output(samples, eager: bool, monkeypatch) -> list:  # noqa: ANN001
    """Every message and publication of a service session (messages on) and its counters;
    ``eager``: each estimate's exact values computed at its tick (the former behaviour) and
    read by the publisher (no approximation offered)."""
    if eager:
        former = DynamicTetherEstimator._estimate

        def estimate(self, *args):  # noqa: ANN001, ANN002, ANN202
            out = former(self, *args)
            out._source.values()
            return out

        monkeypatch.setattr(DynamicTetherEstimator, "_estimate", estimate)
        monkeypatch.setattr(NavigationEstimate, "approximate", lambda self: None)
    config = load_service_config(None, {"recording": {"enabled": False}})
    session = EstimationSession(config, load_vehicle_for(config), messages=True)
    lines: list = []
    for _, sample in samples:
        step = session.on_sample(sample)
        lines += [sorted(m.to_dict().items()) for m in step.messages]
        if step.publication is not None:
            lines.append(step.publication.csv_row())
    counters = session.publisher.counters
    lines.append(dataclasses.asdict(counters))
    monkeypatch.undo()
    return lines


def test_the_service_sends_and_counts_the_same_as_with_every_value_computed(
    flight, monkeypatch
) -> None:
    _, samples = flight
    lazy = _session_output(samples, False, monkeypatch)
    eager = _session_output(samples, True, monkeypatch)
    assert lazy == eager
    assert lazy[-1]["estimates"] >= 1000


def test_an_approximate_decision_near_a_threshold_is_left_to_the_exact_values() -> None:
    common = dict(
        initialised=True,
        reset=False,
        on_ground="",
        inputs_stale=False,
        slack_tension_n=0.5,
        horizontal_m2=(0.01, 0.0, 0.01),
        max_horizontal_std_m=0.3,
        horizontal_pull_n=3.0,
        min_horizontal_pull_n=1.0,
        explained=None,
    )
    assert decide(tension_n=4.0, margin=1e-9, **common) == OK
    assert decide(tension_n=0.2, margin=1e-9, **common) == SLACK
    assert decide(tension_n=0.5 * (1 + 1e-12), margin=1e-9, **common) is None
    assert decide(tension_n=math.nan, margin=1e-9, **common) is None
    assert decide(tension_n=math.nan, **common) == OK  # exact: as assess always did
    near = dict(common, horizontal_m2=(0.09 + 1e-13, 0.0, 0.01))
    assert decide(tension_n=4.0, margin=1e-9, variance_tol=1e-12, **near) is None
    assert decide(tension_n=4.0, **near) == WEAK_PULL  # exact: std 0.3 + 2e-13 m > 0.3 m
    # the pull rule the same way: clear, within the margin, not a number
    weak = dict(common, tension_n=4.0, min_horizontal_pull_n=3.5)
    assert decide(margin=1e-9, **weak) == WEAK_PULL
    assert decide(margin=1e-9, **dict(weak, min_horizontal_pull_n=3.0 * (1 + 1e-12))) is None
    assert decide(margin=1e-9, **dict(weak, horizontal_pull_n=math.nan)) is None
    assert decide(**dict(weak, horizontal_pull_n=math.nan)) == OK  # exact: nan < b is False
