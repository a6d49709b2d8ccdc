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
    (autopilot reboot: time jumps back by more than the window) is accepted."""
    est = Estimator("local_position")
    assert est.on_message(local_position(5000, (1.0, 0.0, -2.0)))
    assert not est.on_message(local_position(5000, (1.0, 0.0, -2.0)))  # duplicate
    assert not est.on_message(local_position(4996, (0.9, 0.0, -2.0)))  # reordered
    assert est.latest is not None and est.latest.position_enu_m[1] == 1.0 and est.rejected == 2
    assert est.on_message(local_position(5004, (1.1, 0.0, -2.0)))
    est2 = Estimator("local_position")
    assert est2.on_message(local_position(60_000))
    assert est2.on_message(local_position(10))  # rebooted
    odo = Estimator("odometry")
    assert odo.on_message(odometry(7_000_000, (0.0, 0.0, -1.0), (0.0, 0.0, 0.0)))
    assert not odo.on_message(odometry(7_000_000, (0.0, 0.0, -1.0), (0.0, 0.0, 0.0)))
