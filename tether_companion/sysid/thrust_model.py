"""Identified thrust models as the estimator's :class:`ThrustInput`, and their YAML files.

``tether-companion sysid --out thrust.yaml`` writes one of two kinds:

- ``kind: static``: a per-motor quadratic ``thrust_curve`` in the vehicle profile's format
  (it can be pasted into ``configs/vehicles/*.yaml``);
- ``kind: linear``: a discrete state-space model of the motor dynamics about an operating
  point, ``x(k+1) = A x + B (v - v0)``, ``T = T0 + C x + D (v - v0)``, sampled every
  ``sample_time_s``, with ``v`` the PWM mapped by ``input_map`` (PWM itself, or each motor's
  normalised throttle and its square). ARX, output error, Box-Jenkins, state-space,
  transfer-function and process models are all written this way (their input paths; the
  noise model only serves prediction from measured thrust, which the estimator does not
  have).

:func:`load_thrust_model` reads either into an object with
``total_thrust_n(pwm_us, time_s) -> float``: a static file into the estimator's
:class:`~tether_companion.estimation.thrust_input.StaticThrustInput`, a linear one into
:class:`LinearThrust`.

A model identified on battery-compensated commands (:mod:`tether_companion.sysid.battery`)
carries a ``battery`` section with the voltage range; both kinds then scale each motor
command by the measured voltage's ratio (``set_battery_voltage_v``) exactly as the
identification did. Without the section (``voltage_max_v: 0``) the commands are used as
they are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from tether_companion.config import ConfigError, from_mapping, read_yaml, spec
from tether_companion.estimation.thrust_input import StaticThrustInput
from tether_companion.physics.battery import BatteryCompensation
from tether_companion.physics.thrust import ThrustCurve
from tether_companion.sysid.battery import compensated_pwm_us
from tether_companion.sysid.input_map import InputMap

FloatArray = NDArray[np.float64]

MAX_GAP_STEPS = 100
"""A pause longer than this many model samples restarts the model in steady state."""


@dataclass(frozen=True)
class StaticModelFile:
    """Schema of a ``kind: static`` thrust-model file."""

    kind: str = spec("static", choices=("static",), doc="model kind")
    structure: str = spec("static", doc="structure the model came from")
    n_motors: int = spec(4, minimum=1, maximum=16, doc="number of motors")
    thrust_curve: ThrustCurve = spec(default_factory=ThrustCurve, doc="per-motor curve")
    battery: BatteryCompensation = spec(
        default_factory=BatteryCompensation,
        doc="voltage range the commands were compensated with at identification (0: none)",
    )
    metrics: dict[str, float] = spec(default_factory=dict, doc="identification metrics")


@dataclass(frozen=True)
class LinearModelFile:
    """Schema of a ``kind: linear`` thrust-model file (see module docstring)."""

    input_operating_point: tuple[float, ...] = spec(doc="v0, one per model input")
    thrust_operating_point_n: float = spec(doc="T0 [N]")
    a: tuple[tuple[float, ...], ...] = spec(doc="A, n x n")
    b: tuple[tuple[float, ...], ...] = spec(doc="B, n x n_inputs")
    c: tuple[tuple[float, ...], ...] = spec(doc="C, 1 x n")
    d: tuple[tuple[float, ...], ...] = spec(doc="D, 1 x n_inputs")
    kind: str = spec("linear", choices=("linear",), doc="model kind")
    structure: str = spec("arx", doc="structure the model came from")
    orders: str = spec("", doc="orders, for the record")
    sample_time_s: float = spec(
        0.01, exclusive_minimum=0.0, maximum=1.0, doc="model sample time [s]"
    )
    input_map: InputMap = spec(default_factory=InputMap, doc="PWM to model input")
    battery: BatteryCompensation = spec(
        default_factory=BatteryCompensation,
        doc="voltage range the commands were compensated with at identification (0: none)",
    )
    metrics: dict[str, float] = spec(default_factory=dict, doc="identification metrics")

    def validate(self) -> None:
        """Matrix shapes must agree and the model must be stable (all |eig(A)| < 1)."""
        n, m = len(self.a), len(self.input_operating_point)
        if m % self.input_map.inputs_per_motor():
            raise ConfigError(
                "",
                "input_operating_point",
                m,
                f"needs {self.input_map.inputs_per_motor()} values per motor",
            )
        checks = (
            ("a", self.a, (n, n)),
            ("b", self.b, (n, m)),
            ("c", self.c, (1, n)),
            ("d", self.d, (1, m)),
        )
        for key, rows, (r, cols) in checks:
            if len(rows) != r or any(len(row) != cols for row in rows):
                raise ConfigError("", key, rows, f"must be a {r} x {cols} matrix")
        if n and np.max(np.abs(np.linalg.eigvals(np.array(self.a)))) >= 1.0:
            raise ConfigError("", "a", self.a, "the model must be stable (all |eig(A)| < 1)")


@dataclass
class LinearThrust:
    """A discrete linear thrust model run on PWM samples arriving at any times.

    The model steps every ``sample_time_s``. Between steps the PWM is held (as the flight
    controller holds its outputs), and each step's input is the time average of the mapped
    PWM over the step, which also keeps fast output chatter from aliasing. The first sample,
    a jump back in time or a pause longer than ``MAX_GAP_STEPS`` steps restarts the model in
    steady state for the current PWM. The output interpolates the state between the last
    step boundary and the next (predicted from the input so far), plus the direct term.
    With a ``battery`` range in the file, each PWM's command is first scaled by the voltage
    ratio (:meth:`set_battery_voltage_v`; 1 until a voltage is measured).
    """

    model_file: LinearModelFile
    _a: FloatArray = field(init=False, repr=False)
    _b: FloatArray = field(init=False, repr=False)
    _c: FloatArray = field(init=False, repr=False)
    _d: FloatArray = field(init=False, repr=False)
    _v0: FloatArray = field(init=False, repr=False)
    _x: FloatArray | None = field(default=None, init=False, repr=False)
    _held: FloatArray | None = field(default=None, init=False, repr=False)
    _sum: FloatArray | None = field(default=None, init=False, repr=False)
    _last_s: float = field(default=math.nan, init=False, repr=False)
    _boundary_s: float = field(default=math.nan, init=False, repr=False)
    voltage_ratio: float = field(default=1.0, init=False)

    def __post_init__(self) -> None:
        self._a = np.array(self.model_file.a, dtype=float).reshape(len(self.model_file.a), -1)
        self._b = np.array(self.model_file.b, dtype=float).reshape(self._a.shape[0], -1)
        self._c = np.array(self.model_file.c, dtype=float).reshape(1, -1)
        self._d = np.array(self.model_file.d, dtype=float).reshape(1, -1)
        self._v0 = np.array(self.model_file.input_operating_point, dtype=float)

    @property
    def n_motors(self) -> int:
        """Number of PWM inputs."""
        return int(self._v0.shape[0]) // self.model_file.input_map.inputs_per_motor()

    def set_battery_voltage_v(self, voltage_v: float) -> None:
        """Measured battery voltage [V]; ignored when the model was identified without
        compensation, a non-finite value keeps the ratio at 1."""
        if self.model_file.battery.enabled:
            self.voltage_ratio = self.model_file.battery.ratio(voltage_v)

    def _restart(self, v: FloatArray, time_s: float) -> None:
        n = self._a.shape[0]
        self._x = np.linalg.solve(np.eye(n) - self._a, self._b @ (v - self._v0))
        self._sum = np.zeros_like(v)
        self._last_s = time_s
        self._boundary_s = time_s + self.model_file.sample_time_s

    def total_thrust_n(self, pwm_us: FloatArray, time_s: float) -> float:
        """Total thrust [N] for pulse widths ``pwm_us`` (shape (n_motors,)) at ``time_s`` [s].

        Raises
        ------
        ValueError
            When the number of pulse widths is wrong or an input is not finite.
        """
        pwm = np.asarray(pwm_us, dtype=float)
        if pwm.shape != (self.n_motors,) or not (
            np.all(np.isfinite(pwm)) and math.isfinite(time_s)
        ):
            raise ValueError(f"expected {self.n_motors} finite pulse widths and a finite time")
        if self.model_file.battery.enabled:
            input_map = self.model_file.input_map
            pwm = compensated_pwm_us(
                pwm, (input_map.pwm_min_us, input_map.pwm_max_us), self.voltage_ratio
            )
        v = self.model_file.input_map.map_pwm(pwm)
        dt = self.model_file.sample_time_s
        if self._x is None or time_s < self._last_s or time_s - self._last_s > MAX_GAP_STEPS * dt:
            self._restart(v, time_s)
        else:
            self._advance(time_s)
        self._held = v
        thrust = (
            self.model_file.thrust_operating_point_n
            + self._c @ self._state_now()
            + self._d @ (v - self._v0)
        )
        return max(float(thrust[0]), 0.0)

    def _state_now(self) -> FloatArray:
        """State interpolated between the last boundary and the next, which is predicted from
        the input average so far (removes most of the half-sample latency of a sampled model)."""
        dt = self.model_file.sample_time_s
        elapsed = dt - (self._boundary_s - self._last_s)
        if elapsed <= 0.0:
            return self._x
        upcoming = self._a @ self._x + self._b @ (self._sum / elapsed - self._v0)
        return self._x + (elapsed / dt) * (upcoming - self._x)

    def _advance(self, time_s: float) -> None:
        """Integrate the held input up to ``time_s``, stepping at every boundary passed."""
        dt = self.model_file.sample_time_s
        while self._last_s < time_s:
            end = min(time_s, self._boundary_s)
            self._sum = self._sum + self._held * (end - self._last_s)
            self._last_s = end
            if end >= self._boundary_s - 1e-12:
                self._x = self._a @ self._x + self._b @ (self._sum / dt - self._v0)
                self._sum = np.zeros_like(self._sum)
                self._boundary_s += dt


def model_file_mapping(
    model_mapping: dict[str, Any],
    metrics: dict[str, float],
    battery: BatteryCompensation | None = None,
) -> dict[str, Any]:
    """A fitted model's ``to_mapping()`` with the battery range it was identified with (when
    compensated) and its metrics added, ready for YAML."""
    mapping = dict(model_mapping)
    if battery is not None and battery.enabled:
        mapping["battery"] = {
            "voltage_max_v": float(battery.voltage_max_v),
            "voltage_min_v": float(battery.voltage_min_v),
        }
    return {**mapping, "metrics": {k: float(v) for k, v in metrics.items()}}


def save_thrust_model(path: str | Path, mapping: dict[str, Any], header: str) -> None:
    """Write a thrust-model mapping as YAML with a comment ``header`` (one or more lines)."""
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    Path(path).write_text(comment + yaml.safe_dump(mapping, sort_keys=False), encoding="utf-8")


def thrust_input_from_mapping(
    data: dict[str, Any], source: str = ""
) -> StaticThrustInput | LinearThrust:
    """Build the :class:`ThrustInput` a thrust-model mapping describes.

    Raises
    ------
    ConfigError
        When ``kind`` is missing or unknown, or any field is invalid.
    """
    kind = data.get("kind")
    if kind == "static":
        return StaticThrustInput(from_mapping(StaticModelFile, data, source=source))
    if kind == "linear":
        return LinearThrust(from_mapping(LinearModelFile, data, source=source))
    raise ConfigError(source, "kind", kind, "must be 'static' or 'linear'")


def load_thrust_model(path: str | Path) -> StaticThrustInput | LinearThrust:
    """Read a thrust-model YAML file (written by ``tether-companion sysid --out``).

    Raises
    ------
    ConfigError
        When the file is missing, not YAML, or describes an invalid or unstable model.
    """
    return thrust_input_from_mapping(dict(read_yaml(path)), source=str(path))
