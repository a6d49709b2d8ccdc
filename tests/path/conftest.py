"""Shared paths for the path tests (built once per session)."""

from __future__ import annotations

import pytest
from pathtools import config_path

from pf_offboard.path import Path


@pytest.fixture(scope="session")
def paper() -> Path:
    return config_path("paper.yaml")


@pytest.fixture(scope="session")
def paper_rmf() -> Path:
    return config_path("paper.yaml", frame="rmf")


@pytest.fixture(scope="session")
def figure8() -> Path:
    return config_path("figure8.yaml")


@pytest.fixture(scope="session")
def helix() -> Path:
    return config_path("helix.yaml")


@pytest.fixture(scope="session")
def helix_rmf() -> Path:
    return config_path("helix.yaml", frame="rmf")


@pytest.fixture(scope="session")
def straight() -> Path:
    return config_path("straight.yaml")


@pytest.fixture(scope="session")
def racetrack() -> Path:
    return config_path("racetrack.yaml")
