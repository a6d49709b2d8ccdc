"""Operator takeover in every phase (take-off, engaging, hand-back): the app stops at once, sends no
setpoint and no mode request after the HEARTBEAT showing it, and exits 4; the vehicle stays in the
operator's mode. Before issue 9, a takeover during take-off got ~1900 more setpoints and was
switched to AUTO.LOITER (exit 3); one while engaging or handing back was undone 0.5 s later."""

from __future__ import annotations

import pytest
from sitl_mock.runner import run_in_thread

from app.flights import run_fly

from .common import PX4_POSCTL, SETPOINT_TYPES, entries, hover, is_mode_request, lockstep, write_config

pytestmark = pytest.mark.integration


def _after_takeover(log_dir) -> list:
    """What the app sent after the first HEARTBEAT showing POSCTL (the operator's mode)."""
    log = entries(log_dir)
    seen = next(i for i, e in enumerate(log) if e.direction == "in" and e.message.get_type() == "HEARTBEAT"
                and e.message.get_srcComponent() == 1 and e.message.custom_mode == PX4_POSCTL)  # fmt: skip
    return [e.message for e in log[seen + 1 :] if e.direction == "out"]


def _check(outcome, mock, log_dir, phase: str) -> None:
    mode, armed = mock.call(lambda m: (m.autopilot.mode.name, m.autopilot.armed))
    after = _after_takeover(log_dir)
    print(f"\ntakeover during {phase}: {outcome.reason} (exit {outcome.exit_code}); vehicle {mode}, armed {armed}; "
          f"sent after it: {sorted({m.get_type() for m in after})}")  # fmt: skip
    assert outcome.exit_code == 4, outcome.reason
    assert f"-> POSCTL by someone else during {phase}; stopped sending, not re-engaging" in outcome.reason
    assert not [m for m in after if m.get_type() in SETPOINT_TYPES]
    assert not [m for m in after if is_mode_request(m) or m.get_type() == "COMMAND_LONG"]
    assert (mode, armed) == ("POSCTL", True)


def test_takeover_during_takeoff(tmp_path) -> None:
    config = write_config(tmp_path)
    # taken over once 0.5 m up: a timed takeover (3.5 s) found the vehicle still on the ground
    # when the client took long to arm under CI load
    with run_in_thread(lockstep("px4", "ground", takeover_above_m=0.5, takeover_mode="POSCTL")) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--takeoff", "2", "--duration", "5")
        _check(outcome, mock, tmp_path / "log", "takeoff")
        assert 0.3 < -mock.call(lambda m: m.truth.position_ned_m[2]) < 2.0  # it was climbing, not yet there


def test_takeover_while_engaging(tmp_path) -> None:
    # The autopilot refuses the OFFBOARD request for a while (busy): the app keeps asking, streaming
    # the follower's setpoints (proof of life), until the operator switches to POSCTL at t = 1 s.
    config = write_config(tmp_path)
    cfg = lockstep("px4", hover(), mode_refused_s=(0.0, 3.0), takeover_at_s=1.0, takeover_mode="POSCTL")
    with run_in_thread(cfg) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "5")
        _check(outcome, mock, tmp_path / "log", "engaging")


def test_takeover_during_hand_back(tmp_path) -> None:
    # Following ends after 1 s; the hold request is refused (busy) until the operator takes over.
    config = write_config(tmp_path)
    cfg = lockstep("px4", hover(), mode_refused_s=(1.0, 30.0), takeover_at_s=3.0, takeover_mode="POSCTL")
    with run_in_thread(cfg) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--duration", "1")
        _check(outcome, mock, tmp_path / "log", "handing_back")
