"""Feed-forward: on the path at eta2_ref the commanded body rates equal the finite-difference
rate of the commanded attitude; attitude/thrust agree with eq. (24); yaw specifications."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import config_path

from pf_offboard.control.types import Compensation, Gains
from pf_offboard.config import load_config
from pf_offboard import Path, PathFollower, YawSpec
from pf_offboard.control.feedforward import YawProfile, attitude_from_thrust, onpath_derivatives, quaternion_from_axes
from pf_offboard.control.types import GRAVITY_M_S2
from pf_offboard.frames import quat_multiply


def quat_log_rate(q0: np.ndarray, q1: np.ndarray, dt: float) -> np.ndarray:
    """Body-frame angular velocity taking q0 to q1 in dt: 2 log(q0^-1 q1) / dt."""
    dq = quat_multiply(q0 * np.array([1.0, -1.0, -1.0, -1.0]), q1)
    if dq[0] < 0.0:
        dq = -dq
    n = np.linalg.norm(dq[1:])
    return 2.0 * math.atan2(n, dq[0]) * dq[1:] / max(n, 1e-300) / dt


def rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


CASES = [
    ("paper.yaml", None),  # constant yaw 0, Frenet frame, eta2_ref = -1.5
    ("figure8.yaml", YawSpec.tangent()),  # tangent yaw, rotation-minimising frame
    ("racetrack.yaml", None),  # yaw table
    ("helix.yaml", None),  # open, tangent yaw
    ("paper.yaml", YawSpec.tangent(0.4)),
    ("paper.yaml", YawSpec.table([(0.0, 0.0), (4.0, 2.0), (9.0, -1.0), (12.0, 0.5)])),
]


@pytest.mark.parametrize("name,yaw", CASES)
def test_body_rates_match_attitude_finite_differences(name, yaw):
    base = PathFollower.from_config(load_config(config_path(name)))
    path, speed = base.path, base.speed
    f = PathFollower(path, speed, gains=base.gains, yaw=yaw or base.yaw, limits=base.limits, compensation=Compensation.off())
    dt = 2e-3
    if path.closed:
        s0, n = 0.0, int(path.length_m / abs(speed) / dt)  # one full lap
    else:
        s0, n = 0.3 * path.length_m, int(0.4 * path.length_m / abs(speed) / dt)
    quats, rates, worst = [], [], 0.0
    for k in range(n):
        lam = path.lam_at_arclength(s0 + speed * k * dt)
        y = path.eval(lam).sigma
        v = speed * path.frame(lam).t
        c = f.update(y, v)
        assert math.hypot(c.state.xi1, c.state.phi1) < 1e-9
        # eq. (24): body z along f = a + g e_z, |f| = thrust
        fvec = c.acceleration + np.array([0.0, 0.0, GRAVITY_M_S2])
        assert np.allclose(rotation(c.attitude)[:, 2] * c.thrust, fvec, atol=1e-9)
        quats.append(c.attitude)
        rates.append(c.body_rates)
    for k in range(1, n - 1):
        fd = quat_log_rate(quats[k - 1], quats[k + 1], 2 * dt)
        worst = max(worst, float(np.abs(fd - rates[k]).max()))
    print(f"{name} {f.yaw.mode}: worst |omega_ff - omega_fd| = {worst:.2e} rad/s, max |omega| {np.abs(rates).max():.2f}")
    assert worst <= 1e-4
    assert np.abs(rates).max() > 0.05  # the feed-forward is not trivially zero


def test_yaw_heading_convention():
    """ZYX yaw: the body x axis points along (cos psi, sin psi) horizontally, for any tilt."""
    rng = np.random.default_rng(11)
    for _ in range(100):
        f = (rng.uniform(-4, 4), rng.uniform(-4, 4), rng.uniform(3, 15))
        psi = rng.uniform(-math.pi, math.pi)
        xb, yb, zb = attitude_from_thrust(f, psi)
        assert math.atan2(xb[1], xb[0]) == pytest.approx(psi, abs=1e-12)
        R = np.array([xb, yb, zb]).T
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0
        q = quaternion_from_axes(xb, yb, zb)
        assert np.allclose(rotation(np.array(q)), R, atol=1e-12)


def test_onpath_derivatives_are_arclength_derivatives(paper_path):
    """sigma_s, sigma_ss, sigma_sss by chain rule vs finite differences in arclength."""
    for s in (1.0, 5.5, 11.0):
        h = 1e-3
        pts = [paper_path.eval(paper_path.lam_at_arclength(s + j * h)).sigma for j in (-2, -1, 0, 1, 2)]
        lam = paper_path.lam_at_arclength(s)
        pt = paper_path.eval(lam)
        t, ss, sss = onpath_derivatives(tuple(pt.d1), tuple(pt.d2), tuple(pt.d3))
        assert np.allclose(t, (pts[3] - pts[1]) / (2 * h), atol=1e-6)
        assert np.allclose(ss, (pts[3] - 2 * pts[2] + pts[1]) / h**2, atol=1e-5)
        assert np.allclose(sss, (pts[4] - 2 * pts[3] + 2 * pts[1] - pts[0]) / (2 * h**3), atol=1e-3)


def test_yaw_table_is_smooth_and_periodic():
    table = ((0.0, 0.0), (3.0, math.pi / 2), (7.0, math.pi), (10.0, 1.5 * math.pi))
    prof = YawProfile(YawSpec.table(table), path_length_m=12.0, closed=True, direction=1.0)
    t = (1.0, 0.0, 0.0)
    z = (0.0, 0.0, 0.0)
    for s, psi in table:
        assert prof.evaluate(s, t, z)[0] == pytest.approx(psi, abs=1e-12)
    # periodic: value and slope agree one lap later (up to the full turn), slope is the FD slope
    for s in (0.5, 2.9, 11.99):
        p0, d0 = prof.evaluate(s, t, z)
        p1, d1 = prof.evaluate(s + 12.0, t, z)
        assert math.remainder(p1 - p0, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
        assert d1 == pytest.approx(d0, rel=1e-9)
        h = 1e-5
        fd = (prof.evaluate(s + h, t, z)[0] - prof.evaluate(s - h, t, z)[0]) / (2 * h)
        assert d0 == pytest.approx(fd, rel=1e-5)
    # continuity across the seam (value and slope)
    a = prof.evaluate(12.0 - 1e-9, t, z)
    b = prof.evaluate(12.0 + 1e-9, t, z)
    assert math.remainder(a[0] - b[0], 2 * math.pi) == pytest.approx(0.0, abs=1e-7)
    assert a[1] == pytest.approx(b[1], rel=1e-6)


def test_tangent_yaw_faces_direction_of_travel():
    path = Path.from_waypoints([[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]], closed=True)
    lam = 0.1
    t = tuple(path.frame(lam).t)
    fwd = YawProfile(YawSpec.tangent(), path.length_m, True, 1.0).evaluate(0.0, t, (0.0, 0.0, 0.0))[0]
    back = YawProfile(YawSpec.tangent(), path.length_m, True, -1.0).evaluate(0.0, t, (0.0, 0.0, 0.0))[0]
    assert fwd == pytest.approx(math.atan2(t[1], t[0]))
    assert math.remainder(back - fwd - math.pi, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)


def test_open_yaw_table_is_c2_beyond_its_ends():
    table = ((1.0, 0.0), (3.0, 1.0), (6.0, -0.5))
    prof = YawProfile(YawSpec.table(table), path_length_m=10.0, closed=False, direction=1.0)
    t, z = (1.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    for end in (1.0, 6.0):
        h = 1e-4
        (pa, da), (pb, db) = prof.evaluate(end - h, t, z), prof.evaluate(end + h, t, z)
        assert pb - pa == pytest.approx(2 * h * da, rel=1e-3)  # value and slope continuous
        assert db == pytest.approx(da, abs=1e-6)  # slope continuous -> psi_dot has no step
    assert prof.evaluate(0.0, t, z)[1] == pytest.approx(prof.evaluate(1.0, t, z)[1])
