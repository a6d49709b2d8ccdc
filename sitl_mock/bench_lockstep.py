"""Lockstep speed over loopback MAVLink with a minimal pymavlink client in the loop.

The mock runs in a subprocess (``python -m sitl_mock --lockstep``) so mock and client use both
cores; a second figure runs mock and client in one asyncio loop (one process, no cross-process
scheduling, which wins on a busy machine). The client turns off the default streams it does not need, asks for LOCAL_POSITION_NED
at every lockstep step, and answers each LOCAL_POSITION_NED with one acceleration setpoint:
each round trip advances simulated time by ``lockstep_dt_s``. Figures are printed by
``sitl-mock --bench`` / ``pf-offboard bench --only mavlink``; tests never assert on them.
"""

from __future__ import annotations

import asyncio
import socket
import statistics
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.config import MockConfig, SpawnSpec
from sitl_mock.profiles import PROFILES
from sitl_mock.runner import spawn
from sitl_mock.server import MockAutopilot, parse_datagram

LOCKSTEP_DT_S = 0.004


def _client() -> mavlink.MAVLink:
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    mav.robust_parsing = True
    return mav


def _send(sock: socket.socket, mav: mavlink.MAVLink, msg: mavlink.MAVLink_message) -> None:
    sock.send(msg.pack(mav))
    mav.seq = (mav.seq + 1) & 0xFF


def _round_trips(sock: socket.socket, mav: mavlink.MAVLink, steps: int, keep_streams: bool) -> dict[str, Any]:
    lpn = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
    if not keep_streams:
        for msgid, _ in PROFILES["px4"].streams:
            if msgid not in (lpn, mavlink.MAVLINK_MSG_ID_HEARTBEAT):
                _send(sock, mav, mavlink.MAVLink_command_long_message(
                    1, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msgid, -1, 0, 0, 0, 0, 0))
    _send(sock, mav, mavlink.MAVLink_command_long_message(
        1, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, lpn, int(LOCKSTEP_DT_S * 1e6), 0, 0, 0, 0, 0))
    setpoint = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0x0C3F, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0, 0)
    received = 0
    last_time_ms = -1
    t_start = time.perf_counter()
    _send(sock, mav, setpoint)
    trips: list[float] = []
    t_trip = time.perf_counter()
    while received < steps:
        data = sock.recv(65536)
        msgs = parse_datagram(mav, data)
        for msg in msgs:
            if msg.get_msgId() == lpn and msg.time_boot_ms != last_time_ms:
                last_time_ms = msg.time_boot_ms
                received += 1
                now = time.perf_counter()
                trips.append(now - t_trip)
                t_trip = now
                _send(sock, mav, setpoint)
    wall = time.perf_counter() - t_start
    sim = received * LOCKSTEP_DT_S
    median = statistics.median(trips[10:]) if len(trips) > 20 else float("nan")
    return {"speed_x": sim / wall, "wall_s": wall, "sim_s": sim, "round_trip_us_median": median * 1e6}


class _LoopClient(asyncio.DatagramProtocol):
    """The same minimal client as an asyncio protocol sharing the mock's event loop."""

    def __init__(self, steps: int, done: asyncio.Future[float]) -> None:
        self.mav = _client()
        self.steps = steps
        self.done = done
        self.received = 0
        self.t_start = 0.0
        self.transport: asyncio.DatagramTransport | None = None
        self.setpoint = mavlink.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0x0C3F, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0, 0)

    def connection_made(self, transport) -> None:  # type: ignore[override]
        self.transport = transport

    def send(self, msg: mavlink.MAVLink_message) -> None:
        assert self.transport is not None
        self.transport.sendto(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) & 0xFF

    def datagram_received(self, data: bytes, addr: Any) -> None:
        lpn = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
        if any(m.get_msgId() == lpn for m in parse_datagram(self.mav, data)):
            self.received += 1
            if self.received >= self.steps:
                if not self.done.done():
                    self.done.set_result(time.perf_counter() - self.t_start)
                return
            self.send(self.setpoint)


async def _in_one_loop(steps: int) -> float:
    config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=None, lockstep=True, lockstep_dt_s=LOCKSTEP_DT_S,
                        spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)))
    loop = asyncio.get_running_loop()
    async with MockAutopilot(config) as mock:
        done: asyncio.Future[float] = loop.create_future()
        transport, client = await loop.create_datagram_endpoint(
            lambda: _LoopClient(steps, done), remote_addr=("127.0.0.1", mock.ports.udp))
        try:
            client.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
            for msgid, _ in PROFILES["px4"].streams:
                interval = LOCKSTEP_DT_S * 1e6 if msgid == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED else -1
                if msgid != mavlink.MAVLINK_MSG_ID_HEARTBEAT:
                    client.send(mavlink.MAVLink_command_long_message(
                        1, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msgid, interval, 0, 0, 0, 0, 0))
            client.t_start = time.perf_counter()
            client.send(client.setpoint)
            wall = await asyncio.wait_for(done, 120)
        finally:
            transport.close()
    return steps * LOCKSTEP_DT_S / wall


def _subprocess_run(steps: int, keep_streams: bool) -> dict[str, Any]:
    config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=None, lockstep=True, lockstep_dt_s=LOCKSTEP_DT_S,
                        spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)))
    with spawn(config) as handle:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.connect(("127.0.0.1", handle.ports.udp))
        sock.settimeout(5.0)
        try:
            mav = _client()
            _send(sock, mav, mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
            return _round_trips(sock, mav, steps, keep_streams)
        finally:
            sock.close()


def run_lockstep(quick: bool = False) -> dict[str, Any]:
    """Lockstep simulation speed (× real time) with a client in the loop.

    Each configuration runs ``repeats`` times; the median and the best run are reported (the
    spread comes from other load on the machine: each round trip needs two processes scheduled).
    """
    steps = 1500 if quick else 5000
    repeats = 1 if quick else 3
    results: dict[str, Any] = {}
    for label, keep in (("minimal_streams", False), ("default_streams", True)):
        runs = [_subprocess_run(steps if not keep else steps // 2, keep) for _ in range(repeats)]
        speeds = [r["speed_x"] for r in runs]
        results[f"lockstep_speed_x_{label}_median"] = statistics.median(speeds)
        results[f"lockstep_speed_x_{label}_best"] = max(speeds)
        trip = statistics.median(r["round_trip_us_median"] for r in runs)
        results[f"lockstep_round_trip_us_median_{label}"] = trip
        # What the median round trip alone would give (the means above include scheduler stalls).
        results[f"lockstep_speed_x_at_median_trip_{label}"] = LOCKSTEP_DT_S / (trip * 1e-6)
    one = [asyncio.run(_in_one_loop(steps)) for _ in range(repeats)]
    results["lockstep_speed_x_one_process_minimal_streams_median"] = statistics.median(one)
    results["lockstep_dt_s"] = LOCKSTEP_DT_S
    results["target_speed_x"] = 20.0
    return results
