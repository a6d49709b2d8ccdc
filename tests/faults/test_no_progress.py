"""A vehicle that cannot make progress: from t = 3 s the autopilot stays in OFFBOARD and accepts the
setpoints but no longer flies them (it holds where it is). The app's commands change nothing, so
the no-progress watchdog (safety.no_progress_s) ends following: only the safe setpoint after the
breach, AUTO.LOITER requested and confirmed, exit 5. Before issue 9 a lap counter fed by jitter
reported "2 laps done" (exit 0) after a real PX4 had made no progress for 356 s."""

from __future__ import annotations

import pytest
from sitl_mock.runner import run_in_thread

from app.flights import run_fly

from .common import SETPOINT_TYPES, hover, is_mode_request, is_safe_setpoint, lockstep, outgoing, write_config

pytestmark = pytest.mark.integration

STUCK_AT_S = 3.0
NO_PROGRESS_S = 2.0


def test_no_progress_ends_following_in_the_confirmed_hold(tmp_path) -> None:
    config = write_config(tmp_path, safety={"no_progress_s": NO_PROGRESS_S})
    with run_in_thread(lockstep("px4", hover(), offboard_stuck_at_s=STUCK_AT_S)) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "30")
        mode, armed, truth = mock.call(lambda m: (m.autopilot.mode.name, m.autopilot.armed, m.truth))
    out = outgoing(tmp_path / "log")
    after = [m for m in out if m.get_type() in SETPOINT_TYPES and m.time_boot_ms >= round(outcome.breach_time_s * 1000)]
    print(f"\nstuck at {STUCK_AT_S} s: {outcome.reason} (exit {outcome.exit_code}) at {outcome.breach_time_s} s; "
          f"{len(after)} setpoints after it, all safe: {all(is_safe_setpoint(m) for m in after)}; vehicle {mode}, armed {armed}")  # fmt: skip
    assert outcome.exit_code == 5, outcome.reason
    assert "safety: no progress for" in outcome.reason and "AUTO.LOITER requested, confirmed" in outcome.reason, outcome.reason
    # detected when the window has run out: it started at the last 0.5 m of progress (safety.min_progress_m),
    # at most 0.5 m / 1.5 m/s before the vehicle stopped
    assert STUCK_AT_S + NO_PROGRESS_S - 0.5 / 1.5 <= outcome.breach_time_s <= STUCK_AT_S + NO_PROGRESS_S + 0.5
    assert (mode, armed) == ("AUTO.LOITER", True) and not truth.landed
    assert after and all(is_safe_setpoint(m) for m in after)  # nothing but the safe setpoint after the breach
    assert [m.param2 for m in out if is_mode_request(m)][-1] == 4  # AUTO (LOITER)
