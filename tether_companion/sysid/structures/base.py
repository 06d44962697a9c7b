"""What every model structure shares: the fitting context and the fitted-model protocol."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from tether_companion.sysid.input_map import InputMap
from tether_companion.sysid.linear_model import PolynomialModel
from tether_companion.sysid.processing import IdData

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FitContext:
    """Facts a structure may need beyond the data.

    Attributes
    ----------
    u0
        Input operating point: mean mapped input of the estimation data, shape (4,), in the
        input map's unit.
    y0_n
        Output operating point: mean thrust of the estimation data [N].
    dt_s
        Sample time [s].
    pwm_min_us, pwm_max_us
        The vehicle's PWM range (zero and full command) [us].
    input_map
        Static map from PWM to the linear models' inputs.
    """

    u0: FloatArray
    y0_n: float
    dt_s: float
    pwm_min_us: float
    pwm_max_us: float
    input_map: InputMap = field(default_factory=InputMap)

    @classmethod
    def from_data(
        cls,
        experiments: Sequence[IdData],
        pwm_range_us: tuple[float, float],
        input_map: InputMap | None = None,
    ) -> FitContext:
        """Operating point from the pooled estimation experiments."""
        input_map = input_map or InputMap(pwm_min_us=pwm_range_us[0], pwm_max_us=pwm_range_us[1])
        mapped = np.concatenate([input_map.inputs(e) for e in experiments])
        thrust = np.concatenate([e.thrust_n for e in experiments])
        return cls(
            u0=mapped.mean(axis=0),
            y0_n=float(thrust.mean()),
            dt_s=experiments[0].dt_s,
            pwm_min_us=pwm_range_us[0],
            pwm_max_us=pwm_range_us[1],
            input_map=input_map,
        )

    def centred(self, data: IdData) -> tuple[FloatArray, FloatArray]:
        """``(map(pwm) - u0, thrust - y0)`` of one experiment, shapes (n, 4) and (n,)."""
        return self.input_map.inputs(data) - self.u0, data.thrust_n - self.y0_n

    def model(
        self,
        f: FloatArray,
        b: FloatArray,
        c: FloatArray | None = None,
        d: FloatArray | None = None,
    ) -> PolynomialModel:
        """A :class:`PolynomialModel` about this operating point (``C = D = 1`` by default)."""
        one = np.ones(1)
        return PolynomialModel(
            f=f,
            b=b,
            c=one if c is None else c,
            d=one if d is None else d,
            u0=self.u0,
            y0_n=self.y0_n,
            dt_s=self.dt_s,
            input_map=self.input_map,
        )


class FittedModel(Protocol):
    """A fitted thrust model: predicts, simulates and describes itself."""

    structure: str
    orders: str

    @property
    def n_params(self) -> int:
        """Number of estimated parameters (for Akaike's FPE)."""
        ...

    def simulate(self, data: IdData) -> FloatArray:
        """Thrust [N], shape (n,), from the motor inputs alone."""
        ...

    def predict(self, data: IdData, k: int) -> FloatArray:
        """k-step-ahead predicted thrust [N], shape (n,), from inputs and measured thrust."""
        ...

    def to_mapping(self) -> dict[str, Any]:
        """Plain data for the thrust-model YAML file."""
        ...


@dataclass(frozen=True)
class LinearFit:
    """A fitted linear structure: a :class:`PolynomialModel` and its name and orders."""

    structure: str
    orders: str
    model: PolynomialModel

    @property
    def n_params(self) -> int:
        """Free parameters of the polynomial model."""
        return self.model.n_params

    def simulate(self, data: IdData) -> FloatArray:
        """See :meth:`PolynomialModel.simulate`."""
        return self.model.simulate(data)

    def predict(self, data: IdData, k: int) -> FloatArray:
        """See :meth:`PolynomialModel.predict`."""
        return self.model.predict(data, k)

    def to_mapping(self) -> dict[str, Any]:
        """The input paths as a state-space model about the operating point."""
        a, b, c, d = self.model.state_space()
        return {
            "kind": "linear",
            "structure": self.structure,
            "orders": self.orders,
            "sample_time_s": float(self.model.dt_s),
            "input_map": self.model.input_map.to_mapping(),
            "input_operating_point": [float(x) for x in self.model.u0],
            "thrust_operating_point_n": float(self.model.y0_n),
            "a": a.tolist(),
            "b": b.tolist(),
            "c": c.tolist(),
            "d": d.tolist(),
        }
