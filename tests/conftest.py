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
