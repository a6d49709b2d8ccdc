"""identify reads PX4 ULogs as PX4 users have them: a real PX4 SIH (airframe 10040) flight flown
by `pf-offboard fly --config px4-sih --output acceleration`, trimmed to what identify reads
(scripts/trim_ulog.py; 29 s in OFFBOARD). SIH's drag is SIH_KDV / mass = 1.0 1/s."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pf_offboard.cli import main
from pf_offboard.config import load_config
from pf_offboard.identify.logdata import load_log

ULOG = Path(__file__).resolve().parents[1] / "data" / "ulog" / "px4_sih_offboard.ulg"
SIH_DRAG_1_S = 1.0


def test_ulog_offboard_flight_is_found_with_px4s_own_setpoints() -> None:
    data = load_log(ULOG)
    assert data.kind == "acceleration" and data.duration_s > 25.0
    truth = load_log(ULOG, truth=True)
    assert truth.duration_s > 25.0


def test_identify_a_ulog_writes_a_vehicle_section_with_sihs_drag(tmp_path, capsys) -> None:
    out = tmp_path / "mine.yaml"
    out.write_text(yaml.safe_dump({"path": {"waypoints": [[0, 0, 2], [4, 0, 2]]}, "speed_m_s": 1.0}))
    assert main(["identify", str(ULOG), "--write-config", str(out)]) == 0, capsys.readouterr().err
    vehicle = load_config(out).vehicle
    print(f"\n{vehicle}")
    assert vehicle.drag_xy_1_s == pytest.approx(SIH_DRAG_1_S, rel=0.15)
    assert vehicle.accel_gain_xy == pytest.approx(1.0, rel=0.15)
    assert 0.05 <= vehicle.accel_lag_xy_s <= 0.3


def test_truth_needs_a_ulog_and_bad_logs_are_named(tmp_path, capsys) -> None:
    bad = tmp_path / "x.ulg"
    bad.write_bytes(b"not a ulog at all")
    assert main(["identify", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: not a PX4 ULog" in err and err.count("\n") == 1
    assert main(["identify", str(tmp_path / "missing.ulg")]) == 2
    assert "missing.ulg: no such file" in capsys.readouterr().err
    tlog = tmp_path / "a.tlog"
    tlog.write_bytes(b"")
    assert main(["identify", str(tlog), "--truth"]) == 2
    assert "--truth: only a PX4 ULog" in capsys.readouterr().err


def test_identify_takes_a_shipped_config_name_as_the_base(tmp_path, capsys) -> None:
    out = tmp_path / "mine.yaml"
    assert main(["identify", str(ULOG), "--config", "px4-sih", "--write-config", str(out)]) == 0, capsys.readouterr().err
    written, shipped = load_config(out), load_config(Path(__file__).resolve().parents[2] / "configs" / "px4-sih.yaml")
    assert written.path == shipped.path and written.vehicle != shipped.vehicle
