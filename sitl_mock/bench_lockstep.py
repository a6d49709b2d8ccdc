"""Lockstep speed over loopback MAVLink with a minimal pymavlink client in the loop.

The mock runs in a subprocess (``python -m sitl_mock --lockstep``) so mock and client use both
cores. The client turns off the default streams it does not need, asks for LOCAL_POSITION_NED
at every lockstep step, and answers each LOCAL_POSITION_NED with one acceleration setpoint:
each round trip advances simulated time by ``lockstep_dt_s``. Figures are printed by
``sitl-mock --bench`` / ``pf-offboard bench --only mavlink``; tests never assert on them.
"""

from __future__ import annotations

import socket
import statistics
import time
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.config import MockConfig, SpawnSpec
from sitl_mock.profiles import PROFILES
from sitl_mock.runner import spawn
from sitl_mock.server import parse_datagram

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


def run_lockstep(quick: bool = False) -> dict[str, Any]:
    """Lockstep simulation speed (× real time) with a client in the loop, mock in a subprocess."""
    steps = 1500 if quick else 7500
    results: dict[str, Any] = {}
    for label, keep in (("minimal_streams", False), ("default_streams", True)):
        config = MockConfig(udp_local_port=0, udp_remote=None, lockstep=True, lockstep_dt_s=LOCKSTEP_DT_S,
                            spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)))
        with spawn(config) as handle:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.connect(("127.0.0.1", handle.ports.udp))
            sock.settimeout(5.0)
            try:
                mav = _client()
                _send(sock, mav, mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
                figures = _round_trips(sock, mav, steps if not keep else steps // 3, keep)
            finally:
                sock.close()
        results[f"lockstep_speed_x_{label}"] = figures["speed_x"]
        results[f"lockstep_round_trip_us_median_{label}"] = figures["round_trip_us_median"]
        # What the median round trip alone would give (the mean above includes scheduler stalls).
        results[f"lockstep_speed_x_at_median_{label}"] = LOCKSTEP_DT_S / (figures["round_trip_us_median"] * 1e-6)
    results["lockstep_dt_s"] = LOCKSTEP_DT_S
    results["target_speed_x"] = 20.0
    return results
