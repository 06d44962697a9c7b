"""Tension-following and landing by the tether: pure decision logic (Martins 2019, 5.1).

The service calls :meth:`TensionModes.step` at its control rate with the filtered tension,
the flight controller's armed state and flight mode, the position estimate and the height,
and sends what the returned :class:`ModeAction` asks for (a GUIDED velocity or position
target, or the autopilot's LAND). Nothing here does I/O or reads a clock.

What the drone does
-------------------
* The cable itself always pulls: toward the anchor horizontally and down. The mode learns that
  pull while idle (a first-order low-pass, ``baseline_time_constant_s``) in the frame of the
  anchor direction (radial and tangential components, plus the vertical one), so a drone that
  moved keeps the learnt pull pointing at the anchor. Only the pull **beyond** it counts.
* Following (Martins: "the goal position is successively updated"): a horizontal extra pull
  above ``horizontal_threshold_n`` for ``debounce_s`` starts it; the drone is sent along the
  pull at ``follow_gain_mps_per_n`` per newton (or to a position ``position_lead_m`` ahead),
  and when the extra pull stays below ``horizontal_release_n`` for ``debounce_s`` it holds
  where it is (a position target at the current position), and the learnt pull is reset to
  the one felt there.
* Landing: with ``land_on_first_tug`` the first detected pull (horizontal, or downward above
  ``vertical_threshold_n``: a tug or the winch reeling in) sets the landing flag; a ground
  station can set it with :meth:`TensionModes.request_landing`. With the flag set the drone
  follows the extra pull in 3D, downward included (never upward), with dead bands of the
  release thresholds; below ``land_height_m`` the autopilot's LAND is commanded, and the
  autopilot lands and disarms.

Safety
------
* Acts only when enabled, armed and in one of ``guided_modes``; otherwise returns nothing and
  forgets any following (disarming also clears the landing flag).
* Never moves the drone on a bad estimate: a tension estimate that is missing, non-finite,
  older than ``max_tension_age_s`` or larger than ``max_tension_n``, or a non-finite position,
  stops any motion at once (zero velocity target) and, if it lasts ``lost_timeout_s``, makes
  the autopilot LAND (as does an unknown height while landing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tether_companion.estimation.tension_kf import TensionEstimate
from tether_companion.modes.config import POSITION, TensionModeConfig

FloatArray = NDArray[np.float64]

# action kinds
NOTHING = "none"
VELOCITY_TARGET = "velocity"
POSITION_TARGET = "position"
LAND = "land"

# states
DISABLED = "disabled"
INACTIVE = "inactive"
IDLE = "idle"
FOLLOWING = "following"
LANDING = "landing"
LAND_COMMANDED = "land_commanded"
FALLBACK_LAND = "fallback_land"


@dataclass(frozen=True, slots=True)
class ModeInputs:
    """What the mode sees at one tick.

    Attributes
    ----------
    time_s
        Time of the tick [s], in the same clock as the tension estimate's ``time_s``.
    tension
        Latest filtered tension (``None`` if there is none).
    armed
        Flight controller armed.
    flight_mode
        Flight controller mode name (e.g. ``GUIDED``, ``LAND``).
    position_ned_m
        Position estimate relative to the anchor, NED, shape (3,) [m] (``nan`` if none).
    height_m
        Height above the ground [m] (rangefinder or estimate; ``nan`` if unknown).
    """

    time_s: float
    tension: TensionEstimate | None
    armed: bool
    flight_mode: str
    position_ned_m: FloatArray
    height_m: float


@dataclass(frozen=True, slots=True)
class ModeAction:
    """What the service should send now.

    Attributes
    ----------
    kind
        ``none``, ``velocity`` (GUIDED velocity target), ``position`` (GUIDED position target)
        or ``land`` (switch the autopilot to LAND).
    velocity_ned_m_s
        Velocity target, NED, shape (3,) [m/s] (``velocity`` only).
    position_ned_m
        Position target relative to the anchor, NED, shape (3,) [m] (``position`` only).
    reason
        Why, for logs and STATUSTEXT.
    """

    kind: str
    velocity_ned_m_s: FloatArray | None = None
    position_ned_m: FloatArray | None = None
    reason: str = ""


_NOTHING = ModeAction(NOTHING)


class TensionModes:
    """The tension-following / landing state machine (see the module docstring).

    Parameters
    ----------
    config
        Validated thresholds and gains.
    """

    def __init__(self, config: TensionModeConfig) -> None:
        self.config = config
        self.enabled = config.enabled
        self.state = DISABLED if not config.enabled else INACTIVE
        self.landing_flag = False
        self._guided = frozenset(config.guided_modes)
        self._radial = np.array((1.0, 0.0))  # unit vector toward the anchor (horizontal)
        self._baseline: FloatArray | None = None  # (radial, tangential, down) [N]
        self._last_time_s = math.nan
        self._pull_since_s = math.nan
        self._release_since_s = math.nan
        self._lost_since_s = math.nan
        self._stopped = False
        self.fallback_lands = 0
        """Times a lost input made the logic hand over to the autopilot's LAND."""
        self._fallback_active = False

    # ------------------------------------------------------------------ commands
    def set_enabled(self, enabled: bool) -> None:
        """Enable or disable the mode (from the CLI or a ground station)."""
        self.enabled = bool(enabled)
        if not self.enabled:
            self._forget(clear_flag=True)
            self.state = DISABLED

    def request_landing(self) -> None:
        """Set the landing flag (a ground-station command); effective while active."""
        self.landing_flag = True

    def cancel_landing(self) -> None:
        """Clear the landing flag; the learnt cable pull is re-learnt from the next tick."""
        self.landing_flag = False
        self._baseline = None
        if self.state in (LANDING, LAND_COMMANDED):
            self.state = IDLE

    # ------------------------------------------------------------------ the tick
    def step(self, inputs: ModeInputs) -> ModeAction:
        """Decide what to do at ``inputs.time_s`` (see the module docstring)."""
        t = inputs.time_s
        dt = t - self._last_time_s if math.isfinite(self._last_time_s) else 0.0
        self._last_time_s = t
        if not self.enabled:
            self.state = DISABLED
            return _NOTHING
        if not inputs.armed:
            self._forget(clear_flag=True)
            self.state = INACTIVE
            return _NOTHING
        if inputs.flight_mode not in self._guided:
            self._forget(clear_flag=False)
            self.state = INACTIVE
            return _NOTHING
        if self.state in (DISABLED, INACTIVE):
            # (re-)entering: the cable's pull is learnt afresh where the drone is now
            self._baseline = None
            self.state = LANDING if self.landing_flag else IDLE

        problem = self._input_problem(inputs)
        if problem:
            return self._on_lost(t, problem)
        self._lost_since_s = math.nan
        if self.state == FALLBACK_LAND:
            self.state = LANDING if self.landing_flag else IDLE
        if self.state == LAND_COMMANDED:
            return ModeAction(LAND, reason="landing by the tether: below the landing height")
        if self.landing_flag and self.state != LANDING:
            self.state = LANDING
        assert inputs.tension is not None  # checked by _input_problem
        position = inputs.position_ned_m
        tension = inputs.tension.tension_ned_n
        excess = self._excess(position, tension)
        if self.state == IDLE:
            action = self._idle(t, dt, excess, position, tension)
        elif self.state == FOLLOWING:
            action = self._following(t, excess, position, tension)
        else:
            action = self._landing(inputs, excess, position)
        if self.state != FALLBACK_LAND:
            self._fallback_active = False
        return action

    # ------------------------------------------------------------------ states
    def _idle(
        self, t: float, dt: float, excess: FloatArray, position: FloatArray, tension: FloatArray
    ) -> ModeAction:
        cfg = self.config
        horizontal = math.hypot(excess[0], excess[1])
        pulled = horizontal > cfg.horizontal_threshold_n
        if cfg.land_on_first_tug:
            pulled = pulled or excess[2] > cfg.vertical_threshold_n
        if not pulled:
            self._pull_since_s = math.nan
            self._learn(dt, position, tension)
            return _NOTHING
        if math.isnan(self._pull_since_s):
            self._pull_since_s = t
        if t - self._pull_since_s < cfg.debounce_s:
            return _NOTHING
        self._pull_since_s = math.nan
        self._stopped = False
        if cfg.land_on_first_tug:
            self.landing_flag = True
            self.state = LANDING
            return self._move(excess, position, landing=True, reason="tug: landing by the tether")
        self.state = FOLLOWING
        return self._move(excess, position, landing=False, reason="following the pull")

    def _following(
        self, t: float, excess: FloatArray, position: FloatArray, tension: FloatArray
    ) -> ModeAction:
        cfg = self.config
        if math.hypot(excess[0], excess[1]) < cfg.horizontal_release_n:
            if math.isnan(self._release_since_s):
                self._release_since_s = t
            if t - self._release_since_s >= cfg.debounce_s:
                self._release_since_s = math.nan
                self.state = IDLE
                self._baseline = None
                self._learn(0.0, position, tension)
                return ModeAction(
                    POSITION_TARGET, position_ned_m=position.copy(), reason="pull stopped: hold"
                )
        else:
            self._release_since_s = math.nan
        return self._move(excess, position, landing=False, reason="following the pull")

    def _landing(self, inputs: ModeInputs, excess: FloatArray, position: FloatArray) -> ModeAction:
        cfg = self.config
        if not math.isfinite(inputs.height_m):
            return self._fallback("landing by the tether: height unknown, autopilot LAND")
        if inputs.height_m <= cfg.land_height_m:
            self.state = LAND_COMMANDED
            return ModeAction(LAND, reason="landing by the tether: below the landing height")
        return self._move(excess, position, landing=True, reason="landing: following the pull")

    # ------------------------------------------------------------------ helpers
    def _input_problem(self, inputs: ModeInputs) -> str:
        cfg = self.config
        est = inputs.tension
        if est is None or not est.valid:
            return "no tension estimate"
        if not est.age_s(inputs.time_s) <= cfg.max_tension_age_s:
            return "tension estimate stale"
        if not est.magnitude_n <= cfg.max_tension_n:
            return "tension estimate absurd"
        if not np.isfinite(inputs.position_ned_m).all():
            return "no position estimate"
        return ""

    def _on_lost(self, t: float, problem: str) -> ModeAction:
        cfg = self.config
        if math.isnan(self._lost_since_s):
            self._lost_since_s = t
        self._pull_since_s = math.nan
        active = self.state in (FOLLOWING, LANDING, LAND_COMMANDED, FALLBACK_LAND)
        if t - self._lost_since_s >= cfg.lost_timeout_s:
            return self._fallback(f"{problem}: autopilot LAND")
        if active and not self._stopped:
            self._stopped = True
            return ModeAction(
                VELOCITY_TARGET, velocity_ned_m_s=np.zeros(3), reason=f"{problem}: stop"
            )
        return _NOTHING

    def _fallback(self, reason: str) -> ModeAction:
        """Hand over to the autopilot's LAND (counted once per episode)."""
        if not self._fallback_active:
            self.fallback_lands += 1
            self._fallback_active = True
        self.state = FALLBACK_LAND
        return ModeAction(LAND, reason=reason)

    def _frame(self, position: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Unit vectors toward the anchor and 90 deg to its right (horizontal, NED)."""
        horizontal = math.hypot(position[0], position[1])
        if horizontal >= self.config.min_anchor_distance_m:
            self._radial = -position[:2] / horizontal
        radial = self._radial
        return radial, np.array((-radial[1], radial[0]))

    def _excess(self, position: FloatArray, tension: FloatArray) -> FloatArray:
        """Pull beyond the learnt pull of the cable itself, NED, shape (3,) [N]."""
        radial, tangential = self._frame(position)
        if self._baseline is None:
            self._baseline = np.array(
                (tension[:2] @ radial, tension[:2] @ tangential, float(tension[2]))
            )
        b = self._baseline
        expected = b[0] * radial + b[1] * tangential
        return np.array((tension[0] - expected[0], tension[1] - expected[1], tension[2] - b[2]))

    def _learn(self, dt: float, position: FloatArray, tension: FloatArray) -> None:
        radial, tangential = self._frame(position)
        felt = np.array((tension[:2] @ radial, tension[:2] @ tangential, float(tension[2])))
        if self._baseline is None:
            self._baseline = felt
            return
        alpha = min(1.0, max(0.0, dt) / self.config.baseline_time_constant_s)
        self._baseline = self._baseline + alpha * (felt - self._baseline)

    def _move(
        self, excess: FloatArray, position: FloatArray, *, landing: bool, reason: str
    ) -> ModeAction:
        cfg = self.config
        gain = cfg.follow_gain_mps_per_n
        pull_h = excess[:2]
        magnitude_h = math.hypot(pull_h[0], pull_h[1])
        velocity = np.zeros(3)
        if landing:
            if magnitude_h > cfg.horizontal_release_n:
                beyond = magnitude_h - cfg.horizontal_release_n
                velocity[:2] = gain * beyond * pull_h / magnitude_h
            if excess[2] > cfg.vertical_release_n:
                descent = gain * (excess[2] - cfg.vertical_release_n)
                velocity[2] = min(descent, cfg.max_descent_speed_mps)
        else:
            velocity[:2] = gain * pull_h
        speed_h = math.hypot(velocity[0], velocity[1])
        if speed_h > cfg.max_horizontal_speed_mps:
            velocity[:2] *= cfg.max_horizontal_speed_mps / speed_h
        self._stopped = False
        if cfg.command == POSITION:
            norm = float(np.linalg.norm(velocity))
            lead = cfg.position_lead_m * velocity / norm if norm > 0.0 else np.zeros(3)
            return ModeAction(POSITION_TARGET, position_ned_m=position + lead, reason=reason)
        return ModeAction(VELOCITY_TARGET, velocity_ned_m_s=velocity, reason=reason)

    def _forget(self, *, clear_flag: bool) -> None:
        """Drop following state (and the landing flag and learnt pull when disarmed)."""
        self._pull_since_s = math.nan
        self._release_since_s = math.nan
        self._lost_since_s = math.nan
        self._stopped = False
        if clear_flag:
            self.landing_flag = False
            self._baseline = None
