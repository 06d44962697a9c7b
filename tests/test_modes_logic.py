"""Tension-following and landing by the tether: the pure decision logic (Martins 2019, 5.1)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tether_companion.config import ConfigError, from_mapping
from tether_companion.estimation.tension_kf import TensionEstimate, TensionHealth
from tether_companion.modes.config import TensionModeConfig
from tether_companion.modes.tension_following import (
    DISABLED,
    FALLBACK_LAND,
    FOLLOWING,
    IDLE,
    INACTIVE,
    LAND,
    LAND_COMMANDED,
    LANDING,
    NOTHING,
    POSITION_TARGET,
    VELOCITY_TARGET,
    ModeInputs,
    TensionModes,
)

FOLLOW = TensionModeConfig(enabled=True, land_on_first_tug=False)
LANDER = TensionModeConfig(enabled=True, land_on_first_tug=True)
DT = 0.05


def _tension(force, time_s, age_s=0.0):
    return TensionEstimate(
        time_s=time_s,
        tension_ned_n=np.asarray(force, dtype=float),
        variance_n2=0.01,
        last_update_s=time_s - age_s,
        observation_ned_n=np.asarray(force, dtype=float),
        updated=True,
        health=TensionHealth(),
    )


def _cable_pull(position, tension_n=4.0):
    """A straight cable of constant tension pulling toward the anchor."""
    p = np.asarray(position, dtype=float)
    return -tension_n * p / np.linalg.norm(p)


def _inputs(t, position, force, *, armed=True, mode="GUIDED", height=None, age_s=0.0):
    position = np.asarray(position, dtype=float)
    return ModeInputs(
        time_s=t,
        tension=_tension(force, t, age_s) if force is not None else None,
        armed=armed,
        flight_mode=mode,
        position_ned_m=position,
        height_m=-position[2] if height is None else height,
    )


def _run(modes, t0, t1, position, force_fn, **kwargs):
    actions = []
    for t in np.arange(t0, t1, DT):
        actions.append(modes.step(_inputs(t, position, force_fn(t), **kwargs)))
    return actions


HOVER = np.array([3.0, 0.0, -3.0])


def test_disabled_inactive_do_nothing():
    modes = TensionModes(replace(FOLLOW, enabled=False))
    tug = _cable_pull(HOVER) + np.array([0.0, 5.0, 0.0])
    assert all(a.kind == NOTHING for a in _run(modes, 0, 2, HOVER, lambda t: tug))
    assert modes.state == DISABLED
    modes.set_enabled(True)
    for kwargs in ({"armed": False}, {"mode": "LOITER"}, {"mode": "LAND"}):
        assert all(a.kind == NOTHING for a in _run(modes, 2, 4, HOVER, lambda t: tug, **kwargs))
        assert modes.state == INACTIVE


def test_cable_own_pull_is_not_a_tug():
    modes = TensionModes(FOLLOW)
    actions = _run(modes, 0, 10, HOVER, lambda t: _cable_pull(HOVER, 4.0 + 0.3 * math.sin(t)))
    assert all(a.kind == NOTHING for a in actions)
    assert modes.state == IDLE


def test_tug_is_followed_along_the_pull_then_holds():
    modes = TensionModes(FOLLOW)
    base = _cable_pull(HOVER)
    _run(modes, 0, 3, HOVER, lambda t: base)
    tug = np.array([0.0, 3.0, 0.0])  # 3 N toward east
    actions = _run(modes, 3, 5, HOVER, lambda t: base + tug)
    assert actions[0].kind == NOTHING  # debounce
    moving = [a for a in actions if a.kind == VELOCITY_TARGET]
    assert len(moving) >= len(actions) - int(FOLLOW.debounce_s / DT) - 1
    for a in moving:
        v = a.velocity_ned_m_s
        assert v[1] > 0.5 and abs(v[0]) < 1e-9 and v[2] == 0.0  # along the pull, no climb/descent
        assert math.hypot(v[0], v[1]) <= FOLLOW.max_horizontal_speed_mps + 1e-12
    assert modes.state == FOLLOWING
    actions = _run(modes, 5, 6, HOVER, lambda t: base)
    holds = [a for a in actions if a.kind == POSITION_TARGET]
    assert len(holds) == 1 and np.allclose(holds[0].position_ned_m, HOVER)
    after_hold = actions[actions.index(holds[0]) + 1 :]
    assert modes.state == IDLE and all(a.kind == NOTHING for a in after_hold)


def test_short_spike_is_debounced():
    modes = TensionModes(FOLLOW)
    base = _cable_pull(HOVER)
    _run(modes, 0, 2, HOVER, lambda t: base)
    spike = _run(modes, 2, 2.1, HOVER, lambda t: base + np.array([0.0, 5.0, 0.0]))
    after = _run(modes, 2.1, 4, HOVER, lambda t: base)
    assert all(a.kind == NOTHING for a in spike + after)


def test_learnt_pull_turns_with_the_anchor_direction():
    """After moving, the cable still pulls toward the anchor: not an extra pull."""
    modes = TensionModes(FOLLOW)
    _run(modes, 0, 3, HOVER, lambda t: _cable_pull(HOVER))
    moved = np.array([2.0, 2.5, -3.0])
    actions = _run(modes, 3, 6, moved, lambda t: _cable_pull(moved))
    assert all(a.kind == NOTHING for a in actions)


def test_pull_is_relearnt_when_guided_is_entered_again():
    """Flown elsewhere in another mode, the cable pulls differently: no spurious following."""
    modes = TensionModes(FOLLOW)
    _run(modes, 0, 3, HOVER, lambda t: _cable_pull(HOVER, 4.0))
    elsewhere = np.array([-1.0, 4.0, -6.0])
    _run(modes, 3, 6, elsewhere, lambda t: _cable_pull(elsewhere, 7.0), mode="LOITER")
    actions = _run(modes, 6, 9, elsewhere, lambda t: _cable_pull(elsewhere, 7.0))
    assert all(a.kind == NOTHING for a in actions) and modes.state == IDLE


def test_position_command_targets_ahead_along_the_pull():
    modes = TensionModes(replace(FOLLOW, command="position", position_lead_m=0.5))
    base = _cable_pull(HOVER)
    _run(modes, 0, 2, HOVER, lambda t: base)
    actions = _run(modes, 2, 3, HOVER, lambda t: base + np.array([-2.0, 0.0, 0.0]))
    targets = [a.position_ned_m for a in actions if a.kind == POSITION_TARGET]
    assert targets and all(np.allclose(p, HOVER + [-0.5, 0.0, 0.0]) for p in targets)


def test_landing_on_first_tug_follows_down_and_lands():
    modes = TensionModes(LANDER)
    base = _cable_pull(HOVER)
    _run(modes, 0, 2, HOVER, lambda t: base)
    pull = np.array([0.0, 0.0, 2.5])  # someone pulls the tether down
    actions = _run(modes, 2, 3, HOVER, lambda t: base + pull)
    assert modes.landing_flag and modes.state == LANDING
    descents = [a.velocity_ned_m_s for a in actions if a.kind == VELOCITY_TARGET]
    assert descents and all(v[2] > 0.0 for v in descents)
    assert all(v[2] <= LANDER.max_descent_speed_mps for v in descents)
    # the pull stops: the landing flag stays, the drone just stops descending
    actions = _run(modes, 3, 4, HOVER, lambda t: base)
    assert modes.landing_flag and all(np.allclose(a.velocity_ned_m_s, 0.0) for a in actions)
    low = np.array([3.0, 0.0, -0.4])
    action = modes.step(_inputs(4.0, low, base + pull))
    assert action.kind == LAND and modes.state == LAND_COMMANDED
    assert modes.step(_inputs(4.05, low, base)).kind == LAND  # until the autopilot switches
    assert modes.step(_inputs(4.1, low, base, mode="LAND")).kind == NOTHING
    modes.step(_inputs(5.0, low, base, armed=False, mode="LAND"))
    assert not modes.landing_flag  # landed and disarmed: cleared


def test_ground_station_landing_request():
    modes = TensionModes(FOLLOW)
    base = _cable_pull(HOVER)
    _run(modes, 0, 1, HOVER, lambda t: base)
    modes.request_landing()
    assert modes.step(_inputs(1.0, HOVER, base)).kind == VELOCITY_TARGET
    assert modes.state == LANDING
    modes.cancel_landing()
    assert modes.step(_inputs(1.05, HOVER, base)).kind == NOTHING and modes.state == IDLE


def test_upward_pull_never_makes_it_climb():
    modes = TensionModes(LANDER)
    base = _cable_pull(HOVER)
    _run(modes, 0, 2, HOVER, lambda t: base)
    modes.request_landing()
    actions = _run(modes, 2, 3, HOVER, lambda t: base + np.array([0.0, 0.0, -5.0]))
    assert all(a.velocity_ned_m_s[2] >= 0.0 for a in actions if a.kind == VELOCITY_TARGET)


@pytest.mark.parametrize(
    ("bad", "reason"),
    [
        ({"force": None}, "no tension"),
        ({"force": [math.nan, 0.0, 1.0]}, "no tension"),
        ({"age_s": 2.0}, "stale"),
        ({"force": [300.0, 0.0, 0.0]}, "absurd"),
        ({"position": [math.nan, 0.0, -3.0]}, "no position"),
    ],
)
def test_lost_estimate_stops_then_lands(bad, reason):
    modes = TensionModes(FOLLOW)
    base = _cable_pull(HOVER)
    _run(modes, 0, 2, HOVER, lambda t: base)
    _run(modes, 2, 3, HOVER, lambda t: base + np.array([0.0, 3.0, 0.0]))
    assert modes.state == FOLLOWING
    kwargs = {"force": base + np.array([0.0, 3.0, 0.0]), "position": HOVER}
    kwargs.update(bad)
    position, force = kwargs.pop("position"), kwargs.pop("force")
    actions = [
        modes.step(_inputs(t, position, force, **kwargs))
        for t in np.arange(3.0, 3.0 + FOLLOW.lost_timeout_s + 0.2, DT)
    ]
    assert actions[0].kind == VELOCITY_TARGET and np.all(actions[0].velocity_ned_m_s == 0.0)
    assert reason in actions[0].reason
    assert all(a.kind == NOTHING for a in actions[1 : int(FOLLOW.lost_timeout_s / DT) - 1])
    assert actions[-1].kind == LAND and modes.state == FALLBACK_LAND
    assert modes.fallback_lands == 1


def test_unknown_height_while_landing_lands():
    modes = TensionModes(LANDER)
    base = _cable_pull(HOVER)
    _run(modes, 0, 1, HOVER, lambda t: base)
    modes.request_landing()
    for t in (1.0, 1.05, 1.1):
        assert modes.step(_inputs(t, HOVER, base, height=math.nan)).kind == LAND
    assert modes.fallback_lands == 1 and modes.state == FALLBACK_LAND


_finite = st.floats(min_value=-100.0, max_value=100.0)
_any = st.one_of(_finite, st.just(math.nan), st.just(math.inf), st.just(-math.inf))


@settings(max_examples=200, deadline=None)
@given(
    force=st.lists(_any, min_size=3, max_size=3),
    position=st.lists(_any, min_size=3, max_size=3),
    age=st.one_of(st.floats(min_value=0.0, max_value=10.0), st.just(math.nan)),
    height=_any,
)
def test_never_sends_nonfinite_or_moves_on_bad_input(force, position, age, height):
    """Whatever arrives, an action never carries NaN/inf, and a bad estimate never yields a
    non-zero motion target."""
    modes = TensionModes(LANDER)
    base = _cable_pull(HOVER)
    _run(modes, 0, 1, HOVER, lambda t: base)
    modes.request_landing()
    inputs = ModeInputs(
        time_s=1.0,
        tension=_tension(force, 1.0, age),
        armed=True,
        flight_mode="GUIDED",
        position_ned_m=np.asarray(position, dtype=float),
        height_m=height,
    )
    action = modes.step(inputs)
    for vector in (action.velocity_ned_m_s, action.position_ned_m):
        assert vector is None or np.isfinite(vector).all()
    bad = (
        not np.isfinite(force).all()
        or not np.isfinite(position).all()
        or not age <= LANDER.max_tension_age_s
        or np.linalg.norm(force) > LANDER.max_tension_n
    )
    if bad:
        assert action.kind == NOTHING or (
            action.kind == VELOCITY_TARGET and not action.velocity_ned_m_s.any()
        )


@pytest.mark.parametrize(
    ("mapping", "key"),
    [
        ({"horizontal_threshold_n": 0.0}, "horizontal_threshold_n"),
        ({"horizontal_threshold_n": 1.0, "horizontal_release_n": 1.5}, "horizontal_release_n"),
        ({"vertical_release_n": 2.0}, "vertical_release_n"),
        ({"land_height_m": 0.0}, "land_height_m"),
        ({"guided_modes": []}, "guided_modes"),
        ({"max_tension_n": 0.5}, "max_tension_n"),
        ({"command": "attitude"}, "command"),
        ({"follow_gain_mps_per_n": math.inf}, "follow_gain_mps_per_n"),
        ({"debounce": 1.0}, "debounce"),
    ],
)
def test_config_refuses_bad_thresholds(mapping, key):
    with pytest.raises(ConfigError, match=key):
        from_mapping(TensionModeConfig, mapping, source="companion.yaml")
