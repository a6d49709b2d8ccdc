"""Helpers for tests and scripts that talk to the mock: free ports, command messages, a client.

Used by ``tests/sitl_mock`` and usable by the app's tests. Loopback only.
"""

from __future__ import annotations

import itertools
import os
import socket
import time

from pymavlink.dialects.v20 import common as mavlink


# Ports handed out below the kernel's ephemeral range (Linux default 32768-60999): a port taken
# from port 0 and released could be handed straight back to the next socket bound to port 0 (the
# mock's own, in the same test), and the client listening on it then fails with "Address already in
# use" (seen in CI). Below the range only an explicit bind can take it.
_PORT_LOW, _PORT_HIGH = 20000, 32000
# One walk over the range per process, starting at a pid-dependent port (parallel test processes
# start apart) and wrapping around.
_start = _PORT_LOW + (os.getpid() * 7919) % (_PORT_HIGH - _PORT_LOW)
_ports = itertools.cycle(itertools.chain(range(_start, _PORT_HIGH), range(_PORT_LOW, _start)))


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that is free now and outside the ephemeral range (for a client to
    listen on). Successive calls in one process walk the range, so two never return the same port."""
    for port in itertools.islice(_ports, _PORT_HIGH - _PORT_LOW):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:  # taken by another process: try the next one
                continue
            return port
    raise RuntimeError(f"no free UDP port in {_PORT_LOW}-{_PORT_HIGH} on 127.0.0.1")


def command_long(command: int, *params: float, target_system: int = 1) -> mavlink.MAVLink_command_long_message:
    values = list(params) + [0.0] * (7 - len(params))
    return mavlink.MAVLink_command_long_message(target_system, 1, command, 0, *values)


def accel_setpoint(ax: float, ay: float, az: float, yaw: float | None = None) -> mavlink.MAVLink_message:
    """SET_POSITION_TARGET_LOCAL_NED, acceleration only (type_mask 0x0C3F, or 0x083F with yaw)."""
    mask = 0x083F if yaw is not None else 0x0C3F
    return mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, mask, 0, 0, 0, 0, 0, 0, ax, ay, az, yaw or 0.0, 0.0
    )


class UdpClient:
    """A blocking pymavlink client on a connected UDP socket (sysid 255, compid 190).

    Use it as a context manager: the socket is opened on entry and closed on exit (no I/O in
    the constructor)."""

    def __init__(self, port: int, timeout_s: float = 5.0) -> None:
        self.port = port
        self.timeout_s = timeout_s
        self.sock: socket.socket | None = None
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.mav.robust_parsing = True
        self.bad = 0

    def open(self) -> UdpClient:
        """Open and connect the socket to 127.0.0.1:``port``."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.connect(("127.0.0.1", self.port))
            sock.settimeout(self.timeout_s)
        except BaseException:
            sock.close()
            raise
        self.sock = sock
        return self

    def send(self, msg: mavlink.MAVLink_message) -> None:
        self._open_socket().send(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) & 0xFF

    def recv(self) -> list[mavlink.MAVLink_message]:
        """Messages of one datagram (CRC failures counted in ``bad`` and dropped)."""
        out = []
        for msg in self.mav.parse_buffer(self._open_socket().recv(65536)) or []:
            if msg.get_type() == "BAD_DATA":
                self.bad += 1
            else:
                out.append(msg)
        return out

    def wait(self, msg_type: str, timeout_s: float = 5.0, condition=lambda m: True) -> mavlink.MAVLink_message:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for msg in self.recv():
                if msg.get_type() == msg_type and condition(msg):
                    return msg
        raise TimeoutError(f"no {msg_type} within {timeout_s} s")

    def _open_socket(self) -> socket.socket:
        if self.sock is None:
            raise RuntimeError("UdpClient is not open: use it as a context manager (with UdpClient(port) as c)")
        return self.sock

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def __enter__(self) -> UdpClient:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()
