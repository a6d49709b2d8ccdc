"""A vehicle that comes down mid-flight: from t = 3 s every motor gives only 45 % of the thrust
it is commanded (a sagging battery, damaged propellers). The autopilot's hover thrust is then far
too low and the most the app's bounded thrust command can get out of it (about 1.15 g) cannot hold
height at the path's tilts. It sinks whatever it is commanded, touches down and is disarmed by
the autopilot (the mock's touchdown faster than 3 m/s is a crash). The floor is put below the
ground for this test so that the fence does not end the flight first. The app ends within 1 s of
the touchdown with exit 6 and sends nothing after it (no setpoint, no mode request to a disarmed
vehicle). Before issue 9 the app followed a crashed, disarmed wreck for 160 s and exited 0.

(The mock's touchdowns on the paper path at these gains are all harder than its 3 m/s crash
speed, so the EXTENDED_SYS_STATE "on the ground while armed" branch stays covered by
tests/safety/test_envelope.py.)"""

from __future__ import annotations

import pytest
from sitl_mock.runner import run_in_thread

from app.flights import run_fly
from pf_offboard.app.profiles import PX4, is_armed

from .common import SETPOINT_TYPES, entries, hover, is_mode_request, is_safe_setpoint, lockstep, outgoing, write_config

pytestmark = pytest.mark.integration

THRUST_LOSS_AT_S = 3.0


def test_coming_down_mid_flight_ends_the_flight_within_1_s_with_exit_6(tmp_path) -> None:
    config = write_config(tmp_path, safety={"min_altitude_m": -1.0, "fence_margin_m": 3.0})
    cfg = lockstep("px4", hover(), thrust_loss_at_s=THRUST_LOSS_AT_S, thrust_loss_factor=0.45)
    touchdown: list[float] = []

    def watch(m) -> None:  # noqa: ANN001
        def record(_msg, _addr) -> None:
            if m.truth.landed and not touchdown:
                touchdown.append(m.autopilot.time_s)

        m.on_received = record

    with run_in_thread(cfg) as mock:
        mock.call(watch)
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "30")
        mode, armed, landed = mock.call(lambda m: (m.autopilot.mode.name, m.autopilot.armed, m.truth.landed))
    out = outgoing(tmp_path / "log")
    breach_ms = round(outcome.breach_time_s * 1000)
    after = [m for m in out if m.get_type() in SETPOINT_TYPES and m.time_boot_ms >= breach_ms]
    print(f"\nthrust loss at {THRUST_LOSS_AT_S} s, touchdown at {touchdown[0]:.3f} s: {outcome.reason} "
          f"(exit {outcome.exit_code}) at {outcome.breach_time_s} s; {len(after)} setpoints after it; "
          f"vehicle {mode}, armed {armed}, on the ground {landed}")  # fmt: skip
    assert outcome.exit_code == 6, outcome.reason
    assert "the vehicle disarmed in flight" in outcome.reason, outcome.reason
    # seen within 1 s of the touchdown, and not before it
    assert touchdown[0] <= outcome.breach_time_s <= touchdown[0] + 1.0
    assert landed and not armed
    # nothing after the disarm was seen but at most the setpoint already stamped with that sample
    # (and, if the host stalled 0.1 s before the app read the disarm, the keep-alive's safe
    # setpoint for that same sample: zero acceleration, seen once on a loaded machine)
    computed = [m for m in after if not is_safe_setpoint(m)]
    assert len(computed) <= 1 and not [m for m in out if m.get_type() in SETPOINT_TYPES and m.time_boot_ms > breach_ms]
    # no mode request once the disarm was in: the mock reports the touchdown (EXTENDED_SYS_STATE on
    # the ground) and the disarm (HEARTBEAT) in either order, as PX4 does; on the ground while armed
    # is the LANDED breach, whose hold request may go out just before the disarm is read
    log = entries(tmp_path / "log")
    first = next(i for i, e in enumerate(log) if e.direction == "out" and e.message.get_type() in SETPOINT_TYPES)
    disarm = next(i for i, e in enumerate(log) if i > first and e.direction == "in" and e.message.get_type() == "HEARTBEAT"
                  and e.message.get_srcSystem() == 1 and not is_armed(e.message.base_mode))  # fmt: skip
    assert not [e for e in log[disarm:] if e.direction == "out" and is_mode_request(e.message)]
    on_ground = [i for i, e in enumerate(log) if e.direction == "in" and e.message.get_type() == "EXTENDED_SYS_STATE"
                 and e.message.landed_state == 1]  # fmt: skip
    for i, e in enumerate(log[:disarm]):
        if e.direction == "out" and is_mode_request(e.message) and e.message.param2 != PX4.offboard.param2:
            assert on_ground and on_ground[0] < i, "a hold requested before the disarm, not answering the touchdown"
