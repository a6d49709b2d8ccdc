"""Several clients at once: UDP answers every sender, TCP serves each connection."""

from __future__ import annotations

import asyncio
import socket

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
        config = MockConfig(udp_local_port=0, udp_remote=("127.0.0.1", listen_port), tcp_port=0, speed=5.0)
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
