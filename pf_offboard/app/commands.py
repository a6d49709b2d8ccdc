"""Commands to the autopilot and their confirmation: COMMAND_LONG, COMMAND_ACK, and the HEARTBEAT
that proves a mode or the armed state changed.

Two pieces, both per link:

- :class:`ModeWatch` — what the autopilot's HEARTBEAT says (mode, armed) and which modes are
  *ours* (the one the vehicle was in when we first asked, and the one we asked for last); any
  other mode is someone else's: the operator's or the autopilot's own failsafe
  (:meth:`ModeWatch.classify`).
- :class:`Commander` — sends commands and waits for them to take effect: a request is re-sent
  every 0.5 s until the HEARTBEAT (or the state) confirms it; COMMAND_ACK DENIED / UNSUPPORTED is
  a refusal at once (:class:`CommandRefusedError`), TEMPORARILY_REJECTED / FAILED are retried until
  the timeout. Once the operator has taken over, no mode is ever requested again.

What the flight does with a confirmation, a takeover or a failsafe is the flight's business
(:mod:`pf_offboard.app.flight`); this module only sends, watches and reports.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.app.modes import Event, ModeTracker
from pf_offboard.app.profiles import ModeRequest, Profile, is_armed
from pf_offboard.app.waiting import Waiter
from pf_offboard.errors import LinkError

MAV_RESULT_NAMES = {0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED", 4: "FAILED", 5: "IN_PROGRESS"}
MAV_STATE_CRITICAL = 5  # HEARTBEAT.system_status: the autopilot is in its own failsafe
RESEND_S = 0.5  # a command not confirmed yet is sent again this often
SAFE_MODE_RETRY_S = 0.25  # the safe-mode request is re-sent this often until the HEARTBEAT shows it


class CommandRefusedError(LinkError):
    """The autopilot answered a command with COMMAND_ACK DENIED / UNSUPPORTED."""

    def __init__(self, message: str, command: int, result: int | None) -> None:
        super().__init__(message)
        self.command = command
        self.result = result


class CommandTimeoutError(LinkError):
    """A command was not confirmed (by HEARTBEAT / state) within its timeout."""


@dataclass(frozen=True)
class CommandTiming:
    """How long commands are retried and how often progress is reported (wall clock)."""

    command_timeout_s: float = 5.0
    progress_every_s: float = 5.0


class ModeChange(enum.Enum):
    """What a HEARTBEAT's mode means for us (see :meth:`ModeWatch.classify`)."""

    OURS = "ours"  # not in control, or one of our modes
    FAILSAFE = "failsafe"  # another mode, and the autopilot reports its own failsafe
    OPERATOR = "operator"  # another mode: the operator (RC / ground station) took over


class EvidenceClock:
    """The clock mode evidence is judged on: monotonic seconds that advance as fast as the faster of
    the wall clock and the vehicle's own clock. On a real autopilot the two run together; a
    lockstep simulator runs ahead of the wall (it handles a request at once, and 0.5 s of wall time
    can be many seconds of its flight), so waiting on the wall alone would let the simulated flight
    run on. A jump of the vehicle's clock (a reboot, a spoofed timestamp) counts for at most
    ``max_vehicle_step_s`` per reading, never enough to confirm a request by itself."""

    def __init__(self, wall: Callable[[], float], vehicle: Callable[[], float | None], max_vehicle_step_s: float = 0.25) -> None:
        self.wall = wall
        self.vehicle = vehicle
        self.max_vehicle_step_s = max_vehicle_step_s
        self._wall_s = wall()
        self._vehicle_s = vehicle()
        self._now_s = self._wall_s

    def __call__(self) -> float:
        wall_s, vehicle_s = self.wall(), self.vehicle()
        dv = 0.0
        if vehicle_s is not None and self._vehicle_s is not None:
            dv = min(max(vehicle_s - self._vehicle_s, 0.0), self.max_vehicle_step_s)
        self._now_s += max(wall_s - self._wall_s, dv, 0.0)
        self._wall_s, self._vehicle_s = wall_s, vehicle_s if vehicle_s is not None else self._vehicle_s
        return self._now_s


class ModeWatch:
    """The autopilot's mode and armed state as its HEARTBEATs report them, and our modes.

    ``tracker`` (:class:`~pf_offboard.app.modes.ModeTracker`, pure) holds the requests: a mode we
    asked for counts as confirmed only on a HEARTBEAT received after the request was sent (and,
    while an earlier request may still land, late enough for the autopilot to have handled it);
    ``clock`` stamps requests and HEARTBEATs (monotonic seconds)."""

    def __init__(self, profile: Profile, clock: Callable[[], float] = time.monotonic) -> None:
        self.profile = profile
        self.clock = clock
        self.tracker = ModeTracker(
            same_mode=lambda a, b: a == b or (profile.is_offboard(a) and profile.is_offboard(b)),
            failsafe_modes=profile.failsafe_custom_modes,
            name=profile.mode_name,
            retry_s=SAFE_MODE_RETRY_S,
        )
        self.custom_mode: int | None = None
        self.base_mode = 0
        self.previous_mode: int | None = None  # custom_mode before the last HEARTBEAT
        self.armed_seen = False
        # Modes that are ours: the one the vehicle was in when we asked (or that we got) and the one
        # we asked for. Any other mode in a HEARTBEAT is the operator's (or a failsafe's).
        self.held_mode: int | None = None
        self.pending_mode: int | None = None

    def record(self, msg: Any) -> Event:
        """Every HEARTBEAT of the target: its mode and armed flag (and what it means for our requests)."""
        self.previous_mode = self.custom_mode
        self.custom_mode, self.base_mode = msg.custom_mode, msg.base_mode
        return self.tracker.on_heartbeat(int(msg.custom_mode), int(getattr(msg, "system_status", 0)), self.clock())

    @property
    def armed(self) -> bool:
        return is_armed(self.base_mode)

    def disarmed_under_us(self, msg: Any) -> bool:
        """True when this HEARTBEAT says disarmed after an armed one while we are in control."""
        if is_armed(msg.base_mode):
            self.armed_seen = True
            return False
        return self.armed_seen and self.in_control()

    def confirm_pending(self, custom_mode: int) -> None:
        """The mode we asked for is reported: it becomes the mode we hold."""
        if self.pending_mode is not None and self.same_mode(custom_mode, self.pending_mode):
            self.held_mode, self.pending_mode = custom_mode, None

    def classify(self, msg: Any) -> ModeChange:
        """Whose mode a HEARTBEAT shows while we may be in control: ours, the autopilot's failsafe
        (system status CRITICAL / EMERGENCY, or a return / land mode we did not ask for), or the
        operator's (any other mode we did not ask for)."""
        if not self.in_control() or self.tracker.is_ours(int(msg.custom_mode)):
            return ModeChange.OURS
        if msg.system_status >= MAV_STATE_CRITICAL or msg.custom_mode in self.profile.failsafe_custom_modes:
            return ModeChange.FAILSAFE
        return ModeChange.OPERATOR

    def in_control(self) -> bool:
        """We have asked the autopilot for a mode (it may be flying our setpoints)."""
        return self.held_mode is not None or self.pending_mode is not None

    def same_mode(self, custom_mode: int, ours: int) -> bool:
        return custom_mode == ours or (self.profile.is_offboard(custom_mode) and self.profile.is_offboard(ours))

    def mode_is_ours(self, custom_mode: int) -> bool:
        return any(m is not None and self.same_mode(custom_mode, m) for m in (self.held_mode, self.pending_mode))

    def asked(self, mode: ModeRequest) -> bool:
        """We are about to request ``mode``; False: we may not (the autopilot's failsafe or the
        operator has the vehicle): send nothing."""
        if not self.tracker.request(self.profile.custom_mode_of(mode), self.clock()):
            return False
        if self.held_mode is None:
            self.held_mode = self.custom_mode  # what the vehicle was in when we first asked
        self.pending_mode = self.profile.custom_mode_of(mode)
        return True

    def confirmed(self, mode: ModeRequest) -> bool:
        """A HEARTBEAT received after our request for ``mode`` shows it (evidence newer than the
        request; see :class:`~pf_offboard.app.modes.ModeTracker`)."""
        return self.tracker.is_confirmed(self.profile.custom_mode_of(mode))

    def shows(self, mode: ModeRequest) -> bool:
        """The last HEARTBEAT shows ``mode`` (OFFBOARD: any sub mode)."""
        if self.custom_mode is None:
            return False
        if mode is self.profile.offboard:
            return self.profile.is_offboard(self.custom_mode)
        return self.custom_mode == self.profile.custom_mode_of(mode)

    def mode_name(self) -> str:
        return self.profile.mode_name(self.custom_mode) if self.custom_mode is not None else "?"


class Commander:
    """Sends COMMAND_LONGs to the target and waits for them to take effect.

    ``yielded()``: the operator has taken over (never request a mode again); the ``waiter``'s
    ``ending()``: the flight is ending another way (stop waiting, send no new request).
    """

    def __init__(
        self,
        link: Any,
        modes: ModeWatch,
        waiter: Waiter,
        timing: CommandTiming,
        say: Callable[[str], None],
        note: Callable[[str], None],
        yielded: Callable[[], bool],
    ) -> None:
        self.link = link
        self.modes = modes
        self.profile = modes.profile
        self.waiter = waiter
        self.timing = timing
        self.say = say
        self.note = note
        self.yielded = yielded
        self.acks: dict[int, int] = {}
        self.last_statustext = ""

    def on_ack(self, msg: Any) -> None:
        """A COMMAND_ACK for us (the link drops those addressed to another system / component)."""
        self.acks[msg.command] = msg.result
        if msg.command == mavlink2.MAV_CMD_DO_SET_MODE:
            self.modes.tracker.on_ack(int(msg.result), ours=True)
        self.waiter.notify()

    def command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.acks.pop(command, None)
        t = self.link.target
        self.link.send(mavlink2.MAVLink_command_long_message(t.system, t.component, command, 0, *p))

    def set_mode_nowait(self, mode: ModeRequest) -> None:
        if self.yielded():
            return  # the operator has the vehicle: never ask for a mode again
        if not self.modes.asked(mode):
            return  # the autopilot's failsafe (or the operator) has the vehicle: never override it
        self.command(mavlink2.MAV_CMD_DO_SET_MODE, 1.0, mode.param2, mode.param3)

    def request_offboard_nowait(self) -> None:
        if not self.modes.armed:
            self.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        self.set_mode_nowait(self.profile.offboard)

    async def confirmed(
        self, what: str, send: Callable[[], None], confirmed: Callable[[], bool], command: int, timeout_s: float | None = None
    ) -> None:
        """Send, re-send every 0.5 s until ``confirmed()``. COMMAND_ACK DENIED / UNSUPPORTED is a
        refusal at once; TEMPORARILY_REJECTED / FAILED (e.g. "no position estimate yet") are
        retried until ``timeout_s`` (default ``command_timeout_s``), with a progress line every
        ``progress_every_s`` while the autopilot keeps refusing. Raises LinkError naming the last
        ACK and autopilot text."""
        timing = self.timing
        clock = self.waiter.clock
        timeout = timing.command_timeout_s if timeout_s is None else max(timeout_s, timing.command_timeout_s)
        start = clock()
        deadline = start + timeout
        next_progress = start + timing.progress_every_s
        final = (mavlink2.MAV_RESULT_DENIED, mavlink2.MAV_RESULT_UNSUPPORTED)
        while True:
            if self.waiter.ending():  # taken over / safing: never send another request
                raise LinkError(f"{what}: interrupted")
            send()
            await self.waiter.until(lambda: confirmed() or self.acks.get(command) in final, RESEND_S)
            if confirmed():
                return
            result = self.acks.get(command)
            detail = f" (COMMAND_ACK result {result}{'; autopilot: ' + self.last_statustext if self.last_statustext else ''})"
            if result in final:
                raise CommandRefusedError(f"{what} refused by the autopilot{detail}", command, result)
            if self.waiter.stop.is_set() or self.waiter.ending():
                raise LinkError(f"{what}: interrupted")
            now = clock()
            if now > deadline:
                raise CommandTimeoutError(f"{what}: not confirmed within {timeout:g} s{detail}")
            if now >= next_progress:
                next_progress = now + timing.progress_every_s
                said = f": autopilot says {self.last_statustext!r}" if self.last_statustext else ""
                self.say(f"waiting for {what}{said} ({now - start:.0f} s of up to {timeout:g} s)")

    async def set_mode(self, mode: ModeRequest, timeout_s: float | None = None) -> None:
        """Request ``mode`` until a HEARTBEAT shows it."""
        await self.confirmed(
            f"mode {mode.name}", lambda: self.set_mode_nowait(mode), lambda: self.modes.confirmed(mode), mavlink2.MAV_CMD_DO_SET_MODE, timeout_s
        )

    async def arm(self, timeout_s: float | None = None) -> None:
        """Arm; the autopilot's refusals while its checks are not ready yet are retried until
        ``timeout_s`` (default ``command_timeout_s``)."""
        await self.confirmed(
            "arming",
            lambda: self.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1.0),
            lambda: self.modes.armed,
            mavlink2.MAV_CMD_COMPONENT_ARM_DISARM,
            timeout_s,
        )

    async def request_mode_until_shown(self, mode: ModeRequest, timeout_s: float, still: Callable[[], bool]) -> bool:
        """The safe-mode request: re-sent every SAFE_MODE_RETRY_S while ``still()`` until a
        HEARTBEAT shows ``mode`` or ``timeout_s`` passes (wall clock). True when confirmed."""
        clock = self.waiter.clock
        deadline = clock() + timeout_s
        confirmed = False
        while still():
            # only a HEARTBEAT received after our request counts (never the one that was already
            # there: it may predate an OFFBOARD request still on its way)
            confirmed = self.modes.confirmed(mode)
            if confirmed or clock() > deadline or self.modes.tracker.yielded:
                break
            try:
                self.set_mode_nowait(mode)
            except LinkError:
                pass
            await self.waiter.until(lambda: not still() or self.modes.confirmed(mode), SAFE_MODE_RETRY_S, interruptible=False)
        return confirmed

    async def request_intervals(self, requests: list[tuple[int, float, str]], ack_timeout_s: float = 1.0) -> None:
        """SET_MESSAGE_INTERVAL for each (message id, rate Hz, name), one at a time so each
        COMMAND_ACK is matched to its request. A refusal is not fatal (the stream may flow at its
        default rate): it is reported as one note line (PX4 refuses HEARTBEAT: it stays at 1 Hz)."""
        for message_id, rate_hz, name in requests:
            self.request_interval(message_id, rate_hz)
            command = mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL
            await self.waiter.until(lambda: command in self.acks, ack_timeout_s)
            result = self.acks.get(command)
            if result is not None and result != mavlink2.MAV_RESULT_ACCEPTED:
                label = MAV_RESULT_NAMES.get(result, str(result))
                consequence = " (a takeover is seen within one HEARTBEAT period of its default rate)" if name == "HEARTBEAT" else ""
                self.note(f"note: the autopilot refused {name} at {rate_hz:g} Hz (SET_MESSAGE_INTERVAL: COMMAND_ACK {label}); "
                          f"it stays at its default rate{consequence}")  # fmt: skip

    def request_interval(self, message_id: int, rate_hz: float) -> None:
        """SET_MESSAGE_INTERVAL; a refusal is reported, not fatal (the stream may already flow)."""
        self.command(mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, float(message_id), 1e6 / rate_hz)
