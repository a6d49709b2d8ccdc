"""``pf-offboard fly``: follow a path on a PX4 / ArduPilot vehicle over MAVLink.

One asyncio loop: the link reader (an event-loop callback on the socket), and one TaskGroup
supervising the flight itself, the keep-alive / watchdog, our HEARTBEAT and the status line.
See docs/app.md for the behaviour in full.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime as _dt
import functools
import gc
import math
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable
from typing import Any, TextIO

from pf_offboard.errors import InputError, LinkError

LAUNCHES = ("takeoff", "airborne", "throw")
# `--takeoff` / `--throw` without a height: take it from the config's flight: section. An object,
# not a number a user could type (`--throw -1` must be refused, not read as "from the config"),
# and not a string (argparse would pass a string const through type=float).
FROM_CONFIG: Any = object()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--connect", required=True, metavar="ENDPOINT",
                        help="udpin:HOST:PORT | udpout:HOST:PORT | tcp:HOST:PORT | serial:DEVICE:BAUD "
                             "(PX4 SITL: udpin:0.0.0.0:14540; ArduPilot SITL: tcp:127.0.0.1:5760)")  # fmt: skip
    parser.add_argument("--config", required=True, metavar="YAML", help="config file, or a shipped config's name (pf-offboard configs)")
    launch = parser.add_mutually_exclusive_group(required=True)
    launch.add_argument("--takeoff", type=float, nargs="?", const=FROM_CONFIG, metavar="H",
                        help="arm, take off to H metres (default flight.takeoff_altitude_m), then follow")  # fmt: skip
    launch.add_argument("--airborne", action="store_true", help="the vehicle is flying: switch to OFFBOARD/GUIDED and follow")
    launch.add_argument("--throw", type=float, nargs="?", const=FROM_CONFIG, metavar="H",
                        help="activate when a thrown vehicle crosses H metres (default flight.throw_activation_height_m)")  # fmt: skip
    parser.add_argument("--output", choices=("acceleration", "attitude", "rates"), help="setpoint type (default: flight.output_mode)")
    parser.add_argument("--autopilot", choices=("auto", "px4", "ardupilot"), default="auto", help="default: from HEARTBEAT")
    parser.add_argument("--laps", type=float, help="end after N laps")
    parser.add_argument("--duration", type=float, metavar="S", help="end after S seconds of following (vehicle time)")
    parser.add_argument("--end-action", choices=("hold", "land"), help="hand-back mode (default: flight.end_action)")
    parser.add_argument("--target-system", type=int, metavar="ID", help="vehicle system id 1..255 (default: first autopilot heard)")
    parser.add_argument("--heartbeat-timeout", type=float, default=10.0, metavar="S", help="give up without a HEARTBEAT (s)")
    parser.add_argument("--state-source", choices=("local_position", "odometry"), default="local_position",
                        help="position/velocity telemetry to follow with")  # fmt: skip
    parser.add_argument("--set-guid-options", action="store_true",
                        help="ArduPilot: set the GUID_OPTIONS bits the output mode needs instead of refusing")  # fmt: skip
    parser.add_argument("--signing-key", metavar="FILE",
                        help="MAVLink 2 signing: sign what we send, drop unsigned / wrongly signed frames. FILE: 32 raw "
                             "bytes, 64 hex digits or a passphrase (SHA-256, as MAVProxy); see the README")  # fmt: skip
    parser.add_argument("--experimental-output", action="store_true",
                        help="fly an output mode the app refuses on this autopilot (ArduPilot acceleration: "
                             "measured to oscillate by metres); experimental")  # fmt: skip
    parser.add_argument("--ready-timeout", type=float, default=120.0, metavar="S",
                        help="--takeoff/--airborne: wait up to S seconds for the position estimate and arming checks (default 120)")  # fmt: skip
    parser.add_argument("--takeoff-timeout", type=float, metavar="S",
                        help="--takeoff: give up if the take-off altitude is not held within S seconds (default 30 + 5 s per metre)")  # fmt: skip
    parser.add_argument("--log-dir", metavar="DIR", help="default: ./flights/<UTC timestamp>/")
    parser.add_argument("--quiet", action="store_true", help="no status line")
    parser.add_argument("--json", action="store_true", help="print the flight report (as in LOG_DIR/summary.json) as JSON on stdout")


@dataclass(frozen=True)
class FlightSettings:
    """The ``flight:`` section of a config with the command-line overrides applied."""

    output_mode: str
    setpoint_rate_hz: float
    state_timeout_s: float
    hover_thrust: float | None
    end_action: str
    attitude_time_constant_s: float
    velocity_correction_s: float | None  # pf_offboard.app.estimator; None: off


def flight_settings(config: Any, args: argparse.Namespace) -> FlightSettings:
    """Read ``config.flight`` (tolerating a config without one) and apply flags; validate."""
    flight = getattr(config, "flight", None)

    def get(name: str, default: Any) -> Any:
        value = getattr(flight, name, None) if flight is not None else None
        return default if value is None else value

    s = FlightSettings(
        output_mode=args.output or get("output_mode", "acceleration"),
        setpoint_rate_hz=float(get("setpoint_rate_hz", 50.0)),
        state_timeout_s=float(get("state_timeout_s", 0.5)),
        hover_thrust=get("hover_thrust", None),
        end_action=args.end_action or get("end_action", "hold"),
        attitude_time_constant_s=_attitude_time_constant(config, get("attitude_time_constant_s", None)),
        velocity_correction_s=get("velocity_correction_s", None),
    )
    if s.output_mode not in ("acceleration", "attitude", "rates"):
        raise InputError("flight.output_mode", f"must be acceleration, attitude or rates, got {s.output_mode!r}")
    if not (math.isfinite(s.setpoint_rate_hz) and 2.0 < s.setpoint_rate_hz <= 1000.0):
        raise InputError("flight.setpoint_rate_hz", f"must be in (2, 1000] Hz (PX4 needs > 2 Hz), got {s.setpoint_rate_hz}")
    if not (math.isfinite(s.state_timeout_s) and 0.0 < s.state_timeout_s <= 5.0):
        raise InputError("flight.state_timeout_s", f"must be in (0, 5] s, got {s.state_timeout_s}")
    if s.hover_thrust is not None and not (0.05 <= float(s.hover_thrust) <= 0.95):
        raise InputError("flight.hover_thrust", f"must be in [0.05, 0.95] (normalised) or omitted, got {s.hover_thrust}")
    if s.end_action not in ("hold", "land"):
        raise InputError("flight.end_action", f"must be hold or land, got {s.end_action!r}")
    if not (math.isfinite(s.attitude_time_constant_s) and 0.01 <= s.attitude_time_constant_s <= 2.0):
        raise InputError("flight.attitude_time_constant_s", f"must be in [0.01, 2] s, got {s.attitude_time_constant_s}")
    return s


def _attitude_time_constant(config: Any, configured: Any) -> float:
    """Rates mode's τ (s): ``flight.attitude_time_constant_s`` if set, else derived from the
    identified rate loop (``vehicle.rate_time_constant_s``: 4x it), else the default 0.25 s."""
    from pf_offboard.control.attitude import AttitudeRateLaw

    if configured is not None:
        return float(configured)
    rate_tc = getattr(getattr(config, "vehicle", None), "rate_time_constant_s", 0.0) or 0.0
    return AttitudeRateLaw.for_rate_loop(float(rate_tc)).time_constant_s


def _heights_from_config(args: argparse.Namespace, config: Any) -> None:
    """Fill ``--takeoff`` / ``--throw`` given without a height from ``flight:``."""
    flight = getattr(config, "flight", None)
    if args.takeoff is FROM_CONFIG:
        args.takeoff = getattr(flight, "takeoff_altitude_m", None)
        if args.takeoff is None:
            raise InputError("--takeoff", "no height given and the config has no flight.takeoff_altitude_m")
    if args.throw is FROM_CONFIG:
        args.throw = getattr(flight, "throw_activation_height_m", None)
        if args.throw is None:
            raise InputError("--throw", "no height given and the config has no flight.throw_activation_height_m")


def _check_args(args: argparse.Namespace) -> None:
    for flag, value in (("--takeoff", args.takeoff), ("--throw", args.throw)):
        if value is not None and not (math.isfinite(value) and 0.3 <= value <= 100.0):
            raise InputError(flag, f"height must be in [0.3, 100] m, got {value}")
    if args.laps is not None and not (math.isfinite(args.laps) and args.laps > 0):
        raise InputError("--laps", f"must be > 0, got {args.laps}")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise InputError("--duration", f"must be > 0 s, got {args.duration}")
    if not (math.isfinite(args.heartbeat_timeout) and args.heartbeat_timeout > 0):
        raise InputError("--heartbeat-timeout", f"must be > 0 s, got {args.heartbeat_timeout}")
    for flag, value in (("--ready-timeout", getattr(args, "ready_timeout", 120.0)), ("--takeoff-timeout", getattr(args, "takeoff_timeout", None))):
        if value is not None and not (math.isfinite(value) and 0 < value <= 3600):
            raise InputError(flag, f"must be in (0, 3600] s, got {value}")
    if args.target_system is not None and not 1 <= args.target_system <= 255:
        raise InputError("--target-system", f"must be a MAVLink system id in 1..255, got {args.target_system}")


def envelope_fence(config: Any) -> Any:
    """The safety fence for this config's path (pf_offboard.safety); InputError (exit 2) if the
    path itself leaves it or dips below the floor: such a flight is refused before any traffic."""
    from pf_offboard.safety import SafetyConfig, check_path, fence_for_path

    safety = getattr(config, "safety", None) or SafetyConfig()
    p = config.path
    path = p.spline()
    n = max(2, math.ceil(path.lam_max / 0.05) + 1)  # every 5 cm or finer
    points = [path.eval_floats(path.lam_max * i / (n - 1))[:3] for i in range(n)]
    fence = fence_for_path(safety, points)
    if safety.enabled:
        why = check_path(fence, points)
        if why:
            raise InputError("safety", why)
    return fence


def _rate_bound(config: Any) -> float | None:
    """safety.max_body_rate_rad_s when the envelope is on (the encoder bounds rates-mode setpoints)."""
    safety = getattr(config, "safety", None)
    return safety.max_body_rate_rad_s if safety is not None and safety.enabled else None


def default_log_dir() -> Path:
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    return Path("flights") / stamp


@dataclass
class FlyOutcome:
    """What ``fly`` hands back to callers (``demo``, tests).

    The steps are not kept in memory during the flight (the summary is computed as they stream to
    the CSV); :attr:`records` reads them back from the log on demand.
    """

    exit_code: int
    reason: str
    log_dir: Path | None
    summary: Any | None
    activation_time_s: float | None
    breach: Any | None = None  # pf_offboard.safety.Verdict when the envelope ended the flight
    breach_time_s: float | None = None  # vehicle time it was detected
    link_counters: Any | None = None  # pf_offboard.app.link.LinkCounters
    estimator: Any | None = None  # the flight's Estimator (its plausibility counters)

    @functools.cached_property
    def records(self) -> list[Any]:
        """Every step, read from the log the first time it is asked for (then kept)."""
        if self.log_dir is None:
            return []
        from pf_offboard.logs.steplog import read_steplog

        return read_steplog(self.log_dir / "flight.csv")


def run(args: argparse.Namespace) -> int:
    outcome = fly(args)
    return outcome.exit_code


def signing_key_from_args(args: argparse.Namespace) -> bytes | None:
    """The ``--signing-key`` file's key (InputError naming the flag when unreadable)."""
    path = getattr(args, "signing_key", None)
    if path is None:
        return None
    from pf_offboard.app.signing import read_key_file

    try:
        return read_key_file(path)
    except OSError as exc:
        raise InputError("--signing-key", f"cannot read {path}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise InputError("--signing-key", f"{path}: {exc}") from None


def fly(args: argparse.Namespace, status_stream: TextIO | None = None, on_start: Callable[[Any], None] | None = None) -> FlyOutcome:
    """Parse, validate and fly; prints the summary and the log path. Never hangs on a dead link.

    ``on_start(bridge)`` (optional) is called once the flight's bridge exists (benchmarks watch it).
    """
    from pf_offboard.app.link import parse_endpoint
    from pf_offboard.config import load_config

    from pf_offboard.shipped import resolve_config

    endpoint = parse_endpoint(args.connect)  # InputError before anything is opened
    signing_key = signing_key_from_args(args)
    args.config = str(resolve_config(args.config))  # a file, or a shipped config's name
    config = load_config(args.config)
    _heights_from_config(args, config)
    _check_args(args)
    settings = flight_settings(config, args)
    # a path outside the fence is bad input: refused before any traffic (a lat/lon path: once it
    # is in the local frame, after connecting but still before any setpoint or command)
    fence = envelope_fence(config) if config.path.geodetic is None else None
    if args.log_dir:
        from pf_offboard.logs._io import make_dir

        make_dir(args.log_dir, "--log-dir")  # an unwritable log directory is bad input: found before connecting
    stream = status_stream if status_stream is not None else sys.stderr
    from pf_offboard.control.tuning import real_vehicle_warning

    caution = real_vehicle_warning(config.gains, config.vehicle, config.compensation.enabled)
    if caution:  # before connecting: the paper's gains limit-cycle on a real inner loop
        print(f"pf-offboard fly: warning: {caution}", file=stream)
    try:
        return asyncio.run(_fly(args, endpoint, config, settings, stream, fence, signing_key, on_start))
    except LinkError as exc:
        print(f"pf-offboard fly: link error: {exc}", file=stream)
        return FlyOutcome(3, str(exc), None, None, None)


async def _fly(
    args: argparse.Namespace, endpoint: Any, config: Any, settings: FlightSettings, stream: TextIO, fence: Any = None,
    signing_key: bytes | None = None, on_start: Callable[[Any], None] | None = None,
) -> FlyOutcome:  # fmt: skip
    from pymavlink.dialects.v20 import common as mavlink2

    from pf_offboard.app.bridge import Bridge, BridgeOptions, EndSpec
    from pf_offboard.app.encoders import Encoder
    from pf_offboard.app.estimator import Estimator
    from pf_offboard.app.link import Link
    from pf_offboard.app.pipeline import Pipeline
    from pf_offboard.app.profiles import Autopilot, output_mode_refusal, select_profile
    from pf_offboard.control import controller_from_config
    from pf_offboard.logs.flightlog import FlightLog
    from pf_offboard.logs.measures import path_tangent
    from pf_offboard.logs.summary import SummaryAccumulator
    from pf_offboard.safety import EnvelopeMonitor, SafetyConfig

    # a path in latitude / longitude is built once the vehicle's origin is known (below)
    follower = controller_from_config(config) if config.path.geodetic is None else None
    link = Link.open(endpoint, signing_key=signing_key)
    # state that waited in the socket longer than the state timeout is never flown
    link.max_state_age_s = settings.state_timeout_s
    summary_acc = SummaryAccumulator()  # running sums: the steps themselves go to the CSV only
    log: FlightLog | None = None
    try:
        target = await link.wait_heartbeat(args.heartbeat_timeout, args.target_system)
        profile = select_profile(args.autopilot, target.autopilot)
        refusal = output_mode_refusal(profile, settings.output_mode)
        if refusal:
            if not getattr(args, "experimental_output", False):
                # before the log, the reader and any command or setpoint
                raise InputError("--output", f"{settings.output_mode} refused on {profile.name}: {refusal}")
            print(f"pf-offboard fly: warning: {settings.output_mode} on {profile.name} is experimental: {refusal}", file=stream)
        link.set_source_system(target.system)
        log_dir = Path(args.log_dir) if args.log_dir else default_log_dir()
        try:
            log = FlightLog.open(log_dir, config_path=args.config)
        except OSError as exc:
            raise InputError("--log-dir", f"cannot write the logs in {log_dir}: {exc.strerror or exc}") from None
        flight_log = log
        link.on_received = lambda m: flight_log.frame(m.get_msgbuf(), time.time())
        link.on_sent = lambda m: flight_log.frame(m.get_msgbuf(), time.time())
        if config.path.geodetic is not None:
            # a path in latitude / longitude: into the vehicle's local frame (its EKF origin), refused
            # if out of bounds, before any setpoint or command; the log keeps the local way-points
            from pf_offboard.app.origin import localise_config

            config = await localise_config(link, config, stream)
            flight_log.write_config(args.config, config)
            follower = controller_from_config(config)
        assert follower is not None

        launch = "takeoff" if args.takeoff is not None else "throw" if args.throw is not None else "airborne"
        height = args.takeoff if args.takeoff is not None else args.throw if args.throw is not None else math.nan
        path = follower.path
        summary_acc.tangent = path_tangent(path)  # the speed along the path from the position
        options = BridgeOptions(
            launch=launch,
            height_m=height,
            end=EndSpec(laps=args.laps, duration_s=args.duration),
            end_action=settings.end_action,
            setpoint_rate_hz=settings.setpoint_rate_hz,
            state_timeout_s=settings.state_timeout_s,
            status=not args.quiet,
            ready_timeout_s=getattr(args, "ready_timeout", 120.0),
            takeoff_timeout_s=getattr(args, "takeoff_timeout", None),
        )
        encoder = Encoder(
            settings.output_mode, profile, target.system, target.component,
            hover_thrust=settings.hover_thrust if settings.hover_thrust is not None else 0.5,
            time_constant_s=settings.attitude_time_constant_s,
            max_body_rate_rad_s=_rate_bound(config),
        )  # fmt: skip
        pipeline = Pipeline(follower, encoder, Estimator(args.state_source, settings.velocity_correction_s))
        safety = getattr(config, "safety", None) or SafetyConfig()
        monitor = EnvelopeMonitor(safety, fence if fence is not None else envelope_fence(config), path.length_m, path.closed)
        bridge = Bridge(
            link, profile, pipeline, options, path.length_m, path.closed, path.lam_max,
            on_step=lambda step: (flight_log.step(step.record), summary_acc.add(step.record)),  # not kept: flights can be long
            status_stream=stream, monitor=monitor,
        )  # fmt: skip
        link.start_reading(bridge.on_message)
        if on_start is not None:
            on_start(bridge)

        async def setup() -> None:
            # telemetry at the rates we need: state at the setpoint rate (a fresh sample drives
            # each setpoint), HEARTBEAT at 10 Hz so a takeover is seen within 0.1 s where honoured.
            state_id = mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED if args.state_source == "local_position" else mavlink2.MAVLINK_MSG_ID_ODOMETRY
            # each request three times: idempotent, and a lossy link must not leave HEARTBEAT at 1 Hz
            # (the lost-HEARTBEAT watchdog counts on it)
            state_name = "LOCAL_POSITION_NED" if args.state_source == "local_position" else "ODOMETRY"
            await bridge.request_intervals([
                (state_id, settings.setpoint_rate_hz, state_name),
                (mavlink2.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, settings.setpoint_rate_hz, "ATTITUDE_QUATERNION"),
                (mavlink2.MAVLINK_MSG_ID_HEARTBEAT, 10.0, "HEARTBEAT"),
            ])  # fmt: skip
            for _ in range(2):  # twice more, not waited for: idempotent
                for msg_id, rate in ((state_id, settings.setpoint_rate_hz), (mavlink2.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, settings.setpoint_rate_hz), (mavlink2.MAVLINK_MSG_ID_HEARTBEAT, 10.0)):
                    bridge.request_interval(msg_id, rate)
            await read_setpoint_mapping(bridge, profile, settings, pipeline, stream)
            if profile.autopilot is Autopilot.ARDUPILOT:
                await _check_guid_options(bridge, profile.required_guid_options(settings.output_mode), args.set_guid_options, settings.output_mode)
                if settings.output_mode == "acceleration":
                    jerk = min(await bridge.read_param("PSC_JERK_XY"), await bridge.read_param("PSC_JERK_Z"))
                    if jerk < 20.0:
                        print(f"pf-offboard fly: warning: ArduPilot jerk-limits acceleration targets (PSC_JERK_XY/Z = {jerk:g} m/s^3): "
                              "expect lag and, at high gains, oscillation; raise PSC_JERK_XY/Z or use --output rates", file=stream)  # fmt: skip

        loop = asyncio.get_running_loop()
        # SIGTERM (systemd, docker stop) and SIGHUP (the terminal closed) end the flight like Ctrl-C:
        # hold requested, summary printed, logs closed.
        stops = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM", signal.SIGHUP: "SIGHUP"}
        for signum, name in stops.items():
            loop.add_signal_handler(signum, bridge.request_stop, f"stop requested ({name})")
        # The path, its caches and pymavlink's tables live for the whole flight: take them out of
        # the cyclic collector's scans so full collections do not stall the 250 Hz loop.
        gc.freeze()
        try:
            async with asyncio.TaskGroup() as tg:
                flight = tg.create_task(bridge.fly(setup))
                helpers = [tg.create_task(bridge.keepalive()), tg.create_task(bridge.heartbeat()), tg.create_task(bridge.status_line())]
                result = await flight
                for task in helpers:  # they poll the phase once a period (HEARTBEAT: 1 s): end them now
                    task.cancel()
        except BaseExceptionGroup as group:
            # TaskGroup wraps what a task raised: hand bad input (InputError -> exit 2, e.g. GUID_OPTIONS
            # refused in setup) and link failures (-> exit 3) on as themselves, not as a traceback.
            first = _first_leaf(group)
            if isinstance(first, (InputError, LinkError)):
                raise first from None
            raise
        finally:
            for signum in stops:
                loop.remove_signal_handler(signum)
    finally:
        link.close()
        if log is not None:
            log.close()
    assert log is not None
    summary = summary_acc.result() if summary_acc.steps else None
    _report(stream, result.reason, result.exit_code, summary, log.paths.tlog.parent, bridge)
    _write_summary_json(args, result.exit_code, result.reason, summary, log.paths.tlog.parent, config)
    return FlyOutcome(
        result.exit_code, result.reason, log.paths.tlog.parent, summary, result.activation_time_s, result.breach,
        result.breach_time_s, link.counters, pipeline.estimator,
    )  # fmt: skip


def _write_summary_json(args: argparse.Namespace, code: int, reason: str, summary: Any, log_dir: Path, config: Any) -> None:
    """``LOG_DIR/summary.json`` always; with ``--json`` the same report on stdout."""
    from pf_offboard.logs.summary import flight_report, report_json, write_report

    report = flight_report(summary, code, reason, log_dir, config)
    write_report(report, log_dir)
    if getattr(args, "json", False):
        print(report_json(report))


def _first_leaf(group: BaseExceptionGroup) -> BaseException:  # type: ignore[type-arg]
    first: BaseException = group
    while isinstance(first, BaseExceptionGroup):
        first = first.exceptions[0]
    return first


async def read_setpoint_mapping(bridge: Any, profile: Any, settings: FlightSettings, pipeline: Any, stream: TextIO) -> None:
    """Read what the encoder needs to know of the autopilot's setpoint mapping and set it.

    attitude / rates: the hover thrust (unless the config gives one); a value no vehicle hovers at
    is a link error. acceleration: whether the autopilot tilts from g alone
    (:attr:`Profile.accel_tilt_param`, PX4's MPC_ACC_DECOUPLE); without an answer the profile's
    default (PX4's own default) is kept and a warning says so.
    """
    if settings.output_mode != "acceleration":
        if settings.hover_thrust is None:
            hover = await bridge.read_param(profile.hover_thrust_param)
            if not 0.05 <= hover <= 0.95:
                raise LinkError(f"{profile.hover_thrust_param} = {hover:g} is not a plausible hover thrust")
            pipeline.encoder = pipeline.encoder.with_hover_thrust(float(hover))
        return
    if profile.accel_tilt_param is None:
        return
    try:
        value = await bridge.read_param(profile.accel_tilt_param)
    except LinkError as exc:
        default = "1 (tilt from g alone)" if profile.accel_tilt_from_gravity else "0"
        print(f"pf-offboard: warning: {exc}; assuming {profile.accel_tilt_param} = {default}, the autopilot's default", file=stream)
        return
    if value not in (0.0, 1.0):
        raise LinkError(f"{profile.accel_tilt_param} = {value:g} is neither 0 nor 1")
    pipeline.encoder = pipeline.encoder.with_tilt_from_gravity(profile.tilts_from_gravity(value))


async def _check_guid_options(bridge: Any, required: int, allow_set: bool, output_mode: str) -> None:
    """ArduPilot: make sure GUID_OPTIONS has the bits the output mode needs, or refuse."""
    value = int(await bridge.read_param("GUID_OPTIONS"))
    if value & required == required:
        return
    missing = required & ~value
    if not allow_set:
        raise InputError(
            "--set-guid-options",
            f"ArduPilot GUID_OPTIONS={value} lacks bit(s) {missing} needed by --output {output_mode} "
            "(8: thrust as thrust; 16: no XY position correction); set them on the vehicle or pass --set-guid-options",
        )
    from pymavlink.dialects.v20 import common as mavlink2

    await bridge.write_param("GUID_OPTIONS", float(value | required), mavlink2.MAV_PARAM_TYPE_INT32)


def _report(stream: TextIO, reason: str, code: int, summary: Any, log_dir: Path, bridge: Any) -> None:
    """The end-of-flight report on ``stream``: outcome, safety, summary, what the link and estimator refused."""
    lines = [f"pf-offboard fly: {reason} (exit {code})"]
    if bridge.breach is not None:
        when = f" at t = {bridge.breach_time_s:.2f} s" if bridge.breach_time_s is not None else ""
        lines.append(f"  safety: {bridge.breach.kind.value}{when}: {bridge.breach.reason}")
    if bridge.monitor is not None:
        lines.append(f"  safety: max measured tilt {math.degrees(bridge.monitor.max_tilt_seen_rad):.1f} deg; fence {bridge.monitor.fence.describe()}")
    if bridge.pipeline.replaced_steps:
        lines.append(f"  safe hold sent instead of a non-finite command {bridge.pipeline.replaced_steps} times")
    if summary is not None:
        lines += ["  " + line for line in summary.lines()]
    link = bridge.link
    lines.append(f"  link                {'signed' if link.signing else 'unsigned'}; {link.counters.line()}")
    est = bridge.pipeline.estimator
    if est.rejected:
        lines.append(
            f"  state samples       rejected {est.rejected}: {est.rejected_old} old/duplicated, {est.clock_jumps} clock jumps "
            f"({est.clock_reanchors} confirmed), {est.rejected_jumps} position jumps ({est.position_resets} confirmed as resets)"
            + (f"; last: {est.last_event}" if est.last_event else "")
        )
    for line in lines:
        print(line, file=stream)
    print(f"logs: {log_dir}", file=stream)
