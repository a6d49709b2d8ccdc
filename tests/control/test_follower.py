"""Closed-loop behaviour of PathFollower on the ideal double integrator (4): invariance,
attractiveness from random starts with limits respected, the self-intersection, straight
segments, open-path ends, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import config_path, rk4_step

from pf_offboard.control.types import Compensation, Gains
from pf_offboard.config import load_config
from pf_offboard import Gains, Limits, Path, PathFollower, YawSpec
from pf_offboard.control.feasible import ThrustSet
from pf_offboard.control.types import GRAVITY_M_S2
from pf_offboard.errors import InputError
from pf_offboard.sim.batch import BatchFollower

G = GRAVITY_M_S2


def feasible(limits: Limits, a: np.ndarray, tol: float = 1e-6) -> bool:
    return ThrustSet(limits.min_thrust_m_s2, limits.max_thrust_m_s2, limits.tan_tilt).contains(
        (a[0], a[1], a[2] + G), tol
    )


@pytest.mark.parametrize("speed", [1.5, -1.5])
def test_invariance_30_s_rk4(paper_path, speed):
    """Started on the path with velocity eta2_ref t, it stays on the path (<= 1e-5 m) for 30 s
    (about three laps)."""
    f = PathFollower(paper_path, speed=speed, gains=Gains.paper(), compensation=Compensation.off())
    lam0 = 0.37 * paper_path.lam_max
    y = paper_path.eval(lam0).sigma.copy()
    v = speed * paper_path.frame(lam0).t
    dt = 2.5e-3  # RK4: the discretisation error (~dt^4) stays far below the 1e-5 m bound
    worst = 0.0
    eta1_travel = 0.0
    prev = f.transverse_state(y, v).eta1
    for _ in range(round(30.0 / dt)):
        y, v, cmd = rk4_step(f, y, v, dt)
        st = cmd.state  # at the start of the step
        worst = max(worst, math.hypot(st.xi1, st.phi1))
        d = st.eta1 - prev
        eta1_travel += d - paper_path.length_m * round(d / paper_path.length_m)
        prev = st.eta1
    st = f.transverse_state(y, v)
    worst = max(worst, math.hypot(st.xi1, st.phi1))
    d = st.eta1 - prev
    eta1_travel += d - paper_path.length_m * round(d / paper_path.length_m)
    print(f"speed {speed}: worst distance from the path over 30 s = {worst:.2e} m")
    assert worst <= 1e-5
    assert abs(st.eta2 - speed) < 1e-6
    assert eta1_travel == pytest.approx(30.0 * speed, rel=1e-5)


def random_start(path: Path, rng: np.random.Generator):
    lam = rng.uniform(0.0, path.lam_max)
    d = rng.normal(size=3)
    y = path.eval(lam).sigma + d / np.linalg.norm(d) * rng.uniform(0.0, 5.0)
    w = rng.normal(size=3)
    return y, w / np.linalg.norm(w) * rng.uniform(0.0, 4.0)


# (planning tilt rate, approach-speed tolerance): None is the ideal double integrator with the
# paper's linear velocity loops everywhere; with the default slew limit the velocity loop is a
# square-root (jerk-limited) controller for large errors, whose tracking lag of a turning desired
# velocity lets the approach speed exceed the limit slightly more (worst of the 200: +0.065 m/s).
@pytest.mark.parametrize("tilt_rate,approach_tol", [(None, 0.05), (Limits().max_tilt_rate_rad_s, 0.1)])
def test_attractive_from_200_random_starts_with_limits(paper_path, tilt_rate, approach_tol):
    """Up to 5 m off and 4 m/s in any direction: converge to ||(xi1, phi1)|| < 1 cm and
    |eta2 - eta2_ref| < 1 cm/s; every command feasible; approach speed within the limit.

    Flown on the batch engine (one BatchFollower per direction, 100 flights each: the scalar
    PathFollower's outputs to rounding, tests/sim/batch/test_batch_follower.py), each flight
    checked at every step until it has stayed in the band for 0.5 s, as a scalar loop would."""
    rng = np.random.default_rng(20260522)
    limits = Limits(
        max_tilt_deg=35.0,
        min_thrust_m_s2=2.0,
        max_thrust_m_s2=20.0,
        max_approach_speed_m_s=2.0,
        max_tilt_rate_rad_s=tilt_rate,
    )
    dt = 0.005
    starts = [random_start(paper_path, rng) for _ in range(200)]  # flight i flies speed 1.5 if i is odd, else -1.5
    times = np.full(200, np.nan)
    for speed in (1.5, -1.5):
        ids = np.array([i for i in range(200) if (1.5 if i % 2 else -1.5) == speed])
        n = len(ids)
        f = BatchFollower(PathFollower(paper_path, speed=speed, limits=limits, gains=Gains.paper(), compensation=Compensation.off()), n)
        y = np.array([starts[i][0] for i in ids])
        v = np.array([starts[i][1] for i in ids])
        converged_at = np.full(n, np.nan)
        flying = np.ones(n, dtype=bool)  # not yet 0.5 s in the band
        for k in range(int(20.0 / dt)):
            c = f.update(y, v)
            a = c.acceleration
            rows = np.flatnonzero(flying)
            assert np.all(c.finite[rows]) and np.all(np.isfinite(a[rows])) and np.all(np.isfinite(c.body_rates[rows]))
            for j in rows:
                assert feasible(limits, a[j]), (ids[j], k, a[j])
            if k * dt > 1.5:
                # after the initial velocity has been dealt with, never approach faster than allowed
                off = rows[c.cross_track_m[rows] > 1e-3]
                s = f.bpath.eval_floats(c.lam[off])
                r = y[off] - np.column_stack(s[0:3])
                approach = -np.einsum("ij,ij->i", r, v[off]) / np.linalg.norm(r, axis=1)
                assert np.all(approach <= limits.max_approach_speed_m_s + approach_tol), (ids[off], k, approach)
            band = (np.hypot(c.xi1, c.phi1) < 0.01) & (np.abs(c.eta2 - speed) < 0.01)
            # passing through the band is not convergence
            converged_at = np.where(flying, np.where(band, np.where(np.isnan(converged_at), k * dt, converged_at), np.nan), converged_at)
            flying &= ~(k * dt > converged_at + 0.5)  # stayed in the band for 0.5 s
            if not flying.any():
                break
            v = v + dt * a
            y = y + dt * v
        assert not np.isnan(converged_at).any(), (ids[np.isnan(converged_at)], y[np.isnan(converged_at)], v[np.isnan(converged_at)])
        times[ids] = converged_at
    assert max(times) < 10.0
    print(f"convergence time: median {np.median(times):.2f} s, max {max(times):.2f} s")


@pytest.mark.parametrize("speed", [1.5, -1.5])
@pytest.mark.parametrize("name", ["paper.yaml", "figure8.yaml"])
def test_self_intersection_eta1_monotonic(name, speed):
    """Two laps through the self-intersection: eta1 advances every step by eta2_ref dt (no branch jump)."""
    path = PathFollower.from_config(load_config(config_path(name))).path
    f = PathFollower(path, speed=speed, gains=Gains.paper(), compensation=Compensation.off())
    y = path.eval(0.0).sigma.copy()
    v = speed * path.frame(0.0).t
    dt = 0.005
    y, v, cmd = rk4_step(f, y, v, dt)
    prev = cmd.state.eta1
    L = path.length_m
    n = int(2 * L / abs(speed) / dt)
    for _ in range(n):
        y, v, cmd = rk4_step(f, y, v, dt)
        eta1 = cmd.state.eta1
        d = eta1 - prev
        d -= L * round(d / L)
        assert d * speed > 0.0
        assert abs(d - speed * dt) < 1e-6
        prev = eta1


def test_self_intersection_passes_near_the_crossing(paper_path):
    """The paper path really crosses itself (so the test above is meaningful)."""
    lam = np.linspace(0.0, paper_path.lam_max, 1000, endpoint=False)
    pts = np.array([paper_path.eval(x).sigma for x in lam])
    d = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    sep = np.abs(lam[:, None] - lam[None, :])
    sep = np.minimum(sep, paper_path.lam_max - sep)
    assert d[sep > 2.0].min() < 0.02  # samples are 1.6 cm apart along the path


def _fly(f: PathFollower, y, v, seconds: float, dt: float = 0.005):
    cmds = []
    for _ in range(int(seconds / dt)):
        c = f.update(y, v)
        cmds.append(c)
        v = v + dt * c.acceleration
        y = y + dt * v
    return cmds, y, v


@pytest.mark.parametrize("name", ["straight.yaml", "racetrack.yaml"])
def test_straight_segments_rmf_no_nans_or_spikes(name):
    f = PathFollower.from_config(load_config(config_path(name)))
    assert f.path.frame_kind == "rmf"
    lam = 0.3 * f.path.lam_max
    pt = f.path.eval(lam)
    y = pt.sigma + np.array([0.3, -0.4, 0.2])
    v = np.zeros(3)
    cmds, y, v = _fly(f, y, v, 8.0)
    acc = np.array([c.acceleration for c in cmds])
    rates = np.array([c.body_rates for c in cmds])
    assert np.all(np.isfinite(acc)) and np.all(np.isfinite(rates))
    assert all(feasible(f.limits, a) for a in acc)
    # after convergence: smooth commands (no spikes) and on the path
    tail = acc[len(acc) // 2 :]
    assert np.abs(np.diff(tail, axis=0)).max() < 0.5  # m/s^2 per 5 ms step
    assert np.abs(rates[len(rates) // 2 :]).max() < 5.0
    assert cmds[-1].cross_track_m < 0.01


def test_open_path_stops_at_its_end(helix_frenet):
    """An open path: the follower brakes and holds at the end point (no NaN past the end)."""
    for speed in (1.5, -1.5):
        f = PathFollower(helix_frenet, speed=speed, gains=Gains.paper(), compensation=Compensation.off())
        lam0 = 0.8 * helix_frenet.lam_max if speed > 0 else 0.2 * helix_frenet.lam_max
        y = helix_frenet.eval(lam0).sigma.copy()
        v = speed * helix_frenet.frame(lam0).t
        cmds, y, v = _fly(f, y, v, 12.0)
        end = helix_frenet.eval(helix_frenet.lam_max if speed > 0 else 0.0).sigma
        assert np.linalg.norm(y - end) < 0.02
        assert np.linalg.norm(v) < 0.02
        assert all(np.all(np.isfinite(c.acceleration)) for c in cmds)


def test_open_path_joined_before_its_start(helix_frenet):
    """Starting beyond the start of an open path: join at the start and travel on."""
    path = helix_frenet
    for speed, lam in ((1.0, 0.0), (-1.0, path.lam_max)):
        f = PathFollower(path, speed=speed, gains=Gains.paper(), compensation=Compensation.off())
        t = path.frame(lam).t
        y = path.eval(lam).sigma - np.sign(speed) * 0.8 * t
        cmds, y, v = _fly(f, y, np.zeros(3), 6.0)
        st = cmds[-1].state
        assert abs(st.eta2 - speed) < 0.01 and cmds[-1].cross_track_m < 0.01
        travelled = st.eta1 if speed > 0 else path.length_m - st.eta1
        assert travelled > 3.0


def test_far_start_bounded_and_limits_respected(paper_path):
    """100 m away at 10 m/s: commands stay within the limits, no NaN, heading back."""
    f = PathFollower(paper_path, speed=1.5, gains=Gains.paper(), compensation=Compensation.off())
    y = np.array([100.0, -40.0, 30.0])
    v = np.array([0.0, 10.0, -3.0])
    cmds, y2, _ = _fly(f, y, v, 10.0)
    assert all(feasible(f.limits, c.acceleration) for c in cmds)
    assert cmds[-1].cross_track_m < cmds[0].cross_track_m - 15.0


def test_one_metre_offset_respects_limits_and_priority(paper_path):
    """With the paper gains, 1 m off asks kp * 1 m > 1000 m/s^2 unlimited; the command is feasible,
    points toward the path and the tangential part is the one cut back."""
    f = PathFollower(paper_path, speed=1.5, gains=Gains.paper(), compensation=Compensation.off())
    assert f.gains.transversal_kp > 1000.0
    lam = 0.5 * paper_path.lam_max
    fr = paper_path.frame(lam)
    y = paper_path.eval(lam).sigma + 0.45 * fr.e3  # inside the exact-law region
    c = f.update(y, np.zeros(3))
    assert feasible(f.limits, c.acceleration)
    assert c.acceleration @ fr.e3 < -1.0  # toward the path
    assert c.saturation.transversal and c.saturation.tangential


def test_bad_input_raises_and_never_commands():
    path = Path.from_waypoints([[0, 0, 1], [1, 0, 1], [1, 1, 1.5]], closed=True)
    f = PathFollower(path, speed=1.0, gains=Gains.paper(), compensation=Compensation.off())
    with pytest.raises(InputError):
        f.update([math.nan, 0.0, 1.0], [0.0, 0.0, 0.0])
    with pytest.raises(InputError):
        f.update([0.0, 0.0, 1.0], [0.0, math.inf, 0.0])
    with pytest.raises(InputError):
        f.update([0.0, 0.0], [0.0, 0.0, 0.0])
    for bad in (0.0, math.nan, 25.0):
        with pytest.raises(InputError):
            PathFollower(path, speed=bad)
    with pytest.raises(InputError, match="speed_m_s"):
        PathFollower(path, speed="fast")  # type: ignore[arg-type]
    # finite but absurd: 1e300 m/s once squared is inf, and the command would be NaN
    with pytest.raises(InputError, match="velocity"):
        f.update([0.0, 0.0, 1.0], [1e300, 0.0, 0.0])
    with pytest.raises(InputError, match="position"):
        f.update([0.0, -1e300, 1.0], [0.0, 0.0, 0.0])


@pytest.mark.parametrize("name", ["paper.yaml", "straight.yaml", "helix.yaml"])
def test_extreme_finite_states_give_finite_commands(name):
    """Up to the input bounds (1e6 m, 1e3 m/s per component) every command is finite."""
    f = PathFollower.from_config(load_config(config_path(name)))
    rng = np.random.default_rng(8)
    for pos_m in (0.0, 1e3, 1e5, 0.999e6):
        for vel_m_s in (0.0, 30.0, 0.999e3):
            for _ in range(10):
                d, w = rng.normal(size=3), rng.normal(size=3)
                f.reset()
                c = f.update(pos_m * d / np.abs(d).max(), vel_m_s * w / np.abs(w).max())
                assert np.all(np.isfinite(c.acceleration)) and np.all(np.isfinite(c.body_rates))
                assert np.all(np.isfinite(c.attitude)) and math.isfinite(c.thrust) and math.isfinite(c.yaw_rate)
                assert feasible(f.limits, c.acceleration)


def test_value_objects_and_reset(paper_path):
    f = PathFollower(paper_path, speed=-1.5, gains=Gains(), yaw=YawSpec.constant(0.3), limits=Limits(), compensation=Compensation.off())
    y = paper_path.eval(1.0).sigma + 0.1
    c = f.update(y, np.zeros(3))
    assert c.attitude.shape == (4,) and abs(np.linalg.norm(c.attitude) - 1.0) < 1e-12
    assert c.thrust == pytest.approx(np.linalg.norm(c.acceleration + [0, 0, G]))
    assert c.yaw == pytest.approx(0.3)
    alpha, beta = f.decoupling(y, np.zeros(3))
    assert alpha.shape == (3,) and beta.shape == (3, 3)
    f.reset()
    assert f.transverse_state(y, np.zeros(3)) == pytest.approx(c.state)
    with pytest.raises(InputError):
        Gains(transversal_bandwidth_hz=0.0)
    with pytest.raises(InputError):
        Limits(max_tilt_deg=90.0)


def test_hold_yaw_flies_the_heading_it_is_given(paper_path):
    y = paper_path.eval(1.0).sigma + 0.1
    f = PathFollower(paper_path, 1.5, yaw=YawSpec.hold())
    assert f.update(y, np.zeros(3)).yaw == 0.0  # no heading given yet: yaw_rad
    assert not f.hold_heading(math.nan)
    assert f.hold_heading(1.2 + 2.0 * math.pi)  # wrapped
    c = f.update(y, np.zeros(3))
    assert c.yaw == pytest.approx(1.2, abs=1e-12) and c.yaw_rate == 0.0
    f.reset()  # an estimator reset keeps the heading
    assert f.update(y, np.zeros(3)).yaw == pytest.approx(1.2, abs=1e-12)
    other = PathFollower(paper_path, 1.5, yaw=YawSpec.constant(0.3))
    assert not other.hold_heading(1.2) and other.update(y, np.zeros(3)).yaw == pytest.approx(0.3)


@pytest.mark.parametrize("name", ["figure8.yaml", "racetrack.yaml", "helix.yaml", "straight.yaml"])
def test_attractive_on_the_other_shipped_paths(name):
    """20 random starts (<= 5 m, <= 4 m/s) per shipped path, both directions, rmf and open paths."""
    base = PathFollower.from_config(load_config(config_path(name)))
    path = base.path
    rng = np.random.default_rng(sum(map(ord, name)))
    dt = 0.005
    for i in range(20):
        speed = base.speed if i % 2 else -base.speed
        f = PathFollower(path, speed=speed, limits=base.limits, gains=Gains.paper(), compensation=Compensation.off())
        lam = rng.uniform(0.2, 0.6) * path.lam_max  # open paths: leave room before the end
        d = rng.normal(size=3)
        y = path.eval(lam).sigma + d / np.linalg.norm(d) * rng.uniform(0.0, 5.0)
        w = rng.normal(size=3)
        v = w / np.linalg.norm(w) * rng.uniform(0.0, 4.0)
        converged_at = None
        for k in range(int(15.0 / dt)):
            c = f.update(y, v)
            assert feasible(f.limits, c.acceleration)
            st = c.state
            if math.hypot(st.xi1, st.phi1) < 0.01 and abs(st.eta2 - f.reference_speed(st.eta1)) < 0.01:
                converged_at = k * dt if converged_at is None else converged_at
            else:
                converged_at = None
            if converged_at is not None and k * dt > converged_at + 0.5:
                break
            v = v + dt * c.acceleration
            y = y + dt * v
        assert converged_at is not None, (name, i, st)


@pytest.mark.parametrize(
    "offset_m,tilt_rate,max_tilt_deg",
    [(0.003, None, 35.0), (0.0002, Limits().max_tilt_rate_rad_s, 20.0), (0.003, Limits().max_tilt_rate_rad_s, 20.0)],
)
def test_transversal_correction_is_delivered_in_full_while_tangential_gives_way(
    paper_path, offset_m, tilt_rate, max_tilt_deg
):
    """Off the path at rest with eta2_ref = 1.5 m/s: the tangential loop asks for far more than the
    limits allow; the transversal correction is still delivered exactly and the tangential
    acceleration is what is cut back. Without a slew limit (tilt_rate None) the correction is the
    paper's PD -kp e - kd e_dot. With the default slew limit it is that PD inside the linear
    neighbourhood (e < 2J/(kd kp) = 0.5 mm, |dv| < J/kd^2 = 7 mm/s; 0.2 mm off), and the square-root
    law's smaller value 3 mm off; tilt and thrust limits are tighter there (20 deg, 12 m/s^2) so
    that the (also slew-limited, 7.7 m/s^2) tangential demand exceeds what is left. The tangential
    bound (max_tangential_accel_m_s2) is off here: it is the allocation under test."""
    f = PathFollower(paper_path, speed=1.5, limits=Limits(
            max_tilt_deg=max_tilt_deg,
            max_thrust_m_s2=20.0 if tilt_rate is None else 12.0,
            max_tilt_rate_rad_s=tilt_rate,
            max_tangential_accel_m_s2=None,
        ), gains=Gains.paper(), compensation=Compensation.off())
    lam = 0.25 * paper_path.lam_max
    fr = paper_path.frame(lam)
    y = paper_path.eval(lam).sigma + offset_m * fr.e2
    v = np.zeros(3)
    c = f.update(y, v)
    alpha, beta = f.decoupling(y, v)
    u = beta @ c.acceleration + alpha
    st = c.state
    kp, kd = f.gains.transversal_kp, f.gains.transversal_kd
    u_xi, u_phi, reduced, _ = f.law.transversal(st.xi1, st.xi2, st.phi1, st.phi2)
    assert not reduced
    assert u[1] == pytest.approx(u_xi, rel=1e-9)
    assert u[2] == pytest.approx(u_phi, abs=1e-9)
    if tilt_rate is None or offset_m < 0.0005:
        assert u[1] == pytest.approx(-kp * st.xi1 - kd * st.xi2, rel=1e-9)
        assert u[2] == pytest.approx(-kp * st.phi1 - kd * st.phi2, abs=1e-9)
    else:
        # beyond the linear neighbourhood the correction is smaller than the linear PD's
        assert 0.0 < -u_xi < kp * abs(st.xi1)
    u_eta_wanted = f.law.tangential(1.5, st.eta2)
    assert 0.0 < u[0] < 0.5 * u_eta_wanted
    assert c.saturation.tangential and not c.saturation.transversal
    assert c.saturation.tilt or c.saturation.thrust  # the tangential part went to the boundary
    assert feasible(f.limits, c.acceleration)


@pytest.mark.parametrize("name", ["paper.yaml", "straight.yaml", "helix.yaml"])
def test_any_state_gives_a_feasible_finite_command(name):
    """500 random states (up to 20 m away, 15 m/s), each after a reset and then warm-started:
    the command is finite, within the limits, with a unit quaternion and thrust in range."""
    f = PathFollower.from_config(load_config(config_path(name)))
    rng = np.random.default_rng(5)
    lim = f.limits
    for i in range(500):
        if i % 2 == 0:
            f.reset()
        lam = rng.uniform(0.0, f.path.lam_max)
        d = rng.normal(size=3)
        y = f.path.eval(lam).sigma + d / np.linalg.norm(d) * rng.uniform(0.0, 20.0) ** rng.uniform(0.0, 1.0)
        w = rng.normal(size=3)
        v = w / np.linalg.norm(w) * rng.uniform(0.0, 15.0)
        c = f.update(y, v)
        assert np.all(np.isfinite(c.acceleration)) and np.all(np.isfinite(c.body_rates))
        assert feasible(lim, c.acceleration)
        assert lim.min_thrust_m_s2 - 1e-9 <= c.thrust <= lim.max_thrust_m_s2 + 1e-9
        assert abs(np.linalg.norm(c.attitude) - 1.0) < 1e-12
        assert math.isfinite(c.yaw) and math.isfinite(c.yaw_rate)
