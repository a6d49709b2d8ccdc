"""Link authority over real loopback UDP (issue 9, item 3): what the link believes and answers.

A fake autopilot (a plain UDP socket packing real pymavlink frames as sysid 1 / compid 1) talks to
an app-side :class:`Link`; a second socket on another port sends the same ids (a spoofer).
"""

from __future__ import annotations

import asyncio
import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.testing import free_udp_port

from pf_offboard.app.link import MAX_MESSAGES_PER_WAKEUP, Link, parse_endpoint

pytestmark = pytest.mark.integration

AUTOPILOT_HB = mavlink2.MAVLink_heartbeat_message(2, 12, 0x91, 393216, 4, 3)  # quadrotor, PX4, OFFBOARD
GCS_HB_POSCTL = mavlink2.MAVLink_heartbeat_message(6, 8, 0x91, 3 << 16, 4, 3)  # GCS type, "POSCTL"


def _udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setblocking(False)
    return s


def _mav(system: int = 1, component: int = 1) -> mavlink2.MAVLink:
    return mavlink2.MAVLink(None, srcSystem=system, srcComponent=component)


class _Handled(list):
    """The messages the link handed on (its reader's handler, called on the event loop), with a
    wait for one of a type instead of polling on the wall clock."""

    def __init__(self) -> None:
        super().__init__()
        self._new = asyncio.Event()

    def append(self, msg) -> None:  # type: ignore[no-untyped-def, override]
        super().append(msg)
        self._new.set()

    async def settle(self, link: Link, until: str, timeout_s: float = 10.0) -> None:
        """Until a message of type ``until`` from the target has been handled (it was sent last:
        everything before it has been read too), or fail after ``timeout_s``."""

        async def seen() -> None:
            while not any(m.get_type() == until for m in self):
                self._new.clear()
                await self._new.wait()

        try:
            await asyncio.wait_for(seen(), timeout_s)
        except TimeoutError:
            raise AssertionError(f"no {until} handled within {timeout_s} s; counters {link.counters}") from None


def test_only_the_target_component_at_the_locked_address_is_believed() -> None:
    port = free_udp_port()

    async def main() -> tuple[list, object, list[bytes]]:
        link = Link.open(parse_endpoint(f"udpin:127.0.0.1:{port}"))
        autopilot, spoofer = _udp(), _udp()
        ap_mav, spoof_mav, camera_mav = _mav(), _mav(), _mav(1, 100)
        dest = ("127.0.0.1", port)
        try:
            autopilot.sendto(AUTOPILOT_HB.pack(ap_mav), dest)
            await link.wait_heartbeat(2.0)
            got = _Handled()
            link.start_reading(got.append)
            # the spoofer, from another port, with the autopilot's ids: a GCS HEARTBEAT claiming
            # POSCTL (a fake takeover) and a position 50 m away
            spoof_lpn = mavlink2.MAVLink_local_position_ned_message(20, 50.0, 0.0, -2.0, 0, 0, 0)
            for msg in (GCS_HB_POSCTL, AUTOPILOT_HB, spoof_lpn):
                spoofer.sendto(msg.pack(spoof_mav), dest)
            # from the autopilot's own address: a GCS-type HEARTBEAT with its ids (not an autopilot's),
            # another component of the same system, then genuine telemetry
            autopilot.sendto(GCS_HB_POSCTL.pack(ap_mav), dest)
            autopilot.sendto(mavlink2.MAVLink_local_position_ned_message(21, 9.0, 9.0, -9.0, 0, 0, 0).pack(camera_mav), dest)
            autopilot.sendto(mavlink2.MAVLink_local_position_ned_message(22, 1.0, 0.0, -2.0, 0, 0, 0).pack(ap_mav), dest)
            autopilot.sendto(mavlink2.MAVLink_sys_status_message(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0).pack(ap_mav), dest)
            await got.settle(link, "SYS_STATUS")
            # udpin answers only the locked peer: the spoofer, who sent datagrams too, gets nothing.
            # sendto on loopback delivers before it returns: once send_heartbeat() is back, anything
            # it sent is already in the receivers' buffers (no waiting needed to see a leak)
            link.send_heartbeat()
            leaked = []
            while True:
                try:
                    leaked.append(spoofer.recv(65535))
                except BlockingIOError:
                    break
            to_autopilot = autopilot.recv(65535)
            assert to_autopilot  # our HEARTBEAT reached the autopilot
            return got, link.counters, leaked
        finally:
            link.close()
            autopilot.close()
            spoofer.close()

    got, counters, leaked = asyncio.run(main())
    types = [(m.get_type(), getattr(m, "x", None)) for m in got]
    assert types == [("LOCAL_POSITION_NED", 1.0), ("SYS_STATUS", None)]
    assert counters.foreign_peer == 3 and counters.not_autopilot_heartbeat == 1 and counters.not_target == 1
    assert leaked == []


def test_reader_yields_after_its_budget_so_timers_run_during_a_flood() -> None:
    """A burst far larger than one wake-up's budget is read in slices: a timer task scheduled
    meanwhile runs between slices (the old reader drained everything first)."""
    port = free_udp_port()
    burst = 20 * MAX_MESSAGES_PER_WAKEUP

    async def main() -> tuple[int, int, object]:
        link = Link.open(parse_endpoint(f"udpin:127.0.0.1:{port}"))
        link._udp_sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        autopilot, flooder = _udp(), _udp()
        dest = ("127.0.0.1", port)
        try:
            autopilot.sendto(AUTOPILOT_HB.pack(_mav()), dest)
            await link.wait_heartbeat(2.0)
            handled = 0
            seen_by_timer: list[int] = []

            def handler(msg) -> None:
                nonlocal handled
                handled += 1

            frame = mavlink2.MAVLink_local_position_ned_message(5, 1, 2, 3, 0, 0, 0).pack(_mav())
            flood_frame = GCS_HB_POSCTL.pack(_mav())
            for i in range(burst):  # queued before the reader starts: one big backlog
                autopilot.sendto(frame, dest)
                flooder.sendto(flood_frame, dest)
            link.start_reading(handler)

            async def timer() -> None:
                while True:
                    seen_by_timer.append(handled)
                    await asyncio.sleep(0)

            task = asyncio.create_task(timer())
            deadline = asyncio.get_running_loop().time() + 10.0
            while handled < burst and asyncio.get_running_loop().time() < deadline:
                await asyncio.sleep(0)
            task.cancel()
            # the timer ran while the backlog was being read, not only before and after it
            during = [n for n in seen_by_timer if 0 < n < burst]
            return handled, len(during), link.counters
        finally:
            link.close()
            autopilot.close()
            flooder.close()

    handled, during, counters = asyncio.run(main())
    assert handled == burst
    assert during >= 10, during
    assert counters.reader_yields >= 20 and counters.foreign_peer == burst


def test_state_that_waited_longer_than_the_state_timeout_is_dropped_unread() -> None:
    """Kernel receive timestamps say how long a datagram waited in the socket; state older than
    ``max_state_age_s`` is never handed on (a backlog is never flown). Non-state messages are."""
    port = free_udp_port()

    async def run(max_age_s: float | None) -> tuple[list[str], object]:
        link = Link.open(parse_endpoint(f"udpin:127.0.0.1:{port}"))
        autopilot = _udp()
        mav = _mav()
        dest = ("127.0.0.1", port)
        try:
            autopilot.sendto(AUTOPILOT_HB.pack(mav), dest)
            await link.wait_heartbeat(2.0)
            link.max_state_age_s = max_age_s
            got = _Handled()
            autopilot.sendto(mavlink2.MAVLink_local_position_ned_message(30, 1, 2, 3, 0, 0, 0).pack(mav), dest)
            autopilot.sendto(mavlink2.MAVLink_sys_status_message(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav), dest)
            link.start_reading(got.append)
            await got.settle(link, "SYS_STATUS")
            return [m.get_type() for m in got], link.counters
        finally:
            link.close()
            autopilot.close()

    if not __import__("sys").platform.startswith("linux"):
        pytest.skip("kernel receive timestamps (SO_TIMESTAMPNS) are Linux-only")
    fresh, counters = asyncio.run(run(5.0))
    assert fresh == ["LOCAL_POSITION_NED", "SYS_STATUS"] and counters.stale_state == 0
    # any real wait exceeds a nanosecond: the sample counts as older than the limit
    stale, counters = asyncio.run(run(1e-9))
    assert stale == ["SYS_STATUS"] and counters.stale_state == 1
