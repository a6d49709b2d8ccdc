"""WGS-84 geodesy: geodetic latitude / longitude / altitude <-> ECEF <-> local ENU.

Planning tools give way-points as (latitude, longitude, altitude); the vehicle flies in the local
frame of its EKF origin. This module converts between them exactly on the WGS-84 ellipsoid (no
flat-earth approximation):

- geodetic (lat_deg, lon_deg, alt_m) -> ECEF (x, y, z metres, Earth-centred, Earth-fixed);
- ECEF -> local ENU (east, north, up metres) at a geodetic origin, by the rotation of the
  origin's tangent plane (up along the ellipsoid normal of the origin);
- and back (ECEF -> geodetic by fixed-point iteration, converged to < 1e-12 rad).

Altitudes: the conversions treat ``alt_m`` as the height along the ellipsoid normal. MAVLink
gives altitudes above mean sea level (AMSL); the two differ by the geoid undulation (tens of
metres), which is constant over a flying field to about a centimetre per kilometre, so using
AMSL consistently for both the origin and the way-points gives local positions correct to that
level. The local *up* of a point is then its altitude difference to the origin minus the drop of
the Earth's curvature (7.8 cm at 1 km). ENU <-> NED goes through :mod:`pf_offboard.frames` only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pf_offboard.errors import InputError

WGS84_A_M = 6378137.0  # semi-major axis
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)  # semi-minor axis, 6356752.314245 m
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared


@dataclass(frozen=True)
class GeoPoint:
    """A geodetic position: WGS-84 latitude / longitude (degrees) and altitude (m, AMSL)."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float

    def __post_init__(self) -> None:
        check_geodetic(self.lat_deg, self.lon_deg, self.alt_amsl_m, "origin")


def check_geodetic(lat_deg: float, lon_deg: float, alt_m: float, what: str) -> None:
    """InputError naming ``what`` unless lat in [-90, 90], lon in [-180, 180], alt finite and in [-1 km, 100 km]."""
    vals = (lat_deg, lon_deg, alt_m)
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in vals):
        raise InputError(what, f"latitude, longitude and altitude must be finite numbers, got {vals}")
    if not -90.0 <= lat_deg <= 90.0:
        raise InputError(what, f"latitude {lat_deg:g} deg is outside [-90, 90]")
    if not -180.0 <= lon_deg <= 180.0:
        raise InputError(what, f"longitude {lon_deg:g} deg is outside [-180, 180]")
    if not -1000.0 <= alt_m <= 100000.0:
        raise InputError(what, f"altitude {alt_m:g} m is not plausible (-1 km .. 100 km)")


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, alt_m: ArrayLike) -> NDArray[np.float64]:
    """ECEF (m), shape (..., 3), of geodetic WGS-84 coordinates (deg, deg, m above the ellipsoid)."""
    lat = np.radians(np.asarray(lat_deg, dtype=float))
    lon = np.radians(np.asarray(lon_deg, dtype=float))
    h = np.asarray(alt_m, dtype=float)
    s, c = np.sin(lat), np.cos(lat)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s * s)  # prime vertical radius of curvature
    x = (n + h) * c * np.cos(lon)
    y = (n + h) * c * np.sin(lon)
    z = (n * (1.0 - WGS84_E2) + h) * s
    return np.stack([x, y, z], axis=-1)


def ecef_to_geodetic(ecef_m: ArrayLike) -> NDArray[np.float64]:
    """(lat_deg, lon_deg, alt_m), shape (..., 3), of ECEF points (m); iterates to < 1e-12 rad.

    Valid away from the Earth's centre (any point within 100 km of the surface)."""
    p_ecef = np.asarray(ecef_m, dtype=float)
    x, y, z = p_ecef[..., 0], p_ecef[..., 1], p_ecef[..., 2]
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(20):
        s = np.sin(lat)
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s * s)
        h = _height(p, z, lat, n)
        new = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
        done = bool(np.all(np.abs(new - lat) < 1e-13))
        lat = new
        if done:
            break
    s = np.sin(lat)
    h = _height(p, z, lat, WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s * s))
    return np.stack([np.degrees(lat), np.degrees(lon), h], axis=-1)


def _height(p: NDArray[np.float64], z: NDArray[np.float64], lat: NDArray[np.float64], n: NDArray[np.float64]) -> NDArray[np.float64]:
    """Ellipsoidal height from whichever of p / cos(lat) and z / sin(lat) is well conditioned."""
    s, c = np.sin(lat), np.cos(lat)
    by_p = p / np.where(c == 0.0, 1.0, c) - n
    by_z = z / np.where(s == 0.0, 1.0, s) - n * (1.0 - WGS84_E2)
    return np.where(np.abs(c) > 0.1, by_p, by_z)


def ecef_to_enu_rotation(lat_deg: float, lon_deg: float) -> NDArray[np.float64]:
    """3x3 rotation taking ECEF vectors to the local (east, north, up) frame at (lat, lon)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array(
        [
            [-so, co, 0.0],
            [-sl * co, -sl * so, cl],
            [cl * co, cl * so, sl],
        ]
    )


def geodetic_to_enu(points: ArrayLike, origin: GeoPoint) -> NDArray[np.float64]:
    """Local ENU (m), shape (N, 3), of geodetic points (N, 3) [lat_deg, lon_deg, alt_amsl_m] at ``origin``."""
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    ecef = geodetic_to_ecef(pts[:, 0], pts[:, 1], pts[:, 2])
    ecef0 = geodetic_to_ecef(origin.lat_deg, origin.lon_deg, origin.alt_amsl_m)
    r = ecef_to_enu_rotation(origin.lat_deg, origin.lon_deg)
    return (ecef - ecef0) @ r.T


def enu_to_geodetic(points_enu_m: ArrayLike, origin: GeoPoint) -> NDArray[np.float64]:
    """Inverse of :func:`geodetic_to_enu`: (N, 3) [lat_deg, lon_deg, alt_amsl_m] of ENU points (m)."""
    enu = np.atleast_2d(np.asarray(points_enu_m, dtype=float))
    ecef0 = geodetic_to_ecef(origin.lat_deg, origin.lon_deg, origin.alt_amsl_m)
    r = ecef_to_enu_rotation(origin.lat_deg, origin.lon_deg)
    return ecef_to_geodetic(ecef0 + enu @ r)
