"""The point-mass lap-time bound at the vehicle's limits (control.profile.vehicle_lap_time_bound,
PathFollower.lap_time_bound_s) against closed forms: a level circle (v = sqrt(a R), a = g tan(tilt))
and a straight segment ending at rest (cruise, then brake at a), plus a finite difference in R."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pf_offboard import PathFollower
from pf_offboard.control.profile import vehicle_lap_time_bound
from pf_offboard.control.types import GRAVITY_M_S2, Limits
from pf_offboard.path import Path

LIMITS = Limits(max_tilt_deg=30.0)
A_MAX = GRAVITY_M_S2 * math.tan(math.radians(30.0))  # the level acceleration the tilt allows


def _circle(radius_m: float, n: int = 72) -> Path:
    th = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return Path.from_waypoints(np.column_stack([radius_m * np.cos(th), radius_m * np.sin(th), np.full(n, 2.0)]), closed=True)


@pytest.mark.parametrize("radius_m", [1.0, 2.5])
def test_circle_at_the_acceleration_limit(radius_m: float) -> None:
    """Fast enough to be limited by the tilt: v = sqrt(a R) all round, lap 2 pi R / v."""
    v = math.sqrt(A_MAX * radius_m)
    lap = vehicle_lap_time_bound(_circle(radius_m), LIMITS, 3.0 * v)
    assert lap == pytest.approx(2.0 * math.pi * radius_m / v, rel=0.01)


def test_circle_at_the_speed_limit_and_direction() -> None:
    path = _circle(2.5)
    v = 0.5 * math.sqrt(A_MAX * 2.5)
    for direction in (1.0, -1.0):
        assert vehicle_lap_time_bound(path, LIMITS, v, direction) == pytest.approx(path.length_m / v, rel=1e-6)


def test_circle_finite_difference_in_radius() -> None:
    """d lap / d R = pi / sqrt(a R) at the acceleration limit (central difference)."""
    r, h = 2.0, 0.05
    lap = lambda radius: vehicle_lap_time_bound(_circle(radius), LIMITS, 10.0)  # noqa: E731
    fd = (lap(r + h) - lap(r - h)) / (2.0 * h)
    assert fd == pytest.approx(math.pi / math.sqrt(A_MAX * r), rel=0.02)


@pytest.mark.parametrize("speed_m_s", [2.0, 6.0])
def test_straight_segment_brakes_to_rest_at_its_end(speed_m_s: float) -> None:
    """An open straight: starts at the speed limit, brakes at a to stop at the end (or, too short
    to reach the speed, the whole way at a: t = sqrt(2 L / a))."""
    length = 6.0
    path = Path.from_waypoints([[0.0, 0.0, 2.0], [length / 2, 0.0, 2.0], [length, 0.0, 2.0]])
    brake = speed_m_s**2 / (2.0 * A_MAX)
    expected = (length - brake) / speed_m_s + speed_m_s / A_MAX if brake <= length else math.sqrt(2.0 * length / A_MAX)
    assert vehicle_lap_time_bound(path, LIMITS, speed_m_s) == pytest.approx(expected, rel=0.01)


def test_follower_bound_uses_its_speed_or_its_profile() -> None:
    path = _circle(2.5)
    assert PathFollower(path, 1.5, limits=LIMITS).lap_time_bound_s() == pytest.approx(path.length_m / 1.5, rel=1e-6)
    from pf_offboard.control.profile import SpeedProfileSpec

    fast = PathFollower(path, 1.5, limits=LIMITS, speed_profile=SpeedProfileSpec(max_speed_m_s=10.0))
    bound = fast.lap_time_bound_s()
    assert bound == pytest.approx(2.0 * math.pi * 2.5 / math.sqrt(A_MAX * 2.5), rel=0.01)
    assert bound <= fast.profile.stats.travel_time_s  # the profile keeps a share for the feedback
