"""In-process flight: the app's pure pipeline against the mock autopilot, in lockstep, no sockets.

One fixed-step loop (period ``1 / rate_hz``; the mock's dynamics run at 1 kHz inside each step):

1. the mock autopilot's due telemetry and replies are packed into MAVLink frames (sysid 1,
   compid 1), logged to the ``.tlog``, decoded again and handed to the sim's bridge;
2. on each fresh state sample the bridge steps :class:`pf_offboard.app.pipeline.Pipeline` — the
   same code ``fly`` and ``replay`` run — and sends its setpoint: packed with our ids (the
   vehicle's sysid, compid 191), logged, decoded (float32 as on the wire) and handed to the
   mock (:class:`sitl_mock.autopilot.Autopilot`), which interprets it like PX4 or ArduPilot;
3. the mock advances one step.

So a ``sim`` flight writes the same ``.tlog`` / ``.csv`` a ``fly`` flight does, and ``replay``
reproduces it. Frames: this module speaks MAVLink (NED) with the mock and ENU with the user; every
conversion goes through :mod:`pf_offboard.frames`.

The sim's bridge is deliberately small: stream setpoints, switch to OFFBOARD / GUIDED (after the
throw trigger for a thrown start), follow until the duration or lap count is reached.
"""

from __future__ import annotations

import functools
import math
import time
from collections import deque
from dataclasses import dataclass, field
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from sitl_mock.dynamics.params import DEFAULT_VEHICLE

from pf_offboard import frames
from pf_offboard.errors import InputError
from pf_offboard.logs.flightlog import FlightLog, FlightLogPaths
from pf_offboard.logs.steplog import StepRecord
from pf_offboard.logs.measures import path_tangent
from pf_offboard.logs.summary import FlightSummary, SummaryAccumulator, time_laps_of
from pf_offboard.logs.tlog import OWN_COMPONENT_ID

AUTOPILOT_SYSTEM_ID = 1
AUTOPILOT_COMPONENT_ID = 1
MAX_RATE_HZ = 250.0  # the mock streams at most this fast
# Streams the controller needs, everything else switched off so logs stay small.
# Attitude first: a LOCAL_POSITION_NED sample steps the controller with the attitude already in.
_STATE_STREAMS = (mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)
_HEARTBEAT_HZ = 10.0  # like fly: a takeover shows within 0.1 s


# a duration shorter than this is no flight (1e-320 s is not a duration): refused like fly's --duration
MIN_DURATION_S = 0.01

@dataclass(frozen=True)
class SimSpec:
    """One simulated flight. Positions / velocities are world ENU (z up), metres and m/s."""

    start_enu_m: tuple[float, float, float] | None = None  # hover start (default: the path's start)
    throw_enu: tuple[float, ...] | None = None  # x, y, z, vx, vy, vz: thrown start, motors locked
    throw_height_m: float | None = None  # activation height of a throw (default: config, else 2 m)
    # a throw's attitude, body FLU -> world ENU quaternion (w, x, y, z); default level, nose north
    throw_q_enu_flu: tuple[float, float, float, float] | None = None
    throw_body_rates_flu_rad_s: tuple[float, float, float] | None = None  # a throw's spin, body FLU
    # engage this long after the release instead of at the activation height (0: at once)
    throw_engage_after_s: float | None = None
    autopilot: str = "px4"  # px4 | ardupilot (the mock's profile)
    vehicle: str = DEFAULT_VEHICLE  # a sitl_mock.dynamics preset (PRESET_NAMES): the realistic px4-sih by default
    wind_enu_m_s: tuple[float, float, float] | None = None  # constant wind, world ENU m/s (air velocity)
    wind_gusts: tuple[float, float] | None = None  # random gusts: (std m/s per axis, time constant s)
    # an external push: (start s of simulated time, duration s, ax, ay, az m/s^2 world ENU), a
    # specific force on the airframe on top of thrust, gravity, drag and wind
    push: tuple[float, float, float, float, float] | None = None
    # the mock autopilot's parameters at start, (name, value) pairs (like PX4_PARAM_NAME=value),
    # e.g. (("MPC_TILTMAX_AIR", 30.0),): read by the sim as fly reads them
    autopilot_params: tuple[tuple[str, float], ...] = ()
    output_mode: str | None = None  # default: config flight.output_mode
    rate_hz: float | None = None  # control / telemetry rate; default: config flight.setpoint_rate_hz
    duration_s: float | None = None  # simulated time from the start
    laps: float | None = None  # laps after activation
    seed: int = 0
    epoch_unix_s: float | None = None  # UNIX time of t = 0 in the .tlog (default: now)
    name: str = "flight"  # log file stem


@dataclass
class SimResult:
    """What a sim flight produced.

    The steps are not kept in memory (an hour at 250 Hz is 900 000 of them): the summary was
    computed as they streamed to the CSV, and :attr:`records` reads them back from it on demand
    (bit-identical: floats are written in their shortest round-trip form).
    """

    paths: FlightLogPaths
    summary: FlightSummary
    reason: str  # why it ended
    activation_time_s: float | None
    crashed: bool
    sim_time_s: float
    autopilot_log: list[str] = field(default_factory=list)

    @functools.cached_property
    def records(self) -> list[StepRecord]:
        """Every step of the flight, read from the step log the first time it is asked for (for
        tests and analysis, not the CLI), then kept."""
        from pf_offboard.logs.steplog import read_steplog

        return read_steplog(self.paths.steps_csv)


def _vec(text: str, n: int, flag: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise InputError(flag, f"expected {n} comma-separated numbers, got {text!r}") from None
    if len(values) != n:
        raise InputError(flag, f"expected {n} comma-separated numbers, got {len(values)} in {text!r}")
    if not all(math.isfinite(v) for v in values):
        raise InputError(flag, f"values must be finite, got {text!r}")
    return values


def parse_start(text: str) -> tuple[float, float, float]:
    """``x,y,z`` (ENU, m) of a hover start; z must be above the ground."""
    v = _vec(text, 3, "--start")
    if v[2] <= 0.2:
        raise InputError("--start", f"z (up) must be > 0.2 m for a hover start, got {v[2]}")
    return v  # type: ignore[return-value]


def parse_throw(text: str) -> tuple[float, ...]:
    """``x,y,z,vx,vy,vz`` (ENU, m and m/s) of a thrown start; z must be above the ground."""
    v = _vec(text, 6, "--throw")
    if v[2] <= 0.0:
        raise InputError("--throw", f"z (up) must be > 0 m, got {v[2]}")
    if math.hypot(*v[3:]) > 30.0:
        raise InputError("--throw", f"speed {math.hypot(*v[3:]):.1f} m/s is beyond a throw (<= 30 m/s)")
    return v


MAX_WIND_M_S = 20.0
MAX_THROW_RATE_RAD_S = 35.0  # ~2000 deg/s (a gyro's usual full scale): beyond any throw
MAX_ENGAGE_AFTER_S = 60.0


def parse_quaternion(text: str, flag: str = "--throw-attitude") -> tuple[float, float, float, float]:
    """``w,x,y,z`` of a unit quaternion (a norm within 1e-3 of 1 is normalised)."""
    return _unit_quaternion(_vec(text, 4, flag), flag)  # type: ignore[arg-type]


def _unit_quaternion(q: tuple[float, ...], flag: str) -> tuple[float, float, float, float]:
    if len(q) != 4 or not all(math.isfinite(v) for v in q):
        raise InputError(flag, f"must be 4 finite numbers w,x,y,z, got {q!r}")
    norm = math.sqrt(sum(v * v for v in q))
    if abs(norm - 1.0) > 1e-3:
        raise InputError(flag, f"must be a unit quaternion w,x,y,z, got norm {norm:.6g}")
    return tuple(v / norm for v in q)  # type: ignore[return-value]


def parse_rates(text: str, flag: str = "--throw-rates") -> tuple[float, float, float]:
    """``p,q,r`` body rates (FLU, rad/s) of a thrown start."""
    return _vec(text, 3, flag)  # type: ignore[return-value]


def _numbers(text: str, flag: str, counts: tuple[int, ...], expected: str) -> tuple[float, ...]:
    """Comma-separated numbers of a flag, as many as one of ``counts``; else an error naming it."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise InputError(flag, f"expected {expected}, got {text!r}") from None
    if len(values) not in counts:
        raise InputError(flag, f"expected {expected}, got {text!r}")
    return values


def parse_wind(text: str) -> tuple[float, float, float]:
    """``E,N[,U]`` (world ENU, m/s) of a constant wind; U defaults to 0."""
    values = _numbers(text, "--wind", (2, 3), "E,N or E,N,U in m/s")
    return (values + (0.0,))[:3]  # type: ignore[return-value]


def parse_gusts(text: str) -> tuple[float, float]:
    """``STD[,TAU]`` of the random gusts: std m/s per axis, time constant s (default 2)."""
    values = _numbers(text, "--wind-gusts", (1, 2), "STD or STD,TAU")
    return (values[0], values[1] if len(values) == 2 else 2.0)


MAX_PUSH_M_S2 = 50.0
MAX_PUSH_DURATION_S = 10.0


def parse_push(text: str) -> tuple[float, float, float, float, float]:
    """``T,DURATION,AX,AY[,AZ]``: a push from simulated time T (s) for DURATION (s) with the
    specific force (AX, AY, AZ) m/s^2, world ENU (AZ default 0)."""
    values = _numbers(text, "--push", (4, 5), "T,DURATION,AX,AY[,AZ] (s, s, m/s^2 ENU)")
    push = (values + (0.0,))[:5]
    _check_push(push)  # type: ignore[arg-type]
    return push  # type: ignore[return-value]


def _check_push(push: tuple[float, ...]) -> None:
    if len(push) != 5 or not all(math.isfinite(v) for v in push):
        raise InputError("--push", f"must be 5 finite numbers (T s, DURATION s, AX, AY, AZ m/s^2 ENU), got {push!r}")
    t, duration, *accel = push
    if t < 0.0:
        raise InputError("--push", f"start T must be >= 0 s, got {t:g}")
    if not 1e-3 <= duration <= MAX_PUSH_DURATION_S:
        raise InputError("--push", f"DURATION must be in [0.001, {MAX_PUSH_DURATION_S:g}] s, got {duration:g}")
    if math.hypot(*accel) > MAX_PUSH_M_S2:
        raise InputError("--push", f"acceleration must be <= {MAX_PUSH_M_S2:g} m/s^2, got {math.hypot(*accel):.3g}")


def _check(spec: SimSpec) -> None:
    if spec.autopilot not in ("px4", "ardupilot"):
        raise InputError("--autopilot", f"must be px4 or ardupilot, got {spec.autopilot!r}")
    from sitl_mock.dynamics import PRESET_NAMES

    if spec.vehicle not in PRESET_NAMES:
        raise InputError("--vehicle", f"must be one of {', '.join(PRESET_NAMES)}, got {spec.vehicle!r}")
    if spec.wind_enu_m_s is not None:
        w = spec.wind_enu_m_s
        if len(w) != 3 or not all(math.isfinite(v) for v in w):
            raise InputError("--wind", f"values must be 3 finite numbers (ENU m/s), got {w!r}")
        if math.hypot(*w) > MAX_WIND_M_S:
            raise InputError("--wind", f"wind speed must be <= {MAX_WIND_M_S:g} m/s, got {math.hypot(*w):.3g}")
    if spec.wind_gusts is not None:
        std, tau = spec.wind_gusts
        if not (math.isfinite(std) and 0.0 <= std <= MAX_WIND_M_S / 2):
            raise InputError("--wind-gusts", f"std must be in [0, {MAX_WIND_M_S / 2:g}] m/s, got {std}")
        if not (math.isfinite(tau) and 0.05 <= tau <= 600.0):
            raise InputError("--wind-gusts", f"time constant must be in [0.05, 600] s, got {tau}")
    if spec.push is not None:
        _check_push(tuple(spec.push))
    if spec.start_enu_m is not None and spec.throw_enu is not None:
        raise InputError("--throw", "give either --start (hover) or --throw, not both")
    _check_throw(spec)
    if spec.duration_s is not None and not (math.isfinite(spec.duration_s) and MIN_DURATION_S <= spec.duration_s <= 3600.0):
        raise InputError("--duration", f"must be in [{MIN_DURATION_S:g}, 3600] s, got {spec.duration_s}")
    if spec.laps is not None and not (math.isfinite(spec.laps) and 0.0 < spec.laps <= 1000.0):
        raise InputError("--laps", f"must be in (0, 1000], got {spec.laps}")
    if spec.rate_hz is not None and not (math.isfinite(spec.rate_hz) and 20.0 <= spec.rate_hz <= MAX_RATE_HZ):
        raise InputError("--rate", f"must be in [20, {MAX_RATE_HZ:g}] Hz, got {spec.rate_hz}")
    if spec.throw_height_m is not None and not (math.isfinite(spec.throw_height_m) and spec.throw_height_m > 0.0):
        raise InputError("--throw-height", f"must be > 0 m, got {spec.throw_height_m}")
    if spec.epoch_unix_s is not None and not (math.isfinite(spec.epoch_unix_s) and 1e9 <= spec.epoch_unix_s <= 7e9):
        raise InputError("--epoch", f"must be a UNIX time in seconds (1e9..7e9), got {spec.epoch_unix_s}")
    if not 0 <= spec.seed < 2**63:
        raise InputError("--seed", f"must be an integer in [0, 2^63), got {spec.seed}")
    if not spec.name or "/" in spec.name or spec.name.startswith("."):
        raise InputError("--name", f"must be a plain file stem, got {spec.name!r}")


def _check_throw(spec: SimSpec) -> None:
    """A throw's attitude, spin and engagement time: only with a throw, finite, in range."""
    extras = (("--throw-attitude", spec.throw_q_enu_flu), ("--throw-rates", spec.throw_body_rates_flu_rad_s),
              ("--throw-engage-after", spec.throw_engage_after_s))  # fmt: skip
    for flag, value in extras:
        if value is not None and spec.throw_enu is None:
            raise InputError(flag, "only a thrown start (--throw) takes it")
    if spec.throw_q_enu_flu is not None:
        _unit_quaternion(tuple(spec.throw_q_enu_flu), "--throw-attitude")
    w = spec.throw_body_rates_flu_rad_s
    if w is not None:
        if len(w) != 3 or not all(math.isfinite(v) for v in w):
            raise InputError("--throw-rates", f"must be 3 finite numbers p,q,r (rad/s), got {w!r}")
        if math.hypot(*w) > MAX_THROW_RATE_RAD_S:
            raise InputError("--throw-rates", f"spin {math.hypot(*w):.1f} rad/s is beyond a throw (<= {MAX_THROW_RATE_RAD_S:g} rad/s)")
    t = spec.throw_engage_after_s
    if t is not None:
        if not (math.isfinite(t) and 0.0 <= t <= MAX_ENGAGE_AFTER_S):
            raise InputError("--throw-engage-after", f"must be in [0, {MAX_ENGAGE_AFTER_S:g}] s, got {t}")
        if spec.throw_height_m is not None:
            raise InputError("--throw-engage-after", "give either --throw-height or --throw-engage-after, not both")


class _NoLog:
    """Stands in for a :class:`FlightLog` when a flight writes no files (sweeps: speed)."""

    def __init__(self, paths: FlightLogPaths) -> None:
        self.paths = paths

    def __enter__(self) -> _NoLog:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def frame(self, frame_bytes: bytes | bytearray, unix_time_s: float) -> None:
        return None

    def step(self, record: StepRecord) -> None:
        return None


class _Codec:
    """Both ends of the in-process link: pack with the sender's ids, decode what was packed."""

    def __init__(self, companion_system_id: int) -> None:
        self.autopilot = mavlink.MAVLink(None, srcSystem=AUTOPILOT_SYSTEM_ID, srcComponent=AUTOPILOT_COMPONENT_ID)
        self.companion = mavlink.MAVLink(None, srcSystem=companion_system_id, srcComponent=OWN_COMPONENT_ID)
        self.parser = mavlink.MAVLink(None)

    def pack(self, sender: Any, msg: Any) -> bytes:
        frame = bytes(msg.pack(sender))
        sender.seq = (sender.seq + 1) % 256
        return frame

    def decode(self, frame: bytes) -> Any:
        return self.parser.decode(bytearray(frame))


class SimFlight:
    """One deterministic in-process flight (see the module docstring). Call :meth:`run` once.

    ``write_logs=False``: no ``.tlog`` / ``.csv`` / ``.yaml`` / summary file (the summary is still
    computed; :attr:`SimResult.records` is then unavailable). Sweeps fly thousands this way."""

    def __init__(self, config_path: str | Path, spec: SimSpec, out_dir: str | Path, write_logs: bool = True) -> None:
        from pf_offboard.app.rules import EndSpec, LapCounter, ThrowTrigger
        from pf_offboard.app.encoders import Encoder
        from pf_offboard.app.estimator import Estimator
        from pf_offboard.app.settings import flight_settings_for
        from pf_offboard.app.pipeline import Pipeline
        from pf_offboard.app.profiles import PROFILES
        from pf_offboard.config import load_config
        from pf_offboard.control import controller_from_config

        _check(spec)
        self.spec = spec
        self.config_path = Path(config_path)
        config = load_config(self.config_path)
        config.require_local("sim has no vehicle to read the origin from")
        self.config = config
        settings = flight_settings_for(config, output=spec.output_mode)
        self.settings = settings
        rate = spec.rate_hz if spec.rate_hz is not None else min(settings.setpoint_rate_hz, MAX_RATE_HZ)
        if not 20.0 <= rate <= MAX_RATE_HZ:
            raise InputError("flight.setpoint_rate_hz", f"sim needs 20..{MAX_RATE_HZ:g} Hz, got {rate} (or pass --rate)")
        self.dt_s = 1.0 / rate
        follower = controller_from_config(config)
        self.path = follower.path
        self.profile = PROFILES[spec.autopilot]
        encoder = Encoder(
            settings.output_mode, self.profile, AUTOPILOT_SYSTEM_ID, AUTOPILOT_COMPONENT_ID,
            hover_thrust=settings.hover_thrust if settings.hover_thrust is not None else 0.5,
            time_constant_s=settings.attitude_time_constant_s,
        )  # fmt: skip
        self.pipeline = Pipeline(follower, encoder, Estimator("local_position", settings.velocity_correction_for(self.profile)))
        self._tilt_params: dict[str, float] = {}  # the autopilot's tilt limit parameters as reported
        self.laps = LapCounter(self.path.length_m, self.path.closed)
        self.end = EndSpec(laps=spec.laps, duration_s=None)
        height = spec.throw_height_m or config.flight.throw_activation_height_m or 2.0
        self.throw = ThrowTrigger(height) if spec.throw_enu is not None else None
        self.duration_s = spec.duration_s if spec.duration_s is not None else (None if spec.laps else 20.0)
        self.out_dir = Path(out_dir)
        self.write_logs = write_logs
        self.autopilot = self._make_autopilot(config)
        self.codec = _Codec(AUTOPILOT_SYSTEM_ID)  # a companion shares its vehicle's system id
        # bridge state
        self.phase = "waiting" if self.throw is not None else "engaging"
        self.activation_time_s: float | None = None
        self._event = ""
        self._mode_requested = False
        self._inbox: deque[Any] = deque()
        self.summary = SummaryAccumulator(path_tangent(self.path))  # running sums only: the steps go to the CSV
        time_laps_of(self.summary, self.pipeline.follower)  # closed path: lap times beside the point-mass bound
        # called with the simulated time every 250 steps (benchmarks sample memory with it)
        self.progress: Callable[[float], None] | None = None
        self.reason = ""

    def _make_autopilot(self, config: Any) -> Any:
        from sitl_mock.autopilot import Autopilot
        from sitl_mock.config import MockConfig, SpawnSpec

        spec = self.spec
        if spec.throw_enu is not None:
            pos = frames.enu_to_ned(spec.throw_enu[:3])
            vel = frames.enu_to_ned(spec.throw_enu[3:])
            q_ned = (1.0, 0.0, 0.0, 0.0) if spec.throw_q_enu_flu is None else frames.quat_enu_flu_to_ned_frd(spec.throw_q_enu_flu)
            w_frd = (0.0, 0.0, 0.0) if spec.throw_body_rates_flu_rad_s is None else frames.flu_to_frd(spec.throw_body_rates_flu_rad_s)
            spawn = SpawnSpec("throw", tuple(map(float, pos)), tuple(map(float, vel)),  # type: ignore[arg-type]
                              tuple(map(float, q_ned)), tuple(map(float, w_frd)))  # type: ignore[arg-type]
        else:
            start = spec.start_enu_m if spec.start_enu_m is not None else tuple(map(float, self.path.eval(0.0).sigma))
            if start[2] <= 0.2:
                raise InputError("--start", f"the path starts at z = {start[2]:.2f} m; give --start above the ground")
            spawn = SpawnSpec("hover", tuple(map(float, frames.enu_to_ned(start))))  # type: ignore[arg-type]
        disturbances: dict[str, Any] = {}
        if spec.wind_enu_m_s is not None:
            disturbances["wind_ned_m_s"] = tuple(map(float, frames.enu_to_ned(spec.wind_enu_m_s)))
        if spec.wind_gusts is not None:
            disturbances["wind_gust_std_m_s"], disturbances["wind_gust_time_constant_s"] = spec.wind_gusts
        if spec.push is not None:
            from sitl_mock.dynamics import Push

            t, duration, *accel = spec.push
            disturbances["pushes"] = (Push(t, duration, tuple(map(float, frames.enu_to_ned(accel)))),)  # type: ignore[arg-type]
        mock = MockConfig(
            profile=spec.autopilot, vehicle=spec.vehicle, spawn=spawn, seed=spec.seed,
            lockstep=True, lockstep_dt_s=self.dt_s, step_dt_s=self.dt_s, ekf_ready_delay_s=0.0, **disturbances,
            params=tuple(spec.autopilot_params),
        )  # fmt: skip
        ap = Autopilot(mock, np.random.default_rng(spec.seed))
        ap.add_link(0)
        return ap

    # ------------------------------------------------------------------ the link, in process
    def _send(self, log: FlightLog, msg: Any) -> None:
        """Companion → autopilot: pack, log, decode, hand to the mock; queue its replies."""
        frame = self.codec.pack(self.codec.companion, msg)
        log.frame(frame, self._stamp())
        for _, reply in self.autopilot.handle(self.codec.decode(frame), 0):
            self._inbox.append(reply)

    def _deliver(self, log: FlightLog) -> None:
        """Autopilot → companion: everything queued, in order (replies may queue more)."""
        while self._inbox:
            frame = self.codec.pack(self.codec.autopilot, self._inbox.popleft())
            log.frame(frame, self._stamp())
            self._on_message(log, self.codec.decode(frame))

    def _stamp(self) -> float:
        return self._epoch + self.autopilot.time_s

    def _command(self, log: FlightLog, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self._send(log, mavlink.MAVLink_command_long_message(AUTOPILOT_SYSTEM_ID, AUTOPILOT_COMPONENT_ID, command, 0, *p))

    # ------------------------------------------------------------------ the sim's bridge
    def _setup(self, log: FlightLog) -> None:
        """Streams at the control rate (others off), hover thrust, ArduPilot GUID_OPTIONS."""
        for msgid, _hz in self.autopilot.profile.streams:
            if msgid != mavlink.MAVLINK_MSG_ID_HEARTBEAT:
                self._command(log, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msgid, -1)
        for msgid in _STATE_STREAMS:
            self._command(log, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msgid, self.dt_s * 1e6)
        self._command(log, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_HEARTBEAT, 1e6 / _HEARTBEAT_HZ)
        # as fly (read_setpoint_mapping): the hover thrust, and the acceleration mapping's tilt
        params = [self.profile.hover_thrust_param]
        if self.settings.output_mode == "acceleration" and self.profile.accel_tilt_param is not None:
            params.append(self.profile.accel_tilt_param)
        if self.settings.output_mode == "acceleration":  # the autopilot's tilt limit (read_tilt_limit)
            params += [name for name, _ in self.profile.accel_tilt_limit_params]
        for param in params:
            self._send(log, mavlink.MAVLink_param_request_read_message(AUTOPILOT_SYSTEM_ID, AUTOPILOT_COMPONENT_ID, param.encode(), -1))
        required = self.profile.required_guid_options(self.settings.output_mode)
        if required:  # like `fly --set-guid-options`
            self._send(log, mavlink.MAVLink_param_set_message(
                AUTOPILOT_SYSTEM_ID, AUTOPILOT_COMPONENT_ID, b"GUID_OPTIONS", float(required), mavlink.MAV_PARAM_TYPE_INT32))  # fmt: skip
        self._deliver(log)

    def _on_message(self, log: FlightLog, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "PARAM_VALUE":
            from pf_offboard.app.params import param_value_decode

            pid = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
            pid = pid.rstrip("\x00")
            value = param_value_decode(msg.param_value, msg.param_type, self.profile.params_bytewise)
            if pid == self.profile.hover_thrust_param and self.settings.hover_thrust is None:
                self.pipeline.encoder = self.pipeline.encoder.with_hover_thrust(float(value))
            elif pid == self.profile.accel_tilt_param and self.settings.output_mode == "acceleration":
                self.pipeline.encoder = self.pipeline.encoder.with_tilt_from_gravity(self.profile.tilts_from_gravity(value))
            elif any(pid == name for name, _ in self.profile.accel_tilt_limit_params) and self.settings.output_mode == "acceleration":
                self._tilt_params[pid] = float(value)
                tilt = self.profile.accel_tilt_limit_deg(self._tilt_params)  # as fly: min(config's, autopilot's)
                cap = getattr(self.pipeline.follower, "cap_tilt", None)
                if tilt is not None and cap is not None:
                    cap(tilt)
            return
        if kind == "COMMAND_ACK":
            if msg.command == mavlink.MAV_CMD_DO_SET_MODE and self._mode_requested and self.phase == "engaging":
                if msg.result == mavlink.MAV_RESULT_ACCEPTED:
                    self.phase = "following"
                    self._event = f"{self._event}; activated" if self._event else "activated"
                else:
                    self._mode_requested = False  # retried on the next step
            return
        if self.pipeline.on_message(msg):
            self._on_state(log)

    def _on_state(self, log: FlightLog) -> None:
        est = self.pipeline.estimator.latest
        assert est is not None
        if self.phase == "waiting" and self.profile.name == "ardupilot":
            # ArduPilot flies GUIDED setpoints at once (it unlocks the motors): stay silent
            self.pipeline.mark_consumed()
        else:
            event, self._event = self._event, ""
            step = self.pipeline.step(self.phase, self.phase != "waiting", event)
            if step is None:
                return
            if self.phase != "waiting" and self.activation_time_s is None:
                self.activation_time_s = est.time_s  # the first setpoint meant to fly
            self.summary.add(step.record)
            log.step(step.record)
            self._send(log, step.setpoint)
            if self.phase == "following":
                self.laps.update(step.record.eta1_m)
        if self.phase == "waiting" and self.spec.throw_engage_after_s is not None:
            if est.time_s >= self.spec.throw_engage_after_s - 1e-9:
                self.phase = "engaging"
                self._event = f"engaged {est.time_s:.2f} s after the throw"
        elif self.phase == "waiting":
            assert self.throw is not None
            if self.throw.update(float(est.position_enu_m[2]), float(np.linalg.norm(est.velocity_enu_m_s))):
                self.phase = "engaging"
                self._event = f"throw trigger at {est.position_enu_m[2]:.2f} m"
        if self.phase == "engaging" and not self._mode_requested:
            self._mode_requested = True
            req = self.profile.offboard
            self._command(log, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, req.param2, req.param3)

    def _end_reason(self) -> str:
        t = self.autopilot.time_s
        if self.duration_s is not None and t >= self.duration_s - 1e-9:
            return f"duration {self.duration_s:g} s reached"
        if self.end.laps is not None and self.laps.laps >= self.end.laps:
            return f"{self.end.laps:g} laps done"
        if self.autopilot.truth.crashed:
            return "crashed"
        if self.autopilot.truth.landed and t > 0.0:
            return "on the ground before the throw trigger fired" if self.phase == "waiting" else "on the ground"
        return ""

    def run(self) -> SimResult:
        spec = self.spec
        self._epoch = spec.epoch_unix_s if spec.epoch_unix_s is not None else time.time()
        if self.duration_s is not None:
            limit_s = self.duration_s
        else:  # --laps: give up at three times the nominal time (stuck, or far too slow)
            speed = max(abs(self.pipeline.speed_ref_m_s), 0.1) if math.isfinite(self.pipeline.speed_ref_m_s) else 1.0
            limit_s = 30.0 + 3.0 * (spec.laps or 1.0) * self.path.length_m / speed
        max_steps = int(math.ceil(limit_s / self.dt_s)) + 1
        opened: Any = (FlightLog.open(self.out_dir, spec.name, config_path=self.config_path, config=self.config) if self.write_logs
                       else _NoLog(FlightLogPaths.in_dir(self.out_dir, spec.name)))  # fmt: skip
        with opened as log:
            self._setup(log)
            for i in range(max_steps):
                if self.progress is not None and i % 250 == 0:
                    self.progress(self.autopilot.time_s)
                self._inbox.extend(msg for _, msg in self.autopilot.due_telemetry())
                self._deliver(log)
                self.reason = self._end_reason()
                if self.reason:
                    break
                self._inbox.extend(msg for _, msg in self.autopilot.step(self.dt_s))
            else:
                self.reason = f"time limit {limit_s:.0f} s reached before {spec.laps:g} laps"
            paths = log.paths
        summary = self.summary.result()
        from pf_offboard.logs.summary import flight_report, write_report

        crashed = bool(self.autopilot.truth.crashed)
        if self.write_logs:
            write_report(flight_report(summary, 1 if crashed else 0, self.reason, paths.tlog.parent, self.config, "sim",
                                       tilt_limit_deg=self.pipeline.tilt_limit_deg),
                         paths.tlog.parent)  # fmt: skip
        return SimResult(
            paths=paths,
            summary=summary,
            reason=self.reason,
            activation_time_s=self.activation_time_s,
            crashed=bool(self.autopilot.truth.crashed),
            sim_time_s=self.autopilot.time_s,
            autopilot_log=[f"{e.time_s:.3f} s: {e.text}" for e in self.autopilot.log],
        )


def simulate(config_path: str | Path, spec: SimSpec, out_dir: str | Path, write_logs: bool = True) -> SimResult:
    """Fly one in-process flight and write its logs to ``out_dir`` (see :class:`SimFlight`)."""
    return SimFlight(config_path, spec, out_dir, write_logs=write_logs).run()
