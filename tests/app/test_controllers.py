"""One controller at a time (pf_offboard.app.controllers): unit cases on real MAVLink messages and a
property test over random timelines of our setpoints, the autopilot's echo, relayed setpoints and
HEARTBEATs."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.app.controllers import ControllerWatch, carries_position_or_velocity

M = mavlink2
ACCEL_ONLY = 0x0C3F  # what the app sends in acceleration mode (and PX4 echoes as 63: pos/vel NaN)
POSITION_ONLY = 0x0DF8
_MAV = M.MAVLink(None, srcSystem=1, srcComponent=191)


def _decoded(msg):
    """Through the wire, so the message knows its sender (system 1 component 191)."""
    return _MAV.decode(bytearray(msg.pack(_MAV)))


def echo(mask: int, x: float = math.nan, vx: float = math.nan) -> M.MAVLink_position_target_local_ned_message:
    return M.MAVLink_position_target_local_ned_message(0, M.MAV_FRAME_LOCAL_NED, mask, x, 0.0, -2.0, vx, 0.0, 0.0, 0.1, 0.0, -9.8, 0.0, 0.0)


def sent_accel() -> M.MAVLink_set_position_target_local_ned_message:
    return M.MAVLink_set_position_target_local_ned_message(0, 1, 1, M.MAV_FRAME_LOCAL_NED, ACCEL_ONLY, 0, 0, 0, 0, 0, 0, 0.1, 0, -9.8, 0, 0)


def sent_position() -> M.MAVLink_set_position_target_local_ned_message:
    return M.MAVLink_set_position_target_local_ned_message(0, 1, 1, M.MAV_FRAME_LOCAL_NED, POSITION_ONLY, 1, 2, -2, 0, 0, 0, 0, 0, 0, 0, 0)


def test_what_carries_a_position_or_velocity() -> None:
    assert not carries_position_or_velocity(sent_accel())
    assert carries_position_or_velocity(sent_position())
    assert not carries_position_or_velocity(echo(63))  # PX4's echo of our acceleration setpoint
    assert carries_position_or_velocity(echo(0, x=1.0, vx=0.2))  # PX4's position controller
    assert carries_position_or_velocity(echo(0xDC7, vx=0.5))  # ArduCopter VelAccel: velocity
    nan = math.nan
    unset = M.MAVLink_position_target_local_ned_message(0, M.MAV_FRAME_LOCAL_NED, 0, nan, nan, nan, nan, nan, nan, 0.1, 0, -9.8, 0, 0)
    assert not carries_position_or_velocity(unset)  # bits clear but the values NaN: nothing in use
    att = M.MAVLink_set_attitude_target_message(0, 1, 1, 0, [1, 0, 0, 0], 0, 0, 0, 0.5)
    assert not carries_position_or_velocity(att)


def test_echoes_need_three_pieces_and_a_newer_offboard_heartbeat() -> None:
    w = ControllerWatch()
    w.heartbeat(True, 0.0)
    for t in (1.0, 1.1, 1.2):
        w.echoed_target(echo(0, x=1.0), t)
        assert w.verdict(t) == ""  # the HEARTBEAT is older than the evidence: could be an operator's switch
    w.heartbeat(True, 1.5)
    assert "another controller is flying the vehicle: 3 setpoints not ours" in w.verdict(1.5)


def test_our_own_position_setpoints_explain_the_echo_for_a_second() -> None:
    w = ControllerWatch()
    w.sent(sent_position(), 0.0)  # our take-off / hold
    for t in (0.2, 0.5, 0.9):
        w.echoed_target(echo(0, x=1.0), t)
    w.heartbeat(True, 0.95)
    assert w.verdict(0.95) == "" and w.echoes == 0
    w.sent(sent_accel(), 1.0)
    w.echoed_target(echo(63), 1.1)  # our acceleration echoed: nothing
    assert w.echoes == 0


def test_the_autopilots_own_target_at_activation_is_not_evidence() -> None:
    """ArduCopter SITL: echoes of its take-off sub-mode (position only) ended 15-40 ms before
    following began; one still in flight must not count."""
    w = ControllerWatch()
    w.autopilot_target(10.0)
    for t in (10.02, 10.06, 10.1):
        w.echoed_target(echo(0xDF8, x=1.0), t)
    w.heartbeat(True, 10.2)
    assert w.verdict(10.2) == "" and w.echoes == 0


def test_relayed_setpoints_name_their_sender() -> None:
    w = ControllerWatch()
    other = _decoded(sent_position())
    for t in (0.0, 0.02, 0.04):
        w.relayed_setpoint(other, t)
    w.heartbeat(True, 0.5)
    assert "SET_POSITION_TARGET_LOCAL_NED from system 1 component 191" in w.verdict(0.5)


def test_old_evidence_expires() -> None:
    w = ControllerWatch(window_s=2.0)
    for t in (0.0, 0.1):
        w.echoed_target(echo(0, x=1.0), t)
    w.echoed_target(echo(0, x=1.0), 3.0)
    w.heartbeat(True, 3.1)
    assert w.verdict(3.1) == ""


# ---------------------------------------------------------------- property test
timeline = st.lists(
    st.tuples(
        st.sampled_from(["send_accel", "send_position", "echo_ours", "echo_foreign", "relayed", "hb_offboard", "hb_other"]),
        st.floats(min_value=0.001, max_value=0.8),
    ),
    min_size=1,
    max_size=80,
)


@settings(max_examples=400, deadline=None)
@given(events=timeline)
def test_random_timelines_never_decide_without_three_pieces_and_a_newer_offboard_heartbeat(events) -> None:
    """Whatever the order: a verdict needs at least 3 pieces of foreign evidence within the window,
    the oldest of them followed by a HEARTBEAT still in OFFBOARD; echoes within a second of our own
    position setpoints never count; our own traffic alone never decides."""
    w = ControllerWatch()
    now = 0.0
    foreign: list[float] = []  # times of evidence that must count
    last_pos_sent = -math.inf
    last_offboard_hb = -math.inf
    for kind, dt in events:
        now += dt
        if kind == "send_accel":
            w.sent(sent_accel(), now)
        elif kind == "send_position":
            w.sent(sent_position(), now)
            last_pos_sent = now
        elif kind == "echo_ours":
            w.echoed_target(echo(63), now)
        elif kind == "echo_foreign":
            w.echoed_target(echo(0, x=1.0), now)
            if now - last_pos_sent > w.own_grace_s:
                foreign.append(now)
        elif kind == "relayed":
            w.relayed_setpoint(_decoded(sent_position()), now)
            foreign.append(now)
        elif kind == "hb_offboard":
            w.heartbeat(True, now)
            last_offboard_hb = now
        else:
            w.heartbeat(False, now)
        verdict = w.verdict(now)
        recent = [t for t in foreign if now - t <= w.window_s]
        expected = len(recent) >= w.confirm and last_offboard_hb > recent[0]
        assert bool(verdict) == expected, (kind, now, recent, last_offboard_hb, verdict)
