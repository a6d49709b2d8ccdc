"""40 % datagram loss (both ways) plus a 2 s telemetry blackout: the app declares the state stale,
streams only the safe setpoint and re-requests AUTO.LOITER until a HEARTBEAT confirms it; the
vehicle ends in that mode, never in PX4's offboard-loss RTL. Before issue 9 the hold was requested
once (lost in 2 of 3 runs) while the keep-alive re-sent the stale acceleration: PX4 flew it open
loop to 7 m/s, 15 m out of the arena, before its own failsafe."""

from __future__ import annotations

import numpy as np
import pytest
from sitl_mock.runner import spawn

from app.flights import run_fly

from .common import SETPOINT_TYPES, entries, last_heartbeat_mode, hover, is_mode_request, is_safe_setpoint, own_clock, read_truth, write_config

pytestmark = pytest.mark.integration


@pytest.mark.parametrize("seed", [0, 1])
def test_loss_and_blackout_end_in_the_requested_hold_not_rtl(tmp_path, seed: int) -> None:
    # Gains a lossy link can carry: 40 % loss holds setpoints for several periods (an extra delay
    # the paper's 6 Hz loop has no margin for; it then ends in a tilt breach before the blackout,
    # which is safe but not the case under test).
    # The HEARTBEAT watchdog (3 s by default) is set beyond what 40 % loss of a 1 Hz HEARTBEAT on a
    # half-speed vehicle can starve (3 s without one happened before the blackout began): the case
    # under test is the stale state, whose 0.5 s watchdog must fire in the blackout.
    config = write_config(tmp_path, safety={"heartbeat_timeout_s": 10.0},
                          gains={"transversal": {"bandwidth_hz": 2.0, "damping": 0.9},
                                 "tangential": {"bandwidth_hz": 1.5, "damping": 1.0}})
    truth_log = tmp_path / "truth.csv"
    # The loss starts with OFFBOARD: connecting and switching through 40 % loss both ways to a 1 Hz
    # HEARTBEAT at half speed sometimes took longer than the app's 5 s command timeout (exit 3
    # before the blackout, which is safe but not the case under test)
    cfg = own_clock("px4", hover(), truth_log, loss=0.4, blackout_s=(3.0, 5.0), windows_from_offboard=True, loss_from_offboard=True)
    from dataclasses import replace

    with spawn(replace(cfg, seed=seed)) as mock:
        # (connecting through 40 % loss to a 1 Hz HEARTBEAT at half speed can take more than 5 s)
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "60", "--heartbeat-timeout", "30")
    truth = read_truth(truth_log)
    t_off = float(truth.time_s[truth.mode.index("OFFBOARD")])
    during = truth.time_s >= t_off + 3.0
    speed = np.linalg.norm(np.diff(truth.position_ned_m, axis=0), axis=1) / np.maximum(np.diff(truth.time_s), 1e-9)
    log = entries(tmp_path / "log")
    requests = [e for e in log if e.direction == "out" and is_mode_request(e.message) and e.message.param2 == 4]
    assert during.any(), f"the flight ended before the blackout: {outcome.reason}"
    print(f"\nseed {seed}: {outcome.reason} (exit {outcome.exit_code}); modes seen {sorted(set(truth.mode))}; "
          f"end {last_heartbeat_mode(tmp_path / 'log', 'px4')}; {len(requests)} hold requests; max speed after the blackout began "
          f"{speed[during[1:]].max():.2f} m/s")  # fmt: skip
    assert outcome.exit_code == 3, outcome.reason
    assert "state went stale" in outcome.reason, outcome.reason
    assert "AUTO.LOITER requested, confirmed" in outcome.reason, outcome.reason
    assert last_heartbeat_mode(tmp_path / "log", "px4") == "AUTO.LOITER" and truth.armed[-1]
    assert "AUTO.RTL" not in truth.mode  # PX4's offboard-loss failsafe never fired
    # nothing flown open loop: the vehicle does not speed up once the blackout began (the regression
    # flew 7 m/s). Usually it is on the path by then (1.5 m/s); a slow connection through the loss
    # can leave it still approaching (paper.yaml allows 3 m/s), seen once at 2.18 m/s, then slowing.
    after = speed[during[1:]]
    assert after.max() < max(2.0, after[0] + 0.3)
    # after the first hold request, only safe setpoints (and more hold requests) left
    first = log.index(requests[0])
    after = [e.message for e in log[first:] if e.direction == "out" and e.message.get_type() in SETPOINT_TYPES]
    assert all(is_safe_setpoint(m) for m in after)
