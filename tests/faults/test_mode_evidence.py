"""Mode changes confirmed only by evidence newer than the request, the autopilot's failsafe wins,
one controller at a time: against sitl-mock over real loopback UDP, end state from the mock's side."""

from __future__ import annotations

import asyncio
import dataclasses

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.config import FaultConfig
from sitl_mock.runner import run_in_thread

from app.flights import write_config

from .attackers import fly_udpin, mock_config
from .common import own_clock, entries, is_mode_request
from sitl_mock.testing import free_udp_port

pytestmark = pytest.mark.integration


def _mock_time_passes(mock, seconds: float) -> None:
    """Wait (on the mock's own clock) until ``seconds`` of simulated time have passed."""
    t_end = mock.call(lambda m: m.time_s) + seconds
    fut = asyncio.run_coroutine_threadsafe(mock.mock.wait_for(lambda m: m.time_s >= t_end, 60.0), mock._loop)
    assert fut.result(65.0)


def _modes(mock) -> list[str]:
    return mock.call(lambda m: [e.text for e in m.autopilot.log if e.text.startswith("mode ")])


def test_stop_while_offboard_is_in_flight_is_held_by_newer_evidence(tmp_path) -> None:
    """PX4 keeps HEARTBEAT at 1 Hz (the mock refuses a faster one, as PX4 does). SIGTERM arrives
    the moment the OFFBOARD request has gone out: the last HEARTBEAT still shows AUTO.LOITER. Before,
    that old HEARTBEAT "confirmed" the hold, the app exited, OFFBOARD then landed with no setpoints
    and PX4's offboard-loss RTL climbed to 29 m. Now the hold is requested and only a HEARTBEAT
    received after it (and after the OFFBOARD request has settled) confirms it; the vehicle ends in
    AUTO.LOITER and stays there (no RTL) after the app has gone."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    cfg = own_clock("px4", "hover:-3.0,0.0,-2.0", tmp_path / "truth.csv", speed=1.0, heartbeat_rate_fixed=True)
    cfg = dataclasses.replace(cfg, udp_remote=("127.0.0.1", app_port))
    stopped: list[float] = []

    def on_start(flight) -> None:
        commander = flight.commander
        original = commander.set_mode_nowait

        def set_mode_nowait(mode) -> None:
            original(mode)
            if mode is flight.profile.offboard and not stopped:
                stopped.append(flight.clock())
                flight.request_stop("stop requested (SIGTERM)")

        commander.set_mode_nowait = set_mode_nowait

    with run_in_thread(cfg) as mock:
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "5", on_start=on_start)
        mock.call(lambda m: m.set_speed(8.0))  # the app has exited: the vehicle's next 3 s pass in 0.4 s
        _mock_time_passes(mock, 3.0)  # > COM_OF_LOSS_T: an OFFBOARD left behind would have failed over to RTL by now
        modes = _modes(mock)
        mode, alt = mock.call(lambda m: (m.autopilot.mode.name, -float(m.truth.position_ned_m[2])))
    print(f"\nstop with OFFBOARD in flight: exit {outcome.exit_code}, {outcome.reason}; mock modes {modes}, now {mode} at {alt:.2f} m")
    assert stopped, "the OFFBOARD request was never sent"
    assert outcome.exit_code == 130, printed
    assert "AUTO.LOITER requested, confirmed" in outcome.reason
    assert mode == "AUTO.LOITER" and not any("RTL" in m for m in modes), modes
    assert alt < 3.0  # it did not climb
    sent = [m for m in (e.message for e in entries(tmp_path / "log") if e.direction == "out") if is_mode_request(m)]
    assert [int(m.param2) for m in sent][:1] == [6] and 4 in [int(m.param2) for m in sent]  # OFFBOARD, then the hold, actually sent


@pytest.mark.parametrize("profile", ["px4", "ardupilot"])
def test_the_autopilot_failsafe_wins(tmp_path, profile: str) -> None:
    """A battery-critical failsafe at 3 s: PX4 AUTO.LAND / ArduPilot LAND with system status
    CRITICAL. The app stops commanding at once (no setpoint, no mode request after the HEARTBEAT
    showing it), reports it, exit 7; the vehicle keeps landing (before: a hold was requested 10 ms
    later and the vehicle hovered)."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    flags = ("--output", "attitude", "--set-guid-options") if profile == "ardupilot" else ()
    with run_in_thread(mock_config(app_port, profile=profile, faults=FaultConfig(failsafe_at_s=3.0))) as mock:
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "8", *flags)
        modes = _modes(mock)
        mode = mock.call(lambda m: m.autopilot.mode.name)
    land = "AUTO.LAND" if profile == "px4" else "LAND"
    assert outcome.exit_code == 7, printed
    assert f"the autopilot's failsafe took over during following" in outcome.reason and f"-> {land}" in outcome.reason
    assert "stopped commanding" in outcome.reason
    assert mode == land and modes[-1].endswith(f"-> {land}"), modes
    log = entries(tmp_path / "log")
    seen = next(i for i, e in enumerate(log) if e.direction == "in" and e.message.get_type() == "HEARTBEAT"
                and e.message.get_srcComponent() == 1 and e.message.system_status == mavlink2.MAV_STATE_CRITICAL)  # fmt: skip
    after = [e.message for e in log[seen + 1 :] if e.direction == "out"]
    assert not [m for m in after if m.get_type() in ("SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET") or is_mode_request(m)]


def test_an_offboard_we_did_not_start_is_refused(tmp_path) -> None:
    """The vehicle is already in OFFBOARD (another controller — a second pf-offboard — is flying
    it): `fly --airborne` refuses with the reason, exit 4, and sends it no setpoint and no mode
    request (before: "already in OFFBOARD", engaged at once, two controllers fought for 13.5 s)."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    with run_in_thread(mock_config(app_port)) as mock:
        mock.call(lambda m: m.autopilot._set_mode(m.autopilot.profile.mode("OFFBOARD"), user=True))
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "3")
        mode = mock.call(lambda m: m.autopilot.mode.name)
    assert outcome.exit_code == 4, printed
    assert "already in OFFBOARD, which we did not start: another controller may be flying it; nothing sent" in outcome.reason
    sent = [e.message for e in entries(tmp_path / "log") if e.direction == "out"]
    assert not [m for m in sent if m.get_type() in ("SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET") or is_mode_request(m)]
    assert mode == "OFFBOARD"  # untouched: the other controller's
