"""A parameter's documented range and default, and reading one value checked against them."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from tether_companion.config import ConfigError


@dataclass(frozen=True)
class ParamRange:
    """A parameter's documented range (the autopilot's ``@Range`` / ``@min``, ``@max``) and
    the firmware default used when the parameter is absent (None: the parameter is required)."""

    minimum: float
    maximum: float
    default: float | None


def checked_value(params: Mapping[str, float], name: str, spec: ParamRange, source: str) -> float:
    """``params[name]`` (or the default when absent), refused outside ``spec``'s range.

    Raises
    ------
    ConfigError
        Naming ``name`` and its value when it is missing without a default, not finite, or
        outside the documented range.
    """
    if name not in params:
        if spec.default is None:
            raise ConfigError(source, name, "<missing>", "is required to build the vehicle")
        return spec.default
    value = float(params[name])
    if not math.isfinite(value) or not spec.minimum <= value <= spec.maximum:
        raise ConfigError(
            source,
            name,
            value,
            f"outside its documented range [{spec.minimum:g}, {spec.maximum:g}]",
        )
    return value
