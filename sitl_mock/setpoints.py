"""Decoding of SET_POSITION_TARGET_LOCAL_NED / SET_ATTITUDE_TARGET the way each autopilot does.

Pure functions: message + current estimate in, a target (or a :class:`Rejected` with the
reason) out. What the real autopilots accept (PX4 ``mavlink_receiver.cpp``, ArduPilot
``GCS_Mavlink.cpp`` of Copter) is summarised in ``docs/sitl-mock.md``. Anything non-finite in a
field that would be used is rejected here, so no NaN ever reaches the dynamics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.rotations import rotate_yaw

_NAN3 = (math.nan, math.nan, math.nan)

POS_IGNORE = (
    mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE
)
VEL_IGNORE = (
    mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE
)
ACC_IGNORE = (
    mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE
)
FORCE_SET = mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET
YAW_IGNORE = mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
YAW_RATE_IGNORE = mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE

ATT_ROLL_RATE_IGNORE = mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
ATT_PITCH_RATE_IGNORE = mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
ATT_YAW_RATE_IGNORE = mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
ATT_THROTTLE_IGNORE = mavlink.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE
ATT_ATTITUDE_IGNORE = mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE


@dataclass(frozen=True)
class Rejected:
    """The autopilot ignores this message; ``reason`` says why (shown in the mock's log)."""

    reason: str


@dataclass(frozen=True)
class TrajectoryTarget:
    """A decoded SET_POSITION_TARGET_LOCAL_NED in the local NED frame; NaN = not given.

    ``kind`` (ArduPilot's guided sub-mode): ``pos``, ``velaccel``, ``accel``, ``posvelaccel``;
    for PX4 it is ``accel`` when only acceleration is given, else ``pvt`` (per-axis NaN).
    """

    kind: str
    position_ned_m: tuple[float, float, float]
    velocity_ned_m_s: tuple[float, float, float]
    accel_ned_m_s2: tuple[float, float, float]
    yaw_rad: float  # NaN: not given
    yaw_rate_rad_s: float  # NaN: not given


@dataclass(frozen=True)
class AttitudeTarget:
    """A decoded SET_ATTITUDE_TARGET.

    ``q_ned_frd`` None = attitude ignored (pure body-rate control); ``rates_frd_rad_s`` None =
    none given; ``thrust`` is 0..1 normalised thrust (PX4; ArduPilot with GUID_OPTIONS bit 3) or
    a climb rate in m/s, positive up (ArduPilot default), as ``thrust_is_climb_rate`` says.
    For PX4 with a quaternion only ``rates_frd_rad_s[2]`` (yaw-rate feed-forward) is non-zero.
    """

    q_ned_frd: tuple[float, float, float, float] | None
    rates_frd_rad_s: tuple[float, float, float] | None
    thrust: float
    thrust_is_climb_rate: bool = False


@dataclass(frozen=True)
class BrakeAndHover:
    """ArduPilot's reaction to a malformed SET_ATTITUDE_TARGET: ``mode_guided.init(true)``."""

    reason: str


def _axes(values: tuple[float, float, float], mask: int, bits: tuple[int, int, int]) -> tuple[float, float, float]:
    return tuple(math.nan if mask & bit else float(v) for v, bit in zip(values, bits))  # type: ignore[return-value]


_POS_BITS = (
    mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE,
)
_VEL_BITS = (
    mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE,
)
_ACC_BITS = (
    mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE,
    mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE,
)


def _finite_or_nan(values: tuple[float, ...]) -> bool:
    """True if every value is finite or NaN (NaN = ignored); infinities are bad input."""
    return not any(map(math.isinf, values))


def px4_position_target(msg, position_ned_m: np.ndarray, yaw_rad: float) -> TrajectoryTarget | Rejected:
    """PX4: LOCAL_NED and BODY_NED only, FORCE_SET rejected, ignored (and NaN) fields = NaN."""
    mask = int(msg.type_mask)
    if mask & FORCE_SET:
        return Rejected("FORCE_SET type_mask bit is not supported")
    frame = int(msg.coordinate_frame)
    if frame not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED):
        return Rejected(f"coordinate_frame {frame} not supported (LOCAL_NED, BODY_NED only)")
    pos = _NAN3 if mask & POS_IGNORE == POS_IGNORE else _axes((msg.x, msg.y, msg.z), mask, _POS_BITS)
    vel = _NAN3 if mask & VEL_IGNORE == VEL_IGNORE else _axes((msg.vx, msg.vy, msg.vz), mask, _VEL_BITS)
    acc = _axes((msg.afx, msg.afy, msg.afz), mask, _ACC_BITS)
    yaw = math.nan if mask & YAW_IGNORE else float(msg.yaw)
    yaw_rate = math.nan if mask & YAW_RATE_IGNORE else float(msg.yaw_rate)
    if not _finite_or_nan(pos + vel + acc + (yaw, yaw_rate)):
        return Rejected("infinite value in a setpoint field")
    if frame == mavlink.MAV_FRAME_BODY_NED:
        pos = tuple(rotate_yaw(yaw_rad, np.array(pos)) + position_ned_m)  # type: ignore[assignment]
        vel = tuple(rotate_yaw(yaw_rad, np.array(vel)))  # type: ignore[assignment]
        acc = tuple(rotate_yaw(yaw_rad, np.array(acc)))  # type: ignore[assignment]
    has_pos = any(math.isfinite(v) for v in pos)
    has_vel = any(math.isfinite(v) for v in vel)
    has_acc = all(math.isfinite(v) for v in acc)
    if not (has_pos or has_vel or has_acc):
        return Rejected("no position, velocity or complete acceleration given")
    kind = "accel" if (has_acc and not has_pos and not has_vel) else "pvt"
    return TrajectoryTarget(kind, pos, vel, acc, yaw, yaw_rate)


def ardupilot_position_target(
    msg, position_ned_m: np.ndarray, yaw_rad: float
) -> TrajectoryTarget | Rejected:
    """ArduCopter: four frames; position / velocity(+accel) / accel / pos+vel(+accel) only."""
    mask = int(msg.type_mask)
    frame = int(msg.coordinate_frame)
    frames = (
        mavlink.MAV_FRAME_LOCAL_NED,
        mavlink.MAV_FRAME_LOCAL_OFFSET_NED,
        mavlink.MAV_FRAME_BODY_NED,
        mavlink.MAV_FRAME_BODY_OFFSET_NED,
    )
    if frame not in frames:
        return Rejected(f"coordinate_frame {frame} not supported")
    pos_ignore = bool(mask & POS_IGNORE)
    vel_ignore = bool(mask & VEL_IGNORE)
    acc_ignore = bool(mask & ACC_IGNORE)
    if not pos_ignore and vel_ignore and acc_ignore:
        kind = "pos"
    elif pos_ignore and not vel_ignore:
        kind = "velaccel"
    elif pos_ignore and vel_ignore and not acc_ignore:
        kind = "accel"
    elif not pos_ignore and not vel_ignore:
        kind = "posvelaccel"
    else:
        return Rejected("position + acceleration without velocity is not a supported combination")
    pos = _NAN3 if pos_ignore else (float(msg.x), float(msg.y), float(msg.z))
    vel = _NAN3 if vel_ignore else (float(msg.vx), float(msg.vy), float(msg.vz))
    acc = (0.0, 0.0, 0.0) if acc_ignore else (float(msg.afx), float(msg.afy), float(msg.afz))
    yaw = math.nan if mask & YAW_IGNORE else float(msg.yaw)
    yaw_rate = math.nan if mask & YAW_RATE_IGNORE else float(msg.yaw_rate)
    given = (() if pos_ignore else pos) + (() if vel_ignore else vel) + acc
    if not all(math.isfinite(v) for v in given):
        return Rejected("non-finite value in a used setpoint field")
    if not _finite_or_nan((yaw, yaw_rate)):
        return Rejected("infinite yaw / yaw_rate")
    if frame in (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED):
        pos = tuple(rotate_yaw(yaw_rad, np.array(pos)))  # type: ignore[assignment]
        vel = tuple(rotate_yaw(yaw_rad, np.array(vel)))  # type: ignore[assignment]
        acc = tuple(rotate_yaw(yaw_rad, np.array(acc)))  # type: ignore[assignment]
        if not math.isnan(yaw):
            yaw = yaw + yaw_rad  # body frames: yaw is relative
    if frame != mavlink.MAV_FRAME_LOCAL_NED and not pos_ignore:
        pos = tuple(np.array(pos) + position_ned_m)  # type: ignore[assignment]
    return TrajectoryTarget(kind, pos, vel, acc, yaw, yaw_rate)


def _quaternion(msg) -> tuple[float, float, float, float]:
    return tuple(float(v) for v in msg.q)  # type: ignore[return-value]


def px4_attitude_target(msg) -> AttitudeTarget | Rejected:
    """PX4: quaternion unless ATTITUDE_IGNORE (then roll+pitch rates required); with a
    quaternion only the yaw rate is used as feed-forward; THROTTLE_IGNORE gives thrust 0."""
    mask = int(msg.type_mask)
    thrust = 0.0 if mask & ATT_THROTTLE_IGNORE else float(msg.thrust)
    if not math.isfinite(thrust):
        return Rejected("thrust is not finite")
    thrust = min(max(thrust, 0.0), 1.0)
    yaw_rate = 0.0 if mask & ATT_YAW_RATE_IGNORE else float(msg.body_yaw_rate)
    if not math.isfinite(yaw_rate):
        return Rejected("body_yaw_rate is not finite")
    if not mask & ATT_ATTITUDE_IGNORE:
        q = np.array(_quaternion(msg))
        norm = float(np.linalg.norm(q)) if np.all(np.isfinite(q)) else math.nan
        if not (norm > 1e-3):
            return Rejected("quaternion is zero or not finite")
        # PX4's attitude controller normalises the setpoint quaternion.
        qn = tuple(float(v) for v in q / norm)
        return AttitudeTarget(qn, (0.0, 0.0, yaw_rate), thrust)  # type: ignore[arg-type]
    if mask & ATT_ROLL_RATE_IGNORE or mask & ATT_PITCH_RATE_IGNORE:
        return Rejected("attitude ignored and roll/pitch rates not both given")
    rates = (float(msg.body_roll_rate), float(msg.body_pitch_rate), yaw_rate)
    if not all(math.isfinite(v) for v in rates):
        return Rejected("body rates not finite")
    return AttitudeTarget(None, rates, thrust)


def ardupilot_attitude_target(
    msg, thrust_is_thrust: bool, speed_up_m_s: float, speed_down_m_s: float
) -> AttitudeTarget | Rejected | BrakeAndHover:
    """ArduCopter GUIDED SET_ATTITUDE_TARGET handling (GCS_MAVLink_Copter.cpp)."""
    mask = int(msg.type_mask)
    if mask & ATT_THROTTLE_IGNORE:
        return Rejected("thrust must not be ignored (THROTTLE_IGNORE set)")
    thrust = float(msg.thrust)
    if not math.isfinite(thrust):
        return Rejected("thrust is not finite")
    if thrust_is_thrust:
        value = min(max(thrust, -1.0), 1.0)
    else:
        thrust = min(max(thrust, 0.0), 1.0)
        if thrust == 0.5:
            value = 0.0
        elif thrust > 0.5:
            value = (thrust - 0.5) * 2.0 * speed_up_m_s
        else:
            value = -(0.5 - thrust) * 2.0 * speed_down_m_s
    rate_bits = (ATT_ROLL_RATE_IGNORE, ATT_PITCH_RATE_IGNORE, ATT_YAW_RATE_IGNORE)
    ignored = [bool(mask & b) for b in rate_bits]
    rates: tuple[float, float, float] | None
    if not any(ignored):
        rates = (float(msg.body_roll_rate), float(msg.body_pitch_rate), float(msg.body_yaw_rate))
        if not all(math.isfinite(v) for v in rates):
            return BrakeAndHover("body rates not finite")
    elif all(ignored):
        rates = None
    else:
        return BrakeAndHover("body rates must be all given or all ignored")
    q: tuple[float, float, float, float] | None = None
    if not mask & ATT_ATTITUDE_IGNORE:
        q = _quaternion(msg)
        qa = np.array(q)
        if not (np.all(np.isfinite(qa)) and abs(float(qa @ qa) - 1.0) < 1e-3):
            return BrakeAndHover("quaternion is not unit length")
    return AttitudeTarget(q, rates, value, thrust_is_climb_rate=not thrust_is_thrust)
