"""The mode/command state machine (pf_offboard.app.modes): unit cases and a property test over
random HEARTBEAT / ACK timings, losses and foreign ACKs against a simulated autopilot that handles
requests in order after a random latency."""

from __future__ import annotations

import copy

from hypothesis import given, settings
from hypothesis import strategies as st

from pf_offboard.app.modes import MAV_STATE_CRITICAL, Event, ModeTracker, Owner

LOITER, OFFBOARD, POSCTL, LAND, RTL = 1, 2, 3, 4, 5
ACTIVE = 4


def tracker() -> ModeTracker:
    return ModeTracker(failsafe_modes=(LAND, RTL), name=lambda m: {1: "LOITER", 2: "OFFBOARD", 3: "POSCTL", 4: "LAND", 5: "RTL"}[m])


def test_a_heartbeat_older_than_the_request_never_confirms_it() -> None:
    """The finding: safing began between the OFFBOARD request and the HEARTBEAT showing it; the
    old HEARTBEAT still said LOITER and counted as the hold confirmed."""
    t = tracker()
    t.on_heartbeat(LOITER, ACTIVE, 0.0)
    assert t.request(OFFBOARD, 1.0)
    assert t.request(LOITER, 1.1)  # safing: the hold, while OFFBOARD is still in flight
    assert t.on_heartbeat(LOITER, ACTIVE, 1.05) is Event.NONE or not t.is_confirmed(LOITER)
    assert t.on_heartbeat(LOITER, ACTIVE, 1.2) is Event.NONE  # newer, but OFFBOARD may still land
    assert t.on_heartbeat(OFFBOARD, ACTIVE, 1.3) is Event.NONE and t.owner is Owner.US  # it landed: ours
    assert t.due(1.36) and t.request(LOITER, 1.36)  # re-sent
    assert t.on_heartbeat(LOITER, ACTIVE, 1.7) is Event.CONFIRMED and t.is_confirmed(LOITER)


def test_the_autopilot_failsafe_and_the_operator_win() -> None:
    t = tracker()
    t.on_heartbeat(LOITER, ACTIVE, 0.0)
    t.request(OFFBOARD, 0.1)
    assert t.on_heartbeat(OFFBOARD, ACTIVE, 0.2) is Event.NONE  # too soon: may have left before the request landed
    assert t.on_heartbeat(OFFBOARD, ACTIVE, 0.7) is Event.CONFIRMED
    assert t.on_heartbeat(LAND, MAV_STATE_CRITICAL, 5.0) is Event.FAILSAFE
    assert t.owner is Owner.AUTOPILOT and not t.request(LOITER, 5.01) and "failsafe" in t.may_request()
    t2 = tracker()
    t2.on_heartbeat(LOITER, ACTIVE, 0.0)
    t2.request(OFFBOARD, 0.1)
    assert t2.on_heartbeat(POSCTL, ACTIVE, 0.3) is Event.OPERATOR and not t2.request(LOITER, 0.4)
    t3 = tracker()  # an RTL we did not ask for, even without CRITICAL: not ours to override
    t3.on_heartbeat(LOITER, ACTIVE, 0.0)
    t3.request(OFFBOARD, 0.1)
    assert t3.on_heartbeat(RTL, ACTIVE, 0.3) is Event.FAILSAFE
    t4 = tracker()  # LAND we asked for is ours
    t4.on_heartbeat(OFFBOARD, ACTIVE, 0.0)
    t4.request(LAND, 0.1)
    assert t4.on_heartbeat(LAND, MAV_STATE_CRITICAL, 0.7) is Event.CONFIRMED


def test_foreign_and_refusing_acks() -> None:
    t = tracker()
    t.on_heartbeat(LOITER, ACTIVE, 0.0)
    t.request(OFFBOARD, 0.1)
    assert t.on_ack(2, ours=False) is Event.NONE and not t.refused
    assert t.on_ack(2, ours=True) is Event.REFUSED and t.refused


# ---------------------------------------------------------------- property test
events = st.lists(
    st.tuples(
        st.sampled_from(["request_offboard", "request_hold", "tick", "foreign_ack", "operator", "failsafe", "lose_next"]),
        st.floats(min_value=0.001, max_value=0.6),  # time to the next event
    ),
    min_size=1,
    max_size=60,
)


@settings(max_examples=400, deadline=None)
@given(events=events, latency=st.floats(min_value=0.0, max_value=0.3), hb_period=st.sampled_from([0.1, 0.5, 1.0]),
       loss=st.floats(min_value=0.0, max_value=0.5), seed=st.integers(0, 2**16))  # fmt: skip
def test_random_timings_never_confirm_without_newer_evidence_nor_override_a_failsafe(events, latency, hb_period, loss, seed) -> None:
    """A simulated autopilot (requests handled in order after ``latency``, HEARTBEATs every
    ``hb_period`` delivered after ``latency``, each datagram lost with probability ``loss``), an
    operator and an autopilot failsafe at random moments, foreign DENIED ACKs. Invariants:
    a confirmation always follows a HEARTBEAT showing the mode, emitted by the autopilot after it
    handled our latest request for it; no request is sent once the failsafe or the operator had
    the vehicle; foreign ACKs change nothing; a pending request is always re-sent in time."""
    import random

    rng = random.Random(seed)
    t = tracker()
    now = 0.0
    ap_mode, ap_status = LOITER, ACTIVE
    inbox: list[tuple[float, str, int, float]] = []  # (deliver at, kind, value, emitted at)
    to_ap: list[tuple[float, int]] = []  # (handled at, mode)
    handled_at: dict[int, float] = {}  # mode -> when the autopilot last switched to it on our request
    took_over_at: float | None = None  # operator / failsafe
    next_hb = 0.0
    must_not_send = False  # the tracker has seen the failsafe, or the operator's mode after we asked
    sent_when_forbidden = 0

    def send(mode: int) -> None:
        nonlocal sent_when_forbidden
        if must_not_send:
            sent_when_forbidden += 1
        if rng.random() >= loss:
            to_ap.append((now + latency, mode))

    t.on_heartbeat(LOITER, ACTIVE, 0.0)
    for kind, dt in events:
        if kind == "request_offboard" and t.request(OFFBOARD, now):
            send(OFFBOARD)
        elif kind == "request_hold" and t.request(LOITER, now):
            send(LOITER)
        elif kind == "foreign_ack":
            before = copy.deepcopy(t.__dict__)
            t.on_ack(2, ours=False)
            assert t.__dict__ == before
        elif kind == "operator" and took_over_at is None:
            ap_mode = POSCTL
            if t.owner is Owner.US:  # a takeover; before we asked it is just the mode we start from
                took_over_at = now
        elif kind == "failsafe" and took_over_at is None:
            ap_mode, ap_status, took_over_at = LAND, MAV_STATE_CRITICAL, now
        # advance time in small steps: the autopilot handles requests, emits HEARTBEATs; we receive
        end = now + dt
        while now < end:
            now = min(end, now + 0.01)
            for item in [x for x in to_ap if x[0] <= now]:
                to_ap.remove(item)
                if took_over_at is None:  # the operator / failsafe mode is not undone by our requests
                    ap_mode = item[1]
                    handled_at[ap_mode] = item[0]
            while next_hb <= now:
                if rng.random() >= loss:
                    inbox.append((next_hb + latency, "hb", ap_mode, next_hb))
                next_hb += hb_period
            for item in sorted(x for x in inbox if x[0] <= now):
                inbox.remove(item)
                _, _, mode, emitted = item
                pending = t.pending
                if mode == LAND or (mode == POSCTL and t.owner is Owner.US and t.start_mode != POSCTL):
                    must_not_send = True
                event = t.on_heartbeat(mode, ap_status if mode == ap_mode else ACTIVE, item[0])
                if event is Event.CONFIRMED:
                    assert pending is not None and mode == pending.mode
                    assert item[0] > pending.first_sent_s  # received after the request was sent
                    if took_over_at is None:
                        # true: the vehicle is in that mode, and no other request of ours is still on its way
                        # to land after it (the finding: a hold "confirmed" while OFFBOARD was in flight)
                        assert ap_mode == mode, (mode, ap_mode, emitted, pending)
                        assert all(m == mode for _, m in to_ap), to_ap
            if t.due(now) and t.pending is not None and t.request(t.pending.mode, now):
                send(t.pending.mode)
            if t.pending is not None and not t.yielded:
                assert now - t.pending.last_sent_s < t.retry_s + 0.011  # re-sent in time
    assert sent_when_forbidden == 0
    if must_not_send:
        assert not t.request(LOITER, now + 1.0) and not t.request(OFFBOARD, now + 1.0)


def test_a_switch_back_to_the_start_mode_after_a_confirmed_request_is_not_ours() -> None:
    """Measured on PX4 SIH: a battery failsafe first holds (AUTO.LOITER, system status CRITICAL) for
    COM_FAIL_ACT_T, then lands. The hold is the failsafe's, not ours, once OFFBOARD was confirmed;
    without CRITICAL, a switch back to it is the operator's."""
    t = tracker()
    t.on_heartbeat(LOITER, ACTIVE, 0.0)
    t.request(OFFBOARD, 0.1)
    assert t.on_heartbeat(LOITER, ACTIVE, 0.3) is Event.NONE  # before the confirmation: still ours
    assert t.on_heartbeat(OFFBOARD, ACTIVE, 0.7) is Event.CONFIRMED
    assert t.on_heartbeat(LOITER, MAV_STATE_CRITICAL, 9.0) is Event.FAILSAFE and t.owner is Owner.AUTOPILOT
    t2 = tracker()
    t2.on_heartbeat(LOITER, ACTIVE, 0.0)
    t2.request(OFFBOARD, 0.1)
    t2.on_heartbeat(OFFBOARD, ACTIVE, 0.7)
    assert t2.on_heartbeat(LOITER, ACTIVE, 9.0) is Event.OPERATOR
