"""Shared by the batch-engine tests: the scalar ``sim`` flight of a task, the reference the batch
engine's flights are compared with."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from pf_offboard.sweep.runner import run_flight


def _scalar_flight(task: Any, followers: list | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """One scalar flight of ``task`` (the sweep's ``run_flight``): the true positions (NED) after
    every step, and its table row (``followers``: gets its PathFollower)."""
    out: list[np.ndarray] = []

    def observe(flight: Any) -> None:
        step = flight.autopilot.step

        def recorded(dt_s: float):  # type: ignore[no-untyped-def]
            events = step(dt_s)
            out.append(np.array(flight.autopilot.truth.position_ned_m))
            return events

        flight.autopilot.step = recorded
        if followers is not None:
            followers.append(flight.pipeline.follower)

    row = run_flight(task, observe)
    return np.array(out), row


@pytest.fixture
def scalar_flight() -> Callable[..., tuple[np.ndarray, dict[str, Any]]]:
    """``scalar_flight(task, followers=None)``: (true positions NED after every step, table row)
    of the scalar flight of ``task``, flown once for both."""
    return _scalar_flight
