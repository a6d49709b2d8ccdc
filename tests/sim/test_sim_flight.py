"""`pf-offboard sim`: in-process flights against the mock autopilot, their logs, and bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pf_offboard import frames
from pf_offboard.cli import main
from pf_offboard.config import load_config
from pf_offboard.errors import InputError
from pf_offboard.logs.plot import make_figures
from pf_offboard.logs.replay import replay_flight
from pf_offboard.logs.measures import path_tangent
from pf_offboard.logs.steplog import read_steplog
from pf_offboard.logs.summary import summarize
from pf_offboard.logs.tlog import read_tlog
from pf_offboard.sim import SimSpec, simulate

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "configs" / "paper.yaml"
EPOCH = 1_780_000_000.0


@pytest.fixture(scope="module")
def soft_paper(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The paper's path and speed with gentler gains (2 Hz / 1.5 Hz)."""
    text = PAPER.read_text()
    text = text.replace("transversal: {bandwidth_hz: 6.0", "transversal: {bandwidth_hz: 2.0")
    text = text.replace("tangential: {bandwidth_hz: 4.0", "tangential: {bandwidth_hz: 1.5")
    assert "bandwidth_hz: 2.0" in text and "bandwidth_hz: 1.5" in text
    path = tmp_path_factory.mktemp("cfg") / "paper_soft.yaml"
    path.write_text(text)
    return path


def test_hover_flight_logs_match_the_link(tmp_path: Path) -> None:
    spec = SimSpec(vehicle="fast", start_enu_m=(0.0, -1.5, 2.0), rate_hz=50.0, duration_s=2.0, epoch_unix_s=EPOCH)
    result = simulate(PAPER, spec, tmp_path)
    assert result.reason == "duration 2 s reached" and not result.crashed
    entries = read_tlog(result.paths.tlog)
    records = read_steplog(result.paths.steps_csv)
    assert records == result.records and len(records) == 101  # t = 0, 0.02, ..., 2.0
    positions = [e for e in entries if e.message.get_type() == "LOCAL_POSITION_NED"]
    setpoints = [e for e in entries if e.message.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    assert len(positions) == len(setpoints) == len(records)
    assert {e.direction for e in positions} == {"in"} and {e.direction for e in setpoints} == {"out"}
    assert {e.message.get_srcComponent() for e in setpoints} == {191}
    # each setpoint is logged right after the sample that produced it, stamped with its time
    for pos, sp, rec in zip(positions, setpoints, records):
        assert sp.message.time_boot_ms == pos.message.time_boot_ms == round(rec.time_s * 1000)
        assert pos.offset < sp.offset
        assert sp.time_unix_s == pytest.approx(EPOCH + rec.time_s, abs=2e-6)
        # the step log is the telemetry in ENU (float32 on the wire)
        ned = (pos.message.x, pos.message.y, pos.message.z)
        assert rec.position_enu_m == pytest.approx(tuple(frames.ned_to_enu(ned)), abs=0)
    assert records[0].position_enu_m == pytest.approx((0.0, -1.5, 2.0), abs=1e-4)
    assert [r.event for r in records if r.event] == ["activated"]
    assert result.paths.config_yaml.read_text() == PAPER.read_text()


def test_sim_is_deterministic(tmp_path: Path) -> None:
    spec = SimSpec(vehicle="fast", start_enu_m=(0.5, -1.0, 2.5), rate_hz=50.0, duration_s=1.0, epoch_unix_s=EPOCH, seed=7)
    a = simulate(PAPER, spec, tmp_path / "a")
    b = simulate(PAPER, spec, tmp_path / "b")
    assert a.paths.tlog.read_bytes() == b.paths.tlog.read_bytes()
    assert a.paths.steps_csv.read_bytes() == b.paths.steps_csv.read_bytes()


def test_soft_gains_converge_from_hover(tmp_path: Path, soft_paper: Path) -> None:
    """Closed loop (core + app pipeline + mock PX4): onto the paper's path and at speed."""
    spec = SimSpec(vehicle="fast", start_enu_m=(0.3, -1.8, 2.2), rate_hz=50.0, duration_s=7.0, epoch_unix_s=EPOCH)  # 0.39 m off
    result = simulate(soft_paper, spec, tmp_path)
    s = result.summary
    assert s.convergence_time_s is not None and s.convergence_time_s < 5.5, s.lines()
    # from activation + 5.5 s (the flight is 7 s): on the path, at speed (from the position's derivative)
    late = summarize(read_steplog(result.paths.steps_csv), path_tangent(load_config(soft_paper).path.spline()), settle_s=5.5).settled
    assert late is not None and late.cross_track_rms_m is not None and late.cross_track_rms_m < 0.01, late
    assert late.speed_error_rms_m_s is not None and late.speed_error_rms_m_s < 0.05, late
    assert replay_flight(result.paths.tlog, load_config(soft_paper)).ok


def test_throw_activates_at_the_height(tmp_path: Path, soft_paper: Path) -> None:
    throw = (1.0, -2.0, 1.0, 0.5, 1.0, 5.0)  # ENU: z up, thrown upwards at 5 m/s
    spec = SimSpec(vehicle="fast", throw_enu=throw, throw_height_m=2.0, rate_hz=50.0, duration_s=5.0, epoch_unix_s=EPOCH)
    result = simulate(soft_paper, spec, tmp_path)
    recs = result.records
    first = next(i for i, r in enumerate(recs) if r.active)
    assert first > 5 and all(r.mode == "waiting" and not r.active for r in recs[:first])
    # ballistic (motors locked) until the trigger: z follows the throw, drag 0.2/s only
    for r in recs[:first]:
        t = r.time_s
        z_vacuum = throw[2] + throw[5] * t - 0.5 * 9.80665 * t * t
        assert r.position_enu_m[2] == pytest.approx(z_vacuum, abs=0.05)
    # the trigger needs two samples beyond 2 m (ThrowTrigger.confirm): fired just above it
    assert recs[first - 1].position_enu_m[2] >= 2.0 and recs[first].position_enu_m[2] < 2.3
    assert result.activation_time_s == pytest.approx(recs[first].time_s)
    assert "throw trigger at" in recs[first].event
    assert result.summary.convergence_time_s is not None  # caught and on the path
    assert replay_flight(result.paths.tlog, load_config(soft_paper)).ok


def test_ardupilot_attitude_flight(tmp_path: Path) -> None:
    spec = SimSpec(vehicle="fast", start_enu_m=(0.0, -1.5, 2.0), autopilot="ardupilot", output_mode="attitude",
                   rate_hz=50.0, duration_s=1.0, epoch_unix_s=EPOCH)  # fmt: skip
    result = simulate(PAPER, spec, tmp_path)
    entries = read_tlog(result.paths.tlog)
    sent = [e.message for e in entries if e.direction == "out"]
    assert any(m.get_type() == "PARAM_SET" and m.param_id == "GUID_OPTIONS" and m.param_value == 8 for m in sent)
    att = [m for m in sent if m.get_type() == "SET_ATTITUDE_TARGET"]
    assert len(att) == len(result.records)
    hover = next(e.message.param_value for e in entries if e.message.get_type() == "PARAM_VALUE" and e.message.param_id == "MOT_THST_HOVER")
    # thrust normalised with the autopilot's hover thrust: level flight near hover_thrust
    assert all(0.0 < m.thrust < 1.0 for m in att)
    assert np.median([m.thrust for m in att]) == pytest.approx(hover, rel=0.5)
    assert replay_flight(result.paths.tlog, load_config(PAPER)).ok


def test_sim_then_plot(tmp_path: Path, soft_paper: Path) -> None:
    spec = SimSpec(vehicle="fast", start_enu_m=(0.0, -1.5, 2.0), rate_hz=50.0, duration_s=1.5, epoch_unix_s=EPOCH, name="PF1")
    result = simulate(soft_paper, spec, tmp_path)
    pngs = make_figures([result.paths.tlog], tmp_path / "fig")  # config found beside the log
    assert sorted(p.name for p in pngs) == ["PF1_tangential.png", "PF1_transversal.png", "map.png", "path3d.png"]


def test_cli_sim_replay_plot(tmp_path: Path, soft_paper: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    code = main(["sim", "--config", str(soft_paper), "--start", "0,-1.5,2", "--duration", "1", "--rate", "50",
                 "--epoch", str(EPOCH), "--out", str(out)])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "duration 1 s reached" in text and "logs:" in text
    assert main(["replay", str(out / "flight.tlog")]) == 0
    assert "MATCH" in capsys.readouterr().out
    assert main(["plot", str(out / "flight.csv"), "--out", str(tmp_path / "fig")]) == 0
    assert (tmp_path / "fig" / "path3d.png").stat().st_size > 5000


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--throw", "1,2,3,4,5"], "--throw: expected 6 comma-separated numbers"),
        (["--throw", "1,2,-1,0,0,5"], "--throw: z (up) must be > 0 m"),
        (["--start", "0,0,nan"], "--start: values must be finite"),
        (["--start", "0,0,0"], "--start: z (up) must be > 0.2 m"),
        (["--duration", "-1"], "--duration: must be in [0.01, 3600] s"),
        (["--rate", "1000"], "--rate: must be in [20, 250] Hz"),
        (["--name", "../x"], "--name: must be a plain file stem"),
        (["--seed", "-1"], "--seed: must be an integer in [0, 2^63)"),
    ],
)
def test_cli_bad_input(tmp_path: Path, flags: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--config", str(PAPER), "--out", str(tmp_path), *flags]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "flight.tlog").exists()  # nothing flown


def test_cli_unwritable_out(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "file").write_text("")
    assert main(["sim", "--config", str(PAPER), "--out", str(tmp_path / "file" / "out")]) == 2
    err = capsys.readouterr().err
    assert "--out: cannot create directory" in err and "Traceback" not in err


def test_cli_bad_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--config", str(tmp_path / "none.yaml"), "--out", str(tmp_path)]) == 2
    assert "--config: no such file" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text(PAPER.read_text().replace("speed_m_s: -1.5", "speed_m_s: fast"))
    assert main(["sim", "--config", str(bad), "--out", str(tmp_path)]) == 2
    assert "speed_m_s" in capsys.readouterr().err


def test_spec_checks() -> None:
    with pytest.raises(InputError, match="--autopilot"):
        simulate(PAPER, SimSpec(vehicle="fast", autopilot="inav"), "/nonexistent")
    with pytest.raises(InputError, match="--throw: give either --start"):
        simulate(PAPER, SimSpec(vehicle="fast", start_enu_m=(0, 0, 2), throw_enu=(0, 0, 1, 0, 0, 3)), "/nonexistent")


def test_laps_end_the_flight(tmp_path: Path, soft_paper: Path) -> None:
    from pf_offboard.control import PathFollower

    from pf_offboard.config import load_config

    length_m = PathFollower.from_config(load_config(soft_paper)).path.length_m
    spec = SimSpec(vehicle="fast", start_enu_m=(0.0, -1.5, 2.0), rate_hz=50.0, laps=0.2, epoch_unix_s=EPOCH)
    result = simulate(soft_paper, spec, tmp_path)
    assert result.reason == "0.2 laps done"
    steps = [b.eta1_m - a.eta1_m for a, b in zip(result.records[1:], result.records[2:])]
    travelled = sum(abs((d + length_m / 2) % length_m - length_m / 2) for d in steps)  # eta1 wraps
    assert travelled == pytest.approx(0.2 * length_m, abs=0.1)  # within about a step at 1.5 m/s
