"""What happens when the app dies is configured, not hoped: `fly` reads (and with --offboard-loss
sets) the autopilot's loss-of-offboard behaviour before it asks for any mode; the app killed with
SIGKILL mid-flight leaves the vehicle in the configured behaviour (the mock models PX4's
COM_OF_LOSS_T / COM_OBL_RC_ACT and ArduPilot's GUID_TIMEOUT as the real autopilots behave)."""

from __future__ import annotations

import asyncio
import dataclasses
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sitl_mock.config import FaultConfig
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from app.flights import write_config
from pf_offboard.errors import InputError

from .attackers import fly_udpin, mock_config
from .common import own_clock

pytestmark = pytest.mark.integration
REPO = Path(__file__).resolve().parents[2]


def _param(mock, name: str) -> float:
    return mock.call(lambda m: m.autopilot.params[name])


def test_px4_offboard_loss_is_read_and_set_at_connect(tmp_path) -> None:
    """PX4's default COM_OBL_RC_ACT 0 (no RC: Return, climbing to RTL_RETURN_ALT) is reported as a
    warning; --offboard-loss hold sets COM_OBL_RC_ACT 5 (confirmed by PARAM_VALUE) before any mode request;
    a motors-off action (7, disarm) is refused before any mode request (exit 2)."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    with run_in_thread(mock_config(app_port)) as mock:
        outcome, printed = fly_udpin(app_port, config, tmp_path / "a", "--airborne", "--duration", "1")
        assert outcome.exit_code == 0, printed
        assert "warning: if the app stops, PX4 flies our last setpoint for COM_OF_LOSS_T 1 s, then COM_OBL_RC_ACT 0: AUTO.RTL" in printed
        outcome, printed = fly_udpin(app_port, config, tmp_path / "b", "--airborne", "--duration", "1", "--offboard-loss", "hold")
        assert outcome.exit_code == 0, printed
        assert _param(mock, "COM_OBL_RC_ACT") == 5.0
        assert "if the app stops, PX4 flies our last setpoint for COM_OF_LOSS_T 1 s, then COM_OBL_RC_ACT 5: AUTO.LOITER" in printed
        mock.call(lambda m: m.autopilot.params.__setitem__("COM_OBL_RC_ACT", 7.0))
        with pytest.raises(InputError) as err:  # exit 2 on the command line
            fly_udpin(app_port, config, tmp_path / "c", "--airborne", "--duration", "1")
        modes = mock.call(lambda m: [e.text for e in m.autopilot.log if e.text.startswith("mode ")])
    assert err.value.field == "--offboard-loss" and "COM_OBL_RC_ACT 7: disarm (motors off: the vehicle falls)" in err.value.reason
    assert len(modes) == 4  # two flights in and out of OFFBOARD; the refused third asked for nothing


def test_ardupilot_attitude_output_warns_that_the_vehicle_would_drift(tmp_path) -> None:
    """ArduPilot stays in GUIDED when our attitude targets stop and only levels after GUID_TIMEOUT:
    said at connect; --offboard-loss hold cannot be configured there: refused (exit 2) before any
    mode request."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    with run_in_thread(mock_config(app_port, profile="ardupilot")) as mock:
        flags = ("--airborne", "--duration", "1", "--output", "attitude", "--set-guid-options")
        outcome, printed = fly_udpin(app_port, config, tmp_path / "a", *flags)
        assert outcome.exit_code == 0, printed
        assert "warning: if the app stops, ArduPilot keeps GUIDED; after GUID_TIMEOUT 3 s it levels and holds altitude but does not brake" in printed
        with pytest.raises(InputError) as err:  # exit 2 on the command line
            fly_udpin(app_port, config, tmp_path / "b", *flags, "--offboard-loss", "hold")
        modes = mock.call(lambda m: [e.text for e in m.autopilot.log if e.text.startswith("mode ")])
    assert err.value.field == "--offboard-loss" and "cannot be configured on ArduPilot" in err.value.reason
    assert modes[-1] == "mode GUIDED -> BRAKE" and sum("-> GUIDED" in m for m in modes) == 1  # the refused second asked for nothing


def _kill_mid_flight(tmp_path: Path, profile: str, *flags: str) -> tuple[list[str], np.ndarray, np.ndarray, str]:
    """`fly` in a subprocess against a mock on its own clock (real time); SIGKILL 2 s (vehicle time)
    after OFFBOARD / GUIDED was entered; then 8 s more of vehicle time. Returns the mock's mode
    changes, the true position at the kill and at the end, and the final mode."""
    config = write_config(tmp_path)
    cfg = own_clock(profile, "hover:-3.0,0.0,-2.0", tmp_path / "truth.csv", speed=1.0)
    with run_in_thread(cfg) as mock:
        port = mock.ports.udp
        proc = subprocess.Popen(
            [sys.executable, "-m", "pf_offboard", "fly", "--connect", f"udpout:127.0.0.1:{port}", "--config", str(config),
             "--airborne", "--duration", "60", "--quiet", "--log-dir", str(tmp_path / "log"), *flags],
            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        try:
            loop = mock._loop
            entered = asyncio.run_coroutine_threadsafe(mock.mock.wait_for(
                lambda m: m.autopilot.mode.name in ("OFFBOARD", "GUIDED"), 60.0), loop).result(65.0)  # fmt: skip
            assert entered, proc.communicate(timeout=5)[0] if proc.poll() is not None else "no OFFBOARD / GUIDED"
            t_kill = mock.call(lambda m: m.time_s) + 2.0
            asyncio.run_coroutine_threadsafe(mock.mock.wait_for(lambda m: m.time_s >= t_kill, 30.0), loop).result(35.0)
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(10)
            # nobody is on the link any more: the vehicle's remaining 8 s pass at 8x real time (the
            # same physics steps; only the mock's wall-clock pacing changes): ~1 s instead of 8 s
            mock.call(lambda m: m.set_speed(8.0))
            at_kill = mock.call(lambda m: np.array(m.truth.position_ned_m))
            t_end = t_kill + 8.0
            asyncio.run_coroutine_threadsafe(mock.mock.wait_for(lambda m: m.time_s >= t_end, 30.0), loop).result(35.0)
            end = mock.call(lambda m: np.array(m.truth.position_ned_m))
            modes = mock.call(lambda m: [e.text for e in m.autopilot.log if e.text.startswith("mode ")])
            mode = mock.call(lambda m: m.autopilot.mode.name)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(5)
    return modes, at_kill, end, mode


def test_px4_app_killed_with_offboard_loss_hold_stays_put(tmp_path) -> None:
    """--offboard-loss hold, then SIGKILL mid-flight: PX4 (the mock, as PX4 SITL behaves) fails
    over to AUTO.LOITER after COM_OF_LOSS_T and holds there; without it, AUTO.RTL climbs."""
    modes, at_kill, end, mode = _kill_mid_flight(tmp_path, "px4", "--offboard-loss", "hold")
    moved = float(np.linalg.norm(end - at_kill))
    print(f"\nPX4, app killed, COM_OBL_RC_ACT 5: {modes[-2:]}, moved {moved:.2f} m in 8 s, climbed {float(at_kill[2] - end[2]):.2f} m")
    assert mode == "AUTO.LOITER" and modes[-1] == "mode OFFBOARD -> AUTO.LOITER", modes
    assert moved < 4.0 and float(at_kill[2] - end[2]) < 1.0  # braked from path speed; a Return would climb metres


def test_ardupilot_app_killed_in_attitude_output_drifts(tmp_path) -> None:
    """The finding behind the connect-time warning: ArduPilot in GUIDED with attitude targets, the
    app killed mid-flight: the mode stays GUIDED and the vehicle levels after GUID_TIMEOUT, without
    braking (measured here: the drift over 8 s)."""
    modes, at_kill, end, mode = _kill_mid_flight(tmp_path, "ardupilot", "--output", "attitude", "--set-guid-options")
    drift = float(np.linalg.norm((end - at_kill)[:2]))
    print(f"\nArduPilot attitude, app killed: stays {mode}, drifted {drift:.2f} m horizontally in 8 s")
    assert mode == "GUIDED" and modes[-1].endswith("-> GUIDED")
    assert drift > 1.0  # nothing holds the position: what the warning says
