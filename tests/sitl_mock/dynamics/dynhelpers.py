"""Helpers shared by the dynamics tests (a uniquely named module: conftest names clash)."""

from __future__ import annotations

import numpy as np

from sitl_mock.dynamics import GRAVITY_M_S2, Simulator, Spawn, VehicleParams, preset


def make_sim(params: VehicleParams | str = "fast", spawn: Spawn | None = None, seed: int = 0, **kw) -> Simulator:
    p = preset(params) if isinstance(params, str) else params
    return Simulator(p, np.random.default_rng(seed), spawn if spawn is not None else Spawn.hover((0.0, 0.0, -10.0)), **kw)


def tilt_rad(q: np.ndarray) -> float:
    """Angle between body z and world z."""
    qw, qx, qy, qz = q
    return float(np.arccos(np.clip(1.0 - 2.0 * (qx * qx + qy * qy), -1.0, 1.0)))


def rotation_matrix(q: np.ndarray) -> np.ndarray:
    qw, qx, qy, qz = q
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
        [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
        [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)],
    ])


G = GRAVITY_M_S2
