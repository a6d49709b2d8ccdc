"""Round trip: what `fly` writes over real loopback MAVLink against sitl-mock, `replay` and
`plot` read — and replay reproduces the flown setpoints. The same flights check what the log
records of the app's telemetry requests, and that pymavlink's mavlogdump.py reads the log."""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from pf_offboard.cli import main
from pf_offboard.logs.steplog import read_steplog
from pf_offboard.logs.tlog import read_tlog

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "configs" / "paper.yaml"
SETPOINT = {"acceleration": "SET_POSITION_TARGET_LOCAL_NED", "attitude": "SET_ATTITUDE_TARGET", "rates": "SET_ATTITUDE_TARGET"}


@pytest.mark.integration
@pytest.mark.parametrize(
    ("autopilot", "output", "state_source"),
    [("px4", "acceleration", "local_position"), ("px4", "attitude", "odometry")],
)
def test_fly_logs_replay_and_plot(
    tmp_path: Path, autopilot: str, output: str, state_source: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from sitl_mock.config import MockConfig, SpawnSpec
    from sitl_mock.runner import spawn

    from pf_offboard.app.fly import add_arguments, fly

    mock_config = MockConfig(vehicle="fast", 
        profile=autopilot, spawn=SpawnSpec("hover", (-1.5, 0.0, -2.0)),  # NED: PF1 start (0, -1.5, 2) ENU
        udp_local_port=0, udp_remote=None, tcp_port=None, lockstep=True, lockstep_dt_s=0.01,
    )  # fmt: skip
    log_dir = tmp_path / "flight"
    with spawn(mock_config) as mock:
        parser = argparse.ArgumentParser()
        add_arguments(parser)
        args = parser.parse_args([
            "--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config", str(PAPER), "--airborne",
            "--duration", "1.5", "--output", output, "--autopilot", autopilot, "--log-dir", str(log_dir),
            "--heartbeat-timeout", "10", "--quiet", "--state-source", state_source,
        ])  # fmt: skip
        outcome = fly(args)
    assert outcome.exit_code == 0, outcome.reason
    tlog, csv = log_dir / "flight.tlog", log_dir / "flight.csv"
    entries = read_tlog(tlog)
    records = read_steplog(csv)
    assert len(records) > 50
    assert {"in", "out"} == {e.direction for e in entries}
    assert any(r.active for r in records)
    state_msg = "ODOMETRY" if state_source == "odometry" else "LOCAL_POSITION_NED"
    assert sum(e.message.get_type() == state_msg for e in entries) >= len(records)
    # SET_MESSAGE_INTERVAL (COMMAND_LONG 511) to the target: the state stream and ATTITUDE_QUATERNION
    # at the setpoint rate (paper.yaml: 100 Hz), HEARTBEAT at 10 Hz, POSITION_TARGET_LOCAL_NED (the
    # autopilot's echoed target, evidence of another controller) at 25 Hz; the autopilot accepts each
    state_id = 331 if state_source == "odometry" else 32
    requests = {int(m.param1): m.param2 for m in (e.message for e in entries if e.direction == "out")
                if m.get_type() == "COMMAND_LONG" and m.command == 511 and (m.target_system, m.target_component) == (1, 1)}  # fmt: skip
    assert requests == {state_id: 1e4, 31: 1e4, 0: 1e5, 85: 4e4}
    acks = [e.message.result for e in entries if e.direction == "in" and e.message.get_type() == "COMMAND_ACK" and e.message.command == 511]
    assert acks and set(acks) == {0}  # MAV_RESULT_ACCEPTED
    # pymavlink's own mavlogdump.py reads the real flight log: every frame, in and out, same types
    dump = subprocess.run([sys.executable, "-m", "pymavlink.tools.mavlogdump", str(tlog)], capture_output=True, text=True, timeout=60)
    assert dump.returncode == 0 and not dump.stderr.strip(), dump.stderr
    dumped = Counter(line.split(": ", 1)[1].split(" ", 1)[0] for line in dump.stdout.splitlines())
    assert dumped == Counter(e.message.get_type() for e in entries)
    assert dumped[state_msg] >= len(records) and dumped[SETPOINT[output]] >= len(records) - 1
    # `sim` writes the same files, with the same step-log columns
    from pf_offboard.sim import SimSpec, simulate

    sim = simulate(PAPER, SimSpec(vehicle="fast", duration_s=0.1, output_mode=output, autopilot=autopilot), tmp_path / "sim")
    assert sorted(p.name for p in sim.paths.tlog.parent.iterdir()) == sorted(p.name for p in log_dir.iterdir())
    assert sim.paths.steps_csv.read_text().splitlines()[0] == csv.read_text().splitlines()[0]
    capsys.readouterr()
    assert main(["replay", str(tlog), "--config", str(PAPER)]) == 0
    out = capsys.readouterr().out
    assert "MATCH" in out and f"{output} setpoints" in out
    assert main(["plot", str(tlog), "--out", str(tmp_path / "fig")]) == 0
    assert {p.name for p in (tmp_path / "fig").iterdir()} == {"path3d.png", "map.png", "flight_tangential.png", "flight_transversal.png"}
