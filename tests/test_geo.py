"""WGS-84 geodesy against published reference points and exact identities."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pf_offboard.errors import InputError
from pf_offboard.geo import (
    WGS84_A_M,
    WGS84_B_M,
    GeoPoint,
    ecef_to_geodetic,
    enu_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_enu,
)

# Published geodetic -> ECEF pairs: (lat_deg, lon_deg, h_m) -> (x, y, z) m, with the reference's
# precision as tolerance.
REFERENCE_ECEF = [
    # pymap3d's test vector (tests/test_geodetic.py: lla0 -> xyz0), micrometre precision
    ((42.0, -82.0, 200.0), (660675.2518247, -4700948.68316, 4245737.66222), 1e-5),
    # GSI / QZSS documentation example (llh2ecef), lat/lon given to 1e-7 deg (~1 cm)
    ((34.4401061, 132.4147804, 233.362), (-3551876.829, 3887786.860, 3586946.387), 0.01),
    # exact: equator / prime meridian, equator at 90 E, north pole (semi-minor axis)
    ((0.0, 0.0, 0.0), (WGS84_A_M, 0.0, 0.0), 1e-9),
    ((0.0, 90.0, 0.0), (0.0, WGS84_A_M, 0.0), 1e-9),
    ((90.0, 0.0, 0.0), (0.0, 0.0, 6356752.314245), 1e-6),
    ((-90.0, 0.0, 100.0), (0.0, 0.0, -6356752.314245 - 100.0), 1e-6),
]


@pytest.mark.parametrize(("lla", "xyz", "tol"), REFERENCE_ECEF)
def test_geodetic_to_ecef_matches_reference(lla, xyz, tol) -> None:
    got = geodetic_to_ecef(*lla)
    assert np.max(np.abs(got - np.array(xyz))) <= tol
    assert np.allclose(ecef_to_geodetic(got), lla, atol=1e-9)  # and back


def test_semi_minor_axis() -> None:
    assert WGS84_B_M == pytest.approx(6356752.314245, abs=1e-6)


def test_enu_matches_pymap3d_aer_reference() -> None:
    """pymap3d's reference: from lla0 = (42, -82, 200), azimuth 33 deg, elevation 70 deg, range
    1000 m is lla1 = (42.002582, -81.997752, 1139.7018) (lat/lon given to 1e-6 deg ~ 0.1 m)."""
    enu = geodetic_to_enu([[42.002582, -81.997752, 1139.7018]], GeoPoint(42.0, -82.0, 200.0))[0]
    az, el = math.radians(33.0), math.radians(70.0)
    expected = 1000.0 * np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])
    assert np.max(np.abs(enu - expected)) < 0.15


def test_enu_axes_point_east_north_up() -> None:
    origin = GeoPoint(47.397742, 8.545594, 488.0)
    one_arcsec = 1.0 / 3600.0
    north = geodetic_to_enu([[origin.lat_deg + one_arcsec, origin.lon_deg, origin.alt_amsl_m]], origin)[0]
    east = geodetic_to_enu([[origin.lat_deg, origin.lon_deg + one_arcsec, origin.alt_amsl_m]], origin)[0]
    up = geodetic_to_enu([[origin.lat_deg, origin.lon_deg, origin.alt_amsl_m + 10.0]], origin)[0]
    # one arc-second of latitude at 47.4 deg: M * pi / 648000 with the meridian radius M
    s2 = math.sin(math.radians(origin.lat_deg)) ** 2
    e2 = 1.0 - (WGS84_B_M / WGS84_A_M) ** 2
    m = WGS84_A_M * (1 - e2) / (1 - e2 * s2) ** 1.5 + origin.alt_amsl_m
    n = WGS84_A_M / math.sqrt(1 - e2 * s2) + origin.alt_amsl_m
    d_north = m * math.radians(one_arcsec)
    d_east = n * math.cos(math.radians(origin.lat_deg)) * math.radians(one_arcsec)
    # up: the tangent plane rises above the ellipsoid by d^2 / (2 R) (7.5e-5 m at 31 m)
    assert north == pytest.approx([0.0, d_north, -(d_north**2) / (2 * m)], abs=2e-6)
    # east along a parallel: the parallel also bends north, by d^2 tan(lat) / (2 N)
    bend = d_east**2 * math.tan(math.radians(origin.lat_deg)) / (2 * n)
    assert east == pytest.approx([d_east, bend, -(d_east**2) / (2 * n)], abs=2e-6)
    assert up == pytest.approx([0.0, 0.0, 10.0], abs=1e-9)


def test_curvature_drop_at_one_km() -> None:
    """A point 1 km north at the origin's altitude lies d^2 / (2 R) ~ 7.8 cm below the tangent plane."""
    origin = GeoPoint(0.0, 0.0, 0.0)
    p = enu_to_geodetic([[0.0, 1000.0, 0.0]], origin)[0]
    q = geodetic_to_enu([[p[0], p[1], 0.0]], origin)[0]
    assert -q[2] == pytest.approx(1000.0**2 / (2 * 6335439.0), rel=0.01)  # meridian radius at the equator


def test_round_trip_around_several_origins() -> None:
    rng = np.random.default_rng(3)
    for lat, lon in ((47.4, 8.5), (-35.36, 149.17), (0.0, 179.999), (78.0, -60.0)):
        origin = GeoPoint(lat, lon, 500.0)
        enu = rng.uniform(-1000, 1000, size=(50, 3))
        back = geodetic_to_enu(enu_to_geodetic(enu, origin), origin)
        assert np.max(np.abs(back - enu)) < 1e-6


@pytest.mark.parametrize(("lat", "lon", "alt"), [(91.0, 0.0, 0.0), (0.0, 180.5, 0.0), (math.nan, 0.0, 0.0), (0.0, 0.0, 2e5)])
def test_bad_origin_is_named(lat, lon, alt) -> None:
    with pytest.raises(InputError, match="origin"):
        GeoPoint(lat, lon, alt)
