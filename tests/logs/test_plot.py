"""`pf-offboard plot` writes the paper's figures from step logs (synthetic circle flights here;
round trips from real sim flights are in tests/sim)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pf_offboard.cli import main
from pf_offboard.logs.plot import Run, make_figures
from pf_offboard.logs.steplog import StepLogWriter, StepRecord


def circle_flight(path: Path, start_xy: tuple[float, float], thrown: bool) -> None:
    """A vehicle spiralling onto the unit circle at 1 m/s, active after 0.4 s."""
    with StepLogWriter.open(path) as w:
        for i in range(300):
            t = 0.01 * i
            r = 1.0 + (np.hypot(*start_xy) - 1.0) * np.exp(-2 * t)
            a = np.arctan2(start_xy[1], start_xy[0]) + t
            pos = (r * np.cos(a), r * np.sin(a), 2.0)
            vel = (3.0, 0.0, 0.0) if thrown and i < 40 else (-np.sin(a), np.cos(a), 0.0)
            w.write(StepRecord(
                time_s=100.0 + t, mode="following" if i >= 40 else "waiting", active=i >= 40,
                position_enu_m=pos, velocity_enu_m_s=vel, lam=a, eta1_m=a, eta2_m_s=1.0 - np.exp(-t),
                xi1_m=r - 1.0, xi2_m_s=-2 * (r - 1.0), phi1_m=0.0, phi2_m_s=0.0, cross_track_m=abs(r - 1),
                speed_ref_m_s=1.0, accel_cmd_enu_m_s2=(0, 0, 0), thrust_cmd_m_s2=9.81,
                q_cmd_enu_flu=(1, 0, 0, 0), rates_cmd_flu_rad_s=(0, 0, 0), yaw_cmd_rad=0.0,
                yaw_rate_cmd_rad_s=0.0, sat_tangential=False, sat_transversal=False, sat_tilt=False,
                sat_thrust=False, sat_approach_speed=False, event="activated" if i == 40 else "",
            ))


def test_figures_written(tmp_path: Path) -> None:
    circle_flight(tmp_path / "PF1.csv", (0.0, -1.5), thrown=False)
    circle_flight(tmp_path / "PF2.csv", (2.0, 0.5), thrown=True)
    pngs = make_figures([tmp_path / "PF1.csv", tmp_path / "PF2.csv"], tmp_path / "fig")
    names = sorted(p.name for p in pngs)
    assert names == ["PF1_tangential.png", "PF1_transversal.png", "PF2_tangential.png", "PF2_transversal.png", "map.png", "path3d.png"]
    for p in pngs:
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and 5_000 < len(data) < 200_000


def test_activation_instants() -> None:
    rec = []
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        circle_flight(Path(d) / "a.csv", (0.0, -1.5), thrown=False)
        from pf_offboard.logs.steplog import read_steplog

        rec = read_steplog(Path(d) / "a.csv")
    run = Run.from_records("a", rec)
    assert run.activation_s == pytest.approx((0.40,))
    assert run.first_active == 40


def test_cli_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plot", str(tmp_path / "missing.csv"), "--out", str(tmp_path)]) == 2
    assert "no such file" in capsys.readouterr().err
    (tmp_path / "x.tlog").write_bytes(b"\0" * 20)
    assert main(["plot", str(tmp_path / "x.tlog"), "--out", str(tmp_path)]) == 2
    assert "x.tlog: is a ground station's tlog" in capsys.readouterr().err  # no step log beside it: needs --config
    circle_flight(tmp_path / "a.csv", (0.0, -1.5), thrown=False)
    assert main(["plot", str(tmp_path / "a.csv"), "--out", str(tmp_path / "x.tlog" / "figs")]) == 2
    err = capsys.readouterr().err
    assert "--out: cannot create directory" in err and "Traceback" not in err
    assert main(["plot", str(tmp_path), "--out", str(tmp_path / "figs")]) == 2
    assert "is a directory" in capsys.readouterr().err


def test_runs_named_after_their_directory(tmp_path: Path) -> None:
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        circle_flight(tmp_path / d / "flight.csv", (0.0, -1.5), thrown=False)
    pngs = make_figures([tmp_path / "a" / "flight.csv", tmp_path / "b" / "flight.csv"], tmp_path / "fig")
    assert {p.name for p in pngs} >= {"a_tangential.png", "b_transversal.png"}


def test_wrapped_arclength_is_not_drawn_as_a_jump() -> None:
    from pf_offboard.logs.plot import _break_wraps

    eta1 = np.array([14.0, 14.5, 15.0, 0.2, 0.7, 1.2])  # closed path of length ~15.2 m
    out = _break_wraps(eta1)
    assert np.isnan(out[2]) and np.all(np.isfinite(np.delete(out, 2)))
