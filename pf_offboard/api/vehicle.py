"""The asyncio API: connect to an autopilot, take off, follow paths, watch progress, hand back.

::

    import pf_offboard

    async with pf_offboard.connect("udp://:14540") as vehicle:
        await vehicle.takeoff(2.0)
        result = await vehicle.follow("field.yaml", laps=2)
        await vehicle.hand_back()

One :class:`Vehicle` per connection. Each :meth:`Vehicle.follow` (and :meth:`Vehicle.takeoff`) is
one flight of the app (:class:`pf_offboard.app.flight.Flight`: the same phases, safety,
confirmation and logs as ``pf-offboard fly``), ending in the hand-back mode (hold) confirmed by
the autopilot, so several follows in a row each start from a vehicle the autopilot holds. An
ending other than the one asked for raises a :class:`pf_offboard.FlightError` subclass carrying
``pf-offboard fly``'s exit code and the partial :class:`FollowResult`.
"""

from __future__ import annotations

import asyncio
import math
import os
import sys
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, replace
from pathlib import Path as FilePath
from typing import Any, TextIO

from pf_offboard.api.results import FollowResult, Progress
from pf_offboard.errors import (
    AnotherController,
    AutopilotFailsafe,
    CommandRefused,
    CrashDetected,
    EnvelopeBreach,
    FlightError,
    FlightInterrupted,
    InputError,
    LinkError,
    LinkLost,
    OperatorTakeover,
)

LAUNCHES = ("takeoff", "airborne", "throw")
PATH_FILE_SUFFIXES = (".plan", ".waypoints", ".csv", ".geojson", ".kml")

_ERRORS: dict[int, type[FlightError]] = {
    3: LinkLost,
    4: OperatorTakeover,
    5: EnvelopeBreach,
    6: CrashDetected,
    7: AutopilotFailsafe,
    8: AnotherController,
    130: FlightInterrupted,
}


@dataclass(frozen=True)
class ConnectSettings:
    """How to reach the autopilot (see :func:`connect`)."""

    endpoint: Any  # text as the user wrote it, or a parsed pf_offboard.app.link.Endpoint
    autopilot: str = "auto"  # auto (from HEARTBEAT) | px4 | ardupilot
    target_system: int | None = None
    heartbeat_timeout_s: float = 30.0
    signing_key: bytes | None = None
    quiet: bool = False  # no status line / progress messages


@dataclass(frozen=True)
class FollowSettings:
    """One flight: how it is launched and ended, and its output (see :meth:`Vehicle.follow`)."""

    launch: str = "airborne"  # takeoff | airborne | throw
    height_m: float = math.nan  # take-off altitude / throw activation height (m above home)
    laps: float | None = None
    duration_s: float | None = None
    output: str | None = None  # acceleration | attitude | rates; None: the config's
    end_action: str | None = None  # hold | land; None: the config's
    state_source: str = "local_position"
    set_guid_options: bool = False
    experimental_output: bool = False
    ready_timeout_s: float = 120.0
    takeoff_timeout_s: float | None = None
    command_timeout_s: float = 5.0  # per mode / arm / parameter request, re-sent meanwhile (wall clock)
    log_dir: str | None = None  # None: no logs
    quiet: bool | None = None  # None: as connected
    open_path_end: bool = True  # end at the end of an open path
    offboard_loss: str | None = None  # what the vehicle does if the app dies: None checks it; hold | land sets it

    def validated(self) -> FollowSettings:
        if self.launch not in LAUNCHES:
            raise InputError("launch", f"must be one of {', '.join(LAUNCHES)}, got {self.launch!r}")
        if self.launch != "airborne" and not (math.isfinite(self.height_m) and 0.3 <= self.height_m <= 100.0):
            raise InputError("height_m", f"must be in [0.3, 100] m, got {self.height_m}")
        for name, value in (("laps", self.laps), ("duration_s", self.duration_s)):
            if value is not None and not (math.isfinite(value) and value > 0):
                raise InputError(name, f"must be > 0, got {value}")
        for name, value in (("ready_timeout_s", self.ready_timeout_s), ("takeoff_timeout_s", self.takeoff_timeout_s),
                            ("command_timeout_s", self.command_timeout_s)):  # fmt: skip
            if value is not None and not (math.isfinite(value) and 0 < value <= 3600):
                raise InputError(name, f"must be in (0, 3600] s, got {value}")
        if self.offboard_loss not in (None, "hold", "land"):
            raise InputError("offboard_loss", f"must be None, hold or land, got {self.offboard_loss!r}")
        if self.state_source not in ("local_position", "odometry"):
            raise InputError("state_source", f"must be local_position or odometry, got {self.state_source!r}")
        return self


@dataclass(frozen=True)
class FlightHooks:
    """For the CLI and benchmarks: ``on_start(flight)`` once the flight exists, ``on_end(flight)``
    once it ended; ``fence``: the safety fence already computed (before connecting)."""

    on_start: Callable[[Any], None] | None = None
    on_end: Callable[[Any], None] | None = None
    fence: Any = None
    config_path: str | None = None  # logged with the flight
    log_name: str = "flight"
    # your own controller instead of a path's: ``follower_factory(estimator)`` (anything with
    # update(position_enu_m, velocity_enu_m_s) -> Command and reset()), its flight settings from
    # ``flight_config``; no path, so no envelope
    follower_factory: Callable[[Any], Any] | None = None
    flight_config: Any = None
    on_step: Callable[[Any, Any], None] | None = None  # (step, flight), after logging
    wait_for_streams: bool = True  # wait for each SET_MESSAGE_INTERVAL's ACK (and repeat each twice)
    output_warnings: bool = True


def load_follow_config(path: Any, speed_m_s: float | None = None, altitude_reference: str | None = None) -> Any:
    """A :class:`pf_offboard.Config` from what :meth:`Vehicle.follow` accepts: a Config, a
    :class:`pf_offboard.Path` (with ``speed_m_s``), a config file / shipped config name, or a
    way-point file from a planning tool (QGC ``.plan``, ``.waypoints``, ``.csv``, ``.geojson``,
    ``.kml``; its altitudes as the file says, else ``altitude_reference``: relative_home | amsl).
    ``speed_m_s`` overrides the config's speed (its sign picks the direction)."""
    from pf_offboard.config import Config, load_config, parse_config

    if isinstance(path, Config):
        config = path
    elif hasattr(path, "waypoints") and hasattr(path, "lam_max"):  # a pf_offboard.Path
        if speed_m_s is None:
            raise InputError("speed", "a Path needs a speed (m/s; its sign picks the direction of travel)")
        data = {"path": {"waypoints": [list(map(float, p)) for p in path.waypoints], "closed": bool(path.closed),
                         "moving_frame": path.frame_kind}, "speed_m_s": float(speed_m_s)}  # fmt: skip
        return parse_config(data, "<Path>")
    elif isinstance(path, (str, os.PathLike)):
        text = os.fspath(path)
        if text.lower().endswith(PATH_FILE_SUFFIXES):
            file = FilePath(text)
            if not file.is_file():
                raise InputError("path", f"no such file: {text}")
            from pf_offboard.geopath import read_geopath

            reference = altitude_reference or read_geopath(str(file)).altitude_reference
            if reference is None:
                raise InputError("altitude_reference", f"{text} does not say what its altitudes are relative to: "
                                 "pass altitude_reference='relative_home' (above home) or 'amsl'")  # fmt: skip
            data: dict[str, Any] = {"path": {"file": str(file.resolve()), "altitude_reference": reference}}
            if speed_m_s is not None:
                data["speed_m_s"] = float(speed_m_s)
            return parse_config(data, str(file))
        from pf_offboard.shipped import resolve_config

        config = load_config(resolve_config(text, "path"))
    else:
        raise InputError("path", f"must be a config file, a way-point file, a Config or a Path, got {type(path).__name__}")
    if speed_m_s is not None:
        if not (math.isfinite(speed_m_s) and abs(speed_m_s) >= 0.01):
            raise InputError("speed", f"must be a non-zero speed in m/s, got {speed_m_s}")
        config = replace(config, speed_m_s=float(speed_m_s))
    return config


class _NoFollower:
    """The follower of a take-off-only flight: never stepped (no path)."""

    speed = math.nan

    def update(self, *args: Any, **kwargs: Any) -> Any:
        raise ArithmeticError("no path: take-off only")

    def reset(self) -> None:
        pass


class Vehicle:
    """One connection to an autopilot. Use :func:`pf_offboard.connect` (``async with``)."""

    def __init__(self, settings: ConnectSettings, status_stream: TextIO | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.settings = settings
        self.stream = status_stream if status_stream is not None else sys.stderr
        self.clock = clock
        self.link: Any = None
        self.target: Any = None
        self.profile: Any = None
        self.dialect: Any = None
        self._flight: Any = None  # the flight running now, if any
        self._flight_task: asyncio.Task[Any] | None = None
        self._last_heartbeat: Any = None
        self._idle: Any = None  # (ModeWatch, Commander) between flights
        self._tasks: list[asyncio.Task[Any]] = []
        self._closed = True
        self._last_progress = Progress("idle", "?", False)
        self._offboard_ours = False  # OFFBOARD / GUIDED left on by our previous flight (ArduPilot after a take-off)

    # ------------------------------------------------------------------ connection

    async def __aenter__(self) -> Vehicle:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def open(self) -> None:
        """Open the link and wait for the autopilot's HEARTBEAT (saying so, with the time waited)."""
        from pf_offboard.app.commands import Commander, CommandTiming, ModeWatch
        from pf_offboard.app.dialects import dialect_for
        from pf_offboard.app.link import Endpoint, Link, parse_endpoint
        from pf_offboard.app.profiles import select_profile
        from pf_offboard.app.waiting import Waiter

        s = self.settings
        endpoint = s.endpoint if isinstance(s.endpoint, Endpoint) else parse_endpoint(s.endpoint)
        if not (math.isfinite(s.heartbeat_timeout_s) and s.heartbeat_timeout_s > 0):
            raise InputError("heartbeat_timeout_s", f"must be > 0 s, got {s.heartbeat_timeout_s}")
        link = Link.open(endpoint, signing_key=s.signing_key)
        try:
            target = await link.wait_heartbeat(s.heartbeat_timeout_s, s.target_system, announce=self._say)
            profile = select_profile(s.autopilot, target.autopilot)
        except LinkError as exc:
            link.close()
            raise LinkLost(str(exc)) from None
        except BaseException:
            link.close()
            raise
        link.set_source_system(target.system)
        self.link, self.target, self.profile, self.dialect = link, target, profile, dialect_for(profile)
        self._last_heartbeat = link.first_heartbeat
        waiter = Waiter(self.clock, lambda: False)
        modes = ModeWatch(profile)
        modes.record(link.first_heartbeat)
        commander = Commander(link, modes, waiter, CommandTiming(), self._say, self._note, lambda: False)
        self._idle = (modes, commander, waiter)
        self._closed = False
        link.start_reading(self._dispatch)
        self._tasks.append(asyncio.get_running_loop().create_task(self._heartbeats()))

    async def close(self) -> None:
        """Hand back if a flight is running (confirmed), then close the link."""
        if self._closed:
            return
        try:
            await self._stop_flight("left the connection's async with block")
        finally:
            self._closed = True
            for task in self._tasks:
                task.cancel()
            self._tasks.clear()
            self.link.close()

    def _say(self, text: str) -> None:
        if not self.settings.quiet:
            self._note(text)

    def _note(self, text: str) -> None:
        self.stream.write(("\r\x1b[K" if self.stream.isatty() else "") + text + "\n")
        self.stream.flush()

    def _dispatch(self, msg: Any) -> None:
        """Every message from the target: to the flight running now; the HEARTBEAT, ACKs and
        text also to the connection's own state (between flights)."""
        modes, commander, waiter = self._idle
        kind = msg.get_type()
        if kind == "HEARTBEAT" and msg.get_srcComponent() == self.target.component:
            if self._last_heartbeat is not None and msg.custom_mode != self._last_heartbeat.custom_mode:
                self._offboard_ours = False  # someone changed the mode since our flight left it
            self._last_heartbeat = msg
            modes.record(msg)
            waiter.notify()
        elif kind == "COMMAND_ACK" and self._flight is None:
            commander.on_ack(msg)
        elif kind == "STATUSTEXT" and self._flight is None:
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            commander.last_statustext = text.rstrip("\x00")
        if self._flight is not None:
            self._flight.on_message(msg)

    async def _heartbeats(self) -> None:
        """Our 1 Hz HEARTBEAT between flights (a flight sends its own)."""
        while True:
            await asyncio.sleep(1.0)
            if self._flight is None:
                try:
                    self.link.send_heartbeat()
                except LinkError:
                    pass

    # ------------------------------------------------------------------ flights
    async def takeoff(self, height_m: float = 2.0, *, ready_timeout_s: float = 120.0, timeout_s: float | None = None) -> FollowResult:
        """Arm, take off to ``height_m`` above home and return once the altitude is held; the
        autopilot then holds the vehicle (hold mode, confirmed). Raises :class:`CommandRefused`
        when OFFBOARD / GUIDED, arming or the take-off is refused or not confirmed."""
        settings = FollowSettings(launch="takeoff", height_m=float(height_m), end_action="hold",
                                  ready_timeout_s=ready_timeout_s, takeoff_timeout_s=timeout_s).validated()  # fmt: skip
        return await self._run(None, settings, FlightHooks())

    async def follow(
        self,
        path: Any,
        *,
        speed: float | None = None,
        altitude_reference: str | None = None,
        laps: float | None = None,
        duration_s: float | None = None,
        output: str | None = None,
        end_action: str | None = None,
        launch: str = "airborne",
        height_m: float | None = None,
        log_dir: str | os.PathLike[str] | None = None,
        set_guid_options: bool = False,
        experimental_output: bool = False,
        state_source: str = "local_position",
        ready_timeout_s: float = 120.0,
        takeoff_timeout_s: float | None = None,
        command_timeout_s: float = 5.0,
    ) -> FollowResult:
        """Follow ``path`` (a config file or shipped name, a QGC ``.plan`` or other way-point file,
        a :class:`pf_offboard.Config`, or a :class:`pf_offboard.Path` with ``speed``) until
        ``laps`` / ``duration_s`` (vehicle time) / the end of an open path, then hand back in
        ``end_action`` (hold | land; default the config's), confirmed. ``launch``: ``airborne``
        (the vehicle flies: switch to OFFBOARD / GUIDED), ``takeoff`` or ``throw`` (with
        ``height_m``). ``output``: acceleration | attitude | rates (default the config's).
        ``log_dir``: write the flight's logs there (default: none). Raises a
        :class:`pf_offboard.FlightError` subclass when it ends any other way."""
        config = load_follow_config(path, speed, altitude_reference)
        config_path = None  # the YAML copied beside the logs (a config file or shipped config)
        if isinstance(path, (str, os.PathLike)) and not os.fspath(path).lower().endswith(PATH_FILE_SUFFIXES):
            from pf_offboard.shipped import resolve_config

            config_path = str(resolve_config(os.fspath(path), "path"))
        if height_m is None:
            flight = config.flight
            height_m = flight.takeoff_altitude_m if launch == "takeoff" else (flight.throw_activation_height_m if launch == "throw" else None)
            if height_m is None and launch == "throw":
                raise InputError("height_m", "a throw needs an activation height (or flight.throw_activation_height_m)")
        settings = FollowSettings(
            launch=launch, height_m=math.nan if height_m is None else float(height_m), laps=laps, duration_s=duration_s,
            output=output, end_action=end_action, state_source=state_source, set_guid_options=set_guid_options,
            experimental_output=experimental_output, ready_timeout_s=ready_timeout_s, takeoff_timeout_s=takeoff_timeout_s,
            command_timeout_s=command_timeout_s, log_dir=None if log_dir is None else os.fspath(log_dir),
        ).validated()  # fmt: skip
        return await self._run(config, settings, FlightHooks(config_path=config_path))

    async def hand_back(self, action: str = "hold") -> None:
        """Give the vehicle back to the autopilot in ``action`` (hold | land), confirmed by its
        HEARTBEAT. A flight running now ends first (handed back as on Ctrl-C)."""
        from pf_offboard.app.commands import CommandRefusedError, CommandTimeoutError

        if action not in ("hold", "land"):
            raise InputError("action", f"must be hold or land, got {action!r}")
        self._require_open()
        await self._stop_flight("hand_back() requested")
        _, commander, _ = self._idle
        mode = self.profile.land if action == "land" else self.profile.hold
        try:
            await commander.set_mode(mode)
        except (CommandRefusedError, CommandTimeoutError) as exc:
            raise CommandRefused(str(exc)) from None
        except LinkError as exc:
            raise LinkLost(str(exc)) from None

    def request_stop(self, reason: str = "stop requested") -> None:
        """End the flight running now and hand back (as Ctrl-C does); returns at once."""
        if self._flight is not None:
            self._flight.request_stop(reason)

    async def status(self, period_s: float = 0.2) -> AsyncIterator[Progress]:
        """Progress samples every ``period_s`` (wall clock) until the connection closes."""
        while not self._closed:
            yield self.progress()
            await asyncio.sleep(period_s)

    def progress(self) -> Progress:
        """The progress now (see :class:`Progress`)."""
        flight = self._flight
        if flight is None:
            modes = self._idle[0] if self._idle is not None else None
            if modes is None:
                return self._last_progress
            last = self._last_progress
            return Progress("idle", modes.mode_name(), modes.armed, last.eta1_m, last.speed_m_s, last.cross_track_m, last.laps, last.time_s)
        import numpy as np

        est = flight.pipeline.estimator.latest
        step = flight.last_step
        cmd = step.command if step is not None else None
        self._last_progress = Progress(
            phase=flight.phase.value,
            mode=flight.modes.mode_name(),
            armed=flight.modes.armed,
            eta1_m=float(cmd.state.eta1) if cmd is not None else None,
            speed_m_s=float(np.linalg.norm(est.velocity_enu_m_s)) if est is not None else None,
            cross_track_m=float(cmd.cross_track_m) if cmd is not None else None,
            laps=float(flight.laps.laps),
            time_s=float(est.time_s) if est is not None else None,
        )
        return self._last_progress

    # ------------------------------------------------------------------ one flight
    def _require_open(self) -> None:
        if self._closed:
            raise RuntimeError("the vehicle is not connected (use: async with pf_offboard.connect(...) as vehicle)")

    async def _stop_flight(self, reason: str) -> None:
        """End the running flight, if any (hand back, confirmed), and wait for it."""
        task = self._flight_task
        if task is None or task.done():
            return
        self.request_stop(reason)
        while not task.done():
            try:
                await asyncio.shield(task)
            except asyncio.CancelledError:
                if task.done():
                    break
                continue
            except BaseException:  # noqa: BLE001  (its own caller sees it)
                break

    async def _run(self, config: Any, settings: FollowSettings, hooks: FlightHooks) -> FollowResult:
        """Fly one flight (``config`` None: take off only) and map its ending to a result / exception."""
        self._require_open()
        if self._flight_task is not None and not self._flight_task.done():
            raise RuntimeError("a flight is already running on this vehicle: one follow at a time")
        task = asyncio.get_running_loop().create_task(self._fly(config, settings, hooks))
        self._flight_task = task
        try:
            while True:
                try:
                    flight, result, summary, log_dir, config = await asyncio.shield(task)
                    break
                except asyncio.CancelledError:
                    # the caller was cancelled: hand back (confirmed) before giving up
                    if task.done() and not task.cancelled():
                        raise
                    self.request_stop("cancelled")
                    await self._stop_flight("cancelled")
                    raise
        finally:
            if task.done():
                self._flight_task = None
        fr = FollowResult(
            reason=result.reason, exit_code=result.exit_code, laps=result.laps, activation_time_s=result.activation_time_s,
            summary=summary, log_dir=log_dir, breach=result.breach, breach_time_s=result.breach_time_s,
            link_counters=self.link.counters, estimator=flight.pipeline.estimator, config=config, flight=flight,
        )  # fmt: skip
        # ArduPilot holds in GUIDED after a take-off: the next follow on this connection may engage
        # at once (any mode change seen between flights clears it: _dispatch)
        self._offboard_ours = flight.left_in_offboard
        if fr.exit_code == 0:
            return fr
        raise self._error_for(flight, fr)

    @staticmethod
    def _error_for(flight: Any, result: FollowResult) -> FlightError:
        from pf_offboard.app.commands import CommandRefusedError, CommandTimeoutError

        cls = _ERRORS.get(result.exit_code, FlightError)
        if result.exit_code == 3 and isinstance(flight.error, (CommandRefusedError, CommandTimeoutError)):
            cls = CommandRefused
        if result.exit_code == 3 and "take-off" in result.reason and "not held" in result.reason:
            cls = CommandRefused
        return cls(result.reason, result)

    async def _fly(self, config: Any, settings: FollowSettings, hooks: FlightHooks) -> tuple[Any, Any, Any, FilePath | None, Any]:
        from pf_offboard.app.encoders import Encoder
        from pf_offboard.app.estimator import Estimator
        from pf_offboard.app.flight import Flight, FlightOptions
        from pf_offboard.app.running import check_offboard_loss, prepare_output, run_flight, stream_requests
        from pf_offboard.app.settings import envelope_fence, flight_settings_for, rate_bound
        from pf_offboard.app.pipeline import Pipeline
        from pf_offboard.app.rules import EndSpec
        from pf_offboard.logs.summary import SummaryAccumulator

        link, profile, dialect, target = self.link, self.profile, self.dialect, self.target
        custom = hooks.follower_factory is not None
        takeoff_only = config is None and not custom
        if takeoff_only:
            fs = flight_settings_for(None, output="acceleration", end_action="hold")
        elif custom:
            fs = flight_settings_for(hooks.flight_config, output=settings.output, end_action=settings.end_action)
        else:
            fs = flight_settings_for(config, output=settings.output, end_action=settings.end_action)
        quiet = self.settings.quiet if settings.quiet is None else settings.quiet
        fence = hooks.fence
        if config is not None and fence is None and config.path.geodetic is None:
            fence = envelope_fence(config)  # a path outside the fence: refused before any command
        refusal = "" if takeoff_only else dialect.output_refusal(fs.output_mode)  # (a take-off sends no path setpoints)
        if refusal:
            if not settings.experimental_output:
                raise InputError("--output", f"{fs.output_mode} refused on {profile.name}: {refusal}")
            print(f"pf-offboard fly: warning: {fs.output_mode} on {profile.name} is experimental: {refusal}", file=self.stream)
        link.max_state_age_s = fs.state_timeout_s
        log = None
        if settings.log_dir is not None:
            from pf_offboard.logs._io import make_dir
            from pf_offboard.logs.flightlog import FlightLog

            make_dir(settings.log_dir, "--log-dir")  # created (or InputError) before anything is sent
            try:
                log = FlightLog.open(FilePath(settings.log_dir), name=hooks.log_name, config_path=hooks.config_path,
                                     warn=lambda text: print(f"pf-offboard: warning: {text}", file=self.stream, flush=True))  # fmt: skip
            except OSError as exc:
                raise InputError("--log-dir", f"cannot write the logs in {settings.log_dir}: {exc.strerror or exc}") from None
            flight_log = log
            link.on_received = lambda m: flight_log.frame(m.get_msgbuf(), time.time())
            link.on_sent = lambda m: flight_log.frame(m.get_msgbuf(), time.time())
        summary_acc = SummaryAccumulator()  # running sums: the steps themselves go to the CSV only
        try:
            if config is not None and config.path.geodetic is not None:
                # a path in latitude / longitude: into the vehicle's local frame (its EKF origin), refused
                # if out of bounds, before any setpoint or command; the log keeps the local way-points
                from pf_offboard.app.origin import localise_config

                config = await localise_config(link, config, self.stream)
                link.start_reading(self._dispatch)  # (reading the origin used the link's reader)
                if log is not None and hooks.config_path is not None:
                    log.write_config(hooks.config_path, config)
            estimator = Estimator(settings.state_source, fs.velocity_correction_for(profile))
            height_m = settings.height_m
            if config is None:
                follower: Any = hooks.follower_factory(estimator) if hooks.follower_factory is not None else _NoFollower()
                length, closed, lam_max = 1.0, True, 1.0
                monitor = None
            else:
                from pf_offboard.control import controller_from_config
                from pf_offboard.safety import EnvelopeMonitor, SafetyConfig

                follower = controller_from_config(config)
                path = follower.path
                from pf_offboard.logs.measures import path_tangent

                summary_acc.tangent = path_tangent(path)  # the speed along the path from the position
                from pf_offboard.logs.summary import time_laps_of

                time_laps_of(summary_acc, follower)  # closed path: lap times beside the point-mass bound
                length, closed, lam_max = path.length_m, path.closed, path.lam_max
                safety = getattr(config, "safety", None) or SafetyConfig()
                fence = fence if fence is not None else envelope_fence(config)
                monitor = EnvelopeMonitor(safety, fence, path.length_m, path.closed)
                if settings.launch == "takeoff" and safety.enabled:
                    # a take-off below the path's fence floor would arm into a breach: climb into it
                    from pf_offboard.safety import takeoff_height_in_fence

                    height_m, note = takeoff_height_in_fence(fence, settings.height_m)
                    if note:
                        print(f"pf-offboard: {note}", file=self.stream)
            options = FlightOptions(
                launch=settings.launch,
                height_m=height_m,
                end=EndSpec(laps=settings.laps, duration_s=settings.duration_s, open_path_end=settings.open_path_end),
                end_action=fs.end_action,
                setpoint_rate_hz=fs.setpoint_rate_hz,
                state_timeout_s=fs.state_timeout_s,
                status=not quiet,
                ready_timeout_s=settings.ready_timeout_s,
                takeoff_timeout_s=settings.takeoff_timeout_s,
                command_timeout_s=settings.command_timeout_s,
                follow=not takeoff_only,
                offboard_ours=self._offboard_ours,
                measure_hover_thrust=fs.output_mode != "acceleration" and fs.hover_thrust is None and profile.hover_thrust_measured,
            )
            encoder = Encoder(
                fs.output_mode, profile, target.system, target.component,
                hover_thrust=fs.hover_thrust if fs.hover_thrust is not None else 0.5,
                time_constant_s=fs.attitude_time_constant_s,
                max_body_rate_rad_s=None if config is None else rate_bound(config),
            )  # fmt: skip
            pipeline = Pipeline(follower, encoder, estimator)

            def on_step(step: Any) -> None:
                if log is not None:
                    log.step(step.record)
                summary_acc.add(step.record)  # not kept: flights can be long
                if hooks.on_step is not None:
                    hooks.on_step(step, flight)

            flight = Flight(
                link, profile, pipeline, options, length, closed, lam_max, on_step=on_step, status_stream=self.stream,
                monitor=monitor, dialect=dialect, heartbeat=self._last_heartbeat,
            )  # fmt: skip
            self._flight = flight
            if hooks.on_start is not None:
                hooks.on_start(flight)

            async def setup() -> None:
                requests = stream_requests(settings.state_source, fs.setpoint_rate_hz)
                if hooks.wait_for_streams:
                    await flight.commander.request_intervals(requests)
                # each request three times: idempotent, and a lossy link must not leave HEARTBEAT at 1 Hz
                # (the lost-HEARTBEAT watchdog counts on it); twice more, not waited for
                for _ in range(2 if hooks.wait_for_streams else 1):
                    for msg_id, rate, _name in requests:
                        flight.commander.request_interval(msg_id, rate)
                if not takeoff_only:
                    await prepare_output(flight, dialect, fs, settings.set_guid_options, self.stream, warnings=hooks.output_warnings)
                    await check_offboard_loss(flight, dialect, fs.output_mode, settings.offboard_loss, self.stream)

            try:
                result = await run_flight(flight, setup)
            finally:
                self._flight = None
                if hooks.on_end is not None:
                    hooks.on_end(flight)
        finally:
            link.on_received = None
            link.on_sent = None
            if log is not None:
                log.close()
        summary = summary_acc.result() if summary_acc.steps else None
        return flight, result, summary, (log.paths.tlog.parent if log is not None else None), config


def connect(
    endpoint: str,
    *,
    autopilot: str = "auto",
    target_system: int | None = None,
    heartbeat_timeout_s: float = 30.0,
    signing_key: bytes | None = None,
    quiet: bool = False,
    status_stream: TextIO | None = None,
) -> Vehicle:
    """A connection to the autopilot at ``endpoint`` (``async with`` it).

    ``endpoint`` as MAVSDK (``udp://:14540``, ``udpin://``, ``udpout://``, ``tcp://``,
    ``serial:///dev/ttyACM0:921600``) or pymavlink / MAVProxy (``udp:``, ``udpin:``, ``udpout:``,
    ``tcp:``, ``tcpin:``, ``/dev/ttyACM0,921600``) write it; see docs/api.md. Entering waits up to
    ``heartbeat_timeout_s`` for the autopilot's HEARTBEAT (:class:`pf_offboard.LinkLost` if none);
    ``autopilot``: auto (from the HEARTBEAT) | px4 | ardupilot. Messages go to ``status_stream``
    (default stderr); ``quiet``: only those the user must see.
    """
    return Vehicle(ConnectSettings(endpoint, autopilot, target_system, heartbeat_timeout_s, signing_key, quiet), status_stream)
