"""Shared by the batch-engine tests: the scalar ``sim`` flight's true trajectory, the reference
the batch engine's flights are compared with."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pf_offboard.sim.flight import SimFlight
from pf_offboard.sweep.runner import _Judge, sim_spec


def _scalar_trajectory(task: Any, followers: list | None = None) -> np.ndarray:
    """The true positions (NED) after every step of the scalar flight of ``task`` (``followers``:
    gets its PathFollower)."""
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "config.yaml"
        cfg.write_text(task.config_yaml, encoding="utf-8")
        flight = SimFlight(cfg, sim_spec(task), tmp, write_logs=False)
        flight.summary = _Judge(flight.summary, task.settings)  # type: ignore[assignment]
        out: list[np.ndarray] = []
        step = flight.autopilot.step

        def recorded(dt_s: float):  # type: ignore[no-untyped-def]
            events = step(dt_s)
            out.append(np.array(flight.autopilot.truth.position_ned_m))
            return events

        flight.autopilot.step = recorded  # type: ignore[method-assign]
        flight.run()
        if followers is not None:
            followers.append(flight.pipeline.follower)
    return np.array(out)


@pytest.fixture
def scalar_trajectory() -> Callable[..., np.ndarray]:
    """``scalar_trajectory(task, followers=None)``: the scalar flight's true positions (NED) after
    every step."""
    return _scalar_trajectory
