"""The link over real loopback UDP: HEARTBEAT wait, target selection, other systems ignored."""

from __future__ import annotations

import asyncio
import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.testing import free_udp_port

from pf_offboard.app.link import Link, parse_endpoint
from pf_offboard.errors import LinkError

pytestmark = pytest.mark.integration


def _sender(system: int) -> tuple[socket.socket, mavlink2.MAVLink]:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    return s, mavlink2.MAVLink(None, srcSystem=system, srcComponent=1)


def test_target_is_chosen_and_other_systems_are_ignored() -> None:
    port = free_udp_port()

    async def main() -> tuple[int, list[tuple[int, str]]]:
        link = Link.open(parse_endpoint(f"udpin:127.0.0.1:{port}"))
        a, mav_a = _sender(1)
        b, mav_b = _sender(2)
        try:
            hb = mavlink2.MAVLink_heartbeat_message(2, 12, 0x91, 393216, 4, 3)
            gcs = mavlink2.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)  # a ground station: never a target
            for sock, mav, msg in ((a, mav_a, gcs), (a, mav_a, hb), (b, mav_b, hb)):
                sock.sendto(msg.pack(mav), ("127.0.0.1", port))
            target = await link.wait_heartbeat(2.0, target_system=2)
            got: list[tuple[int, str]] = []
            done = asyncio.Event()

            def handler(msg) -> None:
                got.append((msg.get_srcSystem(), msg.get_type()))
                if msg.get_type() == "SYS_STATUS":
                    done.set()

            link.start_reading(handler)
            lpn = mavlink2.MAVLink_local_position_ned_message(10, 1, 2, 3, 0, 0, 0)
            a.sendto(lpn.pack(mav_a), ("127.0.0.1", port))
            b.sendto(lpn.pack(mav_b), ("127.0.0.1", port))
            b.sendto(b"\xfd\x09garbage-not-mavlink", ("127.0.0.1", port))  # malformed traffic
            end = mavlink2.MAVLink_sys_status_message(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)
            for _ in range(3):  # the parser may swallow one frame while it resynchronises
                b.sendto(end.pack(mav_b), ("127.0.0.1", port))
            await asyncio.wait_for(done.wait(), 2.0)
            return target.system, got
        finally:
            link.close()
            a.close()
            b.close()

    system, got = asyncio.run(main())
    assert system == 2
    assert (2, "LOCAL_POSITION_NED") in got
    assert all(src == 2 for src, _ in got), got


def test_heartbeat_timeout_is_a_link_error_not_a_hang() -> None:
    port = free_udp_port()

    async def main() -> None:
        link = Link.open(parse_endpoint(f"udpin:127.0.0.1:{port}"))
        try:
            await link.wait_heartbeat(0.3)
        finally:
            link.close()

    with pytest.raises(LinkError, match="no HEARTBEAT"):
        asyncio.run(main())


def test_unreachable_tcp_endpoint_is_a_link_error() -> None:
    port = free_udp_port()  # nothing listens on TCP there (almost surely)
    with pytest.raises(LinkError, match="cannot open"):
        Link.open(parse_endpoint(f"tcp:127.0.0.1:{port}"))
