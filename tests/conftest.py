"""Suite-wide guard: a test that hangs fails with a traceback instead of stalling CI.

Every test here finishes in seconds (lockstep / speed factor, never wall-clock waits); a test still
running after HANG_LIMIT_S is stuck on something (a socket nobody answers, a missed event). SIGALRM
interrupts a blocking call in the main thread, so the failure shows where it hung. This is a hang
guard, not a speed target: speed figures live in `pf-offboard bench`.
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

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


@pytest.fixture
def script() -> Callable[[str], ModuleType]:
    """``script(name)``: ``scripts/<name>.py`` loaded as a module (scripts/ is not a package)."""

    def load(name: str) -> ModuleType:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parents[1] / "scripts" / f"{name}.py")
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # dataclasses look their module up
        spec.loader.exec_module(module)
        return module

    return load


# Each test's measured wall and CPU seconds (tests/durations.json, written by scripts/test_durations.py
# from a run with PF_OFFBOARD_TEST_TIMES set, below): the work units of `--dist loadgroup` (a group,
# or a test of its own) are queued longest first, so that the last units left are short ones and no
# worker idles long at the end while another finishes a long test. Order only: every test still
# runs, and a test missing from the file (a new one) just counts as short.
DURATIONS = Path(__file__).with_name("durations.json")
# A unit that computes less than this share of its wall time mostly waits (real-time flights over
# loopback, subprocesses). Longest first alone queued those together at the start: on 2 cores the
# four workers then waited side by side, and the tests used 0.5-1.4 of the 2 cores for the first
# ~30 s. The queue alternates a computing unit and a waiting one, each list longest first.
WAITING_SHARE = 0.5
# Set to a directory: each test process writes there the wall and CPU seconds (its own and its
# subprocesses') of every test it ran, `times-<worker>.json`, for scripts/test_durations.py.
TIMES_ENV = "PF_OFFBOARD_TEST_TIMES"
# The tests that open the fixed ports of the docs (UDP 14540 / 14580, TCP 5760): one group, so
# that `--dist loadgroup` runs them one after the other on one worker (they would collide).
FIXED_PORT_TESTS = ("tests/test_getting_started.py::test_every_command_of_the_guide_runs",
                    "tests/api/test_api.py::test_the_snippet_with_the_mavsdk_url_flies_end_to_end")  # fmt: skip
_WIDE_SCOPES = ("class", "module", "package")


def pytest_configure(config: pytest.Config) -> None:
    """Keep the queue in the order below: xdist would otherwise sort loadgroup's work units by
    their number of tests, which says little about their time. Record each test's times when
    TIMES_ENV asks for them."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False
    if os.environ.get(TIMES_ENV):
        config.pluginmanager.register(_TimeRecorder(Path(os.environ[TIMES_ENV])), "pf-offboard-test-times")


class _TimeRecorder:
    """Each test's wall and CPU seconds (setup, call and teardown; CPU includes the subprocesses it
    waited for), written per process at the end of the session."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.times: dict[str, list[float]] = {}

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
        wall, cpu = time.perf_counter(), _cpu_s()
        yield
        self.times[item.nodeid] = [round(time.perf_counter() - wall, 3), round(_cpu_s() - cpu, 3)]

    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        if self.times:  # xdist's controller runs no test
            self.directory.mkdir(parents=True, exist_ok=True)
            worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
            (self.directory / f"times-{worker}.json").write_text(json.dumps(self.times, indent=0, sort_keys=True) + "\n")


def _cpu_s() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


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


def _expected_s() -> dict[str, tuple[float, float]]:
    """nodeid -> (wall s, CPU s) from DURATIONS (an unreadable file or entry: no expectation)."""
    try:
        data = json.loads(DURATIONS.read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict):
        return {}
    return {str(k): (float(v[0]), float(v[1])) for k, v in data.items()
            if isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) for x in v)}  # fmt: skip


def waits(wall_s: float, cpu_s: float) -> bool:
    """A unit that mostly waits: CPU below WAITING_SHARE of its wall time."""
    return cpu_s < WAITING_SHARE * wall_s


def queue_order(units: dict[str, tuple[float, float]]) -> list[str]:
    """The units (name -> expected (wall s, CPU s)) in queue order: the computing ones and the
    waiting ones (:func:`waits`) each longest first, taken in turn."""
    by_wall = sorted(units, key=lambda u: -units[u][0])  # stable: ties keep the collection order
    computing = [u for u in by_wall if not waits(*units[u])]
    waiting = [u for u in by_wall if waits(*units[u])]
    return [u for pair in itertools.zip_longest(computing, waiting) for u in pair if u is not None]


def _unit(item: pytest.Item) -> str:
    """The work unit xdist's loadgroup makes of ``item``: its group(s), or the test alone."""
    names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default")) for m in item.iter_markers("xdist_group")})
    return "@" + "_".join(names) if names else item.nodeid


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The groups of `--dist loadgroup` (a test without a group is a work unit of its own, so one
    long file does not hold one worker): the fixed-port tests form one group; a test using a class /
    module scoped fixture (the installed wheel, a fitted log) is grouped with its file, so that
    fixture is still built once. Then the order: :func:`queue_order` (DURATIONS above)."""
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
    cost: dict[str, tuple[float, float]] = {}
    for item in items:
        wall, cpu = cost.get(unit_of[item.nodeid], (0.0, 0.0))
        e_wall, e_cpu = expected.get(item.nodeid, (0.0, 0.0))
        cost[unit_of[item.nodeid]] = (wall + e_wall, cpu + e_cpu)
    rank = {unit: i for i, unit in enumerate(queue_order(cost))}
    items.sort(key=lambda item: rank[unit_of[item.nodeid]])  # stable: a unit's tests keep their order
    # xdist (3.8) marks a grouped test for loadgroup by appending "@group" to its node id, written
    # to `item._nodeid`; pytest 9 keeps the id in `item._id`, so that changed nothing and no test was
    # grouped (a module fixture built on both workers, the fixed-port tests side by side). Write
    # the same suffix where pytest reads the id; with an older pytest (it has `_nodeid`) xdist does.
    if getattr(config.option, "loadgroup", False):
        for item in items:
            unit = unit_of[item.nodeid]
            if unit.startswith("@") and not hasattr(item, "_nodeid") and hasattr(item, "_id"):
                item._id = type(item._id).parse(item.nodeid + unit)
