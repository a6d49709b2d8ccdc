"""`fly --config` with a path planned in latitude / longitude (a QGroundControl .plan) against
sitl-mock with its home set to the plan's field (ArduPilot SITL's Canberra home), over loopback
UDP in lockstep: the app reads the vehicle's origin at connect time and flies the expected local
path; against a vehicle elsewhere it refuses before sending any setpoint or command."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from sitl_mock.config import MockConfig, SpawnSpec
from sitl_mock.runner import spawn

from pf_offboard.logs.tlog import read_tlog
from pf_offboard.path import Path as SplinePath

from .flights import RATE_HZ, run_fly

pytestmark = pytest.mark.integration

DATA = Path(__file__).resolve().parents[1] / "data" / "geo"
HOME = (-35.363261, 149.165230, 584.0)
EXPECTED_ENU_M = np.loadtxt(DATA / "expected_local_enu_m.txt")  # the paper path, 5 m E / 3 m N of home
HOVER_NED = (0.0, 5.0, -2.0)  # ENU (5, 0, 2): 1.5 m south of the path's first way-point (5, 1.5, 2)


def geo_config(tmp: Path, sample: str = "mission.plan", safety: dict | None = None) -> Path:
    shutil.copy(DATA / sample, tmp / sample)
    data: dict = {
        "path": {"file": sample, "altitude_reference": "relative_home", "closed": True},
        "speed_m_s": -1.5,
        "gains": {"transversal": {"bandwidth_hz": 6.0, "damping": 0.7}, "tangential": {"bandwidth_hz": 4.0, "damping": 0.8}},
        # the paper's setting on the mock's ideal vehicle (as configs/paper.yaml)
        "vehicle": {"accel_lag_xy_s": 0.0, "accel_lag_z_s": 0.0, "accel_delay_s": 0.0},
        "compensation": {"enabled": False},
        "flight": {"setpoint_rate_hz": RATE_HZ},
    }
    if safety is not None:
        data["safety"] = safety
    p = tmp / "geo.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


def mock(home: tuple[float, float, float] | None) -> MockConfig:
    extra = {} if home is None else {"home_lat_deg": home[0], "home_lon_deg": home[1], "home_alt_m": home[2]}
    return MockConfig(vehicle="fast", profile="px4", spawn=SpawnSpec("hover", HOVER_NED), udp_local_port=0, udp_remote=None,
                      lockstep=True, lockstep_dt_s=1.0 / RATE_HZ, **extra)  # fmt: skip


def distance_to_expected_path(points: np.ndarray) -> np.ndarray:
    """Distance (m) of each point to the spline through the expected local way-points (built here,
    independently of the app's conversion), by dense sampling (spacing < 4 mm)."""
    path = SplinePath.from_waypoints([tuple(p) for p in EXPECTED_ENU_M], closed=True)
    lam = np.linspace(0.0, path.lam_max, 6000)
    samples = np.array([path.eval(float(x)).sigma for x in lam])
    return np.array([np.min(np.linalg.norm(samples - p, axis=1)) for p in points])


def test_geodetic_plan_flies_the_expected_local_path(tmp_path) -> None:
    config = geo_config(tmp_path)
    with spawn(mock(HOME)) as m:
        outcome = run_fly(m.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "14")
    assert outcome.exit_code == 0, outcome.reason
    # the path the app flew: the plan converted at the vehicle's origin
    flown = yaml.safe_load((tmp_path / "log" / "flight.yaml").read_text())["path"]
    assert "file" not in flown and flown["frame"] == "enu"
    assert np.max(np.linalg.norm(np.array(flown["waypoints"]) - EXPECTED_ENU_M, axis=1)) < 0.01
    # the report beside the logs names the origin read from the vehicle
    report = json.loads((tmp_path / "log" / "summary.json").read_text())
    assert report["exit_code"] == 0 and report["summary"]["convergence_time_s"] == outcome.summary.convergence_time_s
    origin = report["path_file"]["origin"]
    assert (origin["lat_deg"], origin["lon_deg"], origin["alt_amsl_m"]) == pytest.approx(HOME, abs=1e-7)
    # the vehicle converged onto the expected local path and stayed on it
    active = [r for r in outcome.records if r.active]
    assert outcome.summary is not None and outcome.summary.convergence_time_s is not None
    t0 = active[0].time_s + outcome.summary.convergence_time_s
    settled = np.array([r.position_enu_m for r in active if r.time_s >= t0 + 1.0])
    assert len(settled) > 5 * RATE_HZ  # more than 5 s on the path
    d = distance_to_expected_path(settled)
    print(f"\ngeodetic plan: converged after {outcome.summary.convergence_time_s:.2f} s; distance to the expected local path: "
          f"max {d.max() * 1000:.1f} mm, RMS {np.sqrt(np.mean(d**2)) * 1000:.2f} mm over {len(d)} samples")  # fmt: skip
    assert d.max() < 0.02
    # the origin was asked for and read before any setpoint went out
    entries = read_tlog(tmp_path / "log" / "flight.tlog")
    kinds = [(e.direction, e.message.get_type()) for e in entries]
    first_origin = kinds.index(("in", "GPS_GLOBAL_ORIGIN"))
    first_setpoint = kinds.index(("out", "SET_POSITION_TARGET_LOCAL_NED"))
    assert first_origin < first_setpoint
    requests = [e.message for e in entries[:first_origin] if e.direction == "out" and e.message.get_type() == "COMMAND_LONG"]
    assert requests and all(r.command == 512 for r in requests)  # MAV_CMD_REQUEST_MESSAGE only


def test_plan_for_another_field_is_refused_before_any_setpoint(tmp_path, capsys) -> None:
    """The mock's default home is Zurich; the plan is in Canberra: exit 2, one line naming the
    file and the way-point, nothing but HEARTBEAT and REQUEST_MESSAGE sent."""
    from pf_offboard.cli import main

    config = geo_config(tmp_path, "mission.waypoints")
    with spawn(mock(None)) as m:
        code = main(["fly", "--connect", f"udpout:127.0.0.1:{m.ports.udp}", "--config", str(config), "--log-dir",
                     str(tmp_path / "log"), "--airborne", "--heartbeat-timeout", "5", "--quiet"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    assert "mission.waypoints: line " in err and "m from the vehicle's origin" in err
    out = {e.message.get_type() for e in read_tlog(tmp_path / "log" / "flight.tlog") if e.direction == "out"}
    assert out <= {"HEARTBEAT", "COMMAND_LONG"}
    sent = [e.message for e in read_tlog(tmp_path / "log" / "flight.tlog") if e.direction == "out" and e.message.get_type() == "COMMAND_LONG"]
    assert all(c.command == 512 for c in sent)


def test_geodetic_path_outside_the_fence_is_refused_before_any_setpoint(tmp_path, capsys) -> None:
    """The plan is at the vehicle's field but the safety: fence (a box 3 m east at most) leaves
    out its eastern way-points: once the origin is known the converted path is checked against the
    fence, and the flight is refused (exit 2, one line naming safety:) with nothing but the
    origin requests sent."""
    from pf_offboard.cli import main

    config = geo_config(tmp_path, safety={"fence_min_enu_m": [-20, -20, 0], "fence_max_enu_m": [3, 20, 10]})
    with spawn(mock(HOME)) as m:
        code = main(["fly", "--connect", f"udpout:127.0.0.1:{m.ports.udp}", "--config", str(config), "--log-dir",
                     str(tmp_path / "log"), "--airborne", "--heartbeat-timeout", "5", "--quiet"])  # fmt: skip
    err = capsys.readouterr().err
    print("\n" + err.strip())
    assert code == 2, err
    errors = [line for line in err.splitlines() if "error:" in line]  # (the converted path's note line comes first)
    assert len(errors) == 1 and errors[0].startswith("pf-offboard fly: error: safety: the path leaves the fence")
    out = [e.message for e in read_tlog(tmp_path / "log" / "flight.tlog") if e.direction == "out"]
    assert {m.get_type() for m in out} <= {"HEARTBEAT", "COMMAND_LONG"}
    assert all(m.command == 512 for m in out if m.get_type() == "COMMAND_LONG")  # REQUEST_MESSAGE only
