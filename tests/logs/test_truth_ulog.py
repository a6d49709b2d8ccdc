"""A flight against PX4 SIH's ground truth from a ULog: the frames' constant offset is separated
from the estimate's error, and the truth's own tracking figures come from its position."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pf_offboard import frames
from pf_offboard.cli import main
from pf_offboard.config import load_config
from pf_offboard.errors import InputError
from pf_offboard.logs.steplog import read_steplog
from pf_offboard.logs.truth import judge_truth, read_ulog_truth

from .ulog_writer import write_ulog

TOPIC = "vehicle_local_position_groundtruth"
OFFSET_NED_M = np.array([0.2, -0.1, 0.6])  # estimate - truth, constant


def _flight(tmp_path: Path) -> Path:
    """A 14 s sim flight (in process, no sockets) with its logs."""
    out = tmp_path / "flight"
    assert main(["sim", "--config", "px4-sih", "--duration", "14", "--out", str(out)]) == 0
    return out


def _truth(out: Path, tmp_path: Path, amplitude_m: float) -> tuple[Path, np.ndarray]:
    """A ULog whose truth is the flight's estimate minus the offset minus a 0.3 Hz north error."""
    recs = read_steplog(out / "flight.csv")
    t = np.array([r.time_s for r in recs])
    est = np.array([frames.enu_to_ned(r.position_enu_m) for r in recs], dtype=float)
    err = np.zeros_like(est)
    err[:, 0] = amplitude_m * np.sin(2 * np.pi * 0.3 * t)
    truth = est - OFFSET_NED_M - err
    return write_ulog(tmp_path / "sih.ulg", TOPIC, ("x", "y", "z"), (t * 1e6).round().astype(int), truth), err


def test_offset_and_estimate_error_are_separated(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = _flight(tmp_path)
    ulg, err = _truth(out, tmp_path, 0.05)
    capsys.readouterr()
    t_s, ned = read_ulog_truth(ulg)
    recs = read_steplog(out / "flight.csv")
    path = load_config(out / "flight.yaml").path.spline()
    r = judge_truth(recs, t_s, ned, path)
    t = np.array([x.time_s for x in recs])
    act = [x.time_s for x in recs if x.active]
    win = (t >= act[0] + 8.0) & (t <= act[-1]) & np.array([x.active for x in recs])
    e = err[win, 0]
    assert r.frame_offset_ned_m == pytest.approx(OFFSET_NED_M + [e.mean(), 0, 0], abs=2e-6)  # float32 in the ULog
    assert r.estimate_error_rms_ned_m[0] == pytest.approx(math.sqrt(np.mean((e - e.mean()) ** 2)), abs=2e-6)
    assert r.estimate_error_rms_ned_m[1] < 1e-5 and r.estimate_error_rms_ned_m[2] < 1e-5
    assert r.truth is not None and r.truth.window == "from activation + 8 s"
    # the truth moved by the offset is the estimate up to the error: its cross-track RMS is within
    # the error's RMS of the estimate's (triangle inequality, sample by sample)
    ct_est = np.array([x.cross_track_m for x in recs])[win]
    assert abs(r.truth.cross_track_rms_m - math.sqrt(np.mean(ct_est**2))) <= 0.05 + 1e-6
    # the raw truth carries the whole offset (0.64 m) on a path flown within centimetres
    assert r.truth_raw_cross_track_rms_m > 0.4
    # the CLI: replay --truth prints it
    assert main(["replay", str(out / "flight.tlog"), "--truth", str(ulg)]) == 0
    printed = capsys.readouterr().out
    assert "frame offset" in printed and "truth + offset: from activation + 8 s" in printed


def test_a_truthless_or_broken_ulog_is_refused(tmp_path: Path) -> None:
    other = write_ulog(tmp_path / "other.ulg", "vehicle_local_position", ("x", "y", "z"), [0, 10_000], [(0, 0, 0), (1, 1, 1)])
    with pytest.raises(InputError, match="no vehicle_local_position_groundtruth"):
        read_ulog_truth(other)
    junk = tmp_path / "junk.ulg"
    junk.write_bytes(b"not a ulog at all")
    with pytest.raises(InputError, match="junk.ulg"):
        read_ulog_truth(junk)
    golden = Path(__file__).resolve().parents[1] / "data" / "paper_hover_px4.tlog.gz"
    assert main(["replay", str(golden), "--truth", str(junk)]) == 2


def test_the_truth_stays_on_the_estimates_branch_at_a_crossing(tmp_path: Path) -> None:
    """On a figure-eight a fresh closest-point search near the crossing can land on the other
    branch (its tangent crosses this one's): a truth equal to the estimate (offset aside) must give
    the estimate's own figures, speed error included."""
    config = Path(__file__).resolve().parents[1] / "real_sitl" / "configs" / "figure8-tilted.yaml"
    out = tmp_path / "flight"
    assert main(["sim", "--config", str(config), "--duration", "24", "--out", str(out)]) == 0
    recs = read_steplog(out / "flight.csv")
    t = np.array([r.time_s for r in recs])
    truth = np.array([frames.enu_to_ned(r.position_enu_m) for r in recs], dtype=float) - OFFSET_NED_M
    ulg = write_ulog(tmp_path / "sih.ulg", TOPIC, ("x", "y", "z"), (t * 1e6).round().astype(int), truth)
    t_s, ned = read_ulog_truth(ulg)
    path = load_config(config).path.spline()
    r = judge_truth(recs, t_s, ned, path)
    from pf_offboard.logs import measures

    est = measures.tracking_of_records(recs, measures.path_tangent(path)).settled
    assert r.truth is not None and est is not None and est.speed_error_rms_m_s is not None
    assert r.truth.speed_error_rms_m_s == pytest.approx(est.speed_error_rms_m_s, abs=2e-3)
    assert r.truth.cross_track_rms_m == pytest.approx(est.cross_track_rms_m, abs=1e-3)
