"""The mock autopilot as a pure state machine: MAVLink message in → messages out, step → physics.

No sockets and no wall clock here: :class:`Autopilot` advances only when :meth:`Autopilot.step`
is called (simulated time), so it is testable without networking and deterministic for a seed.
The asyncio server (:mod:`sitl_mock.server`) feeds it messages and sends what it returns.

Links are small integers chosen by the caller; outgoing messages are ``(link, message)`` pairs,
``link`` None meaning every link. Position control runs in the *estimated* local frame
(truth + estimator offset, see :meth:`inject_estimator_reset`).
"""

from __future__ import annotations

import collections
import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock import telemetry
from sitl_mock.config import MockConfig, MockConfigError

MAX_LOG_EVENTS = 10_000
from sitl_mock.control import (
    PX4_GAINS,
    ArduGuided,
    level_attitude,
    px4_trajectory_accel,
    thrust_for_climb,
)
from sitl_mock.dynamics import (
    AccelerationSetpoint,
    AttitudeSetpoint,
    MotorsOff,
    PositionSetpoint,
    RateSetpoint,
    Setpoint,
    Simulator,
    Spawn,
    VehicleState,
    preset,
)
from sitl_mock.profiles import (
    ACCEL_DECOUPLE_PARAM,
    PROFILES,
    TILT_LIMIT_PARAMS,
    Behaviour,
    ModeSpec,
    ParamType,
)
from sitl_mock.rotations import euler_from_q
from sitl_mock.setpoints import (
    AttitudeTarget,
    BrakeAndHover,
    Rejected,
    TrajectoryTarget,
    ardupilot_attitude_target,
    ardupilot_position_target,
    px4_attitude_target,
    px4_position_target,
)

Out = tuple[int | None, mavlink.MAVLink_message]

SETPOINT_IDS = frozenset(
    {mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED, mavlink.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET}
)
FORCE_MAGIC = 21196  # MAV_CMD_COMPONENT_ARM_DISARM param2: force
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMP_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink.MAV_RESULT_DENIED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
FAILED = mavlink.MAV_RESULT_FAILED


# ArduPilot's REQUEST_DATA_STREAM groups → the messages of each group the mock can send.
_DATA_STREAMS: Mapping[int, tuple[int, ...]] = MappingProxyType({
    mavlink.MAV_DATA_STREAM_EXTENDED_STATUS: (mavlink.MAVLINK_MSG_ID_SYS_STATUS, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE),
    mavlink.MAV_DATA_STREAM_RAW_SENSORS: (mavlink.MAVLINK_MSG_ID_HIGHRES_IMU,),
    mavlink.MAV_DATA_STREAM_POSITION: (mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    mavlink.MAV_DATA_STREAM_EXTRA1: (mavlink.MAVLINK_MSG_ID_ATTITUDE,),
    mavlink.MAV_DATA_STREAM_EXTRA2: (mavlink.MAVLINK_MSG_ID_VFR_HUD,),
})


@dataclass(frozen=True)
class LogEvent:
    """Something the autopilot did, for the CLI log and for tests (simulated time)."""

    time_s: float
    text: str


def tilt_limit_params(profile: str, vehicle: Any) -> dict[str, float]:
    """The tilt limit parameters a ``profile`` mock reports for ``vehicle`` (before any PARAM_SET),
    as they arrive over MAVLink: the first of the profile's non-zero ones carries the vehicle's
    ``tilt_max_rad`` (PX4 MPC_TILTMAX_AIR deg as float32; ArduPilot ANGLE_MAX cdeg, PSC_ANGLE_MAX 0)."""
    specs = [spec for spec in PROFILES[profile].params if spec.name in TILT_LIMIT_PARAMS]
    out = {spec.name: float(spec.default) for spec in specs}
    for spec in specs:
        if spec.default != 0.0:
            value = math.degrees(vehicle.tilt_max_rad) / TILT_LIMIT_PARAMS[spec.name]
            out[spec.name] = float(round(value)) if spec.kind is ParamType.INT32 else float(np.float32(value))
            break
    return out


class Autopilot:
    """PX4- or ArduPilot-like autopilot around a :class:`sitl_mock.dynamics.Simulator`."""

    def __init__(self, config: MockConfig, rng: np.random.Generator | None = None) -> None:
        config.validate()
        self.config = config
        self.profile = PROFILES[config.profile]
        rng = rng if rng is not None else config.rng()
        rng_dyn, self.rng_faults = rng.spawn(2)
        vehicle = preset(config.vehicle)
        self.params: dict[str, float] = {p.name: float(p.default) for p in self.profile.params}
        self._param_kinds = {p.name: p.kind for p in self.profile.params}
        self._param_names = sorted(self.params)
        self.params[self.profile.hover_param] = vehicle.hover_thrust
        if ACCEL_DECOUPLE_PARAM in self.params:
            self.params[ACCEL_DECOUPLE_PARAM] = 1.0 if vehicle.accel_decouple else 0.0
        self.params.update(tilt_limit_params(config.profile, vehicle))
        spawn = config.spawn
        if spawn.kind == "hover":
            dyn_spawn = Spawn.hover(spawn.position_ned_m)
        elif spawn.kind == "throw":
            dyn_spawn = Spawn.thrown(spawn.position_ned_m, spawn.velocity_ned_m_s, spawn.rates_frd_rad_s, spawn.q_ned_frd)
        else:
            dyn_spawn = Spawn.ground(spawn.position_ned_m)
        self.sim = Simulator(vehicle, rng_dyn, dyn_spawn, wind=config.wind())
        for name, value in config.params:  # like PX4_PARAM_* / a parameter file: before anything flies
            if name not in self.params or not self._set_param(name, float(value)):
                raise MockConfigError("params", f"{name} = {value!r} unknown to the {config.profile} mock or out of its range")
        for push in config.pushes:
            self.sim.add_push(push)
        self.truth: VehicleState = self.sim.state()
        self._position_sp_cache: tuple[object, PositionSetpoint | None] = (None, None)
        self._estimate_cache: tuple[object, int, tuple[np.ndarray, np.ndarray, float]] = (None, -1, (np.zeros(3), np.zeros(3), 0.0))
        self.time_s = 0.0
        self.est_offset_ned_m = np.zeros(3)
        self.reset_counter = 0
        # the latest events only: setpoints ignored outside OFFBOARD / GUIDED log one each, and an
        # hour-long run must not grow without bound
        self.log: collections.deque[LogEvent] = collections.deque(maxlen=MAX_LOG_EVENTS)
        self.streams: dict[int, telemetry.StreamTable] = {}
        # Mode state.
        self.armed = spawn.kind in ("hover", "throw")
        self.motors_locked = spawn.kind == "throw"
        self.mode: ModeSpec = self.profile.mode(self.profile.initial_mode)
        self.user_mode: ModeSpec = self.mode  # PX4 "user intention" (restored after a failsafe)
        self.failsafe = False
        self.took_off = not self.truth.landed
        self.arm_time_s = 0.0
        self.landed_since_s = 0.0
        # Targets (estimated frame).
        self.hold_position = np.array(self.truth.position_ned_m, dtype=float)
        _, _, yaw = euler_from_q(self.truth.q_ned_frd)
        self.hold_yaw = yaw
        self.auto_phase = ""
        self.auto_target = self.hold_position.copy()
        self.last_setpoint_s = -math.inf  # PX4 offboard signal ("proof of life")
        self.px4_target: TrajectoryTarget | AttitudeTarget | None = None
        self.guided = ArduGuided()
        self.position_target_echo: tuple[int, list[float]] | None = None
        self.echo_unsent: tuple[int, list[float]] | None = None  # PX4: published, not yet streamed
        self.rc_throttle: float | None = config.rc_throttle  # the pilot's stick (tests move it)
        self._dyn_setpoint: Setpoint = MotorsOff()
        if spawn.kind == "hover":
            # Already flying, as a pilot would hand it over: PX4 AUTO.LOITER, ArduCopter LOITER.
            self._set_mode(self.profile.mode(self.profile.hold_mode), user=True)
        elif spawn.kind == "throw" and self.profile.name == "ardupilot":
            self.mode = self.user_mode = self.profile.mode("GUIDED")
        # Scheduled injections (simulated time).
        f = config.faults
        self._pending: list[tuple[float, str, object]] = []
        if f.takeover_at_s is not None:
            self._pending.append((f.takeover_at_s, "takeover", f.takeover_mode))
        self._takeover_above_m = f.takeover_above_m  # None once fired (or never set)
        if f.estimator_reset_at_s is not None:
            self._pending.append((f.estimator_reset_at_s, "reset", f.estimator_reset_ned_m))
        if f.gust_at_s is not None:
            self.sim.add_gust(f.gust_at_s, f.gust_duration_s, f.gust_ned_m_s)
        if f.disarm_at_s is not None:
            self._pending.append((f.disarm_at_s, "disarm", None))
        if f.motor_failure_at_s is not None:
            self._pending.append((f.motor_failure_at_s, "motor_failure", None))
        if f.clock_jump_at_s is not None:
            self._pending.append((f.clock_jump_at_s, "clock_jump", f.clock_jump_s))
        if f.attitude_future_at_s is not None:
            self._pending.append((f.attitude_future_at_s, "future_attitude", f.attitude_future_by_s))
        if f.thrust_loss_at_s is not None:
            self._pending.append((f.thrust_loss_at_s, "thrust_loss", f.thrust_loss_factor))
        if f.offboard_stuck_at_s is not None:
            self._pending.append((f.offboard_stuck_at_s, "offboard_stuck", None))
        if f.estimate_lost_at_s is not None:
            self._pending.append((f.estimate_lost_at_s, "estimate_lost", None))
        if f.failsafe_at_s is not None:
            self._pending.append((f.failsafe_at_s, "failsafe", f.failsafe_mode))
        for item in f.corrupt_states:
            self._pending.append((item[0], "corrupt_state", tuple(item[1:])))
        self.estimate_lost = False  # estimate-lost fault: ODOMETRY quality -1, bad estimator reports, drift
        self._next_health_report_s = 0.0
        self.failsafe_kind = ""  # "offboard" (PX4 offboard loss: undone when setpoints resume) | "battery"
        self.motors_failed = False  # a motor failure: no thrust whatever the mode (the vehicle falls)
        self.clock_offset_s = f.clock_at_start_s  # added to every timestamp sent (clock faults)
        self.offboard_stuck_at: np.ndarray | None = None  # offboard-stuck fault: where it holds (estimate)
        self.fault_injector: Any = None  # set by the server: told when OFFBOARD / GUIDED is first entered

    # ------------------------------------------------------------------------------------------
    # Derived state
    # ------------------------------------------------------------------------------------------
    @property
    def est_position_ned_m(self) -> np.ndarray:
        """Reported position: truth + estimator resets + the preset's EKF-like error (NED, m)."""
        return self._estimate()[0]

    @property
    def est_velocity_ned_m_s(self) -> np.ndarray:
        """Reported velocity: truth + the preset's EKF-like error (NED, m/s)."""
        return self._estimate()[1]

    @property
    def reported_time_s(self) -> float:
        """The autopilot's clock as its messages report it (time since boot, plus any clock jump)."""
        return self.time_s + self.clock_offset_s

    @property
    def ekf_ready(self) -> bool:
        # A vehicle spawned in the air (hovering, or armed for a throw) has a converged estimator;
        # only a ground spawn waits for it, as ArduCopter SITL does after boot.
        if self.config.spawn.kind != "ground":
            return True
        return self.time_s >= self.config.ekf_ready_delay_s

    @property
    def hover_thrust(self) -> float:
        """The hover thrust the autopilot's own controllers fly: its acceleration mapping's (the
        parameter as written through MAVLink; PX4's hover-thrust estimate converged on it). The
        parameter as *reported* may differ when a test sets ``params`` directly: PX4's estimator
        never writes MPC_THR_HOVER back."""
        return self.sim.params.hover_thrust

    @property
    def base_mode(self) -> int:
        flags = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | self.mode.base_flags
        return flags | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)

    @property
    def system_status(self) -> int:
        if self.failsafe:
            return mavlink.MAV_STATE_CRITICAL
        return mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY

    @property
    def landed_state(self) -> int:
        if self.truth.landed:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.armed and self.mode.behaviour is Behaviour.TAKEOFF:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if self.armed and (self.mode.behaviour is Behaviour.LAND or self.auto_phase == "land"):
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def offboard_signal_ok(self) -> bool:
        """PX4: a setpoint arrived within COM_OF_LOSS_T (scaled like PX4 does under speed-up)."""
        timeout = self.params.get("COM_OF_LOSS_T", 1.0) * self.config.timeouts_scale
        return self.time_s < self.last_setpoint_s + timeout

    # ------------------------------------------------------------------------------------------
    # Links and streams
    # ------------------------------------------------------------------------------------------
    def add_link(self, link: int) -> None:
        self.streams[link] = telemetry.StreamTable(self.profile.streams, self.time_s)

    def remove_link(self, link: int) -> None:
        self.streams.pop(link, None)

    def due_telemetry(self) -> list[Out]:
        """Messages whose stream interval fell due at the current simulated time, per link."""
        out: list[Out] = []
        cache: dict[int, mavlink.MAVLink_message | None] = {}
        for link, table in self.streams.items():
            for msgid in table.due(self.time_s):
                if msgid not in cache:
                    cache[msgid] = self.build(msgid)
                msg = cache[msgid]
                if msg is not None:
                    out.append((link, msg))
        return out

    def build(self, msgid: int) -> mavlink.MAVLink_message | None:
        builder = telemetry.BUILDERS.get(msgid)
        if builder is None:
            return None
        if msgid in telemetry.NEEDS_POSITION and not self.ekf_ready and self.profile.name == "ardupilot":
            return None
        return builder(self)

    # ------------------------------------------------------------------------------------------
    # Injections (Python API / CLI / scheduled faults)
    # ------------------------------------------------------------------------------------------
    def inject_takeover(self, mode_name: str | None = None) -> list[Out]:
        """An operator (RC / ground station) switches mode; offboard setpoints are then ignored."""
        spec = self.profile.mode(mode_name or self._takeover_default())
        self._set_mode(spec, user=True)
        self.motors_locked = False
        return [self._text(mavlink.MAV_SEVERITY_WARNING, f"Takeover: mode {spec.name}")]

    def _takeover_default(self) -> str:
        return "POSCTL" if self.profile.name == "px4" else "LOITER"

    def inject_estimator_reset(self, delta_ned_m: tuple[float, float, float]) -> list[Out]:
        """Jump the position estimate by ``delta_ned_m`` and bump ODOMETRY.reset_counter."""
        delta = np.array(delta_ned_m, dtype=float)
        if not np.all(np.isfinite(delta)):
            raise ValueError("inject_estimator_reset.delta_ned_m: values must be finite")
        self.est_offset_ned_m = self.est_offset_ned_m + delta
        self.reset_counter += 1
        # The autopilot's own targets move with the estimate (the vehicle does not jump).
        self.hold_position = self.hold_position + delta
        self.auto_target = self.auto_target + delta
        self.guided.hold_position = self.guided.hold_position + delta
        self.guided.pos_t = self.guided.pos_t + delta
        return [self._text(mavlink.MAV_SEVERITY_INFO, f"EKF position reset #{self.reset_counter}")]

    def inject_gust(self, velocity_ned_m_s: tuple[float, float, float], duration_s: float = 1.0) -> None:
        self.sim.add_gust(self.time_s, duration_s, velocity_ned_m_s)

    def _text(self, severity: int, text: str) -> Out:
        self.log.append(LogEvent(self.time_s, text))
        return (None, mavlink.MAVLink_statustext_message(severity, text.encode()[:50]))

    # ------------------------------------------------------------------------------------------
    # Incoming messages
    # ------------------------------------------------------------------------------------------
    def handle(self, msg: mavlink.MAVLink_message, link: int) -> list[Out]:
        """Process one received message; returns the replies (and broadcasts)."""
        msgid = msg.get_msgId()
        if msgid == mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED:
            return self._on_position_target(msg) if self._for_me(msg) else []
        if msgid == mavlink.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET:
            return self._on_attitude_target(msg) if self._for_me(msg) else []
        if msgid in (mavlink.MAVLINK_MSG_ID_COMMAND_LONG, mavlink.MAVLINK_MSG_ID_COMMAND_INT):
            return self._on_command(msg, link) if self._for_me(msg) else []
        if msgid == mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST:
            return [(link, self._param_value(name)) for name in self._param_names] if self._for_me(msg) else []
        if msgid == mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            return self._on_param_read(msg, link) if self._for_me(msg) else []
        if msgid == mavlink.MAVLINK_MSG_ID_PARAM_SET:
            return self._on_param_set(msg) if self._for_me(msg) else []
        if msgid == mavlink.MAVLINK_MSG_ID_REQUEST_DATA_STREAM and self.profile.name == "ardupilot":
            if self._for_me(msg):
                self._on_request_data_stream(msg, link)
            return []
        if msgid == mavlink.MAVLINK_MSG_ID_PING and msg.target_system == 0:
            # A ping request: answer it addressed to the sender.
            reply = mavlink.MAVLink_ping_message(msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent())
            return [(link, reply)]
        if msgid == mavlink.MAVLINK_MSG_ID_TIMESYNC and msg.tc1 == 0:
            return [(link, mavlink.MAVLink_timesync_message(int(self.reported_time_s * 1e9), msg.ts1))]
        return []

    @staticmethod
    def _for_me(msg: mavlink.MAVLink_message) -> bool:
        system = getattr(msg, "target_system", 0)
        component = getattr(msg, "target_component", 0)
        return system in (0, 1) and component in (0, 1)

    def _estimate(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(position, velocity, yaw) as the estimator reports them; cached per vehicle state."""
        truth = self.truth
        if self._estimate_cache[0] is not truth or self._estimate_cache[1] != self.reset_counter:
            _, _, yaw = euler_from_q(truth.q_ned_frd)
            err_p, err_v = self.sim.estimate_error()
            estimate = (truth.position_ned_m + self.est_offset_ned_m + err_p,
                        np.asarray(truth.velocity_ned_m_s) + err_v, yaw)
            self._estimate_cache = (truth, self.reset_counter, estimate)
        return self._estimate_cache[2]

    def _on_position_target(self, msg: mavlink.MAVLink_message) -> list[Out]:
        pos, vel, yaw = self._estimate()
        if self.profile.name == "px4":
            target = px4_position_target(msg, pos, yaw)
            if isinstance(target, Rejected):
                self.log.append(LogEvent(self.time_s, f"SET_POSITION_TARGET_LOCAL_NED ignored: {target.reason}"))
                return []
            self.last_setpoint_s = self.time_s  # counts as offboard signal in any mode
            if self.mode.behaviour is Behaviour.OFFBOARD:  # trajectory_setpoint only in OFFBOARD
                self.px4_target = target
                self._echo_position_target(msg)
            return []
        if self.mode.behaviour is not Behaviour.OFFBOARD:
            return []  # ArduPilot: only in GUIDED
        target = ardupilot_position_target(msg, pos, yaw)
        if isinstance(target, Rejected):
            self.log.append(LogEvent(self.time_s, f"SET_POSITION_TARGET_LOCAL_NED ignored: {target.reason}"))
            return []
        self.guided.set_trajectory(target, self.time_s, pos, vel)
        self.motors_locked = False
        self._echo_position_target(msg)
        return []

    def _echo_position_target(self, msg: mavlink.MAVLink_message) -> None:
        values = [msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, msg.afx, msg.afy, msg.afz, msg.yaw, msg.yaw_rate]
        self.position_target_echo = (int(msg.type_mask), [float(v) for v in values])
        # PX4 streams the latest setpoint its position controller published since the last send (a
        # uORB topic): one run on a setpoint is echoed even if an attitude target follows at once
        self.echo_unsent = self.position_target_echo if self.profile.name == "px4" else None

    def _on_attitude_target(self, msg: mavlink.MAVLink_message) -> list[Out]:
        if self.profile.name == "px4":
            target = px4_attitude_target(msg)
            if isinstance(target, Rejected):
                self.log.append(LogEvent(self.time_s, f"SET_ATTITUDE_TARGET ignored: {target.reason}"))
                return []
            self.last_setpoint_s = self.time_s
            if self.mode.behaviour is Behaviour.OFFBOARD:
                self.px4_target = target
                self.position_target_echo = None  # the position controller is off: nothing echoed
            return []
        if self.mode.behaviour is not Behaviour.OFFBOARD:
            return []
        result = ardupilot_attitude_target(
            msg,
            thrust_is_thrust=bool(int(self.params["GUID_OPTIONS"]) & 8),
            speed_up_m_s=self.params["WPNAV_SPEED_UP"] / 100.0,
            speed_down_m_s=self.params["WPNAV_SPEED_DN"] / 100.0,
        )
        if isinstance(result, Rejected):
            self.log.append(LogEvent(self.time_s, f"SET_ATTITUDE_TARGET ignored: {result.reason}"))
            return []
        pos, vel, yaw = self._estimate()
        if isinstance(result, BrakeAndHover):
            self.log.append(LogEvent(self.time_s, f"SET_ATTITUDE_TARGET: brake and hover ({result.reason})"))
            self.guided.hold(pos, vel, yaw)
            return []
        self.guided.set_angle(result, self.time_s)
        self.position_target_echo = None  # the angle sub-mode has no local target: nothing echoed
        self.motors_locked = False
        return []

    def _on_request_data_stream(self, msg: mavlink.MAVLink_message, link: int) -> None:
        """ArduPilot's legacy stream groups (SRx_ parameters); PX4 ignores this message."""
        table = self.streams.get(link)
        if table is None:
            return
        groups = [msg.req_stream_id] if msg.req_stream_id != mavlink.MAV_DATA_STREAM_ALL else list(_DATA_STREAMS)
        rate = float(msg.req_message_rate)
        for group in groups:
            for msgid in _DATA_STREAMS.get(group, ()):
                if msg.start_stop and rate > 0:
                    table.set_interval(msgid, max(1.0 / rate, self._step_dt()), self.time_s)
                else:
                    table.set_interval(msgid, math.inf, self.time_s)

    # --- parameters ---------------------------------------------------------------------------
    def _param_value(self, name: str) -> mavlink.MAVLink_message:
        value = self.params[name]
        kind = self._param_kinds[name]
        if kind is ParamType.INT32 and self.profile.bytewise_params:
            wire = struct.unpack("<f", struct.pack("<i", int(value)))[0]
        else:
            wire = float(value)
        return mavlink.MAVLink_param_value_message(
            name.encode(), wire, int(kind), len(self._param_names), self._param_names.index(name)
        )

    @staticmethod
    def _param_id(raw: bytes | str) -> str:
        text = raw.decode(errors="replace") if isinstance(raw, bytes) else str(raw)
        return text.split("\x00", 1)[0]

    def _on_param_read(self, msg: mavlink.MAVLink_message, link: int) -> list[Out]:
        if msg.param_index >= 0:
            if msg.param_index >= len(self._param_names):
                return []
            name = self._param_names[msg.param_index]
        else:
            name = self._param_id(msg.param_id)
        return [(link, self._param_value(name))] if name in self.params else []

    def _on_param_set(self, msg: mavlink.MAVLink_message) -> list[Out]:
        name = self._param_id(msg.param_id)
        if name not in self.params:
            return []  # unknown parameter: both autopilots stay silent
        kind = self._param_kinds[name]
        value = float(msg.param_value)
        if kind is ParamType.INT32 and self.profile.bytewise_params:
            value = float(struct.unpack("<i", struct.pack("<f", value))[0])
        self._set_param(name, value)  # refused (non-finite, out of range): the unchanged value is reported
        return [(None, self._param_value(name))]

    def _set_param(self, name: str, value: float) -> bool:
        """Set a known parameter (INT32 truncated here); False (unchanged) when refused."""
        if not math.isfinite(value):
            return False
        if self._param_kinds[name] is ParamType.INT32:
            value = float(int(value))
        if name == self.profile.hover_param:
            if not 0.05 <= value <= 0.95:
                return False
            # The acceleration mapping uses the autopilot's parameter, as PX4/ArduPilot do.
            self.sim.params = self.sim.params.with_(hover_thrust=value)
        if name == ACCEL_DECOUPLE_PARAM:
            if value not in (0.0, 1.0):
                return False
            self.sim.params = self.sim.params.with_(accel_decouple=value == 1.0)
        if name in TILT_LIMIT_PARAMS:
            deg = value * TILT_LIMIT_PARAMS[name]
            if not 0.0 <= deg < 90.0 or (deg == 0.0 and name != "PSC_ANGLE_MAX"):
                return False
            self.params[name] = value
            self.sim.params = self.sim.params.with_(tilt_max_rad=math.radians(self._tilt_limit_deg()))
        self.params[name] = value
        return True

    def _tilt_limit_deg(self) -> float:
        """The acceleration path's tilt limit from the parameters: the first positive one rules
        (PX4 MPC_TILTMAX_AIR; ArduPilot PSC_ANGLE_MAX, else ANGLE_MAX)."""
        for name, deg_per_unit in TILT_LIMIT_PARAMS.items():
            value = self.params.get(name, 0.0)
            if value > 0.0:
                return value * deg_per_unit
        return math.degrees(self.sim.params.tilt_max_rad)

    # --- commands -----------------------------------------------------------------------------
    def _on_command(self, msg: mavlink.MAVLink_message, link: int) -> list[Out]:
        is_int = msg.get_msgId() == mavlink.MAVLINK_MSG_ID_COMMAND_INT
        p = [float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4)]
        p += [float(msg.x), float(msg.y), float(msg.z)] if is_int else [msg.param5, msg.param6, msg.param7]
        # NaN in a parameter that is read as an integer counts as 0 (unused / default).
        p = [v if math.isfinite(v) else (v if i == 6 else 0.0) for i, v in enumerate(map(float, p))]
        command = int(msg.command)
        foreign: list[Out] = []
        if self.config.faults.foreign_denied_ack and command == mavlink.MAV_CMD_DO_SET_MODE:
            foreign = [(None, mavlink.MAVLink_command_ack_message(command, mavlink.MAV_RESULT_DENIED, 0, 0, 255, 190))]
        result, extra = self._dispatch(command, p, link)

        ack = mavlink.MAVLink_command_ack_message(
            command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
        )
        return [(link, ack)] + foreign + extra

    def _dispatch(self, command: int, p: list[float], link: int) -> tuple[int, list[Out]]:
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            return self._cmd_arm(p[0] > 0.5, int(p[1]) == FORCE_MAGIC)
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            return self._cmd_set_mode(p)
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            return self._cmd_takeoff(p[6])
        if command == mavlink.MAV_CMD_NAV_LAND:
            return self._cmd_mode_named(self.profile.land_mode)
        if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._cmd_mode_named(self.profile.rtl_mode)
        if command == mavlink.MAV_CMD_NAV_LOITER_UNLIM and self.profile.name == "px4":
            return self._cmd_mode_named("AUTO.LOITER")
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._cmd_message_interval(int(p[0]), p[1], link), []
        if command == mavlink.MAV_CMD_GET_MESSAGE_INTERVAL:
            interval = self.streams[link].interval_s(int(p[0])) if link in self.streams else math.inf
            us = -1 if math.isinf(interval) else int(round(interval * 1e6))
            return ACCEPTED, [(link, mavlink.MAVLink_message_interval_message(int(p[0]), us))]
        if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            built = self.build(int(p[0]))
            if built is not None:
                return ACCEPTED, [(link, built)]
            # a message we know but cannot send yet (HOME_POSITION / GPS_GLOBAL_ORIGIN before the
            # EKF has a position): FAILED, as the autopilots answer; an unknown one: UNSUPPORTED
            return (mavlink.MAV_RESULT_FAILED if int(p[0]) in telemetry.BUILDERS else UNSUPPORTED), []
        if command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return ACCEPTED, [(link, telemetry.autopilot_version(self))]
        if command == mavlink.MAV_CMD_GET_HOME_POSITION:
            return ACCEPTED, [(link, telemetry.home_position(self))]
        return UNSUPPORTED, []

    def _refuse(self, text: str) -> tuple[int, list[Out]]:
        result = TEMP_REJECTED if self.profile.name == "px4" else FAILED
        return result, [self._text(mavlink.MAV_SEVERITY_CRITICAL, text)]

    def _arming_failure(self) -> str | None:
        """Why arming would be refused now (None: the checks pass)."""
        px4 = self.profile.name == "px4"
        if not self.ekf_ready:
            return "Arming denied: no position estimate" if px4 else "PreArm: Need Position Estimate"
        if not self.mode.armable or self.mode.behaviour in (Behaviour.LAND, Behaviour.RTL):
            return f"Arming denied: not in an armable mode ({self.mode.name})" if px4 else "Arm: Mode not armable"
        if px4 and self.mode.behaviour is Behaviour.OFFBOARD and not self.offboard_signal_ok():
            return "Arming denied: offboard signal lost"
        return None

    def arming_checks_pass(self) -> bool:
        return self._arming_failure() is None

    def _cmd_arm(self, arm: bool, force: bool) -> tuple[int, list[Out]]:
        px4 = self.profile.name == "px4"
        if arm:
            if self.armed:
                return ACCEPTED, []
            # PX4 runs the preflight checks for external (MAVLink) commands even when forced.
            failure = self._arming_failure() if (not force or px4) else None
            if failure is not None:
                return self._refuse(failure)
            self.armed = True
            self.took_off = not self.truth.landed
            self.arm_time_s = self.landed_since_s = self.time_s
            if self.mode.behaviour is Behaviour.HOLD:
                self._enter(self.mode)
            return ACCEPTED, [self._text(mavlink.MAV_SEVERITY_INFO, "Armed by external command" if px4 else "Arming motors")]
        if not self.armed:
            return ACCEPTED, []
        if not self.truth.landed and not force:
            return self._refuse("Disarming denied: not landed" if px4 else "Disarm: vehicle is flying")
        self._disarm("Disarmed by external command" if px4 else "Disarming motors")
        return ACCEPTED, []

    def _disarm(self, why: str) -> None:
        self.armed = False
        self.motors_locked = False
        self.failsafe = False
        self.log.append(LogEvent(self.time_s, why))

    def _cmd_set_mode(self, p: list[float]) -> tuple[int, list[Out]]:
        window = self.config.faults.mode_refused_s
        if window is not None and window[0] <= self.time_s < window[1]:
            return TEMP_REJECTED, []  # fault injection: a busy autopilot
        if not int(p[0]) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return DENIED, []  # base-mode-only switching is not modelled
        if self.profile.name == "px4":
            main, sub = int(p[1]), int(p[2])
            spec = self.profile.mode_by_custom((main << 16) | ((sub if main == 4 else 0) << 24))
        else:
            spec = self.profile.mode_by_custom(int(p[1]))
        if spec is None:  # PX4: "Unsupported auto mode" → TEMPORARILY_REJECTED
            return (TEMP_REJECTED if self.profile.name == "px4" else FAILED), []
        return self._cmd_mode(spec)

    def _cmd_mode_named(self, name: str) -> tuple[int, list[Out]]:
        return self._cmd_mode(self.profile.mode(name))

    def _cmd_mode(self, spec: ModeSpec) -> tuple[int, list[Out]]:
        px4 = self.profile.name == "px4"
        if spec.behaviour is Behaviour.OFFBOARD and px4 and self.armed and not self.offboard_signal_ok():
            # Disarmed, PX4 accepts the switch (the arming check then needs the signal).
            return self._refuse("Switching to Offboard is currently not available")
        if not px4 and spec.behaviour in (Behaviour.OFFBOARD, Behaviour.HOLD, Behaviour.RTL) and not self.ekf_ready:
            return FAILED, [self._text(mavlink.MAV_SEVERITY_WARNING, "Mode change failed: requires position")]
        self._set_mode(spec, user=True)
        self.motors_locked = False
        return ACCEPTED, []

    def _cmd_takeoff(self, altitude_param: float) -> tuple[int, list[Out]]:
        pos, _, yaw = self._estimate()
        if self.profile.name == "px4":
            if math.isfinite(altitude_param):
                alt = altitude_param - self.config.home_alt_m
            else:
                alt = self.params["MIS_TAKEOFF_ALT"]
            alt = max(alt, 1.0)
            self._set_mode(self.profile.mode("AUTO.TAKEOFF"), user=True)
            self.auto_target = np.array([pos[0], pos[1], -alt])
            return ACCEPTED, []
        # ArduCopter: GUIDED, armed, on the ground, altitude > 0 (relative).
        if self.mode.behaviour is not Behaviour.OFFBOARD or not self.armed:
            return FAILED, [self._text(mavlink.MAV_SEVERITY_WARNING, "Takeoff: must be armed in GUIDED")]
        if self.took_off and not self.truth.landed:
            return FAILED, []
        if not (math.isfinite(altitude_param) and altitude_param > 0):
            return FAILED, []
        self.guided.takeoff(pos, altitude_param, yaw)
        return ACCEPTED, []

    def _cmd_message_interval(self, msgid: int, interval_us: float, link: int) -> int:
        table = self.streams.get(link)
        if table is None or msgid not in telemetry.BUILDERS:
            return UNSUPPORTED
        if msgid == mavlink.MAVLINK_MSG_ID_HEARTBEAT and self.config.faults.heartbeat_rate_fixed:
            return DENIED
        if interval_us == -1:
            table.set_interval(msgid, math.inf, self.time_s)
        elif interval_us == 0:
            table.set_interval(msgid, None, self.time_s)
        elif interval_us > 0 and math.isfinite(interval_us):
            # At most one per autopilot step; in real time also the autopilot's own cap. In lockstep
            # a client may ask for one message per step whatever the step.
            cap = self._step_dt() if self.config.lockstep else max(1.0 / self.profile.max_rate_hz, self._step_dt())
            table.set_interval(msgid, max(interval_us * 1e-6, cap), self.time_s)
        else:
            return DENIED
        return ACCEPTED

    def _step_dt(self) -> float:
        return self.config.lockstep_dt_s if self.config.lockstep else self.config.step_dt_s

    # ------------------------------------------------------------------------------------------
    # Modes
    # ------------------------------------------------------------------------------------------
    def _set_mode(self, spec: ModeSpec, user: bool) -> None:
        if user:
            self.user_mode = spec
            self.failsafe = False
        if spec != self.mode:
            self.log.append(LogEvent(self.time_s, f"mode {self.mode.name} -> {spec.name}"))
        previous = self.mode
        self.mode = spec
        if spec.behaviour is Behaviour.OFFBOARD and self.fault_injector is not None:
            self.fault_injector.start_windows(self.time_s)
        if spec != previous or spec.behaviour is not Behaviour.OFFBOARD:
            self._enter(spec)

    def _enter(self, spec: ModeSpec) -> None:
        pos, vel, yaw = self._estimate()
        speed = float(np.linalg.norm(vel))
        self.hold_position = pos + vel * speed / (2.0 * 3.0)  # stopping point at ~3 m/s²
        self.hold_yaw = yaw
        self.auto_phase = ""
        if spec.behaviour is Behaviour.OFFBOARD:
            self.px4_target = None
            self.guided.hold(pos, vel, yaw)
        elif spec.behaviour is Behaviour.LAND:
            # brake to the stopping point, then descend there (as PX4 / ArduPilot LAND do from speed)
            self.auto_target = np.array([self.hold_position[0], self.hold_position[1], pos[2]])
        elif spec.behaviour is Behaviour.RTL:
            self.auto_phase = "climb"
            self.auto_target = self.hold_position.copy()
        elif spec.behaviour is Behaviour.TAKEOFF:
            self.auto_target = np.array([pos[0], pos[1], -self.params.get("MIS_TAKEOFF_ALT", 2.5)])

    # ------------------------------------------------------------------------------------------
    # Time step
    # ------------------------------------------------------------------------------------------
    def step(self, dt_s: float) -> list[Out]:
        """Advance the simulated vehicle by ``dt_s`` and run the mode logic; returns events."""
        out: list[Out] = []
        self._run_scheduled(out)
        if self.estimate_lost:
            self.est_offset_ned_m = self.est_offset_ned_m + np.asarray(self.config.faults.estimate_lost_drift_ned_m_s) * dt_s
            self._estimate_cache = (None, -1, self._estimate_cache[2])
            if self.time_s >= self._next_health_report_s:
                self._next_health_report_s = self.time_s + 0.5
                out.append((None, telemetry.estimator_report(self)))
        self._supervise(out)
        setpoint = self._control(dt_s)
        self._dyn_setpoint = setpoint
        self.truth = self.sim.step(dt_s, setpoint)
        self.time_s = self.truth.time_s
        if self.truth.crashed and self.armed:
            self._disarm("crash detected")
            out.append(self._text(mavlink.MAV_SEVERITY_EMERGENCY, "Crash detected, disarming"))
        return out

    def _run_scheduled(self, out: list[Out]) -> None:
        above = self._takeover_above_m
        if above is not None and self.armed:
            height_m = float(self.config.spawn.position_ned_m[2] - self.truth.position_ned_m[2])
            if height_m > above:
                self._takeover_above_m = None
                self._pending = [item for item in self._pending if item[1] != "takeover"]  # whichever first
                out += self.inject_takeover(self.config.faults.takeover_mode)
        due = [item for item in self._pending if item[0] <= self.time_s]
        if not due:
            return
        self._pending = [item for item in self._pending if item[0] > self.time_s]
        for _, kind, arg in due:
            if kind == "takeover":
                self._takeover_above_m = None  # whichever first
                out += self.inject_takeover(arg)  # type: ignore[arg-type]
            elif kind == "reset":
                out += self.inject_estimator_reset(arg)  # type: ignore[arg-type]
            elif kind == "disarm" and self.armed:
                self._disarm("disarmed in flight (fault injection)")
                out.append(self._text(mavlink.MAV_SEVERITY_CRITICAL, "Disarmed in flight"))
            elif kind == "motor_failure":
                self.motors_failed = True
                out.append(self._text(mavlink.MAV_SEVERITY_EMERGENCY, "Motor failure"))
            elif kind == "clock_jump":
                self.clock_offset_s += float(arg)  # type: ignore[arg-type]
                self.log.append(LogEvent(self.time_s, f"clock jumped {float(arg):+g} s (fault injection)"))  # type: ignore[arg-type]
            elif kind == "future_attitude":
                out.append((None, telemetry.future_attitude_quaternion(self, float(arg))))  # type: ignore[arg-type]
                self.log.append(LogEvent(self.time_s, f"future-dated ATTITUDE_QUATERNION (+{float(arg):g} s) sent"))  # type: ignore[arg-type]
            elif kind == "thrust_loss":
                self.sim.lose_thrust(float(arg))  # type: ignore[arg-type]
                out.append(self._text(mavlink.MAV_SEVERITY_CRITICAL, "Thrust loss"))
            elif kind == "corrupt_state":
                out += [(None, m) for m in telemetry.corrupt_state(self, arg)]  # type: ignore[arg-type]
                self.log.append(LogEvent(self.time_s, f"corrupt state sample sent: {arg}"))
            elif kind == "estimate_lost":
                self.estimate_lost = True
                out.append(self._text(mavlink.MAV_SEVERITY_CRITICAL, "EKF: position estimate lost"))
            elif kind == "failsafe" and self.armed:
                name = str(arg) if arg else self.profile.land_mode
                self._set_mode(self.profile.mode(name), user=False)
                self.failsafe, self.failsafe_kind = True, "battery"
                out.append(self._text(mavlink.MAV_SEVERITY_CRITICAL, f"Failsafe activated: battery critical, {name}"))
            elif kind == "offboard_stuck":
                self.offboard_stuck_at = self._estimate()[0].copy()
                self.log.append(LogEvent(self.time_s, "offboard setpoints no longer flown (fault injection)"))

    def _supervise(self, out: list[Out]) -> None:
        now = self.time_s
        landed = self.truth.landed
        if not landed:
            self.took_off = True
            self.landed_since_s = now
        if not self.armed:
            return
        px4 = self.profile.name == "px4"
        if px4:
            self._px4_offboard_failsafe(out)
            if landed and not self.motors_locked:
                if self.took_off and now - self.landed_since_s > self.params["COM_DISARM_LAND"]:
                    self._disarm("Disarmed by landing")
                    out.append(self._text(mavlink.MAV_SEVERITY_INFO, "Landing detected, disarmed"))
                elif not self.took_off and now - self.arm_time_s > self.params["COM_DISARM_PRFLT"]:
                    self._disarm("Disarmed by auto preflight disarming")
                    out.append(self._text(mavlink.MAV_SEVERITY_INFO, "Disarmed by auto preflight disarming"))
        else:
            delay = 1.0 if (self.mode.behaviour is Behaviour.LAND or self.auto_phase == "land") and self.took_off \
                else self.params["DISARM_DELAY"]
            taking_off = self.guided.submode == "takeoff" and self.mode.behaviour is Behaviour.OFFBOARD
            if landed and not taking_off and delay > 0 and now - max(self.landed_since_s, self.arm_time_s) > delay:
                self._disarm("Disarming motors (landed)")
                out.append(self._text(mavlink.MAV_SEVERITY_INFO, "Disarming motors"))
        # Auto-mode transitions.
        pos, _, _ = self._estimate()
        if self.mode.behaviour is Behaviour.TAKEOFF and abs(pos[2] - self.auto_target[2]) < 0.2:
            self._set_mode(self.profile.mode("AUTO.LOITER"), user=False)
            self.user_mode = self.mode
        if not px4 and self.mode.behaviour is Behaviour.OFFBOARD and self.guided.submode == "takeoff":
            if abs(pos[2] - self.guided.hold_position[2]) < 0.2:
                self.guided.submode = "hold"

    def _px4_offboard_failsafe(self, out: list[Out]) -> None:
        signal = self.offboard_signal_ok()
        if self.mode.behaviour is Behaviour.OFFBOARD and not signal:
            action = int(self.params["COM_OBL_RC_ACT"])
            names = {4: "AUTO.LAND", 5: "AUTO.LOITER"}
            if action in (6, 7):
                self._disarm("offboard lost: terminate/disarm")
                out.append(self._text(mavlink.MAV_SEVERITY_CRITICAL, "Failsafe activated: disarming"))
                return
            # 0-2 want RC modes; without RC PX4 falls back to Return (observed on SITL).
            self._set_mode(self.profile.mode(names.get(action, "AUTO.RTL")), user=False)
            self.failsafe, self.failsafe_kind = True, "offboard"
            out.append(self._text(mavlink.MAV_SEVERITY_CRITICAL, "Failsafe activated: no offboard signal"))
        elif self.failsafe and self.failsafe_kind == "offboard" and signal and self.user_mode.behaviour is Behaviour.OFFBOARD:
            # Setpoints resumed: PX4 restores the user-intended mode.
            self._set_mode(self.user_mode, user=True)
            out.append(self._text(mavlink.MAV_SEVERITY_INFO, "Failsafe deactivated"))

    def _position_sp(self, position_est: np.ndarray, yaw: float | None, velocity=(0.0, 0.0, 0.0)) -> PositionSetpoint:
        """The dynamics' position controller, target converted from the estimate to the true frame."""
        # The autopilot flies its estimate onto the target: the truth ends up off by the error.
        true = position_est - self.est_offset_ned_m - np.asarray(self.sim.estimate_error()[0])
        key = (float(true[0]), float(true[1]), float(true[2]), tuple(velocity), yaw)
        cached_key, cached = self._position_sp_cache
        if cached is None or cached_key != key:  # holds repeat the same target: skip re-validation
            cached = PositionSetpoint(key[:3], key[3], yaw)
            self._position_sp_cache = (key, cached)
        return cached

    def _control(self, dt_s: float) -> Setpoint:
        if not self.armed or self.motors_locked or self.motors_failed:
            return MotorsOff()
        behaviour = self.mode.behaviour
        landed = self.truth.landed
        pos, vel, yaw = self._estimate()
        if behaviour is Behaviour.OFFBOARD:
            return self._offboard(dt_s, pos, vel, landed)
        if behaviour is Behaviour.TAKEOFF:
            return self._position_sp(self.auto_target, self.hold_yaw)
        if behaviour is Behaviour.LAND:
            return self._land(dt_s, landed)
        if behaviour is Behaviour.RTL:
            return self._rtl(dt_s, pos, landed)
        if landed:
            return MotorsOff()  # armed on the ground in a hold / manual mode: idle
        if behaviour is Behaviour.LEVEL:
            thrust = thrust_for_climb(0.0, float(vel[2]), self.truth.q_ned_frd, self.hover_thrust, PX4_GAINS.vel_z)
            return AttitudeSetpoint(level_attitude(yaw), thrust)
        climb = self._pilot_climb_m_s()
        if climb:
            self.hold_position[2] = min(self.hold_position[2] - climb * dt_s, 1.0)
            return self._position_sp(self.hold_position, self.hold_yaw, (0.0, 0.0, -climb))
        return self._position_sp(self.hold_position, self.hold_yaw)

    def _pilot_climb_m_s(self) -> float:
        """ArduCopter LOITER / POSHOLD: the climb rate the pilot's throttle stick asks for (m/s up)."""
        stick = self.rc_throttle
        if stick is None or self.profile.name != "ardupilot" or self.mode.name not in ("LOITER", "POSHOLD"):
            return 0.0
        off = (float(stick) - 0.5) / 0.5  # -1 .. 1
        if abs(off) <= 0.1:  # THR_DZ 100 of 1000
            return 0.0
        return (abs(off) - 0.1) / 0.9 * math.copysign(self.params["PILOT_SPEED_UP"] / 100.0, off)

    def _land(self, dt_s: float, landed: bool) -> Setpoint:
        if landed and self.took_off:
            return MotorsOff()
        speed = self.params["MPC_LAND_SPEED"] if self.profile.name == "px4" else self.params["LAND_SPEED"] / 100.0
        self.auto_target[2] = min(self.auto_target[2] + speed * dt_s, 1.0)
        return self._position_sp(self.auto_target, self.hold_yaw, (0.0, 0.0, speed))

    def _rtl(self, dt_s: float, pos: np.ndarray, landed: bool) -> Setpoint:
        if self.profile.name == "px4":
            rtl_alt = self.params["RTL_RETURN_ALT"]
        else:
            rtl_alt = self.params["RTL_ALT"] / 100.0
        if self.auto_phase == "climb":
            self.auto_target[2] = min(self.auto_target[2], -rtl_alt)
            if pos[2] <= self.auto_target[2] + 0.5:
                self.auto_phase = "return"
            return self._position_sp(self.auto_target, self.hold_yaw)
        if self.auto_phase == "return":
            home = np.array([0.0, 0.0, self.auto_target[2]])
            if float(np.linalg.norm(pos[:2] - home[:2])) < 0.5:
                self.auto_phase = "land"
                self.auto_target = np.array([0.0, 0.0, pos[2]])
            return self._position_sp(home, self.hold_yaw)
        return self._land(dt_s, landed)

    def _offboard(self, dt_s: float, pos: np.ndarray, vel: np.ndarray, landed: bool) -> Setpoint:
        if self.offboard_stuck_at is not None:
            return self._position_sp(self.offboard_stuck_at, self.hold_yaw)
        if self.profile.name == "ardupilot":
            sp = self.guided.update(
                dt_s, self.time_s, self.params["GUID_TIMEOUT"], int(self.params["GUID_OPTIONS"]),
                self.params["PSC_JERK_XY"], self.params["PSC_JERK_Z"], self.hover_thrust,
                pos, vel, self.truth.q_ned_frd, landed,
            )
            if sp is not None:
                return sp
            if landed and self.guided.submode != "takeoff":
                return MotorsOff()
            return self._position_sp(self.guided.hold_position, self.guided.yaw_t)
        target = self.px4_target
        if target is None:
            if landed:
                return MotorsOff()
            return self._position_sp(self.hold_position, self.hold_yaw)
        if isinstance(target, AttitudeTarget):
            if target.q_ned_frd is None:
                return RateSetpoint(target.rates_frd_rad_s, target.thrust)  # type: ignore[arg-type]
            ff = target.rates_frd_rad_s if target.rates_frd_rad_s and target.rates_frd_rad_s[2] != 0.0 else None
            return AttitudeSetpoint(target.q_ned_frd, target.thrust, ff)
        yaw = target.yaw_rad if math.isfinite(target.yaw_rad) else None
        yaw_rate = target.yaw_rate_rad_s if math.isfinite(target.yaw_rate_rad_s) else 0.0
        if target.kind == "accel":
            accel = target.accel_ned_m_s2
        else:
            accel = tuple(float(a) for a in px4_trajectory_accel(target, pos, vel))
        return AccelerationSetpoint(accel, yaw, yaw_rate)
