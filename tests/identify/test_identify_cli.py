"""``pf-offboard identify`` on the command line: report, JSON, --write-config, bad input (exit 2)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml

from pf_offboard.cli import main
from pf_offboard.config import load_config
from pf_offboard.logs.tlog import TlogWriter, read_tlog

from .synthetic import write_tlog

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data" / "identify"


@pytest.fixture(scope="module")
def good_log(tmp_path_factory) -> Path:
    return write_tlog(tmp_path_factory.mktemp("cli") / "flight.tlog", duration_s=12.0)


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err  # one clear line
    return err[0]


def test_report_and_vehicle_section(good_log, capsys) -> None:
    assert main(["identify", str(good_log)]) == 0
    out = capsys.readouterr().out
    assert "acceleration setpoints" in out and "R^2" in out and "NRMSE" in out
    section = yaml.safe_load(out[out.index("vehicle:"):])["vehicle"]
    # no body-rate setpoints in this log: the rate loop is not written (not known)
    assert set(section) == {"accel_lag_xy_s", "accel_lag_z_s", "accel_delay_s", "accel_delay_z_s", "accel_gain_xy",
                            "accel_gain_z", "drag_xy_1_s", "drag_z_1_s"}  # fmt: skip
    assert section["drag_xy_1_s"] == pytest.approx(0.6, rel=0.05)


def test_json(good_log, capsys) -> None:
    assert main(["identify", str(good_log), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["xy"]["gain"] == pytest.approx(0.9, rel=0.03)
    assert data["vehicle"]["accel_gain_z"] == pytest.approx(1.1, rel=0.03)
    assert data["logs"][0]["setpoints"] == "acceleration"


def test_write_config_merges_into_a_copy_of_the_config(good_log, tmp_path, capsys) -> None:
    base = tmp_path / "paper.yaml"
    text = (REPO / "configs" / "paper.yaml").read_text() + "vehicle:\n  accel_lag_xy_s: 1.5  # old\n  rate_time_constant_s: 0.07\n\n"
    base.write_text(text)
    out = tmp_path / "identified.yaml"
    assert main(["identify", str(good_log), "--config", str(base), "--write-config", str(out)]) == 0
    cfg = load_config(out)  # a valid config, with the identified vehicle
    assert cfg.vehicle.drag_xy_1_s == pytest.approx(0.6, rel=0.05)
    assert cfg.vehicle.accel_lag_xy_s < 1.0  # the old section was replaced, not appended to
    assert cfg.vehicle.rate_time_constant_s == 0.07  # not identified by this log: kept
    assert cfg.path == load_config(REPO / "configs" / "paper.yaml").path  # everything else kept
    assert base.read_text() == text  # the base is not touched
    assert [line for line in out.read_text().splitlines() if line.startswith("vehicle:")] != [] and sum(line.startswith("vehicle:") for line in out.read_text().splitlines()) == 1
    # and into an existing file without --config: that file is the base
    assert main(["identify", str(good_log), "--write-config", str(out)]) == 0
    assert load_config(out).vehicle == cfg.vehicle


def test_several_logs_are_fitted_together(good_log, tmp_path, capsys) -> None:
    other = write_tlog(tmp_path / "other.tlog", duration_s=12.0, seed=5)
    assert main(["identify", str(good_log), str(other), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["logs"]) == 2 and data["duration_s"] > 20.0


# ---------------------------------------------------------------------------------- bad input
def test_missing_file(tmp_path, capsys) -> None:
    missing = tmp_path / "nope.tlog"
    assert main(["identify", str(missing)]) == 2
    line = _error(capsys)
    assert str(missing) in line and "no such file" in line


def test_not_a_tlog(tmp_path, capsys) -> None:
    bad = tmp_path / "notes.tlog"
    bad.write_text("this is not a telemetry log\n" * 10)
    assert main(["identify", str(bad)]) == 2
    line = _error(capsys)
    assert str(bad) in line and "not a .tlog" in line


def test_not_gzip(tmp_path, capsys) -> None:
    bad = tmp_path / "flight.tlog.gz"
    bad.write_bytes(b"plain bytes")
    assert main(["identify", str(bad)]) == 2
    assert "gzip" in _error(capsys)


def test_directory(tmp_path, capsys) -> None:
    assert main(["identify", str(tmp_path)]) == 2
    assert "directory" in _error(capsys)


def test_no_setpoints(tmp_path, capsys) -> None:
    path = write_tlog(tmp_path / "telemetry_only.tlog", duration_s=8.0, setpoints=False)
    assert main(["identify", str(path)]) == 2
    line = _error(capsys)
    assert str(path) in line and "no acceleration or attitude setpoints" in line


def test_never_flying(tmp_path, capsys) -> None:
    # setpoints streamed, but the autopilot never switched to OFFBOARD
    path = write_tlog(tmp_path / "never.tlog", duration_s=8.0, offboard_from_s=100.0)
    assert main(["identify", str(path)]) == 2
    line = _error(capsys)
    assert str(path) in line and "OFFBOARD" in line


def test_too_short(tmp_path, capsys) -> None:
    path = write_tlog(tmp_path / "short.tlog", duration_s=3.0)
    assert main(["identify", str(path)]) == 2
    line = _error(capsys)
    assert str(path) in line and "too short" not in line and "at least 5 s" in line


def test_no_excitation(tmp_path, capsys) -> None:
    path = write_tlog(tmp_path / "still.tlog", duration_s=10.0, amplitude_m_s2=0.0)
    assert main(["identify", str(path)]) == 2
    line = _error(capsys)
    assert str(path) in line and "no excitation in xy" in line


def test_attitude_log_without_hover_thrust(tmp_path, capsys) -> None:
    # the real attitude flight with its PARAM_VALUE (the hover thrust) removed
    src = DATA / "px4-sih-attitude-1.5hz.tlog.gz"
    path = tmp_path / "attitude.tlog"
    with TlogWriter.open(path) as w:
        for e in read_tlog(src):
            if e.message.get_type() != "PARAM_VALUE":
                w.write(e.frame, e.time_unix_s)
    assert main(["identify", str(path)]) == 2
    assert "--hover-thrust" in _error(capsys)
    assert main(["identify", str(path), "--hover-thrust", "0.5", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["logs"][0]["hover_thrust_source"] == "--hover-thrust"


def test_bad_flags(tmp_path, good_log, capsys) -> None:
    assert main(["identify"]) == 2
    assert "at least one" in _error(capsys)
    assert main(["identify", str(good_log), "--connect", "udpout:127.0.0.1:9", "--config", "configs/paper.yaml"]) == 2
    assert "not both" in _error(capsys)
    assert main(["identify", "--connect", "udpout:127.0.0.1:9"]) == 2
    assert "--config" in _error(capsys)
    assert main(["identify", str(good_log), "--hover-thrust", "1.5"]) == 2
    assert "--hover-thrust" in _error(capsys)
    assert main(["identify", "--connect", "udpout:127.0.0.1:9", "--config", "configs/paper.yaml", "--box", "50"]) == 2
    assert "--box" in _error(capsys)
    assert main(["identify", "--connect", "udpout:127.0.0.1:9", "--config", "configs/paper.yaml", "--velocity-correction", "0.3"]) == 2
    assert "not the hover excitation" in _error(capsys)
    for bad in ("0", "nan", "100"):
        assert main(["identify", str(good_log), "--velocity-correction", bad]) == 2
        assert "--velocity-correction" in _error(capsys)


def test_velocity_correction_is_reported_and_harmless_on_a_consistent_estimate(good_log, capsys) -> None:
    """The synthetic log's position integrates its velocity (an estimate without the drift the
    correction removes): the fit is the same, and the JSON says which velocity was fitted."""
    assert main(["identify", str(good_log), "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main(["identify", str(good_log), "--json", "--velocity-correction", "0.3"]) == 0
    corrected = json.loads(capsys.readouterr().out)
    assert plain["logs"][0]["velocity_correction_s"] is None and corrected["logs"][0]["velocity_correction_s"] == 0.3
    for group in ("xy", "z"):
        assert corrected[group]["gain"] == pytest.approx(plain[group]["gain"], rel=0.01)
        assert corrected[group]["drag_1_s"] == pytest.approx(plain[group]["drag_1_s"], rel=0.02)
    assert main(["identify", str(good_log), "--velocity-correction", "0.3"]) == 0
    assert "velocity made position-consistent (0.3 s)" in capsys.readouterr().out


def test_the_report_says_what_the_vertical_input_was(good_log, tmp_path, capsys) -> None:
    # the good log has no attitude telemetry: the vertical setpoint, with the caveat
    assert main(["identify", str(good_log)]) == 0
    assert "z input: the vertical setpoint a_sp,z (no attitude telemetry" in capsys.readouterr().out
    assert main(["identify", "--json", str(good_log)]) == 0
    assert json.loads(capsys.readouterr().out)["z"]["measured_tilt_share"] == 0.0
    tilted = write_tlog(tmp_path / "tilted.tlog", duration_s=12.0, tilt_coupled=True)
    assert main(["identify", str(tilted)]) == 0
    assert "along the measured tilt (u_z = lag(|a_sp + g|) * cos(tilt) - g) on 100 % of samples" in capsys.readouterr().out
    assert main(["identify", "--json", str(tilted)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["z"]["measured_tilt_share"] == 1.0 and data["xy"]["measured_tilt_share"] == 0.0


def test_unwritable_config_target(good_log, tmp_path, capsys) -> None:
    target = tmp_path / "ro"
    target.mkdir()
    assert main(["identify", str(good_log), "--write-config", str(target)]) == 2
    assert str(target) in _error(capsys)


def test_gzipped_log_reads_the_same(good_log, tmp_path, capsys) -> None:
    import gzip

    gz = tmp_path / "flight.tlog.gz"
    gz.write_bytes(gzip.compress(good_log.read_bytes()))
    assert main(["identify", str(gz), "--json"]) == 0
    a = json.loads(capsys.readouterr().out)["vehicle"]
    assert main(["identify", str(good_log), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["vehicle"] == a
    shutil.rmtree(tmp_path, ignore_errors=True)
