"""The any-state body-rate feed-forward (feedforward: any_state) by finite differences.

omega_ff must be the body rate of the *commanded* attitude along the closed-loop flow with an ideal
inner loop (y'' = a_des(y, y')), at any state in the tube, not only on the path. Reference: the
flow integrated with RK4 (the follower's own a_des), the commanded attitude q(t) at t = +-h, +-2h,
a fourth-order central difference of q, omega = 2 vec(q^-1 q'). The feed-forward itself is a
central difference of a_des along the flow's direction followed by eq. (25): the two share no
code beyond the law.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import PAPER_YAML

from pf_offboard.control.types import Compensation, Gains
from pf_offboard import PathFollower, YawSpec
from pf_offboard.config import load_config
from pf_offboard.control.profile import SpeedProfileSpec

H_S = 1e-3  # stencil step of the reference difference (s)
SUBSTEPS = 4  # RK4 steps per H_S


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])  # fmt: skip


def _flow_attitudes(f: PathFollower, y0: np.ndarray, v0: np.ndarray) -> dict[int, np.ndarray]:
    """Commanded attitude at t = k H_S, k in -2..2, along the closed-loop flow from (y0, v0)."""

    def acc(y: np.ndarray, v: np.ndarray) -> np.ndarray:
        return f.update(y, v).acceleration

    out = {}
    for direction in (1.0, -1.0):
        f.reset()
        y, v = y0.copy(), v0.copy()
        dt = direction * H_S / SUBSTEPS
        for k in range(1, 3):
            for _ in range(SUBSTEPS):
                k1v, k1a = v, acc(y, v)
                k2v, k2a = v + 0.5 * dt * k1a, acc(y + 0.5 * dt * k1v, v + 0.5 * dt * k1a)
                k3v, k3a = v + 0.5 * dt * k2a, acc(y + 0.5 * dt * k2v, v + 0.5 * dt * k2a)
                k4v, k4a = v + dt * k3a, acc(y + dt * k3v, v + dt * k3a)
                y = y + dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
                v = v + dt / 6.0 * (k1a + 2 * k2a + 2 * k3a + k4a)
            out[int(direction) * k] = f.update(y, v).attitude
    f.reset()
    out[0] = f.update(y0, v0).attitude
    return out


def _rates(q: dict[int, np.ndarray]) -> tuple[np.ndarray, float]:
    """Body rates from the stencil (4th order) and the disagreement of the one-sided 2nd-order
    differences (large where the law has a kink inside the stencil)."""
    qd = (-q[2] + 8.0 * q[1] - 8.0 * q[-1] + q[-2]) / (12.0 * H_S)
    conj = q[0] * np.array([1.0, -1.0, -1.0, -1.0])
    fwd = (-3.0 * q[0] + 4.0 * q[1] - q[2]) / (2.0 * H_S)
    bwd = (3.0 * q[0] - 4.0 * q[-1] + q[-2]) / (2.0 * H_S)
    kink = float(np.linalg.norm(2.0 * (_quat_mul(conj, fwd - bwd))[1:]))
    return 2.0 * _quat_mul(conj, qd)[1:], kink


def _random_tube_state(f: PathFollower, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    path = f.path
    while True:
        lam = rng.uniform(0.0, path.lam_max)
        fr = path.frame(lam)
        p = path.eval(lam)
        d = rng.uniform(0.0, 0.45)
        ang = rng.uniform(0.0, 2.0 * math.pi)
        r = d * (math.cos(ang) * fr.e2 + math.sin(ang) * fr.e3)
        s2 = float(p.d1 @ p.d1)
        if float(p.d2 @ r) / s2 > 0.7:
            continue
        v = rng.normal(size=3)
        v *= rng.uniform(0.0, 3.0) / np.linalg.norm(v)
        return p.sigma + r, v


def _follower(feedforward: str, yaw: YawSpec | None = None, profile: SpeedProfileSpec | None = None) -> PathFollower:
    cfg = load_config(PAPER_YAML)
    cfg = dataclasses.replace(cfg, feedforward=feedforward, speed_profile=profile, yaw=yaw or cfg.yaw)
    return PathFollower.from_config(cfg)


@pytest.mark.parametrize(
    ("yaw", "profile"),
    [(None, None), (YawSpec.tangent(0.3), None), (None, SpeedProfileSpec(4.0, max_tangential_jerk_m_s3=20.0))],
    ids=["constant-yaw", "tangent-yaw", "speed-profile"],
)
def test_any_state_rates_are_the_rate_of_the_commanded_attitude(yaw: YawSpec | None, profile: SpeedProfileSpec | None) -> None:
    ff = _follower("any_state", yaw, profile)
    flow = PathFollower(ff.path, ff.speed, gains=ff.gains, yaw=ff.yaw, limits=ff.limits, compensation=Compensation.off())  # a_des only
    flow.profile = ff.profile  # the same eta2_ref(eta1) without recomputing it
    onpath = PathFollower(ff.path, ff.speed, gains=ff.gains, yaw=ff.yaw, limits=ff.limits, compensation=Compensation.off())
    onpath.profile = ff.profile
    rng = np.random.default_rng(20)
    errors, onpath_errors, kinks = [], [], 0
    while len(errors) < 25:
        y0, v0 = _random_tube_state(ff, rng)
        ff.reset()
        cmd = ff.update(y0, v0)
        assert cmd.cross_track_m < 0.5
        ref, kink = _rates(_flow_attitudes(flow, y0, v0))
        if kink > 1e-2:  # a kink of the law (min of approach-speed bounds, a limit) inside the stencil
            kinks += 1
            assert kinks <= 8
            continue
        errors.append(float(np.max(np.abs(cmd.body_rates - ref))))
        onpath.reset()
        onpath_errors.append(float(np.max(np.abs(onpath.update(y0, v0).body_rates - ref))))
    print(f"any-state: worst |omega_ff - omega| {max(errors):.1e} rad/s over {len(errors)} states ({kinks} at a kink); on-path median {np.median(onpath_errors):.2f}")
    assert max(errors) <= 1e-4, max(errors)
    # the on-path feed-forward is not the rate of the commanded attitude off the path
    assert np.median(onpath_errors) > 0.05


def test_on_path_both_variants_agree() -> None:
    """On the path at eta2_ref the closed-loop flow is the on-path motion: the same rates."""
    ff, op = _follower("any_state"), _follower("on_path")
    for lam in np.linspace(0.0, ff.path.lam_max, 7)[:-1]:
        p = ff.path.eval(lam)
        t = p.d1 / np.linalg.norm(p.d1)
        a, b = ff.update(p.sigma, ff.speed * t), op.update(p.sigma, ff.speed * t)
        np.testing.assert_allclose(a.body_rates, b.body_rates, atol=1e-5)
        np.testing.assert_array_equal(a.attitude, b.attitude)
