"""A vehicle that disarms or loses its motors mid-flight: the app ends within 1 s of vehicle time
with exit 6 and says why. Before issue 9 it followed a disarmed wreck for 160 s and exited 0."""

from __future__ import annotations

import pytest
from sitl_mock.runner import run_in_thread

from app.flights import run_fly

from .common import SETPOINT_TYPES, hover, is_safe_setpoint, lockstep, outgoing, write_config

pytestmark = pytest.mark.integration

FAULT_AT_S = 4.0


@pytest.mark.parametrize(
    ("fault", "expect"),
    [("disarm_at_s", "the vehicle disarmed in flight"), ("motor_failure_at_s", "falling")],
)
def test_crash_or_disarm_mid_flight_ends_within_1_s(tmp_path, fault: str, expect: str) -> None:
    config = write_config(tmp_path)
    with run_in_thread(lockstep("px4", hover(), **{fault: FAULT_AT_S})) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "30")
        armed, on_ground = mock.call(lambda m: (m.autopilot.armed, m.truth.landed))
    out = outgoing(tmp_path / "log")
    setpoints = [m for m in out if m.get_type() in SETPOINT_TYPES]
    last_command = max(m.time_boot_ms for m in setpoints if not is_safe_setpoint(m)) / 1000.0
    print(f"\n{fault} at {FAULT_AT_S} s: detected at {outcome.breach_time_s} s; "
          f"last path-following setpoint at {last_command:.3f} s; {outcome.reason} (exit {outcome.exit_code}); "
          f"vehicle armed {armed}, on the ground {on_ground}")  # fmt: skip
    assert outcome.exit_code == 6, outcome.reason
    # motors lost from 1-2 m: "falling" needs two samples over safety.falling_confirm_s (never one);
    # when the ground comes first, the disarm on impact ends it (the same exit, as soon)
    assert expect in outcome.reason or (fault == "motor_failure_at_s" and "the vehicle disarmed in flight" in outcome.reason)
    assert last_command - FAULT_AT_S <= 1.0  # no path-following command later than 1 s after the fault
    assert outcome.breach is not None and outcome.breach_time_s - FAULT_AT_S <= 1.0
    if fault == "disarm_at_s":
        assert not armed
        # nothing at all after the disarm was seen: no mode request to a disarmed vehicle
        assert not [m for m in setpoints if m.time_boot_ms > (FAULT_AT_S + 0.2) * 1000]
