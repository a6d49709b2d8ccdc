"""Replay-driven regression tests on the golden flights in tests/data/.

Each golden is a recorded flight of the app's pipeline against the mock autopilot
(scripts/regenerate_golden.py). Replaying its telemetry through today's controller must give
the recorded setpoints (float32, as flown) and step records (float64) to <= 1e-9. When the
controller's behaviour changes, these tests fail until the goldens are regenerated on purpose.
"""

from __future__ import annotations

import dataclasses
import gzip
from pathlib import Path

import pytest

from pf_offboard.cli import main
from pf_offboard.config import load_config
from pf_offboard.logs.replay import ReplayOptions, replay_flight
from pf_offboard.logs.steplog import read_steplog
from pf_offboard.logs.tlog import read_tlog

DATA = Path(__file__).resolve().parents[1] / "data"
GOLDENS = ("paper_hover_px4", "paper_throw_px4", "paper_hover_ardupilot")
REGENERATE = "python scripts/regenerate_golden.py"


def golden(name: str) -> tuple[Path, Path, Path]:
    return DATA / f"{name}.tlog.gz", DATA / f"{name}.csv.gz", DATA / f"{name}.yaml"


@pytest.mark.parametrize("name", GOLDENS)
def test_golden_replays_exactly(name: str) -> None:
    tlog, csv, yaml = golden(name)
    report = replay_flight(tlog, load_config(yaml))
    rows = len(read_steplog(csv))
    assert report.steps == rows > 200
    assert not report.problems, report.problems
    assert report.setpoint_max is not None and report.record_max is not None
    assert report.setpoint_max.excess <= 1e-9 and report.record_max.abs_diff <= 1e-9, (
        "the controller no longer reproduces golden flight " + name + ":\n  " + "\n  ".join(report.lines())
        + f"\nIf this change of behaviour is intended, run `{REGENERATE}` and commit tests/data/."
    )
    assert report.ok


def test_goldens_are_what_they_claim() -> None:
    hover = read_tlog(golden("paper_hover_px4")[0])
    assert {e.message.autopilot for e in hover if e.message.get_type() == "HEARTBEAT"} == {12}  # PX4
    assert {e.message.get_type() for e in hover if e.direction == "out"} >= {"SET_POSITION_TARGET_LOCAL_NED", "COMMAND_LONG"}
    ardu = read_tlog(golden("paper_hover_ardupilot")[0])
    assert {e.message.autopilot for e in ardu if e.message.get_type() == "HEARTBEAT"} == {3}  # ArduPilot
    assert "SET_ATTITUDE_TARGET" in {e.message.get_type() for e in ardu if e.direction == "out"}
    rec = read_steplog(golden("paper_hover_px4")[1])
    assert rec[0].position_enu_m == pytest.approx((0.0, -1.5, 2.0), abs=1e-6)  # PF1 start
    assert rec[0].speed_ref_m_s == -1.5
    throw = read_steplog(golden("paper_throw_px4")[1])
    first = next(r for r in throw if r.active)
    assert not throw[0].active and first.time_s > 0.1
    assert first.position_enu_m[2] == pytest.approx(2.0, abs=0.15)  # activation height crossed
    assert first.velocity_enu_m_s[2] > 1.0  # still climbing from the throw


def _perturbed(yaml: Path, **gains: float):
    cfg = load_config(yaml)
    return dataclasses.replace(cfg, gains=dataclasses.replace(cfg.gains, **gains))


@pytest.mark.parametrize(
    "change",
    [{"transversal_bandwidth_hz": 6.0 * 1.001}, {"tangential_damping": 0.8 * 1.001}],
    ids=["transversal_bandwidth", "tangential_damping"],
)
def test_replay_catches_a_changed_gain(change: dict[str, float]) -> None:
    tlog, _, yaml = golden("paper_hover_px4")
    cfg = _perturbed(yaml, **change)
    assert any(getattr(cfg.gains, k) != getattr(load_config(yaml).gains, k) for k in change)
    report = replay_flight(tlog, cfg)
    assert not report.ok
    assert report.record_max is not None and report.record_max.abs_diff > 1e-6
    assert report.setpoint_max is not None and report.setpoint_max.excess > 1e-6
    assert any(line.startswith("DIFFERENT") for line in report.lines())


def test_cli_replay_exit_codes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    tlog, _, yaml = golden("paper_throw_px4")
    assert main(["replay", str(tlog)]) == 0  # config found beside the log
    out = capsys.readouterr().out
    assert "MATCH" in out and "converged" in out and "mode change" in out
    # the same flight against a config with another reference speed: different setpoints, exit 1
    text = yaml.read_text().replace("speed_m_s: -1.5", "speed_m_s: -1.4")
    assert text != yaml.read_text()
    (tmp_path / "other.yaml").write_text(text)
    assert main(["replay", str(tlog), "--config", str(tmp_path / "other.yaml")]) == 1
    out = capsys.readouterr().out
    assert "DIFFERENT" in out and "largest setpoint difference: SET_POSITION_TARGET_LOCAL_NED." in out


def _plain_copy(name: str, dst: Path) -> tuple[Path, bytes]:
    tlog, csv, yaml = golden(name)
    data = gzip.decompress(tlog.read_bytes())
    (dst / "f.csv").write_bytes(gzip.decompress(csv.read_bytes()))
    (dst / "f.yaml").write_bytes(yaml.read_bytes())
    return dst / "f.tlog", data


def test_corrupted_golden_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, data = _plain_copy("paper_hover_px4", tmp_path)
    entries = read_tlog(DATA / "paper_hover_px4.tlog.gz")
    victim = entries[len(entries) // 2]
    corrupt = bytearray(data)
    corrupt[victim.offset + 8 + 11] ^= 0x5A  # a payload byte of a frame in the middle
    path.write_bytes(bytes(corrupt))
    assert main(["replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"@ byte {victim.offset}" in err and "CRC" in err and "Traceback" not in err


def test_truncated_golden_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, data = _plain_copy("paper_throw_px4", tmp_path)
    entries = read_tlog(DATA / "paper_throw_px4.tlog.gz")
    path.write_bytes(data[: entries[-1].offset + 15])  # the last record cut after 15 bytes
    assert main(["replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"@ byte {entries[-1].offset}: truncated record" in err and "Traceback" not in err


def test_replay_without_step_log_names_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, data = _plain_copy("paper_hover_ardupilot", tmp_path)
    path.write_bytes(data)
    (tmp_path / "f.csv").unlink()
    assert main(["replay", str(path)]) == 2
    assert "--steps: no step log" in capsys.readouterr().err


def test_replay_options_override_profile_detection() -> None:
    tlog, _, yaml = golden("paper_hover_ardupilot")
    # read as PX4 the attitude setpoints carry only the yaw-rate feed-forward: they differ
    report = replay_flight(tlog, load_config(yaml), options=ReplayOptions(autopilot="px4", hover_thrust=1.0 / 3.5))
    assert report.profile == "px4" and not report.ok


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--tolerance", "nan"], "--tolerance: must be a finite number"),
        (["--hover-thrust", "2"], "--hover-thrust: must be in [0.05, 0.95]"),
        (["--config", "/nonexistent.yaml"], "--config: no such file"),
    ],
)
def test_cli_replay_bad_flags(flags: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(golden("paper_hover_px4")[0]), *flags]) == 2
    assert message in capsys.readouterr().err


def test_cli_replay_missing_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "x.yaml").write_bytes(golden("paper_hover_px4")[2].read_bytes())
    assert main(["replay", str(tmp_path / "x.tlog")]) == 2
    assert "x.tlog: no such file" in capsys.readouterr().err


def test_cli_replay_of_a_directory_names_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "LOG: " in err and "is a directory" in err and "Traceback" not in err
