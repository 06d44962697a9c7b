"""Root finding on a bracket for the cable models (pure numerics, no units of its own)."""

from __future__ import annotations

from collections.abc import Callable


def bracketed_root(
    func: Callable[[float], float],
    low: float,
    high: float,
    tolerance: float,
    f_low: float | None = None,
) -> float:
    """Root of an increasing ``func`` on [low, high] (func(low) <= 0 <= func(high)).

    Regula falsi with the Illinois modification (superlinear, never leaves the bracket),
    stopping when the bracket is narrower than ``tolerance`` or ``func`` is exactly zero.
    ``f_low`` is ``func(low)`` when the caller has it already. The root returned is one of
    the points ``func`` was evaluated at.
    """
    f_low, f_high = func(low) if f_low is None else f_low, func(high)
    side = 0
    for _ in range(100):
        if f_high - f_low <= 0.0:
            break
        x = high - f_high * (high - low) / (f_high - f_low)
        if not low < x < high:
            x = 0.5 * (low + high)
        fx = func(x)
        if fx == 0.0:
            return x
        if fx < 0.0:
            low, f_low = x, fx
            if side == -1:
                f_high *= 0.5
            side = -1
        else:
            high, f_high = x, fx
            if side == 1:
                f_low *= 0.5
            side = 1
        if high - low < tolerance:
            break
    return low if abs(f_low) < abs(f_high) else high
