"""The autopilot's clock jumps mid-flight (time_boot_ms / time_usec of everything it sends moves by
+30 s or -20 s: a clock reset, a reboot's clock) while the vehicle flies on. The first sample of the
new timeline is refused, the next confirms it; the flight goes on on one continuous clock: `--duration`
ends it after 4 s of the vehicle's real time, not early (forward) or 20 s late (backward), the
envelope's watchdogs are not fooled (this test found the no-progress watchdog ending the flight on
the 30 s gap that never happened), and it hands back in the confirmed hold. Before issue 9
`--duration` was measured across the two clocks.

A small step back (2 s, inside the estimator's reorder window) cannot be told from a stream of
replayed or reordered samples: every sample is refused as old, so the state goes stale and the flight
ends in the confirmed hold with exit 3 — never flying the refused samples."""

from __future__ import annotations

import pytest
from sitl_mock.runner import run_in_thread

from app.flights import run_fly

from .common import SETPOINT_TYPES, hover, is_safe_setpoint, lockstep, outgoing, write_config

pytestmark = pytest.mark.integration

JUMP_AT_S = 2.0
DURATION_S = 4.0


def _mode_changes(log) -> list[tuple[float, str]]:  # noqa: ANN001
    return [(e.time_s, e.text.split(" -> ")[1]) for e in log if e.text.startswith("mode ")]


@pytest.mark.parametrize(("jump_s", "clock_at_start_s"), [(30.0, 0.0), (-20.0, 60.0)], ids=["forward", "backward"])
def test_clock_jump_mid_flight_keeps_one_clock_for_duration_and_watchdogs(tmp_path, jump_s: float, clock_at_start_s: float) -> None:
    config = write_config(tmp_path)
    faults = {"clock_jump_at_s": JUMP_AT_S, "clock_jump_s": jump_s, "clock_at_start_s": clock_at_start_s}
    with run_in_thread(lockstep("px4", hover(), **faults)) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", str(DURATION_S))
        mode, armed, changes = mock.call(lambda m: (m.autopilot.mode.name, m.autopilot.armed, _mode_changes(m.autopilot.log)))
    est = outcome.estimator
    # the mock's own (unjumped) clock: following lasted from OFFBOARD until the hold we asked for
    t_offboard = next(t for t, name in changes if name == "OFFBOARD")
    t_hold = next(t for t, name in changes if t > t_offboard and name == "AUTO.LOITER")
    records = outcome.records
    times = [r.time_s for r in records]
    print(f"\nclock jump {jump_s:+g} s at {JUMP_AT_S} s: {outcome.reason} (exit {outcome.exit_code}); followed "
          f"{t_hold - t_offboard:.3f} s of vehicle time; estimator: {est.clock_jumps} refused, {est.clock_reanchors} "
          f"adopted, last event {est.last_event!r}; vehicle {mode}, armed {armed}")  # fmt: skip
    assert outcome.exit_code == 0, outcome.reason
    assert outcome.reason.startswith(f"duration {DURATION_S:g} s reached") and outcome.breach is None, outcome.reason
    assert (mode, armed) == ("AUTO.LOITER", True)
    # one continuous clock: 4 s of the vehicle's time (plus the hold request's round trip), where two
    # clocks would give ~2 s (forward) or ~24 s (backward)
    assert DURATION_S <= t_hold - t_offboard <= DURATION_S + 0.5
    # both streams (position and attitude) saw the jump, refused its first sample and adopted the new
    # timeline on the confirming one
    assert est.clock_jumps >= 2 and est.clock_reanchors >= 2
    # the steps really did run on both timelines (the step log keeps the autopilot's own stamps)
    jumps = [b - a for a, b in zip(times, times[1:])]
    assert min(jumps) < -15.0 if jump_s < 0 else max(jumps) > 25.0
    if jump_s < 0:  # going back is a reboot-like reset: the follower restarted, and the log says why
        assert any("autopilot clock jumped" in r.event for r in records), [r.event for r in records if r.event]


def test_a_small_step_back_ends_in_the_confirmed_hold_without_flying_old_samples(tmp_path) -> None:
    config = write_config(tmp_path)
    faults = {"clock_jump_at_s": JUMP_AT_S, "clock_jump_s": -2.0, "clock_at_start_s": 60.0}
    with run_in_thread(lockstep("px4", hover(), **faults)) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", str(DURATION_S))
        mode, armed = mock.call(lambda m: (m.autopilot.mode.name, m.autopilot.armed))
    est = outcome.estimator
    out = outgoing(tmp_path / "log")
    t_jump_ms = (60.0 + JUMP_AT_S) * 1000
    commands = [m for m in out if m.get_type() in SETPOINT_TYPES and not is_safe_setpoint(m)]
    print(f"\nclock -2 s at {JUMP_AT_S} s: {outcome.reason} (exit {outcome.exit_code}); {est.rejected_old} old samples "
          f"refused; last command stamped {commands[-1].time_boot_ms} ms; vehicle {mode}, armed {armed}")  # fmt: skip
    assert outcome.exit_code == 3, outcome.reason
    assert "state went stale" in outcome.reason and "AUTO.LOITER requested, confirmed" in outcome.reason, outcome.reason
    assert (mode, armed) == ("AUTO.LOITER", True)
    assert est.rejected_old > 0
    # no command was computed from a sample of the stepped-back clock (they all stamp t < jump)
    assert all(m.time_boot_ms <= t_jump_ms + 4 for m in commands)
    # and none went out after the state went stale: only the safe setpoint
    assert not [r for r in outcome.records if r.time_s > (60.0 + JUMP_AT_S) + 0.01]
