"""The one place where the paper's frames meet MAVLink's.

Core (the paper): world ENU (x east, y north, z up), body FLU (x forward, y left, z up).
MAVLink / PX4 / ArduPilot: world NED (x north, y east, z down), body FRD.

Every conversion between the two lives here; nothing else in the project flips an axis.
Quaternions are (w, x, y, z), Hamilton, body-to-world.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

_S = math.sqrt(0.5)
# Rotation taking ENU world vectors to NED world vectors: (e, n, u) -> (n, e, -u).
# It is a proper rotation (pi about (1, 1, 0)/sqrt 2), so a quaternion exists.
_Q_NED_FROM_ENU = np.array([0.0, _S, _S, 0.0])
# Rotation taking FRD body vectors to FLU body vectors: (x, y, z) -> (x, -y, -z) (pi about x).
_Q_FLU_FROM_FRD = np.array([0.0, 1.0, 0.0, 0.0])


def _vec3(v: ArrayLike, name: str) -> NDArray[np.float64]:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,):
        raise ValueError(f"{name}: expected a 3-vector, got shape {a.shape}")
    return a


def enu_to_ned(v_enu: ArrayLike) -> NDArray[np.float64]:
    """World vector (position m, velocity m/s, acceleration m/s^2) ENU -> NED."""
    v = _vec3(v_enu, "v_enu")
    return np.array([v[1], v[0], -v[2]])


def ned_to_enu(v_ned: ArrayLike) -> NDArray[np.float64]:
    """World vector NED -> ENU (the same axis swap; it is its own inverse)."""
    v = _vec3(v_ned, "v_ned")
    return np.array([v[1], v[0], -v[2]])


def flu_to_frd(v_flu: ArrayLike) -> NDArray[np.float64]:
    """Body vector (e.g. body rates rad/s) FLU -> FRD."""
    v = _vec3(v_flu, "v_flu")
    return np.array([v[0], -v[1], -v[2]])


def frd_to_flu(v_frd: ArrayLike) -> NDArray[np.float64]:
    """Body vector FRD -> FLU (its own inverse)."""
    v = _vec3(v_frd, "v_frd")
    return np.array([v[0], -v[1], -v[2]])


def quat_multiply(q: ArrayLike, r: ArrayLike) -> NDArray[np.float64]:
    """Hamilton product q * r of (w, x, y, z) quaternions."""
    # on Python floats (the same IEEE products and sums as on NumPy scalars, without their overhead)
    w0, x0, y0, z0 = np.asarray(q, dtype=float).tolist()
    w1, x1, y1, z1 = np.asarray(r, dtype=float).tolist()
    return np.array(
        [
            w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1,
            w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
            w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1,
            w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1,
        ]
    )


def _canonical(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit quaternion with w >= 0 (q and -q are the same rotation)."""
    n = float(np.linalg.norm(q))
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError("quaternion: not finite or zero length")
    q = q / n
    return -q if q[0] < 0.0 else q


def quat_enu_flu_to_ned_frd(q_enu_flu: ArrayLike) -> NDArray[np.float64]:
    """Attitude body(FLU)->world(ENU) to body(FRD)->world(NED)."""
    q = np.asarray(q_enu_flu, dtype=float)
    return _canonical(quat_multiply(quat_multiply(_Q_NED_FROM_ENU, q), _Q_FLU_FROM_FRD))


def quat_ned_frd_to_enu_flu(q_ned_frd: ArrayLike) -> NDArray[np.float64]:
    """Attitude body(FRD)->world(NED) to body(FLU)->world(ENU)."""
    q = np.asarray(q_ned_frd, dtype=float)
    # Both fixed rotations are half-turns, so each is its own inverse (up to sign).
    return _canonical(quat_multiply(quat_multiply(_Q_NED_FROM_ENU, q), _Q_FLU_FROM_FRD))


def yaw_enu_to_ned(yaw_enu_rad: float) -> float:
    """Heading: ENU yaw (from east, counter-clockwise) -> NED yaw (from north, clockwise), wrapped to (-pi, pi]."""
    return wrap_pi(math.pi / 2.0 - yaw_enu_rad)


def yaw_ned_to_enu(yaw_ned_rad: float) -> float:
    """Heading: NED yaw -> ENU yaw, wrapped to (-pi, pi]."""
    return wrap_pi(math.pi / 2.0 - yaw_ned_rad)


def yaw_rate_enu_to_ned(yaw_rate_enu_rad_s: float) -> float:
    """World-z yaw rate: up-axis (ENU) -> down-axis (NED)."""
    return -yaw_rate_enu_rad_s


def yaw_rate_ned_to_enu(yaw_rate_ned_rad_s: float) -> float:
    """World-z yaw rate: down-axis (NED) -> up-axis (ENU)."""
    return -yaw_rate_ned_rad_s


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    a = math.fmod(angle_rad + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi
