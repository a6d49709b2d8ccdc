"""Hover, acceleration-setpoint tracking and the documented inner-loop time constants."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dynhelpers import G, make_sim, tilt_rad

from sitl_mock.dynamics import AccelerationSetpoint, Spawn, preset
from sitl_mock.dynamics.identify import accel_step_rise_time_s, attitude_bandwidth_hz

# The figures documented in docs/sitl-mock-dynamics.md ("Measured inner loops").
DOCUMENTED_RISE_S = {
    ("fast", "vertical"): 0.015,
    ("fast", "horizontal"): 0.019,
    ("px4-default", "vertical"): 0.030,
    ("px4-default", "horizontal"): 0.150,
}
DOCUMENTED_ATTITUDE_BANDWIDTH_HZ = {"fast": 26.8, "px4-default": 1.2}


def test_hover_at_hover_thrust_holds_altitude(preset_name: str) -> None:
    sim = make_sim(preset_name, Spawn.hover((1.0, -2.0, -5.0), yaw_rad=0.7))
    sp = AccelerationSetpoint((0.0, 0.0, 0.0))  # yaw None: hold the current heading
    for _ in range(2500):  # 10 s at 250 Hz
        s = sim.step(0.004, sp)
    assert s.time_s == pytest.approx(10.0)
    assert np.max(np.abs(s.position_ned_m - (1.0, -2.0, -5.0))) < 1e-6
    assert np.max(np.abs(s.velocity_ned_m_s)) < 1e-6
    assert s.euler_rad[2] == pytest.approx(0.7, abs=1e-6)
    assert s.thrust_norm_actual == pytest.approx(sim.params.hover_thrust, rel=1e-6)
    assert not s.landed and not s.crashed


@pytest.mark.parametrize("direction", ["vertical", "horizontal"])
def test_accel_step_rise_time_matches_documentation(preset_name: str, direction: str) -> None:
    step = (0.0, 0.0, -0.5) if direction == "vertical" else (0.2, 0.0, 0.0)
    rise = accel_step_rise_time_s(preset(preset_name), step)
    assert rise == pytest.approx(DOCUMENTED_RISE_S[(preset_name, direction)], rel=0.1)


def test_fast_preset_inner_loop_is_faster_than_the_paper_needs() -> None:
    # Transversal loop of the paper: 6 Hz. The attitude loop must be several times faster.
    bw = attitude_bandwidth_hz(preset("fast"))
    assert bw == pytest.approx(DOCUMENTED_ATTITUDE_BANDWIDTH_HZ["fast"], abs=1.0)
    assert bw >= 25.0


def test_px4_default_attitude_bandwidth_documented() -> None:
    assert attitude_bandwidth_hz(preset("px4-default")) == pytest.approx(
        DOCUMENTED_ATTITUDE_BANDWIDTH_HZ["px4-default"], abs=0.3)


@pytest.mark.parametrize("decouple", [False, True])
def test_acceleration_setpoint_is_reached_without_bias(preset_name: str, decouple: bool) -> None:
    """Thrust acceleration (kinematic plus drag) equals the setpoint in steady state; with PX4's
    MPC_ACC_DECOUPLE the horizontal part is scaled by (g - a_z)/g, the vertical part exact."""
    params = preset(preset_name).with_(accel_decouple=decouple)
    sim = make_sim(params)
    target = np.array([1.0, -0.5, -0.3])
    sp = AccelerationSetpoint(tuple(target), yaw_rad=0.0)
    for _ in range(500):  # 2 s
        s = sim.step(0.004, sp)
    thrust_acc = s.accel_ned_m_s2 + params.drag_1_s * s.velocity_ned_m_s
    expected = target.copy()
    if decouple:
        expected[:2] *= (G - target[2]) / G
    np.testing.assert_allclose(thrust_acc, expected, atol=2e-3)


def test_acceleration_mapping_respects_tilt_limit_and_thrust_floor() -> None:
    params = preset("px4-default")
    sim = make_sim(params)
    for _ in range(500):
        s = sim.step(0.004, AccelerationSetpoint((30.0, 0.0, 0.0), yaw_rad=0.0))
    assert tilt_rad(s.q_ned_frd) == pytest.approx(params.tilt_max_rad, abs=0.01)
    assert tilt_rad(s.q_sp_ned_frd) == pytest.approx(params.tilt_max_rad, abs=1e-9)
    # Collective = hover / cos(tilt) while the vertical demand is zero.
    assert s.thrust_norm_sp == pytest.approx(params.hover_thrust / math.cos(params.tilt_max_rad), rel=1e-9)
    # Free-fall demand: the thrust floor holds.
    s = sim.step(0.004, AccelerationSetpoint((0.0, 0.0, 2 * G), yaw_rad=0.0))
    assert s.thrust_norm_sp == pytest.approx(params.thrust_min_norm)


def test_yaw_setpoint_and_yaw_rate_hold() -> None:
    sim = make_sim("fast")
    for _ in range(500):
        s = sim.step(0.004, AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=1.0))
    assert s.euler_rad[2] == pytest.approx(1.0, abs=5e-3)
    # yaw None + yaw rate: the held heading advances at the rate.
    for _ in range(250):  # 1 s at 0.5 rad/s
        s = sim.step(0.004, AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=None, yaw_rate_rad_s=0.5))
    assert s.euler_rad[2] == pytest.approx(1.5, abs=0.05)
    assert abs(s.position_ned_m[2] + 10.0) < 0.01


def test_thrust_lead_shortens_the_vertical_lag() -> None:
    params = preset("fast")
    plain = accel_step_rise_time_s(params, (0.0, 0.0, -0.5))
    led = accel_step_rise_time_s(params.with_(thrust_lead=2.0), (0.0, 0.0, -0.5))
    assert plain == pytest.approx(params.motor_time_constant_s, rel=0.02)
    assert led == pytest.approx(params.motor_time_constant_s / 3.0, rel=0.1)


def test_no_limit_cycles_after_aggressive_random_acceleration_setpoints(preset_name: str) -> None:
    """Motor saturation must not leave the inner loops oscillating: after each of a series of
    large random acceleration steps, the body rates settle to zero."""
    # Seed 4 limit-cycles within 5 steps when the fast preset's poles are pushed to -300 rad/s.
    rng = np.random.default_rng(4)
    sim = make_sim(preset_name, Spawn.hover((0.0, 0.0, -1000.0)))
    for _ in range(12):
        sp = AccelerationSetpoint(tuple(rng.uniform(-4.0, 4.0, 3)), yaw_rad=0.0)
        for _ in range(375):  # 1.5 s
            s = sim.step(0.004, sp)
        assert np.max(np.abs(s.rates_frd_rad_s)) < 0.02  # a limit cycle is ~1 rad/s
