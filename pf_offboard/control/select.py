"""The controller a config selects (``controller:``): the path follower or the tracking baseline."""

from __future__ import annotations

from typing import Protocol

from pf_offboard.control.follower import ControllerConfig, PathFollower
from pf_offboard.control.tracker import TrajectoryTracker


class SelectingConfig(ControllerConfig, Protocol):
    controller: str


def controller_from_config(config: SelectingConfig) -> PathFollower | TrajectoryTracker:
    """From a loaded config (``pf_offboard.config.load_config``): ``controller: path_following``
    (the default): :class:`PathFollower`; ``trajectory_tracking``: :class:`TrajectoryTracker` with
    the same path, speed, gains, yaw, limits and compensation. Both return the same
    :class:`~pf_offboard.control.types.Command`."""
    follower = PathFollower.from_config(config)
    if config.controller == "trajectory_tracking":
        return TrajectoryTracker.like(follower)
    return follower
