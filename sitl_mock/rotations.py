"""Rotation helpers for the autopilot layer (NED world, FRD body, q = (w, x, y, z)); Euler
conversions are the dynamics' own."""

from __future__ import annotations

import math

import numpy as np

from sitl_mock.dynamics import euler_to_quat, quat_to_euler


def euler_from_q(q: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) rad, ZYX convention, of a body-to-world quaternion."""
    return quat_to_euler(tuple(float(v) for v in q))  # type: ignore[arg-type]


def q_from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Body-to-world quaternion (w, x, y, z) from ZYX Euler angles in rad."""
    return np.array(euler_to_quat(roll, pitch, yaw))


def rotate_yaw(yaw: float, v: np.ndarray) -> np.ndarray:
    """Rotate a vector given in a yaw-only (heading) frame into NED."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]])
