"""One controller at a time: evidence that another controller's setpoints reach the vehicle while
we follow. Pure (no I/O; every call carries its time on one monotonic clock).

Two kinds of evidence, both from what real autopilots and routers send:

- **Relayed setpoints**: SET_POSITION_TARGET_LOCAL_NED / SET_POSITION_TARGET_GLOBAL_INT /
  SET_ATTITUDE_TARGET addressed to our autopilot but sent by another system or component, seen on
  our link (a MAVLink router, MAVProxy or an autopilot forwarding between its links delivers
  them). We never receive our own frames back.
- **The autopilot's echoed target** (POSITION_TARGET_LOCAL_NED): while following we send only
  acceleration (PX4) or attitude / rate targets, so the autopilot's echo carries no position or
  velocity target; one that does is flying someone else's position or velocity setpoint. PX4
  echoes its position controller's setpoint at 10 Hz (acceleration-only while we fly
  ``acceleration``; nothing while we fly attitude / rates, its position controller is off);
  ArduCopter sends it only in GUIDED and not in its angle sub-mode (which our attitude / rate
  targets keep it in), with the position / velocity of a position or velocity target.
  Setpoints with a position or velocity that we sent ourselves (take-off, the hold) explain such
  an echo for ``own_grace_s`` afterwards.

Never on one frame: a verdict needs ``confirm`` pieces of evidence within ``window_s``, and a
HEARTBEAT received after the first of them that still shows OFFBOARD / GUIDED (an operator's
switch to a position mode changes the echo too, but its HEARTBEAT shows the new mode: that is a
takeover, and the operator wins).
"""

from __future__ import annotations

import collections
import math
from typing import Any

SETPOINT_MESSAGES = frozenset({"SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT", "SET_ATTITUDE_TARGET"})
ECHO_MESSAGE = "POSITION_TARGET_LOCAL_NED"
# POSITION_TARGET_TYPEMASK: x, y, z, vx, vy, vz ignore bits
_POSITION_VELOCITY_BITS = (1, 2, 4, 8, 16, 32)
_FIELDS = ("x", "y", "z", "vx", "vy", "vz")
# the messages that can carry a position or velocity target: the setpoints but attitude, and the echo
_POSITION_TARGETS = (SETPOINT_MESSAGES - {"SET_ATTITUDE_TARGET"}) | {ECHO_MESSAGE}


def carries_position_or_velocity(msg: Any) -> bool:
    """A (SET_)POSITION_TARGET_* message whose position or velocity fields are in use (bit clear,
    value finite)."""
    if msg.get_type() not in _POSITION_TARGETS:
        return False
    mask = int(getattr(msg, "type_mask", 0xFFFF))
    names = ("lat_int", "lon_int", "alt", "vx", "vy", "vz") if msg.get_type() == "SET_POSITION_TARGET_GLOBAL_INT" else _FIELDS
    for bit, name in zip(_POSITION_VELOCITY_BITS, names, strict=True):
        value = getattr(msg, name, math.nan)
        if not mask & bit and value is not None and math.isfinite(float(value)):
            return True
    return False


class ControllerWatch:
    """Feed it what we send, what the link relays and what the autopilot echoes; :meth:`verdict`
    says (once) why another controller is flying the vehicle ("" while not)."""

    def __init__(self, confirm: int = 3, window_s: float = 5.0, own_grace_s: float = 1.0) -> None:
        self.confirm = confirm
        self.window_s = window_s
        self.own_grace_s = own_grace_s
        self._evidence: collections.deque[tuple[float, str]] = collections.deque()
        self._own_pv_s = -math.inf  # when we last sent a position / velocity setpoint
        self._offboard_hb_s = -math.inf  # the latest HEARTBEAT showing OFFBOARD / GUIDED
        self.relayed = 0  # counts, for the summary
        self.echoes = 0

    def sent(self, msg: Any, now_s: float) -> None:
        if carries_position_or_velocity(msg):
            self._own_pv_s = now_s

    def autopilot_target(self, now_s: float) -> None:
        """The autopilot's own position target until now (ArduCopter's take-off sub-mode until our
        first attitude target lands: its echo can still arrive as following begins)."""
        self._own_pv_s = max(self._own_pv_s, now_s)

    def relayed_setpoint(self, msg: Any, now_s: float) -> None:
        self.relayed += 1
        self._add(now_s, f"{msg.get_type()} from system {msg.get_srcSystem()} component {msg.get_srcComponent()}")

    def echoed_target(self, msg: Any, now_s: float) -> None:
        if not carries_position_or_velocity(msg) or now_s - self._own_pv_s <= self.own_grace_s:
            return
        self.echoes += 1
        self._add(now_s, "the autopilot's target (POSITION_TARGET_LOCAL_NED) has a position / velocity we did not send")

    def heartbeat(self, offboard: bool, now_s: float) -> None:
        if offboard:
            self._offboard_hb_s = now_s

    def _add(self, now_s: float, what: str) -> None:
        self._evidence.append((now_s, what))

    def verdict(self, now_s: float) -> str:
        ev = self._evidence
        while ev and now_s - ev[0][0] > self.window_s:
            ev.popleft()
        if len(ev) < self.confirm or self._offboard_hb_s <= ev[0][0]:
            return ""
        span = ev[-1][0] - ev[0][0]
        return (f"another controller is flying the vehicle: {len(ev)} setpoints not ours in {span:.2f} s "
                f"({ev[-1][1]}) while it stays in offboard control")  # fmt: skip


__all__ = ["ECHO_MESSAGE", "SETPOINT_MESSAGES", "ControllerWatch", "carries_position_or_velocity"]
