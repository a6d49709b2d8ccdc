"""HEARTBEATs stop while telemetry goes on: the mode is unknown, so the app stops commanding at
once (only the safe setpoint) and requests the hold mode, which it cannot confirm: exit 3 after
safety.safe_mode_timeout_s. Before issue 9 it kept commanding (513 setpoints) with the mode unknown."""

from __future__ import annotations

import pytest
from sitl_mock.runner import run_in_thread

from app.flights import run_fly

from .common import SETPOINT_TYPES, hover, is_mode_request, is_safe_setpoint, lockstep, outgoing, write_config

pytestmark = pytest.mark.integration


def test_lost_heartbeat_stops_commanding_and_requests_hold(tmp_path) -> None:
    config = write_config(tmp_path, safety={"heartbeat_timeout_s": 1.0, "safe_mode_timeout_s": 2.0})
    with run_in_thread(lockstep("px4", hover(), heartbeat_mute_s=(4.0, 1000.0))) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "60")
        mode, armed = mock.call(lambda m: (m.autopilot.mode.name, m.autopilot.armed))
    out = outgoing(tmp_path / "log")
    first_request = next(i for i, m in enumerate(out) if is_mode_request(m) and m.param2 == 4)
    after = [m for m in out[first_request:] if m.get_type() in SETPOINT_TYPES]
    print(f"\n{outcome.reason} (exit {outcome.exit_code}); vehicle {mode}, armed {armed}; {len(after)} safe setpoints after the request")
    assert outcome.exit_code == 3, outcome.reason
    assert "no HEARTBEAT from the autopilot" in outcome.reason and "AUTO.LOITER requested, not confirmed within 2 s" in outcome.reason
    assert all(is_safe_setpoint(m) for m in after)
    assert (mode, armed) == ("AUTO.LOITER", True)  # the request arrived: the vehicle holds
