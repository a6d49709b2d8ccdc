"""The mock's quadrotor dynamics and inner loops for N vehicles at once (mirrors
:class:`sitl_mock.dynamics.Simulator` step by step: 1 kHz physics, motors, the rate loop and its
output delay, the attitude loop with PX4's tilt priority, the acceleration mapping, the setpoint and
thrust latencies, ground contact, mean wind per vehicle, and the estimator's error).

All N vehicles share one :class:`~sitl_mock.dynamics.VehicleParams` and one clock (they are
stepped together); each has its own spawn, wind, setpoints and random generator (spawned exactly
as the scalar simulator spawns its streams, so the noise sequences match flight by flight).
Setpoints are given as a :class:`BatchSetpoint` of arrays, each row one of ``MOTORS_OFF``,
``ACCEL``, ``ATTITUDE`` or ``RATES`` (the autopilot's own position controller is not mirrored).
World NED, body FRD, like the scalar simulator.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sitl_mock.dynamics.estimator import EstimatorError
from sitl_mock.dynamics.params import GRAVITY_M_S2, VehicleParams
from sitl_mock.dynamics.sim import PHYSICS_DT_S, PHYSICS_RATE_HZ

from pf_offboard.sim.batch.geometry import atan2, unary

Arr = NDArray[np.float64]
Mask = NDArray[np.bool_]

MOTORS_OFF, ACCEL, ATTITUDE, RATES, POSITION = 0, 1, 2, 3, 4


@dataclass(frozen=True)
class BatchSetpoint:
    """One setpoint per vehicle (NED / FRD). ``kind``: MOTORS_OFF | ACCEL | ATTITUDE | RATES;
    the fields of the other kinds are ignored. ``yaw_rad`` NaN: hold the heading (yaw None);
    ``has_ff`` False: no body-rate feed-forward (None)."""

    kind: NDArray[np.int64]
    accel_ned_m_s2: Arr  # (3, N)
    yaw_rad: Arr
    yaw_rate_rad_s: Arr
    q_ned_frd: Arr  # (4, N)
    thrust_norm: Arr
    rates_frd_rad_s: Arr  # (3, N): the rate setpoint (RATES) or the feed-forward (ATTITUDE)
    has_ff: Mask
    position_ned_m: Arr | None = None  # (3, N), POSITION (the autopilot's position controller)
    velocity_ned_m_s: Arr | None = None  # (3, N), POSITION's velocity feed-forward

    @staticmethod
    def motors_off(n: int) -> BatchSetpoint:
        z = np.zeros(n)
        return BatchSetpoint(np.zeros(n, dtype=np.int64), np.zeros((3, n)), np.full(n, math.nan), z, np.tile([[1.0], [0.0], [0.0], [0.0]], n),
                             z, np.zeros((3, n)), np.zeros(n, dtype=bool))  # fmt: skip

    def take(self, mask: Mask, other: BatchSetpoint) -> BatchSetpoint:
        """Rows of ``other`` where ``mask``, of self elsewhere."""
        return BatchSetpoint(
            np.where(mask, other.kind, self.kind), np.where(mask, other.accel_ned_m_s2, self.accel_ned_m_s2),
            np.where(mask, other.yaw_rad, self.yaw_rad), np.where(mask, other.yaw_rate_rad_s, self.yaw_rate_rad_s),
            np.where(mask, other.q_ned_frd, self.q_ned_frd), np.where(mask, other.thrust_norm, self.thrust_norm),
            np.where(mask, other.rates_frd_rad_s, self.rates_frd_rad_s), np.where(mask, other.has_ff, self.has_ff),
            _take_opt(mask, self.position_ned_m, other.position_ned_m), _take_opt(mask, self.velocity_ned_m_s, other.velocity_ned_m_s),
        )  # fmt: skip


def _take_opt(mask: Mask, a: Arr | None, b: Arr | None) -> Arr | None:
    if a is None and b is None:
        return None
    n = mask.shape[0]
    a = np.zeros((3, n)) if a is None else a
    b = np.zeros((3, n)) if b is None else b
    return np.where(mask, b, a)


def _p_or_sqrt(k: float, accel_max: float, e: Arr) -> Arr:
    """:func:`sitl_mock.dynamics.sim._p_or_sqrt`."""
    if accel_max <= 0.0:
        return k * e
    e_lin = accel_max / (k * k)
    hi = e > e_lin
    lo = e < -e_lin
    return np.where(hi, np.sqrt(2.0 * accel_max * np.maximum(e - 0.5 * e_lin, 0.0)),
                    np.where(lo, -np.sqrt(2.0 * accel_max * np.maximum(-e - 0.5 * e_lin, 0.0)), k * e))  # fmt: skip


def _dcm_to_quat(r00: Arr, r01: Arr, r02: Arr, r10: Arr, r11: Arr, r12: Arr, r20: Arr, r21: Arr, r22: Arr) -> tuple[Arr, Arr, Arr, Arr]:
    tr = r00 + r11 + r22
    b0 = tr > 0.0
    b1 = ~b0 & (r00 > r11) & (r00 > r22)
    b2 = ~b0 & ~b1 & (r11 > r22)
    arg = np.where(b0, tr + 1.0, np.where(b1, 1.0 + r00 - r11 - r22, np.where(b2, 1.0 + r11 - r00 - r22, 1.0 + r22 - r00 - r11)))
    s = 2.0 * np.sqrt(np.maximum(arg, 0.0))
    s = np.where(s == 0.0, 1.0, s)
    return (
        np.where(b0, 0.25 * s, np.where(b1, (r21 - r12) / s, np.where(b2, (r02 - r20) / s, (r10 - r01) / s))),
        np.where(b0, (r21 - r12) / s, np.where(b1, 0.25 * s, np.where(b2, (r01 + r10) / s, (r02 + r20) / s))),
        np.where(b0, (r02 - r20) / s, np.where(b1, (r01 + r10) / s, np.where(b2, 0.25 * s, (r12 + r21) / s))),
        np.where(b0, (r10 - r01) / s, np.where(b1, (r02 + r20) / s, np.where(b2, (r12 + r21) / s, 0.25 * s))),
    )


class BatchSimulator:
    """N :class:`sitl_mock.dynamics.Simulator` s with one params and one clock.

    ``spawns``: (position_ned (3, N), velocity_ned (3, N), q_ned_frd (4, N), rates_frd (3, N),
    motors_at_hover (bool)) — all vehicles spawned alike (thrown or hovering); ``rngs``: one
    Generator per vehicle, as given to the scalar Simulator; ``wind_ned_m_s`` (3, N): a constant
    mean wind per vehicle."""

    def __init__(self, params: VehicleParams, rngs: list[np.random.Generator], position_ned_m: Arr,
                 velocity_ned_m_s: Arr | None = None, q_ned_frd: Arr | None = None, rates_frd_rad_s: Arr | None = None,
                 motors_at_hover: bool = False, wind_ned_m_s: Arr | None = None) -> None:  # fmt: skip
        n = len(rngs)
        self.n = n
        self.params = pr = params
        streams = [r.spawn(2) for r in rngs]
        self._rng_wind = [s[0] for s in streams]
        self._rng_sensors = [s[1] for s in streams]
        self._est = BatchEstimatorError(pr.estimator, [r.spawn(1)[0] for r in rngs]) if pr.estimator.enabled else None
        self._latency_ticks = int(round(pr.setpoint_latency_s * PHYSICS_RATE_HZ))
        tl = pr.setpoint_latency_s if pr.thrust_latency_s is None else pr.thrust_latency_s
        self._thrust_latency_ticks = int(round(tl * PHYSICS_RATE_HZ))
        self._split_thrust = self._thrust_latency_ticks != self._latency_ticks
        self._pending_sp: deque[tuple[int, BatchSetpoint]] = deque()
        self._pending_thrust: deque[tuple[int, BatchSetpoint]] = deque()
        self._init_constants(pr)
        self._ticks = 0
        self._t_req_s = 0.0
        z = np.zeros(n)
        p = np.asarray(position_ned_m, dtype=float).reshape(3, n)
        v = np.zeros((3, n)) if velocity_ned_m_s is None else np.asarray(velocity_ned_m_s, dtype=float).reshape(3, n)
        q = np.tile([[1.0], [0.0], [0.0], [0.0]], n) if q_ned_frd is None else np.asarray(q_ned_frd, dtype=float).reshape(4, n)
        w = np.zeros((3, n)) if rates_frd_rad_s is None else np.asarray(rates_frd_rad_s, dtype=float).reshape(3, n)
        if np.any(p[2] > 0.0):
            raise ValueError("BatchSimulator.position_ned_m: below the ground (NED z > 0)")
        qn = np.sqrt(np.sum(q * q, axis=0))
        q = q / qn  # Spawn's _unit_quat
        t0 = self._m_weight_per_motor if motors_at_hover else 0.0
        # state arrays: position, velocity, quaternion, rates, motor thrusts, rate integrators
        self.px, self.py, self.pz = p[0].copy(), p[1].copy(), p[2].copy()
        self.vx, self.vy, self.vz = v[0].copy(), v[1].copy(), v[2].copy()
        self.qw, self.qx, self.qy, self.qz = q[0].copy(), q[1].copy(), q[2].copy(), q[3].copy()
        self.wx, self.wy, self.wz = w[0].copy(), w[1].copy(), w[2].copy()
        self.t = [np.full(n, t0) for _ in range(4)]
        self.ix, self.iy, self.iz = z.copy(), z.copy(), z.copy()
        self.accel = (z.copy(), z.copy(), z.copy())
        self.landed = (p[2] >= 0.0) & (not motors_at_hover)
        self.crashed = np.zeros(n, dtype=bool)
        self._rs = (z.copy(), z.copy(), z.copy(), np.full(n, t0))
        self.motors_on = np.full(n, motors_at_hover)
        self._countdown = 0
        self._rate_countdown = np.zeros(n, dtype=np.int64)
        self._motor_cmd = [np.full(n, t0) for _ in range(4)]
        n_delay = int(round(pr.rate_loop_delay_s * pr.rate_loop_hz))
        self._delay_q: list[list[Arr]] | None = [[np.full(n, t0) for _ in range(4)] for _ in range(n_delay)] if n_delay > 0 else None
        self._q_sp = (q[0].copy(), q[1].copy(), q[2].copy(), q[3].copy())
        self._thrust_sp = np.full(n, pr.hover_thrust if motors_at_hover else 0.0)
        if motors_at_hover:
            sp = BatchSetpoint.motors_off(n)
            sp = BatchSetpoint(np.full(n, ACCEL, dtype=np.int64), *list(sp.__dict__.values())[1:])  # type: ignore[arg-type]
        else:
            sp = BatchSetpoint.motors_off(n)
        self._setpoint = sp
        self._thrust_setpoint = sp
        self._sp_kind = sp.kind.copy()
        self._yaw_hold = np.full(n, math.nan)
        self._vel_int = [z.copy(), z.copy(), z.copy()]
        wind = np.zeros((3, n)) if wind_ned_m_s is None else np.asarray(wind_ned_m_s, dtype=float).reshape(3, n)
        self._wind_now = (wind[0].copy(), wind[1].copy(), wind[2].copy())

    def _init_constants(self, pr: VehicleParams) -> None:
        dt = PHYSICS_DT_S
        self._tmax = pr.motor_thrust_max_n
        self._tmin = pr.motor_idle_fraction * self._tmax
        self._inv_4tmax = 1.0 / (4.0 * self._tmax)
        self._m_weight_per_motor = pr.weight_n / 4.0
        self._a_arm = pr.arm_length_m / math.sqrt(2.0)
        self._alpha_motor = 1.0 - math.exp(-dt / pr.motor_time_constant_s)
        self._att_div = int(round(PHYSICS_RATE_HZ / pr.attitude_loop_hz))
        self._rate_div = int(round(PHYSICS_RATE_HZ / pr.rate_loop_hz))
        self._att_dt = self._att_div * dt
        rp, yw = pr.roll_pitch, pr.yaw
        self._yaw_w = min(1.0, yw.attitude_p_1_s / rp.attitude_p_1_s)
        self._yaw_err_scale = 1.0 / self._yaw_w
        self._k_att = (rp.attitude_p_1_s, rp.attitude_p_1_s, yw.attitude_p_1_s)
        self._rate_lim = (rp.rate_limit_rad_s, rp.rate_limit_rad_s, yw.rate_limit_rad_s)
        self._att_accel_max = (rp.attitude_accel_max_rad_s2, yw.attitude_accel_max_rad_s2)
        self._cos_tilt_max = math.cos(pr.tilt_max_rad)
        self._sin_tilt_max = math.sin(pr.tilt_max_rad)
        self._hover_thrust = pr.hover_thrust
        self._inv_g = 1.0 / GRAVITY_M_S2
        self._thr_min, self._thr_max = pr.thrust_min_norm, pr.thrust_max_norm
        self._accel_decouple = pr.accel_decouple

    def set_hover_thrust(self, hover_thrust: float) -> None:
        """The autopilot's hover-thrust parameter (``params.with_(hover_thrust=...)``)."""
        self.params = self.params.with_(hover_thrust=hover_thrust)
        self._init_constants(self.params)

    # ------------------------------------------------------------------ public
    @property
    def time_s(self) -> float:
        return self._ticks * PHYSICS_DT_S

    def advance(self, dt_s: float, setpoint: BatchSetpoint) -> None:
        """``Simulator.advance`` for every vehicle."""
        if np.any(setpoint.kind == ATTITUDE):  # AttitudeSetpoint normalises its quaternion
            q = setpoint.q_ned_frd
            qn = q / np.sqrt(((q[0] * q[0] + q[1] * q[1]) + q[2] * q[2]) + q[3] * q[3])
            setpoint = BatchSetpoint(setpoint.kind, setpoint.accel_ned_m_s2, setpoint.yaw_rad, setpoint.yaw_rate_rad_s,
                                     np.where(setpoint.kind == ATTITUDE, qn, q), setpoint.thrust_norm, setpoint.rates_frd_rad_s,
                                     setpoint.has_ff, setpoint.position_ned_m, setpoint.velocity_ned_m_s)  # fmt: skip
        self._t_req_s += dt_s
        target = int(round(self._t_req_s * PHYSICS_RATE_HZ))
        if self._latency_ticks == 0 and not self._split_thrust:
            self._select(setpoint)
            if target > self._ticks:
                self._run(target - self._ticks)
        else:
            self._pending_sp.append((self._ticks + self._latency_ticks, setpoint))
            if self._split_thrust:
                self._pending_thrust.append((self._ticks + self._thrust_latency_ticks, setpoint))
            self._run_queued(target)
        if self._est is not None:
            self._est.advance_to(self._ticks * PHYSICS_DT_S)

    def _run_queued(self, target: int) -> None:
        pending, pending_t = self._pending_sp, self._pending_thrust
        while True:
            while pending and pending[0][0] <= self._ticks:
                self._select(pending.popleft()[1])
            while pending_t and pending_t[0][0] <= self._ticks:
                self._select_thrust(pending_t.popleft()[1])
            if self._ticks >= target:
                break
            stop = target
            if pending and pending[0][0] < stop:
                stop = pending[0][0]
            if pending_t and pending_t[0][0] < stop:
                stop = pending_t[0][0]
            self._run(stop - self._ticks)

    def estimate_error(self) -> tuple[Arr, Arr]:
        """(position (3, N), velocity (3, N)) error of the reported state, NED."""
        if self._est is None:
            return np.zeros((3, self.n)), np.zeros((3, self.n))
        return self._est.position_error_ned_m, self._est.velocity_error_ned_m_s

    # ------------------------------------------------------------------ setpoints
    def _select(self, sp: BatchSetpoint) -> None:
        kind = sp.kind
        changed = kind != self._sp_kind
        vi = changed & (kind != POSITION)
        self._vel_int = [np.where(vi, 0.0, a) for a in self._vel_int]
        self._yaw_hold = np.where(changed & ((kind == ATTITUDE) | (kind == RATES) | (kind == MOTORS_OFF)), math.nan, self._yaw_hold)
        from_off = changed & (self._sp_kind == MOTORS_OFF)
        self.ix = np.where(from_off, 0.0, self.ix)
        self.iy = np.where(from_off, 0.0, self.iy)
        self.iz = np.where(from_off, 0.0, self.iz)
        self._sp_kind = kind.copy()
        self._setpoint = sp
        self.motors_on = kind != MOTORS_OFF
        off = kind == MOTORS_OFF
        rate = kind == RATES
        rs = list(self._rs)
        thr = self._flown_thrust_norm()
        for i in range(3):
            rs[i] = np.where(off, 0.0, np.where(rate, sp.rates_frd_rad_s[i], rs[i]))
        rs[3] = np.where(off, 0.0, np.where(rate, thr * self._tmax, rs[3]))
        self._rs = (rs[0], rs[1], rs[2], rs[3])
        self._thrust_sp = np.where(off, 0.0, np.where(rate, thr, self._thrust_sp))

    def _flown_uses_thrust_path(self) -> Mask:
        if not self._split_thrust:
            return np.zeros(self.n, dtype=bool)
        return self._thrust_setpoint.kind == self._sp_kind

    def _flown_thrust_norm(self) -> Arr:
        return np.where(self._flown_uses_thrust_path(), self._thrust_setpoint.thrust_norm, self._setpoint.thrust_norm)

    def _select_thrust(self, sp: BatchSetpoint) -> None:
        self._thrust_setpoint = sp
        both = (self._sp_kind == RATES) & (sp.kind == RATES)
        rs = self._rs
        self._thrust_sp = np.where(both, sp.thrust_norm, self._thrust_sp)
        self._rs = (rs[0], rs[1], rs[2], np.where(both, sp.thrust_norm * self._tmax, rs[3]))

    # ------------------------------------------------------------------ autopilot
    def _control_tick(self, on: Mask) -> tuple[Arr, Arr, Arr, Arr]:
        sp = self._setpoint
        kind = self._sp_kind
        qw, qx, qy, qz = self.qw, self.qx, self.qy, self.qz
        pos_k = on & (kind == POSITION)
        acc = on & (kind == ACCEL)
        att = on & (kind == ATTITUDE)
        ctl = acc | att | pos_k
        if not ctl.any():
            return self._rs
        # acceleration
        yaw = sp.yaw_rad
        hold = acc & np.isnan(yaw)
        if hold.any():
            latch = hold & np.isnan(self._yaw_hold)
            if latch.any():
                yl = atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
                self._yaw_hold = np.where(latch, yl, self._yaw_hold)
            self._yaw_hold = np.where(hold, self._yaw_hold + sp.yaw_rate_rad_s * self._att_dt, self._yaw_hold)
        self._yaw_hold = np.where(acc & ~hold, math.nan, self._yaw_hold)
        if pos_k.any():  # the position controller (hold / brake): yaw given, or held
            phold = pos_k & np.isnan(sp.yaw_rad)
            if phold.any():
                latch = phold & np.isnan(self._yaw_hold)
                yl = atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
                self._yaw_hold = np.where(latch, yl, self._yaw_hold)
                self._yaw_hold = np.where(phold, self._yaw_hold + 0.0 * self._att_dt, self._yaw_hold)
            self._yaw_hold = np.where(pos_k & ~phold, math.nan, self._yaw_hold)
            yaw = np.where(pos_k, np.where(phold, self._yaw_hold, sp.yaw_rad), yaw)
        yaw = np.where(hold, self._yaw_hold, np.where(acc | pos_k, yaw, 0.0))
        accel = sp.accel_ned_m_s2
        if pos_k.any():
            pa = self._position_control(sp, pos_k)
            accel = np.where(pos_k, pa, accel)
        qd_a, thrust_a = self._accel_to_attitude(accel, yaw)
        if self._split_thrust:
            use_t = self._flown_uses_thrust_path()
            thrust_t = self._accel_to_attitude(self._thrust_setpoint.accel_ned_m_s2, yaw)[1]
            thrust_a = np.where(use_t & acc, thrust_t, thrust_a)
        acc_only = acc
        acc = acc | pos_k  # both fly the acceleration mapping
        qd = tuple(np.where(acc, qa, sp.q_ned_frd[i]) for i, qa in enumerate(qd_a))
        thrust = np.where(acc, thrust_a, self._flown_thrust_norm())
        ffm = att & sp.has_ff
        ff = (np.where(ffm, sp.rates_frd_rad_s[0], 0.0), np.where(ffm, sp.rates_frd_rad_s[1], 0.0), np.where(ffm, sp.rates_frd_rad_s[2], 0.0))
        yaw_rate_w = np.where(acc_only, sp.yaw_rate_rad_s, 0.0)
        self._q_sp = tuple(np.where(ctl, qd[i], self._q_sp[i]) for i in range(4))  # type: ignore[assignment]
        self._thrust_sp = np.where(ctl, thrust, self._thrust_sp)
        rx, ry, rz = self._attitude_control(qw, qx, qy, qz, qd, ff, yaw_rate_w)
        rs = self._rs
        return (np.where(ctl, rx, rs[0]), np.where(ctl, ry, rs[1]), np.where(ctl, rz, rs[2]), np.where(ctl, thrust * self._tmax, rs[3]))

    def _position_control(self, sp: BatchSetpoint, rows: Mask) -> Arr:
        """``Simulator._position_control``: cascaded P (position) -> PI (velocity) -> acceleration."""
        from pf_offboard.sim.batch.geometry import hypot

        pr = self.params
        assert sp.position_ned_m is not None and sp.velocity_ned_m_s is not None
        tx, ty, tz = sp.position_ned_m
        fx, fy, fz = sp.velocity_ned_m_s
        kp = pr.position_p_1_s
        vsx = fx + kp * (tx - self.px)
        vsy = fy + kp * (ty - self.py)
        vh = hypot(vsx, vsy)
        big = vh > pr.velocity_max_xy_m_s
        s = pr.velocity_max_xy_m_s / np.where(big, vh, 1.0)
        vsx, vsy = np.where(big, vsx * s, vsx), np.where(big, vsy * s, vsy)
        vsz = np.where(tz >= 0.0, pr.land_speed_m_s,
                       np.minimum(np.maximum(fz + kp * (tz - self.pz), -pr.velocity_max_up_m_s), pr.velocity_max_down_m_s))  # fmt: skip
        ex, ey, ez = vsx - self.vx, vsy - self.vy, vsz - self.vz
        vi = self._vel_int
        upd = rows & ~self.landed
        ki, dt = pr.velocity_i_1_s2, self._att_dt
        lim = 0.5 * GRAVITY_M_S2
        for i, e in enumerate((ex, ey, ez)):
            vi[i] = np.where(upd, np.minimum(np.maximum(vi[i] + ki * e * dt, -lim), lim), vi[i])
        kv = pr.velocity_p_1_s
        ax, ay, az = kv * ex + vi[0], kv * ey + vi[1], kv * ez + vi[2]
        ah_max = GRAVITY_M_S2 * math.tan(pr.tilt_max_rad)
        ah = hypot(ax, ay)
        big = ah > ah_max
        s = ah_max / np.where(big, ah, 1.0)
        return np.array((np.where(big, ax * s, ax), np.where(big, ay * s, ay), az))

    def _accel_to_attitude(self, accel_ned: Arr, yaw: Arr) -> tuple[tuple[Arr, Arr, Arr, Arr], Arr]:
        g = GRAVITY_M_S2
        ax, ay, az = accel_ned
        bx, by = -ax, -ay
        bz = np.full_like(ax, g) if self._accel_decouple else g - az
        n = np.sqrt(bx * bx + by * by + bz * bz)
        small = n < 1e-6
        ns = np.where(small, 1.0, n)
        bx, by, bz = np.where(small, 0.0, bx / ns), np.where(small, 0.0, by / ns), np.where(small, 1.0, bz / ns)
        cos_tilt = self._cos_tilt_max
        lim = bz < cos_tilt
        h = np.sqrt(bx * bx + by * by)
        hz = h > 1e-9
        k = self._sin_tilt_max / np.where(hz, h, 1.0)
        bx = np.where(lim, np.where(hz, bx * k, self._sin_tilt_max), bx)
        by = np.where(lim, np.where(hz, by * k, 0.0), by)
        bz = np.where(lim, cos_tilt, bz)
        thrust = self._hover_thrust * (1.0 - az * self._inv_g) / bz
        thrust = np.where(thrust < self._thr_min, self._thr_min, np.where(thrust > self._thr_max, self._thr_max, thrust))
        cy, sy = np.cos(yaw), np.sin(yaw)
        xx, xy, xz = cy * bz, sy * bz, -sy * by - cy * bx
        nx = 1.0 / np.sqrt(xx * xx + xy * xy + xz * xz)
        xx, xy, xz = xx * nx, xy * nx, xz * nx
        yx, yy, yz = by * xz - bz * xy, bz * xx - bx * xz, bx * xy - by * xx
        return _dcm_to_quat(xx, yx, bx, xy, yy, by, xz, yz, bz), thrust

    def _attitude_control(self, qw: Arr, qx: Arr, qy: Arr, qz: Arr, qd: Any, ff: tuple[Arr, Arr, Arr], yaw_rate_w: Arr) -> tuple[Arr, Arr, Arr]:
        ffx, ffy, ffz = ff
        dw, dx, dy, dz = qd
        ezx, ezy, ezz = 2.0 * (qx * qz + qw * qy), 2.0 * (qy * qz - qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy)
        edx, edy, edz = 2.0 * (dx * dz + dw * dy), 2.0 * (dy * dz - dw * dx), 1.0 - 2.0 * (dx * dx + dy * dy)
        yaw_w = self._yaw_w
        if yaw_w < 1.0:
            dot = ezx * edx + ezy * edy + ezz * edz
            crx, cry, crz = ezy * edz - ezz * edy, ezz * edx - ezx * edz, ezx * edy - ezy * edx
            rw = 1.0 + dot
            nr = np.sqrt(rw * rw + crx * crx + cry * cry + crz * crz)
            full = (nr < 1e-9) | (rw / np.where(nr == 0.0, 1.0, nr) < 1e-5)
            nr = 1.0 / np.where(full, 1.0, nr)
            aw, ax, ay, az = rw * nr, crx * nr, cry * nr, crz * nr
            r_w = aw * qw - ax * qx - ay * qy - az * qz
            r_x = aw * qx + ax * qw + ay * qz - az * qy
            r_y = aw * qy - ax * qz + ay * qw + az * qx
            r_z = aw * qz + ax * qy - ay * qx + az * qw
            rw, rx, ry, rz = np.where(full, dw, r_w), np.where(full, dx, r_x), np.where(full, dy, r_y), np.where(full, dz, r_z)
            mw = rw * dw + rx * dx + ry * dy + rz * dz
            mz = rw * dz - rx * dy + ry * dx - rz * dw
            neg = mw < 0.0
            mw, mz = np.where(neg, -mw, mw), np.where(neg, -mz, mz)
            mw = np.where(mw > 1.0, 1.0, mw)
            mz = np.where(mz > 1.0, 1.0, np.where(mz < -1.0, -1.0, mz))
            cw = np.cos(yaw_w * unary(math.acos, mw))
            cz = np.sin(yaw_w * unary(math.asin, mz))
            dw, dx, dy, dz = rw * cw - rz * cz, rx * cw + ry * cz, ry * cw - rx * cz, rw * cz + rz * cw
        ew = qw * dw + qx * dx + qy * dy + qz * dz
        ex = qw * dx - qx * dw - qy * dz + qz * dy
        ey = qw * dy + qx * dz - qy * dw - qz * dx
        ez = qw * dz - qx * dy + qy * dx - qz * dw
        s = np.where(ew >= 0.0, 2.0, -2.0)
        kx, ky, kz = self._k_att
        ex, ey, ez = s * ex, s * ey, s * ez * self._yaw_err_scale
        amx, amz = self._att_accel_max
        exy = np.sqrt(ex * ex + ey * ey)
        big = exy > 1e-12
        sxy = np.where(big, _p_or_sqrt(kx, amx, exy) / np.where(big, exy, 1.0), kx)
        rx_ = sxy * ex + ffx + yaw_rate_w * 2.0 * (qx * qz - qw * qy)
        ry_ = sxy * ey + ffy + yaw_rate_w * 2.0 * (qy * qz + qw * qx)
        rz_ = _p_or_sqrt(kz, amz, ez) + ffz + yaw_rate_w * (1.0 - 2.0 * (qx * qx + qy * qy))
        lx, ly, lz = self._rate_lim
        return (np.where(rx_ > lx, lx, np.where(rx_ < -lx, -lx, rx_)), np.where(ry_ > ly, ly, np.where(ry_ < -ly, -ly, ry_)),
                np.where(rz_ > lz, lz, np.where(rz_ < -lz, -lz, rz_)))  # fmt: skip

    # ------------------------------------------------------------------ the 1 kHz loop
    def _run(self, n: int) -> None:
        pr = self.params
        dt = PHYSICS_DT_S
        hdt = 0.5 * dt
        g = GRAVITY_M_S2
        inv_m = 1.0 / pr.mass_kg
        cd = pr.drag_1_s
        if cd > 0.0:
            ed = math.exp(-cd * dt)
            k1 = -math.expm1(-cd * dt) / cd
            k2 = (dt - k1) / cd
        else:
            ed, k1, k2 = 1.0, dt, 0.5 * dt * dt
        jx, jy, jz = pr.inertia_xx_kg_m2, pr.inertia_yy_kg_m2, pr.inertia_zz_kg_m2
        ijx, ijy, ijz = 1.0 / jx, 1.0 / jy, 1.0 / jz
        gx_, gy_, gz_ = (jy - jz) / jx, (jz - jx) / jy, (jx - jy) / jz
        arm = self._a_arm
        km = pr.yaw_torque_per_thrust_m
        inv4a, inv4k = 1.0 / (4.0 * arm), 1.0 / (4.0 * km)
        rp, yw = pr.roll_pitch, pr.yaw
        kpx, kpy, kpz = jx * rp.rate_p_1_s * inv4a, jy * rp.rate_p_1_s * inv4a, jz * yw.rate_p_1_s * inv4k
        kix, kiy, kiz = jx * rp.rate_i_1_s2 * inv4a, jy * rp.rate_i_1_s2 * inv4a, jz * yw.rate_i_1_s2 * inv4k
        ldx = ldy = 1.0 + rp.rate_d
        ldz = 1.0 + yw.rate_d
        kdx, kdy, kdz = rp.rate_d * inv4a, rp.rate_d * inv4a, yw.rate_d * inv4k
        tmax, tmin = self._tmax, self._tmin
        half = 0.5 * (tmax - tmin)
        ilx = 0.2 * half / kix if kix > 0 else 0.0
        ily = 0.2 * half / kiy if kiy > 0 else 0.0
        ilz = 0.2 * half / kiz if kiz > 0 else 0.0
        am = self._alpha_motor
        lead_c = pr.thrust_lead
        crash_speed = pr.crash_speed_m_s
        mu = pr.ground_friction
        on = self.motors_on
        all_on, none_on = bool(on.all()), not on.any()
        div = self._att_div
        countdown = self._countdown
        wnx, wny, wnz = self._wind_now
        crashed, landed = self.crashed, self.landed
        rsx, rsy, rsz, cc = self._rs
        airmode = pr.airmode
        avail = np.full(self.n, half) if airmode else np.minimum(np.maximum(cc - tmin, 0.0), half)
        px, py, pz, vx, vy, vz = self.px, self.py, self.pz, self.vx, self.vy, self.vz
        qw, qx, qy, qz, wx, wy, wz = self.qw, self.qx, self.qy, self.qz, self.wx, self.wy, self.wz
        t0, t1, t2, t3 = self.t
        ix, iy, iz = self.ix, self.iy, self.iz
        tqx = arm * (t1 + t2 - t0 - t3)
        tqy = arm * (t0 + t2 - t1 - t3)
        tqz = km * (t0 + t1 - t2 - t3)
        ticks = self._ticks
        z = np.zeros(self.n)
        ax = ay = az = z
        rdiv = self._rate_div
        rdt = rdiv * dt
        rcount = np.where(on, self._rate_countdown, 0)
        m0, m1, m2, m3 = self._motor_cmd
        delay_q = self._delay_q
        for _ in range(n):
            if countdown <= 0:
                countdown = div
                nq = 1.0 / np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
                qw, qx, qy, qz = qw * nq, qx * nq, qy * nq, qz * nq
                if not none_on:
                    self.qw, self.qx, self.qy, self.qz = qw, qx, qy, qz
                    self.px, self.py, self.pz, self.vx, self.vy, self.vz = px, py, pz, vx, vy, vz
                    self.landed = landed
                    rsx, rsy, rsz, cc = self._control_tick(on)
                    if not airmode:
                        av = np.where(cc - tmin < half, cc - tmin, half)
                        av = np.where(av < 0.0, 0.0, av)
                        avail = np.where(on, av, avail)
            countdown -= 1
            ticks += 1
            if not none_on:
                tick = on & (rcount <= 0)
                if tick.any():
                    rcount = np.where(tick, rdiv, rcount)
                    ex, ey, ez = rsx - wx, rsy - wy, rsz - wz
                    nix = np.minimum(np.maximum(ix + ex * rdt, -ilx), ilx)
                    niy = np.minimum(np.maximum(iy + ey * rdt, -ily), ily)
                    niz = np.minimum(np.maximum(iz + ez * rdt, -ilz), ilz)
                    r = np.minimum(np.maximum(kpx * ex + kix * nix, -avail), avail)
                    p = np.minimum(np.maximum(kpy * ey + kiy * niy, -avail), avail)
                    yv = np.minimum(np.maximum(kpz * ez + kiz * niz, -avail), avail)
                    r = ldx * r - kdx * tqx
                    p = ldy * p - kdy * tqy
                    yv = ldz * yv - kdz * tqz
                    rp0 = p - r
                    rp2 = r + p
                    a0 = np.abs(rp0)
                    a2 = np.abs(rp2)
                    mm = np.where(a0 > a2, a0, a2)
                    sat = mm > half
                    if sat.any():
                        s = half / np.where(sat, mm, 1.0)
                        rp0, rp2 = np.where(sat, rp0 * s, rp0), np.where(sat, rp2 * s, rp2)
                        a0, a2 = np.where(sat, a0 * s, a0), np.where(sat, a2 * s, a2)
                        mm = np.where(sat, half, mm)
                    c = cc + lead_c * (cc - 0.25 * (t0 + t1 + t2 + t3)) if lead_c > 0.0 else cc
                    c = np.where(c > tmax - mm, tmax - mm, c)
                    if airmode:
                        c = np.where(c < tmin + mm, tmin + mm, c)
                    else:
                        low = c < tmin + mm
                        if low.any():
                            zero = low & (c <= tmin)
                            part = low & ~zero
                            s = (c - tmin) / np.where(part, mm, 1.0)
                            c = np.where(zero, tmin, c)
                            rp0 = np.where(zero, 0.0, np.where(part, rp0 * s, rp0))
                            rp2 = np.where(zero, 0.0, np.where(part, rp2 * s, rp2))
                            a0 = np.where(zero, 0.0, np.where(part, a0 * s, a0))
                            a2 = np.where(zero, 0.0, np.where(part, a2 * s, a2))
                    yhi = tmax - c - a0
                    lim = c - a2 - tmin
                    yhi = np.where(lim < yhi, lim, yhi)
                    ylo = tmin - c + a0
                    lim = c + a2 - tmax
                    ylo = np.where(lim > ylo, lim, ylo)
                    yv = np.where(yv > yhi, yhi, np.where(yv < ylo, ylo, yv))
                    n0, n1, n2, n3 = c + rp0 + yv, c - rp0 + yv, c + rp2 - yv, c - rp2 - yv
                    if delay_q is not None:
                        out = delay_q[0]
                        for k in range(len(delay_q) - 1):
                            delay_q[k] = [np.where(tick, delay_q[k + 1][j], delay_q[k][j]) for j in range(4)]
                        delay_q[-1] = [np.where(tick, nn, delay_q[-1][j]) for j, nn in enumerate((n0, n1, n2, n3))]
                        n0, n1, n2, n3 = out
                    ix, iy, iz = np.where(tick, nix, ix), np.where(tick, niy, iy), np.where(tick, niz, iz)
                    m0, m1, m2, m3 = np.where(tick, n0, m0), np.where(tick, n1, m1), np.where(tick, n2, m2), np.where(tick, n3, m3)
                rcount = np.where(on, rcount - 1, rcount)
            if all_on:
                t0 = t0 + am * (m0 - t0)
                t1 = t1 + am * (m1 - t1)
                t2 = t2 + am * (m2 - t2)
                t3 = t3 + am * (m3 - t3)
            elif none_on:
                t0 = t0 - am * t0
                t1 = t1 - am * t1
                t2 = t2 - am * t2
                t3 = t3 - am * t3
            else:
                t0 = np.where(on, t0 + am * (m0 - t0), t0 - am * t0)
                t1 = np.where(on, t1 + am * (m1 - t1), t1 - am * t1)
                t2 = np.where(on, t2 + am * (m2 - t2), t2 - am * t2)
                t3 = np.where(on, t3 + am * (m3 - t3), t3 - am * t3)
            f = (t0 + t1 + t2 + t3) * inv_m
            tqx = arm * (t1 + t2 - t0 - t3)
            tqy = arm * (t0 + t2 - t1 - t3)
            tqz = km * (t0 + t1 - t2 - t3)
            c2x = 2.0 * (qx * qz + qw * qy)
            c2y = 2.0 * (qy * qz - qw * qx)
            c2z = 1.0 - 2.0 * (qx * qx + qy * qy)
            ux = -f * c2x
            uy = -f * c2y
            uz = g - f * c2z
            rx_ = vx - wnx
            ry_ = vy - wny
            rz_ = vz - wnz
            ax = ux - cd * rx_
            ay = uy - cd * ry_
            az = uz - cd * rz_
            px = px + (wnx * dt + rx_ * k1 + ux * k2)
            py = py + (wny * dt + ry_ * k1 + uy * k2)
            pz = pz + (wnz * dt + rz_ * k1 + uz * k2)
            vx = wnx + rx_ * ed + ux * k1
            vy = wny + ry_ * ed + uy * k1
            vz = wnz + rz_ * ed + uz * k1
            dx = tqx * ijx + gx_ * wy * wz
            dy = tqy * ijy + gy_ * wz * wx
            dz = tqz * ijz + gz_ * wx * wy
            mx = wx + hdt * dx
            my = wy + hdt * dy
            mz = wz + hdt * dz
            wx = wx + dt * (tqx * ijx + gx_ * my * mz)
            wy = wy + dt * (tqy * ijy + gy_ * mz * mx)
            wz = wz + dt * (tqz * ijz + gz_ * mx * my)
            hx, hy, hz = mx * hdt, my * hdt, mz * hdt
            n2 = hx * hx + hy * hy + hz * hz
            cq = 1.0 - n2 * (0.5 - n2 * 0.041666666666666664)
            sq = 1.0 - n2 * (0.16666666666666666 - n2 * 0.008333333333333333)
            hx, hy, hz = hx * sq, hy * sq, hz * sq
            qw, qx, qy, qz = (
                qw * cq - qx * hx - qy * hy - qz * hz,
                qw * hx + qx * cq + qy * hz - qz * hy,
                qw * hy - qx * hz + qy * cq + qz * hx,
                qw * hz + qx * hy - qy * hx + qz * cq,
            )
            ground = pz >= 0.0
            if ground.any():
                crashed = crashed | (ground & (vz > crash_speed))
                pz = np.where(ground, 0.0, pz)
                vz = np.where(ground & (vz > 0.0), 0.0, vz)
                rest = ground & (uz > 0.0)
                if rest.any():
                    sh = np.sqrt(vx * vx + vy * vy)
                    dv = mu * uz * dt
                    stop = sh <= dv
                    kk = 1.0 - dv / np.where(stop, 1.0, sh)
                    vx = np.where(rest, np.where(stop, 0.0, vx * kk), vx)
                    vy = np.where(rest, np.where(stop, 0.0, vy * kk), vy)
                    yaw = atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
                    qw = np.where(rest, np.cos(0.5 * yaw), qw)
                    qx = np.where(rest, 0.0, qx)
                    qy = np.where(rest, 0.0, qy)
                    qz = np.where(rest, np.sin(0.5 * yaw), qz)
                    wx, wy, wz = np.where(rest, 0.0, wx), np.where(rest, 0.0, wy), np.where(rest, 0.0, wz)
                    ix, iy, iz = np.where(rest, 0.0, ix), np.where(rest, 0.0, iy), np.where(rest, 0.0, iz)
                    ax, ay, az = np.where(rest, 0.0, ax), np.where(rest, 0.0, ay), np.where(rest, 0.0, az)
                landed = rest
            else:
                landed = ground
        self.px, self.py, self.pz, self.vx, self.vy, self.vz = px, py, pz, vx, vy, vz
        self.qw, self.qx, self.qy, self.qz, self.wx, self.wy, self.wz = qw, qx, qy, qz, wx, wy, wz
        self.t = [t0, t1, t2, t3]
        self.ix, self.iy, self.iz = ix, iy, iz
        self.accel = (ax, ay, az)
        self._ticks = ticks
        self._countdown = countdown
        self._rate_countdown = rcount
        self._motor_cmd = [m0, m1, m2, m3]
        self._rs = (rsx, rsy, rsz, cc)
        self.landed = landed
        self.crashed = crashed


class BatchEstimatorError:
    """:class:`sitl_mock.dynamics.estimator.EstimatorError` for N vehicles sharing one clock and one
    :class:`EstimatorNoise`: the draws come from each vehicle's own generator, per fusion, in the
    scalar order (9 normals, then the bias's 3 from its own spawned stream)."""

    def __init__(self, noise: Any, rngs: list[np.random.Generator]) -> None:
        ref = EstimatorError(noise, np.random.default_rng(0))  # the constants, computed by the scalar code
        self.noise = noise
        self.n = n = len(rngs)
        self._rng = rngs
        bias_on = noise.velocity_bias_std_xy_m_s > 0.0 or noise.velocity_bias_std_z_m_s > 0.0
        self._rng_b = [r.spawn(1)[0] for r in rngs] if bias_on else None
        self._period_s = ref._period_s
        self._epoch = 0
        self._phi_v, self._leak, self._gain_p = ref._phi_v, ref._leak, ref._gain_p
        self._drive = np.array(ref._drive)[:, None]
        self._white_p = np.array(ref._white_p)[:, None]
        self._white_v = np.array(ref._white_v)[:, None]
        self._phi_b = ref._phi_b
        self._drive_b = np.array(ref._drive_b)[:, None]
        self._smooth = ref._smooth
        z = np.zeros((3, n))
        self._vb, self._vbs, self._wv, self._wvs, self._wp = z.copy(), z.copy(), z.copy(), z.copy(), z.copy()
        self.position_error_ned_m = z.copy()
        self.velocity_error_ned_m_s = z.copy()
        self._tau_out_s = ref._tau_out_s
        self._fused_p = z.copy()
        self._out_time_s = 0.0

    def advance_to(self, time_s: float) -> None:
        if not self.noise.enabled:
            return
        due = int(math.floor(time_s / self._period_s + 1e-9))
        if self._tau_out_s <= 0.0:
            if due <= self._epoch:
                return
            self._fuse(due - self._epoch)
            self.position_error_ned_m = self._fused_p
            return
        while self._epoch < due:
            self._relax((self._epoch + 1) * self._period_s)
            self._fuse(1)
        self._relax(time_s)

    def _relax(self, time_s: float) -> None:
        dt = time_s - self._out_time_s
        if dt <= 0.0:
            return
        k = math.exp(-dt / self._tau_out_s)
        p, f = self.position_error_ned_m, self._fused_p
        self.position_error_ned_m = f + (p - f) * k
        self._out_time_s = time_s

    def _fuse(self, m: int) -> None:
        self._epoch += m
        z = np.stack([r.standard_normal((m, 9)) for r in self._rng], axis=2)  # (m, 9, N)
        wv, ws, wp = self._wv, self._wvs, self._wp
        phi, leak, gp, a = self._phi_v, self._leak, self._gain_p, self._smooth
        drive = self._drive
        row = z[-1]
        for row in z:
            wp = leak * wp + gp * ws
            wv = phi * wv + drive * row[0:3]
            ws = a * ws + (1.0 - a) * wv
        self._wv, self._wvs, self._wp = wv, ws, wp
        vb, bs = self._vb, self._vbs
        if self._rng_b is not None:
            zb = np.stack([r.standard_normal((m, 3)) for r in self._rng_b], axis=2)
            for rb in zb:
                vb = self._phi_b * vb + self._drive_b * rb
                bs = a * bs + (1.0 - a) * vb
            self._vb, self._vbs = vb, bs
        self._fused_p = wp + self._white_p * row[3:6]
        self.velocity_error_ned_m_s = ws + self._white_v * row[6:9] + bs
