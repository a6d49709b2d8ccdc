"""The reported-state error (EKF-like) and the setpoint latency of the realistic presets."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sitl_mock.dynamics import AccelerationSetpoint, PositionSetpoint, RateSetpoint, Simulator, Spawn, preset
from sitl_mock.dynamics.estimator import EstimatorError, EstimatorNoise


def _hold(seed: int, duration_s: float, step_s: float = 0.02) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """px4-sih holding a point with its own position controller: times, reported − true pos, vel."""
    sim = Simulator(preset("px4-sih"), np.random.default_rng(seed), Spawn.hover((0.0, 0.0, -2.0)))
    sp = PositionSetpoint((0.0, 0.0, -2.0), yaw_rad=0.0)
    t, ep, ev = [], [], []
    for _ in range(int(round(duration_s / step_s))):
        sim.step(step_s, sp)
        e_p, e_v = sim.estimate_error()
        t.append(sim.time_s)
        ep.append(e_p)
        ev.append(e_v)
    return np.array(t), np.array(ep), np.array(ev)


def test_wander_in_hold_is_as_on_px4_sih() -> None:
    # PX4 SIH: 0.4–0.9 m peak-to-peak of the reported position in hold (per minute).
    p2p = []
    for seed in range(6):
        _, ep, _ = _hold(seed, 60.0, step_s=0.05)
        p2p.append(float(np.ptp(ep[:, :2], axis=0).max()))
    assert 0.4 <= float(np.median(p2p)) <= 0.9, p2p
    assert max(p2p) < 1.5


def test_error_steps_at_the_fusion_rate_and_is_deterministic() -> None:
    t, ep, ev = _hold(3, 4.0, step_s=0.01)
    changed = np.any(np.diff(ep, axis=0) != 0.0, axis=1)
    change_times = t[1:][changed]
    # 10 Hz fusion: the error changes at (and only at) multiples of 0.1 s.
    np.testing.assert_allclose(change_times * 10.0, np.round(change_times * 10.0), atol=1e-6)
    assert 35 <= len(change_times) <= 40
    # Velocity error: EKF-like, a few cm/s.
    assert 0.005 < float(np.std(ev[:, :2])) < 0.1
    t2, ep2, ev2 = _hold(3, 4.0, step_s=0.01)
    np.testing.assert_array_equal(ep, ep2)
    np.testing.assert_array_equal(ev, ev2)
    _, ep3, _ = _hold(4, 4.0, step_s=0.01)
    assert not np.array_equal(ep, ep3)


def test_error_does_not_depend_on_the_callers_step() -> None:
    noise = preset("px4-sih").estimator
    a = EstimatorError(noise, np.random.default_rng(7))
    b = EstimatorError(noise, np.random.default_rng(7))
    for k in range(1, 101):  # 10 s in 0.1 s vs 1 s steps
        a.advance_to(k * 0.1)
    for k in range(1, 11):
        b.advance_to(k * 1.0)
    assert a.position_error_ned_m == b.position_error_ned_m
    assert a.velocity_error_ned_m_s == b.velocity_error_ned_m_s


def test_velocity_bias_is_not_in_the_position_and_leaves_the_other_draws_alone() -> None:
    """px4-sih's velocity bias (EKF2 on SIH: velocity 10-40 cm/s off its position's derivative):
    the reported velocity minus the wander that moves the position has the configured std
    (xy 0.15, z 0.10 m/s, within the sampling error of 20 time constants); the position error is the
    same draw for draw as without the bias (its own generator)."""
    noise = preset("px4-sih").estimator
    assert noise.velocity_bias_std_xy_m_s == 0.15 and noise.velocity_bias_std_z_m_s == 0.10
    plain = dataclasses.replace(noise, velocity_bias_std_xy_m_s=0.0, velocity_bias_std_z_m_s=0.0)
    biased, unbiased = EstimatorError(noise, np.random.default_rng(5)), EstimatorError(plain, np.random.default_rng(5))
    bias = []
    for k in range(1, 1601):  # 160 s at the 10 Hz fusion rate: 20 time constants
        biased.advance_to(k * 0.1)
        unbiased.advance_to(k * 0.1)
        assert biased.position_error_ned_m == unbiased.position_error_ned_m
        bias.append(np.subtract(biased.velocity_error_ned_m_s, unbiased.velocity_error_ned_m_s))
    std = np.sqrt(np.mean(np.square(bias), axis=0))
    assert std[:2] == pytest.approx([0.15, 0.15], rel=0.5) and std[2] == pytest.approx(0.10, rel=0.5)


def test_measure_reports_the_estimate_and_the_truth_is_untouched() -> None:
    params = preset("px4-sih")
    truth_only = Simulator(params.with_(estimator=EstimatorNoise()), np.random.default_rng(1), Spawn.hover((0, 0, -2)))
    noisy = Simulator(params, np.random.default_rng(1), Spawn.hover((0, 0, -2)))
    sp = AccelerationSetpoint((0.3, 0.0, 0.0), yaw_rad=0.0)
    for _ in range(250):
        a = truth_only.step(0.004, sp)
        b = noisy.step(0.004, sp)
    np.testing.assert_array_equal(a.position_ned_m, b.position_ned_m)  # same physics, same seed
    m = noisy.measure()
    ep, ev = noisy.estimate_error()
    np.testing.assert_allclose(m.position_ned_m, b.position_ned_m + ep)
    np.testing.assert_allclose(m.velocity_ned_m_s, b.velocity_ned_m_s + ev)
    assert np.linalg.norm(ep) > 0.0
    assert truth_only.estimate_error() == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def test_setpoint_latency_is_a_pure_delay() -> None:
    # Exact hover thrust: a state at rest stays at rest, so a later start is the same response.
    params = preset("px4-sih")
    base = params.with_(estimator=EstimatorNoise(), hover_thrust=params.true_hover_thrust)
    late = Simulator(base, np.random.default_rng(0), Spawn.hover((0, 0, -5)))
    now = Simulator(base.with_(setpoint_latency_s=0.0), np.random.default_rng(0), Spawn.hover((0, 0, -5)))
    step = AccelerationSetpoint((1.0, 0.0, 0.0), yaw_rad=0.0)
    hold = AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=0.0)
    ax_late, ax_now = [], []
    for k in range(300):  # 1.2 s: the step given at 0.2 s
        sp = step if k >= 50 else hold
        ax_late.append(late.step(0.004, sp).accel_ned_m_s2[0])
        ax_now.append(now.step(0.004, sp).accel_ned_m_s2[0])
    shift = int(round(base.setpoint_latency_s / 0.004))
    assert shift == 15
    np.testing.assert_allclose(ax_late[shift + 50:], ax_now[50:-shift], atol=1e-9)
    assert max(abs(a) for a in ax_late[: 50 + shift]) < 1e-6


@pytest.mark.parametrize("field", ["fusion_rate_hz", "wander_velocity_std_xy_m_s", "position_white_std_z_m"])
def test_bad_estimator_noise_is_named(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        EstimatorNoise(**{field: -1.0})


def test_rate_loop_rate_and_output_delay() -> None:
    """px4-sih: rate loop at 250 Hz (commands held 4 ms) and its output applied one tick late."""
    params = preset("px4-sih").with_(estimator=EstimatorNoise(), setpoint_latency_s=0.0)
    assert (params.rate_loop_hz, params.rate_loop_delay_s) == (250.0, 0.004)
    step = RateSetpoint((1.0, 0.0, 0.0), params.true_hover_thrust)

    def motors(p: object) -> np.ndarray:
        sim = Simulator(p, np.random.default_rng(0), Spawn.hover((0, 0, -5)))  # type: ignore[arg-type]
        return np.array([sim.step(0.001, step).motor_thrust_n for _ in range(12)])

    hover = params.weight_n / 4.0
    delayed = motors(params)
    np.testing.assert_allclose(delayed[:4], hover, rtol=1e-12)  # ticks 1-4: the old command
    assert abs(delayed[4, 0] - hover) > 1e-4  # tick 5: the first rate-loop command arrives
    prompt = motors(params.with_(rate_loop_delay_s=0.0))
    assert abs(prompt[0, 0] - hover) > 1e-4
    # Held between rate ticks: the motors move towards one command for 4 ticks (first-order lag).
    gap = prompt[:4, 0] - prompt[0, 0]
    assert np.all(np.diff(np.abs(gap)) > 0)
    with pytest.raises(ValueError, match="rate_loop_hz"):
        params.with_(rate_loop_hz=300.0)
    with pytest.raises(ValueError, match="rate_loop_delay_s"):
        params.with_(rate_loop_delay_s=-0.001)
