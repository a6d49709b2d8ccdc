"""The bare core API in a simulator written independently of sitl_mock: ``PathFollower(path,
speed)`` with ``update(p, v, time_s=t)`` flies a rigid-body quadrotor with rotor drag, a motor
lag and a first-order closed body-rate loop, through

- ``acceleration``: the simulator's own autopilot turns the commanded acceleration into an
  attitude (its own construction, not the core's) and tracks it with a P attitude loop;
- ``rates``: the core's default rates output (:class:`~pf_offboard.control.AttitudeTracker`
  ``.from_vehicle(VehicleModel.typical())``) closes the attitude loop and the simulator flies body
  rates. It identifies this rate loop (30 ms + 20 ms latency) as too slow for its attitude
  reference, so the attitude-rate law alone flies (the reference engaged here flew 9 cm once the
  follower identified a dead time).

Judged from the simulated truth: the distance to the path and the speed along it from the true
position's central difference (not from any velocity the controller saw). Nothing here was tuned
to this simulator: the follower is built with its defaults only.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from pf_offboard import Path, PathFollower
from pf_offboard.control import AttitudeTracker, VehicleModel
from pf_offboard.path import Projector

G = 9.81
DT_PHYS = 0.001
DT_CTRL = 0.01  # 100 Hz control
DRAG_BODY_1_S = np.array([0.35, 0.35, 0.1])  # rotor drag, body frame: -R D R^T (v - wind)
MOTOR_TAU_S = 0.03
RATE_TAU_S = 0.03  # the autopilot's closed body-rate loop
ATT_P_1_S = 7.0  # the simulator autopilot's attitude loop (acceleration mode)
LATENCY_S = 0.02  # setpoint transport latency


def _rot_from_quat(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def _quat_from_rot(r: np.ndarray) -> np.ndarray:
    tr = np.trace(r)
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k]) * 2
        q = [0.0] * 4
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    q = np.array(q)
    return q / np.linalg.norm(q)


def _attitude_for(accel_enu: np.ndarray, yaw: float) -> np.ndarray:
    """The simulator autopilot's own acceleration -> attitude (body z along a + g, heading yaw)."""
    f = accel_enu + np.array([0.0, 0.0, G])
    zb = f / np.linalg.norm(f)
    xc = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    yb = np.cross(zb, xc)
    yb /= np.linalg.norm(yb)
    return np.column_stack((np.cross(yb, zb), yb, zb))


def _vee(m: np.ndarray) -> np.ndarray:
    return np.array([m[2, 1], m[0, 2], m[1, 0]])


def fly(path: Path, speed: float, mode: str, seconds: float, wind=(0.0, 0.0, 0.0)):
    follower = PathFollower(path, speed)  # the defaults: nothing tuned for this simulator
    rate_output = AttitudeTracker.from_vehicle(VehicleModel.typical())  # the default rates output
    s0 = path.eval(0.0)
    p = np.array(s0.sigma, float)
    v = np.zeros(3)
    r = np.eye(3)
    w_body = np.zeros(3)
    thrust = G
    wind = np.asarray(wind, float)
    queue: list[tuple[float, np.ndarray, float]] = []  # (time active, rates command, thrust command)
    rates_cmd, thrust_cmd = np.zeros(3), G
    t = 0.0
    n_ctrl = int(round(DT_CTRL / DT_PHYS))
    log_t, log_p = [], []
    step = 0
    while t < seconds:
        if step % n_ctrl == 0:
            cmd = follower.update(p, v, time_s=t)
            if mode == "rates":
                q_meas = _quat_from_rot(r)
                rc = rate_output.update(cmd.attitude, q_meas, cmd.body_rates, time_s=t)
                queue.append((t + LATENCY_S, np.asarray(rc, float), float(cmd.thrust)))
            else:  # acceleration: the autopilot builds and tracks its own attitude
                queue.append((t + LATENCY_S, np.asarray(cmd.acceleration, float), float(cmd.yaw)))
            log_t.append(t)
            log_p.append(p.copy())
        while queue and queue[0][0] <= t + 1e-12:
            _, x, y = queue.pop(0)
            if mode == "rates":
                rates_cmd, thrust_cmd = x, y
            else:
                r_des = _attitude_for(x, y)
                e = 0.5 * _vee(r_des.T @ r - r.T @ r_des)
                f_des = x + np.array([0.0, 0.0, G])
                rates_cmd = -ATT_P_1_S * e
                thrust_cmd = float(f_des @ r[:, 2])  # thrust along the current body z
        # physics
        w_body += (rates_cmd - w_body) * (DT_PHYS / RATE_TAU_S)
        thrust += (thrust_cmd - thrust) * (DT_PHYS / MOTOR_TAU_S)
        wx = np.array([[0, -w_body[2], w_body[1]], [w_body[2], 0, -w_body[0]], [-w_body[1], w_body[0], 0]])
        r = r @ (np.eye(3) + wx * DT_PHYS + wx @ wx * (0.5 * DT_PHYS * DT_PHYS))
        u, _, vt = np.linalg.svd(r)
        r = u @ vt
        acc = r[:, 2] * thrust - np.array([0.0, 0.0, G]) - r @ (DRAG_BODY_1_S * (r.T @ (v - wind)))
        p = p + v * DT_PHYS + 0.5 * acc * DT_PHYS * DT_PHYS
        v = v + acc * DT_PHYS
        t += DT_PHYS
        step += 1
    return np.array(log_t), np.array(log_p)


def measure(path: Path, t: np.ndarray, p: np.ndarray, speed: float, settle_s: float):
    """(cross-track RMS m, speed error RMS m/s, mean speed error m/s) after settle_s, from the
    true positions (speed: central difference over +-0.1 s, along the path's tangent)."""
    proj = Projector(path)
    lam = np.array([proj.update(x) for x in p])
    sig = np.array([path.eval(float(x)).sigma for x in lam])
    d1 = np.array([path.eval(float(x)).d1 for x in lam])
    tan = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    k = int(round(0.1 / DT_CTRL))
    vel = (p[2 * k:] - p[:-2 * k]) / (t[2 * k:] - t[:-2 * k])[:, None]
    v_t = np.einsum("ij,ij->i", vel, tan[k:-k])
    ct = np.linalg.norm(p - sig, axis=1)[k:-k]
    win = t[k:-k] >= settle_s
    e = v_t[win] - speed
    return float(np.sqrt(np.mean(ct[win] ** 2))), float(np.sqrt(np.mean(e**2))), float(np.mean(e))


def figure_eight() -> Path:
    pts = []
    for i in range(12):
        u = 2 * math.pi * i / 12
        s = math.sin(u)
        pts.append([2.4 * math.cos(u) / (1 + s * s), 2.4 * math.sin(u) * math.cos(u) / (1 + s * s), 2.0 + 0.4 * math.sin(u)])
    return Path.from_waypoints(pts, closed=True)


@pytest.mark.parametrize("mode", ["acceleration", "rates"])
def test_defaults_follow_in_still_air(mode):
    path = figure_eight()
    t, p = fly(path, 1.5, mode, 22.0)
    ct, spd, mean = measure(path, t, p, 1.5, 8.0)
    print(f"{mode} still air: cross-track RMS {100 * ct:.2f} cm, speed error RMS {100 * spd:.2f} cm/s, mean {100 * mean:+.2f}")
    # measured: acceleration 0.26 cm, 0.85 cm/s (the dead time identified in flight, on by default;
    # 1.36 cm with identify_online=False: the typical model's 0.1 s against this simulator's ~0.03 s);
    # rates 0.96 cm, 1.8 cm/s
    assert ct <= 0.02 and spd <= 0.025


@pytest.mark.parametrize("mode", ["acceleration", "rates"])
def test_defaults_follow_in_a_3_m_s_wind(mode):
    path = figure_eight()
    t, p = fly(path, 1.5, mode, 25.0, wind=(3.0, 0.0, 0.0))
    ct, spd, mean = measure(path, t, p, 1.5, 10.0)
    print(f"{mode} 3 m/s wind: cross-track RMS {100 * ct:.2f} cm, speed error RMS {100 * spd:.2f} cm/s, mean {100 * mean:+.2f}")
    # measured: acceleration 0.49 cm, mean -0.3 cm/s (1.45 cm, +0.9 with identify_online=False);
    # rates 1.0 cm, +0.2 cm/s (the paper's law: -47 cm/s)
    assert ct <= 0.02 and abs(mean) <= 0.02


def test_the_papers_law_flies_slow_in_the_wind():
    """The same simulator and wind with the paper's law (no disturbance rejection): the drag in a
    3 m/s wind leaves a speed bias the default removes."""
    path = figure_eight()
    orig = PathFollower

    class Paper:
        def __new__(cls, p, s):  # noqa: D102
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return orig.paper(p, s)

    globals()["PathFollower"] = Paper
    try:
        t, p = fly(path, 1.5, "rates", 25.0, wind=(3.0, 0.0, 0.0))
    finally:
        globals()["PathFollower"] = orig
    ct, spd, mean = measure(path, t, p, 1.5, 10.0)
    print(f"paper's law, rates, 3 m/s wind: {100 * ct:.2f} cm, {100 * spd:.2f} cm/s RMS, mean {100 * mean:+.2f} cm/s")
    assert abs(mean) > 0.02 or ct > 0.02


def test_the_papers_law_is_there_by_name_and_warns():
    path = figure_eight()
    with pytest.warns(UserWarning, match="ideal inner loop"):
        paper = PathFollower.paper(path, 1.5)
    assert paper.gains.transversal_bandwidth_hz == 6.0 and paper.compensator is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        default = PathFollower(path, 1.5)
    assert default.compensator is not None and default.gains.transversal_bandwidth_hz < 1.0
