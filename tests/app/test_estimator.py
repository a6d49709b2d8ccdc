"""Estimator: NED/FRD telemetry → ENU/FLU state, fresh-sample detection, rejection, resets."""

import math

import numpy as np
import pytest

from pf_offboard import frames
from pf_offboard.app.estimator import Estimator

from .helpers import attitude_quaternion, local_position, odometry, quat_about


def test_local_position_to_enu() -> None:
    est = Estimator()
    assert est.latest is None
    assert not est.on_message(attitude_quaternion(10, rates_frd=(0.1, 0.2, 0.3)))
    assert est.on_message(local_position(20, (1.0, 2.0, -3.0), (0.1, 0.2, -0.3)))
    s = est.latest
    assert s.time_s == pytest.approx(0.020)
    assert s.position_enu_m == pytest.approx([2.0, 1.0, 3.0])
    assert s.velocity_enu_m_s == pytest.approx([0.2, 0.1, 0.3])
    assert s.q_enu_flu == pytest.approx(frames.quat_ned_frd_to_enu_flu([1, 0, 0, 0]))
    assert s.rates_flu_rad_s == pytest.approx([0.1, -0.2, -0.3])
    assert s.sample == 1


def test_bad_samples_are_rejected() -> None:
    est = Estimator()
    assert not est.on_message(local_position(1, (math.nan, 0.0, 0.0)))
    assert not est.on_message(attitude_quaternion(1, (0.5, 0.0, 0.0, 0.0)))  # not unit length
    assert not est.on_message(attitude_quaternion(1, (math.nan, 0.0, 0.0, 1.0)))
    assert est.rejected == 3 and est.latest is None


def test_source_is_locked_so_samples_are_not_double_counted() -> None:
    est = Estimator()  # auto: first source seen wins
    assert est.on_message(local_position(1))
    assert not est.on_message(odometry(2000, (0, 0, 0), (0, 0, 0)))
    only_odo = Estimator("odometry")
    assert not only_odo.on_message(local_position(1))
    assert only_odo.on_message(odometry(2000, (0, 0, 0), (0, 0, 0)))


def test_odometry_body_velocity_is_rotated_to_world() -> None:
    yaw_ned = 0.5  # heading 0.5 rad east of north
    q = quat_about((0, 0, 1), yaw_ned)  # FRD -> NED
    est = Estimator("odometry")
    assert est.on_message(odometry(3_000_000, (1.0, 2.0, -3.0), (1.0, 0.0, 0.0), q))
    s = est.latest
    assert s.time_s == pytest.approx(3.0)
    v_ned = np.array([math.cos(yaw_ned), math.sin(yaw_ned), 0.0])
    assert s.velocity_enu_m_s == pytest.approx(frames.ned_to_enu(v_ned))
    assert s.q_enu_flu == pytest.approx(frames.quat_ned_frd_to_enu_flu(q))
    # velocity already in the local frame (child_frame_id = LOCAL_NED) is not rotated
    est2 = Estimator("odometry")
    est2.on_message(odometry(1, (0, 0, 0), (1.0, 0.0, 0.0), q, child_frame=1))
    assert est2.latest.velocity_enu_m_s == pytest.approx([0.0, 1.0, 0.0])


def test_odometry_reset_counter_flags_a_reset() -> None:
    est = Estimator("odometry")
    est.on_message(odometry(1, (0, 0, 0), (0, 0, 0), reset_counter=3))
    assert not est.reset_pending
    est.on_message(odometry(2, (0, 0, 0), (0, 0, 0), reset_counter=3))
    assert not est.reset_pending
    est.on_message(odometry(3, (2, -1, 0), (0, 0, 0), reset_counter=4))
    assert est.reset_pending


def test_odometry_in_a_non_ned_frame_is_rejected() -> None:
    est = Estimator("odometry")
    assert not est.on_message(odometry(1, (0, 0, 0), (0, 0, 0), frame=20))
    assert est.rejected == 1


def test_duplicated_or_reordered_samples_are_not_fresh() -> None:
    """A UDP duplicate or an older sample does not step the controller; a clock restart
    (autopilot reboot: time jumps back by more than the window) is accepted once the next sample
    confirms it."""
    est = Estimator("local_position")
    assert est.on_message(local_position(5000, (1.0, 0.0, -2.0)))
    assert not est.on_message(local_position(5000, (1.0, 0.0, -2.0)))  # duplicate
    assert not est.on_message(local_position(4996, (0.9, 0.0, -2.0)))  # reordered
    assert est.latest is not None and est.latest.position_enu_m[1] == 1.0 and est.rejected == 2
    assert est.on_message(local_position(5004, (1.1, 0.0, -2.0)))
    est2 = Estimator("local_position")
    assert est2.on_message(local_position(60_000))
    assert not est2.on_message(local_position(10))  # rebooted? refused until confirmed
    assert est2.on_message(local_position(14))  # confirmed: the new timeline is adopted
    assert est2.reset_pending and "clock jumped" in est2.reset_reason and est2.clock_reanchors == 1
    odo = Estimator("odometry")
    assert odo.on_message(odometry(7_000_000, (0.0, 0.0, -1.0), (0.0, 0.0, 0.0)))
    assert not odo.on_message(odometry(7_000_000, (0.0, 0.0, -1.0), (0.0, 0.0, 0.0)))


# ---------------------------------------------------------------------------- plausibility (issue 9)
def _stream(est: Estimator, t0_ms: int, n: int, pos=(1.0, 2.0, -3.0), step_ms: int = 4) -> list[bool]:
    return [est.on_message(local_position(t0_ms + i * step_ms, pos, (0.0, 0.0, 0.0))) for i in range(n)]


def test_attitude_reordered_or_duplicated_is_not_used() -> None:
    est = Estimator("local_position")
    est.on_message(attitude_quaternion(1000, quat_about((0, 0, 1), 0.5)))
    older = quat_about((0, 0, 1), -1.0)
    est.on_message(attitude_quaternion(996, older))  # reordered: older than what we have
    est.on_message(attitude_quaternion(1000, older))  # duplicate time
    assert est.on_message(local_position(1001))
    assert est.latest.q_enu_flu == pytest.approx(frames.quat_ned_frd_to_enu_flu(quat_about((0, 0, 1), 0.5)))
    assert est.rejected_old == 2
    est.on_message(attitude_quaternion(1004, older))  # newer: used
    assert est.on_message(local_position(1005))
    assert est.latest.q_enu_flu == pytest.approx(frames.quat_ned_frd_to_enu_flu(older))


def test_one_future_dated_sample_does_not_block_the_genuine_stream() -> None:
    est = Estimator("local_position")
    est.on_message(attitude_quaternion(4999))
    assert all(_stream(est, 5000, 10))
    assert not est.on_message(local_position(10_000, (1.0, 2.0, -3.0)))  # 5 s in the future: refused
    assert est.clock_jumps == 1 and "time jumped +4.964 s" in est.last_event
    # the genuine stream continues: every sample is fresh (before: "not newer" for 5 s)
    assert all(_stream(est, 5040, 50))
    assert est.latest.time_s == pytest.approx(5.236) and not est.reset_pending
    # a future-dated attitude is not used either
    q_spoof = quat_about((1, 0, 0), 1.0)
    est.on_message(attitude_quaternion(9_000, q_spoof))
    assert est.on_message(local_position(5240))
    assert est.latest.q_enu_flu == pytest.approx(frames.quat_ned_frd_to_enu_flu([1.0, 0.0, 0.0, 0.0]))


def test_interleaved_spoofs_10_s_apart_are_not_a_reboot() -> None:
    """A spoofer interleaving samples 10+ s older (a fake "reboot") with the genuine stream:
    none is accepted, because each genuine sample drops the unconfirmed candidate."""
    est = Estimator("local_position")
    genuine_pos, spoof_pos = (1.0, 2.0, -3.0), (40.0, 2.0, -3.0)
    accepted = []
    for i in range(100):
        accepted.append(est.on_message(local_position(20_000 + 4 * i, genuine_pos, (0, 0, 0))))
        assert not est.on_message(local_position(9_000 + 4 * i, spoof_pos, (0, 0, 0)))
        assert est.latest.position_enu_m == pytest.approx(frames.ned_to_enu(genuine_pos))
    assert all(accepted) and est.clock_reanchors == 0 and not est.reset_pending and est.clock_jumps == 100


def test_a_50_m_position_jump_is_refused_and_flagged_only_when_confirmed() -> None:
    est = Estimator("local_position")
    assert all(_stream(est, 1000, 5, (0.0, 0.0, -2.0)))
    # a single 50 m jump: refused, counted, the controller never sees it
    assert not est.on_message(local_position(1020, (50.0, 0.0, -2.0), (0, 0, 0)))
    assert est.rejected_jumps == 1 and "position jumped 50.00 m" in est.last_event and not est.reset_pending
    assert est.latest.position_enu_m == pytest.approx([0.0, 0.0, 2.0])
    # the genuine track continues: the jump candidate is dropped
    assert est.on_message(local_position(1024, (0.0, 0.0, -2.0), (0, 0, 0)))
    # an estimator that really moved (two consistent samples): accepted as a flagged reset
    assert not est.on_message(local_position(1028, (50.0, 0.0, -2.0), (0, 0, 0)))
    assert est.on_message(local_position(1032, (50.0, 0.0, -2.0), (0, 0, 0)))
    assert est.reset_pending and "position jumped 50.00 m" in est.reset_reason and est.position_resets == 1
    assert est.rejected_jumps == 2


def test_fast_but_plausible_motion_is_not_a_jump() -> None:
    """A vehicle at 15 m/s sampled at 30 Hz moves 0.5 m per sample: accepted."""
    est = Estimator("local_position")
    for i in range(60):
        t_ms = 1000 + round(i * 1000 / 30)
        assert est.on_message(local_position(t_ms, (15.0 * i / 30, 0.0, -2.0), (15.0, 0.0, 0.0)))
    assert est.rejected == 0


def test_the_flight_clock_is_continuous_across_a_clock_jump() -> None:
    est = Estimator("local_position")
    _stream(est, 60_000, 251)  # 1 s
    assert est.latest.clock_s == pytest.approx(1.0)
    est.on_message(local_position(10, (1.0, 2.0, -3.0), (0, 0, 0)))  # reboot candidate
    est.on_message(local_position(14, (1.0, 2.0, -3.0), (0, 0, 0)))  # confirmed
    _stream(est, 18, 250)
    # 1 s before the jump + 1 s after it; not 61 s, nor negative
    assert est.latest.time_s == pytest.approx(1.014) and est.latest.clock_s == pytest.approx(2.0)


def test_a_gap_in_the_stream_is_confirmed_without_a_reset() -> None:
    """Samples resuming 2 s later (a blackout): the first is held back, the next confirms the new
    time, and no estimator reset is flagged (the position did not jump)."""
    est = Estimator("local_position")
    assert all(_stream(est, 1000, 10))
    assert not est.on_message(local_position(3036, (1.0, 2.0, -3.0), (0, 0, 0)))
    assert est.on_message(local_position(3040, (1.0, 2.0, -3.0), (0, 0, 0)))
    assert est.clock_reanchors == 1 and not est.reset_pending and "resumed 2.004 s later" in est.last_event


# ------------------------------------------------------------------------- velocity consistency
def _circle_flight(est: Estimator, bias_ned, seconds: float = 8.0, rate_hz: float = 100.0, t0_ms: int = 1000,
                   rng: np.random.Generator | None = None) -> list[tuple[np.ndarray, np.ndarray]]:  # fmt: skip
    """A vehicle on a 2 m circle at 1.5 m/s; the autopilot reports the true position (plus optional
    5 mm noise) and the true velocity plus ``bias_ned``. Returns (true velocity ENU, used velocity ENU)."""
    out = []
    w = 1.5 / 2.0
    for i in range(int(seconds * rate_hz)):
        t = i / rate_hz
        p = np.array([2.0 * math.cos(w * t), 2.0 * math.sin(w * t), -2.0])
        v = np.array([-1.5 * math.sin(w * t), 1.5 * math.cos(w * t), 0.0])
        if rng is not None:
            p = p + rng.normal(0.0, 0.005, 3)
        assert est.on_message(local_position(t0_ms + round(1000 * t), tuple(p), tuple(v + np.asarray(bias_ned))))
        out.append((frames.ned_to_enu(v), est.latest.velocity_enu_m_s.copy()))
    return out


def test_velocity_correction_removes_a_velocity_bias_the_position_does_not_show() -> None:
    """EKF2 on PX4 SIH reports a velocity 10-40 cm/s off its own position's derivative; with the
    correction (1 s) the velocity the controller sees is back within 1 cm/s of the true one
    after 5 time constants, along a circle (the bias rotates in the path frame); off, the bias stays."""
    bias = (0.3, -0.2, 0.1)
    on, off = Estimator("local_position", velocity_correction_s=1.0), Estimator("local_position")
    flown_on, flown_off = _circle_flight(on, bias), _circle_flight(off, bias)
    late = [np.linalg.norm(used - true) for true, used in flown_on[600:]]
    assert max(late) < 0.01
    assert on.velocity_correction_enu_m_s == pytest.approx(-frames.ned_to_enu(np.array(bias)), abs=0.01)
    assert np.linalg.norm(flown_off[-1][1] - flown_off[-1][0]) == pytest.approx(np.linalg.norm(bias), abs=1e-9)
    assert not off.velocity_correction_enu_m_s.any()


def test_velocity_correction_keeps_an_unbiased_velocity_and_bounds_noise() -> None:
    """No bias, 5 mm white position noise at 100 Hz (more than EKF2 shows): the correction stays small (< 5 cm/s) and averages
    out (its mean < 1 cm/s)."""
    est = Estimator("local_position", velocity_correction_s=1.0)
    flown = _circle_flight(est, (0.0, 0.0, 0.0), seconds=20.0, rng=np.random.default_rng(3))
    err = np.array([used - true for true, used in flown[200:]])
    assert np.abs(err).max() < 0.05 and np.abs(err.mean(axis=0)).max() < 0.01


def test_velocity_correction_ignores_a_confirmed_position_jump() -> None:
    """An estimator reset (a confirmed 50 m jump) is not a velocity: the correction is unchanged
    by it, and a single wild sample moves it by at most the residual bound · dt / tau."""
    est = Estimator("local_position", velocity_correction_s=1.0)
    for k in range(10):
        assert est.on_message(local_position(1000 + 10 * k, (0.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    assert not est.on_message(local_position(1100, (50.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    assert est.on_message(local_position(1110, (50.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    assert est.reset_pending and not est.velocity_correction_enu_m_s.any()
    # a 1 m step within the plausibility margin: bounded to 2 m/s residual · 0.01 s / 1 s
    assert est.on_message(local_position(1120, (50.9, 0.0, -2.0), (0.0, 0.0, 0.0)))
    assert np.linalg.norm(est.velocity_correction_enu_m_s) <= 2.0 * (1.0 - math.exp(-0.01)) + 1e-12


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_velocity_correction_time_constant_is_validated(bad: float) -> None:
    with pytest.raises(ValueError, match="velocity_correction_s"):
        Estimator("local_position", velocity_correction_s=bad)


def test_a_recorded_series_is_corrected_as_the_live_estimator_corrects_it() -> None:
    """identify's position_consistent_velocity and the Estimator share one rule: the same samples
    give the same velocities, to float rounding (biased circle with position noise, 10 s)."""
    from pf_offboard.app.estimator import position_consistent_velocity

    est = Estimator("local_position", velocity_correction_s=0.3)
    rng = np.random.default_rng(5)
    times, pos, vel, live = [], [], [], []
    for i in range(1000):
        t = i / 100.0
        p = np.array([2.0 * math.cos(0.75 * t), 2.0 * math.sin(0.75 * t), -2.0]) + rng.normal(0.0, 0.005, 3)
        v = np.array([-1.5 * math.sin(0.75 * t) + 0.3, 1.5 * math.cos(0.75 * t) - 0.2, 0.1])
        assert est.on_message(local_position(1000 + 10 * i, tuple(p), tuple(v)))
        times.append(1.0 + 0.01 * i)
        pos.append(p)
        vel.append(v)
        live.append(frames.enu_to_ned(est.latest.velocity_enu_m_s))
    series = position_consistent_velocity(np.array(times), np.array(pos), np.array(vel), 0.3)
    assert np.abs(series - np.array(live)).max() < 1e-9
    assert np.abs(series[-1] - (vel[-1] - np.array([0.3, -0.2, 0.1]))).max() < 0.03  # and it corrects


# ---------------------------------------------------------------- health and plausibility (physical limits)
def _hover_track(est: Estimator, t0_ms: int = 0, n: int = 10, dt_ms: int = 4) -> int:
    for k in range(n):
        assert est.on_message(local_position(t0_ms + k * dt_ms, (0.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    return t0_ms + (n - 1) * dt_ms


def test_a_corrupt_sample_cannot_excuse_its_own_jump_with_its_own_speed() -> None:
    """x = 40 m with vx = 5000 m/s: the allowed jump comes from the previous trusted speed, so it is
    refused; the next genuine sample continues the track (the corrupt one is never confirmed)."""
    est = Estimator()
    t = _hover_track(est)
    assert not est.on_message(local_position(t + 4, (40.0, 0.0, -2.0), (5000.0, 0.0, 0.0)))
    assert est.on_message(local_position(t + 8, (0.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    assert est.rejected_jumps == 1 and est.position_resets == 0
    assert est.latest.position_enu_m == pytest.approx([0.0, 0.0, 2.0])


def test_one_impossible_velocity_is_refused() -> None:
    """vz = +50 m/s (NED, falling) on one sample from a hover: beyond 4 g; refused, never flown."""
    est = Estimator()
    t = _hover_track(est)
    assert not est.on_message(local_position(t + 4, (0.0, 0.0, -2.0), (0.0, 0.0, 50.0)))
    assert est.on_message(local_position(t + 8, (0.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    assert est.latest.velocity_enu_m_s[2] == pytest.approx(0.0)
    est2 = Estimator()
    assert not est2.on_message(local_position(0, (0.0, 0.0, -2.0), (100.0, 0.0, 0.0)))  # even as the first sample


def test_a_small_reset_is_accepted_but_flagged_with_its_size() -> None:
    """A 0.6 m vertical step (inside the 1 m jump margin) is a reset all the same: flagged with its size."""
    est = Estimator()
    t = _hover_track(est)
    assert est.on_message(local_position(t + 4, (0.0, 0.0, -1.4), (0.0, 0.0, 0.0)))
    assert est.position_resets == 1 and est.reset_pending
    assert est.last_reset_enu_m == pytest.approx([0.0, 0.0, -0.6])
    # ordinary motion is not a reset: 2 m/s for 40 samples
    est2 = Estimator()
    for k in range(40):
        assert est2.on_message(local_position(4 * k, (0.008 * k, 0.0, -2.0), (2.0, 0.0, 0.0)))
    assert est2.position_resets == 0


def test_odometry_quality_minus_one_is_refused() -> None:
    est = Estimator("odometry")
    q = (1.0, 0.0, 0.0, 0.0)
    assert est.on_message(odometry(1000, (0, 0, -2), (0, 0, 0), q))
    lost = odometry(2000, (0.1, 0, -2), (0.6, 0, 0), q)
    lost.quality = -1
    assert not est.on_message(lost)
    assert est.rejected_unhealthy == 1 and "quality -1" in est.last_event


def test_estimator_reports_degrade_only_when_confirmed_and_recover() -> None:
    from pymavlink.dialects.v20 import common as mavlink2

    good = mavlink2.MAVLink_estimator_status_message(0, 1 | 2 | 4 | 8 | 16 | 32, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1)
    glitch = mavlink2.MAVLink_estimator_status_message(0, 1 | 2 | 4 | 8 | 32 | 1024, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1)
    from pymavlink.dialects.v20 import ardupilotmega

    ekf_bad = ardupilotmega.MAVLink_ekf_status_report_message(1 | 2 | 4 | 8 | 32, 1.5, 0.2, 0.2, 0.1, 0.1)
    est = Estimator()
    t = _hover_track(est)
    est.on_message(glitch)  # one bad report: no verdict
    assert est.health_reason == "" and est.on_message(local_position(t + 4, (0.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    est.on_message(glitch)
    assert "GPS glitch" in est.health_reason
    assert not est.on_message(local_position(t + 8, (0.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    assert est.rejected_unhealthy == 1
    est.on_message(good)
    assert est.health_reason == "" and est.on_message(local_position(t + 12, (0.0, 0.0, -2.0), (0.0, 0.0, 0.0)))
    est.on_message(ekf_bad)
    est.on_message(ekf_bad)
    assert "velocity_variance 1.50" in est.health_reason
