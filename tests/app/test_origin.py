"""The vehicle's origin from GPS_GLOBAL_ORIGIN / HOME_POSITION (pure part of pf_offboard.app.origin)."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.app.origin import origin_from_messages
from pf_offboard.geo import GeoPoint, enu_to_geodetic, geodetic_to_enu

ORIGIN = GeoPoint(-35.363261, 149.165230, 584.0)


def _home(lat_deg: float, lon_deg: float, alt_m: float, x: float, y: float, z: float):
    return mavlink2.MAVLink_home_position_message(round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_m * 1000), x, y, z,
                                                 [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0)  # fmt: skip


def test_gps_global_origin_wins_and_home_gives_the_altitude() -> None:
    origin = mavlink2.MAVLink_gps_global_origin_message(-353632610, 1491652300, 584000, 0)
    found = origin_from_messages(origin, _home(-35.36326, 149.16524, 585.5, 0.1, 0.9, -1.5))
    assert found is not None and found.source == "GPS_GLOBAL_ORIGIN"
    assert (found.origin.lat_deg, found.origin.lon_deg, found.origin.alt_amsl_m) == pytest.approx((-35.363261, 149.16523, 584.0), abs=1e-9)
    assert found.home_alt_amsl_m == pytest.approx(585.5)


def test_origin_from_home_and_its_local_position() -> None:
    """Home 3 m north, 4 m east and 1.5 m above the EKF origin (NED x, y, z = 3, 4, -1.5)."""
    home_lla = enu_to_geodetic([[4.0, 3.0, 1.5]], ORIGIN)[0]
    found = origin_from_messages(None, _home(*home_lla, 3.0, 4.0, -1.5))
    assert found is not None and found.source == "HOME_POSITION"
    back = geodetic_to_enu([[found.origin.lat_deg, found.origin.lon_deg, found.origin.alt_amsl_m]], ORIGIN)[0]
    assert np.max(np.abs(back)) < 0.02  # within the 1e-7 deg (1 cm) / 1 mm resolution of the message


def test_nothing_heard_is_none() -> None:
    assert origin_from_messages(None, None) is None
