"""Running one flight: the telemetry it asks for, the output mode's parameters (through the
dialect), and the TaskGroup that supervises the flight and its periodic tasks."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any, TextIO

from pf_offboard.app.settings import FlightSettings
from pf_offboard.errors import InputError, LinkError


def stream_requests(state_source: str, setpoint_rate_hz: float) -> list[tuple[int, float, str]]:
    """The telemetry a flight needs, as (message id, rate Hz, name): the state at the setpoint rate
    (a fresh sample drives each setpoint), HEARTBEAT at 10 Hz so a takeover is seen within 0.1 s
    where honoured, and the autopilot's echoed target at 25 Hz (another controller's setpoints
    show in it: :mod:`pf_offboard.app.controllers`; PX4 streams it anyway, ArduPilot on request)."""
    from pymavlink.dialects.v20 import common as mavlink2

    if state_source == "local_position":
        state = (mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED, setpoint_rate_hz, "LOCAL_POSITION_NED")
    else:
        state = (mavlink2.MAVLINK_MSG_ID_ODOMETRY, setpoint_rate_hz, "ODOMETRY")
    return [
        state,
        (mavlink2.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, setpoint_rate_hz, "ATTITUDE_QUATERNION"),
        (mavlink2.MAVLINK_MSG_ID_HEARTBEAT, 10.0, "HEARTBEAT"),
        (mavlink2.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED, 25.0, "POSITION_TARGET_LOCAL_NED"),
    ]


async def run_flight(flight: Any, setup: Callable[[], Awaitable[None]] | None = None) -> Any:
    """One TaskGroup: the flight, the keep-alive / watchdogs, our HEARTBEAT and the status line.
    Bad input (InputError -> exit 2, e.g. GUID_OPTIONS refused in setup) and link failures
    (LinkError -> exit 3) raised in a task come out as themselves, not as an exception group."""
    try:
        async with asyncio.TaskGroup() as tg:
            task = tg.create_task(flight.fly(setup))
            helpers = [tg.create_task(flight.keepalive()), tg.create_task(flight.heartbeat()), tg.create_task(flight.status_line())]
            result = await task
            for helper in helpers:  # they poll the phase once a period (HEARTBEAT: 1 s): end them now
                helper.cancel()
    except BaseExceptionGroup as group:
        first = _first_leaf(group)
        if isinstance(first, (InputError, LinkError)):
            raise first from None
        raise
    return result


async def prepare_output(flight: Any, dialect: Any, settings: FlightSettings, allow_set_guid_options: bool, stream: TextIO,
                         warnings: bool = True) -> None:  # fmt: skip
    """The dialect reads what the output mode needs (hover thrust, tilt mapping, tilt limit,
    GUID_OPTIONS) and sets it on the encoder (the tilt limit on the follower: law and speed profile); ``warnings``: also what it warns about (ArduPilot's jerk limits)."""
    pipeline = flight.pipeline
    pipeline.encoder = await dialect.read_setpoint_mapping(
        flight.params, settings.output_mode, settings.hover_thrust, pipeline.encoder, lambda line: print(line, file=stream)
    )
    follower = pipeline.follower
    cap = getattr(follower, "cap_tilt", None)
    if cap is not None:  # the autopilot's tilt limit, read before activation (acceleration output)
        cap(await dialect.read_tilt_limit(
            flight.params, settings.output_mode, follower.limits.max_tilt_deg, lambda line: print(line, file=stream)
        ))  # fmt: skip
    await dialect.ensure_output_requirements(flight.params, settings.output_mode, allow_set_guid_options)
    if warnings:
        for line in await dialect.output_warnings(flight.params, settings.output_mode):
            print(f"pf-offboard fly: warning: {line}", file=stream)


async def check_offboard_loss(flight: Any, dialect: Any, output_mode: str, wanted: str | None, stream: TextIO) -> None:
    """What the vehicle does if the app dies, read (and with ``wanted`` set) before any mode request:
    one line saying it; refused (exit 2) when the motors would stop; a warning when nothing would
    hold the vehicle's position (PX4's Return climbs to RTL_RETURN_ALT; ArduPilot attitude / rates
    drift)."""
    try:
        loss = await dialect.offboard_loss(flight.params, output_mode, wanted)
    except LinkError as exc:
        if wanted is not None:
            raise
        print(f"pf-offboard fly: warning: cannot read what the vehicle does if the app stops ({exc}); see docs/safety.md", file=stream)
        return
    if loss.falls:
        raise InputError("--offboard-loss", f"if the app stopped, {loss.text}; set it to hold or land (--offboard-loss hold)")
    if loss.drifts:
        hint = " (--offboard-loss hold sets a hold)" if wanted is None and dialect.name == "px4" else ""
        print(f"pf-offboard fly: warning: if the app stops, {loss.text}{hint}", file=stream)
    else:
        print(f"pf-offboard fly: if the app stops, {loss.text}", file=stream)


def _first_leaf(group: BaseExceptionGroup) -> BaseException:  # type: ignore[type-arg]
    first: BaseException = group
    while isinstance(first, BaseExceptionGroup):
        first = first.exceptions[0]
    return first
