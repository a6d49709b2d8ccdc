"""Telemetry: message builders (simulated-time stamps) and per-link stream schedules."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.rotations import euler_from_q

if TYPE_CHECKING:
    from sitl_mock.autopilot import Autopilot

EARTH_RADIUS_M = 6378137.0
_SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink.MAV_SYS_STATUS_AHRS
    | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
)
_NAN21 = [math.nan] + [0.0] * 20


@dataclass
class Stream:
    """One periodic message on one link: interval in simulated seconds, next due time."""

    interval_s: float
    next_due_s: float


class StreamTable:
    """Per-link message intervals (SET_MESSAGE_INTERVAL applies to the link it came on)."""

    def __init__(self, defaults: tuple[tuple[int, float], ...], now_s: float) -> None:
        self._defaults = {msgid: 1.0 / hz for msgid, hz in defaults}
        self.streams: dict[int, Stream] = {
            msgid: Stream(interval, now_s) for msgid, interval in self._defaults.items()
        }

    def set_interval(self, msgid: int, interval_s: float | None, now_s: float) -> None:
        """``None`` restores the default; ``inf`` disables."""
        if interval_s is None:
            interval_s = self._defaults.get(msgid, math.inf)
        if math.isinf(interval_s):
            self.streams.pop(msgid, None)
        else:
            self.streams[msgid] = Stream(interval_s, now_s)

    def interval_s(self, msgid: int) -> float:
        stream = self.streams.get(msgid)
        return stream.interval_s if stream else math.inf

    def due(self, now_s: float) -> list[int]:
        """Message ids that fell due by ``now_s`` (each at most once per call)."""
        out = []
        for msgid, stream in self.streams.items():
            if now_s + 1e-9 >= stream.next_due_s:
                out.append(msgid)
                stream.next_due_s += stream.interval_s
                if stream.next_due_s < now_s:  # fell behind (rate above the step rate): resync
                    stream.next_due_s = now_s + stream.interval_s
        return out


def _time_boot_ms(ap: Autopilot) -> int:
    return int(ap.reported_time_s * 1000.0) & 0xFFFFFFFF


def _time_usec(ap: Autopilot) -> int:
    return int(ap.reported_time_s * 1e6)


def ned_to_global(ap: Autopilot, position_ned_m: np.ndarray) -> tuple[int, int, int]:
    """(lat 1e7 deg, lon 1e7 deg, alt mm AMSL) of a local NED position around home (flat earth)."""
    cfg = ap.config
    lat = cfg.home_lat_deg + math.degrees(position_ned_m[0] / EARTH_RADIUS_M)
    lon = cfg.home_lon_deg + math.degrees(
        position_ned_m[1] / (EARTH_RADIUS_M * math.cos(math.radians(cfg.home_lat_deg)))
    )
    alt = cfg.home_alt_m - position_ned_m[2]
    return int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000.0))


def heartbeat(ap: Autopilot) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_QUADROTOR,
        ap.profile.autopilot,
        ap.base_mode,
        ap.mode.custom_mode,
        ap.system_status,
        3,
    )


def sys_status(ap: Autopilot) -> mavlink.MAVLink_message:
    """Sensor bits; PREARM_CHECK healthy when arming would pass (MAVSDK's ``is_armable``)."""
    present = _SENSORS | mavlink.MAV_SYS_STATUS_PREARM_CHECK
    health = _SENSORS if ap.ekf_ready else _SENSORS & ~mavlink.MAV_SYS_STATUS_SENSOR_GPS
    if ap.arming_checks_pass():
        health |= mavlink.MAV_SYS_STATUS_PREARM_CHECK
    return mavlink.MAVLink_sys_status_message(present, present, health, 200, 16200, 500, 100, 0, 0, 0, 0, 0, 0)


def extended_sys_state(ap: Autopilot) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED, ap.landed_state)


def attitude(ap: Autopilot) -> mavlink.MAVLink_message:
    s = ap.truth
    roll, pitch, yaw = euler_from_q(s.q_ned_frd)
    p, q, r = (float(v) for v in s.rates_frd_rad_s)
    return mavlink.MAVLink_attitude_message(_time_boot_ms(ap), roll, pitch, yaw, p, q, r)


def attitude_quaternion(ap: Autopilot) -> mavlink.MAVLink_message:
    s = ap.truth
    w, x, y, z = (float(v) for v in s.q_ned_frd)
    p, q, r = (float(v) for v in s.rates_frd_rad_s)
    return mavlink.MAVLink_attitude_quaternion_message(_time_boot_ms(ap), w, x, y, z, p, q, r, [0.0] * 4)


def future_attitude_quaternion(ap: Autopilot, ahead_s: float) -> mavlink.MAVLink_message:
    """A bogus ATTITUDE_QUATERNION dated ``ahead_s`` in the future: rolled 90 deg, rolling at 3 rad/s
    (fault injection: a receiver that believed it would fly a vehicle on its side)."""
    stamp = int((ap.reported_time_s + ahead_s) * 1000.0) & 0xFFFFFFFF
    h = math.sqrt(0.5)
    msg = mavlink.MAVLink_attitude_quaternion_message(stamp, h, h, 0.0, 0.0, 3.0, 0.0, 0.0, [0.0] * 4)
    msg.fault_injected = True  # the reordering fault leaves it alone (counted on its own)
    return msg


def local_position_ned(ap: Autopilot) -> mavlink.MAVLink_message:
    x, y, z = (float(v) for v in ap.est_position_ned_m)
    vx, vy, vz = (float(v) for v in ap.est_velocity_ned_m_s)
    return mavlink.MAVLink_local_position_ned_message(_time_boot_ms(ap), x, y, z, vx, vy, vz)


def odometry(ap: Autopilot) -> mavlink.MAVLink_message:
    """Current PX4 style: EKF2 publishes NED position AND NED velocity (``VELOCITY_FRAME_NED``),
    so frame_id = child_frame_id = LOCAL_NED; rates are body FRD."""
    s = ap.truth
    x, y, z = (float(v) for v in ap.est_position_ned_m)
    vx, vy, vz = (float(v) for v in ap.est_velocity_ned_m_s)
    p, qr, r = (float(v) for v in s.rates_frd_rad_s)
    return mavlink.MAVLink_odometry_message(
        _time_usec(ap), mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED,
        x, y, z, [float(c) for c in s.q_ned_frd], vx, vy, vz,
        p, qr, r, _NAN21, _NAN21, ap.reset_counter & 0xFF, mavlink.MAV_ESTIMATOR_TYPE_AUTOPILOT, -1 if ap.estimate_lost else 100,
    )


def corrupt_state(ap: Autopilot, spec: tuple[float, ...]) -> list[mavlink.MAVLink_message]:
    """One corrupt state sample (fault injection) as LOCAL_POSITION_NED and ODOMETRY, dated 1 ms
    after now: the estimate moved by spec[0:3] with the velocity spec[3:6] (NED)."""
    x, y, z = (float(v) + float(d) for v, d in zip(ap.est_position_ned_m, spec[:3]))
    vx, vy, vz = (float(v) for v in spec[3:6])
    s = ap.truth
    lp = mavlink.MAVLink_local_position_ned_message((_time_boot_ms(ap) + 1) & 0xFFFFFFFF, x, y, z, vx, vy, vz)
    odo = mavlink.MAVLink_odometry_message(
        _time_usec(ap) + 1000, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED, x, y, z, [float(c) for c in s.q_ned_frd],
        vx, vy, vz, *(float(v) for v in s.rates_frd_rad_s), _NAN21, _NAN21, ap.reset_counter & 0xFF,
        mavlink.MAV_ESTIMATOR_TYPE_AUTOPILOT, 100,
    )  # fmt: skip
    for m in (lp, odo):
        m.fault_injected = True
    return [lp, odo]


def estimator_report(ap: Autopilot) -> mavlink.MAVLink_message:
    """The estimator's health as the autopilot reports it: PX4 ESTIMATOR_STATUS, ArduPilot
    EKF_STATUS_REPORT. Healthy: attitude, velocities, horizontal (relative and absolute) and
    vertical position; lost: attitude and vertical only, test ratios / variances above 1."""
    good = 1 | 2 | 4 | 8 | 16 | 32
    flags, ratio = (1 | 4 | 32, 2.5) if ap.estimate_lost else (good, 0.1)
    if ap.profile.name == "px4":
        return mavlink.MAVLink_estimator_status_message(int(ap.time_s * 1e6), flags, ratio, ratio, ratio, ratio, 0.0, 0.0, 0.1, 0.1)
    from pymavlink.dialects.v20 import ardupilotmega

    return ardupilotmega.MAVLink_ekf_status_report_message(flags, ratio, ratio, ratio, 0.1, 0.1)


def global_position_int(ap: Autopilot) -> mavlink.MAVLink_message:
    pos = ap.est_position_ned_m
    lat, lon, alt = ned_to_global(ap, pos)
    vx, vy, vz = (float(v) for v in ap.est_velocity_ned_m_s)
    _, _, yaw = euler_from_q(ap.truth.q_ned_frd)
    hdg = int(round(math.degrees(yaw) % 360.0 * 100.0)) % 36000
    return mavlink.MAVLink_global_position_int_message(
        _time_boot_ms(ap), lat, lon, alt, int(round(-pos[2] * 1000.0)),
        int(round(vx * 100)), int(round(vy * 100)), int(round(vz * 100)), hdg,
    )


def home_position(ap: Autopilot) -> mavlink.MAVLink_message:
    lat, lon, alt = ned_to_global(ap, np.zeros(3))
    return mavlink.MAVLink_home_position_message(
        lat, lon, alt, 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, _time_usec(ap)
    )


def gps_global_origin(ap: Autopilot) -> mavlink.MAVLink_message:
    """The EKF origin (the local frame's (0, 0, 0)): the mock's home, lat/lon 1e7 deg, alt mm AMSL."""
    lat, lon, alt = ned_to_global(ap, np.zeros(3))
    return mavlink.MAVLink_gps_global_origin_message(lat, lon, alt, _time_usec(ap))


def highres_imu(ap: Autopilot) -> mavlink.MAVLink_message:
    s = ap.truth
    f = s.specific_force_frd_m_s2
    p, q, r = (float(v) for v in s.rates_frd_rad_s)
    alt = ap.config.home_alt_m - float(ap.est_position_ned_m[2])
    return mavlink.MAVLink_highres_imu_message(
        _time_usec(ap), float(f[0]), float(f[1]), float(f[2]), p, q, r, 0.2, 0.0, 0.4,
        1013.25 - alt * 0.12, 0.0, alt, 25.0, 0x1FFF,
    )


def altitude(ap: Autopilot) -> mavlink.MAVLink_message:
    rel = -float(ap.est_position_ned_m[2])
    amsl = ap.config.home_alt_m + rel
    return mavlink.MAVLink_altitude_message(_time_usec(ap), amsl, amsl, rel, rel, math.nan, math.nan)


def vfr_hud(ap: Autopilot) -> mavlink.MAVLink_message:
    v = ap.est_velocity_ned_m_s
    _, _, yaw = euler_from_q(ap.truth.q_ned_frd)
    ground = math.hypot(float(v[0]), float(v[1]))
    return mavlink.MAVLink_vfr_hud_message(
        ground, ground, int(math.degrees(yaw) % 360.0), int(100 * ap.truth.thrust_norm_actual),
        ap.config.home_alt_m - float(ap.est_position_ned_m[2]), -float(v[2]),
    )


def attitude_target(ap: Autopilot) -> mavlink.MAVLink_message:
    s = ap.truth
    w, x, y, z = (float(c) for c in s.q_sp_ned_frd)
    p, q, r = (float(c) for c in s.rates_sp_frd_rad_s)
    return mavlink.MAVLink_attitude_target_message(
        _time_boot_ms(ap), 0, [w, x, y, z], p, q, r, float(s.thrust_norm_sp)
    )


def position_target_local_ned(ap: Autopilot) -> mavlink.MAVLink_message | None:
    """The autopilot's echo of the setpoint it flies (None: not sent). PX4 streams its position
    controller's setpoint, so nothing while an attitude / rate target is flown; ArduCopter sends it
    only in GUIDED and not in its angle sub-mode (GCS_MAVLink_Copter.cpp)."""
    t = ap.position_target_echo if ap.echo_unsent is None else ap.echo_unsent
    ap.echo_unsent = None
    offboard = ap.mode.behaviour.name == "OFFBOARD"
    if ap.profile.name == "ardupilot" and (t is None or not offboard):
        return None
    if t is None:
        if offboard:
            return None  # PX4 flying an attitude / rate target
        mask, values = 0xFFF, [0.0] * 11  # PX4 outside OFFBOARD: its own modes' setpoint (not modelled)
    else:
        mask, values = t
    return mavlink.MAVLink_position_target_local_ned_message(
        _time_boot_ms(ap), mavlink.MAV_FRAME_LOCAL_NED, mask, *values
    )


def autopilot_version(ap: Autopilot) -> mavlink.MAVLink_message:
    version = (1 << 24) | (15 << 16) | (0 << 8) | 255 if ap.profile.name == "px4" else (4 << 24) | (6 << 16) | 255
    return mavlink.MAVLink_autopilot_version_message(
        ap.profile.capabilities, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0x26AC, 0x11, 1
    )


BUILDERS: Mapping[int, Callable[..., object]] = MappingProxyType({
    mavlink.MAVLINK_MSG_ID_HEARTBEAT: heartbeat,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: sys_status,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: extended_sys_state,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: attitude,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: attitude_quaternion,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: local_position_ned,
    mavlink.MAVLINK_MSG_ID_ODOMETRY: odometry,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: global_position_int,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: home_position,
    mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: gps_global_origin,
    mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: highres_imu,
    mavlink.MAVLINK_MSG_ID_ALTITUDE: altitude,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: vfr_hud,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_TARGET: attitude_target,
    mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: position_target_local_ned,
    mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: autopilot_version,
})
# Messages that need a position estimate (ArduPilot sends them only once the EKF has one).
NEEDS_POSITION = frozenset(
    {
        mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
        mavlink.MAVLINK_MSG_ID_ODOMETRY,
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
        mavlink.MAVLINK_MSG_ID_HOME_POSITION,
        mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,  # no origin before the EKF has a position
    }
)
