"""Sweep flights as tasks: the same rows whatever the executor, the judge, logs only when asked."""

from __future__ import annotations

import dataclasses
import io
import math
from pathlib import Path
from types import SimpleNamespace

import pytest

from pf_offboard.errors import InputError
from pf_offboard.sweep import plan
from pf_offboard.sweep.runner import FlightSettings, Progress, _Judge, execute, rows_equal, run_flight

from .helpers import PAPER, tiny_spec


@pytest.fixture(scope="module")
def tasks():  # type: ignore[no-untyped-def]
    return plan.tasks(PAPER, tiny_spec(4))


def _broken(task, index: int):  # type: ignore[no-untyped-def]
    """A task whose flight fails (a row full of NaN), as flight ``index``."""
    return dataclasses.replace(task, start=dataclasses.replace(task.start, index=index), config_yaml="path: 3\n")


@pytest.fixture(scope="module")
def serial_rows(tasks):  # type: ignore[no-untyped-def]
    return execute(tasks, workers=1)


def test_serial_and_process_pool_give_the_same_rows(tasks, serial_rows) -> None:  # type: ignore[no-untyped-def]
    broken = _broken(tasks[0], 4)
    pooled = execute([broken, *tasks[::-1]], workers=2)  # submitted in another order: rows still sorted
    assert rows_equal(pooled, [*serial_rows, run_flight(broken)])
    assert not rows_equal(pooled[:4], serial_rows[::-1])
    assert [r["flight"] for r in serial_rows] == [0, 1, 2, 3]
    assert all(r["activation_time_s"] < 0.1 for r in serial_rows)  # engaged at the drawn state
    assert all(not r["reason"].startswith("error") for r in serial_rows)
    assert all(r["first_in_tube_time_s"] <= r["caught_time_s"] for r in serial_rows if r["success"])


def test_a_sweep_of_more_flights_repeats_the_first_ones(serial_rows) -> None:  # type: ignore[no-untyped-def]
    more = plan.tasks(PAPER, tiny_spec(5))
    assert run_flight(more[2]) == serial_rows[2]


def test_no_files_unless_logs_are_asked_for(tmp_path: Path, tasks, serial_rows) -> None:  # type: ignore[no-untyped-def]
    row = run_flight(dataclasses.replace(tasks[1], logs_dir=str(tmp_path)))
    assert row == serial_rows[1]  # logs do not change the flight
    stem = tmp_path / "flight-000001"
    assert {p.name for p in stem.iterdir()} >= {"flight-000001.tlog", "flight-000001.csv", "flight-000001.yaml", "summary.json"}


def test_a_broken_flight_is_a_row_not_a_lost_sweep(tasks) -> None:  # type: ignore[no-untyped-def]
    row = run_flight(dataclasses.replace(tasks[0], config_yaml="path: 3\n"))
    assert row["success"] is False and row["reason"].startswith("error: ConfigError") and math.isnan(row["caught_time_s"])


def _step(t: float, ct: float, active: bool = True) -> SimpleNamespace:
    return SimpleNamespace(time_s=t, active=active, cross_track_m=ct, eta2_m_s=-1.5, speed_ref_m_s=-1.5)


def test_the_judge_has_two_tubes() -> None:
    """Converged: inside the inner tube, never again beyond the outer one; a pass through the path
    on the way out does not count."""
    summary = SimpleNamespace(add=lambda r: None)
    judge = _Judge(summary, FlightSettings(tube_m=0.3, stay_m=1.0))
    cts = [(0.0, 2.0, False), (0.1, 0.2, True), (0.2, 1.5, True), (0.3, 0.8, True), (0.4, 0.25, True), (0.5, 0.9, True),
           (0.6, math.nan, True), (0.7, 0.1, True), (0.8, 0.95, True)]
    for t, ct, active in cts:
        judge.add(_step(t, ct, active))
    assert (judge.activation_s, judge.first_converged_s, judge.converged_s, judge.last_out_s) == (0.1, 0.1, 0.7, 0.6)
    assert judge.max_after_m == 0.95 and judge.rms_after_m == pytest.approx(math.sqrt((0.01 + 0.95**2) / 2))


def test_progress_is_plain_text_per_tenth_off_a_terminal() -> None:
    clock = iter(float(t) for t in range(100))
    out = io.StringIO()
    bar = Progress(20, stream=out, clock=lambda: next(clock))
    for i in range(20):
        bar.update(i % 4 != 0)
    lines = out.getvalue().splitlines()
    assert len(lines) == 11 and "\r" not in out.getvalue()  # the first flight, then each tenth
    assert lines[-1].startswith("sweep [##############################] 20/20 ok 75.0 %")


@pytest.mark.parametrize(("kwargs", "flag"), [
    ({"duration_s": 0.5}, "--duration"), ({"tube_m": 0.0}, "--tube"), ({"stay_m": 0.1}, "--stay"),
    ({"speed_tol_m_s": -1.0}, "--speed-tol"), ({"settle_s": 30.0}, "--settle"),
])
def test_bad_settings_name_the_flag(kwargs: dict[str, float], flag: str) -> None:
    with pytest.raises(InputError) as exc:
        FlightSettings(**kwargs).validate()
    assert exc.value.field == flag


def test_workers_out_of_range(tasks) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match="--workers"):
        execute(tasks, workers=0)


def test_batch_chunks_on_a_process_pool_give_the_scalar_rows(tasks, serial_rows, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    from pf_offboard.sim.batch import flight as batch_flight

    monkeypatch.setattr(batch_flight, "MIN_CHUNK", 2)  # 4 flights: two chunks, one per worker
    chunks, scalar = batch_flight.plan_chunks(tasks, parts=2)
    assert [len(c.tasks) for c in chunks] == [2, 2] and not scalar
    assert rows_equal(execute(tasks, workers=2, engine="batch"), serial_rows)
    assert rows_equal(execute(tasks, workers=1, engine="scalar"), serial_rows)
    with pytest.raises(InputError, match="--engine"):
        execute(tasks, engine="fast")
