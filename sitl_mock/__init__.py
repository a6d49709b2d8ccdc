"""sitl_mock: a MAVLink mock autopilot (PX4 / ArduPilot profiles) around a simulated quadrotor.

    from sitl_mock import MockAutopilot, MockConfig
    async with MockAutopilot(MockConfig(profile="px4", speed=10)) as mock:
        ...  # connect a MAVLink client to 127.0.0.1:mock.ports.udp (or listen on 14540)

``sitl_mock.dynamics`` is the pure simulation (no networking). The names below are imported
lazily so ``import sitl_mock.dynamics`` stays light. See docs/sitl-mock.md.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

_EXPORTS: Mapping[str, str] = MappingProxyType({
    "MockConfig": "sitl_mock.config",
    "FaultConfig": "sitl_mock.config",
    "SpawnSpec": "sitl_mock.config",
    "MockConfigError": "sitl_mock.config",
    "Autopilot": "sitl_mock.autopilot",
    "MockAutopilot": "sitl_mock.server",
    "Ports": "sitl_mock.server",
    "run_in_thread": "sitl_mock.runner",
    "spawn": "sitl_mock.runner",
})

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'sitl_mock' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
