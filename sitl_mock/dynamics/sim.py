"""The simulator: 6-DoF rigid-body quadrotor + the inner loops a PX4-like autopilot runs.

World NED, body FRD, quaternions (w, x, y, z) body→world (Hamilton).

Timing: physics, motors and the body-rate controller run at 1 kHz; the attitude controller (and
the acceleration mapping / position controller above it) at ``params.attitude_loop_hz``.
The hot loop is plain Python floats in local variables — a numpy call costs about a
microsecond, the whole 1 kHz step has a budget of a few.

External pushes (:meth:`Simulator.add_push`) add a specific force to the translation.

Integration (per 1 ms substep): motors — exact zero-order-hold discretisation of the first-order
lag; translation — exact solution of dv/dt = u − c·(v − w) for the substep's thrust + gravity u
and wind w (so free fall and ballistic flight, with or without drag, carry no integrator error
beyond rounding); rotation —
explicit midpoint (RK2) for Euler's equations and the exact rotation quaternion of the midpoint
rate, renormalised at every attitude tick.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from .estimator import EstimatorError
from .params import GRAVITY_M_S2, VehicleParams
from .types import (
    AccelerationSetpoint,
    AttitudeSetpoint,
    MotorsOff,
    PositionSetpoint,
    Push,
    RateSetpoint,
    SensorNoise,
    Setpoint,
    Spawn,
    VehicleState,
    Wind,
    Gust,
    _num,
    _ro,
)

PHYSICS_RATE_HZ = 1000
PHYSICS_DT_S = 1.0 / PHYSICS_RATE_HZ

_SETPOINT_TYPES = (AccelerationSetpoint, AttitudeSetpoint, RateSetpoint, PositionSetpoint, MotorsOff)


def quat_mul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    """Hamilton product a ⊗ b of (w, x, y, z) tuples."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def _dcm_to_quat(
    r00: float, r01: float, r02: float, r10: float, r11: float, r12: float, r20: float, r21: float, r22: float
) -> tuple[float, float, float, float]:
    """Rotation matrix (rows) → unit quaternion, numerically safe branch choice (Shepperd)."""
    tr = r00 + r11 + r22
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        return (0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
    if r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        return ((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
    if r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        return ((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
    s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
    return ((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)


def _yaw_of(qw: float, qx: float, qy: float, qz: float) -> float:
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


class Simulator:
    """Fixed-step quadrotor simulation. ``step(dt_s, setpoint)`` advances by ``dt_s`` in whole
    1 ms physics ticks (a fractional remainder is carried to the next call)."""

    def __init__(
        self,
        params: VehicleParams,
        rng: np.random.Generator,
        spawn: Spawn | None = None,
        wind: Wind | None = None,
        noise: SensorNoise | None = None,
    ) -> None:
        if not isinstance(params, VehicleParams):
            raise ValueError(f"Simulator.params: expected VehicleParams, got {type(params).__name__}")
        if not isinstance(rng, np.random.Generator):
            raise ValueError("Simulator.rng: expected a numpy.random.Generator (np.random.default_rng(seed))")
        spawn = spawn if spawn is not None else Spawn.ground()
        if not isinstance(spawn, Spawn):
            raise ValueError(f"Simulator.spawn: expected a Spawn, got {type(spawn).__name__}")
        self._params = params
        # Independent streams: how often measure() is called must not change the trajectory.
        self._rng_wind, self._rng_sensors = rng.spawn(2)
        # The estimator's stream is a third child, drawn only when it is on: presets without
        # estimator noise keep their trajectories bit for bit.
        self._est: EstimatorError | None = (
            EstimatorError(params.estimator, rng.spawn(1)[0]) if params.estimator.enabled else None
        )
        # Setpoint latency: setpoints take effect setpoint_latency_s after they are given; their
        # collective thrust thrust_latency_s after (a second queue when the two differ).
        self._latency_ticks = int(round(params.setpoint_latency_s * PHYSICS_RATE_HZ))
        thrust_latency_s = params.setpoint_latency_s if params.thrust_latency_s is None else params.thrust_latency_s
        self._thrust_latency_ticks = int(round(thrust_latency_s * PHYSICS_RATE_HZ))
        self._split_thrust = self._thrust_latency_ticks != self._latency_ticks
        self._pending_sp: deque[tuple[int, Setpoint]] = deque()
        self._pending_thrust: deque[tuple[int, Setpoint]] = deque()
        self._init_constants(params)
        self._ticks = 0
        self._t_req_s = 0.0
        p, v, q, w = spawn.position_ned_m, spawn.velocity_ned_m_s, spawn.q_ned_frd, spawn.rates_frd_rad_s
        t0 = self._m_weight_per_motor if spawn.motors_at_hover else 0.0
        on_ground = p[2] >= 0.0 and not spawn.motors_at_hover
        # Flat state: position, velocity, quaternion, rates, motor thrusts, rate integrators.
        self._x = [p[0], p[1], p[2], v[0], v[1], v[2], q[0], q[1], q[2], q[3], w[0], w[1], w[2],
                   t0, t0, t0, t0, 0.0, 0.0, 0.0]
        self._accel = (0.0, 0.0, 0.0)
        self._landed = on_ground
        self._crashed = False
        # Controller outputs held between attitude ticks: rate setpoint, per-motor collective (N).
        self._rs = (0.0, 0.0, 0.0, t0)
        self._motors_on = spawn.motors_at_hover
        self._countdown = 0
        self._rate_countdown = 0  # rate-loop ticks until the next motor-command update
        self._motor_cmd = (t0, t0, t0, t0)  # motor commands held between rate-loop ticks, N
        # Rate-loop output delay (sensing + actuator transport, in rate-loop ticks): a queue of the
        # commands not yet applied, pre-filled with the spawn's; None when there is no delay.
        n_delay = int(round(params.rate_loop_delay_s * params.rate_loop_hz))
        self._motor_delay_q: deque[tuple[float, float, float, float]] | None = (
            deque([(t0, t0, t0, t0)] * n_delay) if n_delay > 0 else None
        )
        self._q_sp = q
        self._thrust_sp = params.hover_thrust if spawn.motors_at_hover else 0.0
        self._setpoint: Setpoint = AccelerationSetpoint((0.0, 0.0, 0.0)) if spawn.motors_at_hover else MotorsOff()
        self._thrust_setpoint: Setpoint = self._setpoint  # whose collective is flown (split latency)
        self._sp_kind: type = type(self._setpoint)
        self._yaw_hold: float | None = None
        self._vel_int = [0.0, 0.0, 0.0]
        # Wind.
        self._wind = Wind()
        self._gusts: list[Gust] = []  # the Wind's gusts + those from add_gust
        self._added_gusts: list[Gust] = []
        self._turb = [0.0, 0.0, 0.0]
        self._normals: list[float] = []
        self._wind_now = (0.0, 0.0, 0.0)
        self.set_wind(wind if wind is not None else Wind())
        # External pushes (add_push): the specific force acting now, constant between boundaries.
        self._pushes: list[Push] = []
        self._push_now = (0.0, 0.0, 0.0)
        # Sensors.
        self._noise = noise if noise is not None else SensorNoise()
        if not isinstance(self._noise, SensorNoise):
            raise ValueError(f"Simulator.noise: expected SensorNoise, got {type(noise).__name__}")
        self._history: deque[VehicleState] = deque()
        if self._noise.delay_s > 0.0:
            self._history.append(self.state())

    # ------------------------------------------------------------------------------------------
    # Public API
    # ------------------------------------------------------------------------------------------

    @property
    def params(self) -> VehicleParams:
        """The vehicle's parameters. Assigning new ones (e.g. the autopilot's hover thrust after a
        PARAM_SET) takes effect at the next tick; the estimator and the setpoint latency keep the
        values they were built with."""
        return self._params

    @params.setter
    def params(self, params: VehicleParams) -> None:
        if not isinstance(params, VehicleParams):
            raise ValueError(f"Simulator.params: expected VehicleParams, got {type(params).__name__}")
        self._params = params
        self._init_constants(params)

    @property
    def time_s(self) -> float:
        return self._ticks * PHYSICS_DT_S

    def step(self, dt_s: float, setpoint: Setpoint) -> VehicleState:
        """Advance by ``dt_s`` under ``setpoint`` and return the true state."""
        self.advance(dt_s, setpoint)
        state = self.state()
        if self._noise.delay_s > 0.0:
            self._history.append(state)
            horizon = state.time_s - self._noise.delay_s - 1.0
            while len(self._history) > 2 and self._history[1].time_s <= horizon:
                self._history.popleft()
        return state

    def advance(self, dt_s: float, setpoint: Setpoint) -> None:
        """Like :meth:`step` without building the returned state (fastest)."""
        dt_s = _num("Simulator.step", "dt_s", dt_s, 0.0, 3600.0)
        if not isinstance(setpoint, _SETPOINT_TYPES):
            raise ValueError(f"Simulator.step.setpoint: unsupported setpoint {type(setpoint).__name__}")
        self._t_req_s += dt_s
        target = int(round(self._t_req_s * PHYSICS_RATE_HZ))
        if self._latency_ticks == 0 and not self._split_thrust:
            self._select(setpoint)
            if target > self._ticks:
                self._run_pushed(target - self._ticks)
        else:
            self._queue(self._ticks, setpoint)
            self._run_queued(target)
        if self._est is not None:
            self._est.advance_to(self._ticks * PHYSICS_DT_S)

    def _queue(self, given_tick: int, setpoint: Setpoint) -> None:
        self._pending_sp.append((given_tick + self._latency_ticks, setpoint))
        if self._split_thrust:
            self._pending_thrust.append((given_tick + self._thrust_latency_ticks, setpoint))

    def _run_queued(self, target: int) -> None:
        """Run to tick ``target``, adopting each queued setpoint (and thrust) when it is due."""
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
            self._run_pushed(stop - self._ticks)

    def prime(self, history: list[tuple[float, Setpoint]]) -> None:
        """Setpoints given *before* the simulation started, as (age_s > 0, setpoint), oldest first:
        each takes effect (or is already in effect) as if the simulation had been running, so a
        replay that starts mid-flight sees the setpoints still in the latency's pipe. Only before
        the first step."""
        if self._ticks or self._t_req_s or self._pending_sp or self._pending_thrust:
            raise ValueError("Simulator.prime: only before the first step")
        ages = [_num("Simulator.prime", "age_s", a, 1e-9, 3600.0) for a, _ in history]
        if any(b > a for a, b in zip(ages, ages[1:])):
            raise ValueError("Simulator.prime: history must be oldest first (ages not increasing)")
        for age, sp in zip(ages, (sp for _, sp in history)):
            if not isinstance(sp, _SETPOINT_TYPES):
                raise ValueError(f"Simulator.prime: unsupported setpoint {type(sp).__name__}")
            self._queue(-int(round(age * PHYSICS_RATE_HZ)), sp)
        self._run_queued(0)

    def lose_thrust(self, factor: float) -> None:
        """Every motor's full (and idle) thrust x ``factor`` from now on: a sagging battery, damaged
        propellers. The autopilot's hover-thrust parameter is not told: below 1 / thrust-to-weight
        the vehicle sinks whatever it is commanded. (Fault injection; :attr:`params` unchanged.)"""
        factor = _num("Simulator.lose_thrust", "factor", factor, 1e-6, 1.0)
        self._tmax *= factor
        self._tmin *= factor

    def estimate_error(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(position m, velocity m/s) error of the reported state, world NED: reported − true.
        Zero unless ``params.estimator`` is on (see :mod:`sitl_mock.dynamics.estimator`)."""
        if self._est is None:
            return ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        return (self._est.position_error_ned_m, self._est.velocity_error_ned_m_s)

    def state(self) -> VehicleState:
        """The current true state."""
        x = self._x
        qw, qx, qy, qz = x[6], x[7], x[8], x[9]
        ax, ay, az = self._accel
        # Accelerometer: specific force = R^T (a - g), in body FRD.
        sf = _rotate_to_body(qw, qx, qy, qz, ax, ay, az - GRAVITY_M_S2)
        # One read-only buffer, fields are views into it: ~3x cheaper than an array per field.
        buf = np.array(x[0:17] + [ax, ay, az, *sf, *self._q_sp, *self._rs[0:3], *self._wind_now])
        buf.setflags(write=False)
        return _state_from_fields({
            "time_s": self._ticks * PHYSICS_DT_S,
            "position_ned_m": buf[0:3],
            "velocity_ned_m_s": buf[3:6],
            "q_ned_frd": buf[6:10],
            "rates_frd_rad_s": buf[10:13],
            "motor_thrust_n": buf[13:17],
            "accel_ned_m_s2": buf[17:20],
            "specific_force_frd_m_s2": buf[20:23],
            "q_sp_ned_frd": buf[23:27],
            "rates_sp_frd_rad_s": buf[27:30],
            "wind_ned_m_s": buf[30:33],
            "landed": self._landed,
            "crashed": self._crashed,
            "thrust_norm_actual": (x[13] + x[14] + x[15] + x[16]) * self._inv_4tmax,
            "thrust_norm_sp": self._thrust_sp,
            "motors_on": self._motors_on,
        })

    def measure(self) -> VehicleState:
        """Telemetry as a sensor suite/estimator would report it: the state ``noise.delay_s`` ago
        (needs :meth:`step`, not :meth:`advance`, to record history) plus white noise."""
        nz = self._noise
        if nz.delay_s > 0.0 and self._history:
            target = self.time_s - nz.delay_s
            base = self._history[0]
            for s in self._history:
                if s.time_s <= target + 1e-9:
                    base = s
                else:
                    break
        else:
            base = self.state()
        rng = self._rng_sensors

        def noisy(a: np.ndarray, std: float) -> np.ndarray:
            return _ro(a + rng.normal(0.0, std, a.shape)) if std > 0.0 else a

        position, velocity = base.position_ned_m, base.velocity_ned_m_s
        if self._est is not None:  # the estimator's error (current, not delayed: it is slow)
            ep, ev = self.estimate_error()
            position, velocity = _ro(position + ep), _ro(velocity + ev)

        q = base.q_ned_frd
        if nz.attitude_std_rad > 0.0:
            e = rng.normal(0.0, nz.attitude_std_rad, 3)
            dq = (1.0, 0.5 * e[0], 0.5 * e[1], 0.5 * e[2])
            qn = np.array(quat_mul(tuple(q), dq))
            q = _ro(qn / np.linalg.norm(qn))
        return VehicleState(
            time_s=base.time_s,
            position_ned_m=noisy(position, nz.position_std_m),
            velocity_ned_m_s=noisy(velocity, nz.velocity_std_m_s),
            accel_ned_m_s2=noisy(base.accel_ned_m_s2, nz.accel_std_m_s2),
            q_ned_frd=q,
            rates_frd_rad_s=noisy(base.rates_frd_rad_s, nz.rates_std_rad_s),
            motor_thrust_n=base.motor_thrust_n,
            landed=base.landed,
            crashed=base.crashed,
            specific_force_frd_m_s2=noisy(base.specific_force_frd_m_s2, nz.accel_std_m_s2),
            thrust_norm_actual=base.thrust_norm_actual,
            thrust_norm_sp=base.thrust_norm_sp,
            q_sp_ned_frd=base.q_sp_ned_frd,
            rates_sp_frd_rad_s=base.rates_sp_frd_rad_s,
            motors_on=base.motors_on,
            wind_ned_m_s=base.wind_ned_m_s,
        )

    def set_wind(self, wind: Wind) -> None:
        """Replace the wind model (mean, gusts, turbulence). Gusts added before are kept."""
        if not isinstance(wind, Wind):
            raise ValueError(f"Simulator.set_wind.wind: expected Wind, got {type(wind).__name__}")
        self._wind = wind
        self._gusts = list(wind.gusts) + self._added_gusts
        self._update_wind()

    def add_gust(self, start_s: float, duration_s: float, velocity_ned_m_s: tuple[float, float, float]) -> None:
        """Schedule a (1 − cos) gust at simulated time ``start_s``."""
        gust = Gust(start_s, duration_s, velocity_ned_m_s)
        self._added_gusts.append(gust)
        self._gusts.append(gust)
        self._update_wind()

    def add_push(self, push: Push) -> None:
        """Schedule an external push (a constant specific force over a time window, see
        :class:`Push`). Its start and end are rounded to the 1 ms physics tick."""
        if not isinstance(push, Push):
            raise ValueError(f"Simulator.add_push.push: expected a Push, got {type(push).__name__}")
        self._pushes.append(push)

    # ------------------------------------------------------------------------------------------
    # Setup
    # ------------------------------------------------------------------------------------------

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
        # PX4 yaw weight: roll/pitch first. PX4 scales the yaw error by yaw_w and the yaw gain by
        # 1/yaw_w; we undo the error scaling instead (same linear law) so that the square-root
        # limiter below sees the true yaw error.
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

    def _update_wind(self) -> None:
        self._wind_dynamic = bool(self._gusts) or self._wind.turbulence_std_m_s > 0.0
        self._wind_now = self._wind_at(self.time_s)

    def _wind_at(self, t: float) -> tuple[float, float, float]:
        wx, wy, wz = self._wind.mean_ned_m_s
        for g in self._gusts:
            gx, gy, gz = g.at(t)
            wx += gx
            wy += gy
            wz += gz
        tb = self._turb
        return (wx + tb[0], wy + tb[1], wz + tb[2])

    def _advance_turbulence(self) -> None:
        w = self._wind
        if w.turbulence_std_m_s <= 0.0:
            return
        if len(self._normals) < 3:
            self._normals = self._rng_wind.standard_normal(3 * 512).tolist()
        phi = math.exp(-self._att_dt / w.turbulence_time_constant_s)
        k = w.turbulence_std_m_s * math.sqrt(1.0 - phi * phi)
        tb, nrm = self._turb, self._normals
        for i in range(3):
            tb[i] = phi * tb[i] + k * nrm.pop()

    def _select(self, sp: Setpoint) -> None:
        """Adopt a new setpoint; reset the state of controllers that (re)engage."""
        kind = type(sp)
        if kind is not self._sp_kind:
            if kind is not PositionSetpoint:
                self._vel_int = [0.0, 0.0, 0.0]
            if kind in (AttitudeSetpoint, RateSetpoint, MotorsOff):
                self._yaw_hold = None
            if self._sp_kind is MotorsOff:
                x = self._x
                x[17] = x[18] = x[19] = 0.0
            self._sp_kind = kind
        self._setpoint = sp
        self._motors_on = kind is not MotorsOff
        if kind is MotorsOff:
            self._rs = (0.0, 0.0, 0.0, 0.0)
            self._thrust_sp = 0.0
        elif kind is RateSetpoint:
            r = sp.rates_frd_rad_s  # type: ignore[union-attr]
            thrust = self._flown_thrust_setpoint().thrust_norm  # type: ignore[union-attr]
            self._rs = (r[0], r[1], r[2], thrust * self._tmax)
            self._thrust_sp = thrust

    def _flown_thrust_setpoint(self) -> Setpoint:
        """The setpoint whose collective thrust is flown: the thrust path's (split latency) when it
        holds the same kind as the attitude path's, else the attitude path's own."""
        tsp = self._thrust_setpoint
        return tsp if self._split_thrust and type(tsp) is self._sp_kind else self._setpoint

    def _select_thrust(self, sp: Setpoint) -> None:
        """Adopt a setpoint's collective thrust (split latency: it arrives before its attitude)."""
        self._thrust_setpoint = sp
        if self._sp_kind is RateSetpoint and type(sp) is RateSetpoint:
            rs = self._rs
            self._thrust_sp = sp.thrust_norm
            self._rs = (rs[0], rs[1], rs[2], sp.thrust_norm * self._tmax)

    # ------------------------------------------------------------------------------------------
    # Autopilot: position controller, acceleration mapping, attitude controller
    # ------------------------------------------------------------------------------------------

    def _control_tick(self, x: list[float]) -> tuple[float, float, float, float]:
        """Attitude-rate tick: returns (rate setpoint FRD rad/s ×3, per-motor collective N)."""
        sp = self._setpoint
        kind = self._sp_kind
        qw, qx, qy, qz = x[6], x[7], x[8], x[9]
        if kind is AccelerationSetpoint:
            yaw_rate_w = sp.yaw_rate_rad_s  # type: ignore[union-attr]
            yaw = sp.yaw_rad  # type: ignore[union-attr]
            if yaw is None:
                yaw = self._hold_yaw(yaw_rate_w, qw, qx, qy, qz)
            else:
                self._yaw_hold = None
            qd, thrust = self._accel_to_attitude(sp.accel_ned_m_s2, yaw)  # type: ignore[union-attr]
            tsp = self._flown_thrust_setpoint()
            if tsp is not sp:
                thrust = self._accel_to_attitude(tsp.accel_ned_m_s2, yaw)[1]  # type: ignore[union-attr]
            ff = None
        elif kind is AttitudeSetpoint:
            qd = sp.q_ned_frd  # type: ignore[union-attr]
            thrust = self._flown_thrust_setpoint().thrust_norm  # type: ignore[union-attr]
            ff = sp.rates_ff_frd_rad_s  # type: ignore[union-attr]
            yaw_rate_w = 0.0
        elif kind is PositionSetpoint:
            yaw = sp.yaw_rad  # type: ignore[union-attr]
            if yaw is None:
                yaw = self._hold_yaw(0.0, qw, qx, qy, qz)
            else:
                self._yaw_hold = None
            qd, thrust = self._accel_to_attitude(self._position_control(sp, x), yaw)  # type: ignore[arg-type]
            ff = None
            yaw_rate_w = 0.0
        else:  # RateSetpoint / MotorsOff: held values
            return self._rs
        self._q_sp = qd
        self._thrust_sp = thrust
        rx, ry, rz = self._attitude_control(qw, qx, qy, qz, qd, ff, yaw_rate_w)
        return (rx, ry, rz, thrust * self._tmax)

    def _hold_yaw(self, yaw_rate: float, qw: float, qx: float, qy: float, qz: float) -> float:
        """Yaw None: hold the heading latched when yaw control (re)started, advanced by the rate."""
        if self._yaw_hold is None:
            self._yaw_hold = _yaw_of(qw, qx, qy, qz)
        self._yaw_hold += yaw_rate * self._att_dt
        return self._yaw_hold

    def _position_control(self, sp: PositionSetpoint, x: list[float]) -> tuple[float, float, float]:
        """Cascaded P (position) → PI (velocity) → acceleration, like PX4's PositionControl."""
        pr = self.params
        tx, ty, tz = sp.position_ned_m
        fx, fy, fz = sp.velocity_ned_m_s
        px, py, pz, vx, vy, vz = x[0], x[1], x[2], x[3], x[4], x[5]
        kp = pr.position_p_1_s
        vsx = fx + kp * (tx - px)
        vsy = fy + kp * (ty - py)
        vh = math.hypot(vsx, vsy)
        if vh > pr.velocity_max_xy_m_s:
            s = pr.velocity_max_xy_m_s / vh
            vsx *= s
            vsy *= s
        if tz >= 0.0:  # target on or below the ground: land at the land speed
            vsz = pr.land_speed_m_s
        else:
            vsz = min(max(fz + kp * (tz - pz), -pr.velocity_max_up_m_s), pr.velocity_max_down_m_s)
        ex, ey, ez = vsx - vx, vsy - vy, vsz - vz
        vi = self._vel_int
        if not self._landed:
            ki, dt = pr.velocity_i_1_s2, self._att_dt
            lim = 0.5 * GRAVITY_M_S2
            vi[0] = min(max(vi[0] + ki * ex * dt, -lim), lim)
            vi[1] = min(max(vi[1] + ki * ey * dt, -lim), lim)
            vi[2] = min(max(vi[2] + ki * ez * dt, -lim), lim)
        kv = pr.velocity_p_1_s
        ax, ay, az = kv * ex + vi[0], kv * ey + vi[1], kv * ez + vi[2]
        ah_max = GRAVITY_M_S2 * math.tan(pr.tilt_max_rad)
        ah = math.hypot(ax, ay)
        if ah > ah_max:
            s = ah_max / ah
            ax *= s
            ay *= s
        return (ax, ay, az)

    def _accel_to_attitude(self, accel_ned: tuple[float, float, float], yaw: float
                           ) -> tuple[tuple[float, float, float, float], float]:
        """PX4 PositionControl::_accelerationControl + ControlMath::bodyzToAttitude."""
        ax, ay, az = accel_ned
        # Desired body z (down) axis in NED, unnormalised. PX4's MPC_ACC_DECOUPLE = 1 (default)
        # tilts as if the vertical demand were zero; the collective below still meets it exactly.
        bx, by, bz = -ax, -ay, GRAVITY_M_S2 if self._accel_decouple else GRAVITY_M_S2 - az
        n = math.sqrt(bx * bx + by * by + bz * bz)
        if n < 1e-6:
            bx, by, bz = 0.0, 0.0, 1.0
        else:
            bx, by, bz = bx / n, by / n, bz / n
        cos_tilt = self._cos_tilt_max
        if bz < cos_tilt:  # tilt limit (ControlMath::limitTilt)
            h = math.sqrt(bx * bx + by * by)
            if h > 1e-9:
                k = self._sin_tilt_max / h
                bx, by, bz = bx * k, by * k, cos_tilt
            else:
                bx, by, bz = self._sin_tilt_max, 0.0, cos_tilt
        # Collective: hover thrust scaled by the vertical demand over g, divided by cos(tilt).
        thrust = self._hover_thrust * (1.0 - az * self._inv_g) / bz
        if thrust < self._thr_min:
            thrust = self._thr_min
        elif thrust > self._thr_max:
            thrust = self._thr_max
        # body x = y_C × body_z with y_C = (-sin yaw, cos yaw, 0).
        cy, sy = math.cos(yaw), math.sin(yaw)
        xx, xy, xz = cy * bz, sy * bz, -sy * by - cy * bx
        nx = 1.0 / math.sqrt(xx * xx + xy * xy + xz * xz)
        xx, xy, xz = xx * nx, xy * nx, xz * nx
        yx, yy, yz = by * xz - bz * xy, bz * xx - bx * xz, bx * xy - by * xx
        return _dcm_to_quat(xx, yx, bx, xy, yy, by, xz, yz, bz), thrust

    def _attitude_control(self, qw: float, qx: float, qy: float, qz: float, qd: tuple[float, ...],
                          ff: tuple[float, float, float] | None, yaw_rate_w: float) -> tuple[float, float, float]:
        """PX4 AttitudeControl::update: tilt-prioritised quaternion P control + body-rate
        feed-forward ``ff`` (FRD) + yaw-rate feed-forward ``yaw_rate_w`` about world z."""
        ffx, ffy, ffz = ff if ff is not None else (0.0, 0.0, 0.0)
        dw, dx, dy, dz = qd
        # Body z axes (third columns of R) of the current and the desired attitude.
        ezx, ezy, ezz = 2.0 * (qx * qz + qw * qy), 2.0 * (qy * qz - qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy)
        edx, edy, edz = 2.0 * (dx * dz + dw * dy), 2.0 * (dy * dz - dw * dx), 1.0 - 2.0 * (dx * dx + dy * dy)
        yaw_w = self._yaw_w
        if yaw_w < 1.0:
            dot = ezx * edx + ezy * edy + ezz * edz
            crx, cry, crz = ezy * edz - ezz * edy, ezz * edx - ezx * edz, ezx * edy - ezy * edx
            rw = 1.0 + dot
            nr = math.sqrt(rw * rw + crx * crx + cry * cry + crz * crz)
            if nr < 1e-9 or rw / nr < 1e-5:
                rw, rx, ry, rz = dw, dx, dy, dz  # thrust axes opposite: full attitude control
            else:
                nr = 1.0 / nr
                aw, ax, ay, az = rw * nr, crx * nr, cry * nr, crz * nr
                # qr = a ⊗ q (inlined Hamilton product)
                rw = aw * qw - ax * qx - ay * qy - az * qz
                rx = aw * qx + ax * qw + ay * qz - az * qy
                ry = aw * qy - ax * qz + ay * qw + az * qx
                rz = aw * qz + ax * qy - ay * qx + az * qw
            # q_mix = qr^-1 ⊗ qd: the remaining rotation about body z.
            mw = rw * dw + rx * dx + ry * dy + rz * dz
            mz = rw * dz - rx * dy + ry * dx - rz * dw
            if mw < 0.0:
                mw, mz = -mw, -mz
            if mw > 1.0:
                mw = 1.0
            if mz > 1.0:
                mz = 1.0
            elif mz < -1.0:
                mz = -1.0
            cw, cz = math.cos(yaw_w * math.acos(mw)), math.sin(yaw_w * math.asin(mz))
            # qd = qr ⊗ (cw, 0, 0, cz)
            dw, dx, dy, dz = rw * cw - rz * cz, rx * cw + ry * cz, ry * cw - rx * cz, rw * cz + rz * cw
        # qe = q^-1 ⊗ qd; error vector 2·sign(w)·imag.
        ew = qw * dw + qx * dx + qy * dy + qz * dz
        ex = qw * dx - qx * dw - qy * dz + qz * dy
        ey = qw * dy + qx * dz - qy * dw - qz * dx
        ez = qw * dz - qx * dy + qy * dx - qz * dw
        s = 2.0 if ew >= 0.0 else -2.0
        kx, ky, kz = self._k_att
        ex, ey, ez = s * ex, s * ey, s * ez * self._yaw_err_scale
        amx, amz = self._att_accel_max
        # Yaw-rate feed-forward about WORLD z, expressed in body (third row of R).
        # Roll/pitch: the square-root law acts on the tilt error's magnitude, so a diagonal
        # error brakes in time too (the motors' roll/pitch authority is shared).
        exy = math.sqrt(ex * ex + ey * ey)
        sxy = _p_or_sqrt(kx, amx, exy) / exy if exy > 1e-12 else kx
        rx_ = sxy * ex + ffx + yaw_rate_w * 2.0 * (qx * qz - qw * qy)
        ry_ = sxy * ey + ffy + yaw_rate_w * 2.0 * (qy * qz + qw * qx)
        rz_ = _p_or_sqrt(kz, amz, ez) + ffz + yaw_rate_w * (1.0 - 2.0 * (qx * qx + qy * qy))
        lx, ly, lz = self._rate_lim
        return (_clamp(rx_, lx), _clamp(ry_, ly), _clamp(rz_, lz))

    # ------------------------------------------------------------------------------------------
    # The 1 kHz loop
    # ------------------------------------------------------------------------------------------

    def _run_pushed(self, n: int) -> None:
        """``_run(n)`` in pieces over which the pushes' sum is constant (the hot loop reads it once)."""
        if not self._pushes:
            self._run(n)
            return
        end = self._ticks + n
        while self._ticks < end:
            tick = self._ticks
            fx = fy = fz = 0.0
            nxt = end
            for p in self._pushes:
                on = int(round(p.start_s * PHYSICS_RATE_HZ))
                off = int(round((p.start_s + p.duration_s) * PHYSICS_RATE_HZ))
                if on <= tick < off:
                    fx, fy, fz = fx + p.accel_ned_m_s2[0], fy + p.accel_ned_m_s2[1], fz + p.accel_ned_m_s2[2]
                for b in (on, off):
                    if tick < b < nxt:
                        nxt = b
            self._push_now = (fx, fy, fz)
            self._run(nxt - tick)
        self._push_now = (0.0, 0.0, 0.0)

    def _run(self, n: int) -> None:
        pr = self.params
        dt = PHYSICS_DT_S
        hdt = 0.5 * dt
        g = GRAVITY_M_S2
        inv_m = 1.0 / pr.mass_kg
        cd = pr.drag_1_s
        if cd > 0.0:
            ed = math.exp(-cd * dt)
            k1 = -math.expm1(-cd * dt) / cd  # (1 - e^{-c dt}) / c
            k2 = (dt - k1) / cd
        else:
            ed, k1, k2 = 1.0, dt, 0.5 * dt * dt
        jx, jy, jz = pr.inertia_xx_kg_m2, pr.inertia_yy_kg_m2, pr.inertia_zz_kg_m2
        ijx, ijy, ijz = 1.0 / jx, 1.0 / jy, 1.0 / jz
        gx_, gy_, gz_ = (jy - jz) / jx, (jz - jx) / jy, (jx - jy) / jz  # gyroscopic coefficients
        arm = self._a_arm
        km = pr.yaw_torque_per_thrust_m
        inv4a, inv4k = 1.0 / (4.0 * arm), 1.0 / (4.0 * km)
        rp, yw = pr.roll_pitch, pr.yaw
        # Desired torque in per-motor thrust units: J·(k_p·e + k_i·∫e)/(4a) (yaw: /(4k)), clipped
        # to what the motors can give; the motor command then leads it by (1 + k_d) against the
        # motors' present torque (motor-speed feedback), which shortens the motor lag.
        kpx, kpy, kpz = jx * rp.rate_p_1_s * inv4a, jy * rp.rate_p_1_s * inv4a, jz * yw.rate_p_1_s * inv4k
        kix, kiy, kiz = jx * rp.rate_i_1_s2 * inv4a, jy * rp.rate_i_1_s2 * inv4a, jz * yw.rate_i_1_s2 * inv4k
        ldx = ldy = 1.0 + rp.rate_d
        ldz = 1.0 + yw.rate_d
        kdx, kdy, kdz = rp.rate_d * inv4a, rp.rate_d * inv4a, yw.rate_d * inv4k
        tmax, tmin = self._tmax, self._tmin
        half = 0.5 * (tmax - tmin)
        # Integrator limits: the I term may use at most 20 % of the motor range.
        ilx = 0.2 * half / kix if kix > 0 else 0.0
        ily = 0.2 * half / kiy if kiy > 0 else 0.0
        ilz = 0.2 * half / kiz if kiz > 0 else 0.0
        am = self._alpha_motor
        lead_c = pr.thrust_lead
        crash_speed = pr.crash_speed_m_s
        mu = pr.ground_friction
        on = self._motors_on
        div = self._att_div
        countdown = self._countdown
        wind_dynamic = self._wind_dynamic
        wnx, wny, wnz = self._wind_now
        pux, puy, puz = self._push_now
        pushing = pux != 0.0 or puy != 0.0 or puz != 0.0
        crashed = self._crashed
        landed = self._landed
        rsx, rsy, rsz, cc = self._rs
        airmode = pr.airmode
        avail = half if airmode else min(max(cc - tmin, 0.0), half)
        x = self._x
        px, py, pz, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz, t0, t1, t2, t3, ix, iy, iz = x
        tqx = arm * (t1 + t2 - t0 - t3)
        tqy = arm * (t0 + t2 - t1 - t3)
        tqz = km * (t0 + t1 - t2 - t3)
        ticks = self._ticks
        ax = ay = az = 0.0
        rdiv = self._rate_div
        rdt = rdiv * dt
        rcount = self._rate_countdown if on else 0
        m0, m1, m2, m3 = self._motor_cmd
        delay_q = self._motor_delay_q
        for _ in range(n):
            if countdown <= 0:
                countdown = div
                nq = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
                qw, qx, qy, qz = qw * nq, qx * nq, qy * nq, qz * nq
                if on:
                    x[0:20] = (px, py, pz, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz, t0, t1, t2, t3, ix, iy, iz)
                    self._landed = landed
                    rsx, rsy, rsz, cc = self._control_tick(x)
                    if not airmode:
                        avail = cc - tmin if cc - tmin < half else half
                        if avail < 0.0:
                            avail = 0.0
                if wind_dynamic:
                    self._advance_turbulence()
                    wnx, wny, wnz = self._wind_at(ticks * dt)
            countdown -= 1
            ticks += 1
            if on:
                if rcount <= 0:
                    # Rate-loop tick (every tick at 1 kHz; held between ticks when slower).
                    rcount = rdiv
                    # Body-rate controller (P + I + motor-torque feedback) and mixer. Clamps are
                    # written out: a function call here costs more than the whole comparison.
                    ex, ey, ez = rsx - wx, rsy - wy, rsz - wz
                    ix += ex * rdt
                    iy += ey * rdt
                    iz += ez * rdt
                    if ix > ilx:
                        ix = ilx
                    elif ix < -ilx:
                        ix = -ilx
                    if iy > ily:
                        iy = ily
                    elif iy < -ily:
                        iy = -ily
                    if iz > ilz:
                        iz = ilz
                    elif iz < -ilz:
                        iz = -ilz
                    r = kpx * ex + kix * ix
                    if r > avail:
                        r = avail
                    elif r < -avail:
                        r = -avail
                    p = kpy * ey + kiy * iy
                    if p > avail:
                        p = avail
                    elif p < -avail:
                        p = -avail
                    yv = kpz * ez + kiz * iz
                    if yv > avail:
                        yv = avail
                    elif yv < -avail:
                        yv = -avail
                    r = ldx * r - kdx * tqx
                    p = ldy * p - kdy * tqy
                    yv = ldz * yv - kdz * tqz
                    rp0 = p - r
                    rp2 = r + p
                    a0 = rp0 if rp0 >= 0.0 else -rp0
                    a2 = rp2 if rp2 >= 0.0 else -rp2
                    mm = a0 if a0 > a2 else a2
                    if mm > half:  # roll/pitch alone saturate: scale them, keep their ratio
                        s = half / mm
                        rp0 *= s
                        rp2 *= s
                        a0 *= s
                        a2 *= s
                        mm = half
                    # Roll/pitch first: the collective may drop to make room at the top; at the bottom
                    # it rises (airmode) or roll/pitch shrink (PX4 default, airmode off).
                    # Collective, led against the motors' present mean thrust like the torques.
                    c = cc + lead_c * (cc - 0.25 * (t0 + t1 + t2 + t3)) if lead_c > 0.0 else cc
                    if c > tmax - mm:
                        c = tmax - mm
                    if c < tmin + mm and airmode:
                        c = tmin + mm
                    elif c < tmin + mm:
                        if c <= tmin:
                            c = tmin
                            rp0 = rp2 = a0 = a2 = mm = 0.0
                        else:
                            s = (c - tmin) / mm
                            rp0 *= s
                            rp2 *= s
                            a0 *= s
                            a2 *= s
                    yhi = tmax - c - a0
                    lim = c - a2 - tmin
                    if lim < yhi:
                        yhi = lim
                    ylo = tmin - c + a0
                    lim = c + a2 - tmax
                    if lim > ylo:
                        ylo = lim
                    if yv > yhi:
                        yv = yhi
                    elif yv < ylo:
                        yv = ylo
                    if delay_q is None:
                        m0 = c + rp0 + yv
                        m1 = c - rp0 + yv
                        m2 = c + rp2 - yv
                        m3 = c - rp2 - yv
                    else:  # the motors get the command computed rate_loop_delay ticks ago
                        delay_q.append((c + rp0 + yv, c - rp0 + yv, c + rp2 - yv, c - rp2 - yv))
                        m0, m1, m2, m3 = delay_q.popleft()
                rcount -= 1
                t0 += am * (m0 - t0)
                t1 += am * (m1 - t1)
                t2 += am * (m2 - t2)
                t3 += am * (m3 - t3)
            else:
                t0 -= am * t0
                t1 -= am * t1
                t2 -= am * t2
                t3 -= am * t3
            # Forces and torques of the motors (X: 0 FR ccw, 1 RL ccw, 2 FL cw, 3 RR cw).
            f = (t0 + t1 + t2 + t3) * inv_m
            tqx = arm * (t1 + t2 - t0 - t3)
            tqy = arm * (t0 + t2 - t1 - t3)
            tqz = km * (t0 + t1 - t2 - t3)
            c2x = 2.0 * (qx * qz + qw * qy)
            c2y = 2.0 * (qy * qz - qw * qx)
            c2z = 1.0 - 2.0 * (qx * qx + qy * qy)
            # Translation: exact for thrust, gravity and wind constant over the substep, with
            # linear drag on the air-relative velocity (dv/dt = u - c·(v - w)).
            ux = -f * c2x
            uy = -f * c2y
            uz = g - f * c2z
            if pushing:
                ux += pux
                uy += puy
                uz += puz
            rx_ = vx - wnx
            ry_ = vy - wny
            rz_ = vz - wnz
            ax = ux - cd * rx_
            ay = uy - cd * ry_
            az = uz - cd * rz_
            px += wnx * dt + rx_ * k1 + ux * k2
            py += wny * dt + ry_ * k1 + uy * k2
            pz += wnz * dt + rz_ * k1 + uz * k2
            vx = wnx + rx_ * ed + ux * k1
            vy = wny + ry_ * ed + uy * k1
            vz = wnz + rz_ * ed + uz * k1
            # Euler's equations, explicit midpoint.
            dx = tqx * ijx + gx_ * wy * wz
            dy = tqy * ijy + gy_ * wz * wx
            dz = tqz * ijz + gz_ * wx * wy
            mx = wx + hdt * dx
            my = wy + hdt * dy
            mz = wz + hdt * dz
            wx += dt * (tqx * ijx + gx_ * my * mz)
            wy += dt * (tqy * ijy + gy_ * mz * mx)
            wz += dt * (tqz * ijz + gz_ * mx * my)
            # q ← q ⊗ exp(ω_mid·dt/2), series to 4th order in the half angle.
            hx, hy, hz = mx * hdt, my * hdt, mz * hdt
            n2 = hx * hx + hy * hy + hz * hz
            cq = 1.0 - n2 * (0.5 - n2 * 0.041666666666666664)
            sq = 1.0 - n2 * (0.16666666666666666 - n2 * 0.008333333333333333)
            hx *= sq
            hy *= sq
            hz *= sq
            qw, qx, qy, qz = (
                qw * cq - qx * hx - qy * hy - qz * hz,
                qw * hx + qx * cq + qy * hz - qz * hy,
                qw * hy - qx * hz + qy * cq + qz * hx,
                qw * hz + qx * hy - qy * hx + qz * cq,
            )
            if pz >= 0.0:
                # Ground contact: no penetration; a hard touchdown is a crash.
                if vz > crash_speed:
                    crashed = True
                pz = 0.0
                if vz > 0.0:
                    vz = 0.0
                normal = uz  # specific normal force needed to stay on the ground
                if normal > 0.0:
                    landed = True
                    sh = math.sqrt(vx * vx + vy * vy)
                    dv = mu * normal * dt
                    if sh <= dv:
                        vx = vy = 0.0
                    else:
                        k = 1.0 - dv / sh
                        vx *= k
                        vy *= k
                    # Resting on its legs: level, not rotating, rate integrators reset.
                    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
                    qw, qx, qy, qz = math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)
                    wx = wy = wz = 0.0
                    ix = iy = iz = 0.0
                    ax = ay = az = 0.0
                else:
                    landed = False
            else:
                landed = False
        x[0:20] = (px, py, pz, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz, t0, t1, t2, t3, ix, iy, iz)
        self._accel = (ax, ay, az)
        self._ticks = ticks
        self._countdown = countdown
        self._rate_countdown = rcount
        self._motor_cmd = (m0, m1, m2, m3)
        self._rs = (rsx, rsy, rsz, cc)
        self._landed = landed
        self._crashed = crashed
        self._wind_now = (wnx, wny, wnz)


_STATE_FIELDS = frozenset(VehicleState.__dataclass_fields__)


def _state_from_fields(values: dict[str, object]) -> VehicleState:
    """Build a VehicleState without the frozen dataclass __init__ (one object.__setattr__ per
    field costs ~1.5 µs, which matters at 1 kHz). Every field must be given."""
    assert values.keys() == _STATE_FIELDS
    state = object.__new__(VehicleState)
    state.__dict__.update(values)
    return state


def _clamp(value: float, limit: float) -> float:
    """value limited to [-limit, limit]."""
    return limit if value > limit else -limit if value < -limit else value


def _p_or_sqrt(k: float, accel_max: float, e: float) -> float:
    """k·e, or ArduPilot's sqrt_controller: beyond e_lin = a/k² the output grows like
    sqrt(2·a·|e|) so that braking at angular acceleration a stops on the target."""
    if accel_max <= 0.0:
        return k * e
    e_lin = accel_max / (k * k)
    if e > e_lin:
        return math.sqrt(2.0 * accel_max * (e - 0.5 * e_lin))
    if e < -e_lin:
        return -math.sqrt(2.0 * accel_max * (-e - 0.5 * e_lin))
    return k * e


def _rotate_to_body(qw: float, qx: float, qy: float, qz: float, x: float, y: float, z: float
                    ) -> tuple[float, float, float]:
    """R(q)^T · v: a world NED vector in body FRD."""
    r00, r01, r02 = 1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)
    r10, r11, r12 = 2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)
    r20, r21, r22 = 2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)
    return (r00 * x + r10 * y + r20 * z, r01 * x + r11 * y + r21 * z, r02 * x + r12 * y + r22 * z)


__all__ = ["Simulator", "PHYSICS_RATE_HZ", "PHYSICS_DT_S", "quat_mul"]
