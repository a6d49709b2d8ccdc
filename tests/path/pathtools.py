"""Helpers shared by the path tests (imported by name: tests/path is on sys.path)."""

from __future__ import annotations

from pathlib import Path as FsPath

import numpy as np
import yaml

from pf_offboard.path import Path

CONFIGS = FsPath(__file__).resolve().parents[2] / "configs"


def config_waypoints(name: str) -> tuple[np.ndarray, bool, str]:
    """(waypoints, closed, moving_frame) straight from a YAML config (the schema's path section)."""
    raw = yaml.safe_load((CONFIGS / name).read_text())["path"]
    return np.array(raw["waypoints"], dtype=float), bool(raw["closed"]), str(raw["moving_frame"])


def config_path(name: str, frame: str | None = None) -> Path:
    pts, closed, mframe = config_waypoints(name)
    return Path.from_waypoints(pts, closed=closed, frame=frame or mframe)


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| relative to max(1, |b|) (derivative magnitudes here are O(1))."""
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(1.0, float(np.max(np.abs(b)))))
