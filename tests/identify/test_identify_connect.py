"""``pf-offboard identify --connect``: a bounded excitation flown against sitl-mock over real
loopback UDP (lockstep), through fly's Bridge / Pipeline / encoders, then fitted."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from sitl_mock.config import MockConfig, SpawnSpec
from sitl_mock.dynamics import preset
from sitl_mock.dynamics.identify import accel_step_rise_time_s
from sitl_mock.runner import run_in_thread

from pf_offboard.cli import main
from pf_offboard.logs.steplog import read_steplog

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[2]
RATE_HZ = 100.0
HOVER_NED = (1.0, 2.0, -4.0)


def _config(tmp: Path) -> Path:
    data = yaml.safe_load((REPO / "configs" / "paper.yaml").read_text())
    data["flight"] = {"output_mode": "acceleration", "setpoint_rate_hz": RATE_HZ}
    path = tmp / "flight.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _mock(vehicle: str = "px4-default") -> MockConfig:
    return MockConfig(profile="px4", vehicle=vehicle, spawn=SpawnSpec.parse("hover:" + ",".join(map(str, HOVER_NED))),
                      udp_local_port=0, udp_remote=None, lockstep=True, lockstep_dt_s=1.0 / RATE_HZ)  # fmt: skip


def _run(port: int, config: Path, log_dir: Path, *flags: str) -> int:
    return main(["identify", "--connect", f"udpout:127.0.0.1:{port}", "--config", str(config), "--log-dir", str(log_dir),
                 "--heartbeat-timeout", "5", "--quiet", *flags])  # fmt: skip


def test_excitation_flight_is_bounded_and_identifies_the_mock(tmp_path, capsys) -> None:
    with run_in_thread(_mock()) as mock:
        code = _run(mock.ports.udp, _config(tmp_path), tmp_path / "log", "--duration", "14", "--json")  # default amplitude
        mode = mock.call(lambda m: m.autopilot.mode.name)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert mode == "AUTO.LOITER"  # handed back in the hold mode
    data = json.loads(captured.out)
    # bounded: never more than the 1 m box from the start (ENU)
    recs = [r for r in read_steplog(tmp_path / "log" / "identify.csv") if r.active]
    pos = np.array([r.position_enu_m for r in recs])
    start = np.array([HOVER_NED[1], HOVER_NED[0], -HOVER_NED[2]])
    assert np.max(np.abs(pos - start)) < 1.5  # the default --box
    assert recs[-1].time_s - recs[0].time_s > 14.0  # settle + excitation flown in full
    params = preset("px4-default")
    rise_xy = accel_step_rise_time_s(params, (1.0, 0.0, 0.0))
    print(f"\n{json.dumps({k: data[k] for k in ('xy', 'z')})}\ntruth: rise xy {rise_xy:.3f} s, drag {params.drag_1_s}")
    assert data["xy"]["rise_63_s"] == pytest.approx(rise_xy, rel=0.1)
    assert data["xy"]["drag_1_s"] == pytest.approx(params.drag_1_s, rel=0.1)
    assert data["xy"]["gain"] == pytest.approx(1.0, rel=0.1)
    assert data["z"]["gain"] == pytest.approx(1.0, rel=0.1)
    assert data["z"]["drag_1_s"] == pytest.approx(params.drag_1_s, rel=0.1)


def test_leaving_the_box_aborts_to_hold(tmp_path, capsys) -> None:
    with run_in_thread(_mock()) as mock:
        code = _run(mock.ports.udp, _config(tmp_path), tmp_path / "log", "--duration", "14", "--box", "0.2")
        mode = mock.call(lambda m: m.autopilot.mode.name)
    err = capsys.readouterr().err
    assert "excitation aborted" in err and "box" in err
    assert mode == "AUTO.LOITER"
    recs = [r for r in read_steplog(tmp_path / "log" / "identify.csv") if r.active]
    assert recs[-1].time_s - recs[0].time_s < 10.0  # stopped early, not after the full excitation
    assert code in (0, 2)  # fitted what was flown, or said why it could not (too short)


def test_excitation_stays_in_its_box_on_an_ekf_like_estimate(tmp_path, capsys) -> None:
    """The calibrated ``px4-sih`` preset (EKF2-like position and velocity errors, a velocity that
    disagrees with its position's derivative) with the shipped px4-sih.yaml: the excitation is
    flown in full inside the 1 m box, as on the real PX4 SIH once the estimate's velocity is made
    consistent with its position (flight.velocity_correction_s, as fly does)."""
    config = tmp_path / "px4-sih.yaml"
    config.write_text((REPO / "configs" / "px4-sih.yaml").read_text())
    with run_in_thread(_mock("px4-sih")) as mock:
        code = _run(mock.ports.udp, config, tmp_path / "log", "--duration", "14", "--json")
        mode = mock.call(lambda m: m.autopilot.mode.name)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "aborted" not in captured.err and mode == "AUTO.LOITER"
    recs = [r for r in read_steplog(tmp_path / "log" / "identify.csv") if r.active]
    pos = np.array([r.position_enu_m for r in recs])
    start = np.array([HOVER_NED[1], HOVER_NED[0], -HOVER_NED[2]])
    print(f"\nlargest offset from the start {np.max(np.abs(pos - start)):.2f} m")
    # measured 0.28 m; damping on the reported velocity alone (before): 0.82 m here, and out of the
    # box after 5.8 s on the real PX4 SIH, whose velocity error is larger than the preset's
    assert np.max(np.abs(pos - start)) < 0.5
    assert recs[-1].time_s - recs[0].time_s > 14.0


def test_excitation_status_line_shows_time_and_offset_not_nan() -> None:
    """The excitation has no path: the path-following status line showed `η1 nan m`."""
    import math
    import types

    from pf_offboard.identify.excite import ExcitationFollower, ExcitationSpec, excitation_status

    now = [10.0]
    follower = ExcitationFollower(ExcitationSpec(), clock=lambda: now[0])
    follower.update((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), now[0])
    now[0] = 14.0
    record = types.SimpleNamespace(position_enu_m=(1.25, 1.5, 3.0))
    line = "[following] OFFBOARD armed  η1     nan m  η2  +nan m/s  ξ1   +nan m  φ1   +nan m  e  0.5 m  laps 0.00  rate   200 Hz"
    text = excitation_status(line, follower, record, 200.0)
    assert "nan" not in text and text.startswith("[following] OFFBOARD armed  excitation")
    assert "E +0.25 N -0.50 U +0.00 m" in text
    t = follower.excitation_time_s()
    assert math.isfinite(t) and f"{t:5.1f} s" in text
