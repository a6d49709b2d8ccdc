"""The fence: a path outside it is refused before any traffic (exit 2); a vehicle (estimate) that
leaves it in flight ends following with the hold requested and confirmed (exit 5), and nothing but
the safe setpoint goes out after the breach. Before issue 9 a path 4 km away or below ground was
accepted, and a 4 km position jump was chased at the approach-speed limit."""

from __future__ import annotations

import pytest
from sitl_mock.runner import run_in_thread

from pf_offboard.cli import main
from app.flights import RATE_HZ, run_fly

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
    assert 4.0 <= outcome.breach_time_s <= 4.0 + 2.5 / RATE_HZ  # on the first samples after the jump (confirmed on the second)
    assert (mode, armed) == ("AUTO.LOITER", True)
    # the real vehicle never left the fence (x, y within the path box + 2 m; z within 0.5..5.65 m)
    assert -3.51 <= true_ned[0] <= 4.01 and -3.67 <= true_ned[1] <= 2.97 and 0.5 <= -true_ned[2] <= 5.65
    out = outgoing(tmp_path / "log")
    # every setpoint stamped from the breaching sample on is the safe one (no chase of the jump)
    after = [m for m in out if m.get_type() in SETPOINT_TYPES and m.time_boot_ms >= round(outcome.breach_time_s * 1000)]
    assert after and all(is_safe_setpoint(m) for m in after)
    assert [m.param2 for m in out if is_mode_request(m)][-1] == 4  # AUTO (LOITER)


def test_takeoff_height_is_kept_inside_the_fence() -> None:
    from pf_offboard.safety import Fence, takeoff_height_in_fence

    fence = Fence("box", 3.0, 8.0, min_xy_m=(-5.0, -5.0), max_xy_m=(5.0, 5.0))
    assert takeoff_height_in_fence(fence, 5.0) == (5.0, "")
    low, note = takeoff_height_in_fence(fence, 2.0)
    assert low == 3.5 and "below the path's fence floor 3.00 m" in note
    high, note = takeoff_height_in_fence(fence, 20.0)
    assert high == 7.5 and "above the path's fence ceiling" in note
    narrow = Fence("box", 3.0, 3.6, min_xy_m=(-5.0, -5.0), max_xy_m=(5.0, 5.0))
    assert takeoff_height_in_fence(narrow, 2.0)[0] == pytest.approx(3.3)


def test_a_takeoff_below_the_fence_floor_climbs_to_the_floor_instead_of_breaching(tmp_path) -> None:
    """`--takeoff 2` with the path's fence floor at 3 m used to arm, climb to 2 m and end in
    "outside the fence: altitude below the floor" (exit 5). Now the take-off goes to the floor +
    0.5 m, says so before arming, and the flight follows the path (exit 0)."""
    import io
    import re

    import yaml

    from app.flights import fly_args
    from pf_offboard.app.fly import fly

    config = write_config(tmp_path, safety={"min_altitude_m": 3.0})
    data = yaml.safe_load(config.read_text())
    data["path"]["waypoints"] = [[x, y, z + 2.0] for x, y, z in data["path"]["waypoints"]]  # lowest point 3.8 m
    config.write_text(yaml.safe_dump(data))
    status = io.StringIO()
    # in lockstep: the vehicle advances only on the app's setpoints, so a starved app (a loaded
    # machine) cannot leave it flying a stale setpoint on its own clock (the real-time mock at
    # speed 4 tripped the tilt watchdog then, exit 5, ~2 runs in 6 under load)
    with run_in_thread(lockstep("px4", "ground")) as mock:
        args = fly_args("--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config", str(config), "--log-dir",
                        str(tmp_path / "log"), "--heartbeat-timeout", "5", "--takeoff", "2", "--duration", "2")  # fmt: skip
        outcome = fly(args, status_stream=status)
    text = status.getvalue()
    assert "take-off height 2 m is below the path's fence floor 3.00 m: taking off to 3.50 m" in text, (outcome.reason, text[-1500:])
    # said before arming: before "waiting for arming" (printed only when arming takes a while) or the
    # autopilot's "Armed by external command", whichever comes first
    armed = re.search(r"\b[Aa]rm", text)
    assert armed is not None and text.index("taking off to 3.50 m") < armed.start(), (outcome.reason, text[-1500:])
    assert outcome.exit_code == 0, (outcome.reason, text[-1500:])
    first = next(r for r in outcome.records if r.active)
    assert first.position_enu_m[2] >= 3.0  # following began inside the fence


def test_a_plans_take_off_altitude_is_takeoffs_default(tmp_path) -> None:
    """`--takeoff` without a height: the plan's take-off item's altitude (above home), else flight:."""
    import argparse
    import json
    from pathlib import Path

    from pf_offboard.app.fly import FROM_CONFIG, _heights_from_config
    from pf_offboard.config import load_config

    data_dir = Path(__file__).resolve().parents[1] / "data" / "geo"
    plan = json.loads((data_dir / "mission.plan").read_text())
    takeoff = next(item for item in plan["mission"]["items"] if item.get("command") == 22)
    takeoff["params"][6] = 3.5
    (tmp_path / "field.plan").write_text(json.dumps(plan))
    (tmp_path / "field.yaml").write_text("path: {file: field.plan, altitude_reference: relative_home, closed: true}\n"
                                         "flight: {takeoff_altitude_m: 2.5}\n")  # fmt: skip
    args = argparse.Namespace(takeoff=FROM_CONFIG, throw=None)
    _heights_from_config(args, load_config(tmp_path / "field.yaml"))
    assert args.takeoff == 3.5
    (tmp_path / "local.yaml").write_text("path: {waypoints: [[0, 0, 2], [4, 0, 2]]}\nflight: {takeoff_altitude_m: 2.5}\n")
    args = argparse.Namespace(takeoff=FROM_CONFIG, throw=None)
    _heights_from_config(args, load_config(tmp_path / "local.yaml"))
    assert args.takeoff == 2.5
