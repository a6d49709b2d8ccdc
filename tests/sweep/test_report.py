"""The sweep's table, statistics, plot, and the sim command that flies a row again."""

from __future__ import annotations

import argparse
import csv
import json
import math
import shlex
from dataclasses import asdict
from pathlib import Path

import pytest

from pf_offboard.sweep import plan, report
from pf_offboard.sweep.runner import run_flight

from .helpers import PAPER, TINY, tiny_spec


def _row(i: int, ok: bool, t: float, reason: str = "duration 15 s reached") -> dict[str, object]:
    return {"flight": i, "success": ok, "crashed": False, "ground_contact": False, "caught_time_s": t if ok else math.nan,
            "first_in_tube_time_s": t / 2 if ok else math.nan,
            "reason": reason, "distance_m": float(i), "speed_m_s": 1.0, "tilt_deg": 10.0, "rate_rad_s": 0.5, "wind_m_s": 1.0,
            "pos_enu_z_m": 3.0, "vel_enu_z_m_s": 0.0}


def test_statistics_and_failure_kinds() -> None:
    rows = [_row(i, True, float(i)) for i in range(1, 11)]
    rows += [_row(11, False, 0, "duration 15 s reached; never within 0.3 m of the path"),
             _row(12, False, 0, "duration 15 s reached; within 0.3 m at 1.00 s, then beyond 1 m (max 1.2 m, last at 9 s) and not back by the end")]
    stats = report.summarize(rows)
    assert stats["success_rate"] == pytest.approx(10 / 12)
    assert stats["caught_time"]["p50_s"] == pytest.approx(5.5) and stats["caught_time"]["max_s"] == 10.0
    assert stats["first_in_tube_time"]["p50_s"] == pytest.approx(2.75)
    assert stats["failures_by_kind"] == {"left the tube after being caught": 1, "never caught": 1}
    assert stats["failed_start_ranges"]["distance_m"] == [11.0, 12.0]
    assert [b["success_rate"] for b in stats["success_rate_by_start"]["distance_m"]][-1] < 1.0
    assert any("failed starts" in line for line in report.lines(stats))


def test_table_round_trips_and_plot_is_written(tmp_path: Path) -> None:
    rows = [_row(i, i % 3 != 0, 1.0 + i) for i in range(6)]
    files = report.write_table(rows, tmp_path)
    assert files[0].name == "flights.csv"
    back = list(csv.DictReader(files[0].open()))
    assert [float(r["distance_m"]) for r in back] == [r["distance_m"] for r in rows]
    png = report.roa_plot(rows, tmp_path / "roa.png", "test")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_parquet_when_pyarrow_is_there(tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    files = report.write_table([_row(0, True, 1.0)], tmp_path)
    assert pq.read_table(files[1]).num_rows == 1


def test_the_sim_command_flies_the_same_flight(tmp_path: Path) -> None:
    """The command listed for a failure reproduces that row's flight, with its logs."""
    from pf_offboard.logs.summary import SUMMARY_JSON
    from pf_offboard.sim import cli as sim_cli

    task = plan.tasks(PAPER, tiny_spec(2))[1]
    row = run_flight(task)
    command = report.sim_command(row, str(PAPER), asdict(TINY))
    argv = shlex.split(command)
    assert argv[:2] == ["pf-offboard", "sim"] and argv[-2:] == ["--out", "flight-000001"]
    parser = argparse.ArgumentParser()
    sim_cli.add_arguments(parser)
    assert sim_cli.run(parser.parse_args([*argv[2:-2], "--out", str(tmp_path), "--json"])) == 0
    flown = json.loads((tmp_path / SUMMARY_JSON).read_text())
    assert flown["summary"]["whole_flight"]["cross_track_max_m"] == row["cross_track_max_m"]
