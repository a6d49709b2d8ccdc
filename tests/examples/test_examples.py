"""Every script in examples/ runs against sitl-mock over real loopback sockets (the same commands a
user types, with the mock's endpoint) and prints what it promises."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from sitl_mock.config import FaultConfig, MockConfig, SpawnSpec
from sitl_mock.runner import run_in_thread

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
PLAN_HOME = (-35.363261, 149.165230, 584.0)  # examples/mission.plan is 5 m E / 3 m N of this home


def _mock(vehicle: str = "fast", spawn: str = "ground:-1.5,0", rate_hz: float = 50.0, **extra: object) -> MockConfig:
    """Lockstep: one step of the vehicle per setpoint (as fast as the host allows, deterministic)."""
    return MockConfig(vehicle=vehicle, profile="px4", spawn=SpawnSpec.parse(spawn), udp_local_port=0, udp_remote=None,
                      lockstep=True, lockstep_dt_s=1.0 / rate_hz, **extra)  # fmt: skip


def _run(script: str, *args: str, timeout_s: float = 150.0) -> str:
    done = subprocess.run([sys.executable, str(EXAMPLES / script), *args], capture_output=True, text=True, timeout=timeout_s)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    return done.stdout


def test_core_in_your_own_loop_is_short_and_converges() -> None:
    code = [line for line in (EXAMPLES / "core_in_your_loop.py").read_text().splitlines() if line.strip()]
    assert len(code) <= 15
    out = _run("core_in_your_loop.py")
    cross_track_m = float(out.split("after 30 s: ")[1].split(" m")[0])
    assert cross_track_m < 0.01, out


@pytest.mark.integration
def test_fly_config() -> None:
    with run_in_thread(_mock(vehicle="px4-sih")) as mock:
        out = _run("fly_config.py", f"udpout://127.0.0.1:{mock.ports.udp}", "px4-sih")
        assert mock.call(lambda m: m.autopilot.mode.name) == "AUTO.LOITER"
    assert "1 laps done; handed back in AUTO.LOITER" in out and "cross-track RMS" in out


@pytest.mark.integration
def test_fly_qgc_plan() -> None:
    home = {"home_lat_deg": PLAN_HOME[0], "home_lon_deg": PLAN_HOME[1], "home_alt_m": PLAN_HOME[2]}
    with run_in_thread(_mock(spawn="ground:0,5", **home)) as mock:
        out = _run("fly_qgc_plan.py", f"udpout://127.0.0.1:{mock.ports.udp}")
        assert mock.call(lambda m: m.autopilot.mode.name) == "AUTO.LAND"
    assert "end of the open path reached; handed back in AUTO.LOITER" in out


@pytest.mark.integration
def test_two_paths() -> None:
    with run_in_thread(_mock()) as mock:
        out = _run("two_paths.py", f"udpout://127.0.0.1:{mock.ports.udp}")
    assert "loop: 1 laps done" in out and "line: end of the open path reached" in out


@pytest.mark.integration
def test_react_to_takeover() -> None:
    with run_in_thread(_mock(vehicle="px4-sih", faults=FaultConfig(takeover_at_s=20.0, takeover_mode="POSCTL"))) as mock:
        out = _run("react_to_takeover.py", f"udpout://127.0.0.1:{mock.ports.udp}", "px4-sih")
        assert mock.call(lambda m: m.autopilot.mode.name) == "POSCTL"
    assert "the pilot took over after" in out and "POSCTL" in out
