"""Sweep flights for N thrown starts at once: the in-process ``sim`` flight
(:class:`pf_offboard.sim.flight.SimFlight`) mirrored on arrays.

What a scalar sweep flight does per control step, in the same order, for every flight together:
the mock autopilot's telemetry (truth plus the estimator's error, rounded to float32 as MAVLink
carries it, stamped in whole milliseconds), the app's estimator (NED -> ENU, the velocity
correction), the controller (:class:`~pf_offboard.sim.batch.follower.BatchFollower`), the encoder
(acceleration setpoints, tilt-from-gravity as the autopilot reports it, float32 on the wire), the
mock's OFFBOARD handling (the position hold before the first setpoint, then the acceleration
setpoints) and its dynamics (:class:`~pf_offboard.sim.batch.dynamics.BatchSimulator`); the
sweep's judge and the flight summary's figures as arrays. Rows come out as the scalar engine's.

Mirrored: the PX4 profile in every output mode (``rates``: the app's attitude loop per flight with
the scalar functions), engaged at once (``throw_engage_after_s`` 0, what sweeps fly), constant
wind. ArduPilot (GUIDED, every output mode) through the mock's own per-flight handling
(:mod:`pf_offboard.sim.batch.ardupilot`, chosen by :data:`OFFBOARD_HANDLING`), the dynamics still
batched. Anything else — kept logs,
the trajectory-tracking baseline, ``any_state`` feed-forward — is flown by the scalar engine
(:func:`supported` says why); so is any single flight that leaves the mirrored path (a command
that is not finite, an implausible estimator jump).
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard import frames
from pf_offboard.sim.batch.dynamics import ACCEL, ATTITUDE, POSITION, RATES, BatchSetpoint, BatchSimulator
from pf_offboard.sim.batch.follower import BatchFollower

Arr = NDArray[np.float64]


def _f32(a: Arr) -> Arr:
    """What a MAVLink float field carries back: the value rounded to float32."""
    return np.asarray(a, dtype=np.float64).astype(np.float32).astype(np.float64)


class _Setup:
    """The scalar objects of one group of flights (one config text, one FlightSettings)."""

    def __init__(self, config_yaml: str, settings: Any) -> None:
        from sitl_mock.dynamics import preset

        from pf_offboard.app.pipeline import fit_identification_to_output
        from pf_offboard.app.profiles import PROFILES
        from pf_offboard.app.settings import flight_settings_for
        from pf_offboard.config import load_config
        from pf_offboard.control import PathFollower, controller_from_config
        from pf_offboard.sim.flight import MAX_RATE_HZ

        with tempfile.TemporaryDirectory(prefix="pf-batch-") as tmp:
            p = Path(tmp) / "config.yaml"
            p.write_text(config_yaml, encoding="utf-8")
            config = load_config(p)
        self.config = config
        fs = flight_settings_for(config, output=settings.output_mode)
        self.flight = fs
        self.rate_hz = settings.rate_hz if settings.rate_hz is not None else min(fs.setpoint_rate_hz, MAX_RATE_HZ)
        self.dt_s = 1.0 / self.rate_hz
        self.follower = controller_from_config(config)
        self.is_follower = isinstance(self.follower, PathFollower)
        self.profile = PROFILES[settings.autopilot]
        fit_identification_to_output(self.follower, fs.output_mode, self.profile, fs.attitude_time_constant_s)
        self.vehicle = preset(settings.vehicle)
        self.settings = settings
        tilt_param = 1.0 if self.vehicle.accel_decouple else 0.0  # MPC_ACC_DECOUPLE as the mock reports it
        # the encoder's mapping: read from the autopilot where it reports one, else the profile's
        self.tilt_from_gravity = (self.profile.tilts_from_gravity(tilt_param) if self.profile.accel_tilt_param is not None
                                  else self.profile.accel_tilt_from_gravity)  # fmt: skip
        # the tilt limit flown (acceleration): min(config's, the autopilot's), as the mock reports it
        self.tilt_limit_deg: float | None = None
        if fs.output_mode == "acceleration" and self.profile.accel_tilt_limit_params:
            from sitl_mock.autopilot import tilt_limit_params

            self.tilt_limit_deg = self.profile.accel_tilt_limit_deg(tilt_limit_params(settings.autopilot, self.vehicle))
            if self.tilt_limit_deg is not None:
                self.follower.cap_tilt(self.tilt_limit_deg)
        # the encoder's hover thrust: the config's, else MPC_THR_HOVER as the mock reports it (float32)
        self.hover_thrust = fs.hover_thrust if fs.hover_thrust is not None else float(np.float32(self.vehicle.hover_thrust))

    def unsupported(self, logs: bool) -> str | None:
        if logs:
            return "kept logs"
        if self.settings.autopilot not in OFFBOARD_HANDLING:
            return f"autopilot {self.settings.autopilot}"
        if self.flight.output_mode not in ("acceleration", "attitude", "rates"):
            return f"output {self.flight.output_mode}"
        if not self.is_follower:
            return "the trajectory-tracking controller"
        if self.follower.feedforward != "on_path":
            return f"feedforward {self.follower.feedforward}"
        if not 20.0 <= self.rate_hz <= 250.0:
            return "rate out of range"
        return None


def supported(task: Any) -> str | None:
    """None when the batch engine flies ``task`` (a :class:`~pf_offboard.sweep.runner.FlightTask`),
    else what makes it a scalar flight."""
    try:
        return _Setup(task.config_yaml, task.settings).unsupported(task.logs_dir is not None)
    except Exception as exc:  # a broken config: the scalar engine reports it as its row
        return f"{type(exc).__name__}"


def _tilt_from_gravity(ax: Arr, ay: Arr, az: Arr) -> tuple[Arr, Arr, Arr]:
    """:func:`pf_offboard.app.encoders.tilt_from_gravity_setpoint`."""
    from pf_offboard.app.encoders import _TILT_FROM_GRAVITY_FLOOR, G_M_S2

    scale = 1.0 / (np.maximum(G_M_S2 + az, _TILT_FROM_GRAVITY_FLOOR * G_M_S2) / G_M_S2)
    return ax * scale, ay * scale, az


def _norm_rows(q: Arr) -> Arr:
    """``np.linalg.norm`` of each row, as the scalar code computes it (a BLAS dot: no vectorised
    sum rounds the same)."""
    return np.array([float(np.linalg.norm(row)) for row in q])


def _attitude_setpoint(setup: _Setup, cmd: Any, n: int) -> BatchSetpoint:
    """``attitude`` output: the encoder's SET_ATTITUDE_TARGET (NED/FRD quaternion, the body rates
    the profile honours, normalised thrust; float32 on the wire) and the mock's PX4 handling of it
    (``px4_attitude_target``: the quaternion normalised, the yaw rate as feed-forward)."""
    from pf_offboard.app.encoders import G_M_S2

    # frames.quat_enu_flu_to_ned_frd: two fixed half-turns, then _canonical (norm, w >= 0)
    a = np.asarray(frames._Q_NED_FROM_ENU, dtype=float)
    b = np.asarray(frames._Q_FLU_FROM_FRD, dtype=float)
    q = cmd.attitude.T
    w0, x0, y0, z0 = a
    w1, x1, y1, z1 = q
    m = np.array((w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1, w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
                  w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1, w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1))  # fmt: skip
    w0, x0, y0, z0 = m
    w1, x1, y1, z1 = b
    m = np.array((w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1, w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
                  w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1, w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1))  # fmt: skip
    m = m / _norm_rows(m.T)
    m = np.where(m[0] < 0.0, -m, m)
    q_wire = _f32(m)
    # body rates FLU -> FRD; PX4 honours the yaw rate only (profile.attitude_rates_ff)
    rates = np.array((cmd.body_rates[:, 0], -cmd.body_rates[:, 1], -cmd.body_rates[:, 2]))
    used = setup.profile.attitude_rates_ff
    sent = _f32(np.array([rates[i] if used[i] else np.zeros(n) for i in range(3)]))
    thrust = cmd.thrust / G_M_S2 * setup.hover_thrust
    thrust = _f32(np.minimum(1.0, np.maximum(0.0, thrust)))
    # the mock: thrust clipped, the quaternion normalised, the yaw rate as feed-forward when not 0
    thrust = np.minimum(np.maximum(thrust, 0.0), 1.0)
    qn = q_wire / _norm_rows(q_wire.T)
    yaw_rate = sent[2] if used[2] else np.zeros(n)
    has_ff = yaw_rate != 0.0
    ff = np.array((np.zeros(n), np.zeros(n), yaw_rate))
    return BatchSetpoint(np.full(n, ATTITUDE, dtype=np.int64), np.zeros((3, n)), np.full(n, math.nan), np.zeros(n), qn, thrust, ff,
                         has_ff)  # fmt: skip


def _estimated_attitude(q_ned_frd: Arr) -> list[Any]:
    """The app's estimator's attitude per flight (its own functions, row by row: exact)."""
    from pf_offboard.app.estimator import _unit_quat

    out = []
    for row in q_ned_frd.T:
        q = _unit_quat(row)
        out.append(None if q is None else frames.quat_ned_frd_to_enu_flu(q))
    return out


def _rates_setpoint(setup: _Setup, cmd: Any, n: int, q_est: list[Any], t_est: float) -> BatchSetpoint:
    """``rates`` output: the encoder's own attitude loop (the pipeline's rates output, an
    :class:`~pf_offboard.control.AttitudeTracker` per flight: the scalar code, exact), the thrust
    along the current body z, float32 on the wire; the mock's PX4 handling (a rate setpoint)."""
    from pf_offboard.app.encoders import _THRUST_PROJECTION_FLOOR, body_z, thrust_normalised
    from pf_offboard.app.pipeline import rates_output_for
    from pf_offboard.control.attitude import AttitudeRateLaw

    if not hasattr(setup, "rate_outputs"):  # one per flight from its first active step (the pipeline resets it at activation)
        law = AttitudeRateLaw(setup.flight.attitude_time_constant_s)
        setup.rate_outputs = [rates_output_for(setup.follower, setup.profile, law) for _ in range(n)]  # type: ignore[attr-defined]
    rates = np.zeros((3, n))
    thrust = np.zeros(n)
    for i in range(n):
        q = q_est[i]
        if q is None:  # never in a mirrored flight: the scalar encoder would hold
            raise FloatingPointError("no attitude estimate")
        q_des = cmd.attitude[i]
        r = setup.rate_outputs[i].update(q_des, q, cmd.body_rates[i], time_s=t_est)
        projection = float(np.dot(body_z(q_des), body_z(q)))
        thrust[i] = thrust_normalised(float(cmd.thrust[i]) * max(projection, _THRUST_PROJECTION_FLOOR), setup.hover_thrust)
        frd = frames.flu_to_frd(r)
        rates[:, i] = (float(frd[0]), float(frd[1]), float(frd[2]))
    rates = _f32(rates)
    thrust = np.minimum(np.maximum(_f32(thrust), 0.0), 1.0)
    ident = np.tile([[1.0], [0.0], [0.0], [0.0]], n)
    return BatchSetpoint(np.full(n, RATES, dtype=np.int64), np.zeros((3, n)), np.full(n, math.nan), np.zeros(n), ident, thrust, rates,
                         np.zeros(n, dtype=bool))  # fmt: skip


def _wrap_pi(a: Arr) -> Arr:
    r = np.fmod(a + math.pi, 2.0 * math.pi)
    return np.where(r <= 0.0, r + 2.0 * math.pi, r) - math.pi


def fly(tasks: Sequence[Any], trace: list[Arr] | None = None,
        followers: list[BatchFollower] | None = None) -> tuple[dict[tuple[int, int], dict[str, Any]], list[Any]]:  # fmt: skip
    """Fly tasks that share their settings and their config but for its gains, all at once.

    Returns (rows by task key, the tasks the scalar engine must fly: flights that left the
    mirrored path). ``trace``: gets the true positions (3, N) NED after every step; ``followers``:
    the batch follower (its state after the flights)."""
    from pf_offboard.sweep.rows import finish_row

    setup = _Setup(tasks[0].config_yaml, tasks[0].settings)
    why = setup.unsupported(False)
    if why is not None:
        raise ValueError(f"the batch engine does not fly {why}")
    s = setup.settings
    n = len(tasks)
    texts = {t.config_yaml for t in tasks}
    per_flight = None
    if len(texts) > 1:  # a gain sweep: the same config but for its gains (group_key): one law each
        from pf_offboard.config import parse_config_bytes
        from pf_offboard.control.law import ControlLaw

        laws = {}
        for text in texts:
            cfg = parse_config_bytes(text.encode("utf-8"))
            limits = cfg.limits if setup.tilt_limit_deg is None else cfg.limits.with_tilt_at_most(setup.tilt_limit_deg)
            laws[text] = ControlLaw(cfg.gains, limits)  # as the follower's (cap_tilt)
        per_flight = [laws[t.config_yaml] for t in tasks]
    dt = setup.dt_s
    # ---- spawns, as SimFlight._make_autopilot builds them
    pos, vel, q, w, wind, rngs = [], [], [], [], [], []
    for t in tasks:
        st = t.start
        pos.append(tuple(map(float, frames.enu_to_ned(st.position_enu_m))))
        vel.append(tuple(map(float, frames.enu_to_ned(st.velocity_enu_m_s))))
        q.append(tuple(map(float, frames.quat_enu_flu_to_ned_frd(st.q_enu_flu))))
        w.append(tuple(map(float, frames.flu_to_frd(st.body_rates_flu_rad_s))))
        wind.append(tuple(map(float, frames.enu_to_ned(st.wind_enu_m_s))))
        rngs.append(np.random.default_rng(st.sim_seed).spawn(2)[0])  # Autopilot: (dynamics, faults)
    P, Vv, Q, W = np.array(pos).T, np.array(vel).T, np.array(q).T, np.array(w).T
    sim = BatchSimulator(setup.vehicle, rngs, P, Vv, Q, W, wind_ned_m_s=np.array(wind).T)
    # the OFFBOARD entry at the first step: hold the stopping point (estimate = truth at t = 0)
    speed = np.array([float(np.linalg.norm(Vv[:, i])) for i in range(n)])
    hold = P + Vv * speed / (2.0 * 3.0)
    qn = Q / np.sqrt(np.sum(Q * Q, axis=0))
    hold_yaw = np.array([math.atan2(2.0 * (a * d + b * c), 1.0 - 2.0 * (c * c + d * d)) for a, b, c, d in qn.T.tolist()])
    follower = BatchFollower(setup.follower, n, per_flight)
    if followers is not None:
        followers.append(follower)
    duration = s.duration_s
    max_steps = int(math.ceil(duration / dt)) + 1
    with np.errstate(all="ignore"):
        return _loop(tasks, setup, sim, follower, hold, hold_yaw, n, dt, max_steps, finish_row, trace)


def _loop(tasks: Sequence[Any], setup: _Setup, sim: BatchSimulator, follower: BatchFollower, hold: Arr, hold_yaw: Arr, n: int,
          dt: float, max_steps: int, finish_row: Any, trace: list[Arr] | None) -> tuple[dict[tuple[int, int], dict[str, Any]], list[Any]]:  # fmt: skip
    from pf_offboard.app.estimator import (MAX_ACCEL_M_S2, VELOCITY_CORRECTION_GAP_S, VELOCITY_CORRECTION_MAX_M_S, VELOCITY_MARGIN_M_S,
                                           VELOCITY_RESIDUAL_MAX_M_S)  # fmt: skip

    s = setup.settings
    timed = follower.compensator is not None
    profiled = follower.profile is not None
    speed_ref = float(setup.follower.speed)
    tau = setup.flight.velocity_correction_for(setup.profile)
    bias = np.zeros((3, n))
    prev: tuple[float, Arr, Arr] | None = None
    nan = math.nan
    tube, stay = s.tube_m, s.stay_m
    tol = s.speed_tol_m_s if s.speed_tol_m_s is not None else math.inf
    act = np.full(n, nan)
    conv = np.full(n, nan)
    last_out = np.full(n, nan)
    first = np.full(n, nan)
    max_out = np.zeros(n)
    max_after = np.zeros(n)
    sum2 = np.zeros(n)
    cnt = np.zeros(n, dtype=np.int64)
    ct_max = np.full(n, -math.inf)
    ct_any = np.zeros(n, dtype=bool)
    alive = np.ones(n, dtype=bool)
    fallback = np.zeros(n, dtype=bool)
    reason = [""] * n
    end_t = np.zeros(n)
    crashed_end = np.zeros(n, dtype=bool)
    duration = s.duration_s
    ident = np.tile([[1.0], [0.0], [0.0], [0.0]], n)
    zeros3 = np.zeros((3, n))
    false = np.zeros(n, dtype=bool)
    q_est: list[Any] = []
    handling = OFFBOARD_HANDLING[setup.settings.autopilot]
    per_flight = handling(setup, n) if handling is not None else None  # the autopilot's own OFFBOARD handling, per flight
    for i in range(max_steps):
        t_ap = sim.time_s
        # ---- telemetry: LOCAL_POSITION_NED (truth + estimator error, float32, whole ms)
        ep, ev = sim.estimate_error()
        p_ned = _f32(np.array((sim.px, sim.py, sim.pz)) + ep)
        v_ned = _f32(np.array((sim.vx, sim.vy, sim.vz)) + ev)
        t_est = (int((t_ap + 0.0) * 1000.0) & 0xFFFFFFFF) * 1e-3
        # ---- the app's estimator
        if prev is not None:
            dts = t_est - prev[0]
            allowed = 1.0 + (np.maximum(np.sqrt(np.sum(prev[2] ** 2, axis=0)), np.sqrt(np.sum(v_ned**2, axis=0))) + 5.0) * max(dts, 0.0)
            jump = np.sqrt(np.sum((p_ned - prev[1]) ** 2, axis=0)) > 0.5 * allowed
            # its velocity bound too (a crash stops the vehicle within one sample): the estimate's
            # previous velocity carries the correction (<= VELOCITY_CORRECTION_MAX_M_S), the raw one not
            dv = np.sqrt(np.sum((v_ned - prev[2]) ** 2, axis=0))
            jump |= dv > 0.5 * (VELOCITY_MARGIN_M_S + MAX_ACCEL_M_S2 * max(dts, 0.0)) - VELOCITY_CORRECTION_MAX_M_S
            fallback |= alive & jump  # near the estimator's plausibility bound: fly it scalar
        if tau is not None:
            if prev is not None and 0.0 < t_est - prev[0] <= VELOCITY_CORRECTION_GAP_S:
                dts = t_est - prev[0]
                residual = (p_ned - prev[1]) / dts - 0.5 * (v_ned + prev[2])
                residual = np.clip(residual, -VELOCITY_RESIDUAL_MAX_M_S, VELOCITY_RESIDUAL_MAX_M_S)
                out = bias + (1.0 - math.exp(-dts / tau)) * (residual - bias)
                rough = np.sqrt(np.sum(out * out, axis=0))
                for k in np.flatnonzero(rough > 0.99 * VELOCITY_CORRECTION_MAX_M_S).tolist():
                    norm = float(np.linalg.norm(out[:, k]))
                    if norm > VELOCITY_CORRECTION_MAX_M_S:
                        out[:, k] = out[:, k] * (VELOCITY_CORRECTION_MAX_M_S / norm)
                bias = out
            v_used = v_ned + bias
        else:
            v_used = v_ned
        prev = (t_est, p_ned, v_ned)
        if setup.flight.output_mode == "rates" or per_flight is not None:  # ATTITUDE_QUATERNION (truth, float32) -> the estimator's q (FLU -> ENU)
            q_est = _estimated_attitude(_f32(np.array((sim.qw, sim.qx, sim.qy, sim.qz))))
        y_enu = np.stack((p_ned[1], p_ned[0], -p_ned[2]), axis=1)
        v_enu = np.stack((v_used[1], v_used[0], -v_used[2]), axis=1)
        # ---- the pipeline: active from the second sample on (the first is the engage step)
        active = i > 0
        if active and i == 1 and timed:
            follower.reset()
        if active and i == 1:  # the pipeline's activation: YawSpec.hold takes each flight's heading
            from pf_offboard.app.encoders import yaw_of

            q_now = q_est or _estimated_attitude(_f32(np.array((sim.qw, sim.qx, sim.qy, sim.qz))))
            follower.hold_heading(np.array([math.nan if q is None else yaw_of(q) for q in q_now]))
        cmd = follower.update(y_enu, v_enu, t_est if timed else None)
        fallback |= alive & ~cmd.finite
        if active:
            # ---- the judge and the summary (active records only)
            tt = t_est
            act = np.where(alive & np.isnan(act), tt, act)
            ct = cmd.cross_track_m
            fin = np.isfinite(ct)
            upd = alive & fin
            ct_max = np.where(upd, np.maximum(ct_max, np.where(fin, ct, -math.inf)), ct_max)
            ct_any |= upd
            out_ = alive & ~(ct <= stay)
            last_out = np.where(out_, tt, last_out)
            had = out_ & ~np.isnan(first)
            max_out = np.where(had, np.maximum(max_out, np.where(fin, ct, math.inf)), max_out)
            conv = np.where(out_, nan, conv)
            max_after = np.where(out_, 0.0, max_after)
            sum2 = np.where(out_, 0.0, sum2)
            cnt = np.where(out_, 0, cnt)
            inn = alive & ~out_
            # the reference the pipeline logs: the law's (profile, start ramp) when the scalar
            # follower ramps, else the profile's or the constant speed
            ref = cmd.eta2_ref_m_s if (profiled or follower._ramp is not None) else speed_ref
            start = inn & np.isnan(conv) & (ct <= tube) & (np.abs(cmd.eta2 - ref) <= tol)
            conv = np.where(start, tt, conv)
            first = np.where(start & np.isnan(first), tt, first)
            acc_ = inn & ~np.isnan(conv)
            max_after = np.where(acc_, np.maximum(max_after, ct), max_after)
            sum2 = np.where(acc_, sum2 + ct * ct, sum2)
            cnt = np.where(acc_, cnt + 1, cnt)
        # ---- end of the flight (SimFlight._end_reason), after the step's record
        if t_ap >= duration - 1e-9:
            for k in np.flatnonzero(alive).tolist():
                reason[k] = f"duration {duration:g} s reached"
            end_t[alive] = t_ap
            crashed_end[alive] = sim.crashed[alive]
            alive[:] = False
        else:
            c = alive & sim.crashed
            g = alive & ~sim.crashed & sim.landed & (t_ap > 0.0)
            for k in np.flatnonzero(c).tolist():
                reason[k] = "crashed"
            for k in np.flatnonzero(g).tolist():
                reason[k] = "on the ground"
            ended = c | g
            end_t[ended] = t_ap
            crashed_end[ended] = sim.crashed[ended]
            alive &= ~ended
        if not alive.any():
            break
        # ---- the encoder and the mock's OFFBOARD handling
        if per_flight is not None:
            sp = _per_flight_setpoint(per_flight, i, cmd, y_enu, v_enu, q_est, t_est, t_ap, dt, sim, alive)
        elif i == 0:  # no setpoint taken yet: the position hold at the stopping point
            sp = BatchSetpoint(np.full(n, POSITION, dtype=np.int64), zeros3, hold_yaw, np.zeros(n), ident, np.zeros(n), zeros3, false,
                               hold, zeros3)  # fmt: skip
        elif setup.flight.output_mode == "attitude":
            sp = _attitude_setpoint(setup, cmd, n)
        elif setup.flight.output_mode == "rates":
            sp = _rates_setpoint(setup, cmd, n, q_est, t_est)
        else:
            a = cmd.acceleration
            ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
            if setup.tilt_from_gravity:
                ax, ay, az = _tilt_from_gravity(ax, ay, az)
            acc_ned = _f32(np.array((ay, ax, -az)))
            yaw_ned = _f32(_wrap_pi(math.pi / 2.0 - cmd.yaw))
            yaw_rate_ned = _f32(-cmd.yaw_rate)
            sp = BatchSetpoint(np.full(n, ACCEL, dtype=np.int64), acc_ned, yaw_ned, yaw_rate_ned, ident, np.zeros(n), zeros3, false)
        sim.advance(dt, sp)
        if trace is not None:
            trace.append(np.array((sim.px, sim.py, sim.pz)))
    else:
        for k in np.flatnonzero(alive).tolist():
            reason[k] = f"time limit {max_steps * dt:.0f} s reached"
    rows: dict[tuple[int, int], dict[str, Any]] = {}
    redo = []
    for k, task in enumerate(tasks):
        if fallback[k]:
            redo.append(task)
            continue
        row = task.first_columns()

        def opt(a: Arr) -> float | None:
            return None if math.isnan(float(a[k])) else float(a[k])

        rms = math.sqrt(sum2[k] / cnt[k]) if cnt[k] else math.nan
        rows[task.key] = finish_row(row, s, reason[k], bool(crashed_end[k]), float(end_t[k]),
                                    float(ct_max[k]) if ct_any[k] else None, opt(act), opt(conv), opt(first), opt(last_out),
                                    float(max_out[k]), float(max_after[k]), rms)  # fmt: skip
    return rows, redo


def _per_flight_setpoint(handling: Any, i: int, cmd: Any, y_enu: Arr, v_enu: Arr, q_est: list[Any], t_est: float, t_ap: float,
                         dt: float, sim: BatchSimulator, alive: Any) -> BatchSetpoint:  # fmt: skip
    """An autopilot handled per flight (:mod:`pf_offboard.sim.batch.ardupilot`): its estimate
    (truth + the estimator's error, float64); the app's setpoints from the second step on (the
    first flies the GUIDED state the throw spawned in, as the mock does)."""
    from pf_offboard.app.estimator import StateEstimate

    ep, ev = sim.estimate_error()
    pos = np.array((sim.px, sim.py, sim.pz)) + ep
    vel = np.array((sim.vx, sim.vy, sim.vz)) + ev
    q = np.array((sim.qw, sim.qx, sim.qy, sim.qz))
    est = [StateEstimate(t_est, y_enu[k], v_enu[k], q_est[k] if q_est else None, None, i + 1) for k in range(handling.n)]
    return handling.setpoint(cmd, est, int(t_est * 1000.0), t_ap, dt, pos, vel, q, sim.landed, alive, i > 0, ep)


def _ardupilot(setup: _Setup, n: int) -> Any:
    from pf_offboard.sim.batch.ardupilot import ArduPilotOffboard

    return ArduPilotOffboard(setup, n)


# The mock's OFFBOARD handling per autopilot profile: None = mirrored on arrays here (PX4), else
# a factory of the per-flight handling.
OFFBOARD_HANDLING: dict[str, Any] = {"px4": None, "ardupilot": _ardupilot}


# ---------------------------------------------------------------------------------- chunks
MAX_CHUNK = 2000  # flights stepped together in one process (memory ~ a few MB per 1000)
MIN_CHUNK = 50  # below this the per-step overhead of the arrays dominates


def group_key(task: Any) -> tuple[Any, str]:
    """Tasks with equal keys fly in one batch: the same settings and the same config but for its
    gains (a gain sweep's candidates share everything else)."""
    import yaml

    data = yaml.safe_load(task.config_yaml)
    if isinstance(data, dict):
        data.pop("gains", None)
    return (task.settings, yaml.safe_dump(data, sort_keys=True))


@dataclass(frozen=True)
class BatchChunk:
    """Flights the batch engine flies together (picklable: a process pool or a Dask worker runs it)."""

    key: tuple[int, int]
    tasks: tuple[Any, ...]


def plan_chunks(tasks: Sequence[Any], parts: int) -> tuple[list[BatchChunk], list[Any]]:
    """(chunks for the batch engine, tasks for the scalar one). Each group is split into about
    ``parts`` chunks (at least MIN_CHUNK flights each, at most MAX_CHUNK)."""
    groups: dict[tuple[Any, str], list[Any]] = {}
    scalar: list[Any] = []
    verdicts: dict[tuple[Any, str, bool], str | None] = {}
    keys: dict[str, str] = {}  # config text -> the text without its gains
    for t in tasks:
        if t.config_yaml not in keys:
            keys[t.config_yaml] = group_key(t)[1]
        gk = (t.settings, keys[t.config_yaml])
        vk = (*gk, t.logs_dir is not None)
        if vk not in verdicts:  # gains do not change what the batch engine mirrors
            verdicts[vk] = supported(t)
        if verdicts[vk] is not None:
            scalar.append(t)
        else:
            groups.setdefault(gk, []).append(t)
    chunks: list[BatchChunk] = []
    for members in groups.values():
        size = min(MAX_CHUNK, max(MIN_CHUNK, -(-len(members) // max(parts, 1))))
        for lo in range(0, len(members), size):
            part = tuple(members[lo : lo + size])
            chunks.append(BatchChunk((len(chunks), 0), part))
    return chunks, scalar


def run_chunk(chunk: BatchChunk) -> dict[str, Any]:
    """Fly a chunk: ``{"rows": [(task key, row), ...], "redo": [tasks for the scalar engine]}``.
    A chunk that fails as a whole hands all its flights to the scalar engine."""
    try:
        rows, redo = fly(chunk.tasks)
    except Exception:  # never lose flights: the scalar engine flies them (and reports its errors)
        return {"rows": [], "redo": list(chunk.tasks)}
    return {"rows": list(rows.items()), "redo": redo}
