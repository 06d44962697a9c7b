"""Local NED offsets <-> latitude/longitude, and the messages that carry global positions.

Uses ArduPilot's flat-earth approximation (``Location::offset`` / ``get_distance_NED``): a
sphere of the WGS-84 equatorial radius, longitude scaled by cos(latitude). Over a tether's
reach (tens to hundreds of metres) its error is far below a millimetre per metre, and it makes
the emulator's global positions agree with what ArduPilot itself would compute.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.mavlink.units import (
    INT16_MAX,
    INT16_MIN,
    quaternion_from_euler,
    saturate_int,
    seconds_to_boot_ms,
)

FloatArray = NDArray[np.float64]

EARTH_RADIUS_M: float = 6378137.0
"""WGS-84 equatorial radius [m] (ArduPilot's RADIUS_OF_EARTH)."""
_M_PER_DEG: float = math.radians(1.0) * EARTH_RADIUS_M
INT32_MIN, INT32_MAX = -(1 << 31), (1 << 31) - 1


@dataclass(frozen=True, slots=True)
class Geodetic:
    """A point on the Earth: latitude and longitude [deg], altitude above mean sea level [m]."""

    lat_deg: float
    lon_deg: float
    alt_m: float

    def __post_init__(self) -> None:
        if not (-90.0 <= self.lat_deg <= 90.0 and -180.0 <= self.lon_deg <= 180.0):
            raise ValueError(f"latitude/longitude out of range: {self.lat_deg}, {self.lon_deg}")
        if not math.isfinite(self.alt_m):
            raise ValueError(f"altitude must be finite, got {self.alt_m}")

    @property
    def lat_e7(self) -> int:
        """Latitude in degE7 (MAVLink int32)."""
        return saturate_int(self.lat_deg * 1e7, INT32_MIN, INT32_MAX)

    @property
    def lon_e7(self) -> int:
        """Longitude in degE7 (MAVLink int32)."""
        return saturate_int(self.lon_deg * 1e7, INT32_MIN, INT32_MAX)

    @property
    def alt_mm(self) -> int:
        """Altitude in millimetres (MAVLink int32)."""
        return saturate_int(self.alt_m * 1e3, INT32_MIN, INT32_MAX)

    @classmethod
    def from_e7(cls, lat_e7: int, lon_e7: int, alt_mm: int) -> Geodetic:
        """From MAVLink's degE7 / mm integers (SET_GPS_GLOBAL_ORIGIN, HOME_POSITION, ...)."""
        return cls(lat_e7 * 1e-7, lon_e7 * 1e-7, alt_mm * 1e-3)


def ned_to_geodetic(origin: Geodetic, position_ned_m: ArrayLike) -> Geodetic:
    """The point ``position_ned_m`` [m] (NED, relative to ``origin``) as lat/lon/alt."""
    n, e, d = (float(v) for v in np.asarray(position_ned_m, dtype=float))
    lat = origin.lat_deg + n / _M_PER_DEG
    scale = max(math.cos(math.radians(origin.lat_deg)), 0.01)
    lon = origin.lon_deg + e / (_M_PER_DEG * scale)
    lon = (lon + 180.0) % 360.0 - 180.0
    return Geodetic(max(-90.0, min(90.0, lat)), lon, origin.alt_m - d)


def geodetic_to_ned(origin: Geodetic, point: Geodetic) -> FloatArray:
    """NED offset [m] of ``point`` from ``origin``, shape (3,)."""
    scale = max(math.cos(math.radians(origin.lat_deg)), 0.01)
    dlon = (point.lon_deg - origin.lon_deg + 180.0) % 360.0 - 180.0
    return np.array(
        [
            (point.lat_deg - origin.lat_deg) * _M_PER_DEG,
            dlon * _M_PER_DEG * scale,
            origin.alt_m - point.alt_m,
        ]
    )


def global_position_int_message(
    time_s: float,
    home: Geodetic,
    position_ned_m: ArrayLike,
    velocity_ned_m_s: ArrayLike,
    yaw_rad: float,
) -> MAVLinkMessage:
    """GLOBAL_POSITION_INT: degE7, altitude AMSL and above home [mm], velocity [cm/s], cdeg."""
    point = ned_to_geodetic(home, position_ned_m)
    v = np.asarray(velocity_ned_m_s, dtype=float)
    heading_cdeg = saturate_int(math.degrees(yaw_rad) % 360.0 * 100.0, 0, 35999)
    return dialect.MAVLink_global_position_int_message(
        seconds_to_boot_ms(time_s),
        point.lat_e7,
        point.lon_e7,
        point.alt_mm,
        saturate_int(
            -float(np.asarray(position_ned_m, dtype=float)[2]) * 1e3, INT32_MIN, INT32_MAX
        ),
        *(saturate_int(float(x) * 100.0, INT16_MIN, INT16_MAX) for x in v),
        heading_cdeg,
    )


def sim_state_message(
    home: Geodetic,
    position_ned_m: ArrayLike,
    velocity_ned_m_s: ArrayLike,
    euler_rad: tuple[float, float, float],
    specific_force_body_mps2: ArrayLike,
    body_rates_rad_s: ArrayLike,
) -> MAVLinkMessage:
    """SIM_STATE: the simulator's ground truth, as ArduPilot SITL sends it.

    Accelerations are the noise-free specific force in the FRD body frame [m/s^2].
    """
    point = ned_to_geodetic(home, position_ned_m)
    acc = np.asarray(specific_force_body_mps2, dtype=float)
    rates = np.asarray(body_rates_rad_s, dtype=float)
    v = np.asarray(velocity_ned_m_s, dtype=float)
    return dialect.MAVLink_sim_state_message(
        *quaternion_from_euler(*euler_rad),
        *(float(a) for a in euler_rad),
        *(float(a) for a in acc),
        *(float(r) for r in rates),
        float(point.lat_deg),
        float(point.lon_deg),
        float(point.alt_m),
        0.0,
        0.0,
        *(float(x) for x in v),
        point.lat_e7,
        point.lon_e7,
    )
