"""`pf-offboard demo` as shipped: the default mock vehicle is the realistic `px4-sih` (PX4's SIH
quad as calibrated against the real one, with EKF2-like estimate error), flown with the shipped
`px4-sih` config over loopback MAVLink, `--takeoff 2 --laps 2` as `fly` does, from activation + 8 s
as issue 8 measures. Measured: 2.4–2.7 / 2.3–2.6 / 2.2–2.4 cm, 3.1–3.4 / 3.1 / 3.3–3.6 cm/s in
acceleration / attitude / rates (two runs each; with the hand-set vehicle section before, 2.7 /
2.7–2.8 / 2.4–2.7 cm, 3.2 / 3.5–3.9 / 4.0–4.8 cm/s). Over sockets the lockstep clock also advances on the app's
wall-clock keep-alive setpoints, so the take-off's timing, and with it the stretch of estimate
noise the two laps see, moves the speed error by ±0.4 cm/s between runs (rates: 4.0–4.8 cm/s in
six): the cross-track and mean targets (5 cm, 2 cm/s) are asserted as they are, the speed error's
5 cm/s with a 1 cm/s allowance; tests/sim/test_sim_px4_sih_speed_loop.py pins < 5 cm/s on a
deterministic in-process flight."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pf_offboard.cli import main
from pf_offboard.logs.steplog import read_steplog

pytestmark = pytest.mark.integration


def _demo(capsys: pytest.CaptureFixture[str], log_dir: Path, *flags: str) -> str:
    """The command's stderr. Run through the console script's entry point in process (no interpreter
    start-up per demo; `python -m pf_offboard demo` itself: tests/app/test_fly_integration.py)."""
    code = main(["demo", "--no-plots", "--quiet", "--log-dir", str(log_dir), *flags])
    err = capsys.readouterr().err
    assert code == 0, err
    return err


@pytest.mark.parametrize("output", ["acceleration", "attitude", "rates"])
def test_demo_flies_the_realistic_vehicle_within_issue_8s_targets(tmp_path: Path, capsys: pytest.CaptureFixture[str], output: str) -> None:
    err = _demo(capsys, tmp_path, "--output", output)
    assert "vehicle px4-sih" in err and "px4-sih.yaml" in err and "2 laps done; handed back in AUTO.LOITER" in err, err
    recs = [r for r in read_steplog(tmp_path / "flight.csv") if r.mode == "following"]
    late = [r for r in recs if r.time_s >= recs[0].time_s + 8.0]
    assert late[-1].time_s - late[0].time_s > 12.0  # two laps of 10.4 s from activation + 8 s
    ct = np.array([r.cross_track_m for r in late])
    err_speed = np.array([r.eta2_m_s - r.speed_ref_m_s for r in late])
    rms_ct, rms_speed, mean_speed = float(np.sqrt(np.mean(ct**2))), float(np.sqrt(np.mean(err_speed**2))), float(np.mean(err_speed))
    print(f"\ndemo {output}: {100 * rms_ct:.2f} cm, {100 * rms_speed:.2f} cm/s (mean {100 * mean_speed:+.2f})")
    assert rms_ct <= 0.05 and rms_speed <= 0.06 and abs(mean_speed) <= 0.02
    # it is the realistic vehicle, not the ideal one: the estimate's error shows
    assert rms_ct > 0.005


def test_demo_ideal_vehicle_is_asked_for_by_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = _demo(capsys, tmp_path, "--vehicle", "fast", "--laps", "1")
    assert "vehicle fast" in err and "paper.yaml" in err, err
    recs = [r for r in read_steplog(tmp_path / "flight.csv") if r.mode == "following"]
    late = [r for r in recs if r.time_s >= recs[0].time_s + 3.0]
    assert float(np.sqrt(np.mean([r.cross_track_m**2 for r in late]))) < 0.001  # the paper's ideal: below a millimetre
