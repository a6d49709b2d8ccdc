"""``pf-offboard fly``: follow a path on a PX4 / ArduPilot vehicle over MAVLink.

One asyncio loop: the link reader (an event-loop callback on the socket), and one TaskGroup
supervising the flight itself, the keep-alive / watchdog, our HEARTBEAT and the status line.
See docs/app.md for the behaviour in full.
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import gc
import math
import signal
import sys
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable
from typing import Any, TextIO

from pf_offboard.app.settings import (  # noqa: F401  (re-exported: the API and tests use them from here too)
    FlightSettings,
    default_log_dir,
    envelope_fence,
    flight_settings_for,
)
from pf_offboard.errors import InputError, LinkError

LAUNCHES = ("takeoff", "airborne", "throw")
# `--takeoff` / `--throw` without a height: take it from the config's flight: section. An object,
# not a number a user could type (`--throw -1` must be refused, not read as "from the config"),
# and not a string (argparse would pass a string const through type=float).
FROM_CONFIG: Any = object()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--connect", required=True, metavar="ENDPOINT",
                        help="udp://:14540 | udpout://HOST:PORT | tcp://HOST:PORT | serial:///dev/ttyACM0:921600 (MAVSDK), or "
                             "udpin:HOST:PORT | udpout:HOST:PORT | tcp:HOST:PORT | tcpin:HOST:PORT | /dev/ttyACM0,921600 "
                             "(pymavlink); PX4 SITL: udp://:14540; ArduPilot SITL: tcp://127.0.0.1:5760")  # fmt: skip
    parser.add_argument("--config", required=True, metavar="YAML", help="config file, or a shipped config's name (pf-offboard configs)")
    launch = parser.add_mutually_exclusive_group(required=True)
    launch.add_argument("--takeoff", type=float, nargs="?", const=FROM_CONFIG, metavar="H",
                        help="arm, take off to H metres (default: a plan's take-off altitude, else flight.takeoff_altitude_m; raised to the path's fence floor), then follow")  # fmt: skip
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
    parser.add_argument("--command-timeout", type=float, default=5.0, metavar="S",
                        help="give up on a mode / arm / parameter request not answered within S seconds, re-sent meanwhile (default 5)")  # fmt: skip
    parser.add_argument("--takeoff-timeout", type=float, metavar="S",
                        help="--takeoff: give up if the take-off altitude is not held within S seconds (default 30 + 5 s per metre)")  # fmt: skip
    parser.add_argument("--offboard-loss", choices=("check", "hold", "land"), default="check",
                        help="what the vehicle does if the app dies: check (read and report it, refuse if the motors would "
                             "stop), or set it to hold / land where the autopilot allows (PX4 COM_OBL_RC_ACT); see docs/safety.md")  # fmt: skip
    parser.add_argument("--log-dir", metavar="DIR", help="default: ./flights/<UTC timestamp>/")
    parser.add_argument("--quiet", action="store_true", help="no status line")
    parser.add_argument("--json", action="store_true", help="print the flight report (as in LOG_DIR/summary.json) as JSON on stdout")


def flight_settings(config: Any, args: argparse.Namespace) -> FlightSettings:
    """Read ``config.flight`` (tolerating a config without one) and apply the flags; validate."""
    return flight_settings_for(config, output=args.output, end_action=args.end_action)


def _heights_from_config(args: argparse.Namespace, config: Any) -> None:
    """Fill ``--takeoff`` / ``--throw`` given without a height from ``flight:``."""
    flight = getattr(config, "flight", None)
    if args.takeoff is FROM_CONFIG:
        # a planning tool's take-off item (QGroundControl's take-off altitude) first, then flight:
        geodetic = getattr(getattr(config, "path", None), "geodetic", None)
        planned = getattr(geodetic, "takeoff_alt_m", None)
        args.takeoff = planned if planned is not None else getattr(flight, "takeoff_altitude_m", None)
        if args.takeoff is None:
            raise InputError("--takeoff", "no height given and the config has no flight.takeoff_altitude_m")
    if args.throw is FROM_CONFIG:
        args.throw = getattr(flight, "throw_activation_height_m", None)
        if args.throw is None:
            raise InputError("--throw", "no height given and the config has no flight.throw_activation_height_m")


# Durations and counts below these mean nothing a vehicle can fly (1e-320 s is not a duration): refused.
MIN_DURATION_S = 0.01
MIN_LAPS = 1e-3


def _check_args(args: argparse.Namespace) -> None:
    for flag, value in (("--takeoff", args.takeoff), ("--throw", args.throw)):
        if value is not None and not (math.isfinite(value) and 0.3 <= value <= 100.0):
            raise InputError(flag, f"height must be in [0.3, 100] m, got {value}")
    if args.laps is not None and not (math.isfinite(args.laps) and MIN_LAPS <= args.laps <= 1e6):
        raise InputError("--laps", f"must be in [{MIN_LAPS:g}, 1e6], got {args.laps}")
    if args.duration is not None and not (math.isfinite(args.duration) and MIN_DURATION_S <= args.duration <= 1e6):
        raise InputError("--duration", f"must be in [{MIN_DURATION_S:g}, 1e6] s, got {args.duration}")
    if not (math.isfinite(args.heartbeat_timeout) and MIN_DURATION_S <= args.heartbeat_timeout <= 3600):
        raise InputError("--heartbeat-timeout", f"must be in [{MIN_DURATION_S:g}, 3600] s, got {args.heartbeat_timeout}")
    for flag, value in (("--ready-timeout", getattr(args, "ready_timeout", 120.0)), ("--takeoff-timeout", getattr(args, "takeoff_timeout", None)),
                        ("--command-timeout", getattr(args, "command_timeout", 5.0))):  # fmt: skip
        if value is not None and not (math.isfinite(value) and MIN_DURATION_S <= value <= 3600):
            raise InputError(flag, f"must be in [{MIN_DURATION_S:g}, 3600] s, got {value}")
    if args.target_system is not None and not 1 <= args.target_system <= 255:
        raise InputError("--target-system", f"must be a MAVLink system id in 1..255, got {args.target_system}")


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


@dataclass(frozen=True)
class FlyRequest:
    """Everything ``fly`` was asked for, typed and validated: built once from the command line
    (:func:`request_from_args`); nothing below sees ``argparse``."""

    connect: str
    config_path: str  # resolved: a file
    launch: str  # "takeoff" | "airborne" | "throw"
    height_m: float  # take-off altitude or throw activation height; nan when airborne
    autopilot: str = "auto"
    laps: float | None = None
    duration_s: float | None = None
    target_system: int | None = None
    heartbeat_timeout_s: float = 10.0
    state_source: str = "local_position"
    set_guid_options: bool = False
    experimental_output: bool = False
    ready_timeout_s: float = 120.0
    takeoff_timeout_s: float | None = None
    command_timeout_s: float = 5.0
    log_dir: str | None = None
    quiet: bool = False
    json: bool = False
    offboard_loss: str | None = None  # None: check only; "hold" / "land": set the autopilot's action


def request_from_args(args: argparse.Namespace, config: Any) -> FlyRequest:
    """The typed request of ``fly``'s flags (heights from the config where not given); InputError
    naming the flag for anything out of range."""
    _heights_from_config(args, config)
    _check_args(args)
    launch = "takeoff" if args.takeoff is not None else "throw" if args.throw is not None else "airborne"
    height = args.takeoff if args.takeoff is not None else args.throw if args.throw is not None else math.nan
    return FlyRequest(
        connect=args.connect, config_path=str(args.config), launch=launch, height_m=float(height),
        autopilot=args.autopilot, laps=args.laps, duration_s=args.duration, target_system=args.target_system,
        heartbeat_timeout_s=args.heartbeat_timeout, state_source=args.state_source,
        set_guid_options=bool(getattr(args, "set_guid_options", False)),
        experimental_output=bool(getattr(args, "experimental_output", False)),
        ready_timeout_s=getattr(args, "ready_timeout", 120.0), takeoff_timeout_s=getattr(args, "takeoff_timeout", None),
        command_timeout_s=getattr(args, "command_timeout", 5.0), log_dir=args.log_dir, quiet=bool(args.quiet), json=bool(getattr(args, "json", False)),
        offboard_loss=None if getattr(args, "offboard_loss", "check") == "check" else args.offboard_loss,
    )  # fmt: skip


def fly(args: argparse.Namespace, status_stream: TextIO | None = None, on_start: Callable[[Any], None] | None = None) -> FlyOutcome:
    """Parse, validate and fly; prints the summary and the log path. Never hangs on a dead link.

    ``on_start(flight)`` (optional) is called once the :class:`~pf_offboard.app.flight.Flight`
    exists (benchmarks watch it).
    """
    from pf_offboard.app.link import parse_endpoint
    from pf_offboard.config import load_config
    from pf_offboard.shipped import resolve_config

    endpoint = parse_endpoint(args.connect)
    endpoint.check_local()  # InputError before anything is opened
    signing_key = signing_key_from_args(args)
    args.config = str(resolve_config(args.config))  # a file, or a shipped config's name
    config = load_config(args.config)
    request = request_from_args(args, config)
    settings = flight_settings(config, args)
    return fly_request(request, endpoint, config, settings, signing_key, status_stream, on_start)


def fly_request(
    request: FlyRequest, endpoint: Any, config: Any, settings: FlightSettings, signing_key: bytes | None = None,
    status_stream: TextIO | None = None, on_start: Callable[[Any], None] | None = None,
) -> FlyOutcome:  # fmt: skip
    """Fly a validated request (see :func:`fly`)."""
    # a path outside the fence is bad input: refused before any traffic (a lat/lon path: once it
    # is in the local frame, after connecting but still before any setpoint or command)
    fence = envelope_fence(config) if config.path.geodetic is None else None
    if request.log_dir:
        from pf_offboard.logs._io import make_dir

        make_dir(request.log_dir, "--log-dir")  # an unwritable log directory is bad input: found before connecting
    stream = status_stream if status_stream is not None else sys.stderr
    from pf_offboard.control.tuning import real_vehicle_warning

    caution = real_vehicle_warning(config.gains, config.vehicle, config.compensation.enabled)
    if caution:  # before connecting: the paper's gains limit-cycle on a real inner loop
        print(f"pf-offboard fly: warning: {caution}", file=stream)
    try:
        return asyncio.run(_fly(request, endpoint, config, settings, stream, fence, signing_key, on_start))
    except LinkError as exc:
        print(f"pf-offboard fly: link error: {exc}", file=stream)
        return FlyOutcome(3, str(exc), None, None, None)


async def _fly(
    request: FlyRequest, endpoint: Any, config: Any, settings: FlightSettings, stream: TextIO, fence: Any = None,
    signing_key: bytes | None = None, on_start: Callable[[Any], None] | None = None,
) -> FlyOutcome:  # fmt: skip
    """``fly`` as a client of the API (:mod:`pf_offboard.api`): connect, one follow, report."""
    from pf_offboard.api.vehicle import ConnectSettings, FlightHooks, FollowSettings, Vehicle
    from pf_offboard.errors import FlightError

    loop = asyncio.get_running_loop()
    # SIGTERM (systemd, docker stop) and SIGHUP (the terminal closed) end the flight like Ctrl-C:
    # hold requested, summary printed, logs closed.
    stops = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM", signal.SIGHUP: "SIGHUP"}

    def started(flight: Any) -> None:
        for signum, name in stops.items():
            loop.add_signal_handler(signum, flight.request_stop, f"stop requested ({name})")
        # The path, its caches and pymavlink's tables live for the whole flight: take them out of
        # the cyclic collector's scans so full collections do not stall the 250 Hz loop.
        gc.freeze()
        if on_start is not None:
            on_start(flight)

    def ended(flight: Any) -> None:
        for signum in stops:
            loop.remove_signal_handler(signum)

    connect = ConnectSettings(endpoint, request.autopilot, request.target_system, request.heartbeat_timeout_s, signing_key, request.quiet)
    follow = FollowSettings(
        launch=request.launch, height_m=request.height_m, laps=request.laps, duration_s=request.duration_s,
        output=settings.output_mode, end_action=settings.end_action, state_source=request.state_source,
        set_guid_options=request.set_guid_options, experimental_output=request.experimental_output,
        ready_timeout_s=request.ready_timeout_s, takeoff_timeout_s=request.takeoff_timeout_s,
        command_timeout_s=request.command_timeout_s,
        log_dir=request.log_dir or str(default_log_dir()), offboard_loss=request.offboard_loss,
    )  # fmt: skip
    hooks = FlightHooks(on_start=started, on_end=ended, fence=fence, config_path=request.config_path)
    async with Vehicle(connect, stream) as vehicle:
        try:
            result = await vehicle._run(config, follow, hooks)
        except FlightError as exc:
            if exc.result is None:
                raise
            result = exc.result
    flight = result.flight
    _report(stream, result.reason, result.exit_code, result.summary, result.log_dir, flight)
    _write_summary_json(request.json, result.exit_code, result.reason, result.summary, result.log_dir, result.config,
                        flight.pipeline.tilt_limit_deg)  # fmt: skip
    return FlyOutcome(
        result.exit_code, result.reason, result.log_dir, result.summary, result.activation_time_s, result.breach,
        result.breach_time_s, result.link_counters, result.estimator,
    )  # fmt: skip


def _write_summary_json(as_json: bool, code: int, reason: str, summary: Any, log_dir: Path, config: Any,
                        tilt_limit_deg: float | None = None) -> None:  # fmt: skip
    """``LOG_DIR/summary.json`` always; with ``--json`` the same report on stdout."""
    from pf_offboard.logs.summary import flight_report, report_json, write_report

    report = flight_report(summary, code, reason, log_dir, config, tilt_limit_deg=tilt_limit_deg)
    try:
        write_report(report, log_dir)
    except OSError as exc:  # a full disk: the flight's outcome is still reported on the terminal
        print(f"pf-offboard fly: warning: cannot write {log_dir}/summary.json: {exc.strerror or exc}", file=sys.stderr)
    if as_json:
        print(report_json(report))


def _report(stream: TextIO, reason: str, code: int, summary: Any, log_dir: Path, flight: Any) -> None:
    """The end-of-flight report on ``stream``: outcome, safety, summary, what the link and estimator refused."""
    lines = [f"pf-offboard fly: {reason} (exit {code})"]
    if flight.breach is not None:
        when = f" at t = {flight.breach_time_s:.2f} s" if flight.breach_time_s is not None else ""
        lines.append(f"  safety: {flight.breach.kind.value}{when}: {flight.breach.reason}")
    if flight.monitor is not None:
        lines.append(f"  safety: max measured tilt {math.degrees(flight.monitor.max_tilt_seen_rad):.1f} deg; fence {flight.monitor.fence.describe()}")
    tilt = flight.pipeline.tilt_limit_deg
    if tilt is not None:
        lines.append(f"  tilt limit flown    {tilt:g} deg")
    if flight.pipeline.replaced_steps:
        lines.append(f"  safe hold sent instead of a non-finite command {flight.pipeline.replaced_steps} times")
    if summary is not None:
        lines += ["  " + line for line in summary.lines()]
    link = flight.link
    lines.append(f"  link                {'signed' if link.signing else 'unsigned'}; {link.counters.line()}")
    est = flight.pipeline.estimator
    if est.rejected:
        lines.append(
            f"  state samples       rejected {est.rejected}: {est.rejected_old} old/duplicated, {est.clock_jumps} clock jumps "
            f"({est.clock_reanchors} confirmed), {est.rejected_jumps} position jumps ({est.position_resets} confirmed as resets)"
            + (f"; last: {est.last_event}" if est.last_event else "")
        )
    for line in lines:
        print(line, file=stream)
    print(f"logs: {log_dir}", file=stream)
