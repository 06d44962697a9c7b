"""The ground station's calibration errors as states of the dynamic filter (``state.py``:
winch offset and scale, the angle sensor's elevation and azimuth zeros): their prior enters
with the sensor's first reading (``ground_station.open_calibration``), a circle teaches them,
a hover leaves what it cannot tell at the prior; absurd values are dropped."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tether_companion.config import ConfigError
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.dynamic import generated, state
from tether_companion.estimation.dynamic.bank import FilterBank
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.estimation.dynamic.ground_station import open_calibration
from tether_companion.estimation.dynamic.member import MemberFilter
from tether_companion.estimation.dynamic.models import ModelConstants
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.service.config import load_service_config

WINCH = (state.WINCH_OFFSET, state.WINCH_SCALE)
ANGLE = (state.ELEVATION_ZERO, state.AZIMUTH_ZERO)
HOLD_SEEDS = (5, 2)
"""Tuning seeds of the hold test, tried in order until one flight meets its premise."""


def _bank(members: int = 2) -> FilterBank:
    x = np.zeros(state.N_STATES)
    x[state.POSITION] = (3.0, 4.0, -2.0)
    x[state.TENSION], x[state.SCALE] = 4.0, 1.0
    p = np.eye(state.N_STATES) * 0.01
    p[state.CALIBRATION, state.CALIBRATION] = np.eye(4) * state.UNSET_CALIBRATION_VARIANCE
    constants = ModelConstants(1.5, 0.2, 0.0)
    q = np.full(state.N_STATES, 1e-6)
    filters = [MemberFilter(x, p, q, constants, generated.inertial) for _ in range(members)]
    return FilterBank(filters, 0.0, 6.0)


def test_the_prior_enters_with_the_first_reading_and_only_where_none_was_given() -> None:
    bank = _bank()
    before = [m.P.copy() for m in bank.filters]
    open_calibration(bank, WINCH, (0.1, 0.01))
    for member, p in zip(bank.filters, before, strict=True):
        expected = p.copy()
        expected[state.WINCH_OFFSET, state.WINCH_OFFSET] = 0.1**2
        expected[state.WINCH_SCALE, state.WINCH_SCALE] = 0.01**2
        np.testing.assert_array_equal(member.P, expected)  # nothing else moves
    # learnt since: a later reading leaves it
    bank.filters[0].P[state.WINCH_OFFSET, state.WINCH_OFFSET] = 0.03**2
    open_calibration(bank, WINCH, (0.1, 0.01))
    assert bank.filters[0].P[state.WINCH_OFFSET, state.WINCH_OFFSET] == 0.03**2
    # the angle's states still wait for their sensor; a zero prior (known) stays at the floor
    assert np.all(np.diag(bank.filters[1].P)[list(ANGLE)] == state.UNSET_CALIBRATION_VARIANCE)
    open_calibration(bank, ANGLE, (0.0, 0.026))
    p = bank.filters[1].P
    assert p[state.ELEVATION_ZERO, state.ELEVATION_ZERO] == state.UNSET_CALIBRATION_VARIANCE
    assert p[state.AZIMUTH_ZERO, state.AZIMUTH_ZERO] == 0.026**2


def _fly(name: str, seed: int, duration_s: float):
    """Fly the realistic scenario ``name`` with the winch and the cable angle (the bench's
    ``dynamic-winch-angle`` kind) learning the calibration; returns the estimator at the end
    and the flight's drawn calibration (sim/ground_sensors.py)."""
    from tether_companion.bench.estimators.flight import fly
    from tether_companion.bench.estimators.registry import UNKNOWN_TENSION, EstimatorKind
    from tether_companion.estimation.dynamic.scorecard import DynamicKind
    from tether_companion.sim.ground_sensors import GroundSensors
    from tether_companion.sim.scenario import load_scenario

    scenario = dataclasses.replace(load_scenario(name), seed=seed, duration_s=duration_s)
    built: list[DynamicKind] = []

    def build(context):
        built.append(DynamicKind(context, use_winch=True, use_angle=True))
        assert built[-1]._estimator.ground_station.calibration_release.enabled  # the default
        return built[-1]

    kind = EstimatorKind("probe", "probe", build, UNKNOWN_TENSION, True, True, "probe")
    fly(scenario, [kind])
    truth = GroundSensors(scenario.ground_station, scenario.cable.model, seed).calibration
    return built[0]._estimator, truth


@pytest.mark.slow
def test_a_circle_teaches_the_calibration_and_a_hover_keeps_what_it_cannot_tell() -> None:
    """Realistic 4 N circle, tuning seed 1, 30 s: the length's error at the flight's length
    (offset + scale L: on a circle of one radius the two are one number) is learnt well
    inside its prior, within 3 sigma of the truth; the azimuth zero, never released (the
    autopilot's heading error would be taken as it), keeps its prior. Gusty hover, same
    seed: the azimuth zero (it only turns the hover's bearing) and the elevation zero (it
    trades against the range) stay near their priors, and the position across the cable
    keeps the azimuth's spread (``rho`` times it)."""
    estimator, truth = _fly("realistic-circle", 1, 30.0)
    member = estimator.bank.best
    x, p = member.x, member.P
    length = float(np.linalg.norm(x[state.POSITION]))
    row = np.zeros(state.N_STATES)
    row[state.WINCH_OFFSET], row[state.WINCH_SCALE] = 1.0, length
    prior_sd = math.hypot(0.1, 0.01 * length)
    sd = math.sqrt(row @ p @ row)
    error = row @ x - (truth.winch_offset_m + truth.winch_scale * length)
    assert sd < 0.5 * prior_sd and abs(error) < 3.0 * sd, (sd, error)
    assert x[state.AZIMUTH_ZERO] == 0.0
    assert p[state.AZIMUTH_ZERO, state.AZIMUTH_ZERO] == pytest.approx(0.026**2, rel=1e-6)

    estimator, truth = _fly("realistic-gusty-hover", 1, 30.0)
    member = estimator.bank.best
    x, p = member.x, member.P
    assert math.sqrt(p[state.AZIMUTH_ZERO, state.AZIMUTH_ZERO]) > 0.8 * 0.026
    assert math.sqrt(p[state.ELEVATION_ZERO, state.ELEVATION_ZERO]) > 0.8 * 0.007
    n, e = x[0], x[1]
    rho = math.hypot(n, e)
    across = np.array([-e / rho, n / rho, 0.0])
    assert math.sqrt(across @ p[:3, :3] @ across) > 0.8 * 0.026 * rho


@pytest.mark.parametrize(
    "calibration", [(math.nan, 0.026), (0.007, math.inf), (-0.007, 0.026), (0.007, -1.0)]
)
def test_a_reading_with_absurd_calibration_errors_is_counted_and_dropped(calibration) -> None:
    estimator = DynamicTetherEstimator(EstimatorConfig(), load_vehicle("default-quad"))
    estimator.on_cable_angle(0.5, 0.3, 1.0, 0.01, calibration)
    assert estimator.health.nonfinite_rejected == 1
    estimator.on_cable_angle(0.5, 0.3, 1.0, 0.01, (0.007, 0.026))
    assert estimator.health.nonfinite_rejected == 1


@pytest.mark.parametrize(
    ("section", "key", "value"),
    [
        ("cable_angle", "azimuth_calibration_std_rad", math.nan),
        ("cable_angle", "elevation_calibration_std_rad", -0.01),
        ("cable_angle", "azimuth_calibration_std_rad", 2.0),
        ("dynamic_filter", "winch_length_offset_std_m", math.inf),
        ("dynamic_filter", "winch_length_scale_std", -0.01),
        ("dynamic_filter", "winch_length_noise_std_m", 0.0),
    ],
)
def test_absurd_calibration_settings_are_rejected(section, key, value) -> None:
    with pytest.raises(ConfigError, match=key):
        load_service_config(None, {section: {key: value}})


def test_the_winchs_calibration_does_not_learn_while_its_length_is_not_fused(monkeypatch) -> None:
    """cal19: on the fixed-length sagging circle (7.25 m of cable with weight), winch + angle,
    the calibration released, then held while no winch length is fused through its model
    (skipped as slack, or fused only as the chord's bound): through the cross-covariance the
    length's fusions left, the cable angle's updates would move the winch's offset (tuning
    seed 6 on b70c3c6: 0 -> +0.37 m in 4.4 s of slack cable, truth -0.18 m), a relation
    linearised where the cable was taut, the reading skipped exactly where it no longer holds.

    The premise is asserted, not assumed from one release time (startvel23's start moved seed
    6's release out of its slack stretch, and so does sv23b's bank fix by 12.5 s): the first of
    tuning seeds :data:`HOLD_SEEDS` whose flight, by 12 s, has the states released before 8 s
    and no length fused through the model from there to the end while the cable angle is fused
    (40 readings at least). Over that stretch the offset does not move (1e-3 m); with the hold
    taken out (``follow_length`` a no-op) it moves +0.032 m by 12 s on seed 5 with the bank fix
    (+0.023 m by 12.2 s on 351c0c5, without it), -0.0064 m on seed 2 with live24's start
    velocity (whose start releases seed 5 only at 10.1 s)."""
    from tether_companion.estimation.dynamic.calibration_release import CalibrationRelease
    from tether_companion.estimation.dynamic.ground_station import GroundStationInputs

    follow, fuse_angle = CalibrationRelease.follow_length, GroundStationInputs.fuse_angle
    held: list[tuple[bool, float]] = []  # after the release: (length fused, the best's offset [m])
    angles_fused_while_held = [0]

    def spy_length(release: CalibrationRelease, bank: FilterBank, length_fused: bool) -> None:
        if not math.isnan(release.released_time_s):
            held.append((length_fused, float(bank.best.x[state.WINCH_OFFSET])))
        follow(release, bank, length_fused)

    def spy_angle(inputs: GroundStationInputs, bank: FilterBank, *args, **kwargs) -> None:
        fused_before = inputs.cable_angle.status.last_fused_time_s
        fuse_angle(inputs, bank, *args, **kwargs)
        if held and inputs.cable_angle.status.last_fused_time_s != fused_before:
            angles_fused_while_held[0] += 1

    monkeypatch.setattr(CalibrationRelease, "follow_length", spy_length)
    monkeypatch.setattr(GroundStationInputs, "fuse_angle", spy_angle)
    premises = {}
    for seed in HOLD_SEEDS:
        held.clear()
        angles_fused_while_held[0] = 0
        estimator, _ = _fly("realistic-sagging-circle", seed, 12.0)
        released_s = estimator.ground_station.calibration_release.released_time_s
        premises[seed] = (released_s, [fused for fused, _ in held], angles_fused_while_held[0])
        if released_s < 8.0 and held and not any(premises[seed][1]) and premises[seed][2] >= 40:
            break
    else:
        pytest.fail(f"no flight meets the premise (release [s], lengths fused, angles): {premises}")
    offset_at_hold, offset_now = held[0][1], estimator.bank.best.x[state.WINCH_OFFSET]
    assert abs(offset_now - offset_at_hold) < 1e-3, (seed, offset_at_hold, offset_now)
    assert estimator.bank.consider == state.CALIBRATION  # held
