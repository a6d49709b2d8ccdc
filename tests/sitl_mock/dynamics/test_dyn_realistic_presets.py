"""The realistic presets (px4-sih, arducopter): documented inner loops, no limit cycles, the
deliberate hover-thrust mismatch of px4-sih."""

from __future__ import annotations

import numpy as np
import pytest
from dynhelpers import G, make_sim

from sitl_mock.dynamics import AccelerationSetpoint, Spawn, VehicleParams, preset
from sitl_mock.dynamics.estimator import EstimatorNoise
from sitl_mock.dynamics.identify import accel_step_rise_time_s, attitude_bandwidth_hz

# docs/sitl-mock-dynamics.md, "Measured inner loops" (latency off, exact hover thrust).
DOCUMENTED = {
    "px4-sih": {"horizontal": 0.182, "vertical": 0.054, "bandwidth_hz": 1.18},
    "arducopter": {"horizontal": 0.226, "vertical": 0.020, "bandwidth_hz": 0.99},
}


def _inner(name: str) -> VehicleParams:
    p = preset(name)
    return p.with_(setpoint_latency_s=0.0, thrust_latency_s=None, hover_thrust=p.true_hover_thrust, estimator=EstimatorNoise())


@pytest.mark.parametrize("name", sorted(DOCUMENTED))
def test_inner_loop_figures_match_the_documentation(name: str) -> None:
    p = _inner(name)
    doc = DOCUMENTED[name]
    assert accel_step_rise_time_s(p, (0.2, 0.0, 0.0)) == pytest.approx(doc["horizontal"], rel=0.1)
    assert accel_step_rise_time_s(p, (0.0, 0.0, -0.5)) == pytest.approx(doc["vertical"], rel=0.1)
    assert attitude_bandwidth_hz(p) == pytest.approx(doc["bandwidth_hz"], rel=0.1)


@pytest.mark.parametrize("name", sorted(DOCUMENTED))
def test_no_limit_cycles_after_aggressive_random_acceleration_setpoints(name: str) -> None:
    rng = np.random.default_rng(4)
    sim = make_sim(preset(name), Spawn.hover((0.0, 0.0, -1000.0)))
    for _ in range(8):
        sp = AccelerationSetpoint(tuple(rng.uniform(-4.0, 4.0, 3)), yaw_rad=0.0)
        for _ in range(500):  # 2 s: these loops are slower than fast's
            s = sim.step(0.004, sp)
        assert np.max(np.abs(s.rates_frd_rad_s)) < 0.05


def test_px4_sih_climbs_on_a_zero_acceleration_setpoint_like_the_real_one() -> None:
    """MPC_THR_HOVER 0.5 against a true hover throttle of 0.490: +2 % thrust, ~0.19 m/s² up."""
    p = preset("px4-sih").with_(estimator=EstimatorNoise(), drag_1_s=0.0)
    sim = make_sim(p, Spawn.hover((0.0, 0.0, -50.0)))
    for _ in range(500):  # 2 s
        s = sim.step(0.004, AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=0.0))
    expected_up = G * (p.hover_thrust / p.true_hover_thrust - 1.0)
    assert -s.accel_ned_m_s2[2] == pytest.approx(expected_up, rel=0.02)
    assert 0.15 < expected_up < 0.25
