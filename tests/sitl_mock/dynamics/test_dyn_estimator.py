"""The reported-state error (EKF-like) and the setpoint latency of the realistic presets."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sitl_mock.dynamics import AccelerationSetpoint, AttitudeSetpoint, PositionSetpoint, RateSetpoint, Setpoint, Simulator, Spawn, VehicleParams, preset
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
    # 10 Hz fusion: the velocity error changes at (and only at) multiples of 0.1 s ...
    changed = np.any(np.diff(ev, axis=0) != 0.0, axis=1)
    change_times = t[1:][changed]
    np.testing.assert_allclose(change_times * 10.0, np.round(change_times * 10.0), atol=1e-6)
    assert 35 <= len(change_times) <= 40
    # ... the position error, through EKF2's output predictor, moves at every step after the first
    moved = np.any(np.diff(ep, axis=0) != 0.0, axis=1)
    assert not np.any(moved[t[1:] < 0.1 - 1e-9]) and np.all(moved[t[1:] > 0.1 + 1e-9])
    # Velocity error: EKF-like, a few cm/s.
    assert 0.005 < float(np.std(ev[:, :2])) < 0.1
    t2, ep2, ev2 = _hold(3, 4.0, step_s=0.01)
    np.testing.assert_array_equal(ep, ep2)
    np.testing.assert_array_equal(ev, ev2)
    _, ep3, _ = _hold(4, 4.0, step_s=0.01)
    assert not np.array_equal(ep, ep3)


def test_output_predictor_spreads_each_fused_position_step() -> None:
    """Without the output predictor the position error steps at each fusion and holds; with it, it
    covers 1 - exp(-h / tau) of the way to each fused value after h, and the velocity is the same."""
    base = preset("px4-sih").estimator
    stepped = EstimatorError(dataclasses.replace(base, output_time_constant_s=0.0), np.random.default_rng(5))
    smooth = EstimatorError(base, np.random.default_rng(5))
    tau = base.output_time_constant_s
    for k in range(1, 31):  # 3 s: each fusion, then 0.05 s later
        for h in (0.0, 0.05):
            t = k * 0.1 + h
            before = smooth.position_error_ned_m
            stepped.advance_to(t)
            smooth.advance_to(t)
            assert smooth.velocity_error_ned_m_s == stepped.velocity_error_ned_m_s
            if h > 0.0:  # the fused value (stepped's) was set at k * 0.1: an exact first-order step
                want = np.asarray(stepped.position_error_ned_m) + (np.asarray(before) - stepped.position_error_ned_m) * math.exp(-h / tau)
                np.testing.assert_allclose(smooth.position_error_ned_m, want, rtol=0, atol=1e-12)
    assert smooth.position_error_ned_m != stepped.position_error_ned_m


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
    the reported velocity minus the wander that moves the position has the configured std (xy 0.20,
    z 0.10 m/s, times sqrt(τ_b / (τ_b + τ_s)) for the smoothing; within the sampling error of 40 time
    constants); the position error is the same draw for draw as without the bias (its own generator)."""
    noise = preset("px4-sih").estimator
    assert noise.velocity_bias_std_xy_m_s == 0.20 and noise.velocity_bias_std_z_m_s == 0.10
    tb, ts = noise.velocity_bias_time_constant_s, noise.smoothing_time_constant_s
    smoothed = math.sqrt(tb / (tb + ts))
    plain = dataclasses.replace(noise, velocity_bias_std_xy_m_s=0.0, velocity_bias_std_z_m_s=0.0)
    biased, unbiased = EstimatorError(noise, np.random.default_rng(5)), EstimatorError(plain, np.random.default_rng(5))
    bias = []
    for k in range(1, 1601):  # 160 s at the 10 Hz fusion rate: 20 time constants
        biased.advance_to(k * 0.1)
        unbiased.advance_to(k * 0.1)
        assert biased.position_error_ned_m == unbiased.position_error_ned_m
        bias.append(np.subtract(biased.velocity_error_ned_m_s, unbiased.velocity_error_ned_m_s))
    std = np.sqrt(np.mean(np.square(bias), axis=0))
    assert std[:2] == pytest.approx([0.20 * smoothed] * 2, rel=0.5) and std[2] == pytest.approx(0.10 * smoothed, rel=0.5)


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


def _hover_truth() -> VehicleParams:
    # Exact hover thrust: a state at rest stays at rest, so a later start is the same response.
    params = preset("px4-sih")
    return params.with_(estimator=EstimatorNoise(), hover_thrust=params.true_hover_thrust)


def _responses(late_params: VehicleParams, now_params: VehicleParams, step: Setpoint, axis: int) -> tuple[list[float], list[float]]:
    """Acceleration along ``axis`` of two vehicles given a step at 0.2 s (hover before), 4 ms steps."""
    late = Simulator(late_params, np.random.default_rng(0), Spawn.hover((0, 0, -5)))
    now = Simulator(now_params, np.random.default_rng(0), Spawn.hover((0, 0, -5)))
    hold = AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=0.0)
    a_late, a_now = [], []
    for k in range(300):  # 1.2 s
        sp = step if k >= 50 else hold
        a_late.append(late.step(0.004, sp).accel_ned_m_s2[axis])
        a_now.append(now.step(0.004, sp).accel_ned_m_s2[axis])
    return a_late, a_now


def test_setpoint_latency_is_a_pure_delay() -> None:
    base = _hover_truth().with_(thrust_latency_s=None)  # one latency for the whole setpoint
    a_late, a_now = _responses(base, base.with_(setpoint_latency_s=0.0), AccelerationSetpoint((1.0, 0.0, 0.0), yaw_rad=0.0), 0)
    shift = int(round(base.setpoint_latency_s / 0.004))
    assert shift == 15
    np.testing.assert_allclose(a_late[shift + 50:], a_now[50:-shift], atol=1e-9)
    assert max(abs(a) for a in a_late[: 50 + shift]) < 1e-6


def test_thrust_latency_delays_the_collective_alone() -> None:
    base = _hover_truth()
    assert (base.setpoint_latency_s, base.thrust_latency_s) == (0.06, 0.005)  # px4-sih: thrust before tilt
    # A vertical step is collective only: it answers after the thrust latency (5 ms, 1-2 steps of 4 ms)
    thrust_only = base.with_(setpoint_latency_s=base.thrust_latency_s, thrust_latency_s=None)
    up = AccelerationSetpoint((0.0, 0.0, -1.0), yaw_rad=0.0)
    a_split, a_thrust_only = _responses(base, thrust_only, up, 2)
    np.testing.assert_allclose(a_split, a_thrust_only, atol=1e-9)
    assert a_split[50 + 8] < -0.2  # under way 32 ms after the step: long before the 60 ms latency
    # A horizontal step: the tilt waits the full latency; the collective's share (its 1/cos(tilt)
    # once tilted) changes nothing before the vehicle tilts, so the horizontal response is the
    # one-latency vehicle's until then
    side = AccelerationSetpoint((1.0, 0.0, 0.0), yaw_rad=0.0)
    ax_split, ax_one = _responses(base, base.with_(thrust_latency_s=None), side, 0)
    assert max(abs(a) for a in ax_split[: 50 + 15]) < 1e-6
    assert abs(ax_split[50 + 15 + 40]) > 0.3
    # ... and after it, the split flies the same tilt with the collective for it sooner
    assert not np.allclose(ax_split, ax_one, atol=1e-6)


@pytest.mark.parametrize("kind", ["attitude", "rates"])
def test_thrust_latency_applies_to_attitude_and_rate_setpoints(kind: str) -> None:
    base = _hover_truth()
    thrust = 1.1 * base.true_hover_thrust
    late: Setpoint = (AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), thrust) if kind == "attitude"
                      else RateSetpoint((0.0, 0.0, 0.0), thrust))  # fmt: skip
    sims = [Simulator(p, np.random.default_rng(0), Spawn.hover((0, 0, -5)))
            for p in (base, base.with_(setpoint_latency_s=base.thrust_latency_s, thrust_latency_s=None))]  # fmt: skip
    first = (AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), base.true_hover_thrust) if kind == "attitude"
             else RateSetpoint((0.0, 0.0, 0.0), base.true_hover_thrust))  # fmt: skip
    az = [[], []]
    for k in range(100):  # the kind is engaged for 0.2 s before the thrust step (both paths hold it)
        for sim, out in zip(sims, az):
            out.append(sim.step(0.004, first if k < 50 else late).accel_ned_m_s2[2])
    np.testing.assert_allclose(az[0], az[1], atol=1e-9)  # the collective answers after 5 ms, not 60
    assert az[0][50 + 8] < -0.3


def test_prime_equals_setpoints_given_before_the_start() -> None:
    """A primed simulator flies as one without latency fed the same setpoints shifted by it."""
    base = _hover_truth().with_(thrust_latency_s=None)
    a, b, c = (AccelerationSetpoint(v, yaw_rad=0.0) for v in ((0.5, 0.0, 0.0), (-0.5, 0.3, -0.4), (0.0, 0.0, 0.0)))
    primed = Simulator(base, np.random.default_rng(0), Spawn.hover((0, 0, -5)))
    primed.prime([(0.06, a), (0.03, b)])
    shifted = Simulator(base.with_(setpoint_latency_s=0.0), np.random.default_rng(0), Spawn.hover((0, 0, -5)))
    for k in range(24):  # 5 ms steps: a until 30 ms, b until 60 ms, then c (given at 0, 60 ms late)
        s1 = primed.step(0.005, c)
        s2 = shifted.step(0.005, a if k < 6 else b if k < 12 else c)
        np.testing.assert_allclose(s1.accel_ned_m_s2, s2.accel_ned_m_s2, atol=1e-9)
        np.testing.assert_allclose(s1.q_sp_ned_frd, s2.q_sp_ned_frd, atol=1e-12)
    assert abs(s1.accel_ned_m_s2[1]) > 0.01  # b was flown (the only one with a y component)
    with pytest.raises(ValueError, match="before the first step"):
        primed.prime([(0.01, a)])
    fresh = Simulator(base, np.random.default_rng(0), Spawn.hover((0, 0, -5)))
    with pytest.raises(ValueError, match="oldest first"):
        fresh.prime([(0.01, a), (0.02, b)])
    with pytest.raises(ValueError, match="age_s"):
        fresh.prime([(0.0, a)])


def test_thrust_latency_is_validated() -> None:
    with pytest.raises(ValueError, match="thrust_latency_s"):
        preset("px4-sih").with_(thrust_latency_s=-0.01)
    with pytest.raises(ValueError, match="thrust_latency_s"):
        preset("px4-sih").with_(thrust_latency_s=math.nan)


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


# EKF2's error against SIH's ground truth, real PX4 SIH flying the paper path with this app (17 flights,
# 15 s windows, per horizontal axis, cm/s RMS): the reported velocity, and the reported position's
# derivative (over 0.2 s) below 0.7 Hz (above, the ground truth's 1e-7 deg quantisation dominates it).
ERROR_BANDS_HZ = ((0.0, 0.1), (0.1, 0.3), (0.3, 0.7), (0.7, 1.2), (1.2, 2.0), (2.0, 5.0), (5.0, 25.0))
REAL_EKF2_ERROR_BANDS_CM_S = {
    "velocity": (12.4, 12.5, 3.9, 1.4, 1.2, 1.1, 0.8),
    "position_derivative": (3.1, 6.4, 4.4),
}


def _band_rms(z: np.ndarray, rate_hz: float, bands: tuple[tuple[float, float], ...] = ERROR_BANDS_HZ) -> np.ndarray:
    """RMS of z (demeaned, Hann window) in each band, as the real figures were made."""
    z = z - z.mean()
    power = np.abs(np.fft.rfft(z * np.hanning(len(z)))) ** 2
    freq = np.fft.rfftfreq(len(z), 1.0 / rate_hz)
    share = np.array([power[(freq >= lo) & (freq < hi)].sum() for lo, hi in bands]) / power.sum()
    return np.sqrt(share * np.mean(z * z))


def _stationary_error(noise: EstimatorNoise, seed: int, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal (position, velocity) error sampled at rate_hz over the last 15 s of 45 (stationary)."""
    t = np.arange(1, int(45.0 * rate_hz) + 1) / rate_hz
    n = int(15.0 * rate_hz)
    err = EstimatorError(noise, np.random.default_rng(seed))
    p, v = [], []
    for ti in t:
        err.advance_to(float(ti))
        p.append(err.position_error_ned_m[:2])
        v.append(err.velocity_error_ned_m_s[:2])
    return np.array(p)[-n:], np.array(v)[-n:]


def test_error_spectrum_matches_ekf2_on_px4_sih() -> None:
    """The loops pass estimate error on by frequency (the speed loop amplifies 0.7-2 Hz about 2.5x),
    so px4-sih's error must have the real EKF2's spectrum, not only its size: every band within
    0.7-1.4x of the real figure (the previous white-noise-heavy preset had 1.4-1.75x above 1.2 Hz and
    0.3-0.5x of the position's motion at 0.1-0.7 Hz)."""
    noise = preset("px4-sih").estimator
    rate_hz = 50.0
    vel, dpos = [], []
    for seed in range(24):
        p, v = _stationary_error(noise, seed, rate_hz)
        for axis in range(2):
            vel.append(_band_rms(v[:, axis], rate_hz) ** 2)
            d = np.convolve(np.gradient(p[:, axis], 1.0 / rate_hz), np.ones(10) / 10, "same")
            dpos.append(_band_rms(d, rate_hz) ** 2)
    mock = {"velocity": 100 * np.sqrt(np.mean(vel, axis=0)), "position_derivative": 100 * np.sqrt(np.mean(dpos, axis=0))}
    for name, real in REAL_EKF2_ERROR_BANDS_CM_S.items():
        ratio = mock[name][: len(real)] / np.array(real)
        assert np.all((0.7 <= ratio) & (ratio <= 1.4)), (name, np.round(mock[name], 1), real)


# The real reported state against itself - no ground truth needed, so every band counts: EKF2 on the
# real PX4 SIH flying the paper path (10 flights, from activation + 8 s), Δposition/Δt − velocity per
# horizontal axis, cm/s RMS, in CONSISTENCY_BANDS_HZ.
CONSISTENCY_BANDS_HZ = ((0.7, 1.2), (1.2, 2.0), (2.0, 3.0), (3.0, 5.0), (5.0, 10.0), (10.0, 25.0))
REAL_EKF2_CONSISTENCY_BANDS_CM_S = (2.15, 1.57, 1.07, 1.01, 2.62, 1.45)


def test_reported_position_and_velocity_disagree_as_ekf2s_do() -> None:
    """Δposition/Δt − velocity of the reported state within 0.6-1.7x of the real EKF2's in every band
    up to 25 Hz. A position that steps at each fusion (no output predictor) is 1.9-9.6x above 2 Hz:
    its derivative's spikes reach the app's velocity correction and the loops (docs: the estimate's
    spectrum)."""

    def consistency(noise: EstimatorNoise) -> np.ndarray:
        rate_hz = 100.0
        power = []
        for seed in range(8):
            p, v = _stationary_error(noise, seed, rate_hz)
            for axis in range(2):
                z = np.gradient(p[:, axis], 1.0 / rate_hz) - v[:, axis]
                power.append(_band_rms(z, rate_hz, CONSISTENCY_BANDS_HZ) ** 2)
        return 100.0 * np.sqrt(np.mean(power, axis=0))

    real = np.array(REAL_EKF2_CONSISTENCY_BANDS_CM_S)
    noise = preset("px4-sih").estimator
    ratio = consistency(noise) / real
    assert np.all((0.6 <= ratio) & (ratio <= 1.7)), np.round(ratio, 2)
    stepped = consistency(dataclasses.replace(noise, output_time_constant_s=0.0)) / real
    assert np.max(stepped[2:]) > 3.0, np.round(stepped, 2)  # the old preset's flaw, still detectable
