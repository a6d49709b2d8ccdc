"""Mode requests as state: what the app asked for, what the autopilot showed, who owns the vehicle.

Pure (no I/O, no clocks: every call carries the time it happened, on one monotonic clock). The
bridge sends; this module decides.

Rules:

- A request is *pending* from the moment it is sent until a HEARTBEAT **received at least
  ``settle_s`` after it was first sent** shows the mode (evidence older than the request never
  counts: a HEARTBEAT still showing the old hold while an OFFBOARD request is in flight is not a
  confirmed hold; ``settle_s``, 0.5 s, exceeds the link's round trip, so the HEARTBEAT was also
  *emitted* after the autopilot handled the request). A pending request is due to be re-sent
  every ``retry_s`` until confirmed.
- A request for another mode while one is pending leaves the earlier one *unresolved* (it may still
  land: the autopilot handles commands in order, so by ``settle_s`` after the newer request it has
  handled the earlier one too); a HEARTBEAT showing an unresolved mode meanwhile (our earlier
  request landing) is ours, not a takeover, and the newer request stays pending and re-sent.
  Modes we asked for are never someone else's.
- The autopilot's failsafe wins: a HEARTBEAT with system_status CRITICAL / EMERGENCY in a mode we
  did not ask for, or any failsafe mode (LAND, RTL ...) we did not ask for, makes the tracker
  *yield*: no mode is ever requested again. So does an operator's mode (any other mode we did not
  ask for, once we have asked for one).
- COMMAND_ACKs count only when they answer us (command and target matched by the caller,
  ``ours``); DENIED / UNSUPPORTED to our pending request marks it refused. Others are ignored.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Collection
from dataclasses import dataclass, replace

MAV_STATE_CRITICAL = 5
MAV_STATE_EMERGENCY = 6
MAV_RESULT_DENIED = 2
MAV_RESULT_UNSUPPORTED = 3


class Owner(enum.Enum):
    """Who decides the vehicle's mode, as far as the app knows."""

    NOBODY = "nobody"  # we have not asked for a mode
    US = "us"  # we asked; the modes shown are ours
    OPERATOR = "operator"  # someone switched to a mode we did not ask for: we yielded
    AUTOPILOT = "autopilot"  # the autopilot's own failsafe took over: we yielded


class Event(enum.Enum):
    NONE = "none"
    CONFIRMED = "confirmed"  # the pending request is confirmed by a newer HEARTBEAT
    OPERATOR = "operator"
    FAILSAFE = "failsafe"
    REFUSED = "refused"  # our pending request was refused (DENIED / UNSUPPORTED)


@dataclass(frozen=True)
class Request:
    mode: int
    first_sent_s: float
    last_sent_s: float
    sends: int = 1


@dataclass(frozen=True)
class Seen:
    """The latest HEARTBEAT: mode, status, when it was received."""

    mode: int
    system_status: int
    received_s: float


class ModeTracker:
    """The mode/command state machine (see the module docstring).

    ``same_mode(a, b)``: whether two custom modes are the same for us (e.g. any OFFBOARD sub-mode);
    ``failsafe_modes``: custom modes only the autopilot's failsafe (or an operator) chooses when we
    did not ask for them (LAND, RTL); ``name(mode)``: for messages.
    """

    def __init__(
        self,
        same_mode: Callable[[int, int], bool] | None = None,
        failsafe_modes: Collection[int] = (),
        name: Callable[[int], str] = str,
        retry_s: float = 0.25,
        settle_s: float = 0.5,
    ) -> None:
        self._same = same_mode if same_mode is not None else (lambda a, b: a == b)
        self.failsafe_modes = frozenset(failsafe_modes)
        self.name = name
        self.retry_s = retry_s
        self.settle_s = settle_s
        self.pending: Request | None = None
        self.confirmed: Request | None = None
        self.unresolved: dict[int, float] = {}  # earlier requests of ours that may still land: mode -> last sent
        self.start_mode: int | None = None  # the mode the vehicle was in when we first asked
        self.asked: set[int] = set()  # every mode we asked for (a HEARTBEAT still showing one is ours)
        self.last: Seen | None = None
        self.owner = Owner.NOBODY
        self.reason = ""  # why we yielded / what was refused
        self.refused = False

    # ------------------------------------------------------------------ queries
    @property
    def yielded(self) -> bool:
        return self.owner in (Owner.OPERATOR, Owner.AUTOPILOT)

    def may_request(self) -> str:
        """"" when a mode request may be sent now; otherwise why not."""
        if self.yielded:
            return self.reason
        last = self.last
        if last is not None and self._failsafe(last):
            return f"the autopilot's failsafe has the vehicle ({self.name(last.mode)}, system status {last.system_status})"
        return ""

    def is_ours(self, mode: int) -> bool:
        """A mode we asked for (pending, confirmed, unresolved), or the one we started from until a
        request of ours has been confirmed (afterwards a switch back to it is someone else's: the
        operator's, or the autopilot's failsafe hold)."""
        start = self.start_mode if self.confirmed is None else None
        modes = [start, *self.unresolved, *self.asked]
        if self.pending is not None:
            modes.append(self.pending.mode)
        if self.confirmed is not None:
            modes.append(self.confirmed.mode)
        return any(m is not None and self._same(mode, m) for m in modes)

    def is_confirmed(self, mode: int) -> bool:
        return self.pending is None and self.confirmed is not None and self._same(self.confirmed.mode, mode)

    def due(self, now_s: float) -> bool:
        """The pending request should be (re-)sent now."""
        p = self.pending
        return p is not None and not self.yielded and now_s - p.last_sent_s >= self.retry_s

    # ------------------------------------------------------------------ inputs
    def request(self, mode: int, now_s: float) -> bool:
        """Record that a request for ``mode`` is being sent now; False (send nothing) if we may not."""
        if self.may_request():
            return False
        if self.owner is Owner.NOBODY:
            self.owner = Owner.US
            self.start_mode = self.last.mode if self.last is not None else None
        self.asked.add(mode)
        p = self.pending
        if p is not None and self._same(p.mode, mode):
            self.pending = replace(p, last_sent_s=now_s, sends=p.sends + 1)
            return True
        if p is not None:
            self.unresolved[p.mode] = p.last_sent_s  # it may still land
        if self.confirmed is not None and not self._same(self.confirmed.mode, mode):
            self.confirmed = None
        self.pending = Request(mode, now_s, now_s)
        self.refused = False
        return True

    def on_ack(self, result: int, ours: bool) -> Event:
        """A COMMAND_ACK to DO_SET_MODE; ``ours``: its target is us (foreign ones change nothing)."""
        if not ours or self.pending is None:
            return Event.NONE
        if result in (MAV_RESULT_DENIED, MAV_RESULT_UNSUPPORTED):
            self.refused = True
            self.reason = f"{self.name(self.pending.mode)} refused (COMMAND_ACK {result})"
            return Event.REFUSED
        return Event.NONE

    def on_heartbeat(self, mode: int, system_status: int, now_s: float) -> Event:
        """A HEARTBEAT from the autopilot, received at ``now_s``."""
        self.last = seen = Seen(mode, system_status, now_s)
        if self.yielded or self.owner is Owner.NOBODY:
            return Event.NONE
        if self._failsafe(seen):
            self._yield(Owner.AUTOPILOT, f"autopilot failsafe: {self.name(mode)} (system status {system_status})")
            return Event.FAILSAFE
        if not self.is_ours(mode):
            self._yield(Owner.OPERATOR, f"mode changed to {self.name(mode)} by someone else")
            return Event.OPERATOR
        p = self.pending
        if p is not None and self._same(mode, p.mode):
            if now_s > p.first_sent_s and now_s >= p.first_sent_s + self.settle_s:
                # newer than the request (and, with earlier requests in flight, late enough that the
                # autopilot, handling commands in order, has handled them too): confirmed
                self.confirmed, self.pending = p, None
                self.unresolved.clear()
                return Event.CONFIRMED
        return Event.NONE

    # ------------------------------------------------------------------ internals

    def _failsafe(self, seen: Seen) -> bool:
        asked = self.pending is not None and self._same(seen.mode, self.pending.mode)
        asked = asked or (self.confirmed is not None and self._same(seen.mode, self.confirmed.mode))
        asked = asked or any(self._same(seen.mode, m) for m in (*self.unresolved, *self.asked))
        if asked:
            return False
        if seen.system_status in (MAV_STATE_CRITICAL, MAV_STATE_EMERGENCY) and not (
            self.confirmed is None and self.start_mode is not None and self._same(seen.mode, self.start_mode)
        ):
            return True  # e.g. PX4's failsafe hold (AUTO.LOITER, CRITICAL) before its LAND / Return
        return any(self._same(seen.mode, m) for m in self.failsafe_modes)

    def _yield(self, owner: Owner, reason: str) -> None:
        self.owner = owner
        self.reason = reason
        self.pending = None
