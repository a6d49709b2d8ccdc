"""Fixtures for the dynamics tests (pure, no sockets)."""

from __future__ import annotations

import pytest


@pytest.fixture(params=["fast", "px4-default"])
def preset_name(request: pytest.FixtureRequest) -> str:
    return request.param
