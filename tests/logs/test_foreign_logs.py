"""Logs as users have them: PX4 ULogs and ground-station tlogs in plot, clear errors from replay."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from pf_offboard.cli import main
from pf_offboard.config import load_config
from pf_offboard.control import PathFollower
from pf_offboard.logs.foreign import read_foreign_tlog, step_records
from pf_offboard.logs.plot import load_runs
from pf_offboard.logs.steplog import read_steplog
from pf_offboard.shipped import resolve_config

ULOG = Path(__file__).resolve().parents[1] / "data" / "ulog" / "px4_sih_offboard.ulg"


def test_plot_draws_a_px4_ulog_with_its_ground_truth(tmp_path, capsys) -> None:
    assert main(["plot", str(ULOG), "--out", str(tmp_path)]) == 2
    assert f"{ULOG}: is a PX4 ULog: pass --config" in capsys.readouterr().err
    assert main(["plot", str(ULOG), "--config", "px4-sih", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "px4_sih_offboard: from activation + 8 s" in out and "px4_sih_offboard-truth: from activation + 8 s" in out
    names = sorted(p.name for p in tmp_path.glob("*.png"))
    assert names == ["map.png", "path3d.png", "px4_sih_offboard-truth_tangential.png", "px4_sih_offboard-truth_transversal.png",
                     "px4_sih_offboard_tangential.png", "px4_sih_offboard_transversal.png"]  # fmt: skip
    estimate, truth = load_runs(ULOG, resolve_config("px4-sih"))
    active = np.array([r.active for r in estimate.records])
    e = estimate.col("cross_track_m")[active]
    assert 0.2 * len(active) < active.sum() and np.sqrt(np.mean(e[len(e) // 3 :] ** 2)) < 0.10  # the estimate on the path
    t = truth.col("cross_track_m")[np.array([r.active for r in truth.records])]
    assert np.sqrt(np.mean(t[len(t) // 3 :] ** 2)) > np.sqrt(np.mean(e[len(e) // 3 :] ** 2))  # SIH: EKF2 is off the truth


def test_a_ground_stations_tlog_is_read_leniently(tmp_path) -> None:
    """Our own tlog without its step CSV, with 200 bytes of garbage in the middle, as a ground
    station's log: the strict reader refuses it, the lenient one skips the garbage."""
    assert main(["sim", "--config", "px4-sih", "--duration", "10", "--out", str(tmp_path / "sim"), "--json"]) == 0
    data = (tmp_path / "sim" / "flight.tlog").read_bytes()
    cut = len(data) // 2
    foreign = tmp_path / "gcs" / "qgc.tlog"
    foreign.parent.mkdir()
    foreign.write_bytes(data[:cut] + bytes(range(200)) + data[cut:])
    track = read_foreign_tlog(foreign)
    assert track.active.any() and "undecodable" in track.note
    config = load_config(resolve_config("px4-sih"))
    records = step_records(track, PathFollower.from_config(config))
    ours = [r for r in read_steplog(tmp_path / "sim" / "flight.csv") if r.active]
    mine = [r for r in records if r.active]
    # the same flight: the path coordinates recomputed from the telemetry agree with the app's own
    assert abs(np.sqrt(np.mean([r.cross_track_m**2 for r in mine])) - np.sqrt(np.mean([r.cross_track_m**2 for r in ours]))) < 0.01
    assert main(["plot", str(foreign), "--config", "px4-sih", "--out", str(tmp_path / "figs")]) == 0
    assert (tmp_path / "figs" / "map.png").exists()
    # a MAVProxy log of the companion's link holds the setpoints too: identify fits it, garbage and all
    assert main(["identify", str(foreign), "--json"]) == 0


def test_replay_names_the_missing_log_and_refuses_a_ulog(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["replay", "nope.tlog"]) == 2
    err = capsys.readouterr().err
    assert "nope.tlog: no such file" in err and "yaml" not in err
    shutil.copy(ULOG, tmp_path / "f.ulg")
    assert main(["replay", "f.ulg"]) == 2
    assert "f.ulg: is a PX4 ULog" in capsys.readouterr().err


def test_a_fifo_a_device_or_a_huge_file_never_reaches_pymavlink_or_pyulog(tmp_path) -> None:
    """The lenient readers hand the file to pymavlink / pyulog, which block on a FIFO and scan a huge
    file to its end (a 3 GiB sparse file took seconds per read in the CLI fuzz): refused first, each
    with one reason naming the file, as the strict reader refuses them."""
    import os
    import time

    import pytest

    from pf_offboard.errors import InputError
    from pf_offboard.logs.foreign import iter_tlog_lenient
    from pf_offboard.logs.ulog import read_ulog

    os.mkfifo(tmp_path / "fifo.tlog", 0o600)
    with open(tmp_path / "huge.tlog", "wb") as fh:  # sparse: takes no space
        fh.truncate(3 << 30)
    readers = (lambda p: list(iter_tlog_lenient(p)), read_foreign_tlog, read_ulog)
    cases = ((tmp_path / "fifo.tlog", "a FIFO"), (tmp_path / "huge.tlog", "larger than the 2.0 GiB"), (Path("/dev/zero"), "a character device"))
    for read in readers:
        for path, reason in cases:
            started = time.monotonic()
            with pytest.raises(InputError) as err:
                read(path)
            assert reason in str(err.value) and str(path) in str(err.value)
            assert time.monotonic() - started < 1.0  # refused, not read
