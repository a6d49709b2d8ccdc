"""Suite-wide guard: a test that hangs fails with a traceback instead of stalling CI.

Every test here finishes in seconds (lockstep / speed factor, never wall-clock waits); a test still
running after HANG_LIMIT_S is stuck on something (a socket nobody answers, a missed event). SIGALRM
interrupts a blocking call in the main thread, so the failure shows where it hung. This is a hang
guard, not a speed target: speed figures live in `pf-offboard bench`.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator

import pytest

HANG_LIMIT_S = 180


class HangError(Exception):
    """Raised in a test that ran past HANG_LIMIT_S."""


def _hung(signum: int, frame: object) -> None:
    raise HangError(f"test still running after {HANG_LIMIT_S} s: hung (see the traceback for where)")


@pytest.fixture(autouse=True)
def _hang_guard() -> Iterator[None]:
    previous = signal.signal(signal.SIGALRM, _hung)
    signal.alarm(HANG_LIMIT_S)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


# The suite's longest files (a minute or so each on 2 cores, measured with --durations), collected
# first so that `pytest -n auto --dist loadfile` starts them first instead of leaving one worker
# running them alone at the end. Order only: every test still runs, each file on one worker.
LONG_FILES = ("test_getting_started.py", "test_installed.py", "test_cli_fuzz.py", "test_jitter_rates.py", "test_link_faults.py")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    rank = {name: i for i, name in enumerate(LONG_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FILES)))  # stable: the rest keep their order
