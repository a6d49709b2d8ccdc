"""TrajectoryTracker (the baseline of docs/evaluation.md) on the ideal double integrator: it
converges to the timed reference, the schedule starts at the closest point at activation and runs
at constant speed, limits hold, open paths brake to their end, bad input is refused."""

from __future__ import annotations

import math
from pathlib import Path as FsPath

import numpy as np
import pytest

from pf_offboard.config import load_config
from pf_offboard import Gains, Limits, Path
from pf_offboard.control import Command, TrajectoryTracker
from pf_offboard.control.feasible import ThrustSet
from pf_offboard.control.types import GRAVITY_M_S2, Compensation
from pf_offboard.errors import InputError

G = GRAVITY_M_S2

CONFIGS = FsPath(__file__).resolve().parents[2] / "configs"


def config_path(name: str) -> FsPath:
    return CONFIGS / name


def fly(tracker: TrajectoryTracker, y, v, seconds: float, t0: float = 100.0, dt: float = 0.005):
    """The ideal double integrator under the law, sampled every ``dt`` with the command held
    between samples (exact for a held acceleration, as a setpoint stream flies)."""
    y, v = np.asarray(y, float), np.asarray(v, float)
    cmds: list[Command] = []
    for k in range(int(round(seconds / dt))):
        c = tracker.update(y, v, t0 + k * dt)
        a = c.acceleration
        y, v = y + dt * v + 0.5 * dt * dt * a, v + dt * a
        cmds.append(c)
    return cmds, y, v, t0 + seconds


@pytest.mark.parametrize("speed", [1.5, -1.5])
def test_converges_to_the_timed_reference_within_the_limits(paper_path, speed):
    limits = Limits()
    tracker = TrajectoryTracker(paper_path, speed, gains=Gains.from_bandwidth(2.0, damping=0.8), limits=limits, compensation=Compensation.off())
    lam0 = 0.3 * paper_path.lam_max
    y0 = paper_path.eval(lam0).sigma + np.array([0.8, -0.5, 0.4])
    cmds, y, v, t_end = fly(tracker, y0, [1.0, 0.5, -0.5], 8.0)
    # the schedule started at the closest point at activation (t0 = 100 s)
    t0, s0 = tracker.start
    assert t0 == 100.0
    assert s0 == pytest.approx(paper_path.arclength(cmds[0].lam), abs=1e-12)
    ref = tracker.reference(t_end)
    # constant speed along the arclength, wrapped on the closed path
    assert ref.eta1_m == pytest.approx((s0 + speed * 8.0) % paper_path.length_m, abs=1e-9)
    assert np.linalg.norm(ref.velocity_m_s) == pytest.approx(abs(speed), rel=1e-9)
    # converged (to the sampling's residual: the command is held 5 ms while the reference turns)
    assert np.linalg.norm(y - ref.position_m) < 2e-4
    assert np.linalg.norm(v - ref.velocity_m_s) < 5e-4
    assert cmds[-1].cross_track_m < 2e-4
    ts = ThrustSet(limits.min_thrust_m_s2, limits.max_thrust_m_s2, limits.tan_tilt)
    assert all(ts.contains((c.acceleration[0], c.acceleration[1], c.acceleration[2] + G), 1e-6) for c in cmds)
    # the approach toward the reference respected the approach speed (the initial velocity aside)
    assert any(c.saturation.transversal or c.saturation.approach_speed or c.saturation.tilt for c in cmds[:100])


def test_on_the_reference_it_stays_on_it(paper_path):
    """Started exactly on the reference with its velocity: the feed-forward alone keeps it there."""
    tracker = TrajectoryTracker(paper_path, 1.5, gains=Gains.paper(), compensation=Compensation.off())
    lam0 = 0.6 * paper_path.lam_max
    y0 = paper_path.eval(lam0).sigma
    v0 = 1.5 * paper_path.frame(lam0).t
    cmds, y, v, t_end = fly(tracker, y0, v0, 2.0, dt=0.002)
    assert max(c.cross_track_m for c in cmds) < 1e-5
    assert np.linalg.norm(y - tracker.reference(t_end).position_m) < 1e-5


def test_behind_schedule_it_cuts_across(paper_path):
    """What the baseline is for: held back for 1.5 s, it leaves the path to catch the reference
    (a path follower would not)."""
    tracker = TrajectoryTracker(paper_path, 1.5, gains=Gains.paper(), compensation=Compensation.off())
    lam0 = 0.1 * paper_path.lam_max
    y0 = paper_path.eval(lam0).sigma
    tracker.update(y0, np.zeros(3), 0.0)  # activation; then the vehicle is stuck for 1.5 s
    cmds, _, _, _ = fly(tracker, y0, np.zeros(3), 3.0, t0=1.5, dt=0.01)
    assert max(c.cross_track_m for c in cmds) > 0.1


def test_open_path_reference_brakes_and_holds_at_the_end(helix_frenet):
    for speed in (1.5, -1.5):
        tracker = TrajectoryTracker(helix_frenet, speed, gains=Gains.paper(), compensation=Compensation.off())
        lam0 = 0.8 * helix_frenet.lam_max if speed > 0 else 0.2 * helix_frenet.lam_max
        y0 = helix_frenet.eval(lam0).sigma
        v0 = speed * helix_frenet.frame(lam0).t
        cmds, y, v, t_end = fly(tracker, y0, v0, 8.0, dt=0.01)
        end = helix_frenet.eval(helix_frenet.lam_max if speed > 0 else 0.0).sigma
        ref = tracker.reference(t_end)
        np.testing.assert_allclose(ref.position_m, end, atol=1e-9)
        assert ref.speed_m_s == 0.0
        assert np.linalg.norm(y - end) < 0.02 and np.linalg.norm(v) < 0.02
        # the reference's speed never rose and only fell at the law's deceleration
        speeds = [abs(tracker.reference(100.0 + k * 0.05).speed_m_s) for k in range(160)]
        assert max(speeds) <= abs(speed) + 1e-12
        assert max(a - b for a, b in zip(speeds, speeds[1:])) <= tracker.law.a_dec * 0.05 + 1e-9


def test_reset_restarts_the_schedule_at_the_closest_point(paper_path):
    tracker = TrajectoryTracker(paper_path, 1.5, gains=Gains.paper(), compensation=Compensation.off())
    y1 = paper_path.eval(0.2 * paper_path.lam_max).sigma
    tracker.update(y1, np.zeros(3), 5.0)
    assert tracker.start == (5.0, pytest.approx(paper_path.arclength(0.2 * paper_path.lam_max), abs=1e-9))
    tracker.update(y1, np.zeros(3), 6.0)
    assert tracker.start[0] == 5.0  # running
    tracker.reset()
    assert tracker.start is None
    y2 = paper_path.eval(0.7 * paper_path.lam_max).sigma
    tracker.update(y2, np.zeros(3), 9.0)
    assert tracker.start == (9.0, pytest.approx(paper_path.arclength(0.7 * paper_path.lam_max), abs=1e-9))


def test_bad_input_names_the_field(paper_path):
    tracker = TrajectoryTracker(paper_path, 1.5, gains=Gains.paper(), compensation=Compensation.off())
    with pytest.raises(InputError) as exc:
        tracker.update((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
    assert exc.value.field == "time_s"
    with pytest.raises(InputError) as exc:
        tracker.update((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), math.nan)
    assert exc.value.field == "time_s"
    with pytest.raises(InputError) as exc:
        tracker.update((0.0, math.nan, 2.0), (0.0, 0.0, 0.0), 0.0)
    assert exc.value.field == "position"
    with pytest.raises(InputError) as exc:
        TrajectoryTracker(paper_path, 0.0)
    assert exc.value.field == "speed_m_s"
    with pytest.raises(InputError) as exc:
        TrajectoryTracker(paper_path, 1.0).reference(0.0)  # before the schedule started
    assert exc.value.field == "time_s"


def test_from_config_shares_the_followers_settings():
    from pf_offboard.control import PathFollower

    f = PathFollower.from_config(load_config(config_path("px4-sih.yaml")))
    t = TrajectoryTracker.from_config(load_config(config_path("px4-sih.yaml")))
    assert (t.speed, t.gains, t.yaw, t.limits) == (f.speed, f.gains, f.yaw, f.limits)
    assert t.compensator is not None and t.compensator.model == f.compensator.model
    assert isinstance(t.path, Path) and t.path.length_m == f.path.length_m


def test_with_the_compensator_the_lag_lead_replaces_the_rate_feed_forward(paper_path):
    """As in the path follower: with the compensator only the yaw-rate feed-forward is sent (here
    constant yaw: no body rates at all); without it the reference's jerk gives the paper's rates."""
    from pf_offboard.control import VehicleModel
    from pf_offboard.control.compensator import InnerLoopCompensator

    lam0 = 0.3 * paper_path.lam_max
    y0, v0 = paper_path.eval(lam0).sigma, 1.5 * paper_path.frame(lam0).t
    plain, _, _, _ = fly(TrajectoryTracker(paper_path, 1.5, gains=Gains.paper(), compensation=Compensation.off()), y0, v0, 1.0)
    model = VehicleModel(accel_lag_xy_s=0.1, accel_lag_z_s=0.05, accel_delay_s=0.1)
    comp, _, _, _ = fly(TrajectoryTracker(paper_path, 1.5, gains=Gains.paper(), compensator=InnerLoopCompensator(model)), y0, v0, 1.0)
    assert max(float(np.linalg.norm(c.body_rates[:2])) for c in plain) > 0.1
    assert max(float(np.abs(c.body_rates).max()) for c in comp) < 1e-12


def test_a_model_drag_above_the_vehicles_does_not_run_the_tracker_away(paper_path):
    """The compensator's drag is inverted at the reference velocity (its deviation's share bounded,
    no push past the reference speed), as in the path follower: a model drag of 3 1/s (the fit's
    upper bound) on a vehicle without drag (the ideal double integrator) is positive velocity
    feedback when inverted at the velocity. From 4 m/s along the reference (1.5), 10 s: inverted at
    the velocity (before) the tracker ran away, 27 m/s and 50 m off; now at most 4.0 m/s (the
    start) and 0.38 m."""
    from pf_offboard.control import VehicleModel
    from pf_offboard.control.compensator import InnerLoopCompensator

    lam0 = 0.3 * paper_path.lam_max
    y, v = np.asarray(paper_path.eval(lam0).sigma, float), 4.0 * np.asarray(paper_path.frame(lam0).t, float)
    model = VehicleModel(accel_lag_xy_s=0.0, accel_lag_z_s=0.0, accel_delay_s=0.0, drag_xy_1_s=3.0, drag_z_1_s=3.0)
    tracker = TrajectoryTracker(paper_path, 1.5, compensator=InnerLoopCompensator(model))
    dt, top, worst = 0.005, 0.0, 0.0
    for k in range(2000):
        c = tracker.update(y, v, 100.0 + k * dt)
        y, v = y + dt * v + 0.5 * dt * dt * c.acceleration, v + dt * c.acceleration
        top, worst = max(top, float(np.linalg.norm(v))), max(worst, c.cross_track_m)
    assert top < 4.05 and worst < 0.5, (top, worst)
