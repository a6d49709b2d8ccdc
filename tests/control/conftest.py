"""Shared paths for the controller tests."""

from __future__ import annotations

from pathlib import Path as FsPath

import numpy as np
import pytest

from pf_offboard.path import Path

ROOT = FsPath(__file__).resolve().parents[2]
PAPER_YAML = ROOT / "configs" / "paper.yaml"

# Used only until configs/paper.yaml exists: a closed 7-way-point path with one self-intersection.
_PAPER_LIKE = [
    [2.0, 0.0, 2.0],
    [1.0, 2.2, 2.6],
    [-1.5, 1.5, 2.2],
    [1.5, -1.5, 1.6],
    [-1.0, -2.2, 1.5],
    [-2.0, 0.0, 2.0],
    [0.0, 0.0, 3.0],
]


def paper_waypoints() -> np.ndarray:
    if PAPER_YAML.exists():
        from pf_offboard.config import load_config

        return np.asarray(load_config(PAPER_YAML).path.waypoints_enu_m)
    return np.array(_PAPER_LIKE)


def helix_waypoints(turns: float = 2.0, radius: float = 1.5, pitch: float = 0.8, n_per_turn: int = 8) -> np.ndarray:
    n = int(turns * n_per_turn) + 1
    th = np.linspace(0.0, 2.0 * np.pi * turns, n)
    return np.column_stack([radius * np.cos(th), radius * np.sin(th), 1.0 + pitch * th / (2.0 * np.pi)])


@pytest.fixture(scope="session")
def paper_path() -> Path:
    return Path.from_waypoints(paper_waypoints(), closed=True)


@pytest.fixture(scope="session")
def paper_path_rmf() -> Path:
    return Path.from_waypoints(paper_waypoints(), closed=True, frame="rmf")


@pytest.fixture(scope="session")
def helix_frenet() -> Path:
    return Path.from_waypoints(helix_waypoints(), closed=False, frame="frenet")


@pytest.fixture(scope="session")
def helix_rmf() -> Path:
    return Path.from_waypoints(helix_waypoints(), closed=False, frame="rmf")


def rk4_step(follower, y: np.ndarray, v: np.ndarray, dt: float):
    """One RK4 step of the ideal double integrator (4) under follower.update().

    Returns (y, v) after the step and the command at the start of the step."""

    def acc(p, q):
        return follower.update(p, q).acceleration

    cmd = follower.update(y, v)
    a1 = cmd.acceleration
    a2 = acc(y + 0.5 * dt * v, v + 0.5 * dt * a1)
    a3 = acc(y + 0.5 * dt * (v + 0.5 * dt * a1), v + 0.5 * dt * a2)
    a4 = acc(y + dt * (v + 0.5 * dt * a2), v + dt * a3)
    return y + dt * v + dt * dt / 6.0 * (a1 + a2 + a3), v + dt / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4), cmd


def config_path(name: str) -> FsPath:
    return ROOT / "configs" / name
