"""The asyncio API (see docs/api.md): :func:`connect` → :class:`Vehicle` (``takeoff``,
``follow``, ``status``, ``hand_back``), :class:`FollowResult`, :class:`Progress`."""

from pf_offboard.api.results import FollowResult, Progress
from pf_offboard.api.vehicle import ConnectSettings, FollowSettings, Vehicle, connect, load_follow_config

__all__ = ["ConnectSettings", "FollowResult", "FollowSettings", "Progress", "Vehicle", "connect", "load_follow_config"]
