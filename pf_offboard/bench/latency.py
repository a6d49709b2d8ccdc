"""State-in → setpoint-out latency of the app over loopback MAVLink (``pf-offboard bench --only latency``).

A vehicle process (forked, so it has its own interpreter lock) sends a PX4 HEARTBEAT and then
ATTITUDE_QUATERNION + LOCAL_POSITION_NED at 250 Hz along the paper path, slightly off it; the
app side is the real thing — :class:`~pf_offboard.app.link.Link` (pymavlink, event-loop reader),
:class:`~pf_offboard.app.flight.Flight` in its following phase, the :class:`Pipeline` with the
paper's :class:`PathFollower` — and answers each state sample with a setpoint. The vehicle stamps
each LOCAL_POSITION_NED just before ``sendto`` and each setpoint right after ``recv`` and matches
them by ``time_boot_ms``: the figure includes both loopback socket traversals, decoding, the
controller, encoding and the app's bookkeeping (the telemetry log is not written).
"""

from __future__ import annotations

import asyncio
import gc
import io
import math
import multiprocessing
import socket
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

RATE_HZ = 250.0


def _vehicle(conn: Connection, samples: int, warmup: int) -> None:
    """The vehicle side (runs in a forked process)."""
    from pymavlink.dialects.v20 import common as mavlink2

    from pf_offboard import frames
    from pf_offboard.app.demo import paper_config
    from pf_offboard.config import load_config
    from pf_offboard.control import PathFollower

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    conn.send(sock.getsockname()[1])
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.robust_parsing = True
    path = PathFollower.from_config(load_config(paper_config())).path
    sock.settimeout(10.0)
    try:
        _, app_addr = sock.recvfrom(65536)  # the app's first HEARTBEAT tells us where it is
    except TimeoutError:
        conn.send(None)
        return

    def send(msg: Any) -> None:
        sock.sendto(msg.pack(mav), app_addr)
        mav.seq = (mav.seq + 1) & 0xFF

    send(mavlink2.MAVLink_heartbeat_message(2, 12, 0x11, 0, 3, 3))  # quadrotor, PX4, standby
    sent_at: dict[int, float] = {}
    latencies: list[float] = []
    period = 1.0 / RATE_HZ
    start = time.perf_counter()
    total = samples + warmup
    for k in range(total):
        t_ms = 1000 + 4 * k
        lam = (k * 0.006) % path.lam_max
        p_enu = np.asarray(path.eval(lam).sigma) + np.array([0.01, -0.02, 0.015])
        p_ned = frames.enu_to_ned(p_enu)
        v_ned = frames.enu_to_ned(np.asarray(path.eval(lam).d1) * 0.5)
        send(mavlink2.MAVLink_attitude_quaternion_message(t_ms, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, [0.0] * 4))
        sent_at[t_ms] = time.perf_counter()
        send(mavlink2.MAVLink_local_position_ned_message(t_ms, *map(float, p_ned), *map(float, v_ned)))
        deadline = start + (k + 1) * period
        while True:  # receive (blocking, so the stamp is taken on arrival) until the next sample is due
            remaining = deadline - time.perf_counter()
            if remaining <= 0.0:
                break
            sock.settimeout(remaining)
            try:
                data = sock.recv(65536)
            except TimeoutError:
                break
            now = time.perf_counter()
            for msg in mav.parse_buffer(data) or []:
                if msg.get_type() in ("SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET"):
                    t0 = sent_at.pop(msg.time_boot_ms, None)
                    if t0 is not None and msg.time_boot_ms >= 1000 + 4 * warmup:
                        latencies.append(now - t0)
    conn.send((latencies, total - warmup))


async def _app(port: int, samples: int, in_app: list[float]) -> None:
    from pf_offboard.app.flight import Flight, FlightOptions
    from pf_offboard.app.phases import Phase
    from pf_offboard.app.rules import EndSpec
    from pf_offboard.app.demo import paper_config
    from pf_offboard.config import load_config
    from pf_offboard.app.encoders import Encoder
    from pf_offboard.app.link import Link, parse_endpoint
    from pf_offboard.app.pipeline import Pipeline
    from pf_offboard.app.profiles import PX4
    from pf_offboard.control import PathFollower

    follower = PathFollower.from_config(load_config(paper_config()))  # before connecting: no backlog
    link = Link.open(parse_endpoint(f"udpout:127.0.0.1:{port}"))
    try:
        target = await link.wait_heartbeat(10.0)
        pipeline = Pipeline(follower, Encoder("acceleration", PX4, target.system, target.component))
        options = FlightOptions("airborne", math.nan, EndSpec(), setpoint_rate_hz=RATE_HZ, status=False)
        path = follower.path
        bridge = Flight(link, PX4, pipeline, options, path.length_m, path.closed, path.lam_max, status_stream=io.StringIO())
        bridge.phase = Phase.FOLLOWING
        gc.freeze()  # as fly does before its loop
        done = asyncio.Event()

        def on_message(msg: Any) -> None:
            if msg.get_type() == "LOCAL_POSITION_NED":
                t0 = time.perf_counter()
                bridge.on_message(msg)  # estimator, core, encoder, send
                in_app.append(time.perf_counter() - t0)
            else:
                bridge.on_message(msg)
            if bridge.steps >= samples:
                done.set()

        link.start_reading(on_message)
        try:
            await asyncio.wait_for(done.wait(), timeout=samples / RATE_HZ + 2.0)
        except TimeoutError:
            pass
    finally:
        link.close()


def run(quick: bool = False) -> dict[str, Any]:
    """Median / p99 / max latency (ms) of state-in → setpoint-out at 250 Hz over loopback."""
    samples = 500 if quick else 5000
    warmup = 25  # the first projection is a global search
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_vehicle, args=(child, samples, warmup), daemon=True)
    proc.start()
    try:
        port = parent.recv()
        in_app: list[float] = []
        asyncio.run(_app(port, samples + warmup, in_app))
        if not parent.poll(30.0):
            raise RuntimeError("latency bench: vehicle process did not report")
        result = parent.recv()
    finally:
        proc.join(5.0)
        if proc.is_alive():
            proc.terminate()
    if result is None:
        raise RuntimeError("latency bench: the app never connected")
    latencies, expected = result
    ms = np.asarray(latencies) * 1e3
    inside = np.asarray(in_app[warmup:]) * 1e3
    return {
        "rate_hz": RATE_HZ,
        "samples": int(ms.size),
        "answered_fraction": ms.size / expected if expected else 0.0,
        "latency_median_ms": float(np.median(ms)) if ms.size else math.nan,
        "latency_p99_ms": float(np.percentile(ms, 99)) if ms.size else math.nan,
        "latency_max_ms": float(ms.max()) if ms.size else math.nan,
        # the app's own share: state message handled → setpoint handed to the socket
        "in_app_median_ms": float(np.median(inside)) if inside.size else math.nan,
        "in_app_p99_ms": float(np.percentile(inside, 99)) if inside.size else math.nan,
    }
