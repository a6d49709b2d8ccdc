"""Several clients at once: UDP answers every sender, TCP serves each connection."""

from __future__ import annotations

import asyncio
import socket

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.config import MockConfig
from sitl_mock.server import MockAutopilot, new_mavlink, parse_datagram
from sitl_mock.testing import UdpClient, free_udp_port

pytestmark = pytest.mark.integration


def test_udp_default_remote_and_extra_senders_and_tcp_clients() -> None:
    async def scenario() -> None:
        listen_port = free_udp_port()
        listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        listener.bind(("127.0.0.1", listen_port))  # like MAVSDK's udp://:14540
        listener.settimeout(5.0)
        config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=("127.0.0.1", listen_port), tcp_port=0, speed=5.0)
        loop = asyncio.get_running_loop()
        async with MockAutopilot(config) as mock:

            def clients() -> None:
                # 1) the default remote hears the mock without sending anything
                mav = new_mavlink()
                seen: set[str] = set()
                for _ in range(500):
                    seen |= {m.get_type() for m in parse_datagram(mav, listener.recv(65536))}
                    if {"HEARTBEAT", "ATTITUDE"} <= seen:
                        break
                assert {"HEARTBEAT", "ATTITUDE"} <= seen
                # 2) another UDP client is answered once it sends
                with UdpClient(mock.ports.udp) as other:
                    other.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
                    assert other.wait("ATTITUDE").get_type() == "ATTITUDE"
                # 3) two TCP clients at once
                socks = [socket.create_connection(("127.0.0.1", mock.ports.tcp), timeout=5.0) for _ in range(2)]
                try:
                    for s in socks:
                        parser = new_mavlink()
                        seen = set()
                        while "HEARTBEAT" not in seen:
                            seen |= {m.get_type() for m in parser.parse_buffer(s.recv(65536)) or []}
                finally:
                    for s in socks:
                        s.close()

            await loop.run_in_executor(None, clients)
        listener.close()

    asyncio.run(scenario())


def _garbage(rng) -> list[bytes]:
    """Random bytes, truncated frames, a valid frame with a broken CRC, a MAVLink 1 frame and a
    frame for an unknown message id."""
    frame = mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(new_mavlink())
    bad_crc = frame[:-2] + bytes([frame[-2] ^ 0xFF, frame[-1]])
    unknown = bytes([0xFD, 3, 0, 0, 0, 255, 190, 0x39, 0x30, 0x00]) + b"abc" + b"\x00\x00"
    out = [bytes(rng.integers(0, 256, int(n), dtype=np.uint8)) for n in rng.integers(1, 300, 30)]
    out += [frame[:k] for k in range(1, len(frame))] + [bad_crc, b"\xfe\x00" * 40, unknown, b"\xfd" * 300]
    return out


def test_garbage_traffic_is_dropped_and_the_link_keeps_working() -> None:
    """Malformed bytes over UDP and TCP never crash the mock or reach the vehicle: afterwards it
    still answers a parameter request, is still disarmed and its state is finite."""
    rng = np.random.default_rng(3)

    async def scenario() -> None:
        config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=None, tcp_port=0, speed=5.0)
        loop = asyncio.get_running_loop()
        async with MockAutopilot(config) as mock:

            def clients() -> None:
                request = mavlink.MAVLink_param_request_read_message(1, 1, b"MPC_THR_HOVER", -1)
                with UdpClient(mock.ports.udp) as c:
                    for chunk in _garbage(rng):
                        c.sock.send(chunk)
                    c.send(request)
                    assert c.wait("PARAM_VALUE").param_id == "MPC_THR_HOVER"
                with socket.create_connection(("127.0.0.1", mock.ports.tcp), timeout=5.0) as s:
                    s.sendall(b"".join(_garbage(rng)))
                    # In a byte stream a bogus header (e.g. 0xFD, length 253) swallows the bytes
                    # that follow, as in every MAVLink parser: repeat the request until answered.
                    parser = new_mavlink()
                    answered = False
                    for _ in range(30):
                        s.sendall(request.pack(new_mavlink()))
                        for _ in range(20):
                            msgs = parser.parse_buffer(s.recv(65536)) or []
                            if any(m.get_type() == "PARAM_VALUE" for m in msgs):
                                answered = True
                                break
                        if answered:
                            break
                    assert answered

            assert await mock.wait_for(lambda m: m.time_s > 1.0, timeout_s=10.0)  # armable from here on
            await loop.run_in_executor(None, clients)
            assert not mock.autopilot.armed  # the broken-CRC ARM command was not taken
            assert np.all(np.isfinite(mock.truth.position_ned_m)) and np.all(np.isfinite(mock.truth.q_ned_frd))

    asyncio.run(scenario())
