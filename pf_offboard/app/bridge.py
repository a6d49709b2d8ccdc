"""The bridge: activation, watchdog and mode logic between the pipeline and the link.

Backends (:mod:`.encoders`) only encode; every decision about *whether* and *what* to send lives
here. The decision rules are small pure classes (:class:`ThrowTrigger`, :class:`LapCounter`,
:func:`end_reason`) tested on their own; :class:`Bridge` wires them to a :class:`~.link.Link`.

Phases: ``preflight`` → (``takeoff``) → ``waiting`` (throw) / ``engaging`` → ``following`` →
``handing_back`` → ``done``; or ``taken_over`` (the operator switched the mode away, in any
phase once we asked for a mode: we stop sending at once and never re-engage), or ``safing`` (an
envelope breach, stale state, lost HEARTBEAT or a failure while we may be in control: only the
safe setpoint goes out while the safe mode is requested until the HEARTBEAT confirms it) →
``failed``. The envelope itself is :mod:`pf_offboard.safety` (pure); the bridge only wires it.
"""

from __future__ import annotations

import asyncio
import enum
import math
import struct
import sys
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, TextIO

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.app.encoders import position_setpoint, yaw_of
from pf_offboard.app.estimator import StateEstimate, flight_clock_s
from pf_offboard.app.link import Link
from pf_offboard.app.pipeline import Pipeline, Step, time_boot_ms
from pf_offboard.app.profiles import Autopilot, ModeRequest, Profile, is_armed
from pf_offboard.errors import InputError, LinkError
from pf_offboard.safety import Breach, EnvelopeMonitor, SafetyConfig, Verdict, VehicleSample

# Exit codes of `pf-offboard fly` (documented in docs/app.md).
EXIT_OK = 0
EXIT_INPUT = 2
EXIT_LINK = 3  # no heartbeat, refused command, lost telemetry
EXIT_TAKEOVER = 4  # the operator took the vehicle back; we yielded
EXIT_BREACH = 5  # the flight envelope was breached: following ended, safe mode requested
EXIT_CRASH = 6  # the vehicle disarmed, landed or fell while we commanded it
EXIT_INTERRUPTED = 130  # Ctrl-C before following began


_MAV_RESULT_NAMES = {0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED", 4: "FAILED", 5: "IN_PROGRESS"}

KEEPALIVE_S = 0.1  # re-send the last setpoint when nothing went out for this long
SAFE_MODE_RETRY_S = 0.25  # re-send the safe-mode request this often until the HEARTBEAT shows it
MAV_STATE_CRITICAL = 5  # HEARTBEAT.system_status: the autopilot is in its own failsafe


class Phase(enum.Enum):
    PREFLIGHT = "preflight"
    TAKEOFF = "takeoff"
    WAITING = "waiting"  # throw launch: proof-of-life while the vehicle is carried / thrown
    ENGAGING = "engaging"  # mode switch to OFFBOARD / GUIDED requested, not yet confirmed
    FOLLOWING = "following"
    HANDING_BACK = "handing_back"
    SAFING = "safing"  # only the safe setpoint goes out; the safe mode is requested until confirmed
    DONE = "done"
    TAKEN_OVER = "taken_over"
    FAILED = "failed"


_TERMINAL = (Phase.DONE, Phase.TAKEN_OVER, Phase.FAILED)
# a wait in one of these phases is cut short: the flight is ending another way
_INTERRUPTING = (Phase.SAFING, *_TERMINAL)


# ---------------------------------------------------------------------------- pure decision rules
class ThrowTrigger:
    """Fires once, the moment a thrown vehicle crosses the activation height.

    Crossing in either direction counts (thrown up through H from the hand, or falling through H
    after being thrown above it), but only while the vehicle is in free flight: speed at least
    ``min_speed_m_s`` (a vehicle carried slowly past H does not fire) and ``confirm`` consecutive
    samples on the far side of H (a single noisy sample does not fire). The first altitude seen
    sets which side we start on; nothing fires until the vehicle has been seen on one side.
    """

    def __init__(self, height_m: float, min_speed_m_s: float = 0.5, confirm: int = 2) -> None:
        if not (math.isfinite(height_m) and height_m > 0.0):
            raise InputError("--throw", f"activation height must be > 0 m, got {height_m}")
        self.height_m = height_m
        self.min_speed_m_s = min_speed_m_s
        self.confirm = confirm
        self._side: bool | None = None  # True: above H
        self._beyond = 0
        self.fired = False

    def update(self, altitude_m: float, speed_m_s: float) -> bool:
        """Feed one state sample; True exactly once, on the confirming sample of a crossing."""
        if self.fired:
            return False
        above = altitude_m >= self.height_m
        if self._side is None:
            self._side = above
            return False
        if above == self._side:
            self._beyond = 0
            return False
        if speed_m_s < self.min_speed_m_s:
            # a slow crossing (carried by hand, drifting): accept the new side without firing
            self._side, self._beyond = above, 0
            return False
        self._beyond += 1
        if self._beyond >= self.confirm:
            self.fired = True
            return True
        return False


class LapCounter:
    """Laps completed: *net* progress along the path (η1 samples, metres) over its length.

    Each difference of η1 is taken modulo the length on closed paths (the shorter way round, so
    the wrap at the start point is unwrapped) and summed with its sign, so jitter back and forth
    cancels instead of accumulating. ``direction`` is the sign of travel (the sign of η2_ref):
    progress against it counts negative. ``None``: either direction, the magnitude of the net
    progress. Laps are never negative.
    """

    def __init__(self, length_m: float, closed: bool, direction: float | None = None) -> None:
        self.length_m = length_m
        self.closed = closed
        self.direction = None if direction is None else (1.0 if direction >= 0.0 else -1.0)
        self._last: float | None = None
        self.progress_m = 0.0  # signed net progress since the first sample (η1 units)

    def update(self, eta1_m: float) -> float:
        if not math.isfinite(eta1_m):
            return self.laps
        if self._last is not None:
            d = eta1_m - self._last
            if self.closed and self.length_m > 0:
                d = (d + 0.5 * self.length_m) % self.length_m - 0.5 * self.length_m
            self.progress_m += d
        self._last = eta1_m
        return self.laps

    @property
    def travelled_m(self) -> float:
        """Net path length travelled in the direction of travel (m, >= 0)."""
        net = abs(self.progress_m) if self.direction is None else self.direction * self.progress_m
        return max(0.0, net)

    @property
    def laps(self) -> float:
        return self.travelled_m / self.length_m if self.length_m > 0 else 0.0


class TakeoffSettle:
    """When a take-off counts as done: the vehicle holds the take-off altitude, on average.

    A vehicle hovering on GPS never sits still (PX4 SIH holds at 0.13-0.43 m/s), so a
    per-sample rule "within 0.1 m and below 0.1 m/s" may never hold. Instead: over the last
    ``window_s`` of vehicle time (at least that much history), the mean altitude error is within
    ``altitude_tol_m`` and the mean speed below ``speed_tol_m_s``. Pure; feed state samples.
    """

    def __init__(self, height_m: float, altitude_tol_m: float = 0.3, speed_tol_m_s: float = 0.5, window_s: float = 1.0) -> None:
        self.height_m = height_m
        self.altitude_tol_m = altitude_tol_m
        self.speed_tol_m_s = speed_tol_m_s
        self.window_s = window_s
        self._samples: list[tuple[float, float, float]] = []  # (time s, |altitude error| m, speed m/s)

    def update(self, time_s: float, altitude_m: float, speed_m_s: float) -> bool:
        """Feed one sample (vehicle time s, altitude m above home, speed m/s); True once settled."""
        if not (math.isfinite(time_s) and math.isfinite(altitude_m) and math.isfinite(speed_m_s)):
            return False
        if self._samples and time_s <= self._samples[-1][0]:
            return self.settled  # duplicated / reordered sample
        self._samples.append((time_s, abs(altitude_m - self.height_m), speed_m_s))
        while len(self._samples) > 1 and time_s - self._samples[1][0] >= self.window_s:
            self._samples.pop(0)
        return self.settled

    @property
    def settled(self) -> bool:
        s = self._samples
        if len(s) < 2 or s[-1][0] - s[0][0] < self.window_s:
            return False
        n = len(s)
        return sum(e for _, e, _ in s) / n <= self.altitude_tol_m and sum(v for _, _, v in s) / n <= self.speed_tol_m_s


@dataclass(frozen=True)
class EndSpec:
    """When path following ends (any that is set)."""

    laps: float | None = None
    duration_s: float | None = None  # vehicle time since activation
    open_path_end: bool = True  # stop at the end of an open path


def end_reason(
    spec: EndSpec,
    laps: float,
    elapsed_s: float,
    path_closed: bool,
    lam: float,
    lam_max: float,
    speed_ref_m_s: float,
    eta2_m_s: float,
) -> str:
    """Why following should end now ("" to continue). Pure."""
    if spec.laps is not None and laps >= spec.laps:
        return f"{spec.laps:g} laps done"
    if spec.duration_s is not None and elapsed_s >= spec.duration_s:
        return f"duration {spec.duration_s:g} s reached"
    if spec.open_path_end and not path_closed and math.isfinite(lam):
        at_end = lam >= lam_max - 1e-6 if speed_ref_m_s > 0 else lam <= 1e-6
        if at_end and abs(eta2_m_s) < 0.1:
            return "end of the open path reached"
    return ""


def param_value_decode(value: float, param_type: int, bytewise: bool) -> float:
    """A PARAM_VALUE's value: PX4 packs INT32 bytewise into the float, ArduPilot casts."""
    if bytewise and param_type in (mavlink2.MAV_PARAM_TYPE_INT32, mavlink2.MAV_PARAM_TYPE_UINT32):
        return float(struct.unpack("<i", struct.pack("<f", value))[0])
    return float(value)


def param_value_encode(value: float, param_type: int, bytewise: bool) -> float:
    """Inverse of :func:`param_value_decode` for PARAM_SET."""
    if bytewise and param_type in (mavlink2.MAV_PARAM_TYPE_INT32, mavlink2.MAV_PARAM_TYPE_UINT32):
        return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])
    return float(value)


# ---------------------------------------------------------------------------- the bridge
@dataclass(frozen=True)
class BridgeOptions:
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


@dataclass
class FlightResult:
    exit_code: int
    reason: str
    activation_time_s: float | None = None
    laps: float = 0.0
    steps: int = 0
    breach: Verdict | None = None  # what ended following, if the envelope did
    breach_time_s: float | None = None  # vehicle time of the last state sample when it was detected


class Bridge:
    """Runs one flight over an open link (target known). Use ``await bridge.run()``."""

    def __init__(
        self,
        link: Link,
        profile: Profile,
        pipeline: Pipeline,
        options: BridgeOptions,
        path_length_m: float,
        path_closed: bool,
        lam_max: float,
        on_step: Callable[[Step], None] | None = None,
        status_stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
        monitor: EnvelopeMonitor | None = None,
    ) -> None:
        self.link = link
        self.profile = profile
        self.pipeline = pipeline
        self.options = options
        self.path_closed = path_closed
        self.lam_max = lam_max
        self.on_step = on_step
        self.status_stream = status_stream if status_stream is not None else sys.stderr
        self.clock = clock
        self.phase = Phase.PREFLIGHT
        speed_ref = pipeline.speed_ref_m_s
        self.laps = LapCounter(path_length_m, path_closed, speed_ref if math.isfinite(speed_ref) and speed_ref != 0.0 else None)
        self.throw = ThrowTrigger(options.height_m) if options.launch == "throw" else None
        self.custom_mode: int | None = None
        self.base_mode = 0
        self.offboard_seen = False  # OFFBOARD/GUIDED confirmed by HEARTBEAT while following
        self.acks: dict[int, int] = {}
        self.params: dict[str, float] = {}
        self.activation_time_s: float | None = None
        self._activation_clock_s: float | None = None  # the same instant on the estimator's continuous clock
        self.result: FlightResult | None = None
        self.last_step: Step | None = None
        self.steps = 0
        self._last_setpoint: Any = None
        self._last_send_wall = -math.inf
        self._last_fresh_wall = -math.inf
        self._takeoff_target: np.ndarray | None = None
        self._takeoff_yaw = 0.0
        self._settle: TakeoffSettle | None = None
        self._changed = asyncio.Event()
        self._stop = asyncio.Event()
        self._end_reason = ""
        self._rate_count = 0
        self.loop_rate_hz = 0.0
        self.sent_setpoints = 0
        self._event = ""  # logged with the next step
        self.last_statustext = ""
        # safety (pf_offboard.safety): the monitor decides, the bridge acts
        self.monitor = monitor
        self.safety = monitor.config if monitor is not None else SafetyConfig(enabled=False)
        self.landed_state: int | None = None
        self.breach: Verdict | None = None
        self.breach_time_s: float | None = None
        self._armed_seen = False
        # Modes that are ours: the one the vehicle was in when we asked (or that we got) and the one
        # we asked for. Any other mode in a HEARTBEAT is the operator's (or a failsafe's).
        self._held_mode: int | None = None
        self._pending_mode: int | None = None
        self._last_heartbeat_wall = clock()
        self._last_attitude_wall = -math.inf
        self._safing: tuple[int, str, ModeRequest] | None = None
        self._safe_msg: Any = None
        self._activation_checked = False
        # before activation, stream the follower's own (inactive) setpoints as proof of life
        self._stream_follow_before_active = False
        if link.first_heartbeat is not None:  # mode and armed state known from the start
            self._on_heartbeat(link.first_heartbeat)

    # ------------------------------------------------------------------ receive path (event loop callback)
    def on_message(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            target = self.link.target
            if target is None or msg.get_srcComponent() == target.component:
                self._on_heartbeat(msg)
            return
        if kind == "EXTENDED_SYS_STATE":
            self.landed_state = int(msg.landed_state)
            return
        if kind == "COMMAND_ACK":
            self.acks[msg.command] = msg.result
            self._changed.set()
            return
        if kind == "PARAM_VALUE":
            pid = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
            self.params[pid.rstrip("\x00")] = param_value_decode(msg.param_value, msg.param_type, self.profile.params_bytewise)
            self._changed.set()
            return
        if kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            self.last_statustext = text.rstrip("\x00")
            self._print(f"autopilot: {self.last_statustext}")
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
            self._rate_count += 1
            self._on_state()

    def _on_heartbeat(self, msg: Any) -> None:
        previous = self.custom_mode
        self.custom_mode, self.base_mode = msg.custom_mode, msg.base_mode
        self._last_heartbeat_wall = self.clock()
        self._changed.set()
        phase = self.phase
        if phase in _TERMINAL:
            return
        armed = is_armed(msg.base_mode)
        if armed:
            self._armed_seen = True
        elif self._armed_seen and self._in_control() and phase is not Phase.WAITING:
            # disarmed under our commands: crashed, killed or the autopilot's own failsafe
            self._crash(Verdict(Breach.DISARMED, "the vehicle disarmed in flight (crash, kill switch or autopilot failsafe)"))
            return
        if self._pending_mode is not None and self._same_mode(msg.custom_mode, self._pending_mode):
            self._held_mode, self._pending_mode = msg.custom_mode, None
        offboard = self.profile.is_offboard(msg.custom_mode)
        if phase is Phase.ENGAGING and offboard:
            self._activate()
            return
        if phase is Phase.FOLLOWING and offboard:
            self.offboard_seen = True
        if not self._in_control() or self._mode_is_ours(msg.custom_mode):
            return
        old = self.profile.mode_name(previous) if previous is not None else "?"
        new = self.profile.mode_name(msg.custom_mode)
        if msg.system_status >= MAV_STATE_CRITICAL:
            # the autopilot's own failsafe (e.g. PX4 offboard loss -> RTL), not an operator: ask for
            # our safe mode instead (an RTL climbs to tens of metres)
            if phase is not Phase.SAFING:
                self._enter_safing(EXIT_LINK, f"autopilot failsafe: mode {old} -> {new}")
            return
        # The operator (RC / ground station) took over: yield at once, never re-engage, in any phase.
        self.phase = Phase.TAKEN_OVER
        self._last_setpoint = None
        self._safe_msg = None
        self._finish(EXIT_TAKEOVER, f"mode changed {old} -> {new} by someone else during {phase.value}; stopped sending, not re-engaging")

    def _in_control(self) -> bool:
        """We have asked the autopilot for a mode (it may be flying our setpoints)."""
        return self._held_mode is not None or self._pending_mode is not None

    def _same_mode(self, custom_mode: int, ours: int) -> bool:
        return custom_mode == ours or (self.profile.is_offboard(custom_mode) and self.profile.is_offboard(ours))

    def _mode_is_ours(self, custom_mode: int) -> bool:
        return any(m is not None and self._same_mode(custom_mode, m) for m in (self._held_mode, self._pending_mode))

    def _custom_of(self, mode: ModeRequest) -> int:
        p = self.profile
        return {id(p.offboard): p.offboard_custom_mode, id(p.hold): p.hold_custom_mode, id(p.land): p.land_custom_mode}[id(mode)]

    def _on_state(self) -> None:
        est = self.pipeline.estimator.latest
        assert est is not None
        phase = self.phase
        if phase in _TERMINAL:
            return
        if phase is Phase.SAFING:
            # the safe setpoint is stateless and streamed by the keep-alive; the controller is out
            self.pipeline.mark_consumed()
            return
        if phase is Phase.TAKEOFF and self._armed_seen and self.monitor is not None:
            verdict = self.monitor.check_state(self._sample(est, None), following=False)  # tilt, disarm
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
            # keep the stream (and a lockstep clock) going with the hold until the mode changes
            self._send(self.pipeline.encoder.hold(est, time_boot_ms(est)).message)
            return
        if phase is Phase.TAKEOFF and self._settle is not None:
            if self._settle.update(est.time_s, float(est.position_enu_m[2]), float(np.linalg.norm(est.velocity_enu_m_s))):
                self._changed.set()
        if phase is Phase.TAKEOFF and self._takeoff_target is not None:
            self.pipeline.mark_consumed()
            if self.monitor is not None and self._takeoff_target[2] > est.position_enu_m[2] + 0.05:
                verdict = self.monitor.check_setpoint(position_target_enu_m=self._climb_target())
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
                verdict = self._check(step)
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
                    self._request_offboard_nowait()
            return
        self.pipeline.mark_consumed()

    def _pending_event(self) -> str:
        ev, self._event = self._event, ""
        return ev

    def _sample(self, est: StateEstimate, step: Step | None) -> VehicleSample:
        cmd = step.command if step is not None else None
        rates = self.pipeline.encoder.output_mode == "rates"
        return VehicleSample(
            # the monitor's durations (no-progress window, attitude-error time) on the estimator's
            # continuous clock: an autopilot clock jump is not 30 s without progress
            time_s=flight_clock_s(est),
            position_enu_m=est.position_enu_m,
            velocity_enu_m_s=est.velocity_enu_m_s,
            q_enu_flu=est.q_enu_flu,
            armed=is_armed(self.base_mode),
            landed_state=self.landed_state,
            cross_track_m=float(cmd.cross_track_m) if cmd is not None else None,
            eta1_m=float(cmd.state.eta1) if cmd is not None else None,
            # our own attitude loop is judged only once the vehicle flies it (not while engaging)
            q_cmd_enu_flu=np.asarray(cmd.attitude, dtype=float) if (cmd is not None and rates and self.phase is Phase.FOLLOWING) else None,
            rates_flu_rad_s=est.rates_flu_rad_s,
            q_demand_enu_flu=np.asarray(cmd.attitude, dtype=float) if cmd is not None else None,
        )

    def _check(self, step: Step) -> Verdict:
        """The envelope monitor on one controller step: the state it came from, then the setpoint
        itself, before it leaves. Activation (first active step) has its own distance limit."""
        monitor = self.monitor
        if monitor is None:
            return Verdict()
        sample = self._sample(step.estimate, step)
        if not self._activation_checked:
            self._activation_checked = True
            verdict = monitor.check_activation(sample)
            if verdict.breach:
                return verdict
        verdict = monitor.check_state(sample, following=True)
        if verdict.breach or step.command is None or step.encoded.replaced:
            return verdict  # (a replaced step already carries the hold, not the command)
        mode, cmd = self.pipeline.encoder.output_mode, step.command
        return monitor.check_setpoint(
            q_cmd_enu_flu=cmd.attitude if mode != "acceleration" else None,
            rates_frd_rad_s=step.encoded.rates_frd_rad_s if mode == "rates" else None,
            accel_cmd_enu_m_s2=cmd.acceleration if mode == "acceleration" else None,
        )

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
        verdict = self._check(step)
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
            self._changed.set()

    # ------------------------------------------------------------------ ending: breach, crash, safe mode
    def _breach(self, verdict: Verdict, est: StateEstimate | None) -> None:
        """The envelope was left (or would be by this setpoint): end following, stream only the
        safe setpoint and request the safe mode; a vehicle that disarmed needs nothing more."""
        if self.breach is not None or self.phase in _TERMINAL:
            return
        self.breach, self.breach_time_s = verdict, (est.time_s if est is not None else None)
        self._event = f"safety: {verdict.kind.value}"
        if verdict.crash and not is_armed(self.base_mode):
            self._crash(verdict)
            return
        self._enter_safing(EXIT_CRASH if verdict.crash else EXIT_BREACH, f"safety: {verdict.reason}")

    def _crash(self, verdict: Verdict) -> None:
        """Disarmed under our commands: nothing to hold. Stop sending at once and end."""
        if self.breach is None:
            est = self.pipeline.estimator.latest
            self.breach, self.breach_time_s = verdict, (est.time_s if est is not None else None)
        self._print(f"safety: {verdict.reason}")
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
        if self.phase in _TERMINAL or self.phase is Phase.SAFING:
            return
        if mode is None:
            mode = self.profile.land if self.safety.action == "land" else self.profile.hold
        est = self.pipeline.estimator.latest
        if self.phase is Phase.TAKEOFF and self.profile.autopilot is Autopilot.ARDUPILOT:
            safe = None  # GUIDED take-off: any setpoint would cancel it; the mode request suffices
        elif self.phase is Phase.TAKEOFF and est is not None:
            # climbing on position setpoints: hold the current position (PX4 closes the loop)
            safe = position_setpoint(self.link.target.system, self.link.target.component, time_boot_ms(est), est.position_enu_m, self._takeoff_yaw)
        else:
            safe = self._safe_setpoint(est)
        self._print(f"{reason}; sending only the safe setpoint, requesting {mode.name}")
        self._safing = (code, reason, mode)
        self.phase = Phase.SAFING
        self._safe_msg = safe
        self._last_setpoint = None
        if safe is not None:
            self._send(safe)
        self._changed.set()

    async def _safe_mode(self) -> None:
        """Request the safe mode every SAFE_MODE_RETRY_S until a HEARTBEAT shows it (or the
        operator takes over, or safety.safe_mode_timeout_s passes); then stop sending."""
        assert self._safing is not None
        code, reason, mode = self._safing
        custom = self._custom_of(mode)
        deadline = self.clock() + self.safety.safe_mode_timeout_s
        confirmed = False
        while self.phase is Phase.SAFING:
            confirmed = self.custom_mode == custom
            if confirmed or self.clock() > deadline:
                break
            try:
                self._set_mode_nowait(mode)
            except LinkError:
                pass
            await self._wait_until(lambda: self.phase is not Phase.SAFING or self.custom_mode == custom, SAFE_MODE_RETRY_S, interruptible=False)
        self._safe_msg = None
        self._last_setpoint = None
        if self.result is None:
            tail = "confirmed" if confirmed else f"not confirmed within {self.safety.safe_mode_timeout_s:g} s"
            self.phase = Phase.FAILED
            self._finish(code, f"{reason}; {mode.name} requested, {tail}")

    def _climb_target(self) -> Any:
        t = self._takeoff_target
        assert t is not None
        floor = self.monitor.fence.floor_m if self.monitor is not None else -math.inf
        return np.array([t[0], t[1], max(float(t[2]), floor)])

    def _engage(self, event: str) -> None:
        """From now on the streamed setpoints are meant to fly (mode switch requested)."""
        est = self.pipeline.estimator.latest
        self.activation_time_s = est.time_s if est is not None else None
        self._activation_clock_s = flight_clock_s(est) if est is not None else None
        self._event = event
        self.phase = Phase.ENGAGING

    def _activate(self) -> None:
        if self.phase in _INTERRUPTING:
            return  # the flight is ending (safing / taken over): never start following now
        est = self.pipeline.estimator.latest
        if self.activation_time_s is None and est is not None:
            self.activation_time_s = est.time_s
            self._activation_clock_s = flight_clock_s(est)
        self._event = self._event or "activated"
        self.phase = Phase.FOLLOWING
        self.offboard_seen = True
        self._changed.set()

    # ------------------------------------------------------------------ sending
    def _send(self, msg: Any) -> None:
        self.link.send(msg)
        self._last_setpoint = msg
        self._last_send_wall = self.clock()
        self.sent_setpoints += 1

    def _neutral_allowed(self) -> bool:
        """Setpoints are harmless while the autopilot is known not to be in OFFBOARD / GUIDED."""
        return self.custom_mode is not None and not self.profile.is_offboard(self.custom_mode)

    def _send_neutral(self) -> None:
        """Before the first state sample: the hold of our output mode at rest. The autopilot
        ignores it outside OFFBOARD / GUIDED (we never send it there); it starts PX4's
        proof-of-life clock and drives a lockstep simulator to its first telemetry."""
        rest = StateEstimate(0.0, np.zeros(3), np.zeros(3), None, None, 0)
        self._send(self.pipeline.encoder.hold(rest, 0).message)

    def _command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.acks.pop(command, None)
        t = self.link.target
        self.link.send(mavlink2.MAVLink_command_long_message(t.system, t.component, command, 0, *p))

    def _set_mode_nowait(self, mode: ModeRequest) -> None:
        if self.phase is Phase.TAKEN_OVER:
            return  # the operator has the vehicle: never ask for a mode again
        if self._held_mode is None:
            self._held_mode = self.custom_mode  # what the vehicle was in when we first asked
        self._pending_mode = self._custom_of(mode)
        self._command(mavlink2.MAV_CMD_DO_SET_MODE, 1.0, mode.param2, mode.param3)

    def _request_offboard_nowait(self) -> None:
        if not is_armed(self.base_mode):
            self._command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        self._set_mode_nowait(self.profile.offboard)

    async def _wait_until(self, predicate: Callable[[], bool], timeout_s: float, interruptible: bool = True) -> bool:
        """Until ``predicate()`` or the timeout; an ``interruptible`` wait also ends on a stop request
        and when the flight is ending another way (safing, taken over, failed)."""
        deadline = self.clock() + timeout_s
        while not predicate():
            remaining = deadline - self.clock()
            if remaining <= 0 or (interruptible and (self._stop.is_set() or self.phase in _INTERRUPTING)):
                return predicate()
            self._changed.clear()
            try:
                await asyncio.wait_for(self._changed.wait(), min(remaining, 0.1))
            except TimeoutError:
                pass
        return True

    async def _command_confirmed(
        self, what: str, send: Callable[[], None], confirmed: Callable[[], bool], command: int, timeout_s: float | None = None
    ) -> None:
        """Send, re-send every 0.5 s until ``confirmed()``. COMMAND_ACK DENIED / UNSUPPORTED is a
        refusal at once; TEMPORARILY_REJECTED / FAILED (e.g. "no position estimate yet") are
        retried until ``timeout_s`` (default ``command_timeout_s``), with a progress line every
        ``progress_every_s`` while the autopilot keeps refusing. Raises LinkError naming the last
        ACK and autopilot text."""
        timeout = self.options.command_timeout_s if timeout_s is None else max(timeout_s, self.options.command_timeout_s)
        start = self.clock()
        deadline = start + timeout
        next_progress = start + self.options.progress_every_s
        final = (mavlink2.MAV_RESULT_DENIED, mavlink2.MAV_RESULT_UNSUPPORTED)
        while True:
            if self.phase in _INTERRUPTING:  # taken over / safing: never send another request
                raise LinkError(f"{what}: interrupted")
            send()
            await self._wait_until(lambda: confirmed() or self.acks.get(command) in final, 0.5)
            if confirmed():
                return
            result = self.acks.get(command)
            detail = f" (COMMAND_ACK result {result}{'; autopilot: ' + self.last_statustext if self.last_statustext else ''})"
            if result in final:
                raise LinkError(f"{what} refused by the autopilot{detail}")
            if self._stop.is_set() or self.phase in _INTERRUPTING:
                raise LinkError(f"{what}: interrupted")
            now = self.clock()
            if now > deadline:
                raise LinkError(f"{what}: not confirmed within {timeout:g} s{detail}")
            if now >= next_progress:
                next_progress = now + self.options.progress_every_s
                said = f": autopilot says {self.last_statustext!r}" if self.last_statustext else ""
                self._print(f"waiting for {what}{said} ({now - start:.0f} s of up to {timeout:g} s)")

    async def set_mode(self, mode: ModeRequest, custom_mode: int, timeout_s: float | None = None) -> None:
        await self._command_confirmed(
            f"mode {mode.name}",
            lambda: self._set_mode_nowait(mode),
            lambda: self.custom_mode == custom_mode or (mode is self.profile.offboard and self.custom_mode is not None and self.profile.is_offboard(self.custom_mode)),
            mavlink2.MAV_CMD_DO_SET_MODE,
            timeout_s,
        )

    async def arm(self, timeout_s: float | None = None) -> None:
        """Arm; the autopilot's refusals while its checks are not ready yet are retried until
        ``timeout_s`` (default ``command_timeout_s``)."""
        await self._command_confirmed(
            "arming",
            lambda: self._command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1.0),
            lambda: is_armed(self.base_mode),
            mavlink2.MAV_CMD_COMPONENT_ARM_DISARM,
            timeout_s,
        )

    async def request_intervals(self, requests: list[tuple[int, float, str]], ack_timeout_s: float = 1.0) -> None:
        """SET_MESSAGE_INTERVAL for each (message id, rate Hz, name), one at a time so each
        COMMAND_ACK is matched to its request. A refusal is not fatal (the stream may flow at its
        default rate): it is reported as one note line (PX4 refuses HEARTBEAT: it stays at 1 Hz)."""
        for message_id, rate_hz, name in requests:
            self.request_interval(message_id, rate_hz)
            command = mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL
            await self._wait_until(lambda: command in self.acks, ack_timeout_s)
            result = self.acks.get(command)
            if result is not None and result != mavlink2.MAV_RESULT_ACCEPTED:
                label = _MAV_RESULT_NAMES.get(result, str(result))
                consequence = " (a takeover is seen within one HEARTBEAT period of its default rate)" if name == "HEARTBEAT" else ""
                self._note(f"note: the autopilot refused {name} at {rate_hz:g} Hz (SET_MESSAGE_INTERVAL: COMMAND_ACK {label}); "
                            f"it stays at its default rate{consequence}")  # fmt: skip

    def request_interval(self, message_id: int, rate_hz: float) -> None:
        """SET_MESSAGE_INTERVAL; a refusal is reported, not fatal (the stream may already flow)."""
        self._command(mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, float(message_id), 1e6 / rate_hz)

    async def read_param(self, name: str) -> float:
        t = self.link.target
        deadline = self.clock() + self.options.command_timeout_s
        self.params.pop(name, None)
        while name not in self.params:
            self.link.send(mavlink2.MAVLink_param_request_read_message(t.system, t.component, name.encode(), -1))
            await self._wait_until(lambda: name in self.params, 0.5)
            if self.clock() > deadline and name not in self.params:
                raise LinkError(f"parameter {name}: no PARAM_VALUE within {self.options.command_timeout_s:g} s")
        return self.params[name]

    async def write_param(self, name: str, value: float, param_type: int) -> float:
        t = self.link.target
        bytewise = self.profile.params_bytewise
        deadline = self.clock() + self.options.command_timeout_s
        while True:
            self.params.pop(name, None)
            self.link.send(
                mavlink2.MAVLink_param_set_message(t.system, t.component, name.encode(), param_value_encode(value, param_type, bytewise), param_type)
            )
            await self._wait_until(lambda: name in self.params, 0.5)
            if name in self.params and self.params[name] == value:
                return value
            if self.clock() > deadline:
                got = self.params.get(name)
                raise LinkError(f"parameter {name}: set to {value:g} not confirmed (PARAM_VALUE {got})")

    # ------------------------------------------------------------------ the flight
    def request_stop(self, reason: str = "stop requested (Ctrl-C)") -> None:
        """End following and hand back (SIGINT handler)."""
        if self.phase in (Phase.FOLLOWING, Phase.ENGAGING, Phase.WAITING, Phase.TAKEOFF, Phase.PREFLIGHT):
            self._end_reason = reason
            self.phase = Phase.HANDING_BACK
        elif self.phase is Phase.SAFING:
            return  # already stopping: the safe-mode request goes on
        self._stop.set()
        self._changed.set()

    def _finish(self, code: int, reason: str) -> None:
        if self.result is None:
            self.result = FlightResult(code, reason, self.activation_time_s, self.laps.laps, self.steps)
        if self.phase is not Phase.TAKEN_OVER:
            self.phase = Phase.DONE if code == EXIT_OK else Phase.FAILED
        self._changed.set()

    async def fly(self, setup: Callable[[], Awaitable[None]] | None = None) -> FlightResult:
        """``setup`` (streams, parameters), launch, follow, hand back. Returns how it ended
        (LinkError becomes exit 3; InputError from ``setup`` propagates). Whatever ends the flight
        while we may be in control goes through :meth:`_safe_mode` (safe setpoint, safe mode
        requested until confirmed), except an operator takeover (nothing more is sent)."""
        try:
            if setup is not None:
                await setup()
            await self._launch()
            await self._wait_until(lambda: self.phase not in (Phase.FOLLOWING, Phase.ENGAGING, Phase.WAITING), math.inf)
            if self.phase is Phase.HANDING_BACK:
                await self._hand_back()
        except LinkError as exc:
            if self.phase in _INTERRUPTING or self.result is not None:
                pass  # safing, taken over or ended: handled below / already decided
            elif self._stop.is_set():
                # Ctrl-C / SIGTERM before following had begun
                why = f"{self._end_reason or 'interrupted'} before following began"
                if self._in_control():
                    self._enter_safing(EXIT_INTERRUPTED, why, self._end_mode())
                else:
                    self._finish(EXIT_INTERRUPTED, f"{why}; nothing was commanded")
            else:
                self._print(f"error: {exc}")
                if self._in_control():
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

    def _end_mode(self) -> ModeRequest:
        return self.profile.land if self.options.end_action == "land" else self.profile.hold

    async def _launch(self) -> None:
        opts = self.options
        ready_deadline = self.clock() + opts.ready_timeout_s
        # the take-off heading comes from the attitude: wait for an attitude sample too
        est = await self._first_state(ready_deadline, need_attitude=opts.launch == "takeoff")
        if opts.launch == "takeoff":
            await self._takeoff(est, ready_deadline)
            self._stream_follow_before_active = True
            self._activate()
            return
        self._stream_follow_before_active = True
        if opts.launch == "airborne":
            if not is_armed(self.base_mode):
                raise LinkError("--airborne: the vehicle is not armed (is it flying?)")
            if not self._neutral_allowed():
                # already in OFFBOARD / GUIDED: whatever we send flies at once, so engage now
                self._engage("activated (airborne, already in " + self.profile.offboard.name + ")")
            else:
                # stream the follower's setpoints (proof of life), then switch
                self.phase = Phase.WAITING
                await self._proof_of_life()
                self._engage("activated (airborne)")
            await self.set_mode(self.profile.offboard, self.profile.offboard_custom_mode)
            if self.phase is Phase.ENGAGING:
                self._activate()
            return
        # throw: stream the follower's setpoints while waiting; _on_state fires the trigger
        self.phase = Phase.WAITING
        self._print(f"waiting for a throw through {opts.height_m:g} m (Ctrl-C to abort)")
        armed_seen = is_armed(self.base_mode)

        def waiting() -> bool:
            nonlocal armed_seen
            armed_seen = armed_seen or is_armed(self.base_mode)
            return self.phase is Phase.WAITING and not (armed_seen and not is_armed(self.base_mode))

        await self._wait_until(lambda: not waiting(), math.inf)
        if self.phase is Phase.WAITING:
            raise LinkError("the vehicle disarmed (landed or crashed) before crossing the activation height")
        if self.phase is Phase.ENGAGING:
            await self._command_confirmed(
                f"mode {self.profile.offboard.name}",
                self._request_offboard_nowait,
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
            if await self._wait_until(ready, max(0.0, step_end - self.clock())):
                break
            if self._stop.is_set():
                raise LinkError("interrupted while waiting for the position estimate")
            now = self.clock()
            if now >= deadline:
                what = "no LOCAL_POSITION_NED / ODOMETRY" if self.pipeline.estimator.latest is None else "no ATTITUDE_QUATERNION"
                said = f"; autopilot: {self.last_statustext}" if self.last_statustext else ""
                raise LinkError(f"{what} from the vehicle within {now - start:.0f} s (is its position estimate ready? "
                                f"--ready-timeout S waits longer){said}")  # fmt: skip
            got = "position, waiting for attitude" if self.pipeline.estimator.latest is not None else "no position yet"
            self._print(f"waiting for the vehicle's position estimate: {got} ({now - start:.0f} s of up to {deadline - start:.0f} s)")
        est = self.pipeline.estimator.latest
        assert est is not None
        return est

    async def _proof_of_life(self) -> None:
        """PX4 accepts OFFBOARD only after a recent setpoint stream; wait for a few to go out."""
        start = self.sent_setpoints
        need = max(5, int(0.2 * self.options.setpoint_rate_hz))
        ok = await self._wait_until(lambda: self.sent_setpoints - start >= need, self.options.command_timeout_s)
        if not ok:
            raise LinkError("setpoint stream did not start (no fresh state samples)")

    async def _takeoff(self, est: StateEstimate, ready_deadline: float | None = None) -> None:
        opts = self.options
        # the heading of a sample that carries an attitude (see _first_state): never a default yaw
        self._takeoff_yaw = yaw_of(est.q_enu_flu) if est.q_enu_flu is not None else 0.0
        ready_left = None if ready_deadline is None else max(0.0, ready_deadline - self.clock())
        target = np.array([est.position_enu_m[0], est.position_enu_m[1], opts.height_m])
        if self.profile.autopilot is Autopilot.PX4:
            # fly the take-off ourselves in OFFBOARD: position setpoints are the proof of life
            self._takeoff_target = np.array([est.position_enu_m[0], est.position_enu_m[1], est.position_enu_m[2]])
            self.phase = Phase.TAKEOFF
            await self._proof_of_life()
            await self.set_mode(self.profile.offboard, self.profile.offboard_custom_mode, ready_left)
            if not is_armed(self.base_mode):
                await self.arm(None if ready_deadline is None else max(0.0, ready_deadline - self.clock()))
            self._takeoff_target = target
        else:
            # ArduPilot: GUIDED, arm, MAV_CMD_NAV_TAKEOFF (it ignores position targets on the
            # ground). Send nothing meanwhile: in GUIDED any setpoint would cancel the take-off.
            self.phase = Phase.TAKEOFF
            self._last_setpoint = None
            await self.set_mode(self.profile.offboard, self.profile.offboard_custom_mode, ready_left)
            if not is_armed(self.base_mode):
                await self.arm(None if ready_deadline is None else max(0.0, ready_deadline - self.clock()))
            self._command(mavlink2.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, opts.height_m)
        self._print(f"taking off to {opts.height_m:g} m")

        settle = self._settle = TakeoffSettle(opts.height_m)  # fed every state sample by _on_state

        def settled() -> bool:
            return settle.settled

        timeout = opts.takeoff_timeout_s if opts.takeoff_timeout_s is not None else 30.0 + 5.0 * opts.height_m
        if not await self._wait_until(lambda: settled() or self._stop.is_set(), timeout):
            e = self.pipeline.estimator.latest
            where = f" (at {e.position_enu_m[2]:.2f} m, {float(np.linalg.norm(e.velocity_enu_m_s)):.2f} m/s)" if e is not None else ""
            raise LinkError(f"take-off to {opts.height_m:g} m not held (within {settle.altitude_tol_m:g} m, below "
                            f"{settle.speed_tol_m_s:g} m/s over {settle.window_s:g} s) within {timeout:g} s{where}; "
                            "--takeoff-timeout S waits longer")  # fmt: skip
        if self._stop.is_set():
            raise LinkError("interrupted during take-off")
        self._takeoff_target = None
        self._settle = None

    async def _hand_back(self) -> None:
        """Stream the hold setpoint while asking for the hand-back mode, re-sent until the
        HEARTBEAT confirms it; then stop. (Not confirmed in time: safing retries it.)"""
        mode = self._end_mode()
        custom = self._custom_of(mode)
        self._print(f"{self._end_reason}; handing back in {mode.name}")
        self._stop.clear()
        await self.set_mode(mode, custom)
        self.phase = Phase.DONE
        self._last_setpoint = None
        self._finish(EXIT_OK, f"{self._end_reason}; handed back in {mode.name}")

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
        while self.phase not in _TERMINAL:
            await asyncio.sleep(period)
            now = self.clock()
            phase = self.phase
            if phase is Phase.SAFING:
                if self._safe_msg is not None and now - self._last_send_wall >= period:
                    self._send(self._safe_msg)
                continue
            if phase in _TERMINAL:
                return
            silent = now - self._last_heartbeat_wall
            if self._in_control() and phase is not Phase.WAITING and silent > self.safety.heartbeat_timeout_s:
                self._enter_safing(EXIT_LINK, f"no HEARTBEAT from the autopilot for {silent:.2f} s (safety.heartbeat_timeout_s {self.safety.heartbeat_timeout_s:g}): mode unknown")
                continue
            if phase in (Phase.FOLLOWING, Phase.ENGAGING) and now - self._last_fresh_wall > self.options.state_timeout_s:
                self._enter_safing(EXIT_LINK, f"state went stale: no fresh state for {now - self._last_fresh_wall:.2f} s (state_timeout_s {self.options.state_timeout_s:g})")
                continue
            preflight = phase is Phase.PREFLIGHT and self._neutral_allowed()
            if preflight and (self._last_setpoint is None or now - self._last_send_wall >= period):
                self._send_neutral()
            elif self._last_setpoint is not None and now - self._last_send_wall >= KEEPALIVE_S:
                flying = phase in (Phase.FOLLOWING, Phase.ENGAGING, Phase.HANDING_BACK)
                self._send(self._safe_setpoint(self.pipeline.estimator.latest) if flying else self._last_setpoint)

    async def heartbeat(self) -> None:
        while self.phase not in _TERMINAL:
            self.link.send_heartbeat()
            await asyncio.sleep(1.0)

    async def status_line(self) -> None:
        tty = self.status_stream.isatty()
        period = 0.2 if tty else 1.0
        last = self.clock()
        try:
            while self.phase not in (Phase.DONE, Phase.TAKEN_OVER, Phase.FAILED):
                await asyncio.sleep(period)
                now = self.clock()
                self.loop_rate_hz, self._rate_count, last = self._rate_count / max(now - last, 1e-9), 0, now
                if self.options.status:
                    line = self.status_text()
                    self.status_stream.write(f"\r{line}\x1b[K" if tty else line + "\n")
                    self.status_stream.flush()
        finally:  # also when cancelled at the end of the flight
            if self.options.status and tty:
                self.status_stream.write("\n")

    def status_text(self) -> str:
        mode = self.profile.mode_name(self.custom_mode) if self.custom_mode is not None else "?"
        armed = "armed" if is_armed(self.base_mode) else "disarmed"
        head = f"[{self.phase.value}] {mode} {armed}"
        step = self.last_step
        if step is None or step.command is None:
            return f"{head}  rate {self.loop_rate_hz:5.0f} Hz"
        st = step.command.state
        return (
            f"{head}  η1 {st.eta1:7.2f} m  η2 {st.eta2:+5.2f} m/s  ξ1 {st.xi1:+6.3f} m  φ1 {st.phi1:+6.3f} m  "
            f"e {step.command.cross_track_m:6.3f} m  laps {self.laps.laps:4.2f}  rate {self.loop_rate_hz:5.0f} Hz"
        )

    def _note(self, text: str) -> None:
        """One line on the status stream even with --quiet (facts the user must know)."""
        self.status_stream.write(("\r\x1b[K" if self.status_stream.isatty() else "") + text + "\n")
        self.status_stream.flush()

    def _print(self, text: str) -> None:
        if self.options.status:
            self.status_stream.write(("\r\x1b[K" if self.status_stream.isatty() else "") + text + "\n")
            self.status_stream.flush()
