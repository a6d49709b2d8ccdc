"""Synthetic ``.tlog`` files with a known first-order vehicle, for identify's tests.

The "vehicle" obeys exactly the model identify fits (world ENU): ``dv/dt = gain · lag(delay(a_sp))
− drag · v + bias``, integrated at 1 kHz with the setpoint held; or (``tilt_coupled``) a thrust
vector: its horizontal part ``lag_xy(delay(a_sp,xy))``, its magnitude ``lag_z(delay(|a_sp + g e_z|))``,
so that the vertical acceleration is what that magnitude leaves after the tilt, and the log has
the attitude (ATTITUDE_QUATERNION) — identify's vertical model with the measured tilt. The log has
what a ``fly`` log has: the autopilot's HEARTBEAT (armed, OFFBOARD), LOCAL_POSITION_NED (NED, boot clock) and our
SET_POSITION_TARGET_LOCAL_NED acceleration setpoints (component 191), UNIX-stamped by a clock
that may run at ``clock_rate`` times the boot clock (a lockstep SITL is not real time).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from pf_offboard import frames
from pf_offboard.app.encoders import flown_when_tilting_from_gravity
from pf_offboard.control.types import GRAVITY_M_S2
from pf_offboard.logs.tlog import TlogWriter

EPOCH_UNIX_S = 1.7e9
G_M_S2 = GRAVITY_M_S2
PX4_OFFBOARD = 6 << 16


@dataclass(frozen=True)
class Truth:
    lag_xy_s: float = 0.12
    lag_z_s: float = 0.04
    delay_s: float = 0.03
    gain_xy: float = 0.9
    gain_z: float = 1.1
    drag_xy_1_s: float = 0.6
    drag_z_1_s: float = 0.4
    bias_enu_m_s2: tuple[float, float, float] = (0.05, -0.02, -0.3)


def write_tlog(
    path: Path,
    truth: Truth = Truth(),
    duration_s: float = 20.0,
    rate_hz: float = 100.0,
    amplitude_m_s2: float = 1.0,
    clock_rate: float = 1.0,
    seed: int = 0,
    setpoints: bool = True,
    offboard_from_s: float = 0.0,
    tilt_from_gravity: bool = False,
    tilt_coupled: bool = False,
) -> Path:
    """Write the log; the setpoint is random steps (dwell 0.2-0.8 s) of ``amplitude_m_s2`` with
    a soft velocity damping so the vehicle stays put.

    ``tilt_from_gravity``: the autopilot tilts from g alone (PX4's default mapping), so the vehicle
    answers ``a_xy (g + a_up) / g`` and the log says nothing of it; else it flies the setpoint as
    sent and the log holds its PARAM_VALUE MPC_ACC_DECOUPLE = 0 (as fly reads it).
    ``tilt_coupled``: the thrust-vector vehicle of the module docstring, its attitude logged."""
    rng = np.random.default_rng(seed)
    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    app = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    dt = 1.0 / rate_hz
    n = int(round(duration_s * rate_hz))
    lag = np.array([truth.lag_xy_s, truth.lag_xy_s, truth.lag_z_s])
    gain = np.array([truth.gain_xy, truth.gain_xy, truth.gain_z])
    drag = np.array([truth.drag_xy_1_s, truth.drag_xy_1_s, truth.drag_z_1_s])
    bias = np.array(truth.bias_enu_m_s2)
    v = np.zeros(3)
    p = np.array([0.0, 0.0, 5.0])  # ENU: the position integrates the velocity, as an estimator's does
    u = np.zeros(3)  # lag state
    m = G_M_S2  # tilt_coupled: the thrust magnitude's lag state (m/s^2)
    step = np.zeros(3)
    next_change = np.zeros(3)
    delay_steps = int(round(truth.delay_s * 1000))
    history = deque([np.zeros(3)] * (delay_steps + 1), maxlen=delay_steps + 2)  # 1 kHz setpoint history for the delay
    alpha = np.where(lag > 0, 1.0 - np.exp(-1e-3 / np.maximum(lag, 1e-9)), 1.0)  # the lag's per-millisecond factor
    path.parent.mkdir(parents=True, exist_ok=True)
    with TlogWriter.open(path) as log:
        def send(mav, msg, t_boot: float) -> None:
            log.write(msg.pack(mav), EPOCH_UNIX_S + clock_rate * t_boot)
            mav.seq = (mav.seq + 1) % 256

        if not tilt_from_gravity:
            send(ap, mavlink.MAVLink_param_value_message(b"MPC_ACC_DECOUPLE", 0.0, mavlink.MAV_PARAM_TYPE_INT32, 1, 0), 0.0)
        for k in range(n):
            t = k * dt
            if k % int(round(rate_hz / 10)) == 0:  # 10 Hz heartbeat
                mode = PX4_OFFBOARD if t >= offboard_from_s else (4 << 16)
                send(ap, mavlink.MAVLink_heartbeat_message(2, 12, 128 | 1, mode, 4, 3), t)
            v_ned, p_ned = frames.enu_to_ned(v), frames.enu_to_ned(p)
            send(ap, mavlink.MAVLink_local_position_ned_message(int(round(t * 1000)), *map(float, p_ned), *map(float, v_ned)), t)
            if tilt_coupled:
                q = frames.quat_enu_flu_to_ned_frd(_tilt_quaternion(thrust_axis(u, m)))
                send(ap, mavlink.MAVLink_attitude_quaternion_message(int(round(t * 1000)), *map(float, q), 0.0, 0.0, 0.0), t)
            for j in range(3):
                if t >= next_change[j]:
                    step[j] = amplitude_m_s2 * rng.uniform(-1.0, 1.0)
                    next_change[j] = t + rng.uniform(0.2, 0.8)
            a_sp = step - 0.5 * v
            if setpoints:
                a_ned = frames.enu_to_ned(a_sp)
                msg = mavlink.MAVLink_set_position_target_local_ned_message(
                    int(round(t * 1000)), 1, 1, 1, 0x03F, 0, 0, 0, 0, 0, 0, *map(float, a_ned), 0.0, 0.0)  # fmt: skip
                send(app, msg, t)
            asked = np.array(flown_when_tilting_from_gravity(a_sp)) if tilt_from_gravity else a_sp
            for _ in range(int(round(dt * 1000))):
                history.append(asked.copy())
                delayed = history[-1 - delay_steps]
                u = u + alpha * (delayed - u)
                response = u.copy()
                if tilt_coupled:
                    m += alpha[2] * (float(np.linalg.norm(delayed + (0.0, 0.0, G_M_S2))) - m)
                    response[2] = m * thrust_axis(u, m)[2] - G_M_S2
                p = p + 1e-3 * v
                v = v + 1e-3 * (gain * response - drag * v + bias)
    return path


def thrust_axis(u: np.ndarray, magnitude_m_s2: float) -> np.ndarray:
    """Unit thrust axis (world ENU) of the tilt-coupled vehicle: horizontal part u_xy of a thrust
    of ``magnitude_m_s2``."""
    h = np.array([u[0], u[1]]) / magnitude_m_s2
    return np.array([h[0], h[1], np.sqrt(max(1.0 - float(h @ h), 0.0))])


def _tilt_quaternion(axis_enu: np.ndarray) -> np.ndarray:
    """Body FLU -> world ENU quaternion (w, x, y, z) of the shortest rotation taking e_z onto ``axis_enu``."""
    c = np.cross((0.0, 0.0, 1.0), axis_enu)
    q = np.array([1.0 + axis_enu[2], *c])
    return q / np.linalg.norm(q)
