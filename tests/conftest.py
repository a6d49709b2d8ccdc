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
# first so that `pytest -n auto --dist loadgroup` starts them first instead of leaving one worker
# running them alone at the end. Order only: every test still runs.
LONG_FILES = ("test_getting_started.py", "test_installed.py", "test_loss_blackout.py", "test_blackout_rates.py", "test_jitter_rates.py")
# The tests that open the fixed ports of the docs (UDP 14540 / 14580, TCP 5760): one group, so
# that `--dist loadgroup` runs them one after the other on one worker (they would collide).
FIXED_PORT_TESTS = ("tests/test_getting_started.py::test_every_command_of_the_guide_runs",
                    "tests/api/test_api.py::test_the_snippet_with_the_mavsdk_url_flies_end_to_end")  # fmt: skip
_WIDE_SCOPES = ("class", "module", "package")


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The order above, and the groups of `--dist loadgroup` (a test without a group is a work
    unit of its own, so one long file no longer holds one worker): the fixed-port tests form one
    group; a test using a class / module scoped fixture (the installed wheel, a fitted log) is
    grouped with its file, so that fixture is still built once."""
    rank = {name: i for i, name in enumerate(LONG_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FILES)))  # stable: the rest keep their order
    for item in items:
        if item.get_closest_marker("xdist_group") is not None:
            continue
        if item.nodeid in FIXED_PORT_TESTS:
            item.add_marker(pytest.mark.xdist_group("fixed_ports"))
            continue
        info = getattr(item, "_fixtureinfo", None)
        defs = info.name2fixturedefs.values() if info is not None else ()
        if any(d.scope in _WIDE_SCOPES for chain in defs for d in chain):
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))
