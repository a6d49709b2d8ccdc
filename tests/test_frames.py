"""ENU/FLU <-> NED/FRD conversions, both ways, against independent rotation matrices."""

import math

import numpy as np
import pytest

from pf_offboard import frames


def _rot(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])


def test_vectors_known_values():
    np.testing.assert_array_equal(frames.enu_to_ned([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0])
    np.testing.assert_array_equal(frames.ned_to_enu([2.0, 1.0, -3.0]), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(frames.flu_to_frd([1.0, 2.0, 3.0]), [1.0, -2.0, -3.0])
    np.testing.assert_array_equal(frames.frd_to_flu([1.0, -2.0, -3.0]), [1.0, 2.0, 3.0])


def test_vectors_round_trip():
    rng = np.random.default_rng(1)
    for _ in range(100):
        v = rng.normal(size=3)
        np.testing.assert_allclose(frames.ned_to_enu(frames.enu_to_ned(v)), v)
        np.testing.assert_allclose(frames.frd_to_flu(frames.flu_to_frd(v)), v)


def test_bad_shape_rejected():
    with pytest.raises(ValueError, match="3-vector"):
        frames.enu_to_ned([1.0, 2.0])


def test_quaternion_matches_matrix_definition_both_ways():
    rng = np.random.default_rng(2)
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q_ned = frames.quat_enu_flu_to_ned_frd(q)
        # R_ned_frd = M R_enu_flu F^T : a body FRD vector goes FRD->FLU->ENU->NED.
        expected = ENU_TO_NED @ _rot(q) @ FLU_TO_FRD.T
        np.testing.assert_allclose(_rot(q_ned), expected, atol=1e-12)
        back = frames.quat_ned_frd_to_enu_flu(q_ned)
        assert abs(abs(np.dot(back, q)) - 1.0) < 1e-12
        assert back[0] >= 0.0


def test_level_attitudes():
    # Level, nose east in ENU (identity) is level, nose east in NED: yaw +90 deg about down.
    q_ned = frames.quat_enu_flu_to_ned_frd([1.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(_rot(q_ned) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(_rot(q_ned) @ [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], atol=1e-12)


def test_yaw_both_ways_and_consistent_with_quaternion():
    rng = np.random.default_rng(3)
    for yaw_enu in rng.uniform(-math.pi, math.pi, 50):
        yaw_ned = frames.yaw_enu_to_ned(yaw_enu)
        assert math.isclose(frames.wrap_pi(frames.yaw_ned_to_enu(yaw_ned) - yaw_enu), 0.0, abs_tol=1e-12)
        q_enu = np.array([math.cos(yaw_enu / 2), 0.0, 0.0, math.sin(yaw_enu / 2)])
        R = _rot(frames.quat_enu_flu_to_ned_frd(q_enu))
        assert math.isclose(frames.wrap_pi(math.atan2(R[1, 0], R[0, 0]) - yaw_ned), 0.0, abs_tol=1e-9)
    assert frames.yaw_rate_enu_to_ned(0.3) == -0.3
    assert frames.yaw_rate_ned_to_enu(-0.3) == 0.3


def test_wrap_pi_range():
    for a in np.linspace(-20, 20, 401):
        w = frames.wrap_pi(float(a))
        assert -math.pi < w <= math.pi
        assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)
