"""The suite's own queue (tests/conftest.py) and the script that records its times
(scripts/test_durations.py): order only, but a wrong order costs CI minutes."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str, path: Path):  # type: ignore[no-untyped-def]
    """A module by its file (several test directories have a `conftest`: the name alone is ambiguous)."""
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_conftest = _load("suite_conftest", ROOT / "tests" / "conftest.py")
DURATIONS, WAITING_SHARE, _expected_s, queue_order, waits = (_conftest.DURATIONS, _conftest.WAITING_SHARE, _conftest._expected_s,
                                                        _conftest.queue_order, _conftest.waits)  # fmt: skip


def _script():  # type: ignore[no-untyped-def]
    return _load("test_durations_script", ROOT / "scripts" / "test_durations.py")


def test_computing_and_waiting_units_alternate_each_longest_first() -> None:
    units = {"short": (1.0, 1.0), "wait_long": (20.0, 2.0), "cpu_long": (10.0, 9.5), "wait_short": (5.0, 0.5),
             "cpu_mid": (4.0, 4.0), "new": (0.0, 0.0)}  # fmt: skip
    assert queue_order(units) == ["cpu_long", "wait_long", "cpu_mid", "wait_short", "short", "new"]


def test_the_share_decides_what_waits() -> None:
    edge = {"a": (10.0, 10.0 * WAITING_SHARE), "b": (10.0, 10.0 * WAITING_SHARE - 0.01), "c": (9.0, 9.0)}
    assert queue_order(edge) == ["a", "b", "c"]  # a computes (at the share), b waits, then c


def test_equal_units_keep_the_collection_order() -> None:
    units = {name: (0.0, 0.0) for name in ("z", "a", "m")}
    assert queue_order(units) == ["z", "a", "m"]


def test_the_committed_durations_have_wall_and_cpu_for_long_tests() -> None:
    expected = _expected_s()
    assert len(expected) > 100
    assert all(wall >= 0.5 and cpu >= 0.0 for wall, cpu in expected.values())
    waiting = [k for k, (wall, cpu) in expected.items() if waits(wall, cpu)]
    assert waiting and len(waiting) < len(expected)  # both kinds, or the alternation does nothing
    assert json.loads(DURATIONS.read_text()).keys() == expected.keys()


def test_the_script_keeps_the_long_tests_rounded() -> None:
    found = _script().durations({"t::long": [1.234, 0.456], "t::short": [0.3, 0.3]})
    assert found == {"t::long": [1.23, 0.46]}


@pytest.mark.parametrize(("content", "reason"), [(None, "no times-*.json with tests"), ("{not json", "cannot read"),
                                                 ('{"t::a": 1.0}', "not a map of test -> [wall s, CPU s]")])  # fmt: skip
def test_the_script_refuses_missing_or_bad_times(tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | None, reason: str) -> None:
    before = DURATIONS.read_bytes()
    if content is not None:
        (tmp_path / "times-gw0.json").write_text(content)
    assert _script().main([str(tmp_path)]) == 2
    assert reason in capsys.readouterr().err
    assert DURATIONS.read_bytes() == before  # nothing written
