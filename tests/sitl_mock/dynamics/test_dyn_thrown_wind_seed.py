"""Thrown spawn, recovery, wind and gusts, sensors, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from dynhelpers import G, make_sim, tilt_rad

from sitl_mock.dynamics import (
    AccelerationSetpoint,
    AttitudeSetpoint,
    Gust,
    MotorsOff,
    SensorNoise,
    Spawn,
    Wind,
    euler_to_quat,
    preset,
)


def _thrown() -> Spawn:
    return Spawn.thrown((0.0, 0.0, -20.0), (4.0, 1.0, -6.0), rates_frd_rad_s=(4.0, -3.0, 2.0),
                        q_ned_frd=euler_to_quat(0.4, -0.3, 1.0))


def test_thrown_is_ballistic_until_commanded() -> None:
    params = preset("fast")
    c = params.drag_1_s
    sim = make_sim(params, _thrown())
    v0 = np.array([4.0, 1.0, -6.0])
    for _ in range(250):  # 1 s of MotorsOff
        s = sim.step(0.004, MotorsOff())
        t = s.time_s
        # Closed form with linear drag and gravity along +z (NED).
        e = np.exp(-c * t)
        p = v0 * (1 - e) / c + np.array([0.0, 0.0, G / c]) * (t - (1 - e) / c) + (0.0, 0.0, -20.0)
        np.testing.assert_allclose(s.position_ned_m, p, atol=1e-9)
        assert not s.motors_on and np.all(s.motor_thrust_n == 0.0)
        assert not s.landed


@pytest.mark.parametrize("command", ["attitude", "acceleration"])
def test_thrown_recovers_level_when_commanded(command: str) -> None:
    params = preset("fast")
    sim = make_sim(params, _thrown())
    for _ in range(50):  # 0.2 s tumbling
        s = sim.step(0.004, MotorsOff())
    assert tilt_rad(s.q_ned_frd) > 0.3
    if command == "attitude":
        sp = AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), params.hover_thrust)
    else:
        sp = AccelerationSetpoint((0.0, 0.0, 0.0))
    for _ in range(250):  # 1 s
        s = sim.step(0.004, sp)
    assert s.motors_on
    assert tilt_rad(s.q_ned_frd) < 0.02
    assert np.linalg.norm(s.rates_frd_rad_s) < 0.05
    assert not s.landed and not s.crashed
    # Recovered in the air: the vertical velocity decays only through drag (no thrust bias).
    vz_before = s.velocity_ned_m_s[2]
    for _ in range(250):
        s = sim.step(0.004, sp)
    assert abs(s.velocity_ned_m_s[2]) <= abs(vz_before) + 1e-3


def test_wind_pushes_the_vehicle(preset_name: str) -> None:
    calm = make_sim(preset_name)
    windy = make_sim(preset_name, wind=Wind(mean_ned_m_s=(3.0, 0.0, 0.0)))
    sp = AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=0.0)
    for _ in range(750):
        s_calm = calm.step(0.004, sp)
        s_windy = windy.step(0.004, sp)
    np.testing.assert_allclose(s_calm.position_ned_m, (0.0, 0.0, -10.0), atol=1e-9)
    # Open-loop acceleration hold: drag drives the vehicle towards the wind speed.
    c = preset(preset_name).drag_1_s
    expected_vx = 3.0 * (1 - np.exp(-c * 3.0))
    assert s_windy.velocity_ned_m_s[0] == pytest.approx(expected_vx, rel=0.01)
    assert abs(s_windy.position_ned_m[1]) < 1e-9
    np.testing.assert_allclose(s_windy.wind_ned_m_s, (3.0, 0.0, 0.0))


def test_gust_acts_only_during_its_window() -> None:
    sim = make_sim("fast")
    sim.add_gust(1.0, 1.0, (0.0, 5.0, 0.0))
    sp = AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=0.0)
    peak = 0.0
    for _ in range(250):
        s = sim.step(0.004, sp)
    assert s.position_ned_m[1] == 0.0
    for _ in range(250):
        s = sim.step(0.004, sp)
        peak = max(peak, s.wind_ned_m_s[1])
    assert peak == pytest.approx(5.0, rel=0.01)
    assert s.position_ned_m[1] > 0.1
    s = sim.step(0.02, sp)  # wind is sampled at the attitude-loop rate
    np.testing.assert_allclose(s.wind_ned_m_s, 0.0, atol=1e-9)


def test_wind_object_gusts_and_set_wind() -> None:
    sim = make_sim("fast")
    sim.set_wind(Wind(mean_ned_m_s=(0.0, -1.0, 0.0), gusts=(Gust(0.0, 0.5, (2.0, 0.0, 0.0)),)))
    sim.add_gust(0.0, 0.5, (0.0, 0.0, -1.0))
    sim.set_wind(Wind(mean_ned_m_s=(0.0, -1.0, 0.0), gusts=(Gust(0.0, 0.5, (2.0, 0.0, 0.0)),)))  # replaces
    s = sim.step(0.252, AccelerationSetpoint((0.0, 0.0, 0.0)))
    assert s.wind_ned_m_s[0] == pytest.approx(2.0, rel=0.02)  # the Wind's gust, once
    assert s.wind_ned_m_s[1] == pytest.approx(-1.0)
    assert s.wind_ned_m_s[2] == pytest.approx(-1.0, rel=0.02)  # add_gust survives set_wind


def _run(seed: int, measure_every_step: bool = True) -> tuple[np.ndarray, np.ndarray]:
    sim = make_sim("fast", seed=seed, wind=Wind(turbulence_std_m_s=1.0, turbulence_time_constant_s=0.5),
                   noise=SensorNoise(position_std_m=0.05, velocity_std_m_s=0.1, attitude_std_rad=0.01,
                                     rates_std_rad_s=0.02, accel_std_m_s2=0.2, delay_s=0.02))
    truth, meas = [], []
    sp = AccelerationSetpoint((0.5, 0.0, 0.0), yaw_rad=0.0)
    for _ in range(500):
        s = sim.step(0.004, sp)
        truth.append(np.concatenate([s.position_ned_m, s.velocity_ned_m_s, s.q_ned_frd]))
        if measure_every_step:
            m = sim.measure()
            meas.append(np.concatenate([m.position_ned_m, m.velocity_ned_m_s, m.q_ned_frd]))
    return np.array(truth), np.array(meas)


def test_same_seed_same_trajectory_different_seed_differs() -> None:
    t1, m1 = _run(7)
    t2, m2 = _run(7)
    np.testing.assert_array_equal(t1, t2)
    np.testing.assert_array_equal(m1, m2)
    t3, m3 = _run(8)
    assert np.max(np.abs(t1 - t3)) > 1e-3  # turbulence differs
    assert np.max(np.abs(m1 - m3)) > 1e-3  # sensor noise differs


def test_measuring_does_not_change_the_trajectory() -> None:
    t1, _ = _run(3, measure_every_step=True)
    t2, _ = _run(3, measure_every_step=False)
    np.testing.assert_array_equal(t1, t2)


def test_measure_is_delayed_and_noisy() -> None:
    sim = make_sim("fast", noise=SensorNoise(position_std_m=0.1, delay_s=0.02))
    errs = []
    for _ in range(2000):
        s = sim.step(0.004, AccelerationSetpoint((0.0, 0.0, 0.0)))
        m = sim.measure()
        assert m.time_s == pytest.approx(max(0.0, s.time_s - 0.02), abs=1e-9)
        errs.append(m.position_ned_m - s.position_ned_m)  # hovering: the truth does not move
    errs = np.array(errs)
    assert np.std(errs) == pytest.approx(0.1, rel=0.05)
    assert abs(np.mean(errs)) < 0.01
    np.testing.assert_array_equal(sim.state().position_ned_m, (0.0, 0.0, -10.0))


def test_noise_free_measure_is_the_truth() -> None:
    sim = make_sim("fast")
    s = sim.step(0.1, AccelerationSetpoint((1.0, 0.0, 0.0)))
    m = sim.measure()
    np.testing.assert_array_equal(m.position_ned_m, s.position_ned_m)
    np.testing.assert_array_equal(m.q_ned_frd, s.q_ned_frd)
