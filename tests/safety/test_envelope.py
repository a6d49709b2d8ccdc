"""The pure envelope monitor: fence, path check, each breach kind, the watchdog, setpoint checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from pf_offboard.config import parse_config
from pf_offboard.errors import ConfigError
from pf_offboard.safety import Breach, EnvelopeMonitor, SafetyConfig, VehicleSample, check_path, fence_for_path, tilt_rad

SQUARE = [(0.0, 0.0, 2.0), (4.0, 0.0, 2.0), (4.0, 4.0, 3.0), (0.0, 4.0, 3.0)]
LEVEL = np.array([1.0, 0.0, 0.0, 0.0])


def about_x(angle_deg: float) -> np.ndarray:
    a = math.radians(angle_deg) / 2.0
    return np.array([math.cos(a), math.sin(a), 0.0, 0.0])


def sample(t: float = 0.0, pos=(1.0, 1.0, 2.5), vel=(0.0, 0.0, 0.0), q=LEVEL, armed: bool = True, landed=None,
           cross: float | None = 0.1, eta1: float | None = 0.0, q_cmd=None, rates=None, q_demand=None) -> VehicleSample:  # fmt: skip
    return VehicleSample(t, np.array(pos, float), np.array(vel, float), q, armed, landed, cross, eta1, q_cmd, rates, q_demand)


def monitor(**cfg: object) -> EnvelopeMonitor:
    config = SafetyConfig(**cfg)  # type: ignore[arg-type]
    return EnvelopeMonitor(config, fence_for_path(config, SQUARE), 16.0, True)


def test_default_fence_is_the_paths_box_grown_by_the_margin_floored() -> None:
    fence = fence_for_path(SafetyConfig(), SQUARE)
    assert (fence.min_xy_m, fence.max_xy_m) == ((-2.0, -2.0), (6.0, 6.0))
    assert fence.floor_m == 0.5  # 2 - 2 = 0 m, floored at min_altitude_m
    assert fence.ceiling_m == 5.0
    assert fence.violation((0.0, 0.0, 2.0)) == ""
    assert "x = 6.50" in fence.violation((6.5, 0.0, 2.0))
    assert "below the floor" in fence.violation((0.0, 0.0, 0.4))
    assert "above the ceiling" in fence.violation((0.0, 0.0, 5.1))
    assert fence.violation((math.nan, 0.0, 2.0)) == "position not finite"


def test_cylinder_fence_default_and_configured() -> None:
    fence = fence_for_path(SafetyConfig(fence_shape="cylinder", fence_margin_m=1.0), SQUARE)
    assert fence.center_xy_m == (2.0, 2.0)
    assert fence.radius_m == pytest.approx(math.hypot(2.0, 2.0) + 1.0)
    assert fence.violation((2.0 + 3.8, 2.0, 2.0)) == ""
    assert "outside the fence cylinder" in fence.violation((2.0 + 3.8, 2.0 + 1.0, 2.0))
    fixed = fence_for_path(SafetyConfig(fence_shape="cylinder", fence_center_enu_m=(0.0, 0.0), fence_radius_m=2.0), SQUARE)
    assert fixed.radius_m == 2.0 and "outside" in check_path(fixed, SQUARE)


def test_path_outside_a_configured_box_or_below_the_floor_is_refused() -> None:
    inside = fence_for_path(SafetyConfig(), SQUARE)
    assert check_path(inside, SQUARE) == ""
    small = fence_for_path(SafetyConfig(fence_min_enu_m=(-1.0, -1.0, 0.0), fence_max_enu_m=(3.0, 5.0, 10.0)), SQUARE)
    why = check_path(small, SQUARE)
    assert "the path leaves the fence" in why and "(4.00, 0.00, 2.00)" in why
    high_floor = fence_for_path(SafetyConfig(min_altitude_m=2.5), SQUARE)
    assert "below the floor 2.5 m" in check_path(high_floor, SQUARE)


def test_state_inside_the_envelope_is_ok_and_each_limit_breaches() -> None:
    m = monitor()
    assert not m.check_state(sample()).breach
    cases = [
        (sample(pos=(9.0, 1.0, 2.5)), Breach.FENCE),
        (sample(pos=(1.0, 1.0, 0.2)), Breach.FENCE),
        (sample(cross=3.5), Breach.PATH_DISTANCE),
        (sample(q=about_x(61.0)), Breach.TILT),
        (sample(armed=False), Breach.DISARMED),
        (sample(landed=1), Breach.LANDED),
    ]
    for s, kind in cases:
        verdict = monitor().check_state(s)
        assert verdict.kind is kind, (kind, verdict)
        assert verdict.reason and "\n" not in verdict.reason
    assert monitor().check_state(sample(armed=False)).crash and not monitor().check_state(sample(cross=3.5)).crash


def test_falling_is_never_decided_on_one_sample() -> None:
    """One sample claiming 50 m/s down is no verdict; descending beyond the limit on every sample
    for safety.falling_confirm_s (two samples at least) is; a good sample in between starts again."""
    m = monitor()
    assert not m.check_state(sample(t=0.0, vel=(0.0, 0.0, -50.0))).breach
    assert not m.check_state(sample(t=0.004)).breach
    assert not m.check_state(sample(t=0.008, vel=(0.0, 0.0, -5.5))).breach
    assert not m.check_state(sample(t=0.02, vel=(0.0, 0.0, -5.5))).breach  # 0.012 s
    verdict = m.check_state(sample(t=0.03, vel=(0.0, 0.0, -5.5)))
    assert verdict.kind is Breach.FALLING and verdict.crash and "for 0.02 s" in verdict.reason
    slow = monitor(falling_confirm_s=0.5)  # one sample 0.6 s after the first is still two samples
    assert not slow.check_state(sample(t=0.0, vel=(0.0, 0.0, -6.0))).breach
    assert slow.check_state(sample(t=0.6, vel=(0.0, 0.0, -6.0))).kind is Breach.FALLING


def test_estimator_resets_and_degraded_estimates_end_following() -> None:
    m = monitor()
    assert not m.check_estimator(reset_enu_m=(0.0, 0.3, -0.3)).breach  # 0.42 m: followed on
    v = m.check_estimator(reset_enu_m=(0.0, 0.0, -1.6))
    assert v.kind is Breach.ESTIMATOR and not v.crash and "1.60 m" in v.reason and "vertical -1.60" in v.reason
    assert m.check_estimator(degraded="ODOMETRY quality -1").kind is Breach.ESTIMATOR
    assert not monitor(enabled=False).check_estimator(reset_enu_m=(9.0, 0.0, 0.0)).breach


def test_not_following_only_crash_and_tilt_count() -> None:
    m = monitor()
    assert not m.check_state(sample(pos=(9.0, 1.0, 0.1), vel=(0, 0, -6.0), cross=9.0), following=False).breach
    assert m.check_state(sample(q=about_x(70.0)), following=False).kind is Breach.TILT
    assert m.check_state(sample(armed=False), following=False).kind is Breach.DISARMED


def test_disabled_monitor_never_breaches() -> None:
    m = monitor(enabled=False)
    assert not m.check_state(sample(pos=(99.0, 0.0, -5.0), armed=False)).breach
    assert not m.check_setpoint(q_cmd_enu_flu=about_x(89.0)).breach


def test_activation_distance_has_its_own_limit() -> None:
    m = monitor(max_path_distance_at_activation_m=1.0, max_path_distance_m=3.0)
    assert m.check_activation(sample(cross=1.2)).kind is Breach.PATH_DISTANCE
    assert not m.check_activation(sample(cross=0.9)).breach
    assert not m.check_state(sample(cross=2.5)).breach  # while following the wider limit applies


def test_rates_mode_attitude_divergence_must_persist() -> None:
    m = monitor(max_attitude_error_deg=30.0, attitude_error_time_s=0.5)
    off = dict(q=LEVEL, q_cmd=about_x(40.0))
    assert not m.check_state(sample(t=0.0, **off)).breach
    assert not m.check_state(sample(t=0.4, **off)).breach
    assert not m.check_state(sample(t=0.45, q=LEVEL, q_cmd=about_x(10.0))).breach  # back within: window restarts
    assert not m.check_state(sample(t=0.5, **off)).breach
    assert m.check_state(sample(t=1.05, **off)).kind is Breach.ATTITUDE_ERROR
    # a yaw difference alone is not a divergence (thrust axes agree)
    yawed = np.array([math.cos(1.5), 0.0, 0.0, math.sin(1.5)])
    assert not monitor(attitude_error_time_s=0.0).check_state(sample(t=0.0, q=LEVEL, q_cmd=yawed)).breach


def test_no_progress_watchdog() -> None:
    m = monitor(no_progress_s=2.0, min_progress_m=0.5)
    verdicts = [m.check_state(sample(t=0.1 * i, cross=1.0, eta1=0.01 * i)) for i in range(30)]  # 0.1 m/s along it
    first = next(i for i, v in enumerate(verdicts) if v.breach)
    verdict = verdicts[first]
    assert first == 21 and verdict.kind is Breach.NO_PROGRESS and "no progress for 2.1 s" in verdict.reason
    moving = monitor(no_progress_s=2.0)
    for i in range(50):  # 1.5 m/s along the path: never
        assert not moving.check_state(sample(t=0.1 * i, cross=1.0, eta1=(0.15 * i) % 16.0)).breach
    closing = monitor(no_progress_s=2.0)
    for i in range(50):  # not moving along, but approaching the path at 0.3 m/s: progress
        assert not closing.check_state(sample(t=0.1 * i, cross=2.9 - 0.03 * i, eta1=0.0)).breach


def test_no_progress_measures_net_progress_across_the_closed_path_wrap() -> None:
    m = monitor(no_progress_s=1.0, min_progress_m=0.5)
    etas = [15.9, 0.1, 15.9, 0.1, 15.9, 0.1, 15.9, 0.1, 15.9, 0.1, 15.9, 0.1, 15.9]  # jitter at the wrap
    verdicts = [m.check_state(sample(t=0.1 * i, eta1=e)) for i, e in enumerate(etas)]
    assert verdicts[-1].kind is Breach.NO_PROGRESS


def test_setpoints_are_checked_before_they_leave() -> None:
    m = monitor(max_tilt_deg=45.0)
    assert not m.check_setpoint(q_cmd_enu_flu=about_x(40.0)).breach
    assert m.check_setpoint(q_cmd_enu_flu=about_x(50.0)).kind is Breach.SETPOINT
    assert not m.check_setpoint(accel_cmd_enu_m_s2=(9.0, 0.0, 0.0)).breach  # 42.5 deg
    assert m.check_setpoint(accel_cmd_enu_m_s2=(11.0, 0.0, 0.0)).kind is Breach.SETPOINT  # 48.3 deg
    assert m.check_setpoint(position_target_enu_m=(0.0, 0.0, 9.0)).kind is Breach.SETPOINT
    assert m.check_setpoint(rates_frd_rad_s=(math.nan, 0.0, 0.0)).kind is Breach.BODY_RATE


def test_body_rates_are_bounded_keeping_the_tilt_axis() -> None:
    m = monitor(max_body_rate_rad_s=4.0)
    assert m.bound_rates((1.0, -2.0, 3.0)) == ((1.0, -2.0, 3.0), False)
    rates, scaled = m.bound_rates((2.0, -8.0, 1.0))
    assert scaled and rates == pytest.approx((1.0, -4.0, 1.0))  # roll/pitch scaled together
    rates, scaled = m.bound_rates((1.0, 0.5, -9.0))
    assert scaled and rates == pytest.approx((1.0, 0.5, -4.0))  # yaw clipped alone


def test_a_fast_growing_tilt_beyond_the_demand_breaches_before_the_limit() -> None:
    m = monitor(max_tilt_deg=60.0, tilt_lookahead_s=0.1)
    rolling = np.array([4.0, 0.0, 0.0])  # 229 deg/s about body x: tilting further
    verdict = m.check_state(sample(q=about_x(40.0), rates=rolling, q_demand=about_x(30.0)))
    assert verdict.kind is Breach.TILT and "growing at 229 deg/s" in verdict.reason  # 40 + 23 > 60
    # the same motion towards a demanded 50 deg is a commanded manoeuvre, not an overshoot
    assert not monitor().check_state(sample(q=about_x(40.0), rates=rolling, q_demand=about_x(50.0))).breach
    # rolling back towards level is not tilting further
    assert not monitor().check_state(sample(q=about_x(40.0), rates=-rolling, q_demand=about_x(0.0))).breach
    for i in range(10):  # a steady 55 deg is inside
        assert not m.check_state(sample(t=0.01 * i, q=about_x(55.0), rates=np.zeros(3))).breach


def test_tilt_rate_from_attitude_and_body_rates() -> None:
    from pf_offboard.safety.envelope import tilt_rate_rad_s

    assert tilt_rate_rad_s(about_x(30.0), (1.0, 0.0, 0.0)) == pytest.approx(1.0)
    assert tilt_rate_rad_s(about_x(30.0), (-1.0, 0.0, 0.0)) == pytest.approx(-1.0)
    assert tilt_rate_rad_s(about_x(30.0), (0.0, 1.0, 0.0)) == pytest.approx(0.0, abs=1e-12)  # sideways
    assert tilt_rate_rad_s(LEVEL, (0.0, 2.0, 0.0)) == pytest.approx(2.0)


def test_tilt_of_a_quaternion() -> None:
    assert tilt_rad(LEVEL) == 0.0
    assert math.degrees(tilt_rad(about_x(30.0))) == pytest.approx(30.0)
    assert math.degrees(tilt_rad(about_x(180.0))) == pytest.approx(180.0)


def _config(safety: object) -> dict:
    return {"path": {"waypoints": [list(p) for p in SQUARE], "closed": True}, "safety": safety}


def test_safety_section_parses_with_defaults_and_values() -> None:
    assert parse_config(_config(None)).safety == SafetyConfig()
    cfg = parse_config(_config({"action": "land", "fence_shape": "cylinder", "fence_center_enu_m": [1, 2], "fence_radius_m": 9,
                                "max_tilt_deg": 45, "min_altitude_m": 1.0}))  # fmt: skip
    assert cfg.safety.action == "land" and cfg.safety.fence_center_enu_m == (1.0, 2.0) and cfg.safety.max_tilt_deg == 45.0


@pytest.mark.parametrize(
    ("safety", "field"),
    [
        ({"fence_min_enu_m": [0, 0, 0]}, "safety.fence_min_enu_m"),
        ({"fence_min_enu_m": [0, 0, 0], "fence_max_enu_m": [1, -1, 1]}, "safety.fence_max_enu_m"),
        ({"fence_radius_m": 3}, "safety.fence_radius_m"),
        ({"fence_center_enu_m": [0, 0, 0], "fence_radius_m": 3}, "safety.fence_center_enu_m[0]"),
        ({"max_tilt_deg": 0}, "safety.max_tilt_deg"),
        ({"max_tilt_deg": 1e400}, "safety.max_tilt_deg"),
        ({"action": "rtl"}, "safety.action"),
        ({"fence_shape": "sphere"}, "safety.fence_shape"),
        ({"enabled": "yes"}, "safety.enabled"),
        ({"min_altitude_m": 5, "max_altitude_m": 4}, "safety.max_altitude_m"),
        ({"no_such_key": 1}, "safety.no_such_key"),
        ([1, 2], "safety"),
    ],
)
def test_bad_safety_values_are_one_line_errors_naming_the_field(safety: object, field: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_config(yaml.safe_load(yaml.safe_dump(_config(safety))) if not isinstance(safety, list) else _config(safety))
    assert info.value.field == field, str(info.value)
    assert "\n" not in str(info.value)
