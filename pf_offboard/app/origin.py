"""The vehicle's EKF origin, read at connect time, so a path planned in latitude / longitude can be
flown in the local frame the vehicle reports its position in.

The local frame of LOCAL_POSITION_NED has its (0, 0, 0) at the EKF origin, which the autopilot
sends as GPS_GLOBAL_ORIGIN (PX4 streams it at 0.1 Hz; ArduPilot on request). HOME_POSITION gives
the home position (its altitude is what ``altitude_reference: relative_home`` is relative to) and,
in its x / y / z fields, where home lies in the local frame, so the origin follows from it when
GPS_GLOBAL_ORIGIN does not come. Whatever is not streamed is asked for with
MAV_CMD_REQUEST_MESSAGE, every 0.5 s, until ``timeout_s``.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from typing import Any, TextIO

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard import frames
from pf_offboard.errors import LinkError
from pf_offboard.geo import GeoPoint, enu_to_geodetic, geodetic_to_enu

ORIGIN_TIMEOUT_S = 10.0
HOME_GRACE_S = 1.0  # after GPS_GLOBAL_ORIGIN, wait this long for HOME_POSITION (its altitude)
ORIGIN_MISMATCH_WARN_M = 1.0


@dataclass(frozen=True)
class VehicleOrigin:
    """Where the vehicle's local frame is: ``origin`` (WGS-84, AMSL) and the home altitude (m AMSL)."""

    origin: GeoPoint
    home_alt_amsl_m: float | None
    source: str  # "GPS_GLOBAL_ORIGIN" | "HOME_POSITION"


def origin_from_messages(origin_msg: Any | None, home_msg: Any | None) -> VehicleOrigin | None:
    """From a GPS_GLOBAL_ORIGIN and / or HOME_POSITION (either may be None). Pure."""
    home_alt = home_msg.altitude / 1000.0 if home_msg is not None else None
    if origin_msg is not None:
        origin = GeoPoint(origin_msg.latitude * 1e-7, origin_msg.longitude * 1e-7, origin_msg.altitude / 1000.0)
        return VehicleOrigin(origin, home_alt, "GPS_GLOBAL_ORIGIN")
    if home_msg is not None:
        home = GeoPoint(home_msg.latitude * 1e-7, home_msg.longitude * 1e-7, home_alt)  # type: ignore[arg-type]
        local_ned = np.array([home_msg.x, home_msg.y, home_msg.z], dtype=float)
        if not np.all(np.isfinite(local_ned)):
            local_ned = np.zeros(3)
        # the origin is where home's local position points back to
        lat, lon, alt = enu_to_geodetic(-frames.ned_to_enu(local_ned), home)[0]
        return VehicleOrigin(GeoPoint(float(lat), float(lon), float(alt)), home_alt, "HOME_POSITION")
    return None


async def read_origin(link: Any, timeout_s: float = ORIGIN_TIMEOUT_S) -> VehicleOrigin:
    """Listen for GPS_GLOBAL_ORIGIN and HOME_POSITION from the target, asking for them with
    MAV_CMD_REQUEST_MESSAGE. Raises :class:`LinkError` when neither comes within ``timeout_s``."""
    loop = asyncio.get_running_loop()
    target = link.target
    got: dict[str, Any] = {}
    changed = asyncio.Event()

    def handler(msg: Any) -> None:
        kind = msg.get_type()
        if kind in ("GPS_GLOBAL_ORIGIN", "HOME_POSITION"):
            got[kind] = msg
            changed.set()

    link.start_reading(handler)
    start = loop.time()
    origin_at: float | None = None
    try:
        while True:
            now = loop.time()
            if "GPS_GLOBAL_ORIGIN" in got and origin_at is None:
                origin_at = now
            if "GPS_GLOBAL_ORIGIN" in got and ("HOME_POSITION" in got or now - (origin_at or now) >= HOME_GRACE_S):
                break
            if "HOME_POSITION" in got and "GPS_GLOBAL_ORIGIN" not in got and now - start >= timeout_s / 2:
                break  # no origin message: derive it from home's local position
            if now - start >= timeout_s:
                break
            for kind, msg_id in (("GPS_GLOBAL_ORIGIN", mavlink2.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN), ("HOME_POSITION", mavlink2.MAVLINK_MSG_ID_HOME_POSITION)):
                if kind not in got:
                    link.send(mavlink2.MAVLink_command_long_message(
                        target.system, target.component, mavlink2.MAV_CMD_REQUEST_MESSAGE, 0, float(msg_id), 0, 0, 0, 0, 0, 0))  # fmt: skip
            changed.clear()
            try:
                await asyncio.wait_for(changed.wait(), 0.5)
            except TimeoutError:
                pass
            if link.error is not None:
                raise link.error
    finally:
        link.stop_reading()
    found = origin_from_messages(got.get("GPS_GLOBAL_ORIGIN"), got.get("HOME_POSITION"))
    if found is None:
        raise LinkError(f"no GPS_GLOBAL_ORIGIN or HOME_POSITION from the vehicle within {timeout_s:g} s: the path is in "
                        "latitude/longitude and the vehicle's local origin is unknown (GPS fix? EKF origin set?)")  # fmt: skip
    return found


async def localise_config(link: Any, config: Any, stream: TextIO, timeout_s: float = ORIGIN_TIMEOUT_S) -> Any:
    """``config`` with its geodetic path (``path.file``) in the vehicle's local frame; prints what
    was used. The vehicle's origin wins over a ``path.origin`` in the config (warned when they
    differ by more than 1 m). Way-points too far from the origin are refused (InputError, exit 2)
    before any setpoint or command goes out."""
    from pf_offboard.config import with_origin

    geodetic = config.path.geodetic
    found = await read_origin(link, timeout_s)
    o = found.origin
    if geodetic.origin is not None:
        d = float(np.linalg.norm(geodetic_to_enu([[o.lat_deg, o.lon_deg, o.alt_amsl_m]], geodetic.origin)[0]))
        if d > ORIGIN_MISMATCH_WARN_M:
            print(f"pf-offboard fly: warning: path.origin is {d:.1f} m from the vehicle's origin ({found.source}); "
                  "flying in the vehicle's frame", file=stream)  # fmt: skip
    local = with_origin(config, o, found.home_alt_amsl_m)
    home = f", home at {found.home_alt_amsl_m:.2f} m AMSL" if found.home_alt_amsl_m is not None else ""
    skipped = f"; skipped {', '.join(geodetic.skipped)}" if geodetic.skipped else ""
    extent = np.max(np.linalg.norm(np.array(local.path.waypoints_enu_m), axis=1))
    print(f"pf-offboard fly: path {geodetic.file}: {len(geodetic.names)} way-points ({geodetic.altitude_reference}{skipped}) "
          f"in the local frame of {found.source} lat {o.lat_deg:.7f} lon {o.lon_deg:.7f} alt {o.alt_amsl_m:.2f} m AMSL{home}; "
          f"farthest {extent:.1f} m from the origin", file=stream)  # fmt: skip
    if not math.isfinite(extent):
        raise LinkError("the vehicle's origin gave non-finite local way-points")
    return local
