"""pf-offboard: time-invariant quadrotor path following (Kumar & Gill) over MAVLink.

The pure core is importable without any I/O::

    from pf_offboard import Path, PathFollower
    follower = PathFollower(Path.from_waypoints(points, closed=True), speed=1.5)
    cmd = follower.update(position_enu_m, velocity_enu_m_s, time_s=t)

A companion program flies a vehicle with the asyncio API (docs/api.md)::

    async with pf_offboard.connect("udp://:14540") as vehicle:
        await vehicle.takeoff(2.0)
        result = await vehicle.follow("field.yaml", laps=2)
        await vehicle.hand_back()

Names are imported lazily (PEP 562) so that ``pf-offboard --help`` and light modules such as
:mod:`pf_offboard.frames` do not pay for numpy/scipy set-up they do not use.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

# public name -> defining module (a fixed table)
_EXPORTS: dict[str, str] = {
    "Path": "pf_offboard.path",
    "Projector": "pf_offboard.path",
    "PathFollower": "pf_offboard.control",
    "Command": "pf_offboard.control",
    "TransverseState": "pf_offboard.control",
    "Saturation": "pf_offboard.control",
    "Gains": "pf_offboard.control",
    "Limits": "pf_offboard.control",
    "Compensation": "pf_offboard.control",
    "VehicleModel": "pf_offboard.control",
    "YawSpec": "pf_offboard.control",
    "Config": "pf_offboard.config",
    "load_config": "pf_offboard.config",
    "parse_config": "pf_offboard.config",
    "connect": "pf_offboard.api",
    "Vehicle": "pf_offboard.api",
    "FollowResult": "pf_offboard.api",
    "Progress": "pf_offboard.api",
    "FlightError": "pf_offboard.errors",
    "OperatorTakeover": "pf_offboard.errors",
    "EnvelopeBreach": "pf_offboard.errors",
    "CrashDetected": "pf_offboard.errors",
    "LinkLost": "pf_offboard.errors",
    "CommandRefused": "pf_offboard.errors",
    "AutopilotFailsafe": "pf_offboard.errors",
    "AnotherController": "pf_offboard.errors",
    "FlightInterrupted": "pf_offboard.errors",
    "InputError": "pf_offboard.errors",
    "LinkError": "pf_offboard.errors",
}

__all__ = sorted(_EXPORTS)

if TYPE_CHECKING:
    from pf_offboard.api import FollowResult, Progress, Vehicle, connect
    from pf_offboard.config import Config, load_config, parse_config
    from pf_offboard.control import (
        Command, Compensation, Gains, Limits, PathFollower, Saturation, TransverseState, VehicleModel, YawSpec,
    )  # fmt: skip
    from pf_offboard.errors import (
        AnotherController,
        AutopilotFailsafe,
        CommandRefused,
        CrashDetected,
        EnvelopeBreach,
        FlightError,
        FlightInterrupted,
        InputError,
        LinkError,
        LinkLost,
        OperatorTakeover,
    )
    from pf_offboard.path import Path, Projector


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'pf_offboard' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
