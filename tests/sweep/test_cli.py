"""``pf-offboard sweep`` end to end (tiny), and bad flags: one line naming the flag, exit 2."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from pf_offboard.cli import main

from .helpers import PAPER

TINY_FLAGS = ["--vehicle", "fast", "--duration", "1.5", "--rate", "50", "--settle", "0.2", "--max-distance", "1",
              "--max-speed", "1"]


def test_a_tiny_sweep_writes_table_summary_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", "--config", str(PAPER), "--out", str(tmp_path), "--flights", "2", *TINY_FLAGS]) == 0
    out, err = capsys.readouterr()
    assert "2 flights in" in out and "caught after" in out and "2/2" in err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["flights"] == 2 and summary["executor"] == "serial" and summary["engine"] == "batch" and summary["settings"]["ranges"]["max_speed_m_s"] == 1.0
    assert (tmp_path / "flights.csv").read_text().count("\n") == 3
    assert (tmp_path / "roa.png").exists() and not (tmp_path / "flights").exists()


def test_a_gain_sweep_ranks_and_writes_the_best_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["sweep", "--config", str(PAPER), "--out", str(tmp_path), "--flights", "1", *TINY_FLAGS, "--gains", "random",
            "--gain-points", "2", "--bandwidth", "2:4", "--no-plot", "--quiet"]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert "gains (best first): #1" in out and err == ""
    ranking = (tmp_path / "gains.csv").read_text().splitlines()
    assert ranking[0].startswith("rank,gains_id,bandwidth_hz,damping") and len(ranking) == 3
    assert "bandwidth_hz" in (tmp_path / "best-gains.yaml").read_text() and not (tmp_path / "roa.png").exists()


@pytest.mark.parametrize(("flags", "message"), [
    (["--flights", "0"], "--flights: must be in [1, 1000000]"),
    (["--workers", "0"], "--workers: must be in [1, 256]"),
    (["--max-speed", "-1"], "--max-speed: must be in [0, 30]"),
    (["--tube", "2", "--stay", "1"], "--stay: must be in [--tube, 50] m"),
    (["--settle", "20"], "--settle: must be in [0, --duration) s"),
    (["--cluster", "nowhere"], "--cluster: expected 'local' or a Dask scheduler address"),
    (["--bandwidth", "1:2"], "--bandwidth: only a gain sweep (--gains grid|random) takes it"),
    (["--gains", "grid", "--damping", "1.2:0.6"], "--damping: need 0.01 <= LO <= HI <= 5"),
    (["--rate", "5"], "--rate: must be in [20, 250] Hz"),
    (["--seed", "-1"], "--seed: must be an integer in [0, 2^63)"),
    (["--vehicle", "fast,blimp"], "--vehicle: unknown vehicle 'blimp'"),
    (["--vehicle", "fast,fast"], "--vehicle: a vehicle given twice"),
])
def test_bad_flags_exit_2_with_one_line(tmp_path: Path, flags: list[str], message: str,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", "--config", str(PAPER), "--out", str(tmp_path / "o"), *flags]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and err.startswith("pf-offboard sweep: error: ")
    assert not (tmp_path / "o" / "flights.csv").exists()


def test_a_gain_sweep_over_two_vehicles_ranks_each(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    flags = [f if f != "fast" else "fast,px4-sih" for f in TINY_FLAGS]
    argv = ["sweep", "--config", str(PAPER), "--out", str(tmp_path), "--flights", "2", *flags, "--gains", "grid",
            "--gain-points", "2", "--bandwidth", "2:4", "--no-plot", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "gains on fast (best first): #1" in out and "gains on px4-sih (best first): #1" in out
    rows = list(csv.DictReader((tmp_path / "flights.csv").open()))
    assert len(rows) == 2 * 4 * 2 and [r["vehicle"] for r in rows] == ["fast"] * 8 + ["px4-sih"] * 8
    # the same starts on both vehicles
    assert [r["pos_enu_x_m"] for r in rows[:8]] == [r["pos_enu_x_m"] for r in rows[8:]]
    for v in ("fast", "px4-sih"):
        assert len((tmp_path / f"gains-{v}.csv").read_text().splitlines()) == 5
        assert "bandwidth_hz" in (tmp_path / f"best-gains-{v}.yaml").read_text()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["settings"]["vehicles"] == ["fast", "px4-sih"] and "gain_ranking_px4_sih" in summary
