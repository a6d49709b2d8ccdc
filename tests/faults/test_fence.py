"""The fence: a path outside it is refused before any traffic (exit 2); a vehicle (estimate) that
leaves it in flight ends following with the hold requested and confirmed (exit 5), and nothing but
the safe setpoint goes out after the breach. Before issue 9 a path 4 km away or below ground was
accepted, and a 4 km position jump was chased at the approach-speed limit."""

from __future__ import annotations

import pytest
from sitl_mock.runner import run_in_thread

from pf_offboard.cli import main
from app.flights import run_fly

from .common import SETPOINT_TYPES, hover, is_mode_request, is_safe_setpoint, lockstep, outgoing, write_config

pytestmark = pytest.mark.integration


@pytest.mark.parametrize(
    ("safety", "expect"),
    [
        ({"fence_min_enu_m": [-5, -5, 0], "fence_max_enu_m": [5, 1, 10]}, "the path leaves the fence"),
        ({"min_altitude_m": 2.0}, "below the floor 2 m"),
        ({"fence_shape": "cylinder", "fence_center_enu_m": [4000, 0], "fence_radius_m": 50}, "outside the fence cylinder"),
    ],
)
def test_path_outside_the_fence_is_refused_before_any_traffic(tmp_path, capsys, safety: dict, expect: str) -> None:
    config = write_config(tmp_path, safety=safety)
    with run_in_thread(lockstep("px4", hover())) as mock:
        code = main(["fly", "--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config", str(config), "--airborne",
                     "--quiet", "--log-dir", str(tmp_path / "log")])  # fmt: skip
        received = mock.call(lambda m: m.received)
    err = capsys.readouterr().err
    print("\n" + err.strip())
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("pf-offboard fly: error: safety: ") and expect in err
    assert received == 0  # the vehicle never heard from us
    assert not (tmp_path / "log" / "flight.tlog").exists()


def test_position_jump_out_of_the_fence_ends_following_in_hold(tmp_path) -> None:
    """A 10 m estimator jump at t = 4 s (a glitching position source): the estimate leaves the
    fence; the app does not chase it, it requests AUTO.LOITER and exits 5 once it is confirmed."""
    config = write_config(tmp_path)
    cfg = lockstep("px4", hover(), estimator_reset_at_s=4.0, estimator_reset_ned_m=(10.0, 0.0, 0.0))
    with run_in_thread(cfg) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "30")
        mode, armed, true_ned = mock.call(lambda m: (m.autopilot.mode.name, m.autopilot.armed, m.truth.position_ned_m.copy()))
    print(f"\n{outcome.reason} (exit {outcome.exit_code}); vehicle {mode}, armed {armed}, true position NED {true_ned}")
    assert outcome.exit_code == 5, outcome.reason
    # the confirmed 10 m jump is an estimator reset beyond safety.max_estimator_reset_m (judged before the fence)
    assert ("safety: outside the fence" in outcome.reason or "safety: estimator reset moved the position estimate 10.00 m" in outcome.reason)
    assert "AUTO.LOITER requested, confirmed" in outcome.reason
    assert 4.0 <= outcome.breach_time_s <= 4.01  # on the first sample after the jump
    assert (mode, armed) == ("AUTO.LOITER", True)
    # the real vehicle never left the fence (x, y within the path box + 2 m; z within 0.5..5.65 m)
    assert -3.51 <= true_ned[0] <= 4.01 and -3.67 <= true_ned[1] <= 2.97 and 0.5 <= -true_ned[2] <= 5.65
    out = outgoing(tmp_path / "log")
    # every setpoint stamped from the breaching sample on is the safe one (no chase of the jump)
    after = [m for m in out if m.get_type() in SETPOINT_TYPES and m.time_boot_ms >= round(outcome.breach_time_s * 1000)]
    assert after and all(is_safe_setpoint(m) for m in after)
    assert [m.param2 for m in out if is_mode_request(m)][-1] == 4  # AUTO (LOITER)
