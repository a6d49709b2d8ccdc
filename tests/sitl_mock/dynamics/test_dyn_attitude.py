"""Attitude and rate setpoints: steps, body-rate feed-forward, tilt priority, sign conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dynhelpers import make_sim, tilt_rad

from sitl_mock.dynamics import AttitudeSetpoint, RateSetpoint, euler_to_quat, preset


@pytest.mark.parametrize(("name", "settle_s"), [("fast", 0.3), ("px4-default", 1.5)])
def test_attitude_step(name: str, settle_s: float) -> None:
    params = preset(name)
    sim = make_sim(params)
    sp = AttitudeSetpoint(euler_to_quat(0.3, -0.2, 0.0), params.hover_thrust)
    for _ in range(int(settle_s / 0.004)):
        s = sim.step(0.004, sp)
    roll, pitch, yaw = s.euler_rad
    assert roll == pytest.approx(0.3, abs=0.01)
    assert pitch == pytest.approx(-0.2, abs=0.01)
    assert abs(yaw) < 0.01
    np.testing.assert_allclose(s.q_sp_ned_frd, sp.q_ned_frd)


def _yaw_ramp_error(use_ff: bool) -> float:
    """Track yaw(t) = 1 rad/s · t; return the steady yaw lag (rad)."""
    params = preset("fast")
    sim = make_sim(params)
    rate = 1.0
    errs = []
    for i in range(500):
        t = (i + 1) * 0.004
        sp = AttitudeSetpoint(euler_to_quat(0.0, 0.0, rate * t), params.hover_thrust,
                              (0.0, 0.0, rate) if use_ff else None)
        s = sim.step(0.004, sp)
        if t > 1.0:
            errs.append(math.remainder(rate * t - s.euler_rad[2], 2 * math.pi))
    return float(np.mean(np.abs(errs)))


def test_body_rate_feed_forward_removes_tracking_lag() -> None:
    lag_without = _yaw_ramp_error(False)
    lag_with = _yaw_ramp_error(True)
    # Without FF a P attitude loop lags by rate / k_yaw; with FF the lag (nearly) vanishes.
    k_yaw = preset("fast").yaw.attitude_p_1_s
    assert lag_without == pytest.approx(1.0 / k_yaw, rel=0.2)
    assert lag_with < 0.1 * lag_without


def test_roll_rate_feed_forward_is_honoured() -> None:
    params = preset("fast")
    sim = make_sim(params)
    roll_rate = 2.0
    rates = []
    for i in range(100):  # roll ramp at 2 rad/s for 0.4 s with FF
        t = (i + 1) * 0.004
        s = sim.step(0.004, AttitudeSetpoint(euler_to_quat(roll_rate * t, 0.0, 0.0), params.hover_thrust,
                                             (roll_rate, 0.0, 0.0)))
        if t > 0.2:
            rates.append(s.rates_frd_rad_s[0])
    assert np.mean(rates) == pytest.approx(roll_rate, rel=0.02)
    assert s.euler_rad[0] == pytest.approx(0.8, abs=0.01)


def test_tilt_is_prioritised_over_yaw() -> None:
    params = preset("fast")
    sim = make_sim(params)
    sp = AttitudeSetpoint(euler_to_quat(0.3, 0.0, 1.5), params.hover_thrust)
    target_tilt = tilt_rad(np.array(sp.q_ned_frd))
    for _ in range(25):  # 0.1 s
        s = sim.step(0.004, sp)
    tilt_err = abs(tilt_rad(s.q_ned_frd) - target_tilt) / target_tilt
    yaw_err = abs(1.5 - s.euler_rad[2]) / 1.5
    assert tilt_err < 0.1
    assert yaw_err > 0.5


def test_rate_setpoint_tracks_rates_in_frd() -> None:
    params = preset("fast")
    sim = make_sim(params)
    for _ in range(100):
        s = sim.step(0.004, RateSetpoint((0.0, 0.0, 1.0), params.hover_thrust))
    assert s.rates_frd_rad_s[2] == pytest.approx(1.0, rel=0.02)
    assert s.euler_rad[2] > 0.3  # positive FRD yaw rate: nose turns right (towards east)
    sim = make_sim(params)
    for _ in range(25):
        s = sim.step(0.004, RateSetpoint((1.0, 0.0, 0.0), params.hover_thrust))
    assert s.rates_frd_rad_s[0] == pytest.approx(1.0, rel=0.05)
    assert s.euler_rad[0] > 0.05  # positive roll: right side down
    np.testing.assert_allclose(s.rates_sp_frd_rad_s, (1.0, 0.0, 0.0))


def test_positive_pitch_accelerates_backwards() -> None:
    params = preset("fast")
    sim = make_sim(params)
    for _ in range(100):
        s = sim.step(0.004, AttitudeSetpoint(euler_to_quat(0.0, 0.2, 0.0), params.hover_thrust))
    assert s.velocity_ned_m_s[0] < -0.3  # nose up tilts thrust towards -x (south)
