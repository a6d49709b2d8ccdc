"""Suite-wide guard: a test that hangs fails with a traceback instead of stalling CI.

Every test here finishes in seconds (lockstep / speed factor, never wall-clock waits); a test still
running after HANG_LIMIT_S is stuck on something (a socket nobody answers, a missed event). SIGALRM
interrupts a blocking call in the main thread, so the failure shows where it hung. This is a hang
guard, not a speed target: speed figures live in `pf-offboard bench`.
"""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Iterator
from pathlib import Path

# One BLAS thread per test process (and the subprocesses they start), set before NumPy loads:
# xdist runs two workers per core, and OpenBLAS's own threads (one per core by default) then
# compete with them for the same cores — the suite's small solves gain nothing from them, and
# their spinning cost ~7 % of its CPU (tests/sim/test_heldout_defaults.py + test_speed_profile.py:
# 41 -> 38 s user).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402

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


# Each test's measured seconds (tests/durations.json, written by scripts/test_durations.py from a
# `--durations=0` run): the work units of `--dist loadgroup` (a group, or a test of its own) are
# queued longest first, so that the last units left are short ones and neither worker idles long
# at the end while the other finishes a long test. Order only: every test still runs, and a test
# missing from the file (a new one) just counts as short.
DURATIONS = Path(__file__).with_name("durations.json")
# The tests that open the fixed ports of the docs (UDP 14540 / 14580, TCP 5760): one group, so
# that `--dist loadgroup` runs them one after the other on one worker (they would collide).
FIXED_PORT_TESTS = ("tests/test_getting_started.py::test_every_command_of_the_guide_runs",
                    "tests/api/test_api.py::test_the_snippet_with_the_mavsdk_url_flies_end_to_end")  # fmt: skip
_WIDE_SCOPES = ("class", "module", "package")


def pytest_configure(config: pytest.Config) -> None:
    """Keep the queue in the order below: xdist would otherwise sort loadgroup's work units by
    their number of tests, which says little about their time."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


# `-n auto` (the README's command): two workers per core. About a third of the suite's wall time is
# waiting (real-time flights over loopback, subprocesses), not computing: on 2 cores `-n 2` used
# ~600 s of CPU in ~470 s (64 % of the cores); a second worker per core computes while the other
# waits. PYTEST_XDIST_AUTO_NUM_WORKERS still sets the number, `-n N` too.
WORKERS_PER_CORE = 2


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int | None:
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None  # xdist's own hook reads it
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return WORKERS_PER_CORE * cores


def _expected_s() -> dict[str, float]:
    try:
        data = json.loads(DURATIONS.read_text())
    except (OSError, ValueError):
        return {}
    return {str(k): float(v) for k, v in data.items()} if isinstance(data, dict) else {}


def _unit(item: pytest.Item) -> str:
    """The work unit xdist's loadgroup makes of ``item``: its group(s), or the test alone."""
    names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default")) for m in item.iter_markers("xdist_group")})
    return "@" + "_".join(names) if names else item.nodeid


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The groups of `--dist loadgroup` (a test without a group is a work unit of its own, so one
    long file does not hold one worker): the fixed-port tests form one group; a test using a class /
    module scoped fixture (the installed wheel, a fitted log) is grouped with its file, so that
    fixture is still built once. Then the order: the units longest first (DURATIONS above)."""
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
    expected = _expected_s()
    unit_of = {item.nodeid: _unit(item) for item in items}
    cost: dict[str, float] = {}
    for item in items:
        cost[unit_of[item.nodeid]] = cost.get(unit_of[item.nodeid], 0.0) + expected.get(item.nodeid, 0.0)
    items.sort(key=lambda item: -cost[unit_of[item.nodeid]])  # stable: equal units keep their order
    # xdist (3.8) marks a grouped test for loadgroup by appending "@group" to its node id, written
    # to `item._nodeid`; pytest 9 keeps the id in `item._id`, so that changed nothing and no test was
    # grouped (a module fixture built on both workers, the fixed-port tests side by side). Write
    # the same suffix where pytest reads the id; with an older pytest (it has `_nodeid`) xdist does.
    if getattr(config.option, "loadgroup", False):
        for item in items:
            unit = unit_of[item.nodeid]
            if unit.startswith("@") and not hasattr(item, "_nodeid") and hasattr(item, "_id"):
                item._id = type(item._id).parse(item.nodeid + unit)
