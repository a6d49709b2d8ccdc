"""One flight, top to bottom: launch → follow → hand back (or safing / taken over).

:class:`Flight` runs the phase sequence (:mod:`.phases`) over an open link whose target is
known, and wires the rooms that each own one responsibility:

- :mod:`.commands` — COMMAND_LONG / COMMAND_ACK, mode and arming confirmed by HEARTBEAT;
- :mod:`.dialects` — what differs between PX4 and ArduPilot (take-off sequence, parameters);
- :mod:`.supervisor` — the envelope and the watchdogs (verdicts; this module acts on them);
- :mod:`.status` — the status line and messages;
- :mod:`.pipeline` (pure) — estimator → core → encoder, one step per fresh state sample;
- :mod:`.rules` (pure) — throw trigger, laps, take-off settled, when following ends.

Setpoints are computed on each fresh state sample (the link reader's callback); the periodic
tasks (:meth:`keepalive`, :meth:`heartbeat`, :meth:`status_line`) run beside :meth:`fly` in one
TaskGroup.
"""

from __future__ import annotations

import asyncio
import math
import sys
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, TextIO

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.app.commands import Commander, CommandRefusedError, CommandTiming, EvidenceClock, ModeChange, ModeWatch
from pf_offboard.app.dialects import Dialect, dialect_for
from pf_offboard.app.encoders import position_setpoint, yaw_of
from pf_offboard.app.controllers import ECHO_MESSAGE, SETPOINT_MESSAGES, ControllerWatch
from pf_offboard.app.estimator import StateEstimate, flight_clock_s
from pf_offboard.app.hover import HoverThrustMeter
from pf_offboard.app.params import Parameters
from pf_offboard.app.phases import (
    EXIT_BREACH,
    EXIT_CONTROLLER,
    EXIT_CRASH,
    EXIT_FAILSAFE,
    EXIT_INTERRUPTED,
    EXIT_LINK,
    EXIT_OK,
    EXIT_TAKEOVER,
    INTERRUPTING,
    TERMINAL,
    FlightResult,
    Phase,
)
from pf_offboard.app.pipeline import Pipeline, Step, time_boot_ms
from pf_offboard.app.profiles import ModeRequest, Profile
from pf_offboard.app.rules import EndSpec, LapCounter, TakeoffSettle, ThrowTrigger, end_reason
from pf_offboard.app.status import StatusDisplay, status_text
from pf_offboard.app.supervisor import SafetySupervisor
from pf_offboard.app.waiting import Waiter
from pf_offboard.errors import LinkError
from pf_offboard.safety import Breach, EnvelopeMonitor, Verdict

KEEPALIVE_S = 0.1  # re-send the last setpoint when nothing went out for this long
# attitude / rates on PX4: wait up to this long (wall clock) in hold for a steady window of its
# attitude target's thrust before activation (app/hover.py; PX4 streams it at 2-10 Hz)
HOVER_WAIT_S = 3.0


@dataclass(frozen=True)
class FlightOptions:
    """How one flight is launched, flown and ended."""

    launch: str  # "takeoff" | "airborne" | "throw"
    height_m: float  # take-off altitude or throw activation height (m above home)
    end: EndSpec
    end_action: str = "hold"  # "hold" | "land"
    setpoint_rate_hz: float = 50.0
    state_timeout_s: float = 0.5
    command_timeout_s: float = 5.0  # per mode / arm / param request (wall clock)
    status: bool = True
    # --takeoff / --airborne: how long to wait for the position estimate, an attitude sample and
    # the arming checks (wall clock; ArduPilot needs ~42 s after boot)
    ready_timeout_s: float = 120.0
    takeoff_timeout_s: float | None = None  # None: 30 s + 5 s per metre of take-off height
    progress_every_s: float = 5.0  # while waiting for readiness: one progress line this often (wall clock)
    follow: bool = True  # False: take off only, then hand back (the launch must be "takeoff")
    # the vehicle is in OFFBOARD / GUIDED because this connection's previous flight left it there
    # (ArduPilot holds in GUIDED after a take-off): an airborne launch engages at once, not refused
    offboard_ours: bool = False
    # attitude / rates output, no hover thrust in the config, and an autopilot whose parameter is
    # not what it flies (Profile.hover_thrust_measured): before activation, the encoder's hover
    # thrust is replaced by the one measured from the autopilot's attitude target while it holds
    measure_hover_thrust: bool = False


class Flight:
    """Runs one flight over an open link (target known). Use ``await flight.fly()``."""

    def __init__(
        self,
        link: Any,
        profile: Profile,
        pipeline: Pipeline,
        options: FlightOptions,
        path_length_m: float,
        path_closed: bool,
        lam_max: float,
        on_step: Callable[[Step], None] | None = None,
        status_stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
        monitor: EnvelopeMonitor | None = None,
        dialect: Dialect | None = None,
        heartbeat: Any = None,
    ) -> None:
        """``heartbeat``: the autopilot's latest HEARTBEAT (default: the link's first)."""
        self.link = link
        self.profile = profile
        self.dialect = dialect if dialect is not None else dialect_for(profile)
        self.pipeline = pipeline
        self.options = options
        self.path_closed = path_closed
        self.lam_max = lam_max
        self.on_step = on_step
        self.clock = clock
        self.phase = Phase.PREFLIGHT
        self.status_hook: Callable[[str, Any], str] | None = None
        self.left_in_offboard = False  # ended holding in OFFBOARD / GUIDED by our request (see FlightOptions.offboard_ours)
        self.display = StatusDisplay(status_stream if status_stream is not None else sys.stderr, options.status, clock)
        self.waiter = Waiter(clock, lambda: self.phase in INTERRUPTING)
        def vehicle_time_s() -> float | None:
            est = self.pipeline.estimator.latest
            return flight_clock_s(est) if est is not None else None

        self.modes = ModeWatch(profile, EvidenceClock(clock, vehicle_time_s))
        self.commander = Commander(
            link, self.modes, self.waiter, CommandTiming(options.command_timeout_s, options.progress_every_s),
            self.display.say, self.display.note, lambda: self.phase is Phase.TAKEN_OVER,
        )  # fmt: skip
        self.params = Parameters(link, self.waiter, profile.params_bytewise, options.command_timeout_s)
        self.supervisor = SafetySupervisor(monitor, pipeline.encoder.output_mode)
        self.controllers = ControllerWatch()  # one controller at a time (another's setpoints while we fly)
        speed_ref = pipeline.speed_ref_m_s
        self.laps = LapCounter(path_length_m, path_closed, speed_ref if math.isfinite(speed_ref) and speed_ref != 0.0 else None)
        self.throw = ThrowTrigger(options.height_m) if options.launch == "throw" else None
        self.offboard_seen = False  # OFFBOARD/GUIDED confirmed by HEARTBEAT while following
        self.activation_time_s: float | None = None
        self._activation_clock_s: float | None = None  # the same instant on the estimator's continuous clock
        self.result: FlightResult | None = None
        self.error: LinkError | None = None  # what ended the flight, when a LinkError did
        self.last_step: Step | None = None
        self.steps = 0
        self._last_setpoint: Any = None
        self._last_send_wall = -math.inf
        self._last_fresh_wall = -math.inf
        self._takeoff_target: np.ndarray | None = None
        self._takeoff_yaw = 0.0
        self._settle: TakeoffSettle | None = None
        self._end_reason = ""
        self.sent_setpoints = 0
        self._event = ""  # logged with the next step
        self._last_heartbeat_wall = clock()
        self._last_attitude_wall = -math.inf
        self._safing: tuple[int, str, ModeRequest] | None = None
        self._safe_msg: Any = None
        # before activation, stream the follower's own (inactive) setpoints as proof of life
        self._stream_follow_before_active = False
        # the autopilot's hover thrust from its attitude targets before activation (None: not measured)
        self._hover_meter = HoverThrustMeter() if options.measure_hover_thrust else None
        self._hover_event = ""  # logged with the activation: the hover thrust measured
        heartbeat = heartbeat if heartbeat is not None else link.first_heartbeat
        if heartbeat is not None:  # mode and armed state known from the start
            self._on_heartbeat(heartbeat)

    # ------------------------------------------------------------------ what the others read
    @property
    def monitor(self) -> EnvelopeMonitor | None:
        return self.supervisor.monitor

    @property
    def breach(self) -> Verdict | None:
        return self.supervisor.breach

    @property
    def breach_time_s(self) -> float | None:
        return self.supervisor.breach_time_s

    @property
    def loop_rate_hz(self) -> float:
        return self.display.loop_rate_hz

    @property
    def last_statustext(self) -> str:
        return self.commander.last_statustext

    # ------------------------------------------------------------------ the flight
    async def fly(self, setup: Callable[[], Awaitable[None]] | None = None) -> FlightResult:
        """``setup`` (streams, parameters), launch, follow, hand back. Returns how it ended
        (LinkError becomes exit 3; InputError from ``setup`` propagates). Whatever ends the flight
        while we may be in control goes through :meth:`_safe_mode` (safe setpoint, safe mode
        requested until confirmed), except an operator takeover (nothing more is sent)."""
        try:
            if setup is not None:
                await setup()
            await self._launch()
            await self.waiter.until(lambda: self.phase not in (Phase.FOLLOWING, Phase.ENGAGING, Phase.WAITING), math.inf)
            if self.phase is Phase.HANDING_BACK:
                await self._hand_back()
        except LinkError as exc:
            self.error = self.error or exc
            if self.phase in INTERRUPTING or self.result is not None:
                pass  # safing, taken over or ended: handled below / already decided
            elif self.waiter.stop.is_set():
                # Ctrl-C / SIGTERM before following had begun
                why = f"{self._end_reason or 'interrupted'} before following began"
                if self.modes.in_control():
                    self._enter_safing(EXIT_INTERRUPTED, why, self._end_mode())
                else:
                    self._finish(EXIT_INTERRUPTED, f"{why}; nothing was commanded")
            else:
                self.display.say(f"error: {exc}")
                if self.modes.in_control():
                    self._enter_safing(EXIT_LINK, str(exc))
                else:
                    self._finish(EXIT_LINK, str(exc))
        if self.phase is Phase.SAFING and self.result is None:
            await self._safe_mode()
        if self.result is None:
            self._finish(EXIT_LINK, "ended unexpectedly")
        assert self.result is not None
        if self.result.breach is None and self.breach is not None:
            self.result.breach, self.result.breach_time_s = self.breach, self.breach_time_s
        return self.result

    def request_stop(self, reason: str = "stop requested (Ctrl-C)") -> None:
        """End following and hand back (SIGINT handler)."""
        if self.phase in (Phase.FOLLOWING, Phase.ENGAGING, Phase.WAITING, Phase.TAKEOFF, Phase.PREFLIGHT):
            self._end_reason = reason
            self.phase = Phase.HANDING_BACK
        elif self.phase is Phase.SAFING:
            return  # already stopping: the safe-mode request goes on
        self.waiter.stop.set()
        self.waiter.notify()

    def _end_mode(self) -> ModeRequest:
        return self.profile.land if self.options.end_action == "land" else self.profile.hold

    def _refuse_foreign_offboard(self) -> None:
        """Already in OFFBOARD / GUIDED, and not by our request: another controller (a second
        pf-offboard, a GCS script) may be flying it. Two controllers fight (13.5 s seen, undetected):
        refuse, sending nothing."""
        self.phase = Phase.TAKEN_OVER
        self._last_setpoint = None
        self._finish(EXIT_TAKEOVER, f"the vehicle is already in {self.profile.offboard.name}, which we did not start: another "
                                    f"controller may be flying it; nothing sent (switch it to {self.profile.hold.name} first)")  # fmt: skip

    async def _launch(self) -> None:
        opts = self.options
        if opts.launch == "airborne" and self.modes.custom_mode is not None and not self._neutral_allowed() and not opts.offboard_ours:
            self._refuse_foreign_offboard()  # before waiting for anything: nothing of ours may fly
            return
        ready_deadline = self.clock() + opts.ready_timeout_s
        # the take-off heading comes from the attitude: wait for an attitude sample too
        est = await self._first_state(ready_deadline, need_attitude=opts.launch == "takeoff")
        if opts.launch == "takeoff":
            await self._takeoff(est, ready_deadline)
            if not opts.follow:
                self._end_reason = f"take-off to {opts.height_m:g} m held"
                if self.dialect.holds_in_offboard_after_takeoff:
                    self._last_setpoint = None
                    self.left_in_offboard = True
                    self._finish(EXIT_OK, f"{self._end_reason}; holding in {self.profile.offboard.name}")
                    return
                self.phase = Phase.HANDING_BACK
                return
            await self._measure_hover_thrust(HOVER_WAIT_S)
            self._stream_follow_before_active = True
            self._activate()
            return
        self._stream_follow_before_active = True
        if opts.launch == "airborne":
            if not self.modes.armed:
                raise CommandRefusedError("--airborne: the vehicle is not armed (is it flying?)", mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, None)
            if not self._neutral_allowed():
                if not opts.offboard_ours:
                    self._refuse_foreign_offboard()
                    return
                # left in OFFBOARD / GUIDED by our own previous flight: whatever we send flies at once
                await self._measure_hover_thrust(0.0)  # what we send flies at once: no waiting
                self._engage(f"activated (airborne, already in {self.profile.offboard.name})")
            else:
                # stream the follower's setpoints (proof of life), then switch
                self.phase = Phase.WAITING
                await self._proof_of_life()
                await self._measure_hover_thrust(HOVER_WAIT_S)
                self._engage("activated (airborne)")
            await self.commander.set_mode(self.profile.offboard)
            if self.phase is Phase.ENGAGING:
                self._activate()
            return
        # throw: stream the follower's setpoints while waiting; _on_state fires the trigger
        self.phase = Phase.WAITING
        self.display.say(f"waiting for a throw through {opts.height_m:g} m (Ctrl-C to abort)")
        armed_seen = self.modes.armed

        def waiting() -> bool:
            nonlocal armed_seen
            armed_seen = armed_seen or self.modes.armed
            return self.phase is Phase.WAITING and not (armed_seen and not self.modes.armed)

        await self.waiter.until(lambda: not waiting(), math.inf)
        if self.phase is Phase.WAITING:
            raise LinkError("the vehicle disarmed (landed or crashed) before crossing the activation height")
        if self.phase is Phase.ENGAGING:
            await self.commander.confirmed(
                f"mode {self.profile.offboard.name}",
                self.commander.request_offboard_nowait,
                lambda: self.phase is Phase.FOLLOWING,
                mavlink2.MAV_CMD_DO_SET_MODE,
            )

    async def _first_state(self, deadline: float | None = None, need_attitude: bool = False) -> StateEstimate:
        """The first state sample (with an attitude if ``need_attitude``), waiting until
        ``deadline`` (wall clock; default ``max(3, command_timeout_s)`` from now) with a progress
        line every ``progress_every_s``: an autopilot sends LOCAL_POSITION_NED only once its
        position estimate is ready (ArduPilot: ~42 s after boot)."""
        if deadline is None:
            deadline = self.clock() + max(3.0, self.options.command_timeout_s)
        start = self.clock()

        def ready() -> bool:
            est = self.pipeline.estimator.latest
            return est is not None and (est.q_enu_flu is not None or not need_attitude)

        while not ready():
            step_end = min(deadline, self.clock() + self.options.progress_every_s)
            if await self.waiter.until(ready, max(0.0, step_end - self.clock())):
                break
            if self.waiter.stop.is_set():
                raise LinkError("interrupted while waiting for the position estimate")
            now = self.clock()
            if now >= deadline:
                what = "no LOCAL_POSITION_NED / ODOMETRY" if self.pipeline.estimator.latest is None else "no ATTITUDE_QUATERNION"
                said = f"; autopilot: {self.last_statustext}" if self.last_statustext else ""
                raise LinkError(f"{what} from the vehicle within {now - start:.0f} s (is its position estimate ready? "
                                f"--ready-timeout S waits longer){said}")  # fmt: skip
            got = "position, waiting for attitude" if self.pipeline.estimator.latest is not None else "no position yet"
            self.display.say(f"waiting for the vehicle's position estimate: {got} ({now - start:.0f} s of up to {deadline - start:.0f} s)")
        est = self.pipeline.estimator.latest
        assert est is not None
        return est

    async def _proof_of_life(self) -> None:
        """PX4 accepts OFFBOARD only after a recent setpoint stream; wait for a few to go out."""
        start = self.sent_setpoints
        need = max(5, int(0.2 * self.options.setpoint_rate_hz))
        ok = await self.waiter.until(lambda: self.sent_setpoints - start >= need, self.options.command_timeout_s)
        if not ok:
            raise LinkError("setpoint stream did not start (no fresh state samples)")

    async def _takeoff(self, est: StateEstimate, ready_deadline: float) -> None:
        opts = self.options
        # the heading of a sample that carries an attitude (see _first_state): never a default yaw
        self._takeoff_yaw = yaw_of(est.q_enu_flu) if est.q_enu_flu is not None else 0.0
        await self.dialect.take_off(_TakeoffOps(self, est, ready_deadline), opts.height_m)
        self.display.say(f"taking off to {opts.height_m:g} m")

        settle = self._settle = TakeoffSettle(opts.height_m)  # fed every state sample by _on_state

        def settled() -> bool:
            return settle.settled

        timeout = opts.takeoff_timeout_s if opts.takeoff_timeout_s is not None else 30.0 + 5.0 * opts.height_m
        if not await self.waiter.until(lambda: settled() or self.waiter.stop.is_set(), timeout):
            e = self.pipeline.estimator.latest
            where = f" (at {e.position_enu_m[2]:.2f} m, {float(np.linalg.norm(e.velocity_enu_m_s)):.2f} m/s)" if e is not None else ""
            raise LinkError(f"take-off to {opts.height_m:g} m not held (within {settle.altitude_tol_m:g} m, below "
                            f"{settle.speed_tol_m_s:g} m/s over {settle.window_s:g} s) within {timeout:g} s{where}; "
                            "--takeoff-timeout S waits longer")  # fmt: skip
        if self.waiter.stop.is_set():
            raise LinkError("interrupted during take-off")
        self._takeoff_target = None
        self._settle = None

    async def _hand_back(self) -> None:
        """Stream the hold setpoint while asking for the hand-back mode, re-sent until the
        HEARTBEAT confirms it; then stop. (Not confirmed in time: safing retries it.)"""
        mode = self._end_mode()
        self.display.say(f"{self._end_reason}; handing back in {mode.name}")
        self.waiter.stop.clear()
        await self.commander.set_mode(mode)
        self.phase = Phase.DONE
        self._last_setpoint = None
        self._finish(EXIT_OK, f"{self._end_reason}; handed back in {mode.name}")

    def _finish(self, code: int, reason: str) -> None:
        if self.result is None:
            self.result = FlightResult(code, reason, self.activation_time_s, self.laps.laps, self.steps)
        if self.phase is not Phase.TAKEN_OVER:
            self.phase = Phase.DONE if code == EXIT_OK else Phase.FAILED
        self.waiter.notify()

    # ------------------------------------------------------------------ receive path (event loop callback)
    def on_message(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            target = self.link.target
            if target is None or msg.get_srcComponent() == target.component:
                self._on_heartbeat(msg)
            return
        if kind == "EXTENDED_SYS_STATE":
            self.supervisor.on_extended_sys_state(msg)
            return
        if kind == "COMMAND_ACK":
            self.commander.on_ack(msg)
            return
        if kind == "PARAM_VALUE":
            self.params.on_param_value(msg)
            return
        if kind in SETPOINT_MESSAGES:  # (the link hands on only another controller's, relayed to us)
            self.controllers.relayed_setpoint(msg, self.clock())
            self._check_controllers()
            return
        if kind == ECHO_MESSAGE:
            if self.phase is Phase.FOLLOWING:
                self.controllers.echoed_target(msg, self.clock())
                self._check_controllers()
            return
        if kind == "ATTITUDE_TARGET" and self._hover_meter is not None:
            est = self.pipeline.estimator.latest
            speed = float(np.linalg.norm(est.velocity_enu_m_s)) if est is not None else None
            self._hover_meter.add(msg.time_boot_ms / 1000.0, float(msg.thrust), speed)
        if kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            self.commander.last_statustext = text.rstrip("\x00")
            self.display.say(f"autopilot: {self.commander.last_statustext}")
            return
        estimator = self.pipeline.estimator
        attitudes = estimator.attitude_samples
        fresh = self.pipeline.on_message(msg)
        if estimator.attitude_samples != attitudes:
            # rates mode flies only on a fresh attitude: one the estimator accepted (a reordered,
            # duplicated or future-dated sample that arrives is not a fresh attitude)
            self._last_attitude_wall = self.clock()
        if fresh:
            self._last_fresh_wall = self.clock()
            self.display.count_sample()
            self._on_state()

    def _on_heartbeat(self, msg: Any) -> None:
        modes = self.modes
        modes.record(msg)
        self._last_heartbeat_wall = self.clock()
        self.waiter.notify()
        phase = self.phase
        if phase in TERMINAL:
            return
        if modes.disarmed_under_us(msg) and phase is not Phase.WAITING:
            # disarmed under our commands: crashed, killed or the autopilot's own failsafe
            self._crash(Verdict(Breach.DISARMED, "the vehicle disarmed in flight (crash, kill switch or autopilot failsafe)"))
            return
        modes.confirm_pending(msg.custom_mode)
        offboard = self.profile.is_offboard(msg.custom_mode)
        if phase is Phase.ENGAGING and offboard:
            self._activate()
            return
        if phase is Phase.FOLLOWING and offboard:
            self.offboard_seen = True
        change = modes.classify(msg)
        if change is ModeChange.OURS:
            self.controllers.heartbeat(offboard, self.clock())
            self._check_controllers()
            return
        old = self.profile.mode_name(modes.previous_mode) if modes.previous_mode is not None else "?"
        new = self.profile.mode_name(msg.custom_mode)
        if change is ModeChange.FAILSAFE:
            # The autopilot's own failsafe (a critical battery's LAND, a return, any mode with system
            # status CRITICAL / EMERGENCY) wins, like the operator: we stop commanding at once and
            # never ask for a mode over it (a hold requested over a battery LAND kept the vehicle up).
            self._last_setpoint = None
            self._safe_msg = None
            self.phase = Phase.FAILED
            self._finish(EXIT_FAILSAFE, f"the autopilot's failsafe took over during {phase.value}: mode {old} -> {new} "
                                        f"(system status {msg.system_status}); stopped commanding, not overriding it")  # fmt: skip
            return
        # The operator (RC / ground station) took over: yield at once, never re-engage, in any phase.
        self.phase = Phase.TAKEN_OVER
        self._last_setpoint = None
        self._safe_msg = None
        self._finish(EXIT_TAKEOVER, f"mode changed {old} -> {new} by someone else during {phase.value}; stopped sending, not re-engaging")

    def _on_state(self) -> None:
        est = self.pipeline.estimator.latest
        assert est is not None
        phase = self.phase
        if phase in TERMINAL:
            return
        if phase is Phase.SAFING:
            # the safe setpoint is stateless and streamed by the keep-alive; the controller is out
            self.pipeline.mark_consumed()
            return
        if phase is Phase.TAKEOFF and self.modes.armed_seen:
            verdict = self.supervisor.check_takeoff_state(est, self.modes.armed)  # tilt, disarm
            if verdict.breach:
                self._breach(verdict, est)
                return
        if phase is Phase.FOLLOWING:
            step = self.pipeline.step("following", True, self._pending_event())
            if step is not None:
                self._follow_step(step)
            return
        if phase is Phase.HANDING_BACK:
            self.pipeline.mark_consumed()
            if not self.options.follow and not self.dialect.takeoff_streams_setpoints:
                return  # a take-off only (ArduPilot: GUIDED holds by itself): nothing but the mode request
            # keep the stream (and a lockstep clock) going with the hold until the mode changes
            self._send(self.pipeline.encoder.hold(est, time_boot_ms(est)).message)
            return
        if phase is Phase.TAKEOFF and self._settle is not None:
            if self._settle.update(est.time_s, float(est.position_enu_m[2]), float(np.linalg.norm(est.velocity_enu_m_s))):
                self.waiter.notify()
        if phase is Phase.TAKEOFF and self._takeoff_target is not None:
            self.pipeline.mark_consumed()
            if self._takeoff_target[2] > est.position_enu_m[2] + 0.05:
                verdict = self.supervisor.check_climb(self._takeoff_target)
                if verdict.breach:
                    self._breach(verdict, est)
                    return
            self._send(position_setpoint(self.link.target.system, self.link.target.component, time_boot_ms(est), self._takeoff_target, self._takeoff_yaw))
            return
        if phase in (Phase.WAITING, Phase.ENGAGING) and self._stream_follow_before_active:
            # proof of life: the follower's own command, so the first active setpoint continues it
            # from the throw trigger / mode request on these setpoints take effect: mark them active
            step = self.pipeline.step(phase.value, phase is Phase.ENGAGING, self._pending_event())
            if step is None:
                return
            if phase is Phase.ENGAGING:  # these setpoints fly as soon as the mode switches: check them
                verdict = self.supervisor.check_step(step, self.modes.armed, following=False)
                if verdict.breach:
                    self._breach(verdict, step.estimate)
                    return
            self.last_step = step
            if self.on_step is not None:
                self.on_step(step)
            self._send(self._outgoing(step) if phase is Phase.ENGAGING else step.setpoint)
            if self.throw is not None and phase is Phase.WAITING:
                altitude = float(est.position_enu_m[2])
                if self.throw.update(altitude, float(np.linalg.norm(est.velocity_enu_m_s))):
                    self._engage(f"throw activation at {altitude:.2f} m")
                    self.commander.request_offboard_nowait()
            return
        self.pipeline.mark_consumed()

    def _pending_event(self) -> str:
        ev, self._event = self._event, ""
        return ev

    def _outgoing(self, step: Step) -> Any:
        """What actually leaves for an active step: in rates mode, the level hold (quaternion +
        thrust) when the attitude is not fresh (the rates would be flown open loop). (Body rates
        are bounded by the encoder itself: safety.max_body_rate_rad_s.)"""
        if self.pipeline.encoder.output_mode != "rates" or step.encoded.rates_frd_rad_s is None:
            return step.setpoint
        if self.clock() - self._last_attitude_wall > KEEPALIVE_S:
            return self._safe_setpoint(step.estimate)
        return step.setpoint

    def _follow_step(self, step: Step) -> None:
        verdict = self.supervisor.check_step(step, self.modes.armed, following=True)
        if verdict.breach:
            self._breach(verdict, step.estimate)
            return
        self.last_step = step
        self.steps += 1
        self._send(self._outgoing(step))
        if self.on_step is not None:
            self.on_step(step)
        rec = step.record
        laps = self.laps.update(rec.eta1_m)
        # --duration on one continuous clock (an autopilot clock jump must not end or stretch it)
        now_clock = flight_clock_s(step.estimate)
        elapsed = now_clock - (self._activation_clock_s if self._activation_clock_s is not None else now_clock)
        reason = end_reason(
            self.options.end, laps, elapsed, self.path_closed, rec.lam, self.lam_max, self.pipeline.speed_ref_m_s, rec.eta2_m_s
        )
        if reason:
            self._end_reason = reason
            self.phase = Phase.HANDING_BACK
            self.waiter.notify()

    async def _measure_hover_thrust(self, wait_s: float) -> None:
        """Before activation (once): fly attitude / rates with the hover thrust the autopilot's
        attitude target showed while it held the vehicle still (app/hover.py), waiting up to
        ``wait_s`` (wall clock) for a steady window; without one, the parameter read at connect
        stays, and a line says which was used."""
        meter = self._hover_meter
        if meter is None:
            return
        if wait_s > 0.0:  # (the meter keeps taking samples meanwhile)
            await self.waiter.until(lambda: meter.hover_thrust() is not None or self.waiter.stop.is_set(), wait_s)
        self._hover_meter = None
        encoder, param = self.pipeline.encoder, self.profile.hover_thrust_param
        hover = meter.hover_thrust()
        if hover is None:
            self.display.say(f"hover thrust {encoder.hover_thrust:g} from {param}: no steady attitude target from the autopilot in hold to measure it")
            return
        self.pipeline.encoder = encoder.with_hover_thrust(hover)
        self._hover_event = f"hover_thrust_measured={hover:.3f}"
        self.display.say(f"hover thrust {hover:.3f}, measured from the autopilot's attitude target in hold ({param} {encoder.hover_thrust:g})")

    def _with_hover_event(self, event: str) -> str:
        """``event`` with the hover thrust measured for this activation, logged once (with the
        engagement, or with the activation when nothing engaged first)."""
        event, self._hover_event = ";".join(e for e in (event, self._hover_event) if e), ""
        return event

    def _engage(self, event: str) -> None:
        """From now on the streamed setpoints are meant to fly (mode switch requested)."""
        est = self.pipeline.estimator.latest
        self.activation_time_s = est.time_s if est is not None else None
        self._activation_clock_s = flight_clock_s(est) if est is not None else None
        self._event = self._with_hover_event(event)
        self.phase = Phase.ENGAGING

    def _activate(self) -> None:
        if self.phase in INTERRUPTING:
            return  # the flight is ending (safing / taken over): never start following now
        est = self.pipeline.estimator.latest
        if self.activation_time_s is None and est is not None:
            self.activation_time_s = est.time_s
            self._activation_clock_s = flight_clock_s(est)
        self._event = self._with_hover_event(self._event or "activated")
        self.controllers.autopilot_target(self.clock())  # echoes of the take-off / hold target may still arrive
        self.phase = Phase.FOLLOWING
        self.offboard_seen = True
        self.waiter.notify()

    def _check_controllers(self) -> None:
        """Another controller's setpoints while we are in control (taking off, engaging, following):
        end following, the safe setpoint and the hold until confirmed (exit 8). Two controllers
        alternating setpoints fly neither's path; the hold stops both."""
        if self.phase not in (Phase.TAKEOFF, Phase.ENGAGING, Phase.FOLLOWING):
            return
        why = self.controllers.verdict(self.clock())
        if why:
            self._event = "another controller"
            self._enter_safing(EXIT_CONTROLLER, why)

    # ------------------------------------------------------------------ ending: breach, crash, safe mode
    def _breach(self, verdict: Verdict, est: StateEstimate | None) -> None:
        """The envelope was left (or would be by this setpoint): end following, stream only the
        safe setpoint and request the safe mode; a vehicle that disarmed needs nothing more."""
        if self.breach is not None or self.phase in TERMINAL:
            return
        self.supervisor.record(verdict, est)
        self._event = f"safety: {verdict.kind.value}"
        if verdict.crash and not self.modes.armed:
            self._crash(verdict)
            return
        self._enter_safing(EXIT_CRASH if verdict.crash else EXIT_BREACH, f"safety: {verdict.reason}")

    def _crash(self, verdict: Verdict) -> None:
        """Disarmed under our commands: nothing to hold. Stop sending at once and end."""
        self.supervisor.record(verdict, self.pipeline.estimator.latest)
        self.display.say(f"safety: {verdict.reason}")
        self._last_setpoint = None
        self._safe_msg = None
        self.phase = Phase.FAILED
        self._finish(EXIT_CRASH, f"safety: {verdict.reason}; stopped commanding")

    def _safe_setpoint(self, est: StateEstimate | None) -> Any:
        """Stateless, safe to hold for as long as the autopilot keeps it (see Encoder.safe)."""
        yaw = yaw_of(est.q_enu_flu) if est is not None and est.q_enu_flu is not None else self._takeoff_yaw
        stamp = time_boot_ms(est) if est is not None else 0
        return self.pipeline.encoder.safe(yaw, stamp).message

    def _enter_safing(self, code: int, reason: str, mode: ModeRequest | None = None) -> None:
        """From now on only the safe setpoint goes out (at the setpoint rate, from the keep-alive)
        while :meth:`_safe_mode` requests ``mode`` (default: safety.action) until confirmed."""
        if self.phase in TERMINAL or self.phase is Phase.SAFING:
            return
        if mode is None:
            mode = self.profile.land if self.supervisor.config.action == "land" else self.profile.hold
        est = self.pipeline.estimator.latest
        if self.phase is Phase.TAKEOFF and not self.dialect.takeoff_streams_setpoints:
            safe = None  # GUIDED take-off: any setpoint would cancel it; the mode request suffices
        elif self.phase is Phase.TAKEOFF and est is not None:
            # climbing on position setpoints: hold the current position (the autopilot closes the loop)
            safe = position_setpoint(self.link.target.system, self.link.target.component, time_boot_ms(est), est.position_enu_m, self._takeoff_yaw)
        else:
            safe = self._safe_setpoint(est)
        self.display.say(f"{reason}; sending only the safe setpoint, requesting {mode.name}")
        self._safing = (code, reason, mode)
        self.phase = Phase.SAFING
        self._safe_msg = safe
        self._last_setpoint = None
        if safe is not None:
            self._send(safe)
        self.waiter.notify()

    async def _safe_mode(self) -> None:
        """Request the safe mode until a HEARTBEAT shows it (or the operator takes over, or
        safety.safe_mode_timeout_s passes); then stop sending."""
        assert self._safing is not None
        code, reason, mode = self._safing
        timeout_s = self.supervisor.config.safe_mode_timeout_s
        confirmed = await self.commander.request_mode_until_shown(mode, timeout_s, lambda: self.phase is Phase.SAFING)
        self._safe_msg = None
        self._last_setpoint = None
        if self.result is None:
            tail = "confirmed" if confirmed else f"not confirmed within {timeout_s:g} s"
            self.phase = Phase.FAILED
            self._finish(code, f"{reason}; {mode.name} requested, {tail}")

    # ------------------------------------------------------------------ sending
    def _send(self, msg: Any) -> None:
        self.link.send(msg)
        self.controllers.sent(msg, self.clock())
        self._last_setpoint = msg
        self._last_send_wall = self.clock()
        self.sent_setpoints += 1

    def _neutral_allowed(self) -> bool:
        """Setpoints are harmless while the autopilot is known not to be in OFFBOARD / GUIDED."""
        return self.modes.custom_mode is not None and not self.profile.is_offboard(self.modes.custom_mode)

    def _send_neutral(self) -> None:
        """Before the first state sample: the hold of our output mode at rest. The autopilot
        ignores it outside OFFBOARD / GUIDED (we never send it there); it starts PX4's
        proof-of-life clock and drives a lockstep simulator to its first telemetry."""
        rest = StateEstimate(0.0, np.zeros(3), np.zeros(3), None, None, 0)
        self._send(self.pipeline.encoder.hold(rest, 0).message)

    # ------------------------------------------------------------------ periodic tasks (wall clock)
    async def keepalive(self) -> None:
        """Proof-of-life guard, stale-state and HEARTBEAT watchdogs, safe-setpoint stream (wall clock).

        While setpoints are computed on every fresh state sample, nothing is re-sent unless nothing
        went out for ``KEEPALIVE_S`` (10 Hz, five times PX4's 2 Hz minimum and well inside
        COM_OF_LOSS_T); then, while our setpoints fly (engaging, following, handing back), the
        *safe* setpoint goes out, never the last command: a command computed from a state that
        is now late would be flown open loop (body rates flip a vehicle in a fraction of a second).
        Before any state sample (preflight) the neutral setpoint goes out every setpoint period.
        While safing, the safe setpoint (stateless) goes out every setpoint period.
        """
        period = 1.0 / self.options.setpoint_rate_hz
        while self.phase not in TERMINAL:
            await asyncio.sleep(period)
            now = self.clock()
            phase = self.phase
            if phase is Phase.SAFING:
                if self._safe_msg is not None and now - self._last_send_wall >= period:
                    self._send(self._safe_msg)
                continue
            if phase in TERMINAL:
                return
            if self.modes.in_control() and phase is not Phase.WAITING:
                why = self.supervisor.heartbeat_silence(now - self._last_heartbeat_wall)
                if why:
                    self._enter_safing(EXIT_LINK, why)
                    continue
            if phase in (Phase.FOLLOWING, Phase.ENGAGING):
                why = self.supervisor.stale_state(now - self._last_fresh_wall, self.options.state_timeout_s)
                estimator = self.pipeline.estimator
                if why and (estimator.health_reason or "quality -1" in estimator.last_event):
                    why += f" (the estimate is refused: {estimator.health_reason or estimator.last_event})"
                if why:
                    self._enter_safing(EXIT_LINK, why)
                    continue
            # before the stream of our own setpoints started (the first state sample may have come
            # before anything was sent): the neutral setpoint, as in preflight
            idle = phase is Phase.PREFLIGHT or (phase is Phase.WAITING and self._last_setpoint is None)
            preflight = idle and self._neutral_allowed()
            if preflight and (self._last_setpoint is None or now - self._last_send_wall >= period):
                self._send_neutral()
            elif self._last_setpoint is not None and now - self._last_send_wall >= KEEPALIVE_S:
                flying = phase in (Phase.FOLLOWING, Phase.ENGAGING, Phase.HANDING_BACK)
                self._send(self._safe_setpoint(self.pipeline.estimator.latest) if flying else self._last_setpoint)

    async def heartbeat(self) -> None:
        while self.phase not in TERMINAL:
            self.link.send_heartbeat()
            await asyncio.sleep(1.0)

    async def status_line(self) -> None:
        await self.display.run(self.status_text, lambda: self.phase not in TERMINAL)

    def status_text(self) -> str:
        line = status_text(self.phase.value, self.modes.mode_name(), self.modes.armed, self.last_step, self.laps.laps, self.loop_rate_hz)
        # a flight without a path (identify's excitation) words its own line: (line, flight) -> line
        return self.status_hook(line, self) if self.status_hook is not None else line


class _TakeoffOps:
    """The flight's side of a dialect's take-off sequence (:class:`~.dialects.TakeoffOps`)."""

    def __init__(self, flight: Flight, est: StateEstimate, ready_deadline: float) -> None:
        self.flight = flight
        self.est = est
        self.ready_deadline = ready_deadline
        self.ready_left = max(0.0, ready_deadline - flight.clock())

    def hold_here(self) -> None:
        p = self.est.position_enu_m
        self.flight._takeoff_target = np.array([p[0], p[1], p[2]])
        self.flight.phase = Phase.TAKEOFF

    def send_nothing(self) -> None:
        self.flight.phase = Phase.TAKEOFF
        self.flight._last_setpoint = None

    async def proof_of_life(self) -> None:
        await self.flight._proof_of_life()

    async def engage_and_arm(self) -> None:
        f = self.flight
        await f.commander.set_mode(f.profile.offboard, self.ready_left)
        if not f.modes.armed:
            await f.commander.arm(max(0.0, self.ready_deadline - f.clock()))

    def climb_to(self, height_m: float) -> None:
        p = self.est.position_enu_m
        self.flight._takeoff_target = np.array([p[0], p[1], height_m])

    def command(self, command: int, *params: float) -> None:
        self.flight.commander.command(command, *params)
