"""Physical constants shared by every model (SI units)."""

GRAVITY_MPS2: float = 9.80665
"""Standard gravity [m/s^2], the value ArduPilot and PX4 use (GRAVITY_MSS)."""
