"""Rigid-body physics: free fall, conservation, ground contact, landing."""

from __future__ import annotations

import numpy as np
import pytest
from dynhelpers import G, make_sim, rotation_matrix

from sitl_mock.dynamics import AccelerationSetpoint, MotorsOff, PositionSetpoint, Spawn, preset


def test_free_fall_matches_g(preset_name: str) -> None:
    params = preset(preset_name).with_(drag_1_s=0.0)
    sim = make_sim(params, Spawn.thrown((0.0, 0.0, -100.0), (0.0, 0.0, 0.0)))
    for _ in range(2000):  # 2 s in 1 ms steps
        s = sim.step(0.001, MotorsOff())
        t = s.time_s
        assert s.position_ned_m[2] == pytest.approx(-100.0 + 0.5 * G * t * t, abs=1e-9)
        assert s.velocity_ned_m_s[2] == pytest.approx(G * t, abs=1e-9)
    np.testing.assert_allclose(s.accel_ned_m_s2, (0.0, 0.0, G), atol=1e-12)
    # An accelerometer in free fall reads zero.
    np.testing.assert_allclose(s.specific_force_frd_m_s2, 0.0, atol=1e-12)
    assert not s.motors_on and np.all(s.motor_thrust_n == 0.0)


def test_ballistic_flight_conserves_energy_without_drag() -> None:
    params = preset("fast").with_(drag_1_s=0.0)
    sim = make_sim(params, Spawn.thrown((0.0, 0.0, -300.0), (3.0, -2.0, -5.0), rates_frd_rad_s=(1.0, 2.0, 0.5)))

    def energy(s) -> float:  # per unit mass; NED: height = -z
        return 0.5 * float(s.velocity_ned_m_s @ s.velocity_ned_m_s) - G * float(s.position_ned_m[2])

    e0 = energy(sim.state())
    for _ in range(750):  # 3 s
        s = sim.step(0.004, MotorsOff())
        assert abs(energy(s) - e0) <= 1e-9 * e0
    # And the trajectory is the parabola.
    np.testing.assert_allclose(s.position_ned_m, (9.0, -6.0, -300.0 - 15.0 + 0.5 * G * 9.0), atol=1e-8)


def test_torque_free_spinning_body_conserves_energy_and_momentum() -> None:
    inertia = np.array([1e-3, 2e-3, 3e-3])  # all different: full Euler precession
    params = preset("fast").with_(drag_1_s=0.0, inertia_xx_kg_m2=inertia[0], inertia_yy_kg_m2=inertia[1],
                                  inertia_zz_kg_m2=inertia[2])
    sim = make_sim(params, Spawn.thrown((0.0, 0.0, -1e6), (0.0, 0.0, 0.0), rates_frd_rad_s=(2.0, 0.5, 3.0)))

    def invariants(s):
        w = s.rates_frd_rad_s
        body_l = inertia * w
        return 0.5 * float(inertia @ (w * w)), float(np.linalg.norm(body_l)), rotation_matrix(s.q_ned_frd) @ body_l

    e0, l0, lw0 = invariants(sim.state())
    for _ in range(2500):  # 10 s
        s = sim.step(0.004, MotorsOff())
    e, l_norm, lw = invariants(s)
    assert not np.allclose(s.rates_frd_rad_s, (2.0, 0.5, 3.0), atol=0.1)  # it did precess
    assert e / e0 - 1.0 < 1e-6  # no energy created
    assert abs(e / e0 - 1.0) < 1e-5
    assert abs(l_norm / l0 - 1.0) < 1e-5
    # World-frame angular momentum is constant too (checks the attitude integration).
    assert np.linalg.norm(lw - lw0) / l0 < 1e-4
    assert abs(np.linalg.norm(s.q_ned_frd) - 1.0) < 1e-9


def test_resting_on_the_ground(preset_name: str) -> None:
    sim = make_sim(preset_name, Spawn.ground((3.0, 4.0, 0.0), yaw_rad=0.5))
    s = sim.state()
    assert s.landed
    for _ in range(500):
        s = sim.step(0.004, MotorsOff())
        assert s.position_ned_m[2] == 0.0
        assert s.landed and not s.crashed
    np.testing.assert_array_equal(s.position_ned_m, (3.0, 4.0, 0.0))
    np.testing.assert_array_equal(s.velocity_ned_m_s, 0.0)
    assert s.euler_rad[2] == pytest.approx(0.5, abs=1e-12)


@pytest.mark.parametrize(("height_m", "crash"), [(0.2, False), (1.0, True)])
def test_drop_onto_the_ground(height_m: float, crash: bool) -> None:
    params = preset("fast")
    sim = make_sim(params, Spawn.thrown((0.0, 0.0, -height_m), (0.0, 0.0, 0.0)))
    max_z = -np.inf
    for _ in range(1000):
        s = sim.step(0.002, MotorsOff())
        max_z = max(max_z, s.position_ned_m[2])
    assert max_z <= 0.0  # never below the ground
    assert s.position_ned_m[2] == 0.0 and s.landed
    impact = np.sqrt(2 * G * height_m)
    assert (impact > params.crash_speed_m_s) == crash
    assert s.crashed == crash


def test_fast_descent_into_ground_is_a_crash() -> None:
    sim = make_sim("fast", Spawn.thrown((0.0, 0.0, -0.5), (2.0, 0.0, 5.0)))
    for _ in range(100):
        s = sim.step(0.004, MotorsOff())
    assert s.crashed and s.landed and s.position_ned_m[2] == 0.0
    # Ground friction stops the sliding.
    assert np.linalg.norm(s.velocity_ned_m_s) < 1e-9


def test_takeoff_from_the_ground() -> None:
    sim = make_sim("fast", Spawn.ground())
    for _ in range(100):
        sim.step(0.004, MotorsOff())
    for _ in range(250):
        s = sim.step(0.004, AccelerationSetpoint((0.0, 0.0, -1.0), yaw_rad=0.0))
    assert not s.landed
    assert s.position_ned_m[2] < -0.3


def test_position_setpoint_below_ground_lands_gently(preset_name: str) -> None:
    params = preset(preset_name)
    sim = make_sim(params, Spawn.hover((1.0, 1.0, -3.0)))
    sp = PositionSetpoint((1.0, 1.0, 1.0))  # 1 m below the ground: land
    vz_max = 0.0
    for _ in range(3000):
        s = sim.step(0.004, sp)
        vz_max = max(vz_max, s.velocity_ned_m_s[2])
        if s.landed:
            break
    assert s.landed and not s.crashed
    assert vz_max <= params.land_speed_m_s * 1.2
    np.testing.assert_allclose(s.position_ned_m, (1.0, 1.0, 0.0), atol=0.05)


def test_position_setpoint_holds_position(preset_name: str) -> None:
    sim = make_sim(preset_name, Spawn.hover((0.0, 0.0, -2.0)))
    sp = PositionSetpoint((1.0, -2.0, -4.0), yaw_rad=0.3)
    for _ in range(3000):  # 12 s
        s = sim.step(0.004, sp)
    np.testing.assert_allclose(s.position_ned_m, (1.0, -2.0, -4.0), atol=0.02)
    assert np.linalg.norm(s.velocity_ned_m_s) < 0.02
    assert s.euler_rad[2] == pytest.approx(0.3, abs=0.01)


def test_position_setpoint_takes_off_from_the_ground() -> None:
    sim = make_sim("px4-default", Spawn.ground())
    sp = PositionSetpoint((0.0, 0.0, -2.5))
    for _ in range(2500):
        s = sim.step(0.004, sp)
    assert not s.landed
    assert s.position_ned_m[2] == pytest.approx(-2.5, abs=0.05)
