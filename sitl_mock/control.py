"""Autopilot-side outer loops the mock runs above the dynamics' inner loops.

- :func:`px4_trajectory_accel`: PX4 ``PositionControl`` for OFFBOARD position/velocity setpoints
  (per-axis NaN = not controlled), acceleration feed-forward added.
- :class:`ArduGuided`: ArduCopter GUIDED sub-modes (position, velocity, acceleration with jerk
  limit and integration into a velocity/position target, attitude with climb rate or thrust),
  with GUID_TIMEOUT and GUID_OPTIONS semantics.
- :func:`thrust_for_climb`: vertical-speed loop → normalised thrust for attitude modes.

All in the *estimated* local NED frame; the caller converts position targets for the dynamics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sitl_mock.dynamics import (
    AccelerationSetpoint,
    AttitudeSetpoint,
    MotorsOff,
    RateSetpoint,
    Setpoint,
    quat_mul,
)
from sitl_mock.rotations import euler_from_q, q_from_euler
from sitl_mock.setpoints import AttitudeTarget, TrajectoryTarget

GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class Gains:
    """Cascaded P gains: position → velocity (1/s), velocity → acceleration (1/s)."""

    pos_xy: float
    pos_z: float
    vel_xy: float
    vel_z: float
    vel_max_xy_m_s: float
    vel_max_up_m_s: float
    vel_max_down_m_s: float


PX4_GAINS = Gains(0.95, 1.0, 1.8, 4.0, 12.0, 3.0, 1.5)  # MPC_XY_P, MPC_Z_P, MPC_*_VEL_P_ACC
ARDUPILOT_GAINS = Gains(1.0, 1.0, 2.0, 5.0, 10.0, 2.5, 1.5)  # PSC_POSXY_P, PSC_POSZ_P, PSC_VEL*_P


def _limit_velocity(v: np.ndarray, g: Gains) -> np.ndarray:
    out = v.copy()
    speed_xy = math.hypot(out[0], out[1])
    if speed_xy > g.vel_max_xy_m_s:
        out[:2] *= g.vel_max_xy_m_s / speed_xy
    out[2] = min(max(out[2], -g.vel_max_up_m_s), g.vel_max_down_m_s)
    return out


def px4_trajectory_accel(target: TrajectoryTarget, position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """PX4 position/velocity control per axis: NaN position → velocity only; both NaN → the
    acceleration feed-forward alone (0 if that is NaN too). Returns NED acceleration m/s²."""
    pos = np.array(target.position_ned_m)
    vel = np.array(target.velocity_ned_m_s)
    acc = np.array(target.accel_ned_m_s2)
    kp = np.array([PX4_GAINS.pos_xy, PX4_GAINS.pos_xy, PX4_GAINS.pos_z])
    kv = np.array([PX4_GAINS.vel_xy, PX4_GAINS.vel_xy, PX4_GAINS.vel_z])
    has_pos = np.isfinite(pos)
    has_vel = np.isfinite(vel)
    vel_sp = np.where(has_vel, vel, 0.0) + np.where(has_pos, kp * (np.where(has_pos, pos, 0.0) - position), 0.0)
    if has_pos.any():
        vel_sp = _limit_velocity(vel_sp, PX4_GAINS)
    controlled = has_pos | has_vel
    out = np.where(controlled, kv * (vel_sp - velocity), 0.0) + np.where(np.isfinite(acc), acc, 0.0)
    return out


def thrust_for_climb(
    climb_rate_up_m_s: float, velocity_down_m_s: float, q: np.ndarray, hover_thrust: float, gain: float
) -> float:
    """Normalised thrust that drives the vertical speed to ``climb_rate_up_m_s`` (tilt-compensated)."""
    accel_down = gain * (-climb_rate_up_m_s - velocity_down_m_s)
    roll, pitch, _ = euler_from_q(q)
    cos_tilt = max(math.cos(roll) * math.cos(pitch), 0.5)
    thrust = hover_thrust * (GRAVITY_M_S2 - accel_down) / GRAVITY_M_S2 / cos_tilt
    return min(max(thrust, 0.0), 1.0)


def level_attitude(yaw_rad: float) -> tuple[float, float, float, float]:
    return tuple(float(v) for v in q_from_euler(0.0, 0.0, yaw_rad))  # type: ignore[return-value]


def _shape(current: np.ndarray, target: np.ndarray, max_step: float) -> np.ndarray:
    """Move ``current`` toward ``target`` by at most ``max_step`` (vector norm)."""
    delta = target - current
    norm = float(np.linalg.norm(delta))
    if norm <= max_step or norm == 0.0:
        return target.copy()
    return current + delta * (max_step / norm)


class ArduGuided:
    """ArduCopter GUIDED: the target state and the controller that flies it.

    Sub-modes: ``hold`` (stopping point, also after a position target is reached or on a
    velocity/accel timeout), ``pos``, ``velaccel``, ``accel``, ``posvelaccel``, ``angle``,
    ``takeoff``. ``hold_position`` is None until set (the caller flies it with the dynamics'
    own position controller).
    """

    def __init__(self) -> None:
        self.submode = "hold"
        self.pos_t = np.zeros(3)
        self.vel_t = np.zeros(3)
        self.acc_des = np.zeros(3)
        self.cmd: TrajectoryTarget | None = None
        self.angle: AttitudeTarget | None = None
        self.q_t = np.array([1.0, 0.0, 0.0, 0.0])
        self.yaw_t: float | None = None
        self.yaw_rate = 0.0
        self.update_time_s = -math.inf
        self.hold_position = np.zeros(3)
        self.takeoff_alt_down_m = 0.0

    # --- inputs -------------------------------------------------------------------------------
    def hold(self, position: np.ndarray, velocity: np.ndarray, yaw: float) -> None:
        """Brake to the stopping point and hold it (``init(true)`` in ArduPilot)."""
        speed = float(np.linalg.norm(velocity))
        self.hold_position = position + velocity * speed / (2.0 * 2.5)  # 2.5 m/s² braking
        self.submode = "hold"
        self.yaw_t = yaw

    def takeoff(self, position: np.ndarray, altitude_m: float, yaw: float) -> None:
        self.hold_position = np.array([position[0], position[1], -altitude_m])
        self.submode = "takeoff"
        self.yaw_t = yaw

    def set_trajectory(self, target: TrajectoryTarget, now_s: float, position: np.ndarray, velocity: np.ndarray) -> None:
        if target.kind != self.submode or self.submode in ("hold", "takeoff", "angle"):
            # Entering a sub-mode starts its targets from the current state.
            self.pos_t = position.copy()
            self.vel_t = velocity.copy()
            self.acc_des = np.zeros(3)
        self.submode = target.kind
        self.cmd = target
        self.update_time_s = now_s
        if math.isfinite(target.yaw_rad):
            self.yaw_t = target.yaw_rad
            self.yaw_rate = target.yaw_rate_rad_s if math.isfinite(target.yaw_rate_rad_s) else 0.0
        elif math.isfinite(target.yaw_rate_rad_s):
            self.yaw_rate = target.yaw_rate_rad_s
        else:
            self.yaw_t = None  # face the direction of travel (WP_YAW_BEHAVIOR)
            self.yaw_rate = 0.0

    def set_angle(self, target: AttitudeTarget, now_s: float) -> None:
        self.submode = "angle"
        self.angle = target
        self.update_time_s = now_s
        if target.q_ned_frd is not None:
            self.q_t = np.array(target.q_ned_frd)

    # --- controller ---------------------------------------------------------------------------
    def update(
        self,
        dt_s: float,
        now_s: float,
        timeout_s: float,
        options: int,
        jerk_xy: float,
        jerk_z: float,
        hover_thrust: float,
        position: np.ndarray,
        velocity: np.ndarray,
        q: np.ndarray,
        landed: bool,
    ) -> Setpoint | None:
        """One controller step. Returns the dynamics setpoint, or None for "fly ``hold_position``"
        (the caller builds a PositionSetpoint in the true frame)."""
        timed_out = now_s - self.update_time_s > timeout_s
        _, _, yaw_now = euler_from_q(q)
        if self.submode in ("velaccel", "accel", "posvelaccel") and timed_out:
            # GUID_TIMEOUT: velocity/acceleration control stops → brake to a hover.
            self.hold(position, velocity, yaw_now)
        if self.submode in ("hold", "takeoff"):
            return None
        if self.submode == "angle":
            return self._angle(dt_s, timed_out, options, hover_thrust, velocity, q, yaw_now, landed)
        if landed:
            return MotorsOff()  # is_disarmed_or_landed(): guided pos/vel/accel wait for a takeoff
        assert self.cmd is not None
        g = ARDUPILOT_GAINS
        cmd = self.cmd
        if self.submode == "pos":
            target = np.array(cmd.position_ned_m)
            vel_sp = _limit_velocity(np.array([g.pos_xy, g.pos_xy, g.pos_z]) * (target - position), g)
            accel = np.array([g.vel_xy, g.vel_xy, g.vel_z]) * (vel_sp - velocity)
            if float(np.linalg.norm(target - position)) < 0.1:
                self.hold_position = target
        else:
            acc_cmd = np.array(cmd.accel_ned_m_s2)
            self.acc_des[:2] = _shape(self.acc_des[:2], acc_cmd[:2], jerk_xy * dt_s)
            self.acc_des[2:] = _shape(self.acc_des[2:], acc_cmd[2:], jerk_z * dt_s)
            if self.submode == "accel":
                self.pos_t += self.vel_t * dt_s + 0.5 * self.acc_des * dt_s * dt_s
                self.vel_t += self.acc_des * dt_s
            elif self.submode == "velaccel":
                self.vel_t = np.array(cmd.velocity_ned_m_s)
                self.pos_t += self.vel_t * dt_s
            else:  # posvelaccel
                self.vel_t = np.array(cmd.velocity_ned_m_s)
                self.pos_t = np.array(cmd.position_ned_m)
            if options & 32:  # do not stabilise velocity XY (nor position)
                self.pos_t[:2] = position[:2]
                self.vel_t[:2] = velocity[:2]
            elif options & 16:  # do not stabilise position XY
                self.pos_t[:2] = position[:2]
            vel_sp = self.vel_t + np.array([g.pos_xy, g.pos_xy, g.pos_z]) * (self.pos_t - position)
            accel = self.acc_des + np.array([g.vel_xy, g.vel_xy, g.vel_z]) * (vel_sp - velocity)
        yaw = self._yaw(dt_s, velocity, yaw_now)
        return AccelerationSetpoint(tuple(float(a) for a in accel), yaw, self.yaw_rate if yaw is not None else 0.0)

    def _yaw(self, dt_s: float, velocity: np.ndarray, yaw_now: float) -> float:
        if self.yaw_t is None:
            if math.hypot(velocity[0], velocity[1]) > 1.0:
                return math.atan2(velocity[1], velocity[0])
            self.yaw_t = yaw_now
        self.yaw_t = self.yaw_t + self.yaw_rate * dt_s
        return self.yaw_t

    def _angle(
        self,
        dt_s: float,
        timed_out: bool,
        options: int,
        hover_thrust: float,
        velocity: np.ndarray,
        q: np.ndarray,
        yaw_now: float,
        landed: bool,
    ) -> Setpoint:
        target = self.angle
        assert target is not None
        if timed_out:
            # Attitude timeout: level out, zero climb rate (sideways drift is not braked).
            thrust = thrust_for_climb(0.0, float(velocity[2]), q, hover_thrust, ARDUPILOT_GAINS.vel_z)
            return AttitudeSetpoint(level_attitude(yaw_now), thrust)
        if target.thrust_is_climb_rate:
            if landed and target.thrust <= 0.0:
                return MotorsOff()
            thrust = thrust_for_climb(target.thrust, float(velocity[2]), q, hover_thrust, ARDUPILOT_GAINS.vel_z)
        else:
            if landed and target.thrust <= 0.0:
                return MotorsOff()
            thrust = min(max(target.thrust, 0.0), 1.0)
        if target.q_ned_frd is None:
            rates = target.rates_frd_rad_s or (0.0, 0.0, 0.0)
            return RateSetpoint(rates, thrust)
        if target.rates_frd_rad_s is not None:
            # Rates advance the target attitude and are used as feed-forward.
            w = np.array(target.rates_frd_rad_s) * dt_s
            angle = float(np.linalg.norm(w))
            if angle > 0.0:
                axis = w / angle
                dq = np.concatenate(([math.cos(angle / 2)], axis * math.sin(angle / 2)))
                self.q_t = np.array(quat_mul(tuple(self.q_t), tuple(dq)))
                self.q_t /= float(np.linalg.norm(self.q_t))
        return AttitudeSetpoint(tuple(float(v) for v in self.q_t), thrust, target.rates_frd_rad_s)  # type: ignore[arg-type]
