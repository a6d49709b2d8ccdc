"""The controller a config selects (``controller:``): the path follower or the tracking baseline."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from pf_offboard.control.follower import PathFollower
from pf_offboard.control.tracker import TrajectoryTracker

if TYPE_CHECKING:
    from pf_offboard.config import Config


def controller_from_config(config: Config | str | os.PathLike[str]) -> PathFollower | TrajectoryTracker:
    """``controller: path_following`` (the default): :class:`PathFollower`;
    ``trajectory_tracking``: :class:`TrajectoryTracker` with the same path, speed, gains, yaw,
    limits and compensation. Both return the same :class:`~pf_offboard.control.types.Command`."""
    from pf_offboard.config import Config, load_config

    cfg = config if isinstance(config, Config) else load_config(config)
    follower = PathFollower.from_config(cfg)
    if cfg.controller == "trajectory_tracking":
        return TrajectoryTracker.like(follower)
    return follower
